//! The plot of one run: a panel per state and per output against time, a vertical line at every
//! event, and (for a model with several modes) a shaded band per stretch of time spent in a mode.
//! Lines are broken at events so that a jump is drawn as a jump, not as a steep segment.

use std::ops::Range;
use std::path::Path;

use plotters::coord::Shift;
use plotters::prelude::*;

use super::{padded_range, render, text, Figure, PlotError, DATA_COLOR, EVENT_COLOR};
use crate::report::RunReport;
use crate::sim::TrajectoryRow;

/// Band colours, one per mode (cycled).
const MODE_COLORS: [RGBColor; 6] = [
    RGBColor(0x2c, 0xa0, 0x2c),
    RGBColor(0x94, 0x67, 0xbd),
    RGBColor(0x8c, 0x56, 0x4b),
    RGBColor(0xe3, 0x77, 0xc2),
    RGBColor(0xbc, 0xbd, 0x22),
    RGBColor(0x17, 0xbe, 0xcf),
];

/// A plotted quantity: a state or an output, by index.
#[derive(Clone, Copy)]
enum Variable {
    State(usize),
    Output(usize),
}

impl Variable {
    fn value(self, row: &TrajectoryRow) -> f64 {
        match self {
            Variable::State(i) => row.x[i],
            Variable::Output(i) => row.outputs[i],
        }
    }
}

/// A run with its trajectory, ready to draw.
pub struct RunFigure<'a> {
    report: &'a RunReport,
    rows: &'a [TrajectoryRow],
}

/// Plots `report` (which must hold a trajectory, e.g. from `TrajectoryRequest::Every`) into
/// `path` (`.svg` or `.png`).
pub fn plot_run(report: &RunReport, path: &Path) -> Result<(), PlotError> {
    let rows = report.result().trajectory.as_deref().filter(|rows| rows.len() >= 2).ok_or_else(|| {
        PlotError::Empty { what: "the run recorded no trajectory (ask for one in its SimOptions)".into() }
    })?;
    render(&RunFigure { report, rows }, path)
}

impl RunFigure<'_> {
    /// Every plotted variable: its name and where it is in a row.
    fn variables(&self) -> Vec<(&str, Variable)> {
        let info = self.report.info();
        let states = info.state_names.iter().enumerate().map(|(i, n)| (n.as_str(), Variable::State(i)));
        states
            .chain(info.output_names.iter().enumerate().map(|(i, n)| (n.as_str(), Variable::Output(i))))
            .collect()
    }

    /// `(from, to, mode)` for each stretch of time spent in one mode.
    fn mode_spans(&self) -> Vec<(f64, f64, usize)> {
        let r = self.report.result();
        let mut spans = Vec::new();
        let mut from = self.rows[0].t;
        let mut mode = r.events.first().map_or(r.final_state.mode, |e| e.mode_before);
        for e in &r.events {
            if e.mode_after != mode {
                spans.push((from, e.time, mode));
                (from, mode) = (e.time, e.mode_after);
            }
        }
        spans.push((from, r.final_state.time, mode));
        spans
    }
}

/// Index ranges of `rows` between events. A row at an event's time before the jump belongs to
/// the stretch before it; two rows at the same time with an event there are the two sides of it.
fn segments(rows: &[TrajectoryRow], event_times: &[f64]) -> Vec<Range<usize>> {
    let mut out = Vec::new();
    let (mut start, mut next) = (0, 0);
    for i in 1..rows.len() {
        let (before, t) = (rows[i - 1].t, rows[i].t);
        let mut crossed = false;
        while next < event_times.len() && (event_times[next] < t || (event_times[next] == t && before == t)) {
            crossed = true;
            next += 1;
        }
        if crossed {
            out.push(start..i);
            start = i;
        }
    }
    out.push(start..rows.len());
    out
}

impl Figure for RunFigure<'_> {
    fn panels(&self) -> usize {
        self.report.info().n_states() + self.report.info().n_outputs()
    }

    fn draw<DB: DrawingBackend>(
        &self,
        root: &DrawingArea<DB, Shift>,
    ) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
        root.fill(&WHITE)?;
        let report = self.report;
        let info = report.info();
        let params: Vec<String> =
            info.param_names.iter().zip(report.params()).map(|(n, v)| format!("{n} = {v}")).collect();
        let area = root.titled(&format!("{}   ({})", report.model(), params.join(", ")), text(18))?;
        let (t0, t1) =
            (self.rows[0].t, report.result().final_state.time.max(self.rows[self.rows.len() - 1].t));
        let event_times: Vec<f64> = report.result().events.iter().map(|e| e.time).collect();
        let segments = segments(self.rows, &event_times);
        let spans = if info.modes.len() > 1 { self.mode_spans() } else { Vec::new() };
        let panels = area.split_evenly((self.panels(), 1));
        for (p, ((name, var), panel)) in self.variables().into_iter().zip(&panels).enumerate() {
            let (lo, hi) = padded_range(self.rows.iter().map(|r| var.value(r)));
            let mut chart = ChartBuilder::on(panel)
                .margin(6)
                .x_label_area_size(32)
                .y_label_area_size(70)
                .build_cartesian_2d(t0..t1, lo..hi)?;
            chart
                .configure_mesh()
                .x_desc("t")
                .y_desc(name)
                .label_style(text(12))
                .axis_desc_style(text(14))
                .light_line_style(WHITE)
                .draw()?;
            let mut labelled = vec![false; info.modes.len()];
            for &(from, to, mode) in &spans {
                let color = MODE_COLORS[mode % MODE_COLORS.len()];
                let band = chart.draw_series(std::iter::once(Rectangle::new(
                    [(from, lo), (to, hi)],
                    color.mix(0.15).filled(),
                )))?;
                // One legend entry per mode, in the first panel.
                if p == 0 && !labelled[mode] {
                    labelled[mode] = true;
                    band.label(info.modes[mode].name.as_str()).legend(move |(x, y)| {
                        Rectangle::new([(x, y - 5), (x + 14, y + 5)], color.mix(0.4).filled())
                    });
                }
            }
            chart.draw_series(
                event_times.iter().map(|&t| PathElement::new(vec![(t, lo), (t, hi)], EVENT_COLOR.mix(0.6))),
            )?;
            for seg in segments.iter().filter(|s| s.len() >= 2) {
                chart.draw_series(LineSeries::new(
                    self.rows[seg.clone()].iter().map(|r| (r.t, var.value(r))),
                    DATA_COLOR.stroke_width(2),
                ))?;
            }
            if p == 0 && !spans.is_empty() {
                chart
                    .configure_series_labels()
                    .label_font(text(12))
                    .background_style(WHITE.mix(0.8))
                    .border_style(BLACK)
                    .draw()?;
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rows(ts: &[f64]) -> Vec<TrajectoryRow> {
        ts.iter().map(|&t| TrajectoryRow { t, mode: 0, x: vec![], s: vec![], outputs: vec![] }).collect()
    }

    #[test]
    fn lines_break_at_events_and_between_the_two_sides_of_one() {
        // Samples: the one at 0.5 is before the event there.
        assert_eq!(segments(&rows(&[0.0, 0.25, 0.5, 0.75, 1.0]), &[0.5, 0.8]), vec![0..3, 3..4, 4..5]);
        // Step rows: both sides of the event at 0.5, then two events inside one step.
        assert_eq!(segments(&rows(&[0.0, 0.5, 0.5, 1.0]), &[0.5, 0.6, 0.7]), vec![0..2, 2..3, 3..4]);
        assert_eq!(segments(&rows(&[0.0, 1.0]), &[]), vec![0..2]);
    }
}
