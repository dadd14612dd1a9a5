//! The figures of a diagnosis ([`Diagnosis`], `rigtwin diagnose`), each written as PNG and SVG
//! and left out when the diagnosis holds nothing for it:
//! - `mismatch-map` (and `mismatch-map-after` once effects were accepted): where the model
//!   misses the recording, one test x Omega/omega_2 map per channel coloured by the step's
//!   largest feature score;
//! - `evidence-linear`: natural frequency and damping ratio of 1FU and 1FL against the tip
//!   amplitude at resonance, per test (the clamp friction's signature);
//! - `evidence-clearance`: the clearance bracket per test against the session order or the
//!   accumulated normal contact impulse (wear): with the wear stage's clearances refined by model runs
//!   (measured) and the fitted wear's clearance (model);
//! - `evidence-clearance-fit`: the clearance offset's fit, the error of every model run
//!   against the offset to the model's clearance, the train tests together and each alone;
//! - `evidence-sensors`: measured over model RMS per motion channel on the impact-free steps
//!   (a sensitivity error is flat in frequency);
//! - `evidence-tilt`: the tilt's fit, the train tests' error against the face's angle through
//!   the face as given, and the validation tests' contact score with the tilt and with the
//!   clearance offset;
//! - `evidence-discretisation`: the score per step of the tests with contact, of the twin as
//!   given and of each refinement of its modal basis or step tried, and their contact
//!   fraction against the measured one (a coarse twin keeps its impacts closed too long);
//! - `before-after`: the response of the validation tests, measured and the model before and
//!   after the accepted effects.

use std::path::{Path, PathBuf};

use plotters::coord::ranged1d::ValueFormatter;
use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::prelude::*;

use super::panel::{axis_areas, grid_styles, log_tick, Band, Series};
use crate::diagnose::outcome::{
    BandSpread, BandStep, Diagnosis, DiscretisedTwin, EffectResult, Regime, StepScores,
};
use crate::diagnose::TestClearance;
use crate::report::draw::{
    draw_legend, draw_runs, finite_range, marker_radius, padded, palette, segments, split_legend,
    text, title, Fonts, LegendEntry, LineKind,
};
use crate::report::render::{err, render, Figure, Format};
use crate::report::{FigureOptions, ReportError};
use crate::rig::channels::{LOWER_MID, LOWER_TIP, UPPER_MID, UPPER_TIP, VIBROMETER};
use crate::signal::features::CONTACT_CHANNEL;
use crate::twin::FeatureComparison;

/// The motion channels, in the order of the panels.
const MOTION: [&str; 5] = [VIBROMETER, UPPER_TIP, UPPER_MID, LOWER_TIP, LOWER_MID];

/// Label of the excitation frequency axis.
const OMEGA_DESC: &str = "Ω / ω₂ (-)";

/// Grey of the style entries of legends and of reference lines.
const GREY: RGBColor = RGBColor(90, 90, 90);

/// Cells of steps compared on no feature of the channel.
const NOT_COMPARED: RGBColor = RGBColor(150, 150, 150);

/// Draws the figures of diagnosis `d` into `dir` (created when needed), PNG and SVG each;
/// returns the files written. A figure the diagnosis holds no data for is left out, so an
/// empty diagnosis writes nothing.
///
/// Errors: drawing or writing failures, naming the file.
pub fn draw_diagnosis(d: &Diagnosis, dir: &Path) -> Result<Vec<PathBuf>, ReportError> {
    let mut written = Vec::new();
    let scale = ScoreScale::of(d);
    if let Some(f) = mismatch_map(&d.scores_before, &scale, "model as given".into()) {
        write(dir, "mismatch-map", &f, &mut written)?;
    }
    let accepted: Vec<&str> = (d.effects.iter().filter(|e| e.accepted))
        .map(|e| e.effect.as_str())
        .collect();
    let with = match accepted.is_empty() {
        true => "with the effects".to_string(),
        false => format!("with {}", accepted.join(", ")),
    };
    if let Some(f) = mismatch_map(&d.scores_after, &scale, with.clone()) {
        write(dir, "mismatch-map-after", &f, &mut written)?;
    }
    if let Some(f) = evidence_linear(d) {
        write(dir, "evidence-linear", &f, &mut written)?;
    }
    if let Some(f) = evidence_clearance(d) {
        write(dir, "evidence-clearance", &f, &mut written)?;
    }
    if let Some(f) = evidence_clearance_fit(d) {
        write(dir, "evidence-clearance-fit", &f, &mut written)?;
    }
    if let Some(f) = evidence_sensors(d) {
        write(dir, "evidence-sensors", &f, &mut written)?;
    }
    if let Some(f) = evidence_band(d) {
        write(dir, "evidence-band", &f, &mut written)?;
    }
    if let Some(f) = evidence_tilt(d) {
        write(dir, "evidence-tilt", &f, &mut written)?;
    }
    if let Some(f) = evidence_discretisation(d) {
        write(dir, "evidence-discretisation", &f, &mut written)?;
    }
    if let Some(f) = before_after(d, &with) {
        write(dir, "before-after", &f, &mut written)?;
    }
    Ok(written)
}

/// Writes `fig` as `dir/name.png` and `dir/name.svg`.
fn write<F: Figure>(
    dir: &Path,
    name: &str,
    fig: &F,
    written: &mut Vec<PathBuf>,
) -> Result<(), ReportError> {
    for ext in ["png", "svg"] {
        let p = dir.join(format!("{name}.{ext}"));
        render(&p, &FigureOptions::default(), fig)?;
        written.push(p);
    }
    Ok(())
}

/// The distinct names of `names`, in the order first seen.
fn first_seen<'a>(names: impl Iterator<Item = &'a str>) -> Vec<&'a str> {
    let mut out: Vec<&str> = Vec::new();
    for n in names {
        if !out.contains(&n) {
            out.push(n);
        }
    }
    out
}

/// Test names by test index, in session order, from `(index, name)` pairs.
fn session_tests<'a>(tests: impl Iterator<Item = (usize, &'a str)>) -> Vec<(usize, String)> {
    let mut out: Vec<(usize, String)> = Vec::new();
    for (i, name) in tests {
        if !out.iter().any(|(j, _)| *j == i) {
            out.push((i, name.to_string()));
        }
    }
    out.sort_by_key(|(i, _)| *i);
    out
}

/// A legend entry.
fn entry(label: impl Into<String>, color: RGBColor, kind: LineKind) -> LegendEntry {
    LegendEntry {
        label: label.into(),
        color,
        kind,
    }
}

/// The name of integer tick `v` among `names` (empty between integers and outside).
fn name_at(names: &[String], v: f64) -> String {
    let k = v.round();
    match names.get(k as usize) {
        Some(n) if (v - k).abs() < 1e-6 && k >= 0.0 => n.clone(),
        _ => String::new(),
    }
}

// ----- Mismatch map -----

/// The colour scale of the scores: white up to 1 (or the threshold, if lower), pale reds up
/// to the threshold, then red to dark red on a log scale up to the largest score (ColorBrewer
/// "Reds"). The step in colour at the threshold marks it.
struct ScoreScale {
    white: f64,
    threshold: f64,
    top: f64,
}

impl ScoreScale {
    fn of(d: &Diagnosis) -> ScoreScale {
        let threshold = if d.threshold.is_finite() && d.threshold > 0.0 {
            d.threshold
        } else {
            1.0
        };
        let scores = (d.scores_before.iter().chain(&d.scores_after))
            .flat_map(|s| s.features.iter().map(|f| &f.score));
        let max = finite_range(scores).map_or(0.0, |(_, hi)| hi);
        ScoreScale {
            white: threshold.min(1.0),
            threshold,
            top: max.max(2.0 * threshold),
        }
    }

    fn color(&self, s: f64) -> RGBColor {
        let lerp = |a: (u8, u8, u8), b: (u8, u8, u8), f: f64| {
            let f = if f.is_finite() {
                f.clamp(0.0, 1.0)
            } else {
                1.0
            };
            let m = |a: u8, b: u8| (f64::from(a) + f * (f64::from(b) - f64::from(a))).round() as u8;
            RGBColor(m(a.0, b.0), m(a.1, b.1), m(a.2, b.2))
        };
        let frac = |lo: f64, hi: f64| (s / lo).ln() / (hi / lo).ln();
        if s <= self.white {
            WHITE
        } else if s <= self.threshold {
            lerp(
                (255, 245, 240),
                (252, 187, 161),
                frac(self.white, self.threshold),
            )
        } else {
            lerp((251, 106, 74), (103, 0, 13), frac(self.threshold, self.top))
        }
    }
}

/// One cell of a map: a step of a test.
struct Cell {
    /// Omega / omega_2 edges.
    x: (f64, f64),
    /// Row from the top (the test's place in the session).
    row: usize,
    /// The channel's largest score, None: not compared.
    score: Option<f64>,
    /// Contact in the step.
    impacts: bool,
}

struct MismatchMap<'a> {
    title: String,
    tests: Vec<String>,
    x: (f64, f64),
    /// (channel, cells).
    panels: Vec<(String, Vec<Cell>)>,
    scale: &'a ScoreScale,
    legend: Vec<LegendEntry>,
}

/// The map of `steps` (None without a compared channel).
fn mismatch_map<'a>(
    steps: &[StepScores],
    scale: &'a ScoreScale,
    model: String,
) -> Option<MismatchMap<'a>> {
    let steps: Vec<&StepScores> = steps.iter().filter(|s| s.omega_ratio.is_finite()).collect();
    // The known channels in panel order, then any other the comparison holds.
    let mut channels: Vec<&str> = Vec::new();
    let named = steps
        .iter()
        .flat_map(|s| s.features.iter().map(|f| f.channel.as_str()));
    for c in MOTION.into_iter().chain([CONTACT_CHANNEL]).chain(named) {
        if !channels.contains(&c) && steps.iter().any(|s| s.channel_score(c).is_some()) {
            channels.push(c);
        }
    }
    if channels.is_empty() {
        return None;
    }
    let tests = session_tests(steps.iter().map(|s| (s.test_index, s.test.as_str())));
    // Cells reach halfway to the test's neighbouring steps, at most one typical spacing.
    let grids: Vec<Vec<f64>> = (tests.iter())
        .map(|(i, _)| {
            let mut w: Vec<f64> = (steps.iter().filter(|s| s.test_index == *i))
                .map(|s| s.omega_ratio)
                .collect();
            w.sort_by(f64::total_cmp);
            w.dedup();
            w
        })
        .collect();
    let mut gaps: Vec<f64> = grids
        .iter()
        .flat_map(|w| w.windows(2).map(|p| p[1] - p[0]))
        .collect();
    gaps.sort_by(f64::total_cmp);
    let typical = gaps.get(gaps.len() / 2).copied().unwrap_or(0.01);
    let edges = |row: usize, w: f64| {
        let g = &grids[row];
        let k = g.partition_point(|&v| v < w);
        let left = k.checked_sub(1).map_or(typical, |j| 0.5 * (w - g[j]));
        let right = g.get(k + 1).map_or(typical, |v| 0.5 * (v - w));
        (w - left.min(typical), w + right.min(typical))
    };
    let panels: Vec<(String, Vec<Cell>)> = (channels.iter())
        .map(|c| {
            let cells = (steps.iter())
                .map(|s| {
                    let row = tests
                        .iter()
                        .position(|(i, _)| *i == s.test_index)
                        .unwrap_or(0);
                    Cell {
                        x: edges(row, s.omega_ratio),
                        row,
                        score: s.channel_score(c).filter(|v| !v.is_nan()),
                        impacts: s.regime == Regime::Impacts,
                    }
                })
                .collect();
            (c.to_string(), cells)
        })
        .collect();
    let x = finite_range(panels[0].1.iter().flat_map(|c| [&c.x.0, &c.x.1]))?;
    Some(MismatchMap {
        title: format!("Mismatch map, {model}: largest feature score per step and channel"),
        tests: tests.into_iter().map(|(_, n)| n).collect(),
        x,
        panels,
        scale,
        legend: vec![
            entry(
                format!("threshold = {} (colour bar)", sig(scale.threshold)),
                BLACK,
                LineKind::Solid,
            ),
            entry(
                "dot: contact in the step",
                RGBColor(40, 40, 40),
                LineKind::Markers,
            ),
            entry("not compared", NOT_COMPARED, LineKind::Band),
        ],
    })
}

impl MismatchMap<'_> {
    fn draw_panel<DB: DrawingBackend>(
        &self,
        area: &DrawingArea<DB, Shift>,
        (channel, cells): &(String, Vec<Cell>),
        fonts: &Fonts,
    ) -> Result<(), String> {
        let (margin, x_area, _) = axis_areas(fonts);
        let style = text(fonts.label);
        let names_w = (self.tests.iter())
            .filter_map(|t| area.estimate_text_size(t, &style).ok())
            .map(|(w, _)| w)
            .max()
            .unwrap_or(0);
        let n = self.tests.len();
        // At most as many test names as fit the panel's height.
        let fit = (area.dim_in_pixel().1 as f64 / (1.4 * fonts.label)) as usize;
        let mut chart = ChartBuilder::on(area)
            .caption(channel, text(fonts.caption))
            .margin(margin)
            .x_label_area_size(x_area)
            .y_label_area_size(names_w + (fonts.label * 1.5) as u32)
            .build_cartesian_2d(self.x.0..self.x.1, -0.5..n as f64 - 0.5)
            .map_err(err)?;
        // Row 0 (the first test) on top.
        let row_y = |row: usize| (n - 1 - row) as f64;
        let names: Vec<String> = self.tests.iter().rev().cloned().collect();
        let label = |v: &f64| name_at(&names, *v);
        chart
            .configure_mesh()
            .disable_mesh()
            .x_desc(OMEGA_DESC)
            .label_style(text(fonts.label))
            .axis_desc_style(text(fonts.desc))
            .x_labels(6)
            .y_labels((n + 1).min(fit.max(2)))
            .y_label_formatter(&label)
            .draw()
            .map_err(err)?;
        let rect = |c: &Cell| [(c.x.0, row_y(c.row) - 0.5), (c.x.1, row_y(c.row) + 0.5)];
        chart
            .draw_series(cells.iter().map(|c| {
                let color = match c.score {
                    Some(s) => self.scale.color(s).filled(),
                    None => NOT_COMPARED.mix(0.2).filled(),
                };
                Rectangle::new(rect(c), color)
            }))
            .map_err(err)?;
        let outline = RGBColor(200, 200, 200).stroke_width(1);
        chart
            .draw_series(cells.iter().map(|c| Rectangle::new(rect(c), outline)))
            .map_err(err)?;
        let r = (marker_radius(fonts) - 1).max(2);
        let dot = RGBColor(40, 40, 40).filled();
        chart
            .draw_series(
                (cells.iter().filter(|c| c.impacts))
                    .map(|c| Circle::new((0.5 * (c.x.0 + c.x.1), row_y(c.row)), r, dot)),
            )
            .map_err(err)?;
        Ok(())
    }

    /// The colour bar, a log axis of the score.
    fn draw_bar<DB: DrawingBackend>(
        &self,
        area: &DrawingArea<DB, Shift>,
        fonts: &Fonts,
    ) -> Result<(), String> {
        let (margin, x_area, _) = axis_areas(fonts);
        let (lo, hi) = (self.scale.white / 3.0, self.scale.top);
        let mut cb = ChartBuilder::on(area)
            .margin(margin)
            .margin_left(0)
            .x_label_area_size(x_area)
            .y_label_area_size((fonts.label * 5.5) as u32)
            .build_cartesian_2d(0.0..1.0, (lo..hi).log_scale())
            .map_err(err)?;
        let ticks = |v: &f64| log_tick(*v, (hi / lo).log10());
        cb.configure_mesh()
            .disable_mesh()
            .disable_x_axis()
            .y_desc("largest score (-)")
            .label_style(text(fonts.label))
            .axis_desc_style(text(fonts.desc))
            .y_label_formatter(&ticks)
            .draw()
            .map_err(err)?;
        let n = 160;
        let at = |k: f64| lo * (hi / lo).powf(k / n as f64);
        cb.draw_series((0..n).map(|k| {
            let (a, b) = (at(k as f64), at(k as f64 + 1.0));
            let color = self.scale.color((a * b).sqrt());
            Rectangle::new([(0.0, a), (1.0, b)], color.filled())
        }))
        .map_err(err)?;
        let t = self.scale.threshold;
        cb.draw_series([
            PathElement::new(vec![(0.0, t), (1.0, t)], BLACK.stroke_width(fonts.line + 1)),
            PathElement::new(
                vec![(0.0, lo), (1.0, lo), (1.0, hi), (0.0, hi), (0.0, lo)],
                GREY.stroke_width(1),
            ),
        ])
        .map_err(err)?;
        Ok(())
    }
}

/// `v` with three significant digits, plain where that reads well.
fn sig(v: f64) -> String {
    let a = v.abs();
    if a == 0.0 || !a.is_finite() {
        format!("{v}")
    } else if (1e-3..1e4).contains(&a) {
        let decimals = (2.0 - a.log10().floor()).max(0.0) as usize;
        let s = format!("{v:.decimals$}");
        match s.contains('.') {
            true => s.trim_end_matches('0').trim_end_matches('.').to_string(),
            false => s,
        }
    } else {
        format!("{v:.2e}")
    }
}

impl Figure for MismatchMap<'_> {
    fn draw<DB: DrawingBackend>(
        &self,
        root: &DrawingArea<DB, Shift>,
        _format: Format,
    ) -> Result<(), String> {
        root.fill(&WHITE).map_err(err)?;
        let fonts = Fonts::for_area(root);
        let body = title(root, &self.title, &fonts)?;
        let (main, strip) = split_legend(&body, &self.legend, &fonts);
        let (w, _) = main.dim_in_pixel();
        let (maps, bar) = main.split_horizontally(w.saturating_sub((fonts.label * 9.0) as u32));
        let cols = self.panels.len().min(3);
        let rows = self.panels.len().div_ceil(cols);
        for (p, area) in self.panels.iter().zip(maps.split_evenly((rows, cols))) {
            self.draw_panel(&area, p, &fonts)?;
        }
        self.draw_bar(&bar, &fonts)?;
        draw_legend(&strip, &self.legend, &fonts)
    }
}

// ----- Line panels with error bars -----

/// Vertical error bars `(x, low, high)` in one colour, with caps or without (a range, where a
/// zero-length bar shows nothing).
struct Bars {
    points: Vec<(f64, f64, f64)>,
    color: RGBColor,
    caps: bool,
}

/// An x-y panel: bands, curves and error bars; `x_names` names the integer x ticks (a
/// categorical axis) when not empty; `log_y`: a logarithmic y axis (`y` then positive).
struct Panel {
    caption: String,
    x_desc: String,
    y_desc: String,
    x: (f64, f64),
    y: (f64, f64),
    x_names: Vec<String>,
    log_y: bool,
    bands: Vec<Band>,
    series: Vec<Series>,
    bars: Vec<Bars>,
}

impl Panel {
    /// A panel over the finite values of `xs` and `ys` (None when there is none).
    fn over<'a>(
        caption: String,
        (x_desc, y_desc): (&str, &str),
        xs: impl IntoIterator<Item = &'a f64>,
        ys: impl IntoIterator<Item = &'a f64>,
    ) -> Option<Panel> {
        let (x0, x1) = finite_range(xs)?;
        let (y0, y1) = finite_range(ys)?;
        Some(Panel {
            caption,
            x_desc: x_desc.into(),
            y_desc: y_desc.into(),
            x: padded(x0, x1, 0.06),
            y: padded(y0, y1, 0.08),
            x_names: Vec::new(),
            log_y: false,
            bands: Vec::new(),
            series: Vec::new(),
            bars: Vec::new(),
        })
    }

    /// A panel as [`Panel::over`] with a logarithmic y axis over the finite positive values of
    /// `ys`, padded by a fifth of the decades they span (a tenth of a decade at least).
    fn over_log_y<'a>(
        caption: String,
        desc: (&str, &str),
        xs: impl IntoIterator<Item = &'a f64>,
        ys: impl IntoIterator<Item = &'a f64>,
    ) -> Option<Panel> {
        let positive: Vec<f64> = (ys.into_iter().copied())
            .filter(|y| y.is_finite() && *y > 0.0)
            .collect();
        let (y0, y1) = finite_range(&positive)?;
        let pad = (0.2 * (y1 / y0).log10()).max(0.1);
        let xs: Vec<f64> = xs.into_iter().copied().collect();
        let mut p = Panel::over(caption, desc, &xs, &positive)?;
        p.y = (y0 / 10f64.powf(pad), y1 * 10f64.powf(pad));
        p.log_y = true;
        Some(p)
    }

    /// The y value at `share` (0: bottom, 1: top) of the panel's height, on its axis's scale.
    fn y_at(&self, share: f64) -> f64 {
        let (y0, y1) = self.y;
        match self.log_y {
            true => y0 * (y1 / y0).powf(share),
            false => y0 + share * (y1 - y0),
        }
    }

    fn draw<DB: DrawingBackend>(
        &self,
        area: &DrawingArea<DB, Shift>,
        fonts: &Fonts,
    ) -> Result<(), String> {
        let (margin, x_area, y_area) = axis_areas(fonts);
        let mut builder = ChartBuilder::on(area);
        builder
            .caption(&self.caption, text(fonts.caption))
            .margin(margin)
            .x_label_area_size(x_area)
            .y_label_area_size(y_area);
        let (x, (y0, y1)) = (self.x.0..self.x.1, self.y);
        if self.log_y {
            let keys = log_keys(y0, y1);
            let y = (y0..y1).log_scale().with_key_points(keys);
            let mut chart = builder.build_cartesian_2d(x, y).map_err(err)?;
            let ticks = |v: &f64| log_tick(*v, (y1 / y0).log10());
            self.draw_mesh(&mut chart, fonts, Some(&ticks))?;
            self.draw_content(&mut chart, fonts)
        } else {
            let mut chart = builder.build_cartesian_2d(x, y0..y1).map_err(err)?;
            self.draw_mesh(&mut chart, fonts, None)?;
            self.draw_content(&mut chart, fonts)
        }
    }

    /// The panel's axes and grid on `chart`, the y labels by `y_ticks` where given.
    fn draw_mesh<DB, Y>(
        &self,
        chart: &mut ChartContext<'_, DB, Cartesian2d<RangedCoordf64, Y>>,
        fonts: &Fonts,
        y_ticks: Option<&dyn Fn(&f64) -> String>,
    ) -> Result<(), String>
    where
        DB: DrawingBackend,
        Y: Ranged<ValueType = f64> + ValueFormatter<f64>,
    {
        let (bold, light) = grid_styles();
        let names = |v: &f64| name_at(&self.x_names, *v);
        let mut mesh = chart.configure_mesh();
        mesh.x_desc(self.x_desc.as_str())
            .y_desc(self.y_desc.as_str())
            .label_style(text(fonts.label))
            .axis_desc_style(text(fonts.desc))
            .bold_line_style(bold)
            .light_line_style(light)
            .x_labels(8)
            .y_labels(7);
        if !self.x_names.is_empty() {
            mesh.x_labels(self.x_names.len() + 1)
                .x_label_formatter(&names);
        }
        if let Some(ticks) = y_ticks {
            mesh.y_label_formatter(ticks);
        }
        mesh.draw().map_err(err)
    }

    /// The panel's bands, curves and error bars on `chart`.
    fn draw_content<DB, CT>(
        &self,
        chart: &mut ChartContext<'_, DB, CT>,
        fonts: &Fonts,
    ) -> Result<(), String>
    where
        DB: DrawingBackend,
        CT: CoordTranslate<From = (f64, f64)>,
    {
        for band in &self.bands {
            chart
                .draw_series(
                    (band.polygons.iter())
                        .map(|p| Polygon::new(p.clone(), band.color.mix(0.15).filled())),
                )
                .map_err(err)?;
        }
        for s in &self.series {
            draw_runs(chart, &s.runs, s.color, s.kind, s.width, fonts)?;
        }
        let cap = marker_radius(fonts) + 1;
        for b in &self.bars {
            let style = b.color.stroke_width(fonts.line);
            chart
                .draw_series(
                    (b.points.iter())
                        .map(|&(x, lo, hi)| PathElement::new(vec![(x, lo), (x, hi)], style)),
                )
                .map_err(err)?;
            if !b.caps {
                continue;
            }
            chart
                .draw_series(b.points.iter().flat_map(|&(x, lo, hi)| {
                    [lo, hi].map(|y| {
                        EmptyElement::at((x, y))
                            + PathElement::new(vec![(-cap, 0), (cap, 0)], style)
                    })
                }))
                .map_err(err)?;
        }
        Ok(())
    }
}

/// The key points of a log axis over `lo..hi` (both positive): 1, 2 and 5 times the powers of
/// ten within it.
fn log_keys(lo: f64, hi: f64) -> Vec<f64> {
    let (first, last) = (lo.log10().floor() as i32, hi.log10().ceil() as i32);
    (first..=last)
        .flat_map(|e| [1.0, 2.0, 5.0].map(|m| m * 10f64.powi(e)))
        .filter(|v| (lo..=hi).contains(v))
        .collect()
}

/// A grid of [`Panel`]s with a title and a legend strip.
struct Panels {
    title: String,
    cols: usize,
    panels: Vec<Panel>,
    legend: Vec<LegendEntry>,
}

impl Figure for Panels {
    fn draw<DB: DrawingBackend>(
        &self,
        root: &DrawingArea<DB, Shift>,
        _format: Format,
    ) -> Result<(), String> {
        root.fill(&WHITE).map_err(err)?;
        let fonts = Fonts::for_area(root);
        let body = title(root, &self.title, &fonts)?;
        let (main, strip) = split_legend(&body, &self.legend, &fonts);
        let rows = self.panels.len().div_ceil(self.cols);
        for (p, area) in self.panels.iter().zip(main.split_evenly((rows, self.cols))) {
            p.draw(&area, &fonts)?;
        }
        draw_legend(&strip, &self.legend, &fonts)
    }
}

/// A line of `kind` through `points` (one run).
fn line(points: Vec<(f64, f64)>, color: RGBColor, kind: LineKind, width: u32) -> Series {
    Series {
        runs: vec![points],
        color,
        kind,
        width,
    }
}

/// The width of a line: the figures are drawn at [`FigureOptions::default`].
fn width() -> u32 {
    let o = FigureOptions::default();
    Fonts::for_size(o.width, o.height).line
}

/// Error bars `value +- se` at `x` (no bar without a finite standard error).
fn se_bars(points: &[(f64, f64, f64)], color: RGBColor) -> Bars {
    Bars {
        points: (points.iter().filter(|p| p.2.is_finite()))
            .map(|&(x, y, se)| (x, y - se, y + se))
            .collect(),
        color,
        caps: true,
    }
}

// ----- Evidence -----

/// Natural frequency and damping against the tip amplitude at resonance: a row per mode, a
/// marker per test with its standard error, the weighted trend dashed.
fn evidence_linear(d: &Diagnosis) -> Option<Panels> {
    let lin = d.linear.as_ref()?;
    let mut panels = Vec::new();
    let mut used = Vec::new();
    for mode in ["1FU", "1FL"] {
        let fits: Vec<_> = (lin.fits_of(mode))
            .filter(|f| f.peak_tip_amplitude_m > 0.0 && f.frequency_hz.is_finite())
            .filter(|f| f.peak_tip_amplitude_m.is_finite() && f.damping_ratio.is_finite())
            .collect();
        if fits.is_empty() {
            continue;
        }
        let dep = lin.amplitude_dependence.iter().find(|a| a.mode == mode);
        let xs: Vec<f64> = fits.iter().map(|f| 1e3 * f.peak_tip_amplitude_m).collect();
        let Some((x0, x1)) = finite_range(&xs).map(|(a, b)| padded(a, b, 0.08)) else {
            continue;
        };
        let quantities = [
            (
                "natural frequency",
                "f_n (Hz)",
                "Hz/mm",
                dep.map(|a| &a.frequency_vs_amplitude),
            ),
            (
                "damping ratio",
                "ζ (-)",
                "1/mm",
                dep.map(|a| &a.damping_vs_amplitude),
            ),
        ];
        for (k, (what, y_desc, per, trend)) in quantities.into_iter().enumerate() {
            // (amplitude mm, value, standard error, test index)
            let pts: Vec<(f64, f64, f64, usize)> = (fits.iter().zip(&xs))
                .map(|(f, &x)| match k {
                    0 => (
                        x,
                        f.frequency_hz,
                        f.frequency_hz_standard_error,
                        f.test_index,
                    ),
                    _ => (
                        x,
                        f.damping_ratio,
                        f.damping_ratio_standard_error,
                        f.test_index,
                    ),
                })
                .collect();
            let trend = trend.filter(|t| t.intercept.is_finite() && t.slope.is_finite());
            let trend_line: Vec<(f64, f64)> = trend
                .map(|t| {
                    [x0, x1]
                        .map(|x| (x, t.intercept + t.slope * 1e-3 * x))
                        .to_vec()
                })
                .unwrap_or_default();
            let ys = (pts.iter())
                .flat_map(|p| [p.1 - p.2, p.1, p.1 + p.2])
                .chain(trend_line.iter().map(|p| p.1));
            let ys: Vec<f64> = ys.collect();
            let caption = match trend {
                Some(t) => format!(
                    "{mode} {what}: {} {per} ({} σ)",
                    sig(1e-3 * t.slope),
                    sig(t.slope / t.slope_standard_error)
                ),
                None => format!("{mode} {what}"),
            };
            let desc = ("tip amplitude at resonance (mm)", y_desc);
            let Some(mut p) = Panel::over(caption, desc, &xs, &ys) else {
                continue;
            };
            p.x = (x0, x1);
            if !trend_line.is_empty() {
                p.series
                    .push(line(trend_line, GREY, LineKind::Dashed, width()));
            }
            for &(x, y, se, ti) in &pts {
                p.series
                    .push(line(vec![(x, y)], palette(ti), LineKind::Markers, 1));
                p.bars.push(se_bars(&[(x, y, se)], palette(ti)));
            }
            panels.push(p);
        }
        used.extend(fits.iter().map(|f| (f.test_index, f.test.as_str())));
    }
    if panels.is_empty() {
        return None;
    }
    let mut legend: Vec<LegendEntry> = (session_tests(used.into_iter()).into_iter())
        .map(|(i, n)| entry(n, palette(i), LineKind::Markers))
        .collect();
    legend.push(entry("bars: ± 1 standard error", GREY, LineKind::Solid));
    legend.push(entry(
        "weighted trend against the amplitude",
        GREY,
        LineKind::Dashed,
    ));
    Some(Panels {
        title: "Linear fits per test: frequency falling and damping rising with the amplitude \
                point to clamp friction"
            .into(),
        cols: 2,
        panels,
        legend,
    })
}

/// The clearance bracket per test against the session order (or the accumulated normal
/// contact impulse when every test with an estimate has it), with the plan's clearance.
fn evidence_clearance(d: &Diagnosis) -> Option<Panels> {
    let cl = d.clearance.as_ref()?;
    let est: Vec<_> = (cl.tests.iter())
        .filter(|t| t.clearance_m.is_some_and(f64::is_finite))
        .collect();
    if est.is_empty() {
        return None;
    }
    let by_impulse = est
        .iter()
        .all(|t| t.accumulated_contact_impulse_ns.is_some_and(f64::is_finite));
    let at = |t: &TestClearance| match by_impulse {
        true => t.accumulated_contact_impulse_ns.unwrap_or(f64::NAN),
        false => t.test_index as f64,
    };
    let mm = |v: Option<f64>| v.map_or(f64::NAN, |v| 1e3 * v);
    let mut plan: Vec<(f64, f64)> = (cl.tests.iter())
        .map(|t| (at(t), 1e3 * t.plan_clearance_m))
        .filter(|p| p.0.is_finite() && p.1.is_finite())
        .collect();
    plan.sort_by(|a, b| a.0.total_cmp(&b.0));
    let xs: Vec<f64> = est
        .iter()
        .map(|t| at(t))
        .chain(plan.iter().map(|p| p.0))
        .collect();
    let (x0, x1) = finite_range(&xs)?;
    let (x0, x1) = padded(x0, x1, 0.06);
    let trend = (cl.trend.as_ref())
        .filter(|t| t.against.contains("impulse") == by_impulse)
        .filter(|t| t.intercept_m.is_finite() && t.slope_m.is_finite());
    let trend_pts: Vec<(f64, f64)> = trend
        .map(|t| {
            [x0, x1]
                .map(|x| (x, 1e3 * (t.intercept_m + t.slope_m * x)))
                .to_vec()
        })
        .unwrap_or_default();
    let ys: Vec<f64> = (est.iter())
        .flat_map(|t| {
            [
                mm(t.clearance_m),
                mm(t.lower_bound_m),
                mm(t.upper_bound_m),
                mm(t.onset_clearance_m),
            ]
        })
        .chain(plan.iter().chain(&trend_pts).map(|p| p.1))
        .collect();
    let x_desc = match by_impulse {
        true => "normal contact impulse accumulated before the test (N s)",
        false => "test (session order)",
    };
    let mut p = Panel::over(
        "estimate (the first contact's excursion) and bracket".into(),
        (x_desc, "clearance (mm)"),
        &xs,
        &ys,
    )?;
    p.x = (x0, x1);
    if !by_impulse {
        let n = cl.tests.iter().map(|t| t.test_index + 1).max().unwrap_or(0);
        p.x_names = (0..n)
            .map(|i| {
                cl.tests
                    .iter()
                    .find(|t| t.test_index == i)
                    .map_or(i.to_string(), |t| t.test.clone())
            })
            .collect();
    }
    // The plan's clearance from edge to edge (a single test has a line too).
    if let (Some(&(_, first)), Some(&(_, last))) = (plan.first(), plan.last()) {
        plan.insert(0, (x0, first));
        plan.push((x1, last));
    }
    let plan_first = plan.first().map(|q| q.1);
    p.series.push(line(plan, GREY, LineKind::Solid, 1));
    let mut legend = Vec::new();
    for t in &est {
        let (x, color) = (at(t), palette(t.test_index));
        p.series.push(line(
            vec![(x, mm(t.clearance_m))],
            color,
            LineKind::Markers,
            width(),
        ));
        let (lo, hi) = (mm(t.lower_bound_m), mm(t.upper_bound_m));
        if lo.is_finite() && hi.is_finite() {
            p.bars.push(Bars {
                points: vec![(x, lo, hi)],
                color,
                caps: true,
            });
        }
        legend.push(entry(t.test.clone(), color, LineKind::Markers));
    }
    legend.push(entry("bars: lower … upper bound", GREY, LineKind::Solid));
    // The second estimate, at the contact onsets.
    let onsets: Vec<(f64, f64)> = (est.iter())
        .map(|t| (at(t), mm(t.onset_clearance_m)))
        .filter(|q| q.1.is_finite())
        .collect();
    if !onsets.is_empty() {
        p.series
            .push(line(onsets, GREY, LineKind::Markers, width() + 1));
        legend.push(entry(
            "at the contact onsets (mean closing)",
            GREY,
            LineKind::Markers,
        ));
    }
    legend.push(entry(
        "plan clearance (model as given)",
        GREY,
        LineKind::Solid,
    ));
    // The wear stage: each test's clearance from the one refined by model runs within its
    // bracket and the one at the contact onsets (measured; `wear::measured_clearance`), and
    // the fitted model's clearance `plan + offset + k P` (model).
    let wear = d.effects.iter().find(|e| e.effect == "wear");
    if let (true, Some(w)) = (by_impulse, wear) {
        let pts: Vec<(f64, f64)> = (w.evidence["points"].as_array().into_iter().flatten())
            .filter_map(|q| {
                Some((
                    q["contact_impulse_ns"].as_f64()?,
                    1e3 * q["clearance_m"].as_f64()?,
                ))
            })
            .collect();
        if !pts.is_empty() {
            p.series
                .push(line(pts, BLACK, LineKind::Markers, width() + 2));
            legend.push(entry(
                "measured: the model runs' and the onsets' value, each weighted by its spread, at the impulse of the steps it was read from",
                BLACK,
                LineKind::Markers,
            ));
        }
        let k = w.parameters["coefficient"].as_f64();
        let off = w.parameters["clearance_offset"].as_f64().unwrap_or(0.0);
        let cap = w.parameters["max_growth"].as_f64().unwrap_or(f64::INFINITY);
        if let (Some(k), Some(c0)) = (k, plan_first) {
            let model: Vec<(f64, f64)> = (0..=20)
                .map(|i| x0.max(0.0) + (x1 - x0.max(0.0)) * f64::from(i) / 20.0)
                .map(|x| (x, c0 + 1e3 * (off + (k * x).min(cap))))
                .collect();
            p.series.push(line(model, BLACK, LineKind::Dashed, width()));
            legend.push(entry(
                format!(
                    "model: wear {} m/(N s){} ({})",
                    sig(k),
                    if cap.is_finite() {
                        format!(" capped at {} mm", sig(1e3 * cap))
                    } else {
                        String::new()
                    },
                    if w.accepted { "accepted" } else { "rejected" }
                ),
                BLACK,
                LineKind::Dashed,
            ));
        }
    }
    if let Some(t) = trend {
        p.series
            .push(line(trend_pts, GREY, LineKind::Dashed, width()));
        legend.push(entry(
            format!(
                "trend: {} mm per {}",
                sig(1e3 * t.slope_m),
                if by_impulse { "N s" } else { "test" }
            ),
            GREY,
            LineKind::Dashed,
        ));
    }
    Some(Panels {
        title: "Clearance per test: a trend over the session points to wear".into(),
        cols: 1,
        panels: vec![p],
        legend,
    })
}

/// The impact band's steps, one panel per test: the largest score of each step of the model
/// as given pointwise and with the comparison's spread
/// ([`crate::diagnose::outcome::BandSpread`]), and of the fixed model with the spread, against
/// the threshold.
fn evidence_band(d: &Diagnosis) -> Option<Panels> {
    let b = d.band_before.as_ref()?;
    let after = d.band_after.as_ref();
    let tests = first_seen(b.steps.iter().map(|s| s.test.as_str()));
    fn steps_of<'b>(band: &'b BandSpread, t: &str) -> Vec<&'b BandStep> {
        (band.steps.iter())
            .filter(|s| s.test == t && s.omega_ratio.is_finite())
            .collect()
    }
    let points = |steps: &[&BandStep]| -> Vec<(f64, f64)> {
        steps.iter().map(|s| (s.omega_ratio, s.max_score)).collect()
    };
    let mut panels = Vec::new();
    for t in &tests {
        let given = steps_of(b, t);
        let spread = points(&given);
        let fixed = after.map(|a| points(&steps_of(a, t))).unwrap_or_default();
        let point: Vec<(f64, f64)> = (given.iter())
            .filter_map(|s| {
                let q = (d.scores_before.iter()).find(|q| q.test == s.test && q.step == s.step)?;
                Some((s.omega_ratio, q.max_score()?))
            })
            .collect();
        let xs: Vec<f64> = spread.iter().map(|q| q.0).collect();
        let ys: Vec<f64> = (spread.iter().chain(&point).chain(&fixed))
            .map(|q| q.1)
            .chain([0.0, d.threshold])
            .collect();
        let Some(mut p) = Panel::over(
            (*t).to_string(),
            ("Omega / omega_2", "largest feature score"),
            &xs,
            &ys,
        ) else {
            continue;
        };
        let (x0, x1) = p.x;
        p.series.push(line(
            vec![(x0, d.threshold), (x1, d.threshold)],
            GREY,
            LineKind::Dashed,
            width(),
        ));
        p.series.push(line(point, GREY, LineKind::Markers, width()));
        p.series
            .push(line(spread, palette(0), LineKind::Markers, width() + 1));
        if !fixed.is_empty() {
            p.series
                .push(line(fixed, palette(1), LineKind::Markers, width() + 1));
        }
        panels.push(p);
    }
    if panels.is_empty() {
        return None;
    }
    let finer = b
        .finer_modes
        .map(|m| format!(" and a finer model of {m} modes"))
        .unwrap_or_default();
    let verdict = |b: &BandSpread| {
        format!(
            "median {} ({} of {} steps above {}): {}",
            sig(b.scores.median_max_score),
            b.scores.steps_above,
            b.scores.steps,
            sig(d.threshold),
            if b.beyond { "beyond" } else { "within" }
        )
    };
    let mut legend = vec![
        entry(
            "model as given, pointwise (the twin alone)",
            GREY,
            LineKind::Markers,
        ),
        entry(
            format!("model as given, with the spread: {}", verdict(b)),
            palette(0),
            LineKind::Markers,
        ),
    ];
    if let Some(a) = after {
        legend.push(entry(
            format!("fixed model, with the spread: {}", verdict(a)),
            palette(1),
            LineKind::Markers,
        ));
    }
    legend.push(entry(
        format!("threshold = {}", sig(d.threshold)),
        GREY,
        LineKind::Dashed,
    ));
    Some(Panels {
        title: format!(
            "The impact band, largest score per step with the comparison's spread (an ensemble of {}{finer})",
            b.members
        ),
        cols: panels.len().min(2),
        panels,
        legend,
    })
}

/// Measured over model RMS per motion channel on the impact-free steps, before any effect;
/// the gains the sensor evidence decided dashed.
fn evidence_sensors(d: &Diagnosis) -> Option<Panels> {
    let free: Vec<&StepScores> = (d.scores_before.iter())
        .filter(|s| matches!(s.regime, Regime::ImpactFreeLow | Regime::ImpactFreeHigh))
        .filter(|s| s.omega_ratio.is_finite())
        .collect();
    let tests = session_tests(free.iter().map(|s| (s.test_index, s.test.as_str())));
    let (mut series, mut gains, mut legend) = (Vec::new(), Vec::new(), Vec::new());
    for (c, channel) in MOTION.iter().enumerate() {
        let color = palette(c);
        let mut runs: Vec<Vec<(f64, f64)>> = Vec::new();
        for (ti, _) in &tests {
            let mut pts: Vec<(usize, f64, f64)> = (free.iter().filter(|s| s.test_index == *ti))
                .filter_map(|s| {
                    let f = s.feature(channel, "rms")?;
                    let r = f.measured / f.model;
                    r.is_finite().then_some((s.step, s.omega_ratio, r))
                })
                .collect();
            pts.sort_by(|a, b| a.1.total_cmp(&b.1));
            // A line through consecutive steps only: none across the impact band.
            for (k, &(step, w, r)) in pts.iter().enumerate() {
                if k == 0 || pts[k - 1].0.abs_diff(step) != 1 {
                    runs.push(Vec::new());
                }
                if let Some(run) = runs.last_mut() {
                    run.push((w, r));
                }
            }
        }
        if runs.is_empty() {
            continue;
        }
        series.push(Series {
            runs,
            color,
            kind: LineKind::Markers,
            width: 1,
        });
        legend.push(entry(*channel, color, LineKind::Markers));
        let gain = (d.sensors.as_ref()).and_then(|e| e.channel(channel)?.gain);
        gains.extend(gain.filter(|g| g.is_finite()).map(|g| (g, color)));
    }
    let points = || series.iter().flat_map(|s| s.runs.iter().flatten());
    let xs: Vec<f64> = points().map(|p| p.0).collect();
    let ys: Vec<f64> = (points().map(|p| p.1))
        .chain(gains.iter().map(|g| g.0))
        .chain([1.0])
        .collect();
    let desc = (OMEGA_DESC, "RMS measured / RMS model (-)");
    let mut p = Panel::over("impact-free steps, model as given".into(), desc, &xs, &ys)?;
    let (x0, x1) = p.x;
    let across = |y: f64| vec![(x0, y), (x1, y)];
    p.series.push(line(across(1.0), GREY, LineKind::Solid, 1));
    for &(g, color) in &gains {
        p.series
            .push(line(across(g), color, LineKind::Dashed, width()));
    }
    p.series.extend(series);
    legend.push(entry("1: sensitivity as nominal", GREY, LineKind::Solid));
    if !gains.is_empty() {
        legend.push(entry(
            "gain from the redundant channels",
            GREY,
            LineKind::Dashed,
        ));
    }
    Some(Panels {
        title: "Sensor evidence: a sensitivity error is a ratio flat in frequency, off 1".into(),
        cols: 1,
        panels: vec![p],
        legend,
    })
}

/// The discretisation stage's evidence: one panel per test with contact, the RMS feature
/// score of each step (the quantity the judge sums) of the twin as given and of each
/// refinement tried; and the contact fraction of each step, model against measured (a twin
/// that keeps its impacts closed too long lies above the diagonal).
fn evidence_discretisation(d: &Diagnosis) -> Option<Panels> {
    let e = d.discretisation.as_ref()?;
    let twins: Vec<(&DiscretisedTwin, RGBColor)> = std::iter::once((&e.given, GREY))
        .chain(e.options.iter().enumerate().map(|(k, t)| (t, palette(k))))
        .collect();
    let tests = first_seen(
        twins
            .iter()
            .flat_map(|(t, _)| &t.steps)
            .map(|s| s.test.as_str()),
    );
    let mut panels = Vec::new();
    for test in &tests {
        let runs: Vec<(Vec<(f64, f64)>, RGBColor)> = (twins.iter())
            .map(|(t, color)| {
                let mut pts: Vec<(f64, f64)> = (t.steps.iter())
                    .filter(|s| s.test == *test && s.omega_ratio.is_finite())
                    .filter_map(|s| Some((s.omega_ratio, s.score.filter(|v| v.is_finite())?)))
                    .collect();
                pts.sort_by(|a, b| a.0.total_cmp(&b.0));
                (pts, *color)
            })
            .collect();
        let xs: Vec<f64> = runs.iter().flat_map(|r| r.0.iter().map(|p| p.0)).collect();
        let ys: Vec<f64> = (runs.iter().flat_map(|r| r.0.iter().map(|p| p.1)))
            .chain([0.0])
            .collect();
        let role = match () {
            _ if e.train_tests.iter().any(|t| t == test) => " (train)",
            _ if e.validation_tests.iter().any(|t| t == test) => " (validation)",
            _ => "",
        };
        let desc = (OMEGA_DESC, "RMS feature score of the step");
        let Some(mut p) = Panel::over(format!("{test}{role}"), desc, &xs, &ys) else {
            continue;
        };
        for (pts, color) in runs.into_iter().filter(|r| !r.0.is_empty()) {
            p.series.push(line(pts, color, LineKind::Markers, width()));
        }
        panels.push(p);
    }
    if panels.is_empty() {
        return None;
    }
    let contact: Vec<(Vec<(f64, f64)>, RGBColor)> = (twins.iter())
        .map(|(t, color)| {
            let pts = (t.steps.iter())
                .filter_map(|s| Some((s.contact_measured?, s.contact_model?)))
                .filter(|p| p.0.is_finite() && p.1.is_finite())
                .collect();
            (pts, *color)
        })
        .collect();
    let all: Vec<f64> = (contact
        .iter()
        .flat_map(|c| c.0.iter().flat_map(|p| [p.0, p.1])))
    .chain([0.0])
    .collect();
    let mut diagonal = false;
    if all.len() > 1 {
        let desc = (
            "contact fraction, measured (-)",
            "contact fraction, model (-)",
        );
        if let Some(mut p) = Panel::over("contact fraction per step".into(), desc, &all, &all) {
            let hi = p.x.1.min(p.y.1);
            p.series
                .push(line(vec![(0.0, 0.0), (hi, hi)], GREY, LineKind::Solid, 1));
            for (pts, color) in contact.into_iter().filter(|c| !c.0.is_empty()) {
                p.series.push(Series {
                    runs: pts.into_iter().map(|q| vec![q]).collect(),
                    color,
                    kind: LineKind::Markers,
                    width: width(),
                });
            }
            panels.push(p);
            diagonal = true;
        }
    }
    let described = |t: &DiscretisedTwin| {
        let error = match (&t.error, &t.failure) {
            (Some(err), _) => format!(
                "train {}, validation {}",
                sig(err.train),
                sig(err.validation)
            ),
            (None, Some(f)) => format!("could not run: {f}"),
            (None, None) => "nothing compared".into(),
        };
        format!(
            "{}: {} modes up to {} x f(1FU), {} pairs, {} steps per 1FU period; {error}",
            t.refined
                .as_deref()
                .map_or("twin as given".to_string(), |r| format!("{r} refined")),
            t.modes,
            sig(t.highest_mode_over_1fu),
            t.contact_pairs,
            sig(t.steps_per_1fu_period),
        )
    };
    let mut legend: Vec<LegendEntry> = (twins.iter())
        .map(|(t, color)| entry(described(t), *color, LineKind::Markers))
        .collect();
    if diagonal {
        legend.push(entry("measured = model", GREY, LineKind::Solid));
    }
    let cols = match panels.len() {
        n if n <= 3 => n,
        n if n <= 4 => 2,
        _ => 3,
    };
    Some(Panels {
        title: "The twin's own discretisation: the tests with contact, as given and refined".into(),
        cols,
        panels,
        legend,
    })
}

/// The tilt's fit (the tilt stage's evidence): the train tests' error over their steps about
/// the first contact against how much earlier than the mean gap the first edge closes (log:
/// past the cliff, an edge closing before the measured contact, the errors are tens of times
/// the floor's): the tip-side edge's runs, the valley's floor, every other edge's points about
/// its closing, the face as given (closing 0), the fitted edge's closing and its spread; and the
/// contact channel's RMS score on the validation tests for the model without the clearance
/// offset, with the tilt and with the clearance offset (what separates a tilt from a smaller
/// clearance).
fn evidence_tilt(d: &Diagnosis) -> Option<Panels> {
    let e = d.effects.iter().find(|e| e.effect == "tilt")?;
    let ev = &e.evidence;
    let number = |v: &serde_json::Value| v.as_f64().filter(|x| x.is_finite());
    // (closing um, error, angle rad)
    let um = |t: &serde_json::Value| Some(1e6 * number(&t["closing_m"])?);
    let tried: Vec<(f64, f64, f64)> = (ev["angles_tried"].as_array()?.iter())
        .filter_map(|t| Some((um(t)?, number(&t["train_error"])?, number(&t["angle"])?)))
        .collect();
    let mut curve: Vec<(f64, f64)> = tried.iter().map(|t| (t.0, t.1)).collect();
    curve.sort_by(|a, b| a.0.total_cmp(&b.0));
    let flat = number(&ev["train_error_without_tilt"]);
    let taken = ev["edge"].as_str();
    // (edge, closing um, error): every other edge's points (its best alone in older evidence)
    let points = match ev["edge_points"].as_array() {
        Some(p) => p,
        None => ev["edges"].as_array().map_or(&[][..], |e| e.as_slice()),
    };
    let edges: Vec<(&str, f64, f64)> = (points.iter())
        .filter_map(|r| Some((r["edge"].as_str()?, um(r)?, number(&r["train_error"])?)))
        .filter(|r| r.0 != "tip_side")
        .collect();
    let mut names: Vec<&str> = edges.iter().map(|r| r.0).collect();
    names.dedup();
    let fitted = number(&ev["edge_closing_m"]).map(|c| 1e6 * c);
    let spread = number(&ev["closing_spread_m"])
        .filter(|s| *s > 0.0)
        .map(|s| 1e6 * s);
    let floor: Vec<(f64, f64)> = (ev["floor_angles"].as_array().into_iter().flatten())
        .filter_map(number)
        .filter_map(|a| tried.iter().find(|t| t.2 == a).map(|t| (t.0, t.1)))
        .collect();
    let xs: Vec<f64> = (curve.iter().map(|p| p.0))
        .chain(edges.iter().map(|r| r.1))
        .chain(flat.map(|_| 0.0))
        .collect();
    let ys: Vec<f64> = (curve.iter().map(|p| p.1))
        .chain(edges.iter().map(|r| r.2))
        .chain(flat)
        .collect();
    let desc = (
        "how much earlier than the mean gap the first edge closes (µm)",
        "train error, about the first contact (-)",
    );
    let caption = format!("train tests: {}", e.train_tests.join(", "));
    let mut p = Panel::over_log_y(caption, desc, &xs, &ys)?;
    if let Some(f) = flat {
        let (x0, x1) = p.x;
        p.series.push(line(
            vec![(x0, f), (x1, f)],
            GREY,
            LineKind::Dashed,
            width(),
        ));
    }
    p.series
        .push(line(curve, palette(0), LineKind::Markers, width()));
    if !floor.is_empty() {
        p.series.push(Series {
            runs: floor.iter().map(|&q| vec![q]).collect(),
            color: palette(1),
            kind: LineKind::Markers,
            width: width() + 3,
        });
    }
    for (k, name) in names.iter().enumerate() {
        p.series.push(Series {
            runs: (edges.iter().filter(|r| r.0 == *name))
                .map(|r| vec![(r.1, r.2)])
                .collect(),
            color: palette(k + 2),
            kind: LineKind::Markers,
            width: width() + 3,
        });
    }
    if let Some(c) = fitted {
        let (y0, y1) = p.y;
        p.series.push(line(
            vec![(c, y0), (c, y1)],
            palette(1),
            LineKind::Dashed,
            width(),
        ));
        if let Some(s) = spread {
            let y = p.y_at(0.05);
            p.series.push(line(
                vec![(c - s, y), (c + s, y)],
                palette(1),
                LineKind::Solid,
                width() + 2,
            ));
        }
    }
    let mut panels = vec![p];
    let contact = &ev["validation_contact_score_rms"];
    let bars: Vec<(String, f64)> = [
        ("neither", "model_before"),
        ("with the tilt", "with_tilt"),
        ("with the clearance offset", "with_clearance_offset"),
    ]
    .iter()
    .filter_map(|(label, key)| Some((label.to_string(), number(&contact[key])?)))
    .collect();
    if !bars.is_empty() {
        let xs: Vec<f64> = vec![-0.5, bars.len() as f64 - 0.5];
        let ys: Vec<f64> = bars.iter().map(|b| b.1).chain([0.0]).collect();
        let caption = format!("validation tests: {}", e.validation_tests.join(", "));
        let desc = ("", "contact channel, RMS score (-)");
        if let Some(mut q) = Panel::over(caption, desc, &xs, &ys) {
            q.x_names = bars.iter().map(|b| b.0.clone()).collect();
            let pts: Vec<(f64, f64)> = (bars.iter().enumerate())
                .map(|(k, b)| (k as f64, b.1))
                .collect();
            q.bars.push(Bars {
                points: pts.iter().map(|&(x, y)| (x, 0.0, y)).collect(),
                color: palette(0),
                caps: false,
            });
            q.series.push(Series {
                runs: pts.into_iter().map(|pt| vec![pt]).collect(),
                color: palette(0),
                kind: LineKind::Markers,
                width: width(),
            });
            panels.push(q);
        }
    }
    let verdict = judged(e).unwrap_or_default();
    let mut legend = vec![entry(
        "the tip-side edge (a tilt about y), its runs refined once around the best",
        palette(0),
        LineKind::Markers,
    )];
    if !floor.is_empty() {
        legend.push(entry(
            "the valley's floor (within the band's chaos of the smallest error)",
            palette(1),
            LineKind::Markers,
        ));
    }
    for (k, name) in names.iter().enumerate() {
        legend.push(entry(
            format!("the {} edge", name.replace('_', " ")),
            palette(k + 2),
            LineKind::Markers,
        ));
    }
    if let (Some(a), Some(edge)) = (number(&e.parameters["angle"]), taken) {
        let pm = number(&ev["angle_spread"])
            .filter(|s| *s > 0.0)
            .map(|s| format!(" +- {}", sig(s)))
            .unwrap_or_default();
        let told = match ev["other_edge"]["told"].as_bool() {
            Some(false) => ", not told from the others",
            _ => "",
        };
        legend.push(entry(
            format!(
                "fitted ({}): the {} edge{told}, {}{pm} rad about {}{verdict}",
                match edge {
                    "tip_side" => "the floor's mean",
                    _ => "its best point about the floor's closing",
                },
                edge.replace('_', " "),
                sig(a),
                axis_name(&e.parameters["axis"])
            ),
            palette(1),
            LineKind::Dashed,
        ));
    }
    if flat.is_some() {
        legend.push(entry(
            "the face as given (closing 0)",
            GREY,
            LineKind::Dashed,
        ));
    }
    let closing = match (fitted, number(&ev["runs_closing_m"])) {
        (Some(c), Some(r)) => format!(
            ": the fitted edge closes {} µm early (a flat face's runs: {} µm)",
            sig(c),
            sig(1e6 * r)
        ),
        (Some(c), None) => format!(": the fitted edge closes {} µm early", sig(c)),
        _ => String::new(),
    };
    Some(Panels {
        title: format!("Tilt of the contact face{closing}"),
        cols: panels.len(),
        panels,
        legend,
    })
}

/// A tilt's axis `[x, y]` in words ("y" where it is not given).
fn axis_name(axis: &serde_json::Value) -> &'static str {
    let c = |k: usize| axis[k].as_f64().unwrap_or(0.0).abs();
    if c(0) > c(1) {
        "x"
    } else {
        "y"
    }
}

/// How effect `e` was judged, for a legend: "; validation BEFORE -> AFTER, VERDICT" (None
/// where it was not judged).
fn judged(e: &EffectResult) -> Option<String> {
    let (b, a) = (e.error_before.as_ref()?, e.error_after.as_ref()?);
    let verdict = match () {
        _ if e.accepted => "accepted",
        _ if e.reason.contains("an equal alternative") => "an equal alternative",
        _ => "rejected",
    };
    Some(format!(
        "; validation {} -> {}, {verdict}",
        sig(b.validation),
        sig(a.validation)
    ))
}

/// The clearance offset's fit by model runs: the error of every run against the offset to the
/// model's clearance, the train tests together (each offset the median of the band's draws)
/// and each train test alone (one run per clearance), with the offset fitted and the model as
/// given (offset 0). None without runs.
fn evidence_clearance_fit(d: &Diagnosis) -> Option<Panels> {
    let e = d.effects.iter().find(|e| e.effect == "clearance")?;
    let ev = &e.evidence;
    let number = |v: &serde_json::Value| v.as_f64().filter(|x| x.is_finite());
    let runs = |v: &serde_json::Value, key: &str, shift: f64| {
        let mut r: Vec<(f64, f64)> = (v.as_array().into_iter().flatten())
            .filter_map(|p| Some((1e6 * (number(&p[key])? - shift), number(&p["error"])?)))
            .collect();
        r.sort_by(|a, b| a.0.total_cmp(&b.0));
        r
    };
    let together = runs(&ev["offset_by_tests_together"]["runs"], "offset_m", 0.0);
    let alone: Vec<(String, Vec<(f64, f64)>)> = (ev["train_tests_one_by_one"]
        .as_array()
        .into_iter()
        .flatten())
    .filter_map(|t| {
        let model = number(&t["model_clearance_m"])?;
        let name = t["test"].as_str()?.to_string();
        Some((name, runs(&t["runs"], "clearance_m", model)))
    })
    .filter(|(_, r)| !r.is_empty())
    .collect();
    if together.is_empty() && alone.is_empty() {
        return None;
    }
    let all = || together.iter().chain(alone.iter().flat_map(|a| a.1.iter()));
    let xs: Vec<f64> = all().map(|p| p.0).chain([0.0]).collect();
    let ys: Vec<f64> = all().map(|p| p.1).chain([0.0]).collect();
    let desc = (
        "offset to the model's clearance (µm)",
        "error, the steps about the first contact (-)",
    );
    let caption = format!("train tests: {}", e.train_tests.join(", "));
    let mut p = Panel::over(caption, desc, &xs, &ys)?;
    let (y0, y1) = p.y;
    p.series.push(line(
        vec![(0.0, y0), (0.0, y1)],
        GREY,
        LineKind::Dashed,
        width(),
    ));
    let mut legend = Vec::new();
    for (k, (name, r)) in alone.iter().enumerate() {
        p.series
            .push(line(r.clone(), palette(k + 1), LineKind::Markers, width()));
        legend.push(entry(
            format!("{name} alone (one run per clearance)"),
            palette(k + 1),
            LineKind::Markers,
        ));
    }
    if !together.is_empty() {
        p.series.push(line(
            together.clone(),
            palette(0),
            LineKind::Markers,
            width() + 2,
        ));
        legend.insert(
            0,
            entry(
                "the train tests together (each offset the median of the band's draws)",
                palette(0),
                LineKind::Markers,
            ),
        );
    }
    let verdict = judged(e).unwrap_or_else(|| "; not judged".into());
    if let Some(o) = number(&ev["offset_m"]) {
        p.series.push(line(
            vec![(1e6 * o, y0), (1e6 * o, y1)],
            palette(0),
            LineKind::Dashed,
            width(),
        ));
        legend.push(entry(
            format!("fitted: {} µm{verdict}", sig(1e6 * o)),
            palette(0),
            LineKind::Dashed,
        ));
    }
    legend.push(entry(
        "the model as given (offset 0)",
        GREY,
        LineKind::Dashed,
    ));
    Some(Panels {
        title: "Clearance offset by model runs".into(),
        cols: 1,
        panels: vec![p],
        legend,
    })
}

// ----- Before / after -----

/// The validation tests' response per channel: measured, the model as given and the model
/// with the accepted effects.
fn before_after(d: &Diagnosis, with: &str) -> Option<Panels> {
    let after: Vec<&StepScores> = (d.scores_after.iter())
        .filter(|s| d.validation_tests.contains(&s.test) && s.omega_ratio.is_finite())
        .collect();
    let tests = session_tests(after.iter().map(|s| (s.test_index, s.test.as_str())));
    let before = |s: &StepScores| {
        (d.scores_before.iter()).find(|b| b.test_index == s.test_index && b.step == s.step)
    };
    let quantities = MOTION
        .iter()
        .map(|c| (*c, "rms", Some(("amp_p10", "amp_p90"))))
        .chain([(CONTACT_CHANNEL, "contact_fraction", None)]);
    let mut panels = Vec::new();
    for (channel, feat, range) in quantities {
        let (mut series, mut bands, mut bars, mut ys) =
            (Vec::new(), Vec::new(), Vec::new(), vec![0.0]);
        for (ti, _) in &tests {
            let color = palette(*ti);
            let mut steps: Vec<&StepScores> = after
                .iter()
                .copied()
                .filter(|s| s.test_index == *ti)
                .collect();
            steps.sort_by(|a, b| a.omega_ratio.total_cmp(&b.omega_ratio));
            let x: Vec<f64> = steps.iter().map(|s| s.omega_ratio).collect();
            let value = |s: &StepScores, f: &str, m: fn(&FeatureComparison) -> f64| {
                s.feature(channel, f).map_or(f64::NAN, m)
            };
            let measured: Vec<f64> = steps
                .iter()
                .map(|s| value(s, feat, |f| f.measured))
                .collect();
            let model: Vec<f64> = steps.iter().map(|s| value(s, feat, |f| f.model)).collect();
            let model_before: Vec<f64> = (steps.iter())
                .map(|s| before(s).map_or(f64::NAN, |b| value(b, feat, |f| f.model)))
                .collect();
            ys.extend(measured.iter().chain(&model).chain(&model_before));
            if let Some((p10, p90)) = range {
                let span = |m: fn(&FeatureComparison) -> f64| -> Vec<(f64, f64, f64)> {
                    (steps.iter())
                        .map(|s| (s.omega_ratio, value(s, p10, m), value(s, p90, m)))
                        .filter(|p| p.1.is_finite() && p.2.is_finite())
                        .collect()
                };
                let (m, t) = (span(|f| f.measured), span(|f| f.model));
                ys.extend(m.iter().chain(&t).flat_map(|p| [p.1, p.2]));
                if t.len() >= 2 {
                    let mut poly: Vec<(f64, f64)> = t.iter().map(|p| (p.0, p.2)).collect();
                    poly.extend(t.iter().rev().map(|p| (p.0, p.1)));
                    bands.push(Band {
                        polygons: vec![poly],
                        color,
                    });
                }
                bars.push(Bars {
                    points: m,
                    color,
                    caps: false,
                });
            }
            for (v, kind) in [
                (&model_before, LineKind::Dashed),
                (&model, LineKind::Solid),
                (&measured, LineKind::Markers),
            ] {
                series.push(Series {
                    runs: segments(&x, v),
                    color,
                    kind,
                    width: width(),
                });
            }
        }
        if series.iter().all(|s| s.runs.is_empty()) {
            continue;
        }
        let xs: Vec<f64> = after.iter().map(|s| s.omega_ratio).collect();
        let y_desc = match range {
            Some(_) => "velocity / (Ω q_base) (-)",
            None => "contact fraction (-)",
        };
        let Some(mut p) = Panel::over(format!("{channel}: {feat}"), (OMEGA_DESC, y_desc), &xs, &ys)
        else {
            continue;
        };
        let top = finite_range(&ys).map_or(0.0, |r| r.1);
        p.y = (0.0, if top > 0.0 { 1.08 * top } else { 1.0 });
        (p.series, p.bands, p.bars) = (series, bands, bars);
        panels.push(p);
    }
    if panels.is_empty() {
        return None;
    }
    let mut legend: Vec<LegendEntry> = (tests.iter())
        .map(|(i, n)| entry(n.clone(), palette(*i), LineKind::Markers))
        .collect();
    legend.extend([
        entry(
            "measured (bars: p10 … p90 amplitude)",
            GREY,
            LineKind::Markers,
        ),
        entry("model as given", GREY, LineKind::Dashed),
        entry(format!("model {with}"), GREY, LineKind::Solid),
        entry("band: model's p10 … p90 amplitude", GREY, LineKind::Band),
    ]);
    Some(Panels {
        title: format!("Validation tests before and after: the model as given and {with}"),
        cols: panels.len().min(3),
        panels,
        legend,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scores_shade_from_white_through_the_threshold_to_dark_red() {
        let s = ScoreScale {
            white: 1.0,
            threshold: 3.0,
            top: 30.0,
        };
        assert_eq!(s.color(0.5), WHITE);
        assert_eq!(s.color(3.0), RGBColor(252, 187, 161));
        assert_eq!(s.color(3.0001).0, 251);
        assert_eq!(s.color(30.0), RGBColor(103, 0, 13));
        assert_eq!(s.color(f64::INFINITY), RGBColor(103, 0, 13));
        assert_eq!(name_at(&["a".into(), "b".into()], 1.0), "b");
        assert_eq!(name_at(&["a".into()], 0.5), "");
        assert_eq!(sig(-4.56789), "-4.57");
        assert_eq!(sig(0.0012345), "0.00123");
        assert_eq!(sig(3.0), "3");
        assert_eq!(sig(250.0), "250");
    }
}
