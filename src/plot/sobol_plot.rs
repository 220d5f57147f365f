//! The bar chart of a Sobol' analysis: a panel per output, for each varied parameter a bar of its
//! first-order index (`DATA_COLOR`) beside a bar of its total index (`TANGENT_COLOR`), each with
//! its confidence interval as a black error bar. Knows plotters and numbers; not the estimators.

use std::path::Path;

use plotters::coord::Shift;
use plotters::prelude::*;

use super::{padded_range, render, text, Figure, PlotError, DATA_COLOR, TANGENT_COLOR};

/// One output's indices, each with the half-width of its interval (NaN: none).
#[derive(Clone, Debug, PartialEq)]
pub struct SobolPanel {
    /// The output's name.
    pub name: String,
    /// First-order indices with their intervals' half-widths.
    pub s1: Vec<(f64, f64)>,
    /// Total indices with theirs.
    pub st: Vec<(f64, f64)>,
}

/// A Sobol' analysis ready to draw.
#[derive(Clone, Debug, PartialEq)]
pub struct SobolFigure {
    /// The figure's title.
    pub title: String,
    /// The varied parameters, in the order of every panel's bars.
    pub params: Vec<String>,
    /// One panel per output.
    pub panels: Vec<SobolPanel>,
}

/// Draws `figure` into `path` (SVG or PNG by the extension).
pub fn plot_sobol(figure: &SobolFigure, path: &Path) -> Result<(), PlotError> {
    if figure.panels.is_empty() {
        return Err(PlotError::Empty { what: "no output has indices".into() });
    }
    render(figure, path)
}

impl Figure for SobolFigure {
    fn panels(&self) -> usize {
        self.panels.len()
    }

    fn draw<DB: DrawingBackend>(
        &self,
        root: &DrawingArea<DB, Shift>,
    ) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
        root.fill(&WHITE)?;
        let area = root.titled(&self.title, text(18))?;
        let d = self.params.len() as f64;
        for (p, panel) in self.panels.iter().zip(&area.split_evenly((self.panels(), 1))) {
            // The range holds 0, 1 and every interval's ends.
            let ends = p.s1.iter().chain(&p.st).flat_map(|&(v, c)| {
                let c = if c.is_finite() { c } else { 0.0 };
                [v - c, v + c]
            });
            let (lo, hi) = padded_range(ends.chain([0.0, 1.0]));
            let mut chart = ChartBuilder::on(panel)
                .margin(6)
                .x_label_area_size(24)
                .y_label_area_size(70)
                .build_cartesian_2d(0.0..d, lo..hi)?;
            chart
                .configure_mesh()
                .disable_x_mesh()
                .x_labels(0)
                .y_desc(format!("{}: S1, ST", p.name))
                .label_style(text(12))
                .axis_desc_style(text(14))
                .light_line_style(WHITE)
                .draw()?;
            let bars = |values: &[(f64, f64)], from: f64, color: RGBColor| {
                values
                    .iter()
                    .enumerate()
                    .filter(|(_, (v, _))| v.is_finite())
                    .map(move |(i, &(v, _))| {
                        let x = i as f64 + from;
                        Rectangle::new([(x, 0.0), (x + 0.35, v)], color.filled())
                    })
                    .collect::<Vec<_>>()
            };
            chart.draw_series(bars(&p.s1, 0.1, DATA_COLOR))?;
            chart.draw_series(bars(&p.st, 0.55, TANGENT_COLOR))?;
            let whiskers = |values: &[(f64, f64)], from: f64| {
                values
                    .iter()
                    .enumerate()
                    .filter(|(_, (v, c))| v.is_finite() && c.is_finite())
                    .flat_map(move |(i, &(v, c))| {
                        let x = i as f64 + from + 0.175;
                        [
                            PathElement::new(vec![(x, v - c), (x, v + c)], BLACK.stroke_width(1)),
                            PathElement::new(
                                vec![(x - 0.05, v - c), (x + 0.05, v - c)],
                                BLACK.stroke_width(1),
                            ),
                            PathElement::new(
                                vec![(x - 0.05, v + c), (x + 0.05, v + c)],
                                BLACK.stroke_width(1),
                            ),
                        ]
                    })
                    .collect::<Vec<_>>()
            };
            chart.draw_series(whiskers(&p.s1, 0.1))?;
            chart.draw_series(whiskers(&p.st, 0.55))?;
            chart.draw_series(
                self.params
                    .iter()
                    .enumerate()
                    .map(|(i, name)| Text::new(name.clone(), (i as f64 + 0.1, hi), text(13))),
            )?;
        }
        Ok(())
    }
}
