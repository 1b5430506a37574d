//! Multi-start of `mmenn greyest` (`--starts N --seed S`): the same estimation from the
//! model file's own start (start 0) and from `N` seeded starts, the lowest final free-run
//! cost kept, and a plain statement when another start reaches nearly the same cost with
//! materially different parameters (the data do not pin them). Every converged start is
//! probed: which free parameters the records do not exercise there (no effect on the free
//! run: reported as such, and never what makes two minima differ), and whether the point
//! is a minimum at all (a saddle is listed as a start, not as a minimum).
//!
//! **The draw.** Start `k` (1 ≤ k ≤ N) takes a `ChaCha8Rng` seeded with `S + k` (wrapping)
//! and goes through the free parameters in the model's order (fixed parameters, and free
//! ones held by equal bounds, are left alone and consume no draw):
//! - a non-zero start value `v` becomes `v·exp(0.7·z)`, `z ~ N(0, 1)` (a factor of 2 at one
//!   standard deviation; the sign is kept);
//! - a zero start value becomes uniform within its bounds when both are finite;
//! - a zero start value with an infinite bound becomes `s·z` — `s·|z|` on the allowed side
//!   when one bound is finite — where the scale `s` is the magnitude of the file's own
//!   start's estimate of that parameter, or its σ when the estimate is 0, and it stays 0
//!   (no draw) when neither is a positive finite number or that start failed. Start 0 runs
//!   first for this; the seeded starts then run in parallel. (Before, such a parameter
//!   always stayed 0: on the Cascaded Tanks model, whose level-dependent section terms and
//!   pump offset start at 0, 24 starts missed a valley 64 found.);
//! - a drawn value outside its bounds, or on one, is moved halfway between `v` and the
//!   bound it reached (strictly inside); when `v` itself lies on that bound the start
//!   keeps `v` (the estimator moves a start on a bound inside, as it does the file's own).
//!
//! Every start runs the same estimation (the same options, the same start states of the
//! records). The starts run in parallel (rayon) and are combined in start order, so the
//! result does not depend on the number of threads.
//!
//! **Kept.** The successful start with the lowest final free-run cost, ties to the lower
//! start index. A start whose estimation fails (a diverging simulation, …) is listed with
//! its error; only when every start fails is the file's own start's error returned. A
//! spent budget ends the whole job ([`sysid_core::CoreError::BudgetExhausted`]).
//!
//! **Probe.** A solve that "converged" stopped where the cost no longer falls along the
//! directions its Jacobian sees — not necessarily at a minimum. It may stop at a point
//! where a free parameter has no first-order effect on the free run: a coefficient of a
//! term that is zero along the whole simulated trajectory (a dead zone or an overflow never
//! reached, a switch never crossed), whose value is wherever its start left it; or at a
//! saddle, where the gradient vanishes but the cost still falls along some direction
//! (`x' = −p²·x + …` at `p = 0`). So every converged start is probed, in its own task
//! after its estimation: each free parameter `θ` (not one held by equal bounds) is nudged
//! down and up by `δ = max(min(PROBE_STEP·s, PROBE_SIGMAS·σ), PROBE_MIN_STEP·s)` — 1 % of
//! its scale `s`, at most 10 σ when it has a σ (so a nudge stays inside the basin the
//! records resolve), never under 10⁻⁶·s — clipped to its bounds (one side only on a
//! bound), the other parameters and the records' start states held at the estimate, and
//! the free run simulated again by the estimator's own code
//! ([`sysid_core::free_run_residuals`], the same sub-steps). `s = |θ|`; for `θ = 0` the
//! first positive of `|start|`, half the width of finite bounds (the uniform draw's),
//! the draw's scale (start 0's estimate or σ), σ, the larger finite bound, 1. That is
//! `2P + 1` free runs per converged start (`P` free parameters; one at the estimate),
//! charged to the job's budget as their RK4 steps — about two solver iterations' worth,
//! since an iteration also carries `P` + `n` tangent columns. From the nudges:
//! - the **sensitivity** `S = s·‖∂r/∂θ‖/‖r‖` (central difference of the weighted
//!   residuals `r`, one-sided on a bound): the relative change of the residuals for a
//!   relative change of `θ`, unit-free (a change of `θ` by the fraction `ε` moves the
//!   residuals by `ε·S·‖r‖`, the cost at second order by `ε²S²` of itself). At an exact
//!   fit `‖r‖` is replaced by `√M` (residuals of one noise σ each).
//! - the cost `J±` of each nudge relative to the cost `J` at the estimate (recomputed by
//!   the same code).
//!
//! A parameter is **not exercised** by the records at that point when `S <` [`NOT_EXERCISED`]
//! (10⁻⁶) and every nudge leaves the cost within [`COST_FALL`] (10⁻⁶) of `J`. A term that
//! is zero along the trajectory gives `S = 0` exactly; rounding in the simulation stays
//! orders of magnitude under 10⁻⁶ at a 1 % step; and a parameter with `S = 10⁻⁶` could be
//! doubled for a change of the cost of 10⁻¹² of itself, which no record of fewer than
//! 10¹² residuals resolves (`s² = J/(M − P)`). The second condition keeps a parameter with
//! only a second-order effect (`p` in `p²` at 0) exercised. A not-exercised parameter is
//! reported per start and per minimum, and left out wherever two points are compared
//! (distinct minima, valleys, not pinned) when either of them leaves it unexercised: at
//! such a point any value of it gives the same free run, so it cannot make two minima
//! different explanations of the data. A note says so for each one at the kept estimate
//! ([`NotExercised`]).
//!
//! A converged start where a nudge lowers the cost by more than [`COST_FALL`] (relative)
//! is a **saddle** ("saddle (cost falls along p)"): listed among the starts with its
//! nudges ([`CostFall`]), not among the minima. The tolerance is the same-cost tolerance,
//! not [`near_cost`]: at a true minimum a coordinate nudge cannot lower the cost by more
//! than what the solve left undone (relative `ftol` = 10⁻¹⁰ when converged, about 10⁻⁸
//! when it ended with no descending step at gradient cosine 10⁻⁴), while at a stationary
//! point that is not a minimum a 1 % nudge lowers it by a second-order amount that is
//! small in absolute terms (7.7·10⁻⁴ at `p = 0` of the test's `p²` model) but far beyond
//! that. σ is not the test (`σ = None` also on a bound and along a null direction shared
//! by several parameters). Only coordinate directions are probed: a saddle whose descent
//! direction mixes parameters, with no coordinate descending, is not seen. When the kept
//! start (lowest cost) is a saddle it stays kept, with a warning.
//!
//! **Distinct minima.** Among the starts whose free-run solve converged, saddles left
//! out, two starts end at the same minimum when their costs agree within [`SAME_COST`]
//! and every free parameter exercised at both within [`SAME_PARAMETER`] (relative to the
//! larger magnitude of the two); the starts are grouped in order of cost, each joining the
//! first group whose lowest-cost member it matches. A minimum's sensitivities and
//! not-exercised parameters are its lowest-cost start's.
//!
//! **Valleys.** Descents into one flat basin end at slightly different points, which the
//! strict rule above lists as different minima. Minima are grouped, in order of cost, each
//! joining the first valley whose *lowest* minimum it matches: its cost within
//! [`near_cost`] of that minimum's and every free parameter exercised at both within
//! [`DIFFERENT_PARAMETER`] of it (relative to the larger magnitude). Matching is against
//! the lowest member only, so a chain A ~ B ~ C with A ≁ C puts C in a valley of its own.
//! Each valley lists its starts, its cost range and the largest spread of a parameter
//! exercised at both ends in it.
//!
//! **Not pinned.** A minimum other than the kept start's whose cost is within
//! [`near_cost`] of the kept cost but where some free parameter exercised at both differs
//! from the kept estimate by more than [`DIFFERENT_PARAMETER`] (relative to the larger
//! magnitude) is reported as parameters these data do not pin. [`near_cost`] is the larger of
//! [`NEAR_COST`] and the likelihood-ratio bound `χ²_P(0.95)/(M − P)` (`M` residuals, `P`
//! estimated quantities of the kept free-run solve): with the noise variance scaled by
//! the residual variance `s² = J/(M − P)`, as the reported σ are, a minimum whose cost
//! exceeds the kept `J` by less than `s²·χ²_P(0.95)` is one the records do not reject at
//! the 5 % level. On the Cascaded Tanks benchmark a second minimum 1.4 % above the kept
//! cost (bound 2.1 %: M = 1024, P = 12) has coefficients up to 100-fold different.

use std::sync::atomic::{AtomicUsize, Ordering};

use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};
use rand_distr::{Distribution, StandardNormal};
use rayon::prelude::*;
use serde::Serialize;
use sysid_core::{
    ActiveBound, CoreError, Estimation, GreyboxData, GreyboxFit, GreyboxOptions, Parameter,
    ParameterEstimate, ParametricDynamics, PhysicalModel, estimate_parameters, free_run_residuals,
};

use crate::progress::{Progress, ProgressSink};

/// Standard deviation of `ln` of the factor a non-zero start value is multiplied by.
pub const START_SPREAD: f64 = 0.7;
/// Two starts are the same minimum only when their final costs agree within this
/// (relative).
pub const SAME_COST: f64 = 1e-6;
/// … and every free parameter within this (relative).
pub const SAME_PARAMETER: f64 = 1e-3;
/// The least relative cost difference under which another minimum explains the data as
/// well (the likelihood-ratio bound of [`near_cost`] may widen it).
pub const NEAR_COST: f64 = 0.01;

/// How close (relative) to the kept cost another minimum must come to count as explaining
/// the records as well: `max(NEAR_COST, χ²_P(0.95)/(M − P))` for a final free-run solve with
/// `M` residuals and `P` estimated quantities (module documentation); [`NEAR_COST`] when
/// `M ≤ P` or `P = 0`.
pub fn near_cost(residuals: usize, estimated: usize) -> f64 {
    if estimated == 0 || residuals <= estimated {
        return NEAR_COST;
    }
    let Ok(chi) = discovery::chi2_quantile(0.95, estimated as f64) else {
        return NEAR_COST;
    };
    let bound = chi / (residuals - estimated) as f64;
    if bound.is_finite() {
        NEAR_COST.max(bound)
    } else {
        NEAR_COST
    }
}
/// A parameter differing by more than this (relative) between two such minima is not
/// pinned by the data.
pub const DIFFERENT_PARAMETER: f64 = 0.1;

/// The probe's step, relative to the parameter's scale `s` (module doc, "Probe").
pub const PROBE_STEP: f64 = 1e-2;
/// … but at most this many of the parameter's σ, when it has one …
pub const PROBE_SIGMAS: f64 = 10.0;
/// … and never under this, relative to `s` (a σ at rounding level would leave the
/// finite difference to rounding).
pub const PROBE_MIN_STEP: f64 = 1e-6;
/// Sensitivity (unit-free, module doc) under which a parameter has no first-order effect
/// on the free run.
pub const NOT_EXERCISED: f64 = 1e-6;
/// Relative change of the free-run cost that a nudge must exceed to count: a fall by
/// more makes the start not a minimum; a parameter of sensitivity under
/// [`NOT_EXERCISED`] whose nudges change the cost by at most this is not exercised. The
/// same tolerance as [`SAME_COST`] (two costs closer than it are the same cost).
pub const COST_FALL: f64 = SAME_COST;

/// The probe's settings, as written into `greyest.json`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ProbeSettings {
    /// [`PROBE_STEP`].
    pub step: f64,
    /// [`PROBE_SIGMAS`].
    pub sigmas: f64,
    /// [`PROBE_MIN_STEP`].
    pub min_step: f64,
    /// [`NOT_EXERCISED`].
    pub not_exercised: f64,
    /// [`COST_FALL`].
    pub cost_fall: f64,
}

impl Default for ProbeSettings {
    fn default() -> Self {
        Self {
            step: PROBE_STEP,
            sigmas: PROBE_SIGMAS,
            min_step: PROBE_MIN_STEP,
            not_exercised: NOT_EXERCISED,
            cost_fall: COST_FALL,
        }
    }
}

/// What the probe of a converged start found for one free parameter (module doc,
/// "Probe").
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ParameterProbe {
    /// Name.
    pub name: String,
    /// The scale `s` of its step and of its sensitivity: `|θ|`, or for `θ = 0` the
    /// first of `|start|`, half the width of finite bounds, the draw's scale, σ, the
    /// larger finite bound's magnitude, 1.
    pub scale: f64,
    /// The value it was nudged down to (`null`: not that way — on its lower bound, or
    /// held by equal bounds).
    pub down: Option<f64>,
    /// The value it was nudged up to (`null` likewise).
    pub up: Option<f64>,
    /// Free-run cost there relative to the cost at the estimate (`J₋/J − 1`; `null` when
    /// not nudged down, or when the simulation diverged there).
    pub cost_down: Option<f64>,
    /// `J₊/J − 1` likewise.
    pub cost_up: Option<f64>,
    /// `s·‖∂r/∂θ‖/‖r‖` from the nudges (`null` when neither could be simulated or it is
    /// held).
    pub sensitivity: Option<f64>,
    /// Whether the records exercise it at this point: false when its sensitivity is under
    /// [`NOT_EXERCISED`] and every nudge changed the cost by at most [`COST_FALL`].
    pub exercised: bool,
}

/// A nudge along which the free-run cost fell: the start is not a minimum.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CostFall {
    /// The parameter nudged.
    pub name: String,
    /// Its value at the estimate.
    pub from: f64,
    /// The value nudged to.
    pub to: f64,
    /// The cost there relative to the cost at the estimate (negative, below
    /// `−COST_FALL`).
    pub relative_change: f64,
}

/// A note: a free parameter the records never exercise at the kept estimate.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct NotExercised {
    /// Name.
    pub name: String,
    /// Its value at the kept estimate (where its start left it, not an estimate).
    pub kept: f64,
    /// Its sensitivity there.
    pub sensitivity: Option<f64>,
    /// The converged starts that leave it unexercised too, in start order.
    pub starts: Vec<usize>,
    /// Its lowest and highest value at those starts (and the kept one).
    pub lowest: f64,
    /// See `lowest`.
    pub highest: f64,
}

impl NotExercised {
    /// The note in plain words.
    pub fn sentence(&self) -> String {
        let number = crate::show::number;
        let sens = match self.sensitivity {
            Some(0.0) => format!("sensitivity 0, under {NOT_EXERCISED:.0e}"),
            Some(v) => format!("sensitivity {v:.1e}, under {NOT_EXERCISED:.0e}"),
            None => "no sensitivity".to_string(),
        };
        let others = if self.starts.len() > 1 && self.highest > self.lowest {
            format!(
                " The {} converged starts that leave it unexercised end with it anywhere \
                 from {} to {}; that makes none of their minima a different explanation of \
                 the data, and it is left out when minima are compared.",
                self.starts.len(),
                number(self.lowest),
                number(self.highest)
            )
        } else {
            " It is left out when minima are compared.".to_string()
        };
        format!(
            "parameter {} has no effect on the free run at the kept estimate: the records \
             never exercise it ({sens}; a nudge of it leaves the cost within {:.0e}). Its \
             value there, {}, is where its start left it, not an estimate.{others} To \
             estimate it, add records that exercise it; otherwise fix it from other \
             knowledge.",
            self.name,
            COST_FALL,
            number(self.kept)
        )
    }
}

/// One start in `greyest.json`'s `multi_start.starts`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StartSummary {
    /// 0: the model file's own start; `k ≥ 1`: seeded with `seed + k`.
    pub index: usize,
    /// Start value of each free parameter (`parameter_names` order).
    pub start: Vec<f64>,
    /// Final free-run cost (`null` when the estimation failed).
    pub final_cost: Option<f64>,
    /// `final_cost / best − 1` (`null` when the estimation failed).
    pub relative_to_best: Option<f64>,
    /// Whether its final free-run solve converged.
    pub converged: bool,
    /// Estimate of each free parameter (empty when the estimation failed).
    pub values: Vec<f64>,
    /// Its distinct minimum (index into `minima`; `null` when it did not converge or is a
    /// saddle).
    pub minimum: Option<usize>,
    /// Why the estimation failed.
    pub error: Option<String>,
    /// Whether the probe found the free-run cost falling along a parameter (`cost_falls`):
    /// converged, but not a minimum ("saddle (cost falls along p)"), and left out of
    /// `minima`.
    pub saddle: bool,
    /// Unit-free sensitivity of each free parameter (`parameter_names` order; module doc,
    /// "Probe"); empty when the start was not probed (not converged, failed).
    pub sensitivity: Vec<Option<f64>>,
    /// Whether the records exercise each free parameter here (empty when not probed).
    pub exercised: Vec<bool>,
    /// The free parameters the records do not exercise here.
    pub not_exercised: Vec<String>,
    /// The nudges along which the cost fell (empty at a minimum).
    pub cost_falls: Vec<CostFall>,
    /// The probe, parameter by parameter (empty when not probed).
    pub probe: Vec<ParameterProbe>,
}

impl StartSummary {
    /// "saddle (cost falls along p, q)", "not exercised: c", or empty.
    pub fn note(&self) -> String {
        let mut parts = Vec::new();
        if self.saddle {
            let mut names: Vec<&str> = Vec::new();
            for f in &self.cost_falls {
                if !names.contains(&f.name.as_str()) {
                    names.push(&f.name);
                }
            }
            parts.push(format!("saddle (cost falls along {})", names.join(", ")));
        }
        if !self.not_exercised.is_empty() {
            parts.push(format!("not exercised: {}", self.not_exercised.join(", ")));
        }
        parts.join("; ")
    }

    /// The steepest fall of its cost under a nudge, if any.
    fn steepest_fall(&self) -> Option<&CostFall> {
        self.cost_falls
            .iter()
            .min_by(|a, b| a.relative_change.total_cmp(&b.relative_change))
    }
}

/// One distinct minimum.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MinimumSummary {
    /// The starts that end there, lowest cost first.
    pub starts: Vec<usize>,
    /// Cost of its lowest-cost start.
    pub cost: f64,
    /// `cost / best − 1`.
    pub relative_to_best: f64,
    /// Free parameters of its lowest-cost start.
    pub values: Vec<f64>,
    /// Whether the kept start is one of them.
    pub kept: bool,
    /// Sensitivity of each free parameter at its lowest-cost start (empty: not probed).
    pub sensitivity: Vec<Option<f64>>,
    /// Whether the records exercise each free parameter there (empty: not probed).
    pub exercised: Vec<bool>,
    /// The free parameters they do not exercise there (left out when minima are
    /// compared).
    pub not_exercised: Vec<String>,
}

/// A free parameter whose value differs between two nearly equally good minima.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ParameterPair {
    /// Name.
    pub name: String,
    /// The kept estimate.
    pub kept: f64,
    /// Its value at the other minimum.
    pub other: f64,
}

/// An identifiability warning: a minimum other than the kept one, nearly as good, with
/// materially different parameters.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct NotPinned {
    /// The other minimum (index into `minima`).
    pub minimum: usize,
    /// Its starts.
    pub starts: Vec<usize>,
    /// Its cost relative to the kept one (`cost / kept − 1`).
    pub relative_cost: f64,
    /// The bound it is within ([`near_cost`]).
    pub near_cost: f64,
    /// The parameters that differ by more than [`DIFFERENT_PARAMETER`].
    pub parameters: Vec<ParameterPair>,
}

impl NotPinned {
    /// The warning in plain words.
    pub fn sentence(&self) -> String {
        let names: Vec<&str> = self.parameters.iter().map(|p| p.name.as_str()).collect();
        let pairs: Vec<String> = self
            .parameters
            .iter()
            .map(|p| {
                format!(
                    "{} = {} there against {} in the kept estimate",
                    p.name,
                    crate::show::number(p.other),
                    crate::show::number(p.kept)
                )
            })
            .collect();
        let starts: Vec<String> = self.starts.iter().map(usize::to_string).collect();
        let cost = if self.relative_cost < 1e-4 {
            format!(
                "costs the same as the kept estimate (relative difference {:.1e})",
                self.relative_cost
            )
        } else {
            format!(
                "costs only {:.2} % more than the kept estimate (within {:.2} %, the bound \
                 under which the records do not tell them apart)",
                100.0 * self.relative_cost,
                100.0 * self.near_cost
            )
        };
        format!(
            "these data do not pin {}: the minimum reached from start{} {} {cost}, yet {}. \
             Both explain the records about equally well; the kept values are one of them, \
             not the parameters of the system. Fix {} from other knowledge, or add records \
             that tell the minima apart.",
            names.join(", "),
            if self.starts.len() == 1 { "" } else { "s" },
            starts.join(", "),
            pairs.join("; "),
            if names.len() == 1 {
                "it"
            } else {
                "some of them"
            }
        )
    }
}

/// A valley: distinct minima that are one basin in practice (module doc, "Valleys").
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ValleySummary {
    /// Its minima (indices into `minima`), lowest cost first.
    pub minima: Vec<usize>,
    /// The starts that end in it.
    pub starts: Vec<usize>,
    /// Cost of its lowest minimum relative to the kept cost (`cost / best − 1`).
    pub lowest_relative: f64,
    /// Cost of its highest minimum relative to the kept cost.
    pub highest_relative: f64,
    /// The largest relative difference of a free parameter between a member and the
    /// lowest minimum (`|a − b| / max(|a|, |b|)`).
    pub spread: f64,
    /// Whether the kept start ends in it.
    pub kept: bool,
}

impl ValleySummary {
    /// One line: its starts, cost range and parameter spread.
    pub fn sentence(&self) -> String {
        let starts: Vec<String> = self.starts.iter().map(usize::to_string).collect();
        let cost = if self.minima.len() == 1 {
            relative_words(Some(self.lowest_relative))
        } else {
            format!(
                "{} to {}",
                relative_words(Some(self.lowest_relative)),
                relative_words(Some(self.highest_relative))
            )
        };
        format!(
            "valley{}: {} start{} ({}), {} minim{}, cost {cost}, parameters within {:.2} % \
             of its lowest",
            if self.kept { " (kept)" } else { "" },
            self.starts.len(),
            if self.starts.len() == 1 { "" } else { "s" },
            starts.join(", "),
            self.minima.len(),
            if self.minima.len() == 1 { "um" } else { "a" },
            100.0 * self.spread
        )
    }
}

/// The multi-start in `greyest.json` (absent without `--starts`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MultiStart {
    /// The seed: start `k` draws from `ChaCha8Rng::seed_from_u64(seed + k)`.
    pub seed: u64,
    /// Names of the free parameters, the columns of `start` and `values`.
    pub parameter_names: Vec<String>,
    /// The start whose estimate is reported (the lowest final cost).
    pub kept: usize,
    /// Every start, lowest final cost first (failed ones last, by index).
    pub starts: Vec<StartSummary>,
    /// The distinct minima of the converged starts, lowest cost first.
    pub minima: Vec<MinimumSummary>,
    /// The minima grouped into valleys, lowest cost first.
    pub valleys: Vec<ValleySummary>,
    /// How close to the kept cost (relative) another minimum counts as nearly as good
    /// ([`near_cost`]).
    pub near_cost: f64,
    /// Identifiability warnings (empty when no other minimum is nearly as good with
    /// different parameters).
    pub not_pinned: Vec<NotPinned>,
    /// The probe's step and thresholds.
    pub probe: ProbeSettings,
    /// The converged starts the probe found not to be minima, in start order.
    pub saddles: Vec<usize>,
    /// Notes: the free parameters the records never exercise at the kept estimate.
    pub not_exercised: Vec<NotExercised>,
}

impl MultiStart {
    /// How many starts failed.
    pub fn failed(&self) -> usize {
        self.starts.iter().filter(|s| s.error.is_some()).count()
    }

    /// How many starts converged.
    pub fn converged(&self) -> usize {
        self.starts.iter().filter(|s| s.converged).count()
    }

    /// The kept start's row.
    pub fn kept_start(&self) -> Option<&StartSummary> {
        self.starts.iter().find(|s| s.index == self.kept)
    }

    /// A warning when the kept start is a saddle: its cost still falls along a parameter.
    pub fn kept_saddle_warning(&self) -> Option<String> {
        let row = self.kept_start().filter(|r| r.saddle)?;
        let fall = row.steepest_fall()?;
        Some(format!(
            "the kept start {} is not a minimum: its free-run cost falls by {:.2e} (relative) \
             when {} is nudged from {} to {}, and no other start reached a lower cost. The \
             kept values are a saddle of the cost, not an estimate; run more starts, or \
             start {} elsewhere.",
            row.index,
            -fall.relative_change,
            fall.name,
            crate::show::number(fall.from),
            crate::show::number(fall.to),
            fall.name
        ))
    }

    /// One line per minimum with a parameter the records do not exercise there.
    fn minimum_lines(&self) -> Vec<String> {
        self.minima
            .iter()
            .enumerate()
            .filter(|(_, m)| !m.not_exercised.is_empty())
            .map(|(i, m)| {
                let starts: Vec<String> = m.starts.iter().map(usize::to_string).collect();
                format!(
                    "minimum {i}{} (start{} {}): not exercised by these records: {}",
                    if m.kept { " (kept)" } else { "" },
                    if m.starts.len() == 1 { "" } else { "s" },
                    starts.join(", "),
                    m.not_exercised.join(", ")
                )
            })
            .collect()
    }

    /// The summary in lines for the terminal.
    pub fn terminal_lines(&self) -> Vec<String> {
        let mut lines = vec![format!(
            "multi-start: {} starts (the model file's and {} seeded, seed {}); kept start {} \
             (lowest cost); {} distinct minim{} in {} valley{} among {} converged starts{}{}",
            self.starts.len(),
            self.starts.len() - 1,
            self.seed,
            self.kept,
            self.minima.len(),
            if self.minima.len() == 1 { "um" } else { "a" },
            self.valleys.len(),
            if self.valleys.len() == 1 { "" } else { "s" },
            self.converged(),
            match self.saddles.len() {
                0 => String::new(),
                1 => " (1 of them a saddle, not a minimum)".to_string(),
                n => format!(" ({n} of them saddles, not minima)"),
            },
            match self.failed() {
                0 => String::new(),
                n => format!("; {n} failed"),
            }
        )];
        lines.push(format!(
            "  {:>5}  {:>12}  {:>9}  {:<9}{}",
            "start",
            "cost",
            "vs best",
            "converged",
            self.parameter_names
                .iter()
                .map(|n| format!("  {n:>12}"))
                .collect::<String>()
        ));
        for s in &self.starts {
            lines.push(match (&s.error, s.final_cost) {
                (None, Some(cost)) => format!(
                    "  {:>5}  {:>12.6e}  {:>9}  {:<9}{}{}",
                    s.index,
                    cost,
                    relative_words(s.relative_to_best),
                    if s.converged { "yes" } else { "no" },
                    s.values
                        .iter()
                        .map(|v| format!("  {v:>12.6e}"))
                        .collect::<String>(),
                    match s.note() {
                        n if n.is_empty() => n,
                        n => format!("  {n}"),
                    }
                ),
                (e, _) => format!(
                    "  {:>5}  failed: {}",
                    s.index,
                    e.as_deref().unwrap_or("no estimate")
                ),
            });
        }
        for m in self.minimum_lines() {
            lines.push(format!("  {m}"));
        }
        for v in &self.valleys {
            lines.push(format!("  {}", v.sentence()));
        }
        for n in &self.not_exercised {
            lines.push(format!("note: {}", n.sentence()));
        }
        if let Some(w) = self.kept_saddle_warning() {
            lines.push(format!("warning: {w}"));
        }
        for w in &self.not_pinned {
            lines.push(format!("warning: {}", w.sentence()));
        }
        lines
    }

    /// The `report.md` section.
    pub fn markdown(&self) -> String {
        let number = crate::show::number;
        let mut md = String::from("\n## Multi-start\n\n");
        md.push_str(&format!(
            "{} starts: the model file's own (start 0) and {} seeded ones (start k draws \
             each free parameter from a ChaCha8 generator seeded with {} + k: a non-zero \
             start value times exp(0.7·z), z ~ N(0, 1); a zero one uniform within finite \
             bounds, else s·z with s the size of start 0's estimate of it). **Kept: start {}**, the lowest final free-run cost.\n\n",
            self.starts.len(),
            self.starts.len() - 1,
            self.seed,
            self.kept
        ));
        md.push_str("| start | final cost | vs best | converged |");
        for n in &self.parameter_names {
            md.push_str(&format!(" {n} |"));
        }
        md.push_str(" probe |");
        md.push_str("\n|---|---|---|---|");
        md.push_str(&"---|".repeat(self.parameter_names.len() + 1));
        md.push('\n');
        for s in &self.starts {
            match (&s.error, s.final_cost) {
                (None, Some(cost)) => {
                    md.push_str(&format!(
                        "| {}{} | {} | {} | {} |",
                        s.index,
                        if s.index == self.kept { " (kept)" } else { "" },
                        number(cost),
                        relative_words(s.relative_to_best),
                        if s.converged { "yes" } else { "no" }
                    ));
                    for v in &s.values {
                        md.push_str(&format!(" {} |", number(*v)));
                    }
                    md.push_str(&format!(" {} |", s.note()));
                }
                (e, _) => {
                    md.push_str(&format!(
                        "| {} | — | — | failed: {} |",
                        s.index,
                        e.as_deref().unwrap_or("no estimate").replace('|', "\\|")
                    ));
                    md.push_str(&" |".repeat(self.parameter_names.len() + 1));
                }
            }
            md.push('\n');
        }
        md.push_str(&format!(
            "\nEvery converged start is probed: each free parameter is nudged down and up by \
             {} % of its scale (at most {} σ), the free run simulated again from the same \
             start states. A parameter whose sensitivity (the relative change of the \
             residuals for a relative change of it) is under {:.0e} and whose nudges leave \
             the cost within {:.0e} is *not exercised* by these records there: it is left \
             out when minima are compared. A start where a nudge lowers the cost by more \
             than {:.0e} is a *saddle*, not a minimum{}.\n",
            100.0 * PROBE_STEP,
            PROBE_SIGMAS,
            NOT_EXERCISED,
            COST_FALL,
            COST_FALL,
            match self.saddles.len() {
                0 => String::new(),
                _ => format!(
                    " (start{} {} here, left out of the minima)",
                    if self.saddles.len() == 1 { "" } else { "s" },
                    self.saddles
                        .iter()
                        .map(usize::to_string)
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
            }
        ));
        md.push_str(&format!(
            "\n{} distinct minim{} among the {} converged starts{} (the same minimum: \
             costs within {:.0e} and every exercised free parameter within {:.0e}, \
             relative):\n\n",
            self.minima.len(),
            if self.minima.len() == 1 { "um" } else { "a" },
            self.converged(),
            match self.saddles.len() {
                0 => String::new(),
                1 => ", the saddle left out".to_string(),
                _ => ", the saddles left out".to_string(),
            },
            SAME_COST,
            SAME_PARAMETER
        ));
        for m in &self.minima {
            let values: Vec<String> = self
                .parameter_names
                .iter()
                .zip(&m.values)
                .map(|(n, v)| format!("{n} = {}", number(*v)))
                .collect();
            let starts: Vec<String> = m.starts.iter().map(usize::to_string).collect();
            md.push_str(&format!(
                "- cost {} ({}), starts {}{}: {}{}\n",
                number(m.cost),
                relative_words(Some(m.relative_to_best)),
                starts.join(", "),
                if m.kept { ", the kept estimate" } else { "" },
                values.join(", "),
                if m.not_exercised.is_empty() {
                    String::new()
                } else {
                    format!(
                        "; not exercised by these records: {}",
                        m.not_exercised.join(", ")
                    )
                }
            ));
        }
        md.push_str(&format!(
            "\nIn {} valley{} (minima within {:.2} % in cost of a valley's lowest and every \
             exercised free parameter within {} % of it):\n\n",
            self.valleys.len(),
            if self.valleys.len() == 1 { "" } else { "s" },
            100.0 * self.near_cost,
            100.0 * DIFFERENT_PARAMETER
        ));
        for v in &self.valleys {
            md.push_str(&format!("- {}\n", v.sentence()));
        }
        if self.not_pinned.is_empty() {
            md.push_str(&format!(
                "\nNo other minimum comes within {:.2} % of the kept cost with a free \
                 parameter more than {} % different.\n",
                100.0 * self.near_cost,
                100.0 * DIFFERENT_PARAMETER
            ));
        }
        for n in &self.not_exercised {
            md.push_str(&format!("\n**Note**: {}\n", n.sentence()));
        }
        if let Some(w) = self.kept_saddle_warning() {
            md.push_str(&format!("\n**Warning**: {w}\n"));
        }
        for w in &self.not_pinned {
            md.push_str(&format!(
                "\n**Identifiability warning**: {}\n",
                w.sentence()
            ));
        }
        md
    }
}

fn relative_words(r: Option<f64>) -> String {
    match r {
        None => "—".into(),
        Some(0.0) => "best".into(),
        Some(r) => format!("{:+.2e}", r),
    }
}

/// `|a − b| ≤ tol · max(|a|, |b|)`.
fn agree(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol * a.abs().max(b.abs())
}

/// `|a − b| / max(|a|, |b|)` (0 when both are 0): the distance [`agree`] bounds.
fn difference(a: f64, b: f64) -> f64 {
    let scale = a.abs().max(b.abs());
    if scale > 0.0 {
        (a - b).abs() / scale
    } else {
        0.0
    }
}

fn relative(cost: f64, best: f64) -> f64 {
    if best > 0.0 {
        cost / best - 1.0
    } else if cost > best {
        f64::INFINITY
    } else {
        0.0
    }
}

/// Every parameter value of seeded start `k` of `parameters` (module doc: the draw),
/// without scales for zero starts with an infinite bound (they stay 0).
pub fn seeded_start(parameters: &[Parameter], seed: u64, k: usize) -> Vec<f64> {
    seeded_start_scaled(parameters, &[], seed, k)
}

/// The scale of each parameter's zero-start draw (module doc): the magnitude of `fit`'s
/// estimate, else its σ, for a free parameter that starts at 0 with an infinite bound;
/// `None` for every other parameter.
pub fn zero_start_scales(
    parameters: &[Parameter],
    fit: &GreyboxFit<PhysicalModel>,
) -> Vec<Option<f64>> {
    parameters
        .iter()
        .map(|p| {
            let open = !(p.lower.is_finite() && p.upper.is_finite());
            if p.estimation != Estimation::Free || p.value != 0.0 || !open {
                return None;
            }
            let est = fit.parameters.iter().find(|e| e.name == p.name)?;
            let usable = |v: f64| (v.is_finite() && v > 0.0).then_some(v);
            usable(est.value.abs()).or_else(|| est.sigma.and_then(usable))
        })
        .collect()
}

/// [`seeded_start`] with the zero-start scales of [`zero_start_scales`] (`scales` empty or
/// one per parameter).
pub fn seeded_start_scaled(
    parameters: &[Parameter],
    scales: &[Option<f64>],
    seed: u64,
    k: usize,
) -> Vec<f64> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed.wrapping_add(k as u64));
    parameters
        .iter()
        .enumerate()
        .map(|(j, p)| {
            let v = p.value;
            // Equal bounds hold a free parameter at its value (a loaded model's bounds are
            // ordered around its value).
            if p.estimation != Estimation::Free || p.upper <= p.lower {
                return v;
            }
            let drawn = if v != 0.0 {
                let z: f64 = StandardNormal.sample(&mut rng);
                v * (START_SPREAD * z).exp()
            } else if p.lower.is_finite() && p.upper.is_finite() {
                // lo·(1 − u) + hi·u: no overflow of hi − lo.
                let u: f64 = rng.random();
                p.lower * (1.0 - u) + p.upper * u
            } else if let Some(scale) = scales.get(j).copied().flatten() {
                let z: f64 = StandardNormal.sample(&mut rng);
                if p.lower.is_finite() {
                    scale * z.abs()
                } else if p.upper.is_finite() {
                    -scale * z.abs()
                } else {
                    scale * z
                }
            } else {
                return v;
            };
            inside(drawn, v, p.lower, p.upper)
        })
        .collect()
}

/// `drawn` when strictly inside `(lo, hi)`, else halfway between `v` and the bound it
/// reached, else `v`.
fn inside(drawn: f64, v: f64, lo: f64, hi: f64) -> f64 {
    if drawn > lo && drawn < hi {
        return drawn;
    }
    let bound = if drawn <= lo { lo } else { hi };
    let mid = v / 2.0 + bound / 2.0;
    if mid > lo && mid < hi { mid } else { v }
}

/// One start's result.
struct Run {
    row: StartSummary,
    fit: Option<GreyboxFit<PhysicalModel>>,
    /// The file's own start's error (to return when every start fails) or a spent budget.
    error: Option<CoreError>,
}

/// What combining the starts in order keeps: every row, the best fit with its key, the
/// file's own start's error, the first spent budget.
#[derive(Default)]
struct Combined {
    rows: Vec<StartSummary>,
    best: Option<(f64, usize, GreyboxFit<PhysicalModel>)>,
    own_error: Option<CoreError>,
    budget: Option<CoreError>,
}

impl Combined {
    fn of(run: Run) -> Self {
        let mut c = Combined::default();
        let index = run.row.index;
        match run.error {
            Some(e @ CoreError::BudgetExhausted(_)) => c.budget = Some(e),
            Some(e) if index == 0 => c.own_error = Some(e),
            _ => {}
        }
        if let (Some(fit), Some(cost)) = (run.fit, run.row.final_cost) {
            c.best = Some((cost, index, fit));
        }
        c.rows.push(run.row);
        c
    }

    /// `self` then `other` (`other`'s starts come after `self`'s).
    fn then(mut self, other: Self) -> Self {
        self.rows.extend(other.rows);
        self.best = match (self.best, other.best) {
            (Some(a), Some(b)) => {
                // Lowest cost, ties to the lower index.
                if (b.0.total_cmp(&a.0)).then(b.1.cmp(&a.1)).is_lt() {
                    Some(b)
                } else {
                    Some(a)
                }
            }
            (a, b) => a.or(b),
        };
        self.own_error = self.own_error.or(other.own_error);
        self.budget = self.budget.or(other.budget);
        self
    }
}

/// Run the file's own start and `starts` seeded ones of `physical` (module doc); the kept
/// fit and the summary.
pub(crate) fn run(
    physical: &PhysicalModel,
    data: &GreyboxData<'_>,
    gopts: &GreyboxOptions,
    starts: usize,
    seed: u64,
    progress: &dyn ProgressSink,
) -> Result<(GreyboxFit<PhysicalModel>, MultiStart), CoreError> {
    let free: Vec<usize> = physical
        .parameters()
        .iter()
        .enumerate()
        .filter(|(_, p)| p.estimation == Estimation::Free)
        .map(|(j, _)| j)
        .collect();
    let names: Vec<String> = free
        .iter()
        .map(|&j| physical.parameters()[j].name.clone())
        .collect();
    let total = starts.saturating_add(1);
    let done = AtomicUsize::new(0);
    let task = "grey-box estimation (multi-start)";
    let one = |k: usize, scales: &[Option<f64>]| -> Run {
        let values = if k == 0 {
            physical.parameters().iter().map(|p| p.value).collect()
        } else {
            seeded_start_scaled(physical.parameters(), scales, seed, k)
        };
        let start: Vec<f64> = free.iter().map(|&j| values[j]).collect();
        let result = if k == 0 {
            estimate_parameters(physical, data, gopts).map_err(|e| (e.to_string(), Some(e)))
        } else {
            match physical.with_parameters(&values) {
                Ok(m) => estimate_parameters(&m, data, gopts).map_err(|e| (e.to_string(), Some(e))),
                Err(e) => Err((e.to_string(), None)),
            }
        };
        // The probe of a converged start (module doc, "Probe"), in this start's task so
        // the result does not depend on the thread count.
        let probed = match &result {
            Ok(fit) if fit.report().stationary() => {
                probe(fit, data, gopts, scales).map_err(|e| (e.to_string(), Some(e)))
            }
            _ => Ok(Vec::new()),
        };
        let n = done.fetch_add(1, Ordering::Relaxed) + 1;
        progress.report(&Progress::new(task, n, Some(total)));
        let result = match (result, probed) {
            (Ok(fit), Ok(probe)) => Ok((fit, probe)),
            (Err(e), _) | (Ok(_), Err(e)) => Err(e),
        };
        match result {
            Ok((fit, probe)) => {
                let last = &fit.stages[fit.stages.len() - 1].report;
                let cost = last.final_cost();
                let cost_falls: Vec<CostFall> = probe
                    .iter()
                    .flat_map(|q| {
                        let from = fit
                            .parameters
                            .iter()
                            .find(|p| p.name == q.name)
                            .map_or(f64::NAN, |p| p.value);
                        [(q.down, q.cost_down), (q.up, q.cost_up)]
                            .into_iter()
                            .filter_map(move |(to, change)| match (to, change) {
                                (Some(to), Some(c)) if c < -COST_FALL => Some(CostFall {
                                    name: q.name.clone(),
                                    from,
                                    to,
                                    relative_change: c,
                                }),
                                _ => None,
                            })
                    })
                    .collect();
                Run {
                    row: StartSummary {
                        index: k,
                        start,
                        final_cost: Some(cost),
                        relative_to_best: None,
                        converged: last.stationary(),
                        values: fit.parameters.iter().map(|p| p.value).collect(),
                        minimum: None,
                        error: None,
                        saddle: !cost_falls.is_empty(),
                        sensitivity: probe.iter().map(|q| q.sensitivity).collect(),
                        exercised: probe.iter().map(|q| q.exercised).collect(),
                        not_exercised: probe
                            .iter()
                            .filter(|q| !q.exercised)
                            .map(|q| q.name.clone())
                            .collect(),
                        cost_falls,
                        probe,
                    },
                    fit: Some(fit),
                    error: None,
                }
            }
            Err((message, error)) => Run {
                row: StartSummary {
                    index: k,
                    start,
                    final_cost: None,
                    relative_to_best: None,
                    converged: false,
                    values: Vec::new(),
                    minimum: None,
                    error: Some(message),
                    saddle: false,
                    sensitivity: Vec::new(),
                    exercised: Vec::new(),
                    not_exercised: Vec::new(),
                    cost_falls: Vec::new(),
                    probe: Vec::new(),
                },
                fit: None,
                error,
            },
        }
    };
    // An indexed parallel iterator reduces neighbours in order: the rows come out in start
    // order and the kept start is the same for any number of threads.
    // The file's own start first: its estimate scales the draws of zero starts.
    let own = one(0, &[]);
    if let Some(e @ CoreError::BudgetExhausted(_)) = own.error {
        // A spent budget ends the whole job; the seeded starts would only fail on it.
        progress.finish(task);
        return Err(e);
    }
    let scales = own
        .fit
        .as_ref()
        .map(|f| zero_start_scales(physical.parameters(), f))
        .unwrap_or_default();
    let combined = Combined::of(own).then(
        (1..total)
            .into_par_iter()
            .map(|k| Combined::of(one(k, &scales)))
            .reduce(Combined::default, Combined::then),
    );
    progress.finish(task);
    if let Some(e) = combined.budget {
        return Err(e);
    }
    let Some((best_cost, kept, fit)) = combined.best else {
        return Err(combined.own_error.unwrap_or(CoreError::NoFreeParameters {
            parameters: physical.parameters().len(),
        }));
    };
    let mut rows = combined.rows;
    for r in &mut rows {
        r.relative_to_best = r.final_cost.map(|c| relative(c, best_cost));
    }
    // Lowest cost first, failed starts last, ties by index.
    rows.sort_by(|a, b| {
        let ka = a.final_cost.unwrap_or(f64::INFINITY);
        let kb = b.final_cost.unwrap_or(f64::INFINITY);
        (a.error.is_some(), ka)
            .partial_cmp(&(b.error.is_some(), kb))
            .unwrap_or(std::cmp::Ordering::Equal)
            .then(a.index.cmp(&b.index))
    });
    let minima = group(&mut rows, kept, best_cost);
    let kept_values = fit.parameters.iter().map(|p| p.value).collect::<Vec<_>>();
    let kept_exercised = rows
        .iter()
        .find(|r| r.index == kept)
        .map(|r| r.exercised.clone())
        .unwrap_or_default();
    let near = fit
        .stages
        .last()
        .map_or(NEAR_COST, |st| near_cost(st.residuals, st.estimated));
    let valleys = valleys(&minima, near);
    let not_pinned = minima
        .iter()
        .enumerate()
        .filter(|(_, m)| !m.kept && relative(m.cost, best_cost) <= near)
        .filter_map(|(i, m)| {
            // A parameter the records do not exercise at either point cannot make them
            // different explanations of the data.
            let parameters: Vec<ParameterPair> = names
                .iter()
                .zip(kept_values.iter().zip(&m.values))
                .enumerate()
                .filter(|(j, _)| compared(&kept_exercised, &m.exercised, *j))
                .map(|(_, pair)| pair)
                .filter(|(_, (a, b))| !agree(**a, **b, DIFFERENT_PARAMETER))
                .map(|(name, (a, b))| ParameterPair {
                    name: name.clone(),
                    kept: *a,
                    other: *b,
                })
                .collect();
            (!parameters.is_empty()).then(|| NotPinned {
                minimum: i,
                starts: m.starts.clone(),
                relative_cost: m.relative_to_best,
                near_cost: near,
                parameters,
            })
        })
        .collect();
    let not_exercised = not_exercised_notes(&rows, kept, &names);
    let mut saddles: Vec<usize> = rows.iter().filter(|r| r.saddle).map(|r| r.index).collect();
    saddles.sort_unstable();
    Ok((
        fit,
        MultiStart {
            seed,
            parameter_names: names,
            kept,
            starts: rows,
            minima,
            valleys,
            near_cost: near,
            not_pinned,
            probe: ProbeSettings::default(),
            saddles,
            not_exercised,
        },
    ))
}

/// The notes on the free parameters the records do not exercise at the kept start.
fn not_exercised_notes(rows: &[StartSummary], kept: usize, names: &[String]) -> Vec<NotExercised> {
    let Some(row) = rows.iter().find(|r| r.index == kept) else {
        return Vec::new();
    };
    let mut notes = Vec::new();
    for (j, name) in names.iter().enumerate() {
        if row.exercised.get(j).copied().unwrap_or(true) {
            continue;
        }
        let mut starts: Vec<usize> = rows
            .iter()
            .filter(|r| !r.exercised.get(j).copied().unwrap_or(true))
            .map(|r| r.index)
            .collect();
        starts.sort_unstable();
        let values = rows
            .iter()
            .filter(|r| !r.exercised.get(j).copied().unwrap_or(true))
            .filter_map(|r| r.values.get(j).copied());
        let (lowest, highest) = values.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
            (lo.min(v), hi.max(v))
        });
        notes.push(NotExercised {
            name: name.clone(),
            kept: row.values[j],
            sensitivity: row.sensitivity.get(j).copied().flatten(),
            starts,
            lowest,
            highest,
        });
    }
    notes
}

/// Whether parameter `j` takes part in comparing two points with these `exercised`
/// flags: not when either point leaves it unexercised (an empty list: all exercised).
fn compared(a: &[bool], b: &[bool], j: usize) -> bool {
    a.get(j).copied().unwrap_or(true) && b.get(j).copied().unwrap_or(true)
}

/// The scale `s` of a parameter's probe step and sensitivity ([`ParameterProbe::scale`]):
/// `|θ|`; for `θ = 0` the first positive finite of `|start|`, half the width of finite
/// bounds, the draw's scale `draw`, σ, the larger finite bound's magnitude; else 1.
fn probe_scale(est: &ParameterEstimate, draw: Option<f64>) -> f64 {
    let usable = |v: f64| (v.is_finite() && v > 0.0).then_some(v);
    let finite_bound = [est.lower, est.upper]
        .into_iter()
        .filter(|b| b.is_finite())
        .map(f64::abs)
        .fold(0.0, f64::max);
    usable(est.value.abs())
        .or_else(|| usable(est.start.abs()))
        .or_else(|| usable(est.upper / 2.0 - est.lower / 2.0))
        .or_else(|| draw.and_then(usable))
        .or_else(|| est.sigma.and_then(usable))
        .or_else(|| usable(finite_bound))
        .unwrap_or(1.0)
}

/// The probe of a converged start (module doc, "Probe"): each free parameter nudged down
/// and up from the estimate, the others and the start states held, the free run simulated
/// again. At most `2P + 1` free runs (`P` free parameters), charged to the job's budget
/// as their RK4 steps; an error only when the budget is spent.
fn probe(
    fit: &GreyboxFit<PhysicalModel>,
    data: &GreyboxData<'_>,
    gopts: &GreyboxOptions,
    draw_scales: &[Option<f64>],
) -> Result<Vec<ParameterProbe>, CoreError> {
    let steps: usize = data
        .records
        .iter()
        .zip(&fit.substeps)
        .map(|(e, s)| e.len().saturating_sub(1) * s)
        .sum();
    let runs = 2 * fit.parameters.len() + 1;
    gopts
        .budget
        .charge((steps * runs) as u64, "grey-box multi-start probe", 0, None)
        .map_err(CoreError::BudgetExhausted)?;
    let simulate = |model: &PhysicalModel| {
        free_run_residuals(model, data, &fit.x0, &fit.substeps, gopts.blow_up)
            .ok()
            .flatten()
    };
    let Some(r0) = simulate(&fit.model) else {
        return Ok(Vec::new());
    };
    let cost0: f64 = r0.iter().map(|v| v * v).sum();
    // The residuals' norm; at an exact fit, that of residuals of one noise σ each.
    let norm0 = if cost0 > 0.0 {
        cost0.sqrt()
    } else {
        (r0.len().max(1) as f64).sqrt()
    };
    let values: Vec<f64> = fit.model.parameters().iter().map(|p| p.value).collect();
    let nudged = |j: usize, v: f64| {
        let mut vs = values.clone();
        vs[j] = v;
        fit.model
            .with_parameters(&vs)
            .ok()
            .and_then(|m| simulate(&m))
    };
    let cost_of = |r: &Option<Vec<f64>>| {
        r.as_ref()
            .map(|r| relative(r.iter().map(|v| v * v).sum(), cost0))
    };
    let distance = |a: &[f64], b: &[f64]| {
        a.iter()
            .zip(b)
            .map(|(x, y)| (x - y) * (x - y))
            .sum::<f64>()
            .sqrt()
    };
    let mut out = Vec::with_capacity(fit.parameters.len());
    for est in &fit.parameters {
        let theta = est.value;
        let scale = probe_scale(est, draw_scales.get(est.index).copied().flatten());
        if est.active_bound == Some(ActiveBound::Fixed) || est.upper <= est.lower {
            out.push(ParameterProbe {
                name: est.name.clone(),
                scale,
                down: None,
                up: None,
                cost_down: None,
                cost_up: None,
                sensitivity: None,
                exercised: true,
            });
            continue;
        }
        let mut step = PROBE_STEP * scale;
        if let Some(sigma) = est.sigma.filter(|s| s.is_finite() && *s > 0.0) {
            step = step.min(PROBE_SIGMAS * sigma);
        }
        step = step.max(PROBE_MIN_STEP * scale);
        let down = Some((theta - step).max(est.lower)).filter(|v| *v < theta);
        let up = Some((theta + step).min(est.upper)).filter(|v| *v > theta);
        let r_down = down.and_then(|v| nudged(est.index, v));
        let r_up = up.and_then(|v| nudged(est.index, v));
        let slope = match (&r_down, &r_up, down, up) {
            (Some(a), Some(b), Some(lo), Some(hi)) => Some(distance(b, a) / (hi - lo)),
            (Some(a), _, Some(lo), _) => Some(distance(&r0, a) / (theta - lo)),
            (_, Some(b), _, Some(hi)) => Some(distance(b, &r0) / (hi - theta)),
            _ => None,
        };
        let sensitivity = slope.map(|g| g * scale / norm0);
        let (cost_down, cost_up) = (cost_of(&r_down), cost_of(&r_up));
        // A nudge that could not be simulated (it diverged) is an effect.
        let diverged = (down.is_some() && r_down.is_none()) || (up.is_some() && r_up.is_none());
        let flat = [cost_down, cost_up]
            .into_iter()
            .flatten()
            .all(|c| c.abs() <= COST_FALL);
        let exercised = diverged || !flat || sensitivity.is_none_or(|s| s >= NOT_EXERCISED);
        out.push(ParameterProbe {
            name: est.name.clone(),
            scale,
            down,
            up,
            cost_down,
            cost_up,
            sensitivity,
            exercised,
        });
    }
    Ok(out)
}

/// `minima` (sorted by cost) grouped into valleys (module doc, "Valleys").
pub fn valleys(minima: &[MinimumSummary], near: f64) -> Vec<ValleySummary> {
    let mut out: Vec<ValleySummary> = Vec::new();
    for (i, m) in minima.iter().enumerate() {
        let joins = out.iter().position(|v| {
            let low = &minima[v.minima[0]];
            relative(m.cost, low.cost) <= near
                && m.values.len() == low.values.len()
                && m.values
                    .iter()
                    .zip(&low.values)
                    .enumerate()
                    .filter(|(j, _)| compared(&m.exercised, &low.exercised, *j))
                    .all(|(_, (a, b))| agree(*a, *b, DIFFERENT_PARAMETER))
        });
        match joins {
            Some(j) => {
                let v = &mut out[j];
                let low = &minima[v.minima[0]];
                let spread = m
                    .values
                    .iter()
                    .zip(&low.values)
                    .enumerate()
                    .filter(|(j, _)| compared(&m.exercised, &low.exercised, *j))
                    .map(|(_, (a, b))| difference(*a, *b))
                    .fold(v.spread, f64::max);
                v.minima.push(i);
                v.starts.extend(&m.starts);
                v.highest_relative = v.highest_relative.max(m.relative_to_best);
                v.spread = spread;
                v.kept |= m.kept;
            }
            None => out.push(ValleySummary {
                minima: vec![i],
                starts: m.starts.clone(),
                lowest_relative: m.relative_to_best,
                highest_relative: m.relative_to_best,
                spread: 0.0,
                kept: m.kept,
            }),
        }
    }
    out
}

/// The distinct minima of the converged rows that are not saddles (sorted by cost), each
/// such row's `minimum` set. Parameters the records do not exercise at a row or at a
/// minimum's lowest start are left out when they are compared.
fn group(rows: &mut [StartSummary], kept: usize, best: f64) -> Vec<MinimumSummary> {
    let mut minima: Vec<MinimumSummary> = Vec::new();
    for row in rows.iter_mut() {
        let Some(cost) = row.final_cost.filter(|_| row.converged && !row.saddle) else {
            continue;
        };
        let same = minima.iter().position(|m| {
            agree(m.cost, cost, SAME_COST)
                && m.values.len() == row.values.len()
                && m.values
                    .iter()
                    .zip(&row.values)
                    .enumerate()
                    .filter(|(j, _)| compared(&m.exercised, &row.exercised, *j))
                    .all(|(_, (a, b))| agree(*a, *b, SAME_PARAMETER))
        });
        let i = match same {
            Some(i) => {
                minima[i].starts.push(row.index);
                i
            }
            None => {
                minima.push(MinimumSummary {
                    starts: vec![row.index],
                    cost,
                    relative_to_best: relative(cost, best),
                    values: row.values.clone(),
                    kept: false,
                    sensitivity: row.sensitivity.clone(),
                    exercised: row.exercised.clone(),
                    not_exercised: row.not_exercised.clone(),
                });
                minima.len() - 1
            }
        };
        minima[i].kept |= row.index == kept;
        row.minimum = Some(i);
    }
    minima
}

#[cfg(test)]
#[allow(clippy::float_cmp)] // exact draws and halfway points
mod tests {
    use super::*;

    /// The likelihood-ratio bound against hand values: χ²₁₂(0.95) = 21.0261 (tables), so
    /// 1024 residuals and 12 estimated quantities give 21.0261/1012 = 2.078 %; with many
    /// residuals the 1 % floor holds; degenerate counts fall back to the floor.
    #[test]
    fn near_cost_is_the_likelihood_ratio_bound_or_one_per_cent() {
        assert!((near_cost(1024, 12) - 21.026_07 / 1012.0).abs() < 1e-6);
        assert!((near_cost(100_000, 12) - NEAR_COST).abs() < 1e-15);
        assert!((near_cost(10, 12) - NEAR_COST).abs() < 1e-15);
        assert!((near_cost(1024, 0) - NEAR_COST).abs() < 1e-15);
        // One parameter on 101 residuals: χ²₁(0.95) = 3.8415, 3.8415/100.
        assert!((near_cost(101, 1) - 0.038_414_6).abs() < 1e-6);
    }

    fn parameter(value: f64, lower: f64, upper: f64) -> Parameter {
        Parameter {
            name: "p".into(),
            value,
            lower,
            upper,
            estimation: Estimation::Free,
        }
    }

    #[test]
    fn draws_stay_strictly_inside_and_keep_the_sign() {
        let ps = [
            parameter(0.5, 0.0, 1.0),
            parameter(-3.0, f64::NEG_INFINITY, f64::INFINITY),
            parameter(0.0, -2.0, 2.0),
            parameter(0.0, 0.0, f64::INFINITY),
            parameter(1.0, 1.0, 1.0),
            Parameter {
                estimation: Estimation::Fixed,
                ..parameter(2.0, 0.0, 10.0)
            },
            parameter(0.2, 0.2, 0.3),
        ];
        let mut signs = [0usize; 2];
        for k in 1..200 {
            let v = seeded_start(&ps, 7, k);
            assert!(v[0] > 0.0 && v[0] < 1.0, "{v:?}");
            assert!(v[1] < 0.0, "{v:?}");
            assert!(v[2] > -2.0 && v[2] < 2.0, "{v:?}");
            signs[usize::from(v[2] > 0.0)] += 1;
            assert_eq!(v[3], 0.0);
            assert_eq!(v[4], 1.0);
            assert_eq!(v[5], 2.0);
            // On its lower bound: a draw below it keeps the start.
            assert!(v[6] >= 0.2 && v[6] < 0.3, "{v:?}");
        }
        assert!(signs[0] > 50 && signs[1] > 50, "{signs:?}");
        assert_eq!(seeded_start(&ps, 7, 3), seeded_start(&ps, 8, 2));
        assert_ne!(seeded_start(&ps, 7, 3), seeded_start(&ps, 7, 4));
    }

    /// Zero starts with an infinite bound are drawn at their scale, on the allowed side of
    /// a finite bound; without a scale they stay 0, and the other parameters' draws are
    /// those of [`seeded_start`] when no scale is given.
    #[test]
    fn zero_starts_are_drawn_at_their_scale() {
        let ps = [
            parameter(0.0, f64::NEG_INFINITY, f64::INFINITY),
            parameter(0.0, 0.0, f64::INFINITY),
            parameter(0.0, f64::NEG_INFINITY, 0.0),
            parameter(0.0, f64::NEG_INFINITY, f64::INFINITY),
            parameter(2.0, 0.0, 10.0),
        ];
        let scales = [Some(0.1), Some(3.0), Some(1.0), None, None];
        let (mut signs, mut sum_sq) = ([0usize; 2], 0.0);
        let n = 2000;
        for k in 1..=n {
            let v = seeded_start_scaled(&ps, &scales, 11, k);
            signs[usize::from(v[0] > 0.0)] += 1;
            sum_sq += v[0] * v[0];
            assert!(v[1] > 0.0, "{v:?}");
            assert!(v[2] < 0.0, "{v:?}");
            assert_eq!(v[3], 0.0);
            assert!(v[4] > 0.0 && v[4] < 10.0, "{v:?}");
        }
        assert!(signs[0] > 900 && signs[1] > 900, "{signs:?}");
        // The draw's RMS is its scale (0.1) within sampling error (about 1.6 %).
        let rms = (sum_sq / n as f64).sqrt();
        assert!((rms - 0.1).abs() < 0.008, "{rms}");
        assert_eq!(
            seeded_start_scaled(&ps, &[], 11, 5),
            seeded_start(&ps, 11, 5)
        );
        assert_eq!(seeded_start(&ps, 11, 5)[..4], [0.0; 4]);
    }

    fn minimum(cost: f64, best: f64, values: Vec<f64>, start: usize) -> MinimumSummary {
        MinimumSummary {
            starts: vec![start],
            cost,
            relative_to_best: cost / best - 1.0,
            values,
            kept: start == 0,
            sensitivity: Vec::new(),
            exercised: Vec::new(),
            not_exercised: Vec::new(),
        }
    }

    /// Hand-made minima (sorted by cost): B is within 10 % of A, C within 10 % of B but
    /// not of A (the chain: C gets its own valley), D is A's values at a cost beyond the
    /// near bound (its own valley), E is C's twin.
    #[test]
    fn minima_are_grouped_into_valleys_against_each_valleys_lowest() {
        let ms = [
            minimum(100.0, 100.0, vec![1.0, 10.0], 0),
            minimum(100.5, 100.0, vec![1.08, 10.0], 1),
            minimum(100.6, 100.0, vec![1.16, 10.0], 2),
            minimum(100.7, 100.0, vec![1.17, 10.1], 4),
            minimum(105.0, 100.0, vec![1.0, 10.0], 3),
        ];
        let v = valleys(&ms, 0.02);
        assert_eq!(v.len(), 3, "{v:#?}");
        assert_eq!(v[0].minima, vec![0, 1]);
        assert_eq!(v[0].starts, vec![0, 1]);
        assert!(v[0].kept && !v[1].kept);
        assert!((v[0].spread - 0.08 / 1.08).abs() < 1e-12, "{}", v[0].spread);
        assert!((v[0].highest_relative - 0.005).abs() < 1e-12);
        assert_eq!(v[1].minima, vec![2, 3]);
        assert!((v[1].lowest_relative - 0.006).abs() < 1e-12);
        assert_eq!(v[2].minima, vec![4]);
        assert!(
            v[2].sentence().contains("1 start (3), 1 minimum"),
            "{}",
            v[2].sentence()
        );
    }

    /// A parameter the records do not exercise at either minimum is left out of the
    /// valley test and the spread: the minima differing only in it (2-fold) are one
    /// valley of spread 0; exercised at both, the same difference splits them.
    #[test]
    fn a_parameter_not_exercised_does_not_split_valleys() {
        let mut a = minimum(100.0, 100.0, vec![1.0, 1.0], 0);
        let mut b = minimum(100.0, 100.0, vec![1.0, 2.0], 1);
        assert_eq!(valleys(&[a.clone(), b.clone()], 0.02).len(), 2);
        a.exercised = vec![true, true];
        b.exercised = vec![true, false];
        let v = valleys(&[a.clone(), b.clone()], 0.02);
        assert_eq!(v.len(), 1, "{v:#?}");
        assert_eq!(v[0].spread, 0.0);
        // The other parameter still counts.
        b.values[0] = 1.5;
        assert_eq!(valleys(&[a, b], 0.02).len(), 2);
        assert!(compared(&[], &[], 3));
        assert!(!compared(&[true, false], &[], 1));
        assert!(!compared(&[], &[true, false], 1));
    }

    fn estimate(value: f64, start: f64, lower: f64, upper: f64) -> ParameterEstimate {
        ParameterEstimate {
            name: "p".into(),
            index: 0,
            start,
            value,
            sigma: None,
            lower,
            upper,
            active_bound: None,
        }
    }

    /// The probe's scale: `|θ|`, else `|start|`, half the width of finite bounds, the
    /// draw's scale, σ, the larger finite bound, 1.
    #[test]
    fn the_probe_scale_follows_the_draw() {
        assert_eq!(
            probe_scale(&estimate(-3.0, 1.0, -10.0, 10.0), Some(7.0)),
            3.0
        );
        assert_eq!(
            probe_scale(&estimate(0.0, -0.5, -10.0, 10.0), Some(7.0)),
            0.5
        );
        assert_eq!(probe_scale(&estimate(0.0, 0.0, -2.0, 2.0), Some(7.0)), 2.0);
        let open = estimate(0.0, 0.0, 0.0, f64::INFINITY);
        assert_eq!(probe_scale(&open, Some(7.0)), 7.0);
        let with_sigma = ParameterEstimate {
            sigma: Some(0.25),
            ..open.clone()
        };
        assert_eq!(probe_scale(&with_sigma, None), 0.25);
        assert_eq!(
            probe_scale(&estimate(0.0, 0.0, -4.0, f64::INFINITY), None),
            4.0
        );
        assert_eq!(
            probe_scale(&estimate(0.0, 0.0, f64::NEG_INFINITY, f64::INFINITY), None),
            1.0
        );
    }

    #[test]
    fn a_draw_outside_is_moved_halfway_to_the_bound() {
        assert_eq!(inside(1.5, 0.5, 0.0, 1.0), 0.75);
        assert_eq!(inside(-1.0, 0.5, 0.0, 1.0), 0.25);
        assert_eq!(inside(0.0, 0.5, 0.0, 1.0), 0.25);
        assert_eq!(inside(0.7, 0.5, 0.0, 1.0), 0.7);
        assert_eq!(inside(-1.0, 0.0, 0.0, 1.0), 0.0);
        assert_eq!(inside(f64::INFINITY, 1e308, 0.0, f64::INFINITY), 1e308);
    }
}
