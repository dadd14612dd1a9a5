//! Output plumbing shared by all figures: the embedded font, the format chosen by the file
//! extension, and drawing one [`Figure`] on the matching plotters backend.

use std::path::Path;
use std::sync::OnceLock;

use plotters::coord::Shift;
use plotters::prelude::*;

use super::{FigureOptions, ReportError};

/// DejaVu Sans (assets/fonts/README.md has its licence).
static FONT: &[u8] = include_bytes!("../../assets/fonts/DejaVuSans.ttf");

/// Family name under which the embedded font is registered; plotters' default family.
pub(crate) const FAMILY: &str = "sans-serif";

/// Smallest accepted figure side, px.
const MIN_SIDE: u32 = 200;

/// Largest accepted figure side, px (a typo guard: 16k x 16k RGB is already 768 MB).
const MAX_SIDE: u32 = 16_384;

/// The image format of an output file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Format {
    Png,
    Svg,
}

/// A figure that can be drawn on any plotters backend. Errors are plotters' messages.
pub(crate) trait Figure {
    fn draw<DB: DrawingBackend>(
        &self,
        root: &DrawingArea<DB, Shift>,
        format: Format,
    ) -> Result<(), String>;
}

/// Turns any displayable plotters error into the message of [`ReportError::Draw`].
pub(crate) fn err<E: std::fmt::Display>(e: E) -> String {
    e.to_string()
}

/// Registers the embedded font once; `false` if it could not be parsed.
fn font_ready() -> bool {
    static READY: OnceLock<bool> = OnceLock::new();
    *READY.get_or_init(|| plotters::style::register_font(FAMILY, FontStyle::Normal, FONT).is_ok())
}

fn format_of(path: &Path) -> Result<Format, ReportError> {
    match path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
        .as_deref()
    {
        Some("png") => Ok(Format::Png),
        Some("svg") => Ok(Format::Svg),
        _ => Err(ReportError::UnsupportedFormat {
            path: path.to_path_buf(),
        }),
    }
}

/// The format `out` will be written in, checked before any data work.
pub(crate) fn check_output(out: &Path, opts: &FigureOptions) -> Result<Format, ReportError> {
    let format = format_of(out)?;
    let ok = |s: u32| (MIN_SIDE..=MAX_SIDE).contains(&s);
    if !ok(opts.width) || !ok(opts.height) {
        return Err(ReportError::InvalidSize {
            path: out.to_path_buf(),
            width: opts.width,
            height: opts.height,
            min: MIN_SIDE,
        });
    }
    Ok(format)
}

/// Draws `figure` into `out` (PNG or SVG by extension), creating the directory if needed.
pub(crate) fn render<F: Figure>(
    out: &Path,
    opts: &FigureOptions,
    figure: &F,
) -> Result<(), ReportError> {
    let format = check_output(out, opts)?;
    let draw_error = |message: String| ReportError::Draw {
        path: out.to_path_buf(),
        message,
    };
    if !font_ready() {
        return Err(draw_error(
            "the embedded DejaVu Sans font could not be loaded".into(),
        ));
    }
    if let Some(dir) = out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(|source| ReportError::Io {
            path: out.to_path_buf(),
            source,
        })?;
    }
    let size = (opts.width, opts.height);
    match format {
        Format::Png => {
            let root = BitMapBackend::new(out, size).into_drawing_area();
            figure.draw(&root, format).map_err(draw_error)?;
            root.present().map_err(|e| draw_error(err(e)))
        }
        Format::Svg => {
            let root = SVGBackend::new(out, size).into_drawing_area();
            figure.draw(&root, format).map_err(draw_error)?;
            root.present().map_err(|e| draw_error(err(e)))
        }
    }
}
