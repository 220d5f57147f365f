//! hybc's integration tests, built as one crate so that hybc, Cranelift and plotters are linked
//! into one test binary: one module per area, the helpers they share in `support`. `cargo test`
//! runs everything; `cargo test --test it closed_forms` runs one module (any name filter works).

mod support;

mod check_grad;
mod cli_cases;
mod cli_run;
mod closed_forms;
mod compass_gait;
mod convergence;
mod derive_snapshots;
mod detection;
mod doc_outputs;
mod event_edges;
mod event_landing;
mod event_semantics;
mod expr_growth;
mod expr_props;
mod expr_rules;
mod fit;
mod flow_switches;
mod frontend;
mod frontend_props;
mod gradient_existence;
mod hostile_input;
mod inputs;
mod jit_ball;
mod jit_diff;
mod jit_errors;
mod jit_models;
mod juggler;
mod knots;
mod layers;
mod limits;
mod optimize;
mod optimize_many;
mod optimize_problems;
mod optimize_verdicts;
mod periodic;
mod plot;
mod quadrature;
mod relations;
mod run_gradients;
mod samples;
mod sbml;
mod sim_ball;
mod sim_events;
mod sobol;
mod stiff;
mod stiff_chain;
mod stress_events;
mod stress_frontend;
mod sweep;
mod sweep_stream;
mod vector_params;
mod zeno;
