//! Integration tests of `nn`: derivatives against finite differences, training against
//! known answers, determinism, round trips, early stopping and input validation.

#[path = "cases/common.rs"]
mod common;
#[path = "cases/determinism.rs"]
mod determinism;
#[path = "cases/early_stopping.rs"]
mod early_stopping;
#[path = "cases/errors.rs"]
mod errors;
#[path = "cases/jacobian.rs"]
mod jacobian;
#[path = "cases/roundtrip.rs"]
mod roundtrip;
#[path = "cases/training.rs"]
mod training;
#[path = "cases/trajectory.rs"]
mod trajectory;
