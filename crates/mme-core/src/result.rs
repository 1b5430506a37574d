//! What an estimate returns beyond [`sysid_core::MmeEstimate`]: the residual-variance
//! versus `W` curve of the automatic search and the noise-variance report.

use serde::{Deserialize, Serialize};
use sysid_core::{MmeEstimate, Termination};

/// One point of the residual-variance-versus-`W` curve (thesis §2.3).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WCurvePoint {
    /// Scale `α` of `W = α·shape`.
    pub alpha: f64,
    /// Residual mean square `Σ_k r_ik² / n_i` per measured channel at this `α`.
    pub residual_variance: Vec<f64>,
    /// Covariance-constraint ratio `Σ_i Σ_k r_ik²/R_i / Σ_i n_i` (see
    /// [`crate::AutoWeight`]).
    pub ratio: f64,
}

/// How the automatic `W` search ended.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WSearch {
    /// The `α` chosen (`W = α·shape`).
    pub alpha: f64,
    /// The ratio reached at `alpha` (target: [`crate::AutoWeight::target_ratio`]).
    pub ratio: f64,
    /// `Converged` (ratio within tolerance), `NotBracketed` (the ratio never crossed the
    /// target: the end of the search closest to it was used), or `MaxIterations`.
    pub termination: Termination,
    /// Sweeps (or nonlinear solves) used.
    pub evaluations: usize,
}

/// How the noise variance was obtained.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
#[non_exhaustive]
pub enum NoiseMethod {
    /// Given by the user.
    Given,
    /// Maximum restricted (diffuse-initial-state) marginal likelihood of the equivalent
    /// state-space model, computed exactly from the sweep (see [`crate::noise`]).
    MarginalLikelihood,
    /// The difference-based estimate, used when the likelihood is degenerate (its
    /// maximum runs to `R → 0`; see [`crate::noise`]) and it was the lower of the two
    /// model-free references.
    DifferenceBased,
    /// The spectral floor (the lowest band of the Welch periodogram), used when the
    /// likelihood is degenerate and it was below the difference-based estimate in some
    /// channel (signals with content near the Nyquist frequency; see [`crate::noise`]).
    SpectralFloor,
}

/// The noise variances used and how they were found.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NoiseReport {
    /// Method.
    pub method: NoiseMethod,
    /// Variance per model output channel, used as `R`.
    pub variance: Vec<f64>,
    /// Difference-based estimate per channel (normalised second differences; the start
    /// point of the likelihood search and a cross-check). Empty when the noise was given.
    pub difference_based: Vec<f64>,
    /// Spectral floor per channel: the lowest band mean of the Welch periodogram, an upper
    /// bound on the white noise that signal content near the Nyquist frequency does not
    /// inflate (`None` when the records are too short for it). Empty when the noise was
    /// given.
    #[serde(default)]
    pub spectral_floor: Vec<Option<f64>>,
    /// The `α` maximising the likelihood (`W = α·shape`); `None` when the noise was given.
    pub likelihood_alpha: Option<f64>,
    /// `−2 log L` at the maximum (up to a constant); `None` when the noise was given.
    pub neg2_log_likelihood: Option<f64>,
    /// Likelihood evaluations (sweeps) used.
    pub evaluations: usize,
}

/// The full result of an estimate.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MmeOutput {
    /// States, corrections, `W`, `R`, residual variances, cost and solve report.
    pub estimate: MmeEstimate,
    /// Every `(α, residual variance)` the automatic `W` search evaluated, sorted by `α`
    /// (empty for a fixed `W`).
    pub w_curve: Vec<WCurvePoint>,
    /// How the automatic `W` search ended (`None` for a fixed `W`).
    pub w_search: Option<WSearch>,
    /// The noise variances and how they were found.
    pub noise: NoiseReport,
}
