//! Stage 5 (sim): the weighted sums of Runge-Kutta stages that every step, error estimate and
//! dense output is made of, in blocks of components (up to 16 at once) so each stage block is
//! read once. Knows only the stage layout (`nz`-long blocks) and [`Terms`]; nothing of methods or models.
//!
//! The one place in `sim` with `unsafe`: the AVX build of the sums behind a run-time CPU check,
//! and block loads checked once per tableau row instead of once per term.
#![allow(unsafe_code)]

use super::tableau::Terms;

/// `out_i = init(i) + sum_j (scale w_j) k_{j,i}` for the first `out.len()` components, summed in
/// ascending stage order over the nonzero weights `w` of one tableau row (`k` holds the stages as
/// blocks of `nz`). Blocks of components (up to 16 at once) are summed in registers, so each stage
/// block is read once, `out` written once, and the index arithmetic and bounds checks are paid
/// per block rather than per component.
#[inline(always)]
pub(crate) fn stage_sum<I: Fn(usize) -> f64>(
    k: &[f64],
    nz: usize,
    terms: &Terms,
    scale: f64,
    init: I,
    out: &mut [f64],
) {
    sum_blocks::<false, I>(k, nz, terms, scale, init, out)
}

/// `out_i = sum_j w_j (k_{j,i} - k_{0,i})` for a row whose weights sum to zero (the error
/// estimators and the dense-output corrections): equal to `sum_j w_j k_{j,i}` in exact
/// arithmetic, but the part of the derivative common to all stages cancels before it is
/// weighted instead of after. Where the derivative hardly changes over a step (tight
/// tolerances, nearly polynomial solutions) the plain sum leaves round-off of size
/// `eps |f| max |w_j|` in the error estimate, which at rtol 1e-10 can exceed the true error and
/// hold the step size down (on the bouncing ball, whose flights every pair integrates exactly).
#[inline(always)]
pub(crate) fn centred_sum(k: &[f64], nz: usize, terms: &Terms, out: &mut [f64]) {
    sum_blocks::<true, _>(k, nz, terms, 1.0, |_| 0.0, out)
}

/// Component `i` of [`centred_sum`] alone, with the same operations in the same order (the same
/// bits): a dense output built for the components its reader needs.
#[inline]
pub(crate) fn centred_sum_at(k: &[f64], nz: usize, terms: &Terms, i: usize) -> f64 {
    let stages_end = (terms.last_stage() + 1).checked_mul(nz);
    assert!(i < nz && stages_end.is_some_and(|end| end <= k.len()), "stage sum outside the stages");
    let mut out = [0.0];
    // SAFETY: `i + 1 <= nz`, with the check above.
    unsafe { sum_block::<1, true, _>(k, nz, terms, 1.0, &|_| 0.0, i, &mut out) };
    out[0]
}

#[inline(always)]
fn sum_blocks<const CENTRED: bool, I: Fn(usize) -> f64>(
    k: &[f64],
    nz: usize,
    terms: &Terms,
    scale: f64,
    init: I,
    out: &mut [f64],
) {
    // Up to 16 components in one block of exactly their number (`sum_narrow`), more in blocks of
    // eight (`sum_blocks_portable`), each in a function of its own (the hopper's sweep took 4%
    // fewer instructions than with both in one).
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx") {
        if out.len() <= 16 {
            // SAFETY: the CPU supports AVX (checked just above).
            unsafe { sum_narrow_avx::<CENTRED, I>(k, nz, terms, scale, init, out) };
        } else {
            // SAFETY: the CPU supports AVX (checked just above).
            unsafe { sum_blocks_avx::<CENTRED, I>(k, nz, terms, scale, init, out) };
        }
        return;
    }
    if out.len() <= 16 {
        sum_narrow::<CENTRED, I>(k, nz, terms, scale, init, out)
    } else {
        sum_blocks_portable::<CENTRED, I>(k, nz, terms, scale, init, out)
    }
}

/// [`sum_narrow`] compiled for AVX.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
fn sum_narrow_avx<const CENTRED: bool, I: Fn(usize) -> f64>(
    k: &[f64],
    nz: usize,
    terms: &Terms,
    scale: f64,
    init: I,
    out: &mut [f64],
) {
    sum_narrow::<CENTRED, I>(k, nz, terms, scale, init, out)
}

/// At most 16 components in one block of exactly their number: the weights and stage offsets are
/// read once per term for the whole block (the hopper's 14 components were summed as eight, four
/// and two, each reading them again: a third of the sums' instructions). The operations on each
/// component are those of every other width, in the same order, so the bits do not depend on
/// the blocks.
#[inline(always)]
fn sum_narrow<const CENTRED: bool, I: Fn(usize) -> f64>(
    k: &[f64],
    nz: usize,
    terms: &Terms,
    scale: f64,
    init: I,
    out: &mut [f64],
) {
    let stages_end = (terms.last_stage() + 1).checked_mul(nz);
    assert!(out.len() <= nz && stages_end.is_some_and(|end| end <= k.len()), "stage sum outside the stages");
    if !out.is_empty() {
        // SAFETY: the block is `out`, with the check above.
        unsafe { sum_exact::<CENTRED, I>(k, nz, terms, scale, &init, 0, out) };
    }
}

/// [`sum_blocks_portable`] compiled for AVX: the blocks of eight components are then summed in
/// two 4-wide registers instead of four 2-wide ones. Only the vector width changes (no fused
/// multiply-add, same order of operations), so the results are bit for bit those of the
/// baseline code. Measured: a bouncing-ball run (nz = 8) 3% faster.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
fn sum_blocks_avx<const CENTRED: bool, I: Fn(usize) -> f64>(
    k: &[f64],
    nz: usize,
    terms: &Terms,
    scale: f64,
    init: I,
    out: &mut [f64],
) {
    sum_blocks_portable::<CENTRED, I>(k, nz, terms, scale, init, out)
}

#[inline(always)]
fn sum_blocks_portable<const CENTRED: bool, I: Fn(usize) -> f64>(
    k: &[f64],
    nz: usize,
    terms: &Terms,
    scale: f64,
    init: I,
    out: &mut [f64],
) {
    // Checked once per row instead of per term (the per-term checks took 3% of a
    // bouncing-ball run): every block `sum_block` reads lies in `k`, since each stage is at most
    // the last (they ascend, `Terms`' invariant) and each block ends by `nz` within its stage.
    let stages_end = (terms.last_stage() + 1).checked_mul(nz);
    assert!(out.len() <= nz && stages_end.is_some_and(|end| end <= k.len()), "stage sum outside the stages");
    // Blocks of eight, then four, two and one, as a block of exactly the rest would take (the
    // same operations per component), without a loop over components with a bounds check per
    // term.
    let mut i0 = 0;
    while i0 + 8 <= out.len() {
        // SAFETY: `i0 + 8 <= out.len()`, with the check above.
        unsafe { sum_block::<8, CENTRED, I>(k, nz, terms, scale, &init, i0, &mut out[i0..i0 + 8]) };
        i0 += 8;
    }
    if i0 + 4 <= out.len() {
        // SAFETY: `i0 + 4 <= out.len()`, with the check above.
        unsafe { sum_block::<4, CENTRED, I>(k, nz, terms, scale, &init, i0, &mut out[i0..i0 + 4]) };
        i0 += 4;
    }
    if i0 + 2 <= out.len() {
        // SAFETY: `i0 + 2 <= out.len()`, with the check above.
        unsafe { sum_block::<2, CENTRED, I>(k, nz, terms, scale, &init, i0, &mut out[i0..i0 + 2]) };
        i0 += 2;
    }
    if i0 < out.len() {
        // SAFETY: `i0 + 1 <= out.len()`, with the check above.
        unsafe { sum_block::<1, CENTRED, I>(k, nz, terms, scale, &init, i0, &mut out[i0..i0 + 1]) };
    }
}

/// Components `i0..i0 + out.len()` (at most 16) in one block of that width.
///
/// # Safety
/// As [`sum_block`], with `W = out.len()`.
#[inline(always)]
unsafe fn sum_exact<const CENTRED: bool, I: Fn(usize) -> f64>(
    k: &[f64],
    nz: usize,
    terms: &Terms,
    scale: f64,
    init: &I,
    i0: usize,
    out: &mut [f64],
) {
    macro_rules! widths {
        ($($w:literal)*) => {
            match out.len() {
                // SAFETY: the caller's contract, with `W = out.len()`.
                $($w => unsafe { sum_block::<$w, CENTRED, I>(k, nz, terms, scale, init, i0, out) },)*
                _ => unreachable!("a block of at most 16 components"),
            }
        };
    }
    widths!(1 2 3 4 5 6 7 8 9 10 11 12 13 14 15 16)
}

/// Components `i0..i0 + W` of [`stage_sum`] or (`CENTRED`) [`centred_sum`].
///
/// # Safety
/// `k[j * nz + i0..j * nz + i0 + W]` must be in bounds for every stage `j` of `terms`: the
/// caller checks `i0 + W <= nz` and `(terms.last_stage() + 1) * nz <= k.len()`.
#[inline(always)]
unsafe fn sum_block<const W: usize, const CENTRED: bool, I: Fn(usize) -> f64>(
    k: &[f64],
    nz: usize,
    terms: &Terms,
    scale: f64,
    init: &I,
    i0: usize,
    out: &mut [f64],
) {
    let mut acc: [f64; W] = std::array::from_fn(|l| init(i0 + l));
    let base: [f64; W] = if CENTRED { k[i0..i0 + W].try_into().expect("a block of W") } else { [0.0; W] };
    for (&j, &w) in terms.stages().iter().zip(terms.weights()) {
        let sw = scale * w;
        // SAFETY: in bounds by the caller's contract; `[f64; W]` has the alignment of `f64`.
        let kj: &[f64; W] = unsafe { &*k.as_ptr().add(j * nz + i0).cast::<[f64; W]>() };
        for ((a, kv), b) in acc.iter_mut().zip(kj).zip(&base) {
            *a += sw * (kv - b);
        }
    }
    out.copy_from_slice(&acc);
}

#[cfg(test)]
mod tests {
    use super::super::tableau::DOP853;
    use super::*;

    /// The sums component by component in the plainest form, each term in the same order and
    /// grouping (`(scale w) (k - base)`), for comparison bit for bit.
    fn reference(k: &[f64], nz: usize, terms: &Terms, scale: f64, centred: bool, y: &[f64]) -> Vec<f64> {
        (0..nz)
            .map(|i| {
                let base = if centred { k[i] } else { 0.0 };
                let mut acc = if centred { 0.0 } else { y[i] };
                for (&j, &w) in terms.stages().iter().zip(terms.weights()) {
                    acc += scale * w * (k[j * nz + i] - base);
                }
                acc
            })
            .collect()
    }

    #[test]
    fn every_block_width_gives_the_plain_sums_bits() {
        // Every remainder after the blocks of eight (four, two, one and their combinations), on
        // values of mixed signs and magnitudes, for a stage row and a dense-output row.
        for nz in 1..=19 {
            let k: Vec<f64> = (0..DOP853.all_stages * nz)
                .map(|m| ((m as f64 * 0.7548776662466927).fract() - 0.5) * 10f64.powi((m % 7) as i32 - 3))
                .collect();
            let y: Vec<f64> = (0..nz).map(|i| 1.0 / (i as f64 + 0.3)).collect();
            let (row, dense_row) = (&DOP853.a[9], &DOP853.d[2]);
            let mut out = vec![0.0; nz];
            stage_sum(&k, nz, row, 0.37, |c| y[c], &mut out);
            let want = reference(&k, nz, row, 0.37, false, &y);
            assert!(out.iter().zip(&want).all(|(a, b)| a.to_bits() == b.to_bits()), "{nz}: {out:?} {want:?}");
            centred_sum(&k, nz, dense_row, &mut out);
            let want = reference(&k, nz, dense_row, 1.0, true, &y);
            assert!(out.iter().zip(&want).all(|(a, b)| a.to_bits() == b.to_bits()), "{nz}: {out:?} {want:?}");
            for (i, w) in want.iter().enumerate() {
                assert_eq!(centred_sum_at(&k, nz, dense_row, i).to_bits(), w.to_bits(), "{nz} {i}");
            }
        }
    }
}
