//! Quadrature states: states that only accumulate along the trajectory (a running cost such as
//! `der(effort) = u^2`), read by no flow, guard or enabling condition, and by no reset but their
//! own. They take no part in the dynamics: a periodic orbit leaves them out (they grow from
//! period to period by design), and a trajectory optimiser's cost can live in one without the
//! events or the other states depending on it. Outputs may read them.

use super::model::Model;
use super::walk::{StatesRead, Walk};

/// `quadrature[i]`: whether state `i` is a quadrature state of `model`.
pub fn quadrature_states(model: &Model) -> Vec<bool> {
    let n = model.states.len();
    let (mut walk, mut read) = (Walk::new(), StatesRead::new(n));
    for mode in &model.modes {
        for flow in &mode.flows {
            let _ = walk.expr(flow, &mut read);
        }
    }
    let mut own_reset_reads: Vec<StatesRead> = Vec::new();
    for event in &model.events {
        let _ = walk.expr(&event.guard, &mut read);
        if let Some(c) = &event.condition {
            let _ = walk.cond(c, &mut read);
        }
        for (target, value) in &event.resets {
            // A reset may read its own state (`n := n + 1`); any other state's reset may not.
            let mut own = StatesRead::new(n);
            let _ = Walk::new().expr(value, &mut own);
            own.by[target.0 as usize] = false;
            own_reset_reads.push(own);
        }
    }
    for own in own_reset_reads {
        for (r, o) in read.by.iter_mut().zip(own.by) {
            *r |= o;
        }
    }
    read.by.iter().map(|r| !r).collect()
}

#[cfg(test)]
mod tests {
    use super::quadrature_states;

    fn quadrature(text: &str) -> Vec<bool> {
        quadrature_states(&super::super::check(&crate::syntax::parse(text).expect("parses")).expect("checks"))
    }

    #[test]
    fn a_running_cost_is_a_quadrature_state_and_a_state_anything_reads_is_not() {
        let text = "model m\nparam k = 1\nstate x = 1\nstate cost = 0\nstate n = 0\nstate seen = 0\n\
                    der(x) = -k * x\nder(cost) = x^2\nder(n) = 0\nder(seen) = 0\n\
                    event e when x <= 0.5 {\n    n := n + 1\n    seen := if n < 1 then x else seen\n    x := 1\n}\n\
                    output c = cost\n";
        // x: read by its flow; cost: read by an output only; n: by `seen`'s reset; seen: by its
        // own reset only.
        assert_eq!(quadrature(text), vec![false, true, false, true]);
    }

    #[test]
    fn a_state_read_by_a_guard_a_condition_or_its_own_flow_is_not_a_quadrature_state() {
        let text = "model m\nstate x = 1\nstate a = 0\nstate b = 0\nstate c = 1\n\
                    der(x) = -1\nder(a) = 1\nder(b) = 1\nder(c) = -c\n\
                    event e when a >= 2 if b < 1 {\n    x := 1\n}\n";
        assert_eq!(quadrature(text), vec![true, false, false, false]);
    }
}
