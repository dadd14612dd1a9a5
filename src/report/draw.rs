//! Drawing helpers shared by the figures: colours, source line styles, text sizes, the
//! legend strip, NaN-aware segments, envelope decimation and axis ranges.

use plotters::coord::Shift;
use plotters::prelude::*;

use super::data::Source;
use super::render::{err, FAMILY};

/// Colours for tests (Tableau 10): distinguishable, print- and colour-blind-friendly enough.
const PALETTE: [RGBColor; 10] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(255, 127, 14),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(127, 127, 127),
    RGBColor(188, 189, 34),
    RGBColor(23, 190, 207),
];

/// The i-th palette colour (cycles).
pub(crate) fn palette(i: usize) -> RGBColor {
    PALETTE[i % PALETTE.len()]
}

/// How a curve is drawn.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum LineKind {
    /// Solid line.
    Solid,
    /// Dashed line.
    Dashed,
    /// Markers on a thin line.
    Markers,
    /// A filled band (legend sample only).
    Band,
}

/// The line style of a source in frequency-domain figures.
pub(crate) fn source_kind(source: Source) -> LineKind {
    match source {
        Source::Simulation => LineKind::Solid,
        Source::Measurement => LineKind::Markers,
        Source::Twin => LineKind::Dashed,
    }
}

/// One legend entry.
#[derive(Debug, Clone)]
pub(crate) struct LegendEntry {
    pub label: String,
    pub color: RGBColor,
    pub kind: LineKind,
}

/// Text sizes scaled with the figure.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Fonts {
    pub title: f64,
    pub caption: f64,
    pub label: f64,
    pub desc: f64,
    pub legend: f64,
    /// Line width of curves, px.
    pub line: u32,
}

impl Fonts {
    /// Sizes for a figure of `width` x `height` px.
    pub fn for_size(width: u32, height: u32) -> Fonts {
        let s = (f64::from(width.min(height)) / 1000.0).clamp(0.3, 4.0);
        let size = |base: f64| (base * s).max(9.0);
        Fonts {
            title: size(30.0),
            caption: size(24.0),
            label: size(19.0),
            desc: size(22.0),
            legend: size(20.0),
            line: ((2.0 * s).round() as u32).max(1),
        }
    }

    /// Sizes for a drawing area.
    pub fn for_area<DB: DrawingBackend>(area: &DrawingArea<DB, Shift>) -> Fonts {
        let (w, h) = area.dim_in_pixel();
        Fonts::for_size(w, h)
    }
}

/// A text style in the embedded family.
pub(crate) fn text(size: f64) -> TextStyle<'static> {
    (FAMILY, size).into_font().color(&BLACK)
}

/// Draws a figure title centred at the top of `area` and returns the area below it.
pub(crate) fn title<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    title: &str,
    fonts: &Fonts,
) -> Result<DrawingArea<DB, Shift>, String> {
    let top = (fonts.title * 0.4) as u32;
    area.margin(top, 0, 0, 0)
        .titled(title, text(fonts.title))
        .map_err(err)
}

/// Lays out legend entries in rows; returns the rows (entry indices) for a strip `width` px
/// wide.
fn legend_rows<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    entries: &[LegendEntry],
    width: u32,
    fonts: &Fonts,
) -> Vec<Vec<usize>> {
    let style = text(fonts.legend);
    let sample = (fonts.legend * 2.5) as u32;
    let gap = (fonts.legend * 1.5) as u32;
    let mut rows: Vec<Vec<usize>> = Vec::new();
    let mut used = 0u32;
    for (i, e) in entries.iter().enumerate() {
        let tw = area
            .estimate_text_size(&e.label, &style)
            .map_or(e.label.len() as u32 * fonts.legend as u32 / 2, |(w, _)| w);
        let w = sample + gap / 3 + tw + gap;
        match rows.last_mut() {
            Some(row) if used + w <= width => {
                row.push(i);
                used += w;
            }
            _ => {
                rows.push(vec![i]);
                used = w;
            }
        }
    }
    rows
}

/// Height, px, of the legend strip `entries` need under an area of `area`'s width.
pub(crate) fn legend_height<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    entries: &[LegendEntry],
    fonts: &Fonts,
) -> u32 {
    if entries.is_empty() {
        return 0;
    }
    let (w, _) = area.dim_in_pixel();
    let rows = legend_rows(area, entries, w.saturating_sub(40), fonts).len() as u32;
    rows * (fonts.legend * 1.6) as u32 + (fonts.legend * 0.8) as u32
}

/// Splits `area` into (panels, legend strip) with room for `entries`.
pub(crate) fn split_legend<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    entries: &[LegendEntry],
    fonts: &Fonts,
) -> (DrawingArea<DB, Shift>, DrawingArea<DB, Shift>) {
    let (_, h) = area.dim_in_pixel();
    let lh = legend_height(area, entries, fonts).min(h / 2);
    area.split_vertically(h - lh)
}

/// Draws the legend entries in rows, centred in `area`.
pub(crate) fn draw_legend<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    entries: &[LegendEntry],
    fonts: &Fonts,
) -> Result<(), String> {
    if entries.is_empty() {
        return Ok(());
    }
    let (w, _) = area.dim_in_pixel();
    let style = text(fonts.legend);
    let sample = (fonts.legend * 2.5) as i32;
    let gap = (fonts.legend * 1.5) as i32;
    let row_h = (fonts.legend * 1.6) as i32;
    let rows = legend_rows(area, entries, w.saturating_sub(40), fonts);
    for (r, row) in rows.iter().enumerate() {
        let widths: Vec<i32> = row
            .iter()
            .map(|&i| {
                let tw = area
                    .estimate_text_size(&entries[i].label, &style)
                    .map_or(0, |(w, _)| w as i32);
                sample + gap / 3 + tw
            })
            .collect();
        let total: i32 = widths.iter().sum::<i32>() + gap * (row.len() as i32 - 1);
        let mut x = (w as i32 - total).max(0) / 2;
        let y = (fonts.legend * 0.4) as i32 + r as i32 * row_h + row_h / 2;
        for (k, &i) in row.iter().enumerate() {
            let e = &entries[i];
            legend_sample(area, e, (x, y), sample, fonts)?;
            area.draw(&Text::new(
                e.label.clone(),
                (x + sample + gap / 3, y - (fonts.legend * 0.45) as i32),
                style.clone(),
            ))
            .map_err(err)?;
            x += widths[k] + gap;
        }
    }
    Ok(())
}

fn legend_sample<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    e: &LegendEntry,
    (x, y): (i32, i32),
    len: i32,
    fonts: &Fonts,
) -> Result<(), String> {
    let stroke = e.color.stroke_width(fonts.line + 1);
    match e.kind {
        LineKind::Solid => area
            .draw(&PathElement::new(vec![(x, y), (x + len, y)], stroke))
            .map_err(err),
        LineKind::Dashed => {
            let dash = (len / 5).max(2);
            let mut x0 = x;
            while x0 < x + len {
                let x1 = (x0 + dash).min(x + len);
                area.draw(&PathElement::new(vec![(x0, y), (x1, y)], stroke))
                    .map_err(err)?;
                x0 += 2 * dash - dash / 3;
            }
            Ok(())
        }
        LineKind::Markers => {
            area.draw(&PathElement::new(
                vec![(x, y), (x + len, y)],
                e.color.stroke_width(1),
            ))
            .map_err(err)?;
            area.draw(&Circle::new(
                (x + len / 2, y),
                marker_radius(fonts),
                e.color.filled(),
            ))
            .map_err(err)
        }
        LineKind::Band => {
            let h = (fonts.legend * 0.35) as i32;
            area.draw(&Rectangle::new(
                [(x, y - h), (x + len, y + h)],
                e.color.mix(0.2).filled(),
            ))
            .map_err(err)
        }
    }
}

/// Radius of data markers, px.
pub(crate) fn marker_radius(fonts: &Fonts) -> i32 {
    (fonts.line as i32 + 2).max(3)
}

/// Splits paired samples into runs of finite points; a non-finite x or y ends a run.
pub(crate) fn segments(x: &[f64], y: &[f64]) -> Vec<Vec<(f64, f64)>> {
    let mut out = Vec::new();
    let mut cur: Vec<(f64, f64)> = Vec::new();
    for (&a, &b) in x.iter().zip(y) {
        if a.is_finite() && b.is_finite() {
            cur.push((a, b));
        } else if !cur.is_empty() {
            out.push(std::mem::take(&mut cur));
        }
    }
    if !cur.is_empty() {
        out.push(cur);
    }
    out
}

/// Reduces a long run of points (x increasing) to at most about `2 * bins` points keeping
/// each bin's minimum and maximum in time order, so the drawn envelope of a dense signal is
/// unchanged while the file stays small.
pub(crate) fn decimate(points: &[(f64, f64)], bins: usize) -> Vec<(f64, f64)> {
    let bins = bins.max(1);
    if points.len() <= 2 * bins {
        return points.to_vec();
    }
    let per = points.len().div_ceil(bins);
    let mut out = Vec::with_capacity(2 * bins + 1);
    for chunk in points.chunks(per) {
        let (mut lo, mut hi) = (0, 0);
        for (i, p) in chunk.iter().enumerate() {
            if p.1 < chunk[lo].1 {
                lo = i;
            }
            if p.1 > chunk[hi].1 {
                hi = i;
            }
        }
        let (a, b) = if lo <= hi { (lo, hi) } else { (hi, lo) };
        out.push(chunk[a]);
        if b != a {
            out.push(chunk[b]);
        }
    }
    out
}

/// `(min, max)` of the finite values, or `None` if there is none.
pub(crate) fn finite_range<'a>(values: impl IntoIterator<Item = &'a f64>) -> Option<(f64, f64)> {
    values
        .into_iter()
        .filter(|v| v.is_finite())
        .fold(None, |acc, &v| match acc {
            None => Some((v, v)),
            Some((lo, hi)) => Some((lo.min(v), hi.max(v))),
        })
}

/// A linear axis range around `[lo, hi]` with `pad` (fraction of the span) on both sides; a
/// degenerate range is widened so the axis has a span.
pub(crate) fn padded(lo: f64, hi: f64, pad: f64) -> (f64, f64) {
    let span = hi - lo;
    if span > 0.0 {
        (lo - pad * span, hi + pad * span)
    } else {
        let w = if lo == 0.0 { 1.0 } else { 0.05 * lo.abs() };
        (lo - w, hi + w)
    }
}

/// A log axis range around the positive `[lo, hi]`, widened to whole half-decades.
pub(crate) fn log_range(lo: f64, hi: f64) -> (f64, f64) {
    let a = (lo.log10() * 2.0).floor() / 2.0;
    let mut b = (hi.log10() * 2.0).ceil() / 2.0;
    if b <= a {
        b = a + 1.0;
    }
    (10f64.powf(a), 10f64.powf(b))
}

/// Draws runs of points with a line kind.
pub(crate) fn draw_runs<DB, CT>(
    chart: &mut ChartContext<'_, DB, CT>,
    runs: &[Vec<(f64, f64)>],
    color: RGBColor,
    kind: LineKind,
    width: u32,
    fonts: &Fonts,
) -> Result<(), String>
where
    DB: DrawingBackend,
    CT: CoordTranslate<From = (f64, f64)>,
{
    for run in runs {
        match kind {
            LineKind::Solid | LineKind::Band => {
                chart
                    .draw_series(LineSeries::new(
                        run.iter().copied(),
                        color.stroke_width(width),
                    ))
                    .map_err(err)?;
            }
            LineKind::Dashed => {
                let dash = (fonts.label * 0.6) as i32;
                chart
                    .draw_series(DashedLineSeries::new(
                        run.iter().copied(),
                        dash,
                        dash * 2 / 3,
                        color.stroke_width(width),
                    ))
                    .map_err(err)?;
            }
            LineKind::Markers => {
                chart
                    .draw_series(LineSeries::new(run.iter().copied(), color.stroke_width(1)))
                    .map_err(err)?;
                let r = marker_radius(fonts);
                chart
                    .draw_series(run.iter().map(|&p| Circle::new(p, r, color.filled())))
                    .map_err(err)?;
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn segments_break_at_non_finite_values() {
        let x = [0.0, 1.0, 2.0, 3.0, f64::NAN, 5.0];
        let y = [1.0, f64::NAN, 2.0, 3.0, 4.0, f64::INFINITY];
        let s = segments(&x, &y);
        assert_eq!(s, vec![vec![(0.0, 1.0)], vec![(2.0, 2.0), (3.0, 3.0)]]);
    }

    #[test]
    fn decimate_keeps_extremes_in_order() {
        let pts: Vec<(f64, f64)> = (0..1000)
            .map(|i| (i as f64, (i as f64 * 0.37).sin()))
            .collect();
        let d = decimate(&pts, 50);
        assert!(d.len() <= 100 + 2, "{}", d.len());
        assert!(d.windows(2).all(|w| w[0].0 < w[1].0));
        let max_all = pts.iter().map(|p| p.1).fold(f64::MIN, f64::max);
        let max_d = d.iter().map(|p| p.1).fold(f64::MIN, f64::max);
        assert_eq!(max_all, max_d);
    }

    #[test]
    fn ranges() {
        assert_eq!(finite_range(&[f64::NAN, 2.0, -1.0]), Some((-1.0, 2.0)));
        assert_eq!(finite_range(&[f64::NAN]), None);
        assert_eq!(padded(0.0, 10.0, 0.1), (-1.0, 11.0));
        let (a, b) = padded(2.0, 2.0, 0.1);
        assert!(a < 2.0 && b > 2.0);
        let (a, b) = log_range(0.003, 0.2);
        assert!(a <= 0.003 && b >= 0.2);
    }
}
