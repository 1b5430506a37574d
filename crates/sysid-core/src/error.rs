//! The one error type of `sysid-core`: every variant says *what* is wrong and *where*
//! (matrix, channel, experiment, sample or time).

use thiserror::Error;

/// Errors raised by the shared vocabulary (datasets, models, integrators, metrics).
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum CoreError {
    /// A matrix that must be square is not.
    #[error("matrix {matrix} must be square, got {rows}x{cols}")]
    NotSquare {
        /// Matrix name (`A`, `W`, …).
        matrix: &'static str,
        /// Rows found.
        rows: usize,
        /// Columns found.
        cols: usize,
    },
    /// A matrix or vector has the wrong shape.
    #[error("matrix {matrix} has shape {rows}x{cols}, expected {expected_rows}x{expected_cols}")]
    Shape {
        /// Matrix name.
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
    /// A length does not match what the context requires.
    #[error("{what}: length {found}, expected {expected}")]
    Length {
        /// What was measured.
        what: &'static str,
        /// Length found.
        found: usize,
        /// Length expected.
        expected: usize,
    },
    /// A matrix entry is NaN or infinite.
    #[error("matrix {matrix} has a non-finite entry at ({row}, {col})")]
    NonFiniteMatrix {
        /// Matrix name.
        matrix: &'static str,
        /// Row index (0-based).
        row: usize,
        /// Column index (0-based).
        col: usize,
    },
    /// An input sample is missing or not finite (inputs must be complete).
    #[error(
        "input channel '{channel}' is not finite at sample {sample} of experiment {experiment}"
    )]
    NonFiniteInput {
        /// Channel name.
        channel: String,
        /// Experiment index.
        experiment: usize,
        /// Sample index.
        sample: usize,
    },
    /// A measured value is infinite (missing samples are NaN; infinities are errors).
    #[error("channel '{channel}' is infinite at sample {sample} of experiment {experiment}")]
    InfiniteOutput {
        /// Channel name.
        channel: String,
        /// Experiment index.
        experiment: usize,
        /// Sample index.
        sample: usize,
    },
    /// The sample period is not positive and finite.
    #[error("sample period must be positive and finite, got {dt}")]
    BadSamplePeriod {
        /// The offending period, s.
        dt: f64,
    },
    /// A time vector does not increase.
    #[error("time does not increase at sample {sample}: t = {t} after {t_prev}")]
    NonIncreasingTime {
        /// Sample index where it happens.
        sample: usize,
        /// Previous time, s.
        t_prev: f64,
        /// This time, s.
        t: f64,
    },
    /// A time vector is not uniformly sampled.
    #[error(
        "time is not uniformly sampled at sample {sample}: step {step} differs from {dt} by more than the tolerance"
    )]
    NonUniformTime {
        /// Sample index where it happens.
        sample: usize,
        /// Step found, s.
        step: f64,
        /// Nominal step, s.
        dt: f64,
    },
    /// A channel or state name is not known.
    #[error("unknown {kind} '{name}'")]
    UnknownName {
        /// What kind of name (state, input, output, channel).
        kind: &'static str,
        /// The name.
        name: String,
    },
    /// A name appears twice.
    #[error("duplicate {kind} '{name}'")]
    DuplicateName {
        /// What kind of name.
        kind: &'static str,
        /// The name.
        name: String,
    },
    /// A variance is not positive.
    #[error("variance of '{channel}' must be positive and finite, got {value}")]
    NonPositiveVariance {
        /// Channel name.
        channel: String,
        /// Value given.
        value: f64,
    },
    /// A simulation diverged (non-finite or beyond the blow-up bound).
    #[error("simulation diverged at t = {t} s: state {state} = {value}")]
    Diverged {
        /// Time, s.
        t: f64,
        /// State index.
        state: usize,
        /// Value reached.
        value: f64,
    },
    /// The adaptive integrator needed a step below its minimum.
    #[error("step size underflow at t = {t} s (h = {h})")]
    StepSizeUnderflow {
        /// Time, s.
        t: f64,
        /// Step size tried, s.
        h: f64,
    },
    /// A job's stated budget ran out ([`crate::Budget`]).
    #[error(transparent)]
    BudgetExhausted(#[from] crate::budget::BudgetExhausted),
    /// The adaptive integrator hit its step budget.
    #[error("integrator exceeded {max_steps} steps before t = {t} s")]
    TooManySteps {
        /// Budget.
        max_steps: usize,
        /// Time reached, s.
        t: f64,
    },
    /// A scalar argument is outside its valid range.
    #[error("argument {name} = {value} is invalid: {reason}")]
    InvalidArgument {
        /// Argument name.
        name: &'static str,
        /// Value given.
        value: f64,
        /// What is required.
        reason: &'static str,
    },
    /// A range of samples is outside the data.
    #[error("sample range {start}..{end} is outside 0..{len}")]
    Range {
        /// Start index.
        start: usize,
        /// End index (exclusive).
        end: usize,
        /// Number of samples.
        len: usize,
    },
    /// A parameter estimator was given a model with nothing to estimate.
    #[error(
        "the model has no free parameters (all {parameters} are fixed, or held by equal bounds): \
         nothing to estimate"
    )]
    NoFreeParameters {
        /// Parameters of the model.
        parameters: usize,
    },
    /// A free parameter's start value is outside its bounds (or not finite).
    #[error("parameter '{name}' starts at {value}, outside its bounds [{lower}, {upper}]")]
    ParameterOutsideBounds {
        /// The parameter.
        name: String,
        /// Its start value.
        value: f64,
        /// Lower bound.
        lower: f64,
        /// Upper bound.
        upper: f64,
    },
    /// Too few valid samples for the requested statistic.
    #[error("{what}: {found} valid samples, need at least {needed}")]
    TooFewSamples {
        /// What needed them.
        what: &'static str,
        /// Valid samples found.
        found: usize,
        /// Minimum needed.
        needed: usize,
    },
}

/// Result alias for `sysid-core`.
pub type Result<T, E = CoreError> = std::result::Result<T, E>;

/// Check that every entry of a matrix is finite, naming the matrix otherwise.
pub fn check_finite(matrix: &'static str, m: &nalgebra::DMatrix<f64>) -> Result<()> {
    for j in 0..m.ncols() {
        for i in 0..m.nrows() {
            if !m[(i, j)].is_finite() {
                return Err(CoreError::NonFiniteMatrix {
                    matrix,
                    row: i,
                    col: j,
                });
            }
        }
    }
    Ok(())
}

impl CoreError {
    /// `Ok` when `found == expected`, else [`CoreError::Length`] naming `what`: the one
    /// spelling of a length or dimension check.
    pub fn check_len(what: &'static str, found: usize, expected: usize) -> Result<()> {
        if found == expected {
            Ok(())
        } else {
            Err(CoreError::Length {
                what,
                found,
                expected,
            })
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn check_len_names_what_and_both_lengths() {
        assert_eq!(CoreError::check_len("inputs", 3, 3), Ok(()));
        let e = CoreError::check_len("inputs", 2, 3).unwrap_err();
        assert_eq!(
            e,
            CoreError::Length {
                what: "inputs",
                found: 2,
                expected: 3
            }
        );
    }
}
