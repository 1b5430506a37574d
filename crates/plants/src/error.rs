//! The one error type of `plants`: every variant names the system, parameter, request
//! field or signal setting that is wrong, and the value it had.

use sysid_core::CoreError;
use thiserror::Error;

/// Errors raised while building plants, signals, noise or simulated experiments.
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum PlantError {
    /// No system of that name is registered (see [`crate::systems`]).
    #[error("unknown system '{name}'")]
    UnknownSystem {
        /// The name asked for.
        name: String,
    },
    /// A recipe name other than `train` / `test`.
    #[error("unknown recipe '{name}' (expected 'train' or 'test')")]
    UnknownRecipe {
        /// The name asked for.
        name: String,
    },
    /// A parameter override names no parameter of the system.
    #[error("system '{system}' has no parameter '{name}'")]
    UnknownParameter {
        /// System name.
        system: &'static str,
        /// The parameter name given.
        name: String,
    },
    /// A physical parameter is outside its valid range (or not finite).
    #[error("parameter '{name}' of system '{system}' = {value} is invalid: {reason}")]
    InvalidParameter {
        /// System name.
        system: &'static str,
        /// Parameter name.
        name: String,
        /// Value given.
        value: f64,
        /// What is required.
        reason: &'static str,
    },
    /// A field of a [`crate::SimulationRequest`] is invalid.
    #[error("request field '{field}' = {value} is invalid: {reason}")]
    InvalidRequest {
        /// Field name (`fs`, `noise_variance`, `duration`, …).
        field: &'static str,
        /// Value given.
        value: f64,
        /// What is required.
        reason: &'static str,
    },
    /// A setting of an excitation signal is invalid.
    #[error("signal '{signal}': setting '{field}' = {value} is invalid: {reason}")]
    InvalidSignal {
        /// Signal kind (`sine`, `multisine`, `chirp`, `aprbs`, `steps`, `prbs`).
        signal: &'static str,
        /// Setting name.
        field: &'static str,
        /// Value given.
        value: f64,
        /// What is required.
        reason: &'static str,
    },
    /// A scalar argument of a helper (noise, resampling) is invalid.
    #[error("argument '{name}' = {value} is invalid: {reason}")]
    InvalidArgument {
        /// Argument name.
        name: &'static str,
        /// Value given.
        value: f64,
        /// What is required.
        reason: &'static str,
    },
    /// Integrating a truth system failed (divergence, step-size underflow, step budget).
    #[error("simulating system '{system}' failed: {source}")]
    Simulation {
        /// System name.
        system: &'static str,
        /// What the integrator reported (carries the time).
        #[source]
        source: CoreError,
    },
    /// Building a model, dataset or matrix failed in `sysid-core`.
    #[error(transparent)]
    Core(#[from] CoreError),
}

/// Result alias for `plants`.
pub type Result<T, E = PlantError> = std::result::Result<T, E>;
