//! Stage 4: expression DAG -> Cranelift IR -> native kernels behind a safe `CompiledModel`.
//! All `unsafe` in hybc lives in this module.
