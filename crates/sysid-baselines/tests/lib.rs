//! Integration tests of `sysid-baselines`: correlation against closed forms and simulated
//! processes, output-error fits against known parameters (inputs held or linear between
//! samples), NARX on the pendulum truth, evaluation and residual analysis, and input
//! validation.

#[path = "cases/common.rs"]
mod common;
#[path = "cases/correlation.rs"]
mod correlation;
#[path = "cases/errors.rs"]
mod errors;
#[path = "cases/evaluation.rs"]
mod evaluation;
#[path = "cases/foh.rs"]
mod foh;
#[path = "cases/frols.rs"]
mod frols;
#[path = "cases/narx.rs"]
mod narx;
#[path = "cases/oe.rs"]
mod oe;
#[path = "cases/poly_narx.rs"]
mod poly_narx;
#[path = "cases/subspace.rs"]
mod subspace;
