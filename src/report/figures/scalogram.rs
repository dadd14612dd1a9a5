//! (e) The Morlet scalogram heat map of u/(Omega l) (reference Fig. "wavelets"): time on x,
//! frequency in multiples of the excitation frequency on y, log10 |W| as colour with a
//! colour bar.

use std::path::Path;

use plotters::coord::Shift;
use plotters::prelude::*;

use super::panel::{axis_areas, grid_styles};
use super::ScalogramOptions;
use crate::report::draw::{text, title, Fonts};
use crate::report::render::{check_output, err, render, Figure, Format};
use crate::report::{FigureOptions, ReportError};
use crate::signal::wavelet::Scalogram;

/// Viridis, sampled at 9 points (matplotlib's table), interpolated linearly.
const VIRIDIS: [(u8, u8, u8); 9] = [
    (68, 1, 84),
    (71, 44, 122),
    (59, 81, 139),
    (44, 113, 142),
    (33, 144, 141),
    (39, 173, 129),
    (92, 200, 99),
    (170, 220, 50),
    (253, 231, 37),
];

/// The colour of `h` in [0, 1] (clamped).
fn viridis(h: f64) -> RGBColor {
    let h = if h.is_finite() {
        h.clamp(0.0, 1.0)
    } else {
        0.0
    };
    let x = h * (VIRIDIS.len() - 1) as f64;
    let i = (x.floor() as usize).min(VIRIDIS.len() - 2);
    let f = x - i as f64;
    let mix = |a: u8, b: u8| (f64::from(a) + f * (f64::from(b) - f64::from(a))).round() as u8;
    let (a, b) = (VIRIDIS[i], VIRIDIS[i + 1]);
    RGBColor(mix(a.0, b.0), mix(a.1, b.1), mix(a.2, b.2))
}

/// Columns of cells for a format: about one per pixel for PNG, fewer for SVG (one
/// rectangle element per cell).
fn columns(format: Format, plot_px: u32, n_times: usize) -> usize {
    let cap = match format {
        Format::Png => plot_px as usize,
        Format::Svg => 300,
    };
    n_times.min(cap.max(1))
}

struct Heat<'a> {
    s: &'a Scalogram,
    /// Row order by ascending frequency.
    order: Vec<usize>,
    /// Cell edges on the y axis (f / f_exc), `order.len() + 1` values.
    edges: Vec<f64>,
    t0: f64,
    /// log10 |W| colour range.
    lo: f64,
    hi: f64,
    title: String,
}

impl Heat<'_> {
    /// Mean of row `i` over time samples `a..b`.
    fn mean(&self, i: usize, a: usize, b: usize) -> f64 {
        let row = &self.s.row(i)[a..b];
        let (sum, n) = row
            .iter()
            .filter(|v| v.is_finite())
            .fold((0.0, 0usize), |(s, n), v| (s + v, n + 1));
        if n == 0 {
            f64::NAN
        } else {
            sum / n as f64
        }
    }

    fn color(&self, magnitude: f64) -> RGBColor {
        let v = if magnitude > 0.0 {
            magnitude.log10()
        } else {
            self.lo
        };
        viridis((v - self.lo) / (self.hi - self.lo))
    }
}

impl Figure for Heat<'_> {
    fn draw<DB: DrawingBackend>(
        &self,
        root: &DrawingArea<DB, Shift>,
        format: Format,
    ) -> Result<(), String> {
        root.fill(&WHITE).map_err(err)?;
        let fonts = Fonts::for_area(root);
        let body = title(root, &self.title, &fonts)?;
        let (w, _) = body.dim_in_pixel();
        let bar_w = (fonts.label * 9.0) as u32;
        let (main, bar) = body.split_horizontally(w.saturating_sub(bar_w));
        let (margin, x_area, y_area) = axis_areas(&fonts);
        let n_t = self.s.n_times;
        let t_end = self.t0 + n_t as f64 * self.s.dt;
        let (y0, y1) = (self.edges[0], self.edges[self.edges.len() - 1]);
        let mut chart = ChartBuilder::on(&main)
            .margin(margin)
            .x_label_area_size(x_area)
            .y_label_area_size(y_area)
            .build_cartesian_2d(self.t0..t_end, y0..y1)
            .map_err(err)?;
        let (bold, light) = grid_styles();
        chart
            .configure_mesh()
            .x_desc("t (s)")
            .y_desc("f / f_exc (-)")
            .label_style(text(fonts.label))
            .axis_desc_style(text(fonts.desc))
            .bold_line_style(bold)
            .light_line_style(light)
            .disable_mesh()
            .x_labels(8)
            .y_labels(8)
            .draw()
            .map_err(err)?;
        let (px, _) = chart.plotting_area().dim_in_pixel();
        let cols = columns(format, px, n_t);
        let mut cells = Vec::with_capacity(cols * self.order.len());
        for c in 0..cols {
            let a = c * n_t / cols;
            let b = ((c + 1) * n_t / cols).max(a + 1);
            let (ta, tb) = (
                self.t0 + a as f64 * self.s.dt,
                self.t0 + b as f64 * self.s.dt,
            );
            for (r, &i) in self.order.iter().enumerate() {
                let color = self.color(self.mean(i, a, b));
                cells.push(Rectangle::new(
                    [(ta, self.edges[r]), (tb, self.edges[r + 1])],
                    color.filled(),
                ));
            }
        }
        chart.draw_series(cells).map_err(err)?;
        // Colour bar.
        let mut cb = ChartBuilder::on(&bar)
            .margin(margin)
            .margin_left(0)
            .x_label_area_size(x_area)
            .y_label_area_size((fonts.label * 5.5) as u32)
            .build_cartesian_2d(0.0..1.0, self.lo..self.hi)
            .map_err(err)?;
        cb.configure_mesh()
            .disable_mesh()
            .disable_x_axis()
            .y_desc("log10 |W| (-)")
            .label_style(text(fonts.label))
            .axis_desc_style(text(fonts.desc))
            .y_labels(6)
            .draw()
            .map_err(err)?;
        let n = 128;
        let step = (self.hi - self.lo) / n as f64;
        cb.draw_series((0..n).map(|k| {
            let v = self.lo + k as f64 * step;
            Rectangle::new(
                [(0.0, v), (1.0, v + step)],
                viridis((k as f64 + 0.5) / n as f64).filled(),
            )
        }))
        .map_err(err)?;
        Ok(())
    }
}

/// (e) Draws a Morlet scalogram of u/(Omega l) as produced by
/// [`morlet_scalogram`](crate::signal::wavelet::morlet_scalogram): time t0 + k dt on x,
/// `frequency / excitation_hz` on y (cells reach halfway to the neighbouring analysis
/// frequencies), log10 |W| as colour over `opts.decades` decades below the maximum, with a
/// colour bar. Each cell shows the mean |W| over the time samples it covers.
///
/// Errors: unsupported extension or size, `excitation_hz` not positive, a magnitude vector
/// of the wrong length, no positive finite magnitude, drawing or writing failures; each
/// names `out`.
pub fn scalogram(
    s: &Scalogram,
    excitation_hz: f64,
    opts: &ScalogramOptions,
    out: &Path,
    fig: &FigureOptions,
) -> Result<(), ReportError> {
    check_output(out, fig)?;
    let invalid = |what: String| ReportError::InvalidData {
        path: out.to_path_buf(),
        what,
    };
    if !(excitation_hz.is_finite() && excitation_hz > 0.0) {
        return Err(invalid(format!(
            "excitation frequency {excitation_hz} Hz: expected > 0"
        )));
    }
    if !(opts.decades.is_finite() && opts.decades > 0.0) {
        return Err(invalid(format!(
            "colour range of {} decades: expected > 0",
            opts.decades
        )));
    }
    if !(s.dt.is_finite() && s.dt > 0.0) {
        return Err(invalid(format!("scalogram dt = {} s: expected > 0", s.dt)));
    }
    let nf = s.frequencies.len();
    if s.magnitude.len() != nf * s.n_times {
        return Err(invalid(format!(
            "scalogram has {} magnitudes, expected {} frequencies x {} times = {}",
            s.magnitude.len(),
            nf,
            s.n_times,
            nf * s.n_times
        )));
    }
    let mut order: Vec<usize> = (0..nf)
        .filter(|&i| s.frequencies[i].is_finite() && s.frequencies[i] > 0.0)
        .collect();
    order.sort_by(|&a, &b| s.frequencies[a].total_cmp(&s.frequencies[b]));
    let hi = order
        .iter()
        .flat_map(|&i| s.row(i).iter())
        .filter(|v| v.is_finite() && **v > 0.0)
        .fold(f64::NEG_INFINITY, |m, v| m.max(v.log10()));
    if s.n_times == 0 || order.is_empty() || !hi.is_finite() {
        return Err(ReportError::NothingToPlot {
            path: out.to_path_buf(),
            what: format!(
                "no positive finite magnitude in the scalogram ({nf} frequencies x {} times)",
                s.n_times
            ),
        });
    }
    let ratio: Vec<f64> = order
        .iter()
        .map(|&i| s.frequencies[i] / excitation_hz)
        .collect();
    let edges = cell_edges(&ratio);
    let title = if opts.label.is_empty() {
        "Morlet scalogram of u / (Ω l)".to_string()
    } else {
        format!("Morlet scalogram of u / (Ω l): {}", opts.label)
    };
    let heat = Heat {
        s,
        order,
        edges,
        t0: opts.t0,
        lo: hi - opts.decades,
        hi,
        title,
    };
    render(out, fig, &heat)
}

/// Edges of cells centred on ascending `centres`: midpoints, the outer cells mirrored (a
/// single centre gets +-5 %).
fn cell_edges(centres: &[f64]) -> Vec<f64> {
    let n = centres.len();
    if n == 1 {
        return vec![0.95 * centres[0], 1.05 * centres[0]];
    }
    let mut e = Vec::with_capacity(n + 1);
    e.push((centres[0] - 0.5 * (centres[1] - centres[0])).max(0.0));
    for k in 0..n - 1 {
        e.push(0.5 * (centres[k] + centres[k + 1]));
    }
    e.push(centres[n - 1] + 0.5 * (centres[n - 1] - centres[n - 2]));
    e
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn viridis_ends() {
        assert_eq!(viridis(0.0), RGBColor(68, 1, 84));
        assert_eq!(viridis(1.0), RGBColor(253, 231, 37));
        assert_eq!(viridis(f64::NAN), RGBColor(68, 1, 84));
        assert_eq!(viridis(2.0), RGBColor(253, 231, 37));
    }

    #[test]
    fn cell_edges_are_midpoints() {
        assert_eq!(cell_edges(&[1.0, 2.0, 4.0]), vec![0.5, 1.5, 3.0, 5.0]);
        assert_eq!(cell_edges(&[2.0]), vec![1.9, 2.1]);
    }
}
