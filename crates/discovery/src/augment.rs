//! The "fix" of discovery: write named terms into the assumed model (a
//! [`TermModel`]) and calibrate their coefficients — and optionally the initial states —
//! by free-run simulation error, because coefficients regressed on MME's `d̂` are shrunk
//! by the weight `W` (MME trades model error against fit, so `d̂` under-reports the
//! missing term).
//!
//! # Cost
//!
//! `J(θ) = (1/M) Σ_experiments Σ_k Σ_channels w_c·(y_ck − (C x_sim(t_k; θ))_c)²` over the
//! `M` measured (non-NaN) values, with `w_c = 1/R_c` (noise variances given) or
//! `1/var(y_c)`. With `w = 1/R` a correct model gives `J ≈ 1`.
//!
//! # Solver
//!
//! The workspace's Levenberg–Marquardt ([`sysid_core::least_squares`]: MINPACK's column
//! scaling, gain-ratio damping) on the residuals `√(w_c/M)·(y − ŷ)`, started from the
//! regression coefficients. Jacobians come from forward sensitivities integrated with the
//! state (the exact derivative of the RK4 simulation, module `sensitivity`); finite
//! differences (step `1e-5·max(|θ_j|, 0.01)`, forward inside the solver, central for the
//! standard errors) stand in for the adaptive integrator, for a term whose derivative does
//! not build, and from the first non-finite sensitivity on.
//! A trial step whose simulation diverges counts as a failed step. A stage stops when an
//! accepted step lowers `J` by at most `tolerance·J` (converged), when no damping gives a
//! descent (reported as [`sysid_core::Termination::NoDescent`], not as converged: a
//! stationary point to working precision, or a Jacobian that does not describe the
//! residuals), or after `max_iterations` Jacobians. A
//! calibration none of whose stages moved `J`, ending at a rank-deficient Jacobian, stopped
//! where it started ([`sysid_core::Termination::NoProgress`]): an error
//! ([`DiscoveryError::NoProgress`]), not a calibrated model.
//!
//! **Growing horizons.** Free-run error of an oscillator is far from convex in its
//! coefficients: a 40 % error in a stiffness shifts the phase by half a period within a
//! few cycles, and a local solver on the full record then settles in a wrong valley. The
//! solve therefore runs in stages on the first 10 %, 25 %, 50 % and 100 % of every
//! experiment (`horizons`), each warm-started from the previous one, so that the phase
//! error stays small at every stage (a continuation in the horizon, as in multiple
//! shooting's initialisation). The reported termination is that of the last stage.
//! The reported standard errors are `√diag(σ̂²(J_ρᵀJ_ρ)⁻¹)` with `ρ = √w·(y − ŷ)` and
//! `σ̂² = Σρ²/(M − p)`: valid for white measurement noise (an output-error model).

use nalgebra::{DMatrix, DVector};
use sysid_core::integrate::DEFAULT_BLOW_UP;
use sysid_core::{
    Dataset, Dynamics, Experiment, Integrator, IterationRecord, LeastSquaresProblem, LinearModel,
    LmSettings, Term, TermModel, TermSpec, Termination, levenberg_marquardt, simulate_experiment,
};

use crate::error::{DiscoveryError, Result};
use crate::propose::FoundEffect;

mod initial;
pub(crate) mod sensitivity;
#[cfg(test)]
mod tests;

pub use initial::fit_initial_states;

/// Add named effects to `model` as `[[terms]]`: each effect's integrable form
/// (`model_effect`, `model_term`) with its coefficient, on its state's equation.
pub fn augment(model: &LinearModel, effects: &[FoundEffect]) -> Result<TermModel> {
    let specs = effects.iter().map(|e| TermSpec {
        state: &e.state,
        into: None,
        effect: &e.model_effect,
        term: &e.model_term,
        coefficient: e.coefficient,
    });
    Ok(TermModel::from_specs(model.clone(), specs)?)
}

/// Whether the initial states are calibrated too.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum InitialState {
    /// Keep the given initial states.
    Fixed,
    /// Calibrate every experiment's initial state with the coefficients.
    Estimate,
}

/// How the output channels are weighted in the cost.
#[derive(Debug, Clone, PartialEq)]
pub enum OutputWeights {
    /// `1/R_c` with these noise variances (one per output, > 0).
    NoiseVariance(Vec<f64>),
    /// `1/var(y_c)` over all experiments.
    DataVariance,
}

/// Settings of [`calibrate`].
#[derive(Debug, Clone, PartialEq)]
pub struct CalibrationConfig {
    /// Integrator of the free-run simulations. Default RK4 with 4 sub-steps.
    pub integrator: Integrator,
    /// Whether initial states are calibrated. Default [`InitialState::Fixed`].
    pub initial_state: InitialState,
    /// Channel weights. Default [`OutputWeights::DataVariance`].
    pub weights: OutputWeights,
    /// Indices of the terms whose coefficients are calibrated; `None` = all.
    pub terms: Option<Vec<usize>>,
    /// Horizons of the successive stages, as fractions of each experiment's length
    /// (increasing, in (0, 1], the last 1). Default `[0.1, 0.25, 0.5, 1.0]`.
    pub horizons: Vec<f64>,
    /// Iteration budget per stage (≥ 1). Default 50.
    pub max_iterations: usize,
    /// Relative cost decrease below which an accepted step ends the solve (> 0).
    /// Default 1e-10.
    pub tolerance: f64,
    /// States beyond this magnitude count as a diverged simulation (> 0). Default 1e12.
    pub blow_up: f64,
}

impl Default for CalibrationConfig {
    fn default() -> Self {
        Self {
            integrator: Integrator::Rk4 { substeps: 4 },
            initial_state: InitialState::Fixed,
            weights: OutputWeights::DataVariance,
            terms: None,
            horizons: vec![0.1, 0.25, 0.5, 1.0],
            max_iterations: 50,
            tolerance: 1e-10,
            blow_up: DEFAULT_BLOW_UP,
        }
    }
}

/// The calibrated model and how the calibration went.
#[derive(Debug, Clone)]
pub struct Calibration {
    /// The model with calibrated coefficients.
    pub model: TermModel,
    /// Initial state per experiment (calibrated or as given).
    pub x0: Vec<Vec<f64>>,
    /// Free-run cost `J` at the start.
    pub cost_before: f64,
    /// Free-run cost `J` at the end.
    pub cost_after: f64,
    /// Coefficients of every term at the start.
    pub coefficients_before: Vec<f64>,
    /// Coefficients of every term at the end.
    pub coefficients_after: Vec<f64>,
    /// Standard error of every term's coefficient (`NaN` for terms not calibrated).
    pub coefficient_std: Vec<f64>,
    /// Accepted iterations.
    pub iterations: Vec<IterationRecord>,
    /// Why the solver's last stage stopped, as the solver reported it (e.g. `Converged`;
    /// `NoDescent` when no damped step lowered the cost, a stationary point to working
    /// precision rather than a convergence test met; `MaxIterations`; `Exact` with
    /// nothing to calibrate). A caller that accepts several names each one it accepts.
    pub termination: Termination,
    /// Free-run simulations run.
    pub evaluations: usize,
}

/// The linear part plus terms with coefficients taken from a slice (no rebuild per trial).
struct Trial<'a> {
    linear: &'a LinearModel,
    terms: &'a [Term],
    coefficients: &'a [f64],
}

impl Dynamics for Trial<'_> {
    fn n_states(&self) -> usize {
        self.linear.n_states()
    }
    fn n_inputs(&self) -> usize {
        self.linear.n_inputs()
    }
    fn rhs(&self, t: f64, x: &[f64], u: &[f64], dx: &mut [f64]) {
        trial_rhs(self.linear, self.terms, self.coefficients, t, x, u, dx);
    }
}

/// `dx = A x + B u + Σ_k c_k φ_k(x, u) (e_{s_k} − e_{r_k})`: the right-hand side of a
/// [`Trial`], shared with the sensitivity pass so both simulate the same bits.
pub(crate) fn trial_rhs(
    linear: &LinearModel,
    terms: &[Term],
    coefficients: &[f64],
    t: f64,
    x: &[f64],
    u: &[f64],
    dx: &mut [f64],
) {
    linear.rhs(t, x, u, dx);
    for (term, c) in terms.iter().zip(coefficients) {
        let v = c * term.expr.eval_parts(x, u);
        dx[term.state] += v;
        if let Some(r) = term.into {
            dx[r] -= v;
        }
    }
}

/// Number of measured (non-missing) output values over every record of `data`: the `M`
/// of the free-run cost `J = (1/M) Σ r²/R`.
pub fn measured_values(data: &Dataset) -> usize {
    data.experiments()
        .iter()
        .map(|e| e.outputs().iter().filter(|v| !v.is_nan()).count())
        .sum()
}

/// Outputs `C x_sim` (`p × N`) of a free-run simulation of `f` over one experiment from
/// `x0`, with the experiment's inputs held between samples.
pub fn simulate_outputs<D: Dynamics + ?Sized>(
    f: &D,
    c: &DMatrix<f64>,
    x0: &[f64],
    experiment: &Experiment,
    integrator: &Integrator,
) -> sysid_core::Result<DMatrix<f64>> {
    simulate_window(
        f,
        c,
        x0,
        experiment,
        experiment.len(),
        integrator,
        DEFAULT_BLOW_UP,
    )
}

/// [`simulate_outputs`] over the first `len` samples with a given blow-up bound.
fn simulate_window<D: Dynamics + ?Sized>(
    f: &D,
    c: &DMatrix<f64>,
    x0: &[f64],
    experiment: &Experiment,
    len: usize,
    integrator: &Integrator,
    blow_up: f64,
) -> sysid_core::Result<DMatrix<f64>> {
    let x = simulate_experiment(f, x0, experiment, 0..len, integrator, blow_up)?;
    Ok(c * x)
}

struct Problem<'a> {
    linear: &'a LinearModel,
    terms: &'a [Term],
    data: &'a Dataset,
    weights: Vec<f64>,
    free: Vec<usize>,
    estimate_x0: bool,
    base_coefficients: Vec<f64>,
    base_x0: &'a [Vec<f64>],
    integrator: Integrator,
    blow_up: f64,
    /// Samples used per experiment (the current horizon).
    lengths: Vec<usize>,
    /// Measured values within the horizon.
    valid: usize,
    evaluations: usize,
    /// Term derivatives for sensitivity Jacobians; `None` = finite differences.
    partials: Option<sensitivity::Partials>,
}

impl Problem<'_> {
    /// Use the first `fraction` of every experiment (at least 10 samples, or all).
    fn set_horizon(&mut self, fraction: f64) {
        let p = self.weights.len();
        self.lengths = self
            .data
            .experiments()
            .iter()
            .map(|e| ((fraction * e.len() as f64).ceil() as usize).clamp(e.len().min(10), e.len()))
            .collect();
        self.valid = self
            .data
            .experiments()
            .iter()
            .zip(&self.lengths)
            .map(|(e, &len)| {
                (0..len)
                    .map(|k| (0..p).filter(|&c| !e.outputs()[(c, k)].is_nan()).count())
                    .sum::<usize>()
            })
            .sum();
    }

    fn unpack(&self, theta: &[f64]) -> (Vec<f64>, Vec<Vec<f64>>) {
        let mut coefficients = self.base_coefficients.clone();
        for (i, &k) in self.free.iter().enumerate() {
            coefficients[k] = theta[i];
        }
        let mut x0 = self.base_x0.to_vec();
        if self.estimate_x0 {
            let n = self.linear.n_states();
            let mut at = self.free.len();
            for x in &mut x0 {
                x.copy_from_slice(&theta[at..at + n]);
                at += n;
            }
        }
        (coefficients, x0)
    }

    /// Weighted residuals `√(w/M)(y − ŷ)`, or the simulation error.
    fn residuals(&mut self, theta: &[f64]) -> Result<DVector<f64>, (usize, sysid_core::CoreError)> {
        self.evaluations += 1;
        let (coefficients, x0) = self.unpack(theta);
        let f = Trial {
            linear: self.linear,
            terms: self.terms,
            coefficients: &coefficients,
        };
        let mut r = Vec::with_capacity(self.valid);
        let scale = 1.0 / (self.valid as f64).sqrt();
        for (e, exp) in self.data.experiments().iter().enumerate() {
            let len = self.lengths[e];
            let y_sim = simulate_window(
                &f,
                self.linear.c(),
                &x0[e],
                exp,
                len,
                &self.integrator,
                self.blow_up,
            )
            .map_err(|err| (e, err))?;
            let y = exp.outputs();
            for k in 0..len {
                for (ch, w) in self.weights.iter().enumerate() {
                    let v = y[(ch, k)];
                    if !v.is_nan() {
                        r.push(scale * w.sqrt() * (v - y_sim[(ch, k)]));
                    }
                }
            }
        }
        Ok(DVector::from_vec(r))
    }
}

/// Channel weights and the number of measured values; checks shapes.
fn weights_for(
    linear: &LinearModel,
    data: &Dataset,
    weights: &OutputWeights,
) -> Result<(Vec<f64>, usize)> {
    let p = linear.n_outputs();
    if data.output_channels().len() != p {
        return Err(DiscoveryError::Length {
            what: "output channels of the data vs the model",
            found: data.output_channels().len(),
            expected: p,
        });
    }
    if data.input_channels().len() != linear.n_inputs() {
        return Err(DiscoveryError::Length {
            what: "input channels of the data vs the model",
            found: data.input_channels().len(),
            expected: linear.n_inputs(),
        });
    }
    let mut valid = 0;
    let mut sums = vec![(0.0, 0.0, 0usize); p];
    for exp in data.experiments() {
        for k in 0..exp.len() {
            for (ch, s) in sums.iter_mut().enumerate() {
                let v = exp.outputs()[(ch, k)];
                if !v.is_nan() {
                    s.0 += v;
                    s.1 += v * v;
                    s.2 += 1;
                    valid += 1;
                }
            }
        }
    }
    let w = match weights {
        OutputWeights::NoiseVariance(r) => {
            if r.len() != p {
                return Err(DiscoveryError::Length {
                    what: "noise variances",
                    found: r.len(),
                    expected: p,
                });
            }
            for &v in r {
                if !(v.is_finite() && v > 0.0) {
                    return Err(DiscoveryError::InvalidConfig {
                        field: "weights",
                        value: v,
                        reason: "noise variances must be positive and finite",
                    });
                }
            }
            r.iter().map(|v| 1.0 / v).collect()
        }
        OutputWeights::DataVariance => sums
            .iter()
            .map(|&(s, ss, c)| {
                let c = c.max(2) as f64;
                let var = (ss - s * s / c) / (c - 1.0);
                if var > 0.0 { 1.0 / var } else { 1.0 }
            })
            .collect(),
    };
    Ok((w, valid))
}

/// The free-run cost `J` (module doc) of any dynamics with output matrix `c` on `data`
/// from the initial states `x0` (one per experiment) — e.g. of the assumed model, for the
/// "before" column of a report.
pub fn free_run_cost<D: Dynamics + ?Sized>(
    f: &D,
    linear: &LinearModel,
    data: &Dataset,
    x0: &[Vec<f64>],
    weights: &OutputWeights,
    integrator: &Integrator,
) -> Result<f64> {
    let (w, valid) = weights_for(linear, data, weights)?;
    check_x0(linear, data, x0)?;
    let mut sse = 0.0;
    for (e, exp) in data.experiments().iter().enumerate() {
        let y_sim = simulate_outputs(f, linear.c(), &x0[e], exp, integrator).map_err(|source| {
            DiscoveryError::Simulation {
                experiment: e,
                source,
            }
        })?;
        for k in 0..exp.len() {
            for (ch, wc) in w.iter().enumerate() {
                let v = exp.outputs()[(ch, k)];
                if !v.is_nan() {
                    sse += wc * (v - y_sim[(ch, k)]).powi(2);
                }
            }
        }
    }
    Ok(sse / valid.max(1) as f64)
}

fn check_x0(linear: &LinearModel, data: &Dataset, x0: &[Vec<f64>]) -> Result<()> {
    if x0.len() != data.experiments().len() {
        return Err(DiscoveryError::Length {
            what: "initial states vs experiments",
            found: x0.len(),
            expected: data.experiments().len(),
        });
    }
    for x in x0 {
        if x.len() != linear.n_states() {
            return Err(DiscoveryError::Length {
                what: "initial state",
                found: x.len(),
                expected: linear.n_states(),
            });
        }
    }
    Ok(())
}

/// Calibrate the term coefficients of `model` (and optionally the initial states) by
/// free-run simulation error on `data`, starting from the model's coefficients and `x0`
/// (one initial state per experiment). See the module doc for cost and solver.
///
/// Errors: invalid config; data channels or `x0` not matching the model; a term index
/// out of range; no measured value; a simulation that diverges at the starting point; a
/// calibration that stopped where it started ([`DiscoveryError::NoProgress`]: no stage
/// moved the cost and the Jacobian at the start is rank-deficient, e.g. a term that is
/// zero along the whole start trajectory).
pub fn calibrate(
    model: &TermModel,
    data: &Dataset,
    x0: &[Vec<f64>],
    config: &CalibrationConfig,
) -> Result<Calibration> {
    if config.max_iterations == 0 {
        return Err(DiscoveryError::InvalidConfig {
            field: "max_iterations",
            value: 0.0,
            reason: "at least 1",
        });
    }
    if !(config.tolerance.is_finite() && config.tolerance > 0.0) {
        return Err(DiscoveryError::InvalidConfig {
            field: "tolerance",
            value: config.tolerance,
            reason: "must be positive and finite",
        });
    }
    let h = &config.horizons;
    if h.last().is_none_or(|&l| (l - 1.0).abs() > 0.0)
        || h.iter().any(|&f| !(f > 0.0 && f <= 1.0))
        || h.windows(2).any(|w| w[1] <= w[0])
    {
        return Err(DiscoveryError::InvalidConfig {
            field: "horizons",
            value: h.last().copied().unwrap_or(f64::NAN),
            reason: "fractions must increase within (0, 1] and end at 1",
        });
    }
    if config.blow_up.is_nan() || config.blow_up <= 0.0 {
        return Err(DiscoveryError::InvalidConfig {
            field: "blow_up",
            value: config.blow_up,
            reason: "must be positive",
        });
    }
    let linear = model.linear();
    let terms = model.terms();
    let (weights, valid) = weights_for(linear, data, &config.weights)?;
    check_x0(linear, data, x0)?;
    if valid == 0 {
        return Err(DiscoveryError::TooFewSamples {
            what: "measured values for calibration",
            found: 0,
            needed: 1,
        });
    }
    let free: Vec<usize> = match &config.terms {
        Some(list) => {
            for &k in list {
                if k >= terms.len() {
                    return Err(DiscoveryError::InvalidConfig {
                        field: "terms",
                        value: k as f64,
                        reason: "term index out of range",
                    });
                }
            }
            list.clone()
        }
        None => (0..terms.len()).collect(),
    };
    let base: Vec<f64> = terms.iter().map(|t| t.coefficient).collect();
    let estimate_x0 = config.initial_state == InitialState::Estimate;
    let mut theta: Vec<f64> = free.iter().map(|&k| base[k]).collect();
    if estimate_x0 {
        theta.extend(x0.iter().flatten());
    }
    let mut problem = Problem {
        linear,
        terms,
        data,
        weights,
        free,
        estimate_x0,
        base_coefficients: base.clone(),
        base_x0: x0,
        integrator: config.integrator,
        blow_up: config.blow_up,
        lengths: data.experiments().iter().map(|e| e.len()).collect(),
        valid,
        evaluations: 0,
        partials: None,
    };
    problem.partials = sensitivity_partials(&problem);
    problem.set_horizon(1.0);
    let r_full = problem
        .residuals(&theta)
        .map_err(|(experiment, source)| DiscoveryError::Simulation { experiment, source })?;
    let cost_before = r_full.norm_squared();
    let mut iterations = Vec::new();
    let mut termination = Termination::Exact;
    // Until a stage moves the cost each one is asked whether it stopped where it started;
    // a later stage that finds nothing to do (warm-started at a moved point) reports how
    // it ended (converged, or no descent), not a failure.
    let mut ask = true;
    let mut rank = None;
    for &fraction in &config.horizons {
        problem.set_horizon(fraction);
        let stage = lm_stage(&mut problem, theta, config, ask, &mut iterations)?;
        theta = stage.theta;
        termination = stage.termination;
        rank = stage.rank;
        ask &= !stage.moved;
    }
    // No stage moved and the last (the full records) stopped at a rank-deficient start:
    // no calibrated model.
    if termination == Termination::NoProgress {
        let (rank, of) = rank.unwrap_or((0, theta.len()));
        return Err(DiscoveryError::NoProgress {
            what: "the free-run calibration",
            rank,
            of,
        });
    }
    problem.set_horizon(1.0);
    let r = problem
        .residuals(&theta)
        .map_err(|(experiment, source)| DiscoveryError::Simulation { experiment, source })?;
    let cost = r.norm_squared();
    let p = theta.len();
    // Standard errors at the end (ρ = √M·r, so J_ρᵀJ_ρ = M·JᵀJ).
    let m = r.len() as f64;
    let mut coefficient_std = vec![f64::NAN; base.len()];
    if p > 0 && m > p as f64 {
        let jac_end = jacobian(&mut problem, &theta, None)?;
        let sigma2 = cost * m / (m - p as f64);
        if let Some(inv) = (jac_end.transpose() * &jac_end * m).try_inverse() {
            for (i, &k) in problem.free.iter().enumerate() {
                coefficient_std[k] = (sigma2 * inv[(i, i)]).max(0.0).sqrt();
            }
        }
    }
    let (coefficients, x0_end) = problem.unpack(&theta);
    let new_terms: Vec<Term> = terms
        .iter()
        .zip(&coefficients)
        .map(|(t, &c)| Term {
            coefficient: c,
            ..t.clone()
        })
        .collect();
    let calibrated = TermModel::new(linear.clone(), new_terms)?;
    Ok(Calibration {
        model: calibrated,
        x0: x0_end,
        cost_before,
        cost_after: cost,
        coefficients_before: base,
        coefficients_after: coefficients,
        coefficient_std,
        iterations,
        termination,
        evaluations: problem.evaluations,
    })
}

/// The calibration at its current horizon as a least-squares problem.
struct Stage<'p, 'a> {
    problem: &'p mut Problem<'a>,
}

impl LeastSquaresProblem for Stage<'_, '_> {
    type Error = DiscoveryError;

    fn residual_count(&self) -> usize {
        self.problem.valid
    }

    /// A diverging trial simulation is a rejected step.
    fn residuals(&mut self, theta: &[f64], r: &mut [f64]) -> Result<bool> {
        Ok(match self.problem.residuals(theta) {
            Ok(v) => {
                r.copy_from_slice(v.as_slice());
                true
            }
            Err(_) => false,
        })
    }

    fn jacobian(&mut self, theta: &[f64], r: &[f64], jac: &mut DMatrix<f64>) -> Result<()> {
        let at = DVector::from_column_slice(r);
        jac.copy_from(&jacobian(self.problem, theta, Some(&at))?);
        Ok(())
    }
}

/// How one stage of [`calibrate`] ended.
struct StageEnd {
    theta: Vec<f64>,
    termination: Termination,
    /// Whether the stage lowered its cost ([`sysid_core::LmReport::moved`]).
    moved: bool,
    /// Rank and columns of the normalised `JᵀJ` when the no-progress test ran.
    rank: Option<(usize, usize)>,
}

/// One Levenberg–Marquardt solve ([`sysid_core::least_squares`]) at the problem's current
/// horizon, from `theta`; its accepted steps are appended to `iterations`. The solver's
/// termination is reported as it is: a stage that finds no descent at any damping ends
/// [`Termination::NoDescent`] (never relabelled as converged) — or, when
/// `ask_no_progress` and it never moved from a rank-deficient start,
/// [`Termination::NoProgress`] ([`LmSettings::no_progress`]).
fn lm_stage(
    problem: &mut Problem<'_>,
    theta: Vec<f64>,
    config: &CalibrationConfig,
    ask_no_progress: bool,
    iterations: &mut Vec<IterationRecord>,
) -> Result<StageEnd> {
    if theta.is_empty() {
        return Ok(StageEnd {
            theta,
            termination: Termination::Exact,
            moved: false,
            rank: None,
        });
    }
    // The start of a stage must simulate: its error names the experiment.
    problem
        .residuals(&theta)
        .map_err(|(experiment, source)| DiscoveryError::Simulation { experiment, source })?;
    let settings = LmSettings {
        max_iterations: config.max_iterations,
        ftol: config.tolerance,
        no_progress: ask_no_progress,
        ..LmSettings::default()
    };
    let solution = levenberg_marquardt(&mut Stage { problem }, &theta, &settings)?;
    for step in &solution.report.steps {
        iterations.push(IterationRecord {
            iteration: iterations.len() + 1,
            ..*step
        });
    }
    Ok(StageEnd {
        theta: solution.theta,
        termination: solution.report.termination,
        moved: solution.report.moved(),
        rank: solution.report.rank,
    })
}

/// Term derivatives for sensitivity Jacobians, or `None` where finite differences must
/// do: the adaptive integrator, a repeated calibrated term, a derivative that does not
/// build.
fn sensitivity_partials(problem: &Problem<'_>) -> Option<sensitivity::Partials> {
    if !matches!(problem.integrator, Integrator::Rk4 { .. }) {
        return None;
    }
    let mut seen = vec![false; problem.terms.len()];
    for &k in &problem.free {
        if std::mem::replace(&mut seen[k], true) {
            return None;
        }
    }
    sensitivity::Partials::new(problem.linear.n_states(), problem.terms)
}

/// Jacobian of the residuals at `theta` (`at` = the residuals there, when known): by
/// forward sensitivities when the problem has them, else (or once a sensitivity turns
/// non-finite, for the rest of the calibration) by [`jacobian_fd`]. A diverging
/// simulation is an error naming the experiment.
fn jacobian(
    problem: &mut Problem<'_>,
    theta: &[f64],
    at: Option<&DVector<f64>>,
) -> Result<DMatrix<f64>> {
    if let (Some(partials), Integrator::Rk4 { substeps }) = (&problem.partials, problem.integrator)
    {
        let outcome = sensitivity::jacobian(problem, partials, theta, substeps)
            .map_err(|(experiment, source)| DiscoveryError::Simulation { experiment, source })?;
        problem.evaluations += 1;
        match outcome {
            sensitivity::Outcome::Jacobian(j) => return Ok(j),
            sensitivity::Outcome::NonFinite => problem.partials = None,
        }
    }
    jacobian_fd(problem, theta, at)
}

/// Finite-difference Jacobian of the residuals: forward differences from the residual
/// `at` (inside the solver, where a step direction needs no more), central differences
/// when `at` is `None`. A diverging perturbed simulation is an error naming the
/// experiment.
fn jacobian_fd(
    problem: &mut Problem<'_>,
    theta: &[f64],
    at: Option<&DVector<f64>>,
) -> Result<DMatrix<f64>> {
    let p = theta.len();
    let mut cols: Vec<DVector<f64>> = Vec::with_capacity(p);
    let mut t = theta.to_vec();
    for j in 0..p {
        let h = 1e-5 * theta[j].abs().max(0.01);
        t[j] = theta[j] + h;
        let plus = problem.residuals(&t);
        if let Some(r0) = at {
            t[j] = theta[j];
            match plus {
                Ok(a) => cols.push((a - r0) / h),
                Err((experiment, source)) => {
                    return Err(DiscoveryError::Simulation { experiment, source });
                }
            }
            continue;
        }
        t[j] = theta[j] - h;
        let minus = problem.residuals(&t);
        t[j] = theta[j];
        let (plus, minus) = match (plus, minus) {
            (Ok(a), Ok(b)) => (a, b),
            (Err((experiment, source)), _) | (_, Err((experiment, source))) => {
                return Err(DiscoveryError::Simulation { experiment, source });
            }
        };
        cols.push((plus - minus) / (2.0 * h));
    }
    let rows = cols.first().map_or(0, |c| c.len());
    Ok(DMatrix::from_fn(rows, p, |i, j| cols[j][i]))
}
