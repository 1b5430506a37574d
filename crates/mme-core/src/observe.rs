//! What an estimate is doing while it runs, told to an observer the caller passes
//! ([`MmeObserver`]): the steps that cost time — the noise-variance search's likelihood
//! evaluations, each trial `W` of the automatic search, each Gauss–Newton iteration of
//! the nonlinear estimator, each pass of the robust estimate — and the start of each
//! phase.
//!
//! The observer only watches: the estimate computes the same bits with or without one
//! (tested), and this crate never prints; turning events into a bar, a log line or
//! nothing is the caller's business. Events are small `Copy` values built on the stack,
//! one per solve or iteration (never per sample). An observer must be `Sync`: estimates
//! may run on several threads at once and report through the same reference.
//!
//! Order of events of one estimate: [`MmeEvent::Phase`] with [`MmePhase::NoiseVariance`]
//! when the noise variance is estimated (then the `W` trials of its covariance-constraint
//! start, then one [`MmeEvent::NoiseStep`] per likelihood evaluation), then
//! [`MmePhase::WeightSearch`] when `W` is automatic (one [`MmeEvent::WTrial`] per trial,
//! in the order tried; sorted by `α` they are [`crate::MmeOutput::w_curve`]), then
//! [`MmePhase::FinalSolve`]. A nonlinear estimate reports [`MmeEvent::Iteration`] inside
//! every solve (a likelihood evaluation, a `W` trial and the final solve each run their
//! own Gauss–Newton iterations, numbered from 1); those after `FinalSolve` are
//! `report.iterations`. A robust estimate wraps this: the events of each inner estimate,
//! then one [`MmeEvent::RobustPass`] per pass.

/// A phase of an estimate, announced as it begins.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum MmePhase {
    /// The noise-variance search (maximum restricted marginal likelihood); only when the
    /// noise variance is estimated.
    NoiseVariance,
    /// The automatic `W` search (covariance constraint); only when `W` is automatic.
    WeightSearch,
    /// The solve at the final `(W, R)`: one exact sweep for a linear model, Gauss–Newton
    /// iterations for a nonlinear one.
    FinalSolve,
}

/// One step of an estimate.
#[derive(Debug, Clone, Copy, PartialEq)]
#[non_exhaustive]
pub enum MmeEvent {
    /// A phase begins.
    Phase(MmePhase),
    /// One evaluation of the noise-variance likelihood finished (a solve at a trial
    /// `(W, R)`). The search has no fixed count: a grid over `log β`, extended while its
    /// minimum sits on an edge, then Nelder–Mead until the simplex settles.
    NoiseStep {
        /// Evaluations so far, counted as [`crate::NoiseReport::evaluations`] counts them
        /// (the covariance-constraint start's `W` trials included).
        evaluation: usize,
        /// `−2 log L` concentrated over the common scale (up to a constant); infinite
        /// where the trial is infeasible. The last evaluation is the solve at the optimum
        /// that yields the variances.
        neg2_log_likelihood: f64,
    },
    /// One trial `W = α·shape` of the automatic search finished.
    WTrial {
        /// Trial number within this search, from 1.
        trial: usize,
        /// Most trials the search may use ([`crate::AutoWeight::max_evaluations`]).
        max_trials: usize,
        /// `α` tried.
        alpha: f64,
        /// The covariance-constraint ratio reached (residual over noise variance).
        ratio: f64,
        /// The ratio sought ([`crate::AutoWeight::target_ratio`]).
        target: f64,
    },
    /// One Gauss–Newton iteration of the nonlinear estimator finished.
    Iteration {
        /// Iteration within the current solve, from 1.
        iteration: usize,
        /// Most iterations per solve ([`crate::IterationOptions::max_iterations`]).
        max_iterations: usize,
        /// `J` after the iteration (summed over experiments).
        cost: f64,
        /// `|J_before − J_after| / |J_after|`, the measure the convergence test compares
        /// with `tolerance` (infinite after a start that is not a rollout).
        relative_change: f64,
        /// [`crate::IterationOptions::cost_tolerance`].
        tolerance: f64,
    },
    /// One pass of the robust (Huber) estimate finished.
    RobustPass {
        /// Pass number, from 1.
        pass: usize,
        /// Most passes ([`crate::RobustConfig::max_passes`]).
        max_passes: usize,
        /// Largest move of a pseudo-observation, in noise standard deviations.
        moved: f64,
        /// The move below which the passes stop ([`crate::RobustConfig::tolerance`]).
        tolerance: f64,
    },
}

/// Receives the events of an estimate, possibly from several threads at once. Any
/// `Fn(&MmeEvent) + Sync` closure is one; [`NoObserver`] ignores everything.
pub trait MmeObserver: Sync {
    /// A step of the estimate happened.
    fn event(&self, event: &MmeEvent);
}

impl<F: Fn(&MmeEvent) + Sync> MmeObserver for F {
    fn event(&self, event: &MmeEvent) {
        self(event)
    }
}

/// Ignores every event (what the entry points without an observer pass).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct NoObserver;

impl MmeObserver for NoObserver {
    fn event(&self, _event: &MmeEvent) {}
}
