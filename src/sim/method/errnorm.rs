//! Stage 5 (sim): the step-size error norm over `z = [x, S]`, shared by every stepper.
//!
//! Each block of `n` components, the states and then each sensitivity column, is measured by its
//! own root mean square in units of `atol + rtol |z_i|`, and the step's error is the largest of
//! them (CVODES' `errconS`). One root mean square over all `n (1 + m)` components, as before,
//! let a block exceed its tolerance by `sqrt(1 + m)` while the others were quiet: with 10
//! parameters the states, the derivatives through an event time, or one parameter's column
//! could be 3.3 times less accurate than asked.

/// Whether component `i` of `z = [x, S]` (blocks of `block`) is in the step-size control: not
/// at a position `excluded` marks (empty: every component is).
#[inline(always)]
pub(crate) fn controlled(excluded: &[bool], block: usize, i: usize) -> bool {
    excluded.is_empty() || !excluded[i % block.max(1)]
}

/// Accumulates squared scaled errors component by component (in order) and keeps the largest
/// block norm. `with3` is DOP853's second estimate: a block's norm is then Hairer's
/// `sum5 / sqrt(count (sum5 + 0.01 sum3))` instead of `sqrt(sum5 / count)`.
pub(crate) struct BlockNorm<'e> {
    block: usize,
    /// Positions within a block left out of the norm (the quadrature states); empty: none.
    excluded: &'e [bool],
    next_end: usize,
    sum5: f64,
    sum3: f64,
    used: usize,
    worst: f64,
    /// The largest scaled error of an excluded state (first block only) and its position: a
    /// running cost's own error, kept aside so that the run can say when it was not resolved.
    outside: (f64, usize),
}

impl<'e> BlockNorm<'e> {
    /// Blocks of `block` components (the state count; at least 1), the positions `excluded`
    /// marks left out of every block (empty: none).
    pub(crate) fn new(block: usize, excluded: &'e [bool]) -> BlockNorm<'e> {
        let block = block.max(1);
        BlockNorm {
            block,
            excluded,
            next_end: block,
            sum5: 0.0,
            sum3: 0.0,
            used: 0,
            worst: 0.0,
            outside: (0.0, 0),
        }
    }

    /// Component `i`'s scaled errors (`r3` is 0 without a second estimate), or `None` for a
    /// component left out (a sensitivity that does not exist). Components come in order.
    #[inline(always)]
    pub(crate) fn add(&mut self, i: usize, r: Option<(f64, f64)>, with3: bool) {
        while i >= self.next_end {
            self.close(with3);
        }
        if !self.excluded.is_empty() && self.excluded[i + self.block - self.next_end] {
            // Out of the test, but its error is measured as a block of its own would be, its
            // sensitivities' as well: they need not follow its value (`der(y) = x^p` from
            // x = 0: the value's integrand is smooth enough for the steps, dy/dp's, x^p ln x, is
            // not, and at p = 1 dy/dp came out 4e-5 off at rtol 1e-8 with the value exact).
            if let Some((r5, r3)) = r {
                let e = if with3 { hairer(r5 * r5, r3 * r3, 1.0) } else { r5.abs() };
                if e > self.outside.0 {
                    self.outside = (e, i % self.block);
                }
            }
            return;
        }
        if let Some((r5, r3)) = r {
            self.sum5 += r5 * r5;
            self.sum3 += r3 * r3;
            self.used += 1;
        }
    }

    fn close(&mut self, with3: bool) {
        if self.used > 0 {
            let n = self.used as f64;
            let e = if with3 { hairer(self.sum5, self.sum3, n) } else { (self.sum5 / n).sqrt() };
            // `max` would drop a NaN: a NaN block makes the whole norm NaN.
            self.worst = if e.is_nan() || self.worst.is_nan() { f64::NAN } else { self.worst.max(e) };
        }
        self.next_end += self.block;
        self.sum5 = 0.0;
        self.sum3 = 0.0;
        self.used = 0;
    }

    /// The largest scaled error among the excluded states (the running costs) and the state's
    /// index: above 1, the step would have failed its error test had they been in it. `(0, 0)`
    /// when none is excluded.
    pub(crate) fn outside(&self) -> (f64, usize) {
        self.outside
    }

    /// The largest block norm (0 when nothing was added).
    pub(crate) fn finish(mut self, with3: bool) -> f64 {
        self.close(with3);
        self.worst
    }
}

/// [`BlockNorm`] when every one of the `ne` components counts (none excluded, none left out):
/// `sums(range)` gives a block's sums of squared scaled errors (5th- and 3rd-order), added in
/// component order as [`BlockNorm::add`] adds them, so the norm is its to the bit, without the
/// bookkeeping per component (which cost the hopper's attempts a tenth of their error norm).
#[inline(always)]
pub(crate) fn plain_block_norm<F: FnMut(std::ops::Range<usize>) -> (f64, f64)>(
    block: usize,
    ne: usize,
    with3: bool,
    mut sums: F,
) -> f64 {
    let block = block.max(1);
    let mut worst = 0.0f64;
    let mut start = 0;
    while start < ne {
        let end = (start + block).min(ne);
        let (sum5, sum3) = sums(start..end);
        let n = (end - start) as f64;
        start = end;
        // A block's norm is at most `sqrt(sum5 / n)` (DOP853's denominator is at least `sum5`),
        // so a block whose bound is below the largest norm so far cannot change it: its square
        // root and division, one waiting on the other, were most of the norm's time. The margin
        // covers the few roundings of the norm against its bound; a NaN is never skipped.
        if sum5 < n * worst * worst * (1.0 - 1e-12) {
            continue;
        }
        let e = if with3 { hairer(sum5, sum3, n) } else { (sum5 / n).sqrt() };
        // As `BlockNorm::close`: a NaN block makes the whole norm NaN.
        worst = if e.is_nan() || worst.is_nan() { f64::NAN } else { worst.max(e) };
    }
    worst
}

/// DOP853's norm of `count` components from the sums of their squared 5th- and 3rd-order
/// scaled errors (Hairer's `sum5 / sqrt(count (sum5 + 0.01 sum3))`). A NaN estimate stays NaN
/// (the step is rejected); only a zero one is zero.
#[inline(always)]
fn hairer(sum5: f64, sum3: f64, count: f64) -> f64 {
    let den = sum5 + 0.01 * sum3;
    if den == 0.0 {
        0.0
    } else {
        sum5 / (count * den).sqrt()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_largest_block_counts() {
        // Block 0: errors 1, 1 (norm 1); block 1: 3, 0 (norm sqrt(4.5)); block 2: left out.
        let mut b = BlockNorm::new(2, &[]);
        for (i, r) in [Some(1.0), Some(1.0), Some(3.0), Some(0.0), None, None].into_iter().enumerate() {
            b.add(i, r.map(|r| (r, 0.0)), false);
        }
        assert_eq!(b.finish(false), 4.5f64.sqrt());
        // One root mean square over all four would have been sqrt(11 / 4) = 1.66 < 2.12.
    }

    #[test]
    fn the_plain_norm_is_the_block_norm_to_the_bit() {
        // Blocks of 3 over 8 components (the last short), with and without the second estimate,
        // and a NaN block.
        let r5 = [0.3, -1.7, 2.2e-3, 5.5, 0.0, 1e-9, -0.8, 4.1];
        let r3 = [1.1, 0.2, -7.0, 0.05, 3.0, 2.5, -1e-4, 0.6];
        for with3 in [false, true] {
            for nan in [None, Some(4)] {
                let mut v5 = r5;
                if let Some(i) = nan {
                    v5[i] = f64::NAN;
                }
                let mut b = BlockNorm::new(3, &[]);
                for i in 0..8 {
                    b.add(i, Some((v5[i], if with3 { r3[i] } else { 0.0 })), with3);
                }
                let plain = plain_block_norm(3, 8, with3, |range| {
                    let (mut s5, mut s3) = (0.0, 0.0);
                    for i in range {
                        s5 += v5[i] * v5[i];
                        s3 += r3[i] * r3[i];
                    }
                    (s5, s3)
                });
                assert_eq!(plain.to_bits(), b.finish(with3).to_bits(), "{with3} {nan:?}");
            }
        }
    }

    #[test]
    fn the_plain_norm_skips_no_block_that_matters() {
        // Many draws of blocks whose norms are close, equal (repeated blocks), zero, tiny or huge,
        // infinite or NaN: the plain norm, which skips the blocks its bound rules out, is
        // `BlockNorm`'s to the bit.
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        for case in 0..2000 {
            let block = 1 + (next() * 4.0) as usize;
            let ne = block * (1 + (next() * 12.0) as usize) - (next() * block as f64) as usize % block;
            let mut r5 = vec![0.0; ne];
            let mut r3 = vec![0.0; ne];
            for i in 0..ne {
                let scale = 10f64.powi((next() * 8.0) as i32 - 4);
                r5[i] = match (next() * 40.0) as u32 {
                    0 => 0.0,
                    1 if case % 7 == 0 => f64::INFINITY,
                    2 if case % 11 == 0 => f64::NAN,
                    3 if i >= block => r5[i - block],
                    _ => (next() - 0.5) * scale,
                };
                r3[i] = if i >= block && next() < 0.2 { r3[i - block] } else { (next() - 0.5) * scale };
            }
            for with3 in [false, true] {
                let mut b = BlockNorm::new(block, &[]);
                for i in 0..ne {
                    b.add(i, Some((r5[i], if with3 { r3[i] } else { 0.0 })), with3);
                }
                let plain = plain_block_norm(block, ne, with3, |range| {
                    let (mut s5, mut s3) = (0.0, 0.0);
                    for i in range {
                        s5 += r5[i] * r5[i];
                        s3 += r3[i] * r3[i];
                    }
                    (s5, if with3 { s3 } else { 0.0 })
                });
                let want = b.finish(with3);
                assert!(
                    plain.to_bits() == want.to_bits() || plain.is_nan() && want.is_nan(),
                    "case {case}: {plain} against {want}"
                );
            }
        }
    }

    #[test]
    fn a_nan_block_is_nan() {
        let mut b = BlockNorm::new(1, &[]);
        b.add(0, Some((f64::NAN, 0.0)), false);
        b.add(1, Some((2.0, 0.0)), false);
        assert!(b.finish(false).is_nan());
    }

    #[test]
    fn hairers_combination_per_block() {
        let mut b = BlockNorm::new(1, &[]);
        b.add(0, Some((3.0, 4.0)), true);
        assert_eq!(b.finish(true), 9.0 / (9.0f64 + 0.16).sqrt());
    }

    #[test]
    fn an_excluded_position_is_left_out_of_every_block() {
        // Blocks of 2 with the second position excluded: only 1 and 3 count.
        let mut b = BlockNorm::new(2, &[false, true]);
        for (i, r) in [1.0, 100.0, 3.0, 100.0].into_iter().enumerate() {
            b.add(i, Some((r, 0.0)), false);
        }
        // The excluded state's own error is kept aside, not in the norm.
        assert_eq!(b.outside(), (100.0, 1));
        assert_eq!(b.finish(false), 3.0);
        // Its sensitivities' too, named by the state.
        let mut b = BlockNorm::new(2, &[false, true]);
        for (i, r) in [1.0, 2.0, 3.0, 50.0].into_iter().enumerate() {
            b.add(i, Some((r, 0.0)), false);
        }
        assert_eq!(b.outside(), (50.0, 1));
    }
}
