//! The one error type of `sysid-baselines`: every variant says what is wrong and where
//! (which parameter, channel, experiment, sample or configuration field).

use sysid_core::{CoreError, Horizon};
use thiserror::Error;

/// Errors raised by correlation analysis, NARX and output-error models, residual analysis
/// and evaluation.
///
/// Failing to converge is not an error: fits return a [`sysid_core::SolveReport`] or an
/// [`nn::TrainReport`] with the reason they stopped.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum BaselineError {
    /// An error of the shared vocabulary (data, model shapes, metrics, correlation).
    #[error(transparent)]
    Core(#[from] CoreError),
    /// An error of the network crate (shapes, training configuration).
    #[error(transparent)]
    Network(#[from] nn::NnError),
    /// A configuration value is outside its valid range.
    #[error("configuration field {field} = {value} is invalid: {reason}")]
    InvalidConfig {
        /// Field name.
        field: &'static str,
        /// Value given (counts converted to `f64`).
        value: f64,
        /// What is required.
        reason: &'static str,
    },
    /// The lags (or the initialisation window) need more samples than an experiment has.
    #[error("{what} needs {needed} samples but experiment {experiment} has only {available}")]
    LagsExceedData {
        /// What needed the samples (e.g. `NARX regressor window`).
        what: &'static str,
        /// Experiment index.
        experiment: usize,
        /// Samples needed.
        needed: usize,
        /// Samples available.
        available: usize,
    },
    /// No complete window of measured samples was found to start a simulation from.
    #[error(
        "experiment {experiment}: no window of {window} consecutive measured samples to initialise from"
    )]
    NoInitialWindow {
        /// Experiment index (0 when the caller passed a single experiment).
        experiment: usize,
        /// Window length needed.
        window: usize,
    },
    /// After skipping rows that touch missing samples, too few rows were left.
    #[error("{what}: {found} usable rows, need at least {needed}")]
    TooFewRows {
        /// What needed them.
        what: &'static str,
        /// Rows found.
        found: usize,
        /// Rows needed.
        needed: usize,
    },
    /// Two things that must have the same size do not.
    #[error("dimension mismatch in {what}: found {found}, expected {expected}")]
    Dimension {
        /// What was compared (e.g. `input channels of the dataset vs the model`).
        what: &'static str,
        /// Size found.
        found: usize,
        /// Size expected.
        expected: usize,
    },
    /// A channel of the data does not match the model's channel at that position.
    #[error("{kind} channel {position} is '{found}' in the data but '{expected}' in the model")]
    ChannelMismatch {
        /// `input` or `output`.
        kind: &'static str,
        /// Position in the channel list.
        position: usize,
        /// Name in the data.
        found: String,
        /// Name in the model.
        expected: String,
    },
    /// A model output has no channel of that name in the data.
    #[error("model output '{name}' is not a channel of the data")]
    UnknownOutput {
        /// The model's output name.
        name: String,
    },
    /// A free-parameter name is not of the form `A[i,j]` or `B[i,j]`.
    #[error("free parameter '{name}' is not of the form A[i,j] or B[i,j]: {reason}")]
    BadParameterName {
        /// The name given.
        name: String,
        /// What is wrong with it.
        reason: &'static str,
    },
    /// A free-parameter index is outside its matrix.
    #[error("free parameter '{name}' is outside {matrix}, which is {rows}x{cols}")]
    ParameterIndex {
        /// The name given.
        name: String,
        /// `A` or `B`.
        matrix: &'static str,
        /// Rows of the matrix.
        rows: usize,
        /// Columns of the matrix.
        cols: usize,
    },
    /// A free parameter is listed twice.
    #[error("free parameter '{name}' is listed twice")]
    DuplicateParameter {
        /// The name given.
        name: String,
    },
    /// A parameter (or the initial state) cannot be identified from the data: the
    /// Jacobian of the simulated outputs is (numerically) rank deficient.
    #[error(
        "parameter '{name}' is not identifiable from the data (Jacobian column norm ratio {ratio:e})"
    )]
    Unidentifiable {
        /// The parameter most involved in the null direction.
        name: String,
        /// Smallest over largest singular value of the scaled Jacobian.
        ratio: f64,
    },
    /// The outputs do not determine the state over a window (initial-state estimation).
    #[error("the state is not observable from the {window} samples starting at sample {sample}")]
    Unobservable {
        /// First sample of the window.
        sample: usize,
        /// Window length, samples.
        window: usize,
    },
    /// No prefix count of a FROLS ranking ran free on every K-fold fold.
    #[error(
        "every prefix count of the {ranked} FROLS-ranked terms failed in free run on some of \
         the {folds} K-fold folds"
    )]
    NoStableCount {
        /// Terms ranked.
        ranked: usize,
        /// Folds.
        folds: usize,
    },
    /// A free-run simulation left the blow-up bound or became non-finite.
    #[error("simulation diverged at sample {sample}: {channel} = {value}")]
    Diverged {
        /// Sample index.
        sample: usize,
        /// Channel or state name.
        channel: String,
        /// Value reached.
        value: f64,
    },
    /// A signal the method needs to vary is constant over the rows it uses.
    #[error("{what} does not vary over the {rows} rows used")]
    NoVariation {
        /// Which signal (e.g. `FROLS target output`).
        what: &'static str,
        /// Rows used.
        rows: usize,
    },
    /// A table row was evaluated with a different horizon than the table's.
    #[error("table '{table}' holds {expected} results; row '{row}' is a {found} result")]
    MixedHorizon {
        /// Table title.
        table: String,
        /// Row label.
        row: String,
        /// The table's horizon.
        expected: Horizon,
        /// The row's horizon.
        found: Horizon,
    },
    /// A model's own error (evaluation and residual analysis accept any
    /// [`sysid_core::Model`]).
    #[error("model failed on experiment {experiment}")]
    Model {
        /// Experiment index in the dataset.
        experiment: usize,
        /// The model's error.
        #[source]
        source: Box<dyn std::error::Error + Send + Sync + 'static>,
    },
}

/// Result alias for `sysid-baselines`.
pub type Result<T, E = BaselineError> = std::result::Result<T, E>;

/// Error unless `value` lies in the range described by `ok`.
pub(crate) fn check_config(
    field: &'static str,
    value: f64,
    reason: &'static str,
    ok: bool,
) -> Result<()> {
    if ok {
        Ok(())
    } else {
        Err(BaselineError::InvalidConfig {
            field,
            value,
            reason,
        })
    }
}

/// Error unless the k-step prediction horizon `k` is at least 1.
pub(crate) fn check_horizon(k: usize) -> Result<()> {
    if k == 0 {
        return Err(BaselineError::InvalidConfig {
            field: "k",
            value: 0.0,
            reason: "prediction horizon must be at least 1 step",
        });
    }
    Ok(())
}
