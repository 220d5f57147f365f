//! The plot of a sweep: a panel per output (per final state when the model has no outputs, or
//! the outputs and states chosen with `--show`) against one varied parameter, a marker per point, and at a few points the tangent whose slope
//! is the computed gradient, so that the eye can check the gradient against the curve.

use std::path::Path;

use plotters::coord::Shift;
use plotters::prelude::*;

use super::{padded_range, render, text, Figure, PlotError, DATA_COLOR, TANGENT_COLOR};
use crate::sim::{SimResult, StopReason, SystemInfo};
use crate::sweep::PointResult;

/// A tangent line through `(x, y)` with slope `dy/dx`.
#[derive(Clone, Debug, PartialEq)]
pub struct Tangent {
    /// The point's abscissa.
    pub x: f64,
    /// Its ordinate.
    pub y: f64,
    /// The slope there.
    pub slope: f64,
}

/// One plotted quantity.
#[derive(Clone, Debug, PartialEq)]
pub struct SweepSeries {
    /// The quantity's name.
    pub name: String,
    /// `(parameter value, final value)` of every point that ran to its end.
    pub points: Vec<(f64, f64)>,
    /// Tangents at a few points, from the gradients.
    pub tangents: Vec<Tangent>,
}

/// A quantity a panel shows: an output or a final state, by index.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Shown {
    /// Output `i`.
    Output(usize),
    /// State `i` (its final value).
    State(usize),
}

impl Shown {
    /// Every output, or every state for a model without outputs: the default panels.
    pub fn default_for(info: &SystemInfo) -> Vec<Shown> {
        if info.n_outputs() > 0 {
            (0..info.n_outputs()).map(Shown::Output).collect()
        } else {
            (0..info.n_states()).map(Shown::State).collect()
        }
    }

    /// The output or state called `name` (outputs first, as names are unique across both).
    pub fn by_name(info: &SystemInfo, name: &str) -> Option<Shown> {
        info.output_names
            .iter()
            .position(|n| n == name)
            .map(Shown::Output)
            .or_else(|| info.state_names.iter().position(|n| n == name).map(Shown::State))
    }

    fn name(self, info: &SystemInfo) -> &str {
        match self {
            Shown::Output(i) => &info.output_names[i],
            Shown::State(i) => &info.state_names[i],
        }
    }
}

/// A sweep against one parameter, ready to draw.
#[derive(Clone, Debug, PartialEq)]
pub struct SweepFigure {
    /// The figure's title.
    pub title: String,
    /// The parameter on the x axis.
    pub param: String,
    /// One panel per quantity shown.
    pub series: Vec<SweepSeries>,
    /// Join the points by a line (sensible when only this parameter varies).
    pub connect: bool,
    /// What each series shows, in the order of `series`.
    shown: Vec<Shown>,
}

/// The value of `shown` in a complete run and, when it exists, its gradient row (one entry per
/// differentiated parameter). After a `stop` event the gradients are the total ones, the
/// derivatives of the values as functions of the parameters.
fn quantity(info: &SystemInfo, r: &SimResult, shown: Shown) -> Option<(f64, Option<Vec<f64>>)> {
    let f = &r.final_state;
    let by_event = match r.stopped_by {
        StopReason::TEnd => false,
        StopReason::Event { .. } => true,
        _ => return None,
    };
    let (values, grads, i) = match shown {
        Shown::Output(i) => {
            (&f.outputs, if by_event { f.doutputs_total.as_deref() } else { f.doutputs.as_deref() }, i)
        }
        Shown::State(i) => {
            (&f.state, if by_event { f.dstate_total.as_deref() } else { f.dstate.as_deref() }, i)
        }
    };
    let rows = values.len();
    let grad = grads.map(|d| (0..info.n_grad()).map(|j| d[j * rows + i]).collect());
    Some((values[i], grad))
}

impl SweepFigure {
    /// The final outputs (or states) of the complete runs among `results` against parameter
    /// `param` (an index into all parameters), without tangents.
    pub fn new(
        title: &str,
        info: &SystemInfo,
        param: usize,
        points: &[Vec<f64>],
        results: &[PointResult],
        connect: bool,
    ) -> SweepFigure {
        Self::showing(title, info, param, points, results, connect, Shown::default_for(info))
    }

    /// As [`Self::new`], a panel per entry of `shown`.
    pub fn showing(
        title: &str,
        info: &SystemInfo,
        param: usize,
        points: &[Vec<f64>],
        results: &[PointResult],
        connect: bool,
        shown: Vec<Shown>,
    ) -> SweepFigure {
        let mut series: Vec<SweepSeries> = shown
            .iter()
            .map(|q| SweepSeries { name: q.name(info).to_string(), points: Vec::new(), tangents: Vec::new() })
            .collect();
        for (p, r) in points.iter().zip(results) {
            let Ok(r) = r else { continue };
            for (s, &q) in series.iter_mut().zip(&shown) {
                if let Some((v, _)) = quantity(info, r, q) {
                    s.points.push((p[param], v));
                }
            }
        }
        for s in &mut series {
            s.points.sort_by(|a, b| a.0.total_cmp(&b.0));
        }
        SweepFigure {
            title: title.to_string(),
            param: info.param_names[param].clone(),
            series,
            connect,
            shown,
        }
    }

    /// Indices of up to `count` points that ran to their end, spread evenly over the values of
    /// `param` (by rank), where tangents are worth drawing.
    pub fn tangent_points(
        points: &[Vec<f64>],
        results: &[PointResult],
        param: usize,
        count: usize,
    ) -> Vec<usize> {
        let mut complete: Vec<usize> = (0..points.len())
            .filter(|&i| {
                results[i]
                    .as_ref()
                    .is_ok_and(|r| matches!(r.stopped_by, StopReason::TEnd | StopReason::Event { .. }))
            })
            .collect();
        complete.sort_by(|&a, &b| points[a][param].total_cmp(&points[b][param]));
        if complete.len() <= count {
            return complete;
        }
        let last = complete.len() - 1;
        let mut chosen: Vec<usize> = (0..count).map(|c| complete[c * last / (count - 1).max(1)]).collect();
        chosen.dedup();
        chosen
    }

    /// Adds the tangents at `points` from `results` of runs whose shape `info` differentiates
    /// `param` (they may come from the sweep itself or from extra runs made for the plot).
    pub fn add_tangents(
        &mut self,
        info: &SystemInfo,
        param: usize,
        points: &[Vec<f64>],
        results: &[PointResult],
    ) -> Result<(), PlotError> {
        let Some(j) = info.grad_params.iter().position(|&g| g == param) else {
            return Err(PlotError::Empty {
                what: format!("no gradient with respect to {}", info.param_names[param]),
            });
        };
        for (p, r) in points.iter().zip(results) {
            let Ok(r) = r else { continue };
            for (s, &q) in self.series.iter_mut().zip(&self.shown) {
                // Grazing or ended early: no gradient to draw.
                if let Some((y, Some(d))) = quantity(info, r, q) {
                    s.tangents.push(Tangent { x: p[param], y, slope: d[j] });
                }
            }
        }
        Ok(())
    }
}

/// Plots `figure` into `path` (`.svg` or `.png`).
pub fn plot_sweep(figure: &SweepFigure, path: &Path) -> Result<(), PlotError> {
    if figure.series.iter().all(|s| s.points.is_empty()) {
        return Err(PlotError::Empty { what: "no point of the sweep ran to its end".into() });
    }
    render(figure, path)
}

impl Figure for SweepFigure {
    fn panels(&self) -> usize {
        self.series.len()
    }

    fn draw<DB: DrawingBackend>(
        &self,
        root: &DrawingArea<DB, Shift>,
    ) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
        root.fill(&WHITE)?;
        let area = root.titled(&self.title, text(18))?;
        let xs = || self.series.iter().flat_map(|s| s.points.iter().map(|p| p.0));
        let (x0, x1) = padded_range(xs());
        // Tangents span an eighth of the parameter range, centred on their point.
        let half = (x1 - x0) / 16.0;
        for (s, panel) in self.series.iter().zip(&area.split_evenly((self.panels(), 1))) {
            let ends = s.tangents.iter().flat_map(|t| [t.y - t.slope * half, t.y + t.slope * half]);
            let (lo, hi) = padded_range(s.points.iter().map(|p| p.1).chain(ends));
            let mut chart = ChartBuilder::on(panel)
                .margin(6)
                .x_label_area_size(32)
                .y_label_area_size(70)
                .build_cartesian_2d(x0..x1, lo..hi)?;
            chart
                .configure_mesh()
                .x_desc(self.param.as_str())
                .y_desc(s.name.as_str())
                .label_style(text(12))
                .axis_desc_style(text(14))
                .light_line_style(WHITE)
                .draw()?;
            if self.connect {
                chart.draw_series(LineSeries::new(s.points.iter().copied(), DATA_COLOR.mix(0.5)))?;
            }
            chart.draw_series(s.points.iter().map(|&p| Circle::new(p, 3, DATA_COLOR.filled())))?;
            chart.draw_series(s.tangents.iter().map(|t| {
                PathElement::new(
                    vec![(t.x - half, t.y - t.slope * half), (t.x + half, t.y + t.slope * half)],
                    TANGENT_COLOR.stroke_width(2),
                )
            }))?;
        }
        Ok(())
    }
}
