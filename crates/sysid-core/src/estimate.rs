//! The result types of an MME estimate and the report of how its solver ended. They live
//! here (not in `mme-core`) because every consumer — networks, discovery, condition
//! monitoring, the facade — reads them without depending on the estimator.

use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

/// Why an iterative solver stopped. Not converging is reported here, not as an error.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
#[non_exhaustive]
pub enum Termination {
    /// Solved exactly in one pass (linear problems).
    Exact,
    /// The convergence criterion was met.
    Converged,
    /// The iteration budget ran out first.
    MaxIterations,
    /// The line search could not reduce the cost any further.
    LineSearchFailed,
    /// A bracketing search could not bracket a root; the closest end was used.
    NotBracketed,
    /// No damping of a Levenberg–Marquardt step lowered the cost: a stationary point to
    /// working precision, or a Jacobian that does not describe the residuals.
    NoDescent,
    /// The caller ended the solve after an accepted step (early stopping on held-out
    /// data).
    StoppedEarly,
    /// The model could not be evaluated at the starting point.
    Diverged,
    /// Stopped where it started: the solve ended as it would have converged (or found
    /// no descent), but the cost never moved from its start and the Jacobian there is
    /// rank-deficient — a start at a stationary point of a degenerate problem (e.g. an
    /// unmeasured state at a term's singular point, `sqrt(0)`, where its sensitivity is
    /// zero), not an estimate. Only a solve that asks for this test reports it
    /// ([`crate::LmSettings::no_progress`]).
    NoProgress,
}

/// One iteration of an iterative solve.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct IterationRecord {
    /// Iteration number, from 1.
    pub iteration: usize,
    /// Cost after the iteration.
    pub cost: f64,
    /// Size of the step taken (norm of the change), in the solver's own measure.
    pub step_norm: f64,
    /// Line-search step length accepted (1 for a full step).
    pub step_length: f64,
}

/// How a solve went: termination reason, iteration history and time per phase.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct SolveReport {
    /// Why it stopped; `None` until a solve has run.
    pub termination: Option<Termination>,
    /// Iteration history (empty for one-pass solves).
    pub iterations: Vec<IterationRecord>,
    /// Wall time per named phase, seconds.
    pub phase_seconds: Vec<(String, f64)>,
}

/// MME's estimate for one experiment.
///
/// The correction `d` is piecewise constant on `substeps` pieces per sample interval;
/// `corrections` holds every piece (`q × (N−1)·substeps`), starting at `t0`, each lasting
/// `dt / substeps`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ExperimentEstimate {
    /// Time of the first sample, s.
    pub t0: f64,
    /// Sample period, s.
    pub dt: f64,
    /// Sub-steps per sample interval.
    pub substeps: usize,
    /// Estimated states at the sample times, `n × N`.
    pub states: DMatrix<f64>,
    /// Estimated correction pieces, `q × (N−1)·substeps`.
    pub corrections: DMatrix<f64>,
}

impl ExperimentEstimate {
    /// Number of samples.
    pub fn len(&self) -> usize {
        self.states.ncols()
    }

    /// True when there are no samples.
    pub fn is_empty(&self) -> bool {
        self.states.ncols() == 0
    }

    /// The correction at each sample time, `q × N`: the piece that starts at the sample
    /// (the last sample takes the last piece).
    pub fn corrections_at_samples(&self) -> DMatrix<f64> {
        let q = self.corrections.nrows();
        let n = self.len();
        let pieces = self.corrections.ncols();
        DMatrix::from_fn(q, n, |i, k| {
            if pieces == 0 {
                0.0
            } else {
                self.corrections[(i, (k * self.substeps).min(pieces - 1))]
            }
        })
    }
}

/// MME's estimate over all experiments of a dataset, with what it was run with.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MmeEstimate {
    /// State names, in order.
    pub state_names: Vec<String>,
    /// Correction names (one per column of `E`).
    pub correction_names: Vec<String>,
    /// Output (measured channel) names.
    pub output_names: Vec<String>,
    /// One estimate per experiment.
    pub experiments: Vec<ExperimentEstimate>,
    /// The weight `W` used (`q × q`, per unit time: a piece held for `h` costs `h·dᵀWd`).
    pub w: DMatrix<f64>,
    /// Noise variance per measured channel used in `R`.
    pub noise_variance: Vec<f64>,
    /// Sample variance of `ỹ − C x̂` per measured channel.
    pub residual_variance: Vec<f64>,
    /// Value of the MME cost `J` at the optimum.
    pub cost: f64,
    /// How the solve went.
    pub report: SolveReport,
}
