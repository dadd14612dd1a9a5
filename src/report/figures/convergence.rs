//! (f) Convergence studies (reference Figs. "convergence_time", "convergence_modal"): the
//! overlaid time signals of the runs (left, when given) and the relative RMS error vs time
//! steps per period or number of modes on log-log axes (right).

use std::path::Path;

use plotters::coord::Shift;
use plotters::prelude::*;

use super::panel::{axis_areas, grid_styles, log_tick, tick, LinePanel, Series};
use crate::report::data::{Convergence, ConvergenceKind};
use crate::report::draw::{
    decimate, draw_legend, draw_runs, finite_range, log_range, padded, palette, segments,
    split_legend, text, title, Fonts, LegendEntry, LineKind,
};
use crate::report::render::{check_output, err, render, Figure, Format};
use crate::report::{FigureOptions, ReportError};

fn run_label(kind: ConvergenceKind, x: f64) -> String {
    match kind {
        ConvergenceKind::Dt => format!("{} steps/period", tick(x)),
        ConvergenceKind::Modes => format!("{} modes", tick(x)),
    }
}

struct Study {
    title: String,
    kind: ConvergenceKind,
    points: Vec<(f64, f64)>,
    x: (f64, f64),
    y: (f64, f64),
    signals: Option<LinePanel>,
    legend: Vec<LegendEntry>,
}

impl Study {
    fn draw_error<DB: DrawingBackend>(
        &self,
        area: &DrawingArea<DB, Shift>,
        fonts: &Fonts,
    ) -> Result<(), String> {
        let (margin, x_area, y_area) = axis_areas(fonts);
        let mut chart = ChartBuilder::on(area)
            .caption("relative RMS error", text(fonts.caption))
            .margin(margin)
            .x_label_area_size(x_area)
            .y_label_area_size(y_area)
            .build_cartesian_2d(
                (self.x.0..self.x.1).log_scale(),
                (self.y.0..self.y.1).log_scale(),
            )
            .map_err(err)?;
        let (bold, light) = grid_styles();
        chart
            .configure_mesh()
            .x_desc(self.kind.axis_label())
            .y_desc("ε_RMS (-)")
            .label_style(text(fonts.label))
            .axis_desc_style(text(fonts.desc))
            .bold_line_style(bold)
            .light_line_style(light)
            .x_label_formatter(&|v| log_tick(*v, (self.x.1 / self.x.0).log10()))
            .y_label_formatter(&|v| log_tick(*v, (self.y.1 / self.y.0).log10()))
            .draw()
            .map_err(err)?;
        draw_runs(
            &mut chart,
            std::slice::from_ref(&self.points),
            RGBColor(20, 20, 20),
            LineKind::Markers,
            1,
            fonts,
        )
    }
}

impl Figure for Study {
    fn draw<DB: DrawingBackend>(
        &self,
        root: &DrawingArea<DB, Shift>,
        _format: Format,
    ) -> Result<(), String> {
        root.fill(&WHITE).map_err(err)?;
        let fonts = Fonts::for_area(root);
        let body = title(root, &self.title, &fonts)?;
        let (main, strip) = split_legend(&body, &self.legend, &fonts);
        match &self.signals {
            Some(panel) => {
                let (w, _) = main.dim_in_pixel();
                let (left, right) = main.split_horizontally(w / 2);
                panel.draw(&left, &fonts)?;
                self.draw_error(&right, &fonts)?;
            }
            None => self.draw_error(&main, &fonts)?,
        }
        draw_legend(&strip, &self.legend, &fonts)
    }
}

/// (f) Draws a convergence study: relative RMS error vs the varied quantity on log-log axes
/// (points with a non-positive or non-finite x or error are skipped: the reference run has
/// error 0), and, when `study.signals` is not empty, the runs' time signals u/(Omega l)
/// overlaid in a left panel (the reference run, if named, in black).
///
/// Errors: unsupported extension or size, `x` and `error` (or a signal's `t` and `u`) of
/// different lengths, no positive finite (x, error) pair, drawing or writing failures; each
/// names `out`.
pub fn convergence(
    study: &Convergence,
    out: &Path,
    opts: &FigureOptions,
) -> Result<(), ReportError> {
    check_output(out, opts)?;
    let invalid = |what: String| ReportError::InvalidData {
        path: out.to_path_buf(),
        what,
    };
    if study.x.len() != study.error.len() {
        return Err(invalid(format!(
            "`x` has {} values but `error` has {}",
            study.x.len(),
            study.error.len()
        )));
    }
    for (i, s) in study.signals.iter().enumerate() {
        if s.t.len() != s.u.len() {
            return Err(invalid(format!(
                "signal {} ({}): `t` has {} samples but `u` has {}",
                i + 1,
                run_label(study.kind, s.x),
                s.t.len(),
                s.u.len()
            )));
        }
    }
    let mut points: Vec<(f64, f64)> = study
        .x
        .iter()
        .zip(&study.error)
        .filter(|(x, e)| x.is_finite() && e.is_finite() && **x > 0.0 && **e > 0.0)
        .map(|(&x, &e)| (x, e))
        .collect();
    if points.is_empty() {
        return Err(ReportError::NothingToPlot {
            path: out.to_path_buf(),
            what: format!(
                "no positive finite (x, error) pair among {} run(s)",
                study.x.len()
            ),
        });
    }
    points.sort_by(|a, b| a.0.total_cmp(&b.0));
    let (x_lo, x_hi) = finite_range(points.iter().map(|p| &p.0)).unwrap_or((1.0, 10.0));
    let (y_lo, y_hi) = finite_range(points.iter().map(|p| &p.1)).unwrap_or((1e-3, 1.0));
    let fonts = Fonts::for_size(opts.width, opts.height);
    let bins = (opts.width / 2) as usize;
    let mut legend = Vec::new();
    let mut series = Vec::new();
    let mut t_all = Vec::new();
    let mut u_all = Vec::new();
    for (i, s) in study.signals.iter().enumerate() {
        let is_ref = study.reference == Some(s.x);
        let color = if is_ref {
            RGBColor(20, 20, 20)
        } else {
            palette(i)
        };
        let runs: Vec<_> = segments(&s.t, &s.u)
            .iter()
            .map(|r| decimate(r, bins))
            .collect();
        if runs.is_empty() {
            continue;
        }
        t_all.extend(runs.iter().flatten().map(|p| p.0));
        u_all.extend(runs.iter().flatten().map(|p| p.1));
        let mut label = run_label(study.kind, s.x);
        if is_ref {
            label.push_str(" (reference)");
        }
        legend.push(LegendEntry {
            label,
            color,
            kind: LineKind::Solid,
        });
        series.push(Series {
            runs,
            color,
            kind: LineKind::Solid,
            width: if is_ref { fonts.line + 1 } else { fonts.line },
        });
    }
    let signals = (!series.is_empty()).then(|| LinePanel {
        caption: "upper tip velocity".into(),
        x_desc: "t (s)".into(),
        y_desc: "u / (Ω l) (-)".into(),
        x: finite_range(&t_all).map_or((0.0, 1.0), |(a, b)| padded(a, b, 0.0)),
        y: finite_range(&u_all).map_or((-1.0, 1.0), |(a, b)| padded(a, b, 0.05)),
        bands: Vec::new(),
        series,
    });
    if signals.is_none() {
        if let Some(r) = study.reference {
            legend.push(LegendEntry {
                label: format!("reference: {}", run_label(study.kind, r)),
                color: RGBColor(20, 20, 20),
                kind: LineKind::Markers,
            });
        }
    }
    let fig = Study {
        title: match study.kind {
            ConvergenceKind::Dt => "Convergence with the time step".into(),
            ConvergenceKind::Modes => "Convergence with the number of normal modes".into(),
        },
        kind: study.kind,
        points,
        x: log_range(x_lo, x_hi),
        y: log_range(y_lo, y_hi),
        signals,
        legend,
    };
    render(out, opts, &fig)
}
