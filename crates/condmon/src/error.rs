//! The one error type of `condmon`: every variant says what is wrong and where (which
//! matrix, sample, feature, class, fold or configuration field).

use thiserror::Error;

/// Errors raised when building features, fitting transforms and classifiers, or
/// cross-validating.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum CondmonError {
    /// A matrix has the wrong number of rows (samples) or columns (features).
    #[error("matrix {matrix} has shape {rows}x{cols}, expected {expected_rows}x{expected_cols}")]
    Shape {
        /// Matrix name (`features`, `test features`, …).
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
    /// A slice or list has the wrong length.
    #[error("{what}: length {found}, expected {expected}")]
    Length {
        /// What was measured (`labels`, `feature names`, …).
        what: &'static str,
        /// Length found.
        found: usize,
        /// Length expected.
        expected: usize,
    },
    /// A feature value is NaN or infinite.
    #[error("{matrix} is not finite at sample {sample}, feature {feature}")]
    NonFinite {
        /// Matrix name.
        matrix: &'static str,
        /// Sample (row) index, 0-based.
        sample: usize,
        /// Feature (column) index, 0-based.
        feature: usize,
    },
    /// Fewer samples (or features) than the operation needs.
    #[error("{what}: {found} available, need at least {needed}")]
    TooFewSamples {
        /// What needed them.
        what: &'static str,
        /// Number available.
        found: usize,
        /// Minimum needed.
        needed: usize,
    },
    /// The labels name fewer distinct classes than a classifier needs (at least two).
    #[error("{what}: {found} distinct class(es), need at least 2")]
    TooFewClasses {
        /// Where the labels came from (`training labels`, `training fold 3`, …).
        what: &'static str,
        /// Distinct classes found.
        found: usize,
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
    /// A covariance matrix is singular (or too ill-conditioned to factor) after the
    /// configured regularisation.
    #[error(
        "{what} covariance is singular (class {class:?}, eigenvalue ratio {ratio:e}, \
         regularisation {regularisation})"
    )]
    SingularCovariance {
        /// Which covariance (`pooled`, `class`).
        what: &'static str,
        /// Class label for per-class covariances.
        class: Option<usize>,
        /// Smallest / largest eigenvalue of the regularised matrix.
        ratio: f64,
        /// Regularisation weight that was in use.
        regularisation: f64,
    },
    /// Every feature is constant, so no variance-based method can be fitted.
    #[error("{what}: every feature has zero variance")]
    ZeroVariance {
        /// Which fit.
        what: &'static str,
    },
    /// Canonicalisation is defined here for networks with exactly one hidden layer.
    #[error(
        "weight canonicalisation needs exactly one hidden layer, the network has {hidden_layers}"
    )]
    UnsupportedArchitecture {
        /// Number of hidden layers found.
        hidden_layers: usize,
    },
    /// Feature vectors to be stacked do not carry the same names in the same order.
    #[error(
        "feature sample {sample} has name {found:?} at position {position}, expected {expected:?}"
    )]
    FeatureNameMismatch {
        /// Sample index.
        sample: usize,
        /// Feature position.
        position: usize,
        /// Name found.
        found: String,
        /// Name expected (from sample 0).
        expected: String,
    },
    /// A step failed inside one cross-validation fold.
    #[error("cross-validation fold {fold}: {source}")]
    Fold {
        /// Fold index, 0-based (the left-out sample's index for leave-one-out).
        fold: usize,
        /// What went wrong there.
        source: Box<CondmonError>,
    },
    /// Building a network from canonicalised weights failed.
    #[error("network error: {0}")]
    Network(#[from] nn::NnError),
    /// linfa's Gaussian naive Bayes failed to fit.
    #[error("naive Bayes fit failed: {0}")]
    NaiveBayes(#[from] linfa_bayes::NaiveBayesError),
    /// linfa-nn could not build or query its neighbour index.
    #[error("nearest-neighbour index: {0}")]
    NeighbourBuild(#[from] linfa_nn::BuildError),
    /// linfa-nn query failed.
    #[error("nearest-neighbour query: {0}")]
    NeighbourQuery(#[from] linfa_nn::NnError),
}

/// Result alias for this crate.
pub type Result<T> = std::result::Result<T, CondmonError>;
