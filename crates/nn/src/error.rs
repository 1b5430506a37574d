//! The one error type of `nn`: every variant says what is wrong and where (which matrix,
//! channel, sample, layer or configuration field).

use thiserror::Error;

/// Errors raised when building, evaluating or training networks.
///
/// Failing to converge is not an error: training returns a
/// [`TrainReport`](crate::TrainReport) with a [`StopReason`](crate::StopReason).
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum NnError {
    /// A data matrix has the wrong number of rows (channels) or columns (samples).
    #[error("matrix {matrix} has shape {rows}x{cols}, expected {expected_rows}x{expected_cols}")]
    Shape {
        /// Matrix name (`inputs`, `targets`, `test inputs`, …).
        matrix: &'static str,
        /// Rows found.
        rows: usize,
        /// Columns found.
        cols: usize,
        /// Rows expected.
        expected_rows: usize,
        /// Columns expected.
        expected_cols: usize,
    },
    /// A slice or vector has the wrong length.
    #[error("{what}: length {found}, expected {expected}")]
    Length {
        /// What was measured (`input sample`, `weight vector`, …).
        what: &'static str,
        /// Length found.
        found: usize,
        /// Length expected.
        expected: usize,
    },
    /// A data entry is NaN or infinite.
    #[error("{matrix} is not finite at channel {channel}, sample {sample}")]
    NonFinite {
        /// Matrix or vector name.
        matrix: &'static str,
        /// Channel (row) index, 0-based.
        channel: usize,
        /// Sample (column) index, 0-based.
        sample: usize,
    },
    /// Too few samples for the requested operation (zero samples, or a split that leaves
    /// one side empty).
    #[error("{what}: {found} samples, need at least {needed}")]
    TooFewSamples {
        /// What needed them.
        what: &'static str,
        /// Samples available.
        found: usize,
        /// Minimum needed.
        needed: usize,
    },
    /// A network dimension is zero (no inputs, no outputs, or an empty hidden layer).
    #[error("network {what} must be at least 1 (layer {layer})")]
    ZeroDimension {
        /// Which dimension (`inputs`, `outputs`, `hidden units`).
        what: &'static str,
        /// Layer index (0 = first hidden layer; the output layer is the last).
        layer: usize,
    },
    /// A scaler's parameters are unusable (non-finite centre, non-positive half-range).
    #[error("scaler channel {channel}: {reason}")]
    BadScaler {
        /// Channel index.
        channel: usize,
        /// What is required.
        reason: &'static str,
    },
    /// A configuration value is outside its valid range.
    #[error("configuration field {field} = {value} is invalid: {reason}")]
    InvalidConfig {
        /// Field name.
        field: &'static str,
        /// Value given (counts are converted to `f64`).
        value: f64,
        /// What is required.
        reason: &'static str,
    },
    /// Networks that cannot be combined (averaged) with the first one.
    #[error("{what} {index} has {reason} than the first")]
    Incompatible {
        /// What was combined.
        what: &'static str,
        /// Index of the offending network, 0-based.
        index: usize,
        /// How it differs.
        reason: &'static str,
    },
    /// Every run of a sizing sweep ended with a non-finite test MSE.
    #[error("none of the {runs} sweep runs has a finite test MSE")]
    NoFiniteRun {
        /// Runs trained.
        runs: usize,
    },
    /// A correction network does not read the number of states it was declared with.
    #[error("correction reads {n_states} states but the network has only {n_inputs} inputs")]
    CorrectionSplit {
        /// States declared.
        n_states: usize,
        /// Network inputs.
        n_inputs: usize,
    },
    /// A correction network's input count is neither the model's states nor its states
    /// and inputs.
    #[error(
        "a correction of a model with {n_states} states and {n_model_inputs} inputs needs a \
         network of {n_states} inputs (states alone) or of the states and inputs, but it has \
         {n_inputs}"
    )]
    CorrectionInputs {
        /// States of the model.
        n_states: usize,
        /// Inputs of the model.
        n_model_inputs: usize,
        /// Network inputs.
        n_inputs: usize,
    },
    /// The hybrid model with the initial network diverges on a shooting window, so
    /// trajectory training has no finite objective to descend from.
    #[error(
        "the hybrid model diverges on the shooting window of record {record} starting at sample {sample}"
    )]
    TrajectoryDiverged {
        /// Record index, 0-based.
        record: usize,
        /// First sample of the window, 0-based.
        sample: usize,
    },
    /// A problem would need more memory than the documented bound.
    #[error(
        "{what} would need about {bytes} bytes ({rows} × {columns}), more than the limit of \
         {limit} bytes; {hint}"
    )]
    TooLarge {
        /// What would be allocated.
        what: &'static str,
        /// Rows.
        rows: usize,
        /// Columns.
        columns: usize,
        /// Estimated bytes.
        bytes: u128,
        /// The limit, bytes.
        limit: u128,
        /// What to do instead.
        hint: &'static str,
    },
}

/// Result alias for `nn`.
pub type Result<T, E = NnError> = std::result::Result<T, E>;

/// Check that every entry of a `channels × samples` matrix is finite.
pub(crate) fn check_finite(matrix: &'static str, m: &nalgebra::DMatrix<f64>) -> Result<()> {
    for sample in 0..m.ncols() {
        for channel in 0..m.nrows() {
            if !m[(channel, sample)].is_finite() {
                return Err(NnError::NonFinite {
                    matrix,
                    channel,
                    sample,
                });
            }
        }
    }
    Ok(())
}

/// Check a `channels × samples` matrix has `rows` channels and `cols` samples.
pub(crate) fn check_shape(
    matrix: &'static str,
    m: &nalgebra::DMatrix<f64>,
    rows: usize,
    cols: usize,
) -> Result<()> {
    if m.nrows() != rows || m.ncols() != cols {
        return Err(NnError::Shape {
            matrix,
            rows: m.nrows(),
            cols: m.ncols(),
            expected_rows: rows,
            expected_cols: cols,
        });
    }
    Ok(())
}
