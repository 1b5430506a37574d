//! Whether the MME estimates a fit builds on converged, and what `compute_fit` does when
//! one did not ([`UnconvergedMme`]): a network trained on the `d̂` of an estimate that did
//! not converge learns a correction that is not MME's estimate, so by default no network is
//! trained on it.
//!
//! One `not_bracketed` ending counts as converged: a `W` search whose ratio saturated below
//! 1 within the sampling band of a correct model ([`sampling_band`];
//! docs/decisions/mme-ratio-tolerance.md).

use std::collections::BTreeMap;

use serde::Serialize;
use sysid_core::{Dataset, Termination};

use crate::words;

/// Which of `fit`'s MME estimates.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
#[non_exhaustive]
pub enum MmeStage {
    /// MME on the training records with the assumed model: the estimate the network learns
    /// from, or, under the regression update, the one the update reads.
    Training,
    /// MME on the training records again, with the model the regression update gave (the
    /// estimate the network learns from; [`super::ModelUpdateChoice::Regression`]).
    RegressionUpdate,
    /// MME on the validation records at the training `W` and noise variance (the network
    /// sweep's test pairs, and the trajectory training's validation states).
    Validation,
    /// The K-fold guard's MME on a piece of the first training record (or another record)
    /// without a held-out stretch, at the whole record's `W` and noise variance
    /// ([`MmeConvergence::fold`] says which).
    GuardFold,
}

impl MmeStage {
    /// The estimate in words.
    pub fn describe(self) -> &'static str {
        match self {
            Self::Training => "training estimate",
            Self::RegressionUpdate => "re-estimate with the regression-updated model",
            Self::Validation => "validation estimate (at the training W and noise variance)",
            Self::GuardFold => "K-fold guard estimate (at the training W and noise variance)",
        }
    }
}

/// How one of `fit`'s MME estimates ended (`mme_estimates` in `summary.json`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MmeConvergence {
    /// Which estimate.
    pub stage: MmeStage,
    /// How it ended (its [`sysid_core::SolveReport::termination`]): `exact` (linear model,
    /// given `W`), `converged`, or, when the iteration at the final `W` did not converge,
    /// its ending (`max_iterations`, `line_search_failed`), otherwise the `W` search's
    /// (`not_bracketed`, `max_iterations`).
    pub termination: Option<Termination>,
    /// How the automatic `W` search (covariance constraint) ended; `None` for a given `W`
    /// (the validation estimate always uses the training `W`).
    pub w_search: Option<Termination>,
    /// Residual variance over noise variance per measured channel (the covariance
    /// constraint's target is 1): far above 1, `x̂` does not follow the data and `d̂` is not
    /// the correction it needs.
    pub variance_ratio: BTreeMap<String, f64>,
    /// The `W` search's own ratio where it ended (`Σ_i SSE_i/R_i` over the observed
    /// samples); `None` for a given `W`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub w_search_ratio: Option<f64>,
    /// The lower edge of the ratio's sampling band for a correct model
    /// ([`sampling_band`]); `None` for a given `W`. A `W` search that ends `not_bracketed`
    /// with its ratio in `[sampling_band, 1)` counts as converged.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sampling_band: Option<f64>,
    /// For [`MmeStage::GuardFold`]: which fold and which of its records.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fold: Option<FoldEstimate>,
}

/// Which of the K-fold guard's estimates ([`MmeStage::GuardFold`]).
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct FoldEstimate {
    /// The fold, from 1.
    pub index: usize,
    /// Folds in all.
    pub folds: usize,
    /// First and one-past-last sample of the held-out stretch in the first training record.
    pub stretch: (usize, usize),
    /// The record estimated without it (`samples a..b` of the first record, `record k`).
    pub record: String,
}

impl std::fmt::Display for FoldEstimate {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "fold {} of {} (stretch samples {}..{} held out), on {}",
            self.index, self.folds, self.stretch.0, self.stretch.1, self.record
        )
    }
}

/// How many standard deviations of the ratio below its mean the sampling band reaches.
pub const SAMPLING_BAND_Z: f64 = 4.0;

/// The lower edge of the band the `W` search's ratio takes when the assumed model is right
/// and the noise variance is stated correctly, with `observed` output samples and
/// `initial_states` fitted initial states: `1 − p/M − z·√(2/M)` with
/// [`SAMPLING_BAND_Z`]. At the strongest penalty (`d̂ ≈ 0`) the residual is the noise less
/// its projection on the initial states: mean `1 − p/M`, spread `√(2/M)` for Gaussian noise
/// (docs/decisions/mme-ratio-tolerance.md; measured there under the real pipeline).
pub fn sampling_band(observed: usize, initial_states: usize) -> f64 {
    let m = observed as f64;
    1.0 - initial_states as f64 / m - SAMPLING_BAND_Z * (2.0 / m).sqrt()
}

impl MmeConvergence {
    /// The record of an estimate of `data` (the records MME read: their observed output
    /// samples set the sampling band).
    pub fn of(stage: MmeStage, out: &mme_core::MmeOutput, data: &Dataset) -> Self {
        let est = &out.estimate;
        let observed: usize = data
            .experiments()
            .iter()
            .map(|e| e.outputs().iter().filter(|v| v.is_finite()).count())
            .sum();
        let initial_states = est.state_names.len() * est.experiments.len();
        Self {
            stage,
            termination: est.report.termination,
            w_search: out.w_search.as_ref().map(|w| w.termination),
            variance_ratio: est
                .output_names
                .iter()
                .zip(est.residual_variance.iter().zip(&est.noise_variance))
                .map(|(name, (r, n))| (name.clone(), r / n))
                .collect(),
            w_search_ratio: out.w_search.as_ref().map(|w| w.ratio),
            sampling_band: out
                .w_search
                .as_ref()
                .map(|_| sampling_band(observed, initial_states)),
            fold: None,
        }
    }

    /// The record of one of the K-fold guard's estimates.
    pub fn of_fold(out: &mme_core::MmeOutput, data: &Dataset, fold: FoldEstimate) -> Self {
        Self {
            fold: Some(fold),
            ..Self::of(MmeStage::GuardFold, out, data)
        }
    }

    /// Whether it ended `exact` or `converged`, or its `W` search ended `not_bracketed`
    /// below 1 within the sampling band ([`MmeConvergence::within_sampling_band`]): what
    /// [`UnconvergedMme::Refuse`] and `mmenn fit` take for converged (any other ending, or
    /// none, makes `mmenn fit` exit with status 3).
    pub fn converged(&self) -> bool {
        match self.termination {
            Some(Termination::Exact | Termination::Converged) => true,
            Some(Termination::NotBracketed) => self.within_sampling_band(),
            _ => false,
        }
    }

    /// Whether the `W` search ended `not_bracketed` (the iteration at its final `W`
    /// converged) with its ratio below 1 and at least [`MmeConvergence::sampling_band`]:
    /// even the strongest penalty leaves the residual a little under the stated noise
    /// variance, by no more than sampling explains for a correct model. A ratio above 1
    /// that no `W` lowers is a misfit and never counts.
    pub fn within_sampling_band(&self) -> bool {
        match (
            self.termination,
            self.w_search,
            self.w_search_ratio,
            self.sampling_band,
        ) {
            (
                Some(Termination::NotBracketed),
                Some(Termination::NotBracketed),
                Some(ratio),
                Some(band),
            ) => ratio.is_finite() && band.is_finite() && ratio < 1.0 && ratio >= band,
            _ => false,
        }
    }

    /// The `W` search's ending in words, with its ratio against the sampling band when it
    /// ended `not_bracketed` below 1.
    fn w_search_words(&self, w: Termination) -> String {
        let words = words::termination(Some(w));
        match (w, self.w_search_ratio, self.sampling_band) {
            (Termination::NotBracketed, Some(r), Some(b)) if r < 1.0 => {
                if self.within_sampling_band() {
                    format!("{words}; within the sampling band (ratio {r:.3} ≥ {b:.3})")
                } else {
                    format!("{words}; below the sampling band (ratio {r:.3} < {b:.3})")
                }
            }
            (_, Some(r), _) => format!("{words} (ratio {r:.3})"),
            _ => words.to_string(),
        }
    }

    /// How it ended, in words, saying when it was the `W` search and when it was the
    /// iteration at the final `W` (or the fixed `W`).
    pub fn ending(&self) -> String {
        match (self.termination, self.w_search) {
            (t, Some(w)) if t == Some(w) => {
                format!(
                    "W search (covariance constraint): {}",
                    self.w_search_words(w)
                )
            }
            (t, Some(w)) => format!(
                "Gauss–Newton iteration at the final W: {}; W search (covariance constraint): \
                 {}",
                words::termination(t),
                self.w_search_words(w)
            ),
            (t @ (None | Some(Termination::Exact)), None) => words::termination(t).to_string(),
            (t, None) => format!(
                "Gauss–Newton iteration at the given W: {}",
                words::termination(t)
            ),
        }
    }

    /// What usually helps when it did not converge.
    pub fn remedy(&self) -> &'static str {
        match self.termination {
            Some(Termination::NotBracketed) => {
                "no W brings the residual variance to the stated noise variance, and the \
                 ratio is outside the sampling band of a correct model: check the model, and \
                 its noise_variance (or let MME estimate it, \"auto\")"
            }
            Some(Termination::MaxIterations)
                if self.w_search != Some(Termination::MaxIterations) =>
            {
                "raise the iteration limit (EstimateOptions::iterations), or check the \
                 assumed model against the data"
            }
            Some(Termination::LineSearchFailed) => {
                "the iteration stuck where the model's linearisation does not describe it: \
                 check the assumed model (its terms, coefficients and start) against the data"
            }
            _ => "check the assumed model and its noise_variance against the data",
        }
    }
}

impl std::fmt::Display for MmeConvergence {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}", self.stage.describe())?;
        if let Some(fold) = &self.fold {
            write!(f, ", {fold},")?;
        }
        write!(
            f,
            " {} ({}); residual/noise variance: {}",
            if self.converged() {
                "converged"
            } else {
                "did not converge"
            },
            self.ending(),
            words::named_values(&self.variance_ratio)
        )
    }
}

/// What [`super::compute_fit`] does when an MME estimate it builds on did not converge
/// ([`MmeConvergence::converged`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum UnconvergedMme {
    /// Return [`crate::MmennError::MmeNotConverged`] (naming the estimate, its ending and
    /// its residual/noise variance ratios) as soon as that estimate ends, before any network
    /// is trained. The library's default.
    #[default]
    Refuse,
    /// Go on and build the hybrid; [`super::FitSummary::mme_estimates`] records the
    /// ending and [`super::FitSummary::mme_converged`] is false. The command line's
    /// policy: `mmenn fit` writes the results for inspection and exits with status 3.
    Warn,
}
