//! Whether the MME estimates a fit builds on converged, and what `compute_fit` does when
//! one did not ([`UnconvergedMme`]): a network trained on the `d̂` of an estimate that did
//! not converge learns a correction that is not MME's estimate, so by default no network is
//! trained on it.

use std::collections::BTreeMap;

use serde::Serialize;
use sysid_core::Termination;

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
}

impl MmeStage {
    /// The estimate in words.
    pub fn describe(self) -> &'static str {
        match self {
            Self::Training => "training estimate",
            Self::RegressionUpdate => "re-estimate with the regression-updated model",
            Self::Validation => "validation estimate (at the training W and noise variance)",
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
}

impl MmeConvergence {
    /// The record of an estimate.
    pub fn of(stage: MmeStage, out: &mme_core::MmeOutput) -> Self {
        let est = &out.estimate;
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
        }
    }

    /// Whether it ended `exact` or `converged` (what `mmenn fit` takes for converged; any
    /// other ending, or none, makes it exit with status 3).
    pub fn converged(&self) -> bool {
        matches!(
            self.termination,
            Some(Termination::Exact | Termination::Converged)
        )
    }

    /// How it ended, in words, saying when it was the `W` search.
    pub fn ending(&self) -> String {
        match (self.termination, self.w_search) {
            (t, Some(w)) if t == Some(w) => {
                format!(
                    "W search (covariance constraint): {}",
                    words::termination(t)
                )
            }
            (t, Some(w)) => format!(
                "{}; W search (covariance constraint): {}",
                words::termination(t),
                words::termination(Some(w))
            ),
            (t, None) => words::termination(t).to_string(),
        }
    }

    /// What usually helps when it did not converge.
    pub fn remedy(&self) -> &'static str {
        match self.termination {
            Some(Termination::NotBracketed) => {
                "no W brings the residual variance to the stated noise variance: check the \
                 model's noise_variance (or let MME estimate it, \"auto\")"
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
        write!(
            f,
            "{} {} ({}); residual/noise variance: {}",
            self.stage.describe(),
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
