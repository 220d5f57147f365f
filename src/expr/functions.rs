//! The model's functions and their derivatives as DAG roots: what `lower` produces from a checked
//! model and what both the reference evaluator and `codegen` consume.
//!
//! Derivatives are taken with respect to *every* parameter; a consumer that needs only some
//! parameters filters the sparse entries. Sparse containers hold only structurally non-zero
//! entries, in ascending (row, column) order.

use super::node::{ExprId, Lookup};
use super::store::ExprStore;

/// A sparse vector: `(index, expression)` for each structurally non-zero entry, ascending.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SparseVec {
    /// `(index, expression)`, ascending by index.
    pub entries: Vec<(u32, ExprId)>,
}

/// A sparse matrix: `(row, column, expression)` for each structurally non-zero entry, ascending
/// by row, then column.
#[derive(Clone, Debug, PartialEq)]
pub struct SparseMat {
    /// Rows.
    pub n_rows: u32,
    /// Columns.
    pub n_cols: u32,
    /// `(row, column, expression)`, ascending by row, then column.
    pub entries: Vec<(u32, u32, ExprId)>,
}

/// Flow of one mode: `der(x) = f(t, x, p)`.
#[derive(Clone, Debug, PartialEq)]
pub struct ModeFunctions {
    /// `f[i]`, one per state.
    pub flow: Vec<ExprId>,
    /// `df_i/dx_k`: n_states x n_states.
    pub flow_x: SparseMat,
    /// `df_i/dp_j`: n_states x n_params.
    pub flow_p: SparseMat,
    /// `df_i/dt`.
    pub flow_t: SparseVec,
    /// The lookups (`pwl`, `pwc`) of the vectors the flow reads through lookups only (no element
    /// written out, no `sum` or `dot`), ascending by node: the adjoint's `f_p^T w` takes such a
    /// vector as `c_L = sum_i w_i df_i/dL` per lookup `L`, scattered onto the (at most two)
    /// elements `L` reads at its position, instead of one `flow_p` entry per element (which
    /// `flow_p` still holds, for the forward sensitivities).
    pub lookups: Vec<FlowLookup>,
}

/// A lookup a mode's flow reads, of a vector the flow reads through lookups only
/// ([`ModeFunctions::lookups`]).
#[derive(Clone, Debug, PartialEq)]
pub struct FlowLookup {
    /// The lookup node `Lookup(lookup, position)`.
    pub node: ExprId,
    /// How it reads which vector.
    pub lookup: Lookup,
    /// Its knot position.
    pub position: ExprId,
    /// `df_i/dL`, the flow's derivative with respect to the lookup's value taken as an
    /// independent variable (`Var::Node`): `df_i/du_j` is the sum over the vector's lookups of
    /// `df_i/dL` times `u_j`'s weight at `L`'s position. Structurally nonzero rows only.
    pub flow_l: SparseVec,
}

/// One event: guard, enabling condition and reset map with their derivatives.
#[derive(Clone, Debug, PartialEq)]
pub struct EventFunctions {
    /// `g(t, x, p) = lhs - rhs`.
    pub guard: ExprId,
    /// `dg/dx`.
    pub guard_x: SparseVec,
    /// `dg/dp`.
    pub guard_p: SparseVec,
    /// `dg/dt` (the constant 0 node when `t` does not appear).
    pub guard_t: ExprId,
    /// 1.0 where the event is enabled, 0.0 otherwise; `None` means always enabled.
    pub condition: Option<ExprId>,
    /// The whole post-event state `R(t, x, p)`, one entry per state (`x_i` itself where the event
    /// does not assign `x_i`).
    pub reset: Vec<ExprId>,
    /// `dR_i/dx_k`: n_states x n_states (the identity rows for unassigned states).
    pub reset_x: SparseMat,
    /// `dR_i/dp_j`: n_states x n_params.
    pub reset_p: SparseMat,
    /// `dR_i/dt`.
    pub reset_t: SparseVec,
}

/// The knots of an input a mode's flows read (`sim::KnotSet`): its knot position `s(t, p)`,
/// affine in `t`, with knot `k` where `s = k`. The integrator computes the knots' times from it
/// when a run starts, and their motion `dt_k/dp = -s_p / s_t` where a `pwc` knot jumps.
#[derive(Clone, Debug, PartialEq)]
pub struct KnotFunctions {
    /// `s(t, p)`: the node the input's value reads (hash-consing), so that the knots' times and
    /// the value agree on the side of every knot to the last bit.
    pub position: ExprId,
    /// `ds/dp`.
    pub position_p: SparseVec,
    /// `ds/dt` (a function of the parameters alone).
    pub position_t: ExprId,
}

/// Everything hybc compiles for one model, sharing one store.
#[derive(Clone, Debug)]
pub struct ModelFunctions {
    /// The store every function's nodes are in.
    pub store: ExprStore,
    /// States.
    pub n_states: u32,
    /// Parameters.
    pub n_params: u32,
    /// Indexed by `ModeId`.
    pub modes: Vec<ModeFunctions>,
    /// Indexed by `EventIdx`.
    pub events: Vec<EventFunctions>,
    /// The modes' input knots, in the order of `sim::SystemInfo::knots` (mode by mode, each
    /// mode's inputs in `sema::Mode::inputs`' order).
    pub knots: Vec<KnotFunctions>,
    /// Initial state `x0(p)`, one per state.
    pub init: Vec<ExprId>,
    /// `dx0_i/dp_j`: n_states x n_params.
    pub init_p: SparseMat,
    /// Outputs `h(t, x, p)`, one per output.
    pub outputs: Vec<ExprId>,
    /// n_outputs x n_states.
    pub output_x: SparseMat,
    /// n_outputs x n_params.
    pub output_p: SparseMat,
    /// `dh/dt`, per output.
    pub output_t: SparseVec,
}
