//! A generic x-y line panel (axes, grid, bands, curves) used by the line figures.

use plotters::coord::Shift;
use plotters::prelude::*;

use crate::report::draw::{draw_runs, text, Fonts, LineKind};
use crate::report::render::err;

/// One curve: runs of finite points drawn with one colour and line kind.
pub(crate) struct Series {
    pub runs: Vec<Vec<(f64, f64)>>,
    pub color: RGBColor,
    pub kind: LineKind,
    /// Line width, px.
    pub width: u32,
}

/// A translucent filled region (closed polygons).
pub(crate) struct Band {
    pub polygons: Vec<Vec<(f64, f64)>>,
    pub color: RGBColor,
}

/// A linear x-y panel.
pub(crate) struct LinePanel {
    pub caption: String,
    pub x_desc: String,
    pub y_desc: String,
    pub x: (f64, f64),
    pub y: (f64, f64),
    pub bands: Vec<Band>,
    pub series: Vec<Series>,
}

/// A number for a log axis tick: plain in [1e-3, 1e5), else `1e-6` style.
pub(crate) fn tick(v: f64) -> String {
    let a = v.abs();
    if a == 0.0 || (1e-3..1e5).contains(&a) {
        let s = format!("{v:.4}");
        let s = s.trim_end_matches('0').trim_end_matches('.');
        s.to_string()
    } else {
        // Three significant digits, trailing zeros of the mantissa dropped: 1.28e5, 1e-6.
        let e = format!("{v:.2e}");
        match e.split_once('e') {
            Some((m, x)) => format!("{}e{x}", m.trim_end_matches('0').trim_end_matches('.')),
            None => e,
        }
    }
}

/// A log-axis tick label: only mantissas 1, 2 and 5 are labelled (plotters puts a key point
/// at every integer mantissa, whose labels would overlap), and only powers of ten when the
/// axis spans more than three decades.
pub(crate) fn log_tick(v: f64, decades: f64) -> String {
    if !(v.is_finite() && v > 0.0) {
        return String::new();
    }
    let m = v / 10f64.powf(v.log10().floor());
    let near = |k: f64| (m - k).abs() < 1e-6 * k || (m - 10.0 * k).abs() < 1e-5 * k;
    let keep = if decades > 3.0 {
        near(1.0)
    } else {
        near(1.0) || near(2.0) || near(5.0)
    };
    if keep {
        tick(v)
    } else {
        String::new()
    }
}

/// Axis label area sizes and margin, px, for `fonts`.
pub(crate) fn axis_areas(fonts: &Fonts) -> (u32, u32, u32) {
    (
        (fonts.label * 0.8) as u32,
        (fonts.label * 3.2) as u32,
        (fonts.label * 5.0) as u32,
    )
}

/// Light grid styles.
pub(crate) fn grid_styles() -> (ShapeStyle, ShapeStyle) {
    (
        RGBColor(215, 215, 215).stroke_width(1),
        RGBColor(240, 240, 240).stroke_width(1),
    )
}

impl LinePanel {
    /// Draws the panel into `area`.
    pub fn draw<DB: DrawingBackend>(
        &self,
        area: &DrawingArea<DB, Shift>,
        fonts: &Fonts,
    ) -> Result<(), String> {
        let (margin, x_area, y_area) = axis_areas(fonts);
        let mut chart = ChartBuilder::on(area)
            .caption(&self.caption, text(fonts.caption))
            .margin(margin)
            .x_label_area_size(x_area)
            .y_label_area_size(y_area)
            .build_cartesian_2d(self.x.0..self.x.1, self.y.0..self.y.1)
            .map_err(err)?;
        let (bold, light) = grid_styles();
        chart
            .configure_mesh()
            .x_desc(self.x_desc.as_str())
            .y_desc(self.y_desc.as_str())
            .label_style(text(fonts.label))
            .axis_desc_style(text(fonts.desc))
            .bold_line_style(bold)
            .light_line_style(light)
            .x_labels(8)
            .y_labels(7)
            .draw()
            .map_err(err)?;
        for band in &self.bands {
            chart
                .draw_series(
                    band.polygons
                        .iter()
                        .map(|p| Polygon::new(p.clone(), band.color.mix(0.15).filled())),
                )
                .map_err(err)?;
        }
        for s in &self.series {
            draw_runs(&mut chart, &s.runs, s.color, s.kind, s.width, fonts)?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ticks_read_well() {
        assert_eq!(tick(1000.0), "1000");
        assert_eq!(tick(0.25), "0.25");
        assert_eq!(tick(1e-6), "1e-6");
        assert_eq!(tick(128000.0), "1.28e5");
        assert_eq!(log_tick(2000.0, 2.0), "2000");
        assert_eq!(log_tick(7000.0, 2.0), "");
        assert_eq!(log_tick(2000.0, 4.0), "");
        assert_eq!(log_tick(0.01, 4.0), "0.01");
        assert_eq!(log_tick(20.0, 2.0), "20");
        assert_eq!(log_tick(0.5, 2.0), "0.5");
        assert_eq!(log_tick(20.0, 4.0), "");
    }
}
