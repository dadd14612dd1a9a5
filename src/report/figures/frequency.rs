//! Frequency-domain figures: (a) RMS frequency response of both beams per level, forward and
//! backward ([`rms_response`]); (b) min/mean/max per-period amplitude per level
//! ([`amplitude_range`]).

use std::path::Path;

use plotters::coord::Shift;
use plotters::prelude::*;

use super::panel::{Band, LinePanel, Series};
use crate::report::data::{Beam, FrequencyResponse, Source, TestCurve};
use crate::report::draw::{
    draw_legend, finite_range, padded, palette, segments, source_kind, split_legend, title, Fonts,
    LegendEntry, LineKind,
};
use crate::report::render::{check_output, render, Figure, Format};
use crate::report::{FigureOptions, ReportError};

/// Label of the excitation frequency axis.
const OMEGA_DESC: &str = "Ω / ω₂ (-)";

/// Checks the vector lengths of every curve (a vector may be empty: not available).
fn check_lengths(data: &FrequencyResponse, out: &Path) -> Result<(), ReportError> {
    for (i, c) in data.tests.iter().enumerate() {
        let n = c.omega_ratio.len();
        let fields: [(&str, usize); 8] = [
            ("rms_upper", c.rms_upper.len()),
            ("rms_lower", c.rms_lower.len()),
            ("amp_min_upper", c.amp_min_upper.len()),
            ("amp_mean_upper", c.amp_mean_upper.len()),
            ("amp_max_upper", c.amp_max_upper.len()),
            ("amp_min_lower", c.amp_min_lower.len()),
            ("amp_mean_lower", c.amp_mean_lower.len()),
            ("amp_max_lower", c.amp_max_lower.len()),
        ];
        for (field, len) in fields {
            if len != 0 && len != n {
                return Err(ReportError::InvalidData {
                    path: out.to_path_buf(),
                    what: format!(
                        "curve {} \"{}\" ({}): `{field}` has {len} values but `omega_ratio` \
                         has {n}",
                        i + 1,
                        c.name,
                        c.source
                    ),
                });
            }
        }
    }
    Ok(())
}

/// Distinct levels, ascending (levels within a relative 1e-6 are one level).
fn levels(curves: &[&TestCurve]) -> Vec<f64> {
    let mut out: Vec<f64> = Vec::new();
    for c in curves {
        if !out
            .iter()
            .any(|&l| (l - c.level).abs() <= 1e-6 * l.abs().max(c.level.abs()))
        {
            out.push(c.level);
        }
    }
    out.sort_by(f64::total_cmp);
    out
}

fn same_level(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-6 * a.abs().max(b.abs())
}

/// Colour of each curve: one per test name, in order of first appearance.
fn test_colors(curves: &[TestCurve]) -> Vec<RGBColor> {
    let mut names: Vec<&str> = Vec::new();
    curves
        .iter()
        .map(|c| {
            let i = names.iter().position(|n| *n == c.name).unwrap_or_else(|| {
                names.push(&c.name);
                names.len() - 1
            });
            palette(i)
        })
        .collect()
}

/// One legend entry per (test, source), in order.
fn legend(
    curves: &[TestCurve],
    colors: &[RGBColor],
    keep: impl Fn(usize) -> bool,
) -> Vec<LegendEntry> {
    let mut seen: Vec<(&str, Source)> = Vec::new();
    let mut out = Vec::new();
    for (i, c) in curves.iter().enumerate() {
        if !keep(i) || seen.contains(&(c.name.as_str(), c.source)) {
            continue;
        }
        seen.push((&c.name, c.source));
        out.push(LegendEntry {
            label: format!("{} ({}, {})", c.name, c.direction, c.source),
            color: colors[i],
            kind: source_kind(c.source),
        });
    }
    out
}

fn level_label(level: f64) -> String {
    format!("q_base = {level:.2e} l")
}

/// A grid of panels (rows x columns) with a title and a legend strip.
struct Grid {
    title: String,
    rows: usize,
    cols: usize,
    panels: Vec<LinePanel>,
    legend: Vec<LegendEntry>,
}

impl Figure for Grid {
    fn draw<DB: DrawingBackend>(
        &self,
        root: &DrawingArea<DB, Shift>,
        _format: Format,
    ) -> Result<(), String> {
        root.fill(&WHITE).map_err(crate::report::render::err)?;
        let fonts = Fonts::for_area(root);
        let body = title(root, &self.title, &fonts)?;
        let (main, strip) = split_legend(&body, &self.legend, &fonts);
        for (panel, area) in self
            .panels
            .iter()
            .zip(main.split_evenly((self.rows, self.cols)))
        {
            panel.draw(&area, &fonts)?;
        }
        draw_legend(&strip, &self.legend, &fonts)
    }
}

/// (a) The RMS frequency response (reference Fig. "plot_rms"): RMS tip velocity / (Omega
/// q_base) vs Omega / omega_2, one row per beam (upper, lower; a beam without data is left
/// out), one column per base level, all tests (forward and backward) and sources of that
/// level overlaid. Colours tell tests apart, line styles sources (simulation solid,
/// measurement markers, twin dashed).
///
/// Errors: unsupported extension or size, vectors of a curve with different lengths,
/// nothing finite to plot, drawing or writing failures; each names `out`.
pub fn rms_response(
    data: &FrequencyResponse,
    out: &Path,
    opts: &FigureOptions,
) -> Result<(), ReportError> {
    check_output(out, opts)?;
    check_lengths(data, out)?;
    let curves = &data.tests;
    let colors = test_colors(curves);
    let fonts = Fonts::for_size(opts.width, opts.height);
    let all: Vec<&TestCurve> = curves.iter().collect();
    let levels = levels(&all);
    let x = finite_range(curves.iter().flat_map(|c| c.omega_ratio.iter()));
    let mut panels = Vec::new();
    let mut rows = 0;
    for beam in [Beam::Upper, Beam::Lower] {
        let has_data = curves
            .iter()
            .any(|c| !segments(&c.omega_ratio, c.rms(beam)).is_empty());
        if !has_data {
            continue;
        }
        rows += 1;
        // One y range per beam row, so levels compare at a glance.
        let y_max =
            finite_range(curves.iter().flat_map(|c| c.rms(beam).iter())).map_or(1.0, |(_, hi)| hi);
        for &level in &levels {
            let series = curves
                .iter()
                .enumerate()
                .filter(|(_, c)| same_level(c.level, level))
                .map(|(i, c)| Series {
                    runs: segments(&c.omega_ratio, c.rms(beam)),
                    color: colors[i],
                    kind: source_kind(c.source),
                    width: fonts.line,
                })
                .collect();
            panels.push(LinePanel {
                caption: format!("{} beam, {}", beam.as_str(), level_label(level)),
                x_desc: OMEGA_DESC.into(),
                y_desc: "u_rms / (Ω q_base) (-)".into(),
                x: x.map_or((0.9, 1.1), |(lo, hi)| padded(lo, hi, 0.02)),
                y: (0.0, if y_max > 0.0 { 1.08 * y_max } else { 1.0 }),
                bands: Vec::new(),
                series,
            });
        }
    }
    if rows == 0 {
        return Err(ReportError::NothingToPlot {
            path: out.to_path_buf(),
            what: format!(
                "no finite (omega_ratio, rms) pair in {} curve(s)",
                curves.len()
            ),
        });
    }
    let grid = Grid {
        title: "RMS frequency response of the tip velocities".into(),
        rows,
        cols: levels.len(),
        panels,
        legend: legend(curves, &colors, |_| true),
    };
    render(out, opts, &grid)
}

/// (b) Min/mean/max per-period zero-to-peak amplitude of a beam's tip velocity / (Omega
/// q_base) vs Omega / omega_2 (reference Figs. "plot_minmax"): one panel per base level; per
/// curve the mean as a thick line, min and max as thin lines with a light band between them.
/// Curves without amplitudes for `beam` are left out.
///
/// Errors: as [`rms_response`]; nothing to plot when no curve has finite amplitudes.
pub fn amplitude_range(
    data: &FrequencyResponse,
    beam: Beam,
    out: &Path,
    opts: &FigureOptions,
) -> Result<(), ReportError> {
    check_output(out, opts)?;
    check_lengths(data, out)?;
    let curves = &data.tests;
    let colors = test_colors(curves);
    let fonts = Fonts::for_size(opts.width, opts.height);
    let usable: Vec<usize> = (0..curves.len())
        .filter(|&i| {
            let (lo, mean, hi) = curves[i].amplitudes(beam);
            let w = &curves[i].omega_ratio;
            [lo, mean, hi].iter().any(|v| !segments(w, v).is_empty())
        })
        .collect();
    if usable.is_empty() {
        return Err(ReportError::NothingToPlot {
            path: out.to_path_buf(),
            what: format!(
                "no finite per-period amplitude of the {} beam in {} curve(s)",
                beam.as_str(),
                curves.len()
            ),
        });
    }
    let chosen: Vec<&TestCurve> = usable.iter().map(|&i| &curves[i]).collect();
    let levels = levels(&chosen);
    let x = finite_range(chosen.iter().flat_map(|c| c.omega_ratio.iter()));
    let y_max = finite_range(chosen.iter().flat_map(|c| {
        let (lo, mean, hi) = c.amplitudes(beam);
        lo.iter().chain(mean).chain(hi)
    }))
    .map_or(1.0, |(_, hi)| hi);
    let mut panels = Vec::new();
    for &level in &levels {
        let mut series = Vec::new();
        let mut bands = Vec::new();
        for &i in usable
            .iter()
            .filter(|&&i| same_level(curves[i].level, level))
        {
            let c = &curves[i];
            let (lo, mean, hi) = c.amplitudes(beam);
            let kind = source_kind(c.source);
            bands.push(Band {
                polygons: band_polygons(&c.omega_ratio, lo, hi),
                color: colors[i],
            });
            // Markers only on the mean: on min and max they would triple the clutter.
            let edge_kind = if kind == LineKind::Markers {
                LineKind::Solid
            } else {
                kind
            };
            for (v, k, width) in [
                (lo, edge_kind, 1),
                (hi, edge_kind, 1),
                (mean, kind, fonts.line + 1),
            ] {
                series.push(Series {
                    runs: segments(&c.omega_ratio, v),
                    color: colors[i],
                    kind: k,
                    width,
                });
            }
        }
        panels.push(LinePanel {
            caption: format!("{} beam, {}", beam.as_str(), level_label(level)),
            x_desc: OMEGA_DESC.into(),
            y_desc: "tip velocity amplitude / (Ω q_base) (-)".into(),
            x: x.map_or((0.9, 1.1), |(lo, hi)| padded(lo, hi, 0.02)),
            y: (0.0, if y_max > 0.0 { 1.08 * y_max } else { 1.0 }),
            bands,
            series,
        });
    }
    let mut legend = legend(curves, &colors, |i| usable.contains(&i));
    legend.push(LegendEntry {
        label: "thick: mean, thin + band: min … max over the periods".into(),
        color: RGBColor(90, 90, 90),
        kind: LineKind::Band,
    });
    let grid = Grid {
        title: format!(
            "Per-period amplitude of the {} tip velocity: min, mean, max",
            beam.as_str()
        ),
        rows: 1,
        cols: levels.len(),
        panels,
        legend,
    };
    render(out, opts, &grid)
}

/// Closed polygons between `lo` and `hi` over runs where x, lo and hi are all finite.
fn band_polygons(x: &[f64], lo: &[f64], hi: &[f64]) -> Vec<Vec<(f64, f64)>> {
    if lo.len() != x.len() || hi.len() != x.len() {
        return Vec::new();
    }
    let mut out = Vec::new();
    let mut run: Vec<usize> = Vec::new();
    let flush = |run: &mut Vec<usize>, out: &mut Vec<Vec<(f64, f64)>>| {
        if run.len() >= 2 {
            let mut p: Vec<(f64, f64)> = run.iter().map(|&k| (x[k], hi[k])).collect();
            p.extend(run.iter().rev().map(|&k| (x[k], lo[k])));
            out.push(p);
        }
        run.clear();
    };
    for k in 0..x.len() {
        if x[k].is_finite() && lo[k].is_finite() && hi[k].is_finite() {
            run.push(k);
        } else {
            flush(&mut run, &mut out);
        }
    }
    flush(&mut run, &mut out);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn band_polygons_split_at_nan() {
        let x = [1.0, 2.0, 3.0, 4.0, 5.0];
        let lo = [0.0, 0.0, f64::NAN, 0.0, 0.0];
        let hi = [1.0, 1.0, 1.0, 1.0, 1.0];
        let p = band_polygons(&x, &lo, &hi);
        assert_eq!(p.len(), 2);
        assert_eq!(p[0], vec![(1.0, 1.0), (2.0, 1.0), (2.0, 0.0), (1.0, 0.0)]);
    }
}
