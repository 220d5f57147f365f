//! The JIT rejects inconsistent input with a `CodegenError` naming what is wrong, before any
//! native code exists: shapes that disagree with `SystemInfo`, indices out of range, unsorted
//! sparse entries, bad gradient parameter lists.

use crate::support::hand_functions::{ball, ball_info, mat, vec_, E, G};
use hybc::codegen::{CodegenError, CompileOptions, CompiledModel};
use hybc::expr::Node;

fn compile(
    funcs: hybc::expr::ModelFunctions,
    info: hybc::sim::SystemInfo,
) -> Result<CompiledModel, CodegenError> {
    CompiledModel::compile(&funcs, info, &CompileOptions::default())
}

#[test]
fn gradient_parameter_out_of_range() {
    let err = compile(ball(), ball_info(vec![3])).unwrap_err();
    assert!(matches!(err, CodegenError::IndexOutOfRange { index: 3, len: 3, .. }), "{err}");
    assert_eq!(err.to_string(), "gradient parameter index 3 out of range for length 3");
}

#[test]
fn gradient_parameter_listed_twice() {
    let err = compile(ball(), ball_info(vec![E, G, E])).unwrap_err();
    assert!(matches!(err, CodegenError::DuplicateGradParam { param: E }), "{err}");
}

#[test]
fn state_count_disagreeing_with_info() {
    let mut info = ball_info(vec![]);
    info.state_names.push("extra".into());
    let err = compile(ball(), info).unwrap_err();
    assert!(matches!(err, CodegenError::ShapeMismatch { expected: 3, found: 2, .. }), "{err}");
}

#[test]
fn flow_with_a_missing_entry() {
    let mut funcs = ball();
    funcs.modes[0].flow.pop();
    let err = compile(funcs, ball_info(vec![])).unwrap_err();
    assert_eq!(err.to_string(), "mode 0 flow has 1 entries, expected 2");
}

#[test]
fn jacobian_entry_outside_the_matrix() {
    let mut funcs = ball();
    let one = funcs.store.intern(Node::constant(1.0));
    funcs.output_x = mat(2, 2, vec![(0, 0, one), (1, 2, one)]);
    let err = compile(funcs, ball_info(vec![])).unwrap_err();
    assert!(matches!(err, CodegenError::IndexOutOfRange { index: 2, len: 2, .. }), "{err}");
}

#[test]
fn unsorted_or_repeated_sparse_entries() {
    let mut funcs = ball();
    let one = funcs.store.intern(Node::constant(1.0));
    funcs.events[0].reset_x = mat(2, 2, vec![(1, 1, one), (0, 0, one)]);
    let err = compile(funcs, ball_info(vec![])).unwrap_err();
    assert!(matches!(err, CodegenError::UnsortedSparse { position: 1, .. }), "{err}");

    let mut funcs = ball();
    funcs.events[0].guard_x = vec_(vec![(0, one), (0, one)]);
    let err = compile(funcs, ball_info(vec![])).unwrap_err();
    assert!(matches!(err, CodegenError::UnsortedSparse { position: 1, .. }), "{err}");
}

#[test]
fn initial_state_reading_a_state() {
    // x0 may depend on parameters only: its kernel has no state array to read.
    let mut funcs = ball();
    funcs.init[1] = funcs.store.intern(Node::State(0));
    let err = compile(funcs, ball_info(vec![])).unwrap_err();
    assert!(matches!(err, CodegenError::IndexOutOfRange { index: 0, len: 0, .. }), "{err}");
}

#[test]
fn parameter_node_beyond_the_parameter_count() {
    let mut funcs = ball();
    funcs.outputs[0] = funcs.store.intern(Node::Param(7));
    let err = compile(funcs, ball_info(vec![])).unwrap_err();
    assert_eq!(err.to_string(), "parameter index 7 out of range for length 3");
}

#[test]
fn expression_id_not_in_the_store() {
    let mut funcs = ball();
    let len = funcs.store.len();
    funcs.outputs[1] = hybc::expr::ExprId(len as u32 + 5);
    let err = compile(funcs, ball_info(vec![])).unwrap_err();
    assert!(matches!(err, CodegenError::UnknownExpr { .. }), "{err}");
}

#[test]
fn mode_listing_an_unknown_event() {
    let mut info = ball_info(vec![]);
    info.modes[0].events.push(4);
    let err = compile(ball(), info).unwrap_err();
    assert!(matches!(err, CodegenError::IndexOutOfRange { index: 4, len: 1, .. }), "{err}");
}
