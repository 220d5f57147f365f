//! A log-log chart of measured curves: cost against size, one line with markers per series and a
//! legend (the adjoint's cost against the number of knots, in docs/performance.md). Knows
//! plotters and numbers; the measurements are the caller's.

use std::path::Path;

use plotters::coord::Shift;
use plotters::prelude::*;

use super::{render, text, Figure, PlotError, DATA_COLOR, EVENT_COLOR, TANGENT_COLOR};

/// One measured curve: points `(x, y)` with both positive (others are left out).
#[derive(Clone, Debug, PartialEq)]
pub struct CurveSeries {
    /// The legend's label.
    pub name: String,
    /// The points, in drawing order.
    pub points: Vec<(f64, f64)>,
}

/// Curves on one log-log panel.
#[derive(Clone, Debug, PartialEq)]
pub struct CurveFigure {
    /// The figure's title.
    pub title: String,
    /// The x axis' label.
    pub x_desc: String,
    /// The y axis' label.
    pub y_desc: String,
    /// The curves, coloured in turn.
    pub series: Vec<CurveSeries>,
}

/// Draws `figure` into `path` (SVG or PNG by the extension).
pub fn plot_curves(figure: &CurveFigure, path: &Path) -> Result<(), PlotError> {
    if figure.points().next().is_none() {
        return Err(PlotError::Empty { what: "no curve has a positive point".into() });
    }
    render(figure, path)
}

impl CurveFigure {
    /// Every point a log-log panel can show.
    fn points(&self) -> impl Iterator<Item = (f64, f64)> + '_ {
        self.series
            .iter()
            .flat_map(|s| s.points.iter().copied())
            .filter(|&(x, y)| x.is_finite() && y.is_finite() && x > 0.0 && y > 0.0)
    }
}

/// A log range holding `values`, widened by a fifth of a decade on each side.
fn log_range(values: impl Iterator<Item = f64>) -> std::ops::Range<f64> {
    let (lo, hi) = values.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| (lo.min(v), hi.max(v)));
    let pad = 10f64.powf(0.2);
    lo / pad..hi * pad
}

impl Figure for CurveFigure {
    fn panels(&self) -> usize {
        // Square enough for a curve over decades: two panels' height.
        2
    }

    fn draw<DB: DrawingBackend>(
        &self,
        root: &DrawingArea<DB, Shift>,
    ) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
        root.fill(&WHITE)?;
        let area = root.titled(&self.title, text(18))?;
        let xs = log_range(self.points().map(|p| p.0));
        let ys = log_range(self.points().map(|p| p.1));
        let mut chart = ChartBuilder::on(&area)
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(70)
            .build_cartesian_2d(xs.log_scale(), ys.log_scale())?;
        chart
            .configure_mesh()
            // `{}` writes 1000 for 1000.0 and 0.001 for 1e-3: the decades as a reader writes them.
            .x_label_formatter(&|v| format!("{v}"))
            .y_label_formatter(&|v| format!("{v}"))
            .x_desc(self.x_desc.as_str())
            .y_desc(self.y_desc.as_str())
            .label_style(text(12))
            .axis_desc_style(text(14))
            .draw()?;
        let colors = [DATA_COLOR, TANGENT_COLOR, EVENT_COLOR, RGBColor(0x2c, 0xa0, 0x2c)];
        for (i, series) in self.series.iter().enumerate() {
            let color = colors[i % colors.len()];
            let points: Vec<(f64, f64)> = series
                .points
                .iter()
                .copied()
                .filter(|&(x, y)| x > 0.0 && y > 0.0 && x.is_finite() && y.is_finite())
                .collect();
            chart
                .draw_series(LineSeries::new(points.iter().copied(), color.stroke_width(2)))?
                .label(series.name.as_str())
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2)));
            chart.draw_series(points.iter().map(|&p| Circle::new(p, 4, color.filled())))?;
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperLeft)
            .label_font(text(13))
            .background_style(WHITE.mix(0.9))
            .border_style(BLACK)
            .draw()?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn figure(series: Vec<CurveSeries>) -> CurveFigure {
        CurveFigure { title: "t".into(), x_desc: "K".into(), y_desc: "cost".into(), series }
    }

    #[test]
    fn draws_each_curve_with_its_markers() {
        let dir = std::env::temp_dir().join(format!("hybc-curves-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("c.svg");
        let fig = figure(vec![
            CurveSeries { name: "flat".into(), points: vec![(10.0, 2.0), (100.0, 2.5), (1000.0, 2.0)] },
            // The non-positive point cannot sit on a log axis and is left out, not drawn at 0.
            CurveSeries { name: "grows".into(), points: vec![(10.0, 1.6), (100.0, 8.8), (1000.0, 0.0)] },
        ]);
        plot_curves(&fig, &path).unwrap();
        let svg = std::fs::read_to_string(&path).unwrap();
        std::fs::remove_dir_all(&dir).ok();
        assert_eq!(svg.matches("<circle").count(), 5, "one marker per positive point");
        assert!(svg.contains("flat") && svg.contains("grows"), "the legend names both curves");
    }

    #[test]
    fn refuses_a_figure_with_nothing_to_draw() {
        let fig =
            figure(vec![CurveSeries { name: "none".into(), points: vec![(0.0, 1.0), (1.0, f64::NAN)] }]);
        let err = plot_curves(&fig, Path::new("never-written.svg")).unwrap_err();
        assert!(matches!(err, PlotError::Empty { .. }), "{err}");
    }
}
