//! The one error type of `mme-core`: every variant says what is wrong and where (matrix,
//! channel, experiment, sample).

use sysid_core::CoreError;
use thiserror::Error;

/// Errors raised by the MME estimator. Not converging is *not* an error: it is reported
/// in [`sysid_core::SolveReport::termination`].
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum MmeError {
    /// An error from the shared vocabulary (model shapes, data, integration).
    #[error(transparent)]
    Core(#[from] CoreError),
    /// A channel the model needs is not in the dataset.
    #[error("the model's {kind} channel '{name}' is not in the dataset")]
    UnknownChannel {
        /// `input` or `output`.
        kind: &'static str,
        /// Channel name.
        name: String,
    },
    /// A noise variance is not positive and finite.
    #[error("noise variance of channel '{channel}' must be positive and finite, got {value}")]
    NonPositiveVariance {
        /// Model output channel name.
        channel: String,
        /// Value given.
        value: f64,
    },
    /// A weight matrix is not symmetric positive definite.
    #[error("weight matrix {matrix} is not symmetric positive definite ({reason})")]
    NotPositiveDefinite {
        /// Which matrix (`W`, `W shape`).
        matrix: &'static str,
        /// What failed.
        reason: &'static str,
    },
    /// A matrix or vector given in the configuration has the wrong size.
    #[error("{what} has size {rows}x{cols}, expected {expected_rows}x{expected_cols}")]
    Dimension {
        /// What was given (`W`, `noise variance`, `initial state`, …).
        what: &'static str,
        /// Rows found.
        rows: usize,
        /// Columns found.
        cols: usize,
        /// Rows expected.
        expected_rows: usize,
        /// Columns expected.
        expected_cols: usize,
    },
    /// A setting names a state the model does not have.
    #[error("{setting}: the model has no state '{name}'")]
    UnknownState {
        /// Which setting (`initial-state prior`).
        setting: &'static str,
        /// The name given.
        name: String,
    },
    /// An entry of the initial-state prior is invalid.
    #[error("initial-state prior of state '{state}': {field} = {value} {reason}")]
    InvalidPrior {
        /// The state's name.
        state: String,
        /// Which field (`mean`, `std`, or `state` for a state given twice).
        field: &'static str,
        /// The value given (NaN for a repeated state).
        value: f64,
        /// What is required.
        reason: &'static str,
    },
    /// A scalar setting is outside its valid range.
    #[error("setting {name} = {value} is invalid: {reason}")]
    InvalidSetting {
        /// Setting name.
        name: &'static str,
        /// Value given.
        value: f64,
        /// What is required.
        reason: &'static str,
    },
    /// The dataset has no experiments.
    #[error("the dataset has no experiments")]
    NoExperiments,
    /// The model has no states.
    #[error("the model has no states: MME needs at least one state")]
    NoStates,
    /// The sub-step grid of an experiment would need more memory than the documented
    /// bound ([`crate::discretize::MAX_SWEEP_BYTES`]).
    #[error(
        "experiment {experiment}: {samples} samples × {substeps} sub-steps = {steps} sub-steps \
         would need about {bytes} bytes of sweep storage, more than the limit of {limit} bytes \
         (use fewer sub-steps or a shorter record)"
    )]
    TooLarge {
        /// Experiment index.
        experiment: usize,
        /// Samples of the experiment.
        samples: usize,
        /// Sub-steps per sample interval.
        substeps: usize,
        /// Sub-steps in all.
        steps: usize,
        /// Estimated bytes.
        bytes: u128,
        /// The limit, bytes.
        limit: u128,
    },
    /// The model's right-hand side or its Jacobian is not finite where the estimator
    /// evaluates it (a term undefined there, e.g. a division by zero).
    #[error(
        "experiment {experiment}: the model is not finite at t = {time} s: {what} in the \
         equation of state '{state}' is {value} (at x = {point:?}); a term in that equation \
         is undefined there (division by zero, log of a non-positive number, overflow?)"
    )]
    NonFiniteModel {
        /// Experiment index.
        experiment: usize,
        /// Time, s.
        time: f64,
        /// Name of the state whose equation is not finite.
        state: String,
        /// What is not finite: `f` or `∂f/∂<state>`.
        what: String,
        /// The value found.
        value: f64,
        /// The state where the model was evaluated.
        point: Vec<f64>,
    },
    /// An experiment is too short.
    #[error("experiment {experiment} has {found} samples, need at least {needed}")]
    TooFewSamples {
        /// Experiment index.
        experiment: usize,
        /// Samples found.
        found: usize,
        /// Samples needed.
        needed: usize,
    },
    /// A measured channel has no (non-missing) samples where some are needed.
    #[error("channel '{channel}' has {found} measured samples, need at least {needed}")]
    TooFewMeasurements {
        /// Model output channel name.
        channel: String,
        /// Non-missing samples found.
        found: usize,
        /// Needed.
        needed: usize,
    },
    /// The initial state is not determined by the data (the information matrix of the
    /// free initial state is not positive definite).
    #[error(
        "experiment {experiment}: the initial state is not observable from the measurements \
         (pivot {pivot} of the initial-state information matrix is {value:e}, relative to its \
         largest diagonal entry)"
    )]
    NotObservable {
        /// Experiment index.
        experiment: usize,
        /// Pivot index (state) where the Cholesky factorisation failed.
        pivot: usize,
        /// Relative pivot value found.
        value: f64,
    },
    /// A sweep lost positive definiteness or produced non-finite numbers (ill-conditioned
    /// problem, or a diverged nonlinear trajectory).
    #[error(
        "experiment {experiment}: numerical breakdown at t = {time} s (sub-step {step}): {what}"
    )]
    Breakdown {
        /// Experiment index.
        experiment: usize,
        /// Sub-step index.
        step: usize,
        /// Time of the sub-step, s.
        time: f64,
        /// What went wrong.
        what: &'static str,
    },
    /// Neither start of the nonlinear estimator led to a finite trajectory: the
    /// data-based start ([`crate::StartTrajectory::FromData`]) gave no finite rollout,
    /// and the fitted start that replaces it then (the model's run from initial states
    /// fitted to the first outputs, measured directions kept from the data) failed too.
    #[error(
        "experiment {experiment}: the nonlinear estimator found no start: from the data, \
         {data_start}; then from the model run from initial states fitted to the first \
         outputs, {fitted_start} (give initial states, or a model that stays finite there)"
    )]
    StartFailed {
        /// Experiment index.
        experiment: usize,
        /// Why the data-based start failed.
        data_start: Box<MmeError>,
        /// Why the fitted start failed.
        fitted_start: Box<MmeError>,
    },
    /// The nonlinear model's trajectory diverged (non-finite or beyond the blow-up bound).
    #[error(
        "experiment {experiment}: nonlinear trajectory diverged at t = {time} s (state {state})"
    )]
    Diverged {
        /// Experiment index.
        experiment: usize,
        /// Time, s.
        time: f64,
        /// State index.
        state: usize,
    },
    /// A regression for the model update has too few usable rows or a singular regressor.
    #[error(
        "model update regression for correction '{correction}' is singular or has too few rows ({rows} rows, {columns} regressors)"
    )]
    SingularRegression {
        /// Correction name.
        correction: String,
        /// Rows used.
        rows: usize,
        /// Regressors.
        columns: usize,
    },
}

/// Result alias for `mme-core`.
pub type Result<T, E = MmeError> = std::result::Result<T, E>;
