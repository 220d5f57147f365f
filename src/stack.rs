//! Deep recursion on demand.
//!
//! A chain of `let`s makes a checked expression as deep as the chain (`sema::MAX_EXPR_DEPTH`
//! levels at most), and the passes over checked expressions (name resolution, the flow-switch
//! and constant checks, lowering) recurse along it. Rather than rewrite each pass as an explicit
//! work list, each recursive step runs through [`deep`], which moves onto a fresh heap-allocated
//! stack segment when less than `RED_ZONE` is left: the depth is bounded by the expression cap,
//! not by the calling thread's stack (2 MiB for a test thread, 8 MiB for `main`).

/// Stack that must remain before a recursive step continues on the current segment.
const RED_ZONE: usize = 128 * 1024;
/// Size of each new segment.
const SEGMENT: usize = 2 * 1024 * 1024;

/// Runs `f`, on a new stack segment if the current one is nearly used up.
pub fn deep<R>(f: impl FnOnce() -> R) -> R {
    stacker::maybe_grow(RED_ZONE, SEGMENT, f)
}
