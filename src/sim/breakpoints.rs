//! Stage 5 (sim): breakpoints, the times the integrator lands on exactly: a step that would pass
//! one is clipped to end on it. `t_end` is always the last; time events and input knots join
//! them. Knows nothing of models or methods.

/// Sorted times to land on, consumed in order as the run passes them.
#[derive(Clone, Debug, Default)]
pub(crate) struct Breakpoints {
    times: Vec<f64>,
    next: usize,
}

impl Breakpoints {
    /// Starts a run: forgets the times of an earlier run and lands on `t_end` last.
    pub fn reset(&mut self, t_end: f64) {
        self.times.clear();
        self.times.push(t_end);
        self.next = 0;
    }

    /// Adds a time to land on (before `sort`).
    pub fn add(&mut self, t: f64) {
        self.times.push(t);
    }

    /// Orders the times after the last `add`.
    pub fn sort(&mut self) {
        self.times.sort_by(f64::total_cmp);
        self.times.dedup();
    }

    /// The first breakpoint strictly after `t` (`t_end` itself when `t` is at or past it). The
    /// ones at or before `t` are consumed.
    pub fn next_after(&mut self, t: f64) -> f64 {
        while self.next + 1 < self.times.len() && self.times[self.next] <= t {
            self.next += 1;
        }
        self.times[self.next]
    }
}
