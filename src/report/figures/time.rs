//! Time-domain figures: (c) tip velocities u/(Omega l) over time ([`time_histories`]); (d)
//! contact activity with the integrated normal and tangential contact forces normalised by
//! their maximum in the window ([`contact_activity`]).

use std::path::Path;

use plotters::coord::Shift;
use plotters::prelude::*;

use super::panel::{axis_areas, grid_styles, LinePanel, Series};
use super::TimeWindow;
use crate::report::data::{Source, TimeHistory};
use crate::report::draw::{
    decimate, draw_legend, finite_range, padded, palette, segments, split_legend, text, title,
    Fonts, LegendEntry, LineKind,
};
use crate::report::render::{check_output, err, render, Figure, Format};
use crate::report::{FigureOptions, ReportError};

/// Line style of a history: the twin dashed (over the measurement it is compared with), the
/// rest solid.
fn history_kind(h: &TimeHistory) -> LineKind {
    if h.source == Source::Twin {
        LineKind::Dashed
    } else {
        LineKind::Solid
    }
}

/// Colour of each history: fixed per source when every history has its own source
/// (measurement black, simulation blue, twin orange), else the palette by name, so a test's
/// measurement and twin share a colour (the twin dashed).
fn history_colors(h: &[TimeHistory]) -> Vec<RGBColor> {
    let distinct = h
        .iter()
        .enumerate()
        .all(|(i, a)| h[..i].iter().all(|b| b.source != a.source));
    h.iter()
        .enumerate()
        .map(|(i, x)| {
            if distinct {
                match x.source {
                    Source::Measurement => RGBColor(20, 20, 20),
                    Source::Simulation => palette(0),
                    Source::Twin => palette(3),
                }
            } else {
                let first = h.iter().position(|y| y.name == x.name).unwrap_or(i);
                let names = h[..first]
                    .iter()
                    .enumerate()
                    .filter(|(j, y)| h[..*j].iter().all(|z| z.name != y.name))
                    .count();
                palette(names)
            }
        })
        .collect()
}

fn check(h: &[TimeHistory], out: &Path) -> Result<(), ReportError> {
    for (i, x) in h.iter().enumerate() {
        let n = x.t.len();
        let fields = [
            ("upper", x.upper.len()),
            ("lower", x.lower.len()),
            ("contact_closed", x.contact_closed.len()),
            ("normal_force", x.normal_force.len()),
            ("tangential_force", x.tangential_force.len()),
        ];
        for (field, len) in fields {
            // `upper` is required; the others may be absent.
            if (len != 0 || field == "upper") && len != n {
                return Err(ReportError::InvalidData {
                    path: out.to_path_buf(),
                    what: format!(
                        "time history {} \"{}\" ({}): `{field}` has {len} samples but `t` \
                         has {n}",
                        i + 1,
                        x.name,
                        x.source
                    ),
                });
            }
        }
    }
    Ok(())
}

/// Samples of `y` against `t` inside the window, split at non-finite values.
fn in_window(t: &[f64], y: &[f64], w: Option<TimeWindow>) -> Vec<Vec<(f64, f64)>> {
    segments(t, y)
        .into_iter()
        .map(|r| match w {
            Some(w) => r
                .into_iter()
                .filter(|p| w.contains(p.0))
                .collect::<Vec<_>>(),
            None => r,
        })
        .filter(|r| !r.is_empty())
        .collect()
}

/// [`in_window`], each run decimated to about `bins` min/max pairs.
fn windowed(t: &[f64], y: &[f64], w: Option<TimeWindow>, bins: usize) -> Vec<Vec<(f64, f64)>> {
    in_window(t, y, w)
        .into_iter()
        .map(|r| decimate(&r, bins))
        .collect()
}

fn omega_caption(h: &[TimeHistory]) -> String {
    match h.first() {
        Some(first)
            if h.iter()
                .all(|x| (x.omega_ratio - first.omega_ratio).abs() < 1e-9) =>
        {
            format!(" at Ω / ω₂ = {:.3}", first.omega_ratio)
        }
        _ => String::new(),
    }
}

/// The time axis: the window, or the span of all finite times.
fn x_range(h: &[TimeHistory], w: Option<TimeWindow>) -> (f64, f64) {
    match w {
        Some(w) => (w.start, w.end),
        None => finite_range(h.iter().flat_map(|x| x.t.iter())).map_or((0.0, 1.0), |(a, b)| {
            if b > a {
                (a, b)
            } else {
                padded(a, b, 0.0)
            }
        }),
    }
}

struct Stack {
    title: String,
    panels: Vec<LinePanel>,
    lanes: Option<Lanes>,
    legend: Vec<LegendEntry>,
}

impl Figure for Stack {
    fn draw<DB: DrawingBackend>(
        &self,
        root: &DrawingArea<DB, Shift>,
        _format: Format,
    ) -> Result<(), String> {
        root.fill(&WHITE).map_err(err)?;
        let fonts = Fonts::for_area(root);
        let body = title(root, &self.title, &fonts)?;
        let (main, strip) = split_legend(&body, &self.legend, &fonts);
        let n = self.panels.len() + usize::from(self.lanes.is_some());
        let areas = main.split_evenly((n, 1));
        let mut areas = areas.iter();
        if let Some(lanes) = &self.lanes {
            if let Some(area) = areas.next() {
                lanes.draw(area, &fonts)?;
            }
        }
        for (panel, area) in self.panels.iter().zip(areas) {
            panel.draw(area, &fonts)?;
        }
        draw_legend(&strip, &self.legend, &fonts)
    }
}

/// (c) Tip velocity time histories (reference Figs. "velsignal"): u/(Omega l) of the upper
/// beam (top) and the lower beam (bottom, when any history has it) over t, all histories
/// overlaid (sources told apart by colour), optionally restricted to `window`. Dense signals
/// are reduced to their per-pixel envelope.
///
/// Errors: unsupported extension or size, a vector whose length differs from `t`, nothing
/// finite in the window, drawing or writing failures; each names `out`.
pub fn time_histories(
    histories: &[TimeHistory],
    window: Option<TimeWindow>,
    out: &Path,
    opts: &FigureOptions,
) -> Result<(), ReportError> {
    check_output(out, opts)?;
    check(histories, out)?;
    let colors = history_colors(histories);
    let bins = opts.width as usize;
    let upper: Vec<_> = histories
        .iter()
        .map(|h| windowed(&h.t, &h.upper, window, bins))
        .collect();
    let lower: Vec<_> = histories
        .iter()
        .map(|h| windowed(&h.t, &h.lower, window, bins))
        .collect();
    let mut panels = Vec::new();
    let x = x_range(histories, window);
    for (beam, runs) in [("upper", &upper), ("lower", &lower)] {
        if runs.iter().all(|r| r.is_empty()) {
            continue;
        }
        let y = finite_range(runs.iter().flatten().flatten().map(|p| &p.1)).map_or(
            (-1.0, 1.0),
            |(a, b)| {
                let m = a.abs().max(b.abs());
                padded(-m, m, 0.05)
            },
        );
        panels.push(LinePanel {
            caption: format!("{beam} beam tip"),
            x_desc: "t (s)".into(),
            y_desc: "u / (Ω l) (-)".into(),
            x,
            y,
            bands: Vec::new(),
            series: runs
                .iter()
                .enumerate()
                .map(|(i, r)| Series {
                    runs: r.clone(),
                    color: colors[i],
                    kind: history_kind(&histories[i]),
                    width: 1,
                })
                .collect(),
        });
    }
    if panels.is_empty() {
        return Err(ReportError::NothingToPlot {
            path: out.to_path_buf(),
            what: format!(
                "no finite velocity sample{} in {} time histor{}",
                if window.is_some() {
                    " in the window"
                } else {
                    ""
                },
                histories.len(),
                if histories.len() == 1 { "y" } else { "ies" }
            ),
        });
    }
    let legend = histories
        .iter()
        .enumerate()
        .map(|(i, h)| LegendEntry {
            label: format!("{} ({})", h.name, h.source),
            color: colors[i],
            kind: history_kind(h),
        })
        .collect();
    let fig = Stack {
        title: format!("Tip velocity{}", omega_caption(histories)),
        panels,
        lanes: None,
        legend,
    };
    render(out, opts, &fig)
}

/// One contact-state lane.
struct Lane {
    label: String,
    color: RGBColor,
    /// Closed intervals [t0, t1], s.
    closed: Vec<(f64, f64)>,
}

/// Contact state lanes: one lane per history, closed intervals drawn as filled bars.
struct Lanes {
    x: (f64, f64),
    lanes: Vec<Lane>,
}

impl Lanes {
    fn draw<DB: DrawingBackend>(
        &self,
        area: &DrawingArea<DB, Shift>,
        fonts: &Fonts,
    ) -> Result<(), String> {
        let (margin, x_area, y_area) = axis_areas(fonts);
        let n = self.lanes.len() as f64;
        let mut chart = ChartBuilder::on(area)
            .caption("contact closed", text(fonts.caption))
            .margin(margin)
            .x_label_area_size(x_area)
            .y_label_area_size(y_area)
            .build_cartesian_2d(self.x.0..self.x.1, 0.0..n)
            .map_err(err)?;
        let (bold, light) = grid_styles();
        chart
            .configure_mesh()
            .x_desc("t (s)")
            .y_desc("contact")
            .label_style(text(fonts.label))
            .axis_desc_style(text(fonts.desc))
            .bold_line_style(bold)
            .light_line_style(light)
            .disable_y_mesh()
            .y_labels(0)
            .x_labels(8)
            .draw()
            .map_err(err)?;
        let span = self.x.1 - self.x.0;
        // NOTE: an impact lasts a sample or two, far less than a pixel of a record of seconds:
        // every bar is at least one pixel wide (of the whole area: a lower bound of the plot's
        // pixel), so no contact disappears from the lanes.
        let min_width = span / f64::from(area.dim_in_pixel().0.max(1));
        for (
            k,
            Lane {
                label,
                color,
                closed: runs,
            },
        ) in self.lanes.iter().enumerate()
        {
            // Lane k occupies [k, k+1): bars in the lower 60 %, the label above them.
            let lane = (self.lanes.len() - 1 - k) as f64;
            chart
                .draw_series(runs.iter().map(|&(a, b)| {
                    Rectangle::new(
                        [(a, lane + 0.1), (b.max(a + min_width), lane + 0.7)],
                        color.filled(),
                    )
                }))
                .map_err(err)?;
            chart
                .draw_series(std::iter::once(Text::new(
                    label.clone(),
                    (self.x.0 + 0.005 * span, lane + 0.96),
                    text(fonts.label),
                )))
                .map_err(err)?;
        }
        Ok(())
    }
}

/// Closed intervals of a contact-state record inside the window: a run of closed samples
/// k0..=k1 spans [t[k0], t[k1 + 1]) (one sample interval at the end of the record).
fn closed_intervals(t: &[f64], closed: &[bool], w: Option<TimeWindow>) -> Vec<(f64, f64)> {
    let n = t.len().min(closed.len());
    let mut out = Vec::new();
    let mut k = 0;
    while k < n {
        if !closed[k] || !t[k].is_finite() {
            k += 1;
            continue;
        }
        let k0 = k;
        while k + 1 < n && closed[k + 1] && t[k + 1].is_finite() {
            k += 1;
        }
        let end = if k + 1 < n {
            t[k + 1]
        } else if k > 0 {
            // The record's last sample: one sample interval long.
            2.0 * t[k] - t[k - 1]
        } else {
            t[k]
        };
        let (mut a, mut b) = (t[k0], end);
        if let Some(w) = w {
            a = a.max(w.start);
            b = b.min(w.end);
        }
        if b > a || (b == a && w.is_none_or(|w| w.contains(a))) {
            out.push((a, b));
        }
        k += 1;
    }
    out
}

/// `y / max |y|` over the window (0 when the maximum is 0), as windowed runs.
fn normalised(t: &[f64], y: &[f64], w: Option<TimeWindow>, bins: usize) -> Vec<Vec<(f64, f64)>> {
    let runs = in_window(t, y, w);
    let max = runs
        .iter()
        .flatten()
        .map(|p| p.1.abs())
        .fold(0.0_f64, f64::max);
    let scale = if max > 0.0 { 1.0 / max } else { 0.0 };
    runs.into_iter()
        .map(|r| {
            let r: Vec<(f64, f64)> = r.into_iter().map(|(a, b)| (a, b * scale)).collect();
            decimate(&r, bins)
        })
        .collect()
}

/// (d) Contact activity (reference Fig. "contactactivity"): one lane per history that has a
/// contact state (bars where closed), then the integrated normal and tangential contact
/// forces, each normalised by its largest magnitude inside the window, for the histories
/// that have them. Use `window` for the zoomed view.
///
/// Errors: as [`time_histories`]; nothing to plot when no history has a contact state or a
/// force.
pub fn contact_activity(
    histories: &[TimeHistory],
    window: Option<TimeWindow>,
    out: &Path,
    opts: &FigureOptions,
) -> Result<(), ReportError> {
    check_output(out, opts)?;
    check(histories, out)?;
    let colors = history_colors(histories);
    let bins = opts.width as usize;
    let lanes: Vec<Lane> = histories
        .iter()
        .enumerate()
        .filter(|(_, h)| !h.contact_closed.is_empty())
        .map(|(i, h)| Lane {
            label: format!("{} ({})", h.name, h.source),
            color: colors[i],
            closed: closed_intervals(&h.t, &h.contact_closed, window),
        })
        .collect();
    let normal: Vec<_> = histories
        .iter()
        .map(|h| normalised(&h.t, &h.normal_force, window, bins))
        .collect();
    let tangential: Vec<_> = histories
        .iter()
        .map(|h| normalised(&h.t, &h.tangential_force, window, bins))
        .collect();
    let has_force = |f: &Vec<Vec<Vec<(f64, f64)>>>| f.iter().any(|r| !r.is_empty());
    if lanes.is_empty() && !has_force(&normal) && !has_force(&tangential) {
        return Err(ReportError::NothingToPlot {
            path: out.to_path_buf(),
            what: format!(
                "no contact state or contact force{} in {} time histor{}",
                if window.is_some() {
                    " in the window"
                } else {
                    ""
                },
                histories.len(),
                if histories.len() == 1 { "y" } else { "ies" }
            ),
        });
    }
    let x = x_range(histories, window);
    let mut panels = Vec::new();
    for (what, runs) in [("normal", &normal), ("tangential", &tangential)] {
        if !has_force(runs) {
            continue;
        }
        let lo = finite_range(runs.iter().flatten().flatten().map(|p| &p.1))
            .map_or(0.0, |(a, _)| a.min(0.0));
        panels.push(LinePanel {
            caption: format!("integrated {what} contact force"),
            x_desc: "t (s)".into(),
            y_desc: format!("F_{} / max|F_{}| (-)", &what[..1], &what[..1]),
            x,
            y: (lo - 0.05, 1.05),
            bands: Vec::new(),
            series: runs
                .iter()
                .enumerate()
                .map(|(i, r)| Series {
                    runs: r.clone(),
                    color: colors[i],
                    kind: history_kind(&histories[i]),
                    width: 1,
                })
                .collect(),
        });
    }
    let legend = histories
        .iter()
        .enumerate()
        .filter(|(i, h)| {
            !h.contact_closed.is_empty() || !normal[*i].is_empty() || !tangential[*i].is_empty()
        })
        .map(|(i, h)| LegendEntry {
            label: format!("{} ({})", h.name, h.source),
            color: colors[i],
            kind: history_kind(h),
        })
        .collect();
    let fig = Stack {
        title: format!("Contact activity{}", omega_caption(histories)),
        panels,
        lanes: (!lanes.is_empty()).then_some(Lanes { x, lanes }),
        legend,
    };
    render(out, opts, &fig)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn closed_intervals_cover_runs() {
        let t = [0.0, 1.0, 2.0, 3.0, 4.0, 5.0];
        let c = [false, true, true, false, false, true];
        assert_eq!(closed_intervals(&t, &c, None), vec![(1.0, 3.0), (5.0, 6.0)]);
        let w = TimeWindow {
            start: 2.5,
            end: 10.0,
        };
        // An interval crossing the window's start is clipped to it.
        assert_eq!(
            closed_intervals(&t, &c, Some(w)),
            vec![(2.5, 3.0), (5.0, 6.0)]
        );
        let w = TimeWindow {
            start: 3.5,
            end: 4.5,
        };
        assert!(closed_intervals(&t, &c, Some(w)).is_empty());
    }

    #[test]
    fn forces_are_normalised_in_the_window() {
        let t = [0.0, 1.0, 2.0, 3.0];
        let f = [10.0, 2.0, 4.0, 1.0];
        let w = TimeWindow {
            start: 1.0,
            end: 3.0,
        };
        let r = normalised(&t, &f, Some(w), 100);
        assert_eq!(r, vec![vec![(1.0, 0.5), (2.0, 1.0), (3.0, 0.25)]]);
    }
}
