//! The one error type of `discovery`: every variant says what is wrong and where
//! (experiment, row, sample, equation, config field).

use sysid_core::{CoreError, ExprError, TermError};
use thiserror::Error;

/// Errors of the discovery crate.
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum DiscoveryError {
    /// An error of the shared vocabulary (model shapes, integrators, metrics).
    #[error(transparent)]
    Core(#[from] CoreError),
    /// A term could not be added to a model.
    #[error(transparent)]
    Term(#[from] TermError),
    /// A catalogue expression could not be built over the model's variables.
    #[error("effect {effect} for equation '{equation}': expression '{text}': {source}")]
    Expression {
        /// Catalogue name of the effect.
        effect: &'static str,
        /// Name of the state equation.
        equation: String,
        /// The expression text.
        text: String,
        /// What is wrong with it.
        source: ExprError,
    },
    /// A configuration value is out of its valid range.
    #[error("config field {field} = {value} is invalid: {reason}")]
    InvalidConfig {
        /// The field.
        field: &'static str,
        /// The value given.
        value: f64,
        /// What is required.
        reason: &'static str,
    },
    /// A matrix of an experiment has the wrong shape.
    #[error(
        "{what} of experiment {experiment} has shape {rows}x{cols}, expected \
         {expected_rows}x{expected_cols}"
    )]
    Shape {
        /// Which matrix.
        what: &'static str,
        /// Experiment index.
        experiment: usize,
        /// Rows found.
        rows: usize,
        /// Columns found.
        cols: usize,
        /// Rows expected.
        expected_rows: usize,
        /// Columns expected.
        expected_cols: usize,
    },
    /// A value is NaN or infinite where a finite one is required.
    #[error("{what} is not finite at row {row}, sample {sample} of experiment {experiment}")]
    NonFinite {
        /// Which matrix.
        what: &'static str,
        /// Experiment index.
        experiment: usize,
        /// Row index.
        row: usize,
        /// Sample index.
        sample: usize,
    },
    /// A list has the wrong length.
    #[error("{what}: length {found}, expected {expected}")]
    Length {
        /// What was measured.
        what: &'static str,
        /// Length found.
        found: usize,
        /// Length expected.
        expected: usize,
    },
    /// The model's `E` is not a selection matrix, so the corrected equations are unknown.
    #[error("matrix {matrix} must be a selection matrix (one unit entry per column)")]
    NotSelection {
        /// The matrix (`E`).
        matrix: &'static str,
    },
    /// A name that is not a state, input or catalogue effect.
    #[error("unknown {kind} '{name}'")]
    UnknownName {
        /// What kind of name.
        kind: &'static str,
        /// The name.
        name: String,
    },
    /// A noise floor that is negative or not finite.
    #[error("noise floor {what} of equation {equation} is {value}: {reason}")]
    InvalidFloor {
        /// Which quantity (`rms`, `neff_ratio`).
        what: &'static str,
        /// Index of the corrected equation.
        equation: usize,
        /// The value given.
        value: f64,
        /// What is required.
        reason: &'static str,
    },
    /// Too few samples for the statistic asked for.
    #[error("{what}: {found} samples, need at least {needed}")]
    TooFewSamples {
        /// What needed them.
        what: &'static str,
        /// Samples found.
        found: usize,
        /// Minimum needed.
        needed: usize,
    },
    /// A probability distribution with parameters outside its domain.
    #[error("{distribution} distribution with {parameter} = {value} is undefined")]
    Distribution {
        /// Distribution name.
        distribution: &'static str,
        /// Parameter name.
        parameter: &'static str,
        /// Its value.
        value: f64,
    },
    /// A free-run simulation failed at the starting point of a calibration.
    #[error("free-run simulation of experiment {experiment} failed: {source}")]
    Simulation {
        /// Experiment index.
        experiment: usize,
        /// What the integrator reported.
        source: CoreError,
    },
    /// The free run of a validation record failed under the one validation rule
    /// ([`crate::validation`]): its initial-state fit failed from every start, the run
    /// diverged or left finite values.
    #[error(
        "free run of validation record {record} (initial state fitted to its first {window} \
         samples) failed: {source}"
    )]
    ValidationRun {
        /// Index of the validation record.
        record: usize,
        /// Samples of the initial-state fit.
        window: usize,
        /// What the judge reported.
        source: CoreError,
    },
    /// A calibration stopped where it started: the solver ended without moving the cost,
    /// at a rank-deficient Jacobian ([`sysid_core::Termination::NoProgress`]). The start
    /// is a stationary point of a degenerate problem (e.g. a state at a term's singular
    /// point, `sqrt(0)`, or a term that is zero along the whole start trajectory), not a
    /// calibrated model.
    #[error(
        "{what} stopped where it started: the cost did not move and the data determine \
         only {rank} of the {of} calibrated quantities there (a start at a stationary \
         point, e.g. a state at a term's singular point such as sqrt(0))"
    )]
    NoProgress {
        /// Which calibration.
        what: &'static str,
        /// Rank of the column-normalised `JᵀJ` at the start.
        rank: usize,
        /// Quantities calibrated.
        of: usize,
    },
}

/// Result alias of the crate.
pub type Result<T, E = DiscoveryError> = std::result::Result<T, E>;
