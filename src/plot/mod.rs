//! Plots of a run (states and outputs against time, with event markers and mode bands) and of a
//! sweep (each output against a varied parameter, with gradient tangents), and measured curves on
//! log-log axes (a benchmark's cost against size), as SVG or PNG chosen
//! by the file extension. Knows plotters (only here) and the results of `sim` and `sweep`; text is
//! drawn with an embedded font so that no system font library is needed.
//!
//! Every plot is [`WIDTH`] pixels wide and [`PANEL_HEIGHT`] pixels high per panel, one panel per
//! variable, stacked. Data lines, event markers and tangents have their own colours
//! ([`DATA_COLOR`], [`EVENT_COLOR`], [`TANGENT_COLOR`]), which tests use to count them.

mod curve_plot;
mod font;
mod run_plot;
mod sobol_plot;
mod sweep_plot;

use std::path::{Path, PathBuf};

use plotters::coord::Shift;
use plotters::prelude::*;

pub use curve_plot::{plot_curves, CurveFigure, CurveSeries};
pub use run_plot::{plot_run, RunFigure};
pub use sobol_plot::{plot_sobol, SobolFigure, SobolPanel};
pub use sweep_plot::{plot_sweep, Shown, SweepFigure, SweepSeries, Tangent};

/// Width of every plot, in pixels.
pub const WIDTH: u32 = 960;
/// Height of one panel, in pixels.
pub const PANEL_HEIGHT: u32 = 240;
/// Lines of trajectories and sweep curves.
pub const DATA_COLOR: RGBColor = RGBColor(0x1f, 0x77, 0xb4);
/// Vertical lines at event times.
pub const EVENT_COLOR: RGBColor = RGBColor(0xd6, 0x27, 0x28);
/// Gradient tangents of a sweep.
pub const TANGENT_COLOR: RGBColor = RGBColor(0xff, 0x7f, 0x0e);

/// The pixel size of a plot with `panels` panels.
pub fn size(panels: usize) -> (u32, u32) {
    (WIDTH, PANEL_HEIGHT * panels.max(1) as u32)
}

/// The image formats a plot can be written in.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ImageFormat {
    /// An SVG file.
    Svg,
    /// A PNG file.
    Png,
}

impl ImageFormat {
    /// The format named by `path`'s extension (`.svg` or `.png`, any case).
    pub fn from_path(path: &Path) -> Result<ImageFormat, PlotError> {
        let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
        match ext.as_deref() {
            Some("svg") => Ok(ImageFormat::Svg),
            Some("png") => Ok(ImageFormat::Png),
            _ => Err(PlotError::Extension { path: path.to_path_buf() }),
        }
    }
}

/// Why a figure was not drawn.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    /// A path whose extension is neither `.svg` nor `.png`.
    #[error("`{}`: the plot file must end in .svg or .png", path.display())]
    Extension {
        /// The path.
        path: PathBuf,
    },
    /// Nothing to draw.
    #[error("nothing to plot: {what}")]
    Empty {
        /// What is missing.
        what: String,
    },
    /// Drawing or writing failed.
    #[error("cannot draw `{}`: {message}", path.display())]
    Draw {
        /// The path.
        path: PathBuf,
        /// The drawing backend's message.
        message: String,
    },
}

/// Something drawn on a stack of panels, on any plotters backend.
pub(crate) trait Figure {
    fn panels(&self) -> usize;
    fn draw<DB: DrawingBackend>(
        &self,
        root: &DrawingArea<DB, Shift>,
    ) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>>;
}

/// Draws `figure` into `path` in the format its extension names.
pub(crate) fn render(figure: &impl Figure, path: &Path) -> Result<(), PlotError> {
    let format = ImageFormat::from_path(path)?;
    font::register();
    let size = size(figure.panels());
    // plotters reports a backend's IO errors through its own generic error type; its message is
    // all a caller can act on.
    let draw_error = |message: String| PlotError::Draw { path: path.to_path_buf(), message };
    match format {
        ImageFormat::Svg => {
            let root = SVGBackend::new(path, size).into_drawing_area();
            figure.draw(&root).and_then(|()| root.present()).map_err(|e| draw_error(e.to_string()))
        }
        ImageFormat::Png => {
            let root = BitMapBackend::new(path, size).into_drawing_area();
            figure.draw(&root).and_then(|()| root.present()).map_err(|e| draw_error(e.to_string()))
        }
    }
}

/// `(lo, hi)` of `values` with 5% room on each side; a flat or empty set gets a unit range.
pub(crate) fn padded_range(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = values
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| (lo.min(v), hi.max(v)));
    if lo > hi {
        return (-1.0, 1.0);
    }
    let pad = if hi > lo { 0.05 * (hi - lo) } else { 0.5 * lo.abs().max(1.0) };
    (lo - pad, hi + pad)
}

/// The text style of axis labels and titles.
pub(crate) fn text(size: u32) -> TextStyle<'static> {
    (font::FAMILY, size).into_font().color(&BLACK)
}
