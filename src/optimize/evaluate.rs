//! One evaluation of an optimisation problem: one run of the compiled model at a parameter
//! point, read through `fit::evaluate` (the same reading of outputs, states, event times and
//! values at times, with their exact gradients, that a fit uses), then arranged as the smooth
//! program's objective and constraints (equalities first).

use super::solver::SmoothPoint;
use super::spec::{Constraint, Quantity, Sense};
use crate::fit::{self, Rejection, Target};
use crate::sim::{HybridSystem, Runner, SystemInfo};

/// The quantities of a problem, in the order the program sees them.
pub struct Layout {
    /// The objective, then every constraint (equalities first, then inequalities).
    pub quantities: Vec<Quantity>,
    /// Constraints reordered: equalities first.
    pub constraints: Vec<Constraint>,
    pub n_eq: usize,
    /// The run-read quantities as fit targets (goal 0, weight 1: the residual is the value),
    /// and for each quantity its row among them (`None` for a parameter).
    targets: Vec<Target>,
    rows: Vec<Option<usize>>,
}

impl Layout {
    pub fn new(objective: Quantity, constraints: &[Constraint]) -> Layout {
        let mut ordered: Vec<Constraint> =
            constraints.iter().filter(|c| c.sense == Sense::Eq).cloned().collect();
        let n_eq = ordered.len();
        ordered.extend(constraints.iter().filter(|c| c.sense != Sense::Eq).cloned());
        let quantities: Vec<Quantity> =
            std::iter::once(objective).chain(ordered.iter().map(|c| c.quantity)).collect();
        let mut targets = Vec::new();
        let rows = quantities
            .iter()
            .map(|q| match q {
                Quantity::Observable(o) => {
                    targets.push(Target { observable: *o, value: 0.0, weight: 1.0, observed: false });
                    Some(targets.len() - 1)
                }
                Quantity::Param(_) => None,
            })
            .collect();
        Layout { quantities, constraints: ordered, n_eq, targets, rows }
    }

    /// The run-read quantities, for `fit::sample_times`.
    pub fn observables(&self) -> impl Iterator<Item = &crate::fit::Observable> {
        self.targets.iter().map(|t| &t.observable)
    }
}

/// A point's values: every quantity's value, the program's view of them, and the run's event
/// sequence (ids), which says on which smooth piece the point lies.
#[derive(Clone, Debug)]
pub struct Evaluated {
    /// Value of each quantity (objective first, then the constraints in layout order).
    pub values: Vec<f64>,
    pub point: SmoothPoint,
    pub events: Vec<usize>,
}

/// Runs the model at `p` (all parameters) and reads the layout's quantities.
pub fn evaluate<S: HybridSystem + ?Sized>(
    simulator: &mut Runner<&S>,
    info: &SystemInfo,
    layout: &Layout,
    p: &[f64],
) -> Result<Evaluated, Rejection> {
    let read = fit::evaluate(simulator, p, &layout.targets)?;
    let m = info.n_grad();
    let mut values = Vec::with_capacity(layout.quantities.len());
    let mut gradients = Vec::with_capacity(layout.quantities.len());
    for (q, row) in layout.quantities.iter().zip(&layout.rows) {
        match (q, row) {
            (_, Some(i)) => {
                values.push(read.values[*i]);
                gradients.push((0..m).map(|j| read.jacobian[(*i, j)]).collect::<Vec<f64>>());
            }
            (Quantity::Param(j), None) => {
                values.push(p[*j]);
                gradients.push(info.grad_params.iter().map(|&g| if g == *j { 1.0 } else { 0.0 }).collect());
            }
            (Quantity::Observable(_), None) => unreachable!("every observable has a target row"),
        }
    }
    let mut constraints = Vec::with_capacity(layout.constraints.len());
    let mut jacobian = Vec::with_capacity(layout.constraints.len());
    for (k, c) in layout.constraints.iter().enumerate() {
        let (value, slope) = c.normalized(values[k + 1]);
        constraints.push(value);
        jacobian.push(gradients[k + 1].iter().map(|d| slope * d).collect());
    }
    let point =
        SmoothPoint { objective: values[0], gradient: gradients.swap_remove(0), constraints, jacobian };
    Ok(Evaluated { values, point, events: read.events })
}
