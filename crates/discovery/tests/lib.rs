//! Integration tests of `discovery`: known answers from the `plants` truth systems
//! (truth corrections plus coloured noise, so these tests do not depend on `mme-core`),
//! verdicts on pure noise and on an effect outside the library, localisation of an
//! injected disturbance, and calibration by free-run error.

mod calibration;
mod calibration_se;
mod common;
mod known_plants;
mod localisation;
mod verdicts;
