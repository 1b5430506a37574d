//! Grey-box parameter estimation (what MATLAB's `nlgreyest` does): the free parameters of
//! a [`ParametricDynamics`] model (a [`crate::PhysicalModel`]), within their bounds,
//! together with the initial state of every record, by the output error of RK4
//! simulations weighted by the noise variance,
//!
//! ```text
//! min Σ_records Σ_k Σ_i (ỹ_ik − (C x(t_k; p, x0))_i)² / σ_i²
//! ```
//!
//! on one or several records, by the workspace's one Levenberg–Marquardt
//! ([`crate::least_squares`]), with the exact Jacobian of the simulated outputs from the
//! tangent RK4 step ([`crate::tangent`]: `∂x/∂x0` and `∂x/∂p`, the latter driven by
//! [`ParametricDynamics::parameter_jacobian`]); no finite differences.
//!
//! **Shooting.** [`Shooting::FreeRun`] simulates each record from its one start state.
//! [`Shooting::Multiple`] first cuts each record into segments of a given length, each
//! with its own start state (started from the model's prediction with the measured part
//! replaced by the measurement, `x + C⁺(ỹ − Cx)`), continuity between consecutive segments
//! asked of the solver as weighted defect residuals; then it runs the free-run solve from
//! there. Long or lightly damped records, whose free run from a poor start is far from the
//! data (and whose cost surface is full of local minima), are calibrated this way. The
//! estimates, their uncertainty and the fit always come from the free-run solve.
//!
//! **Bounds** by a change of variable (`greybox/transform.rs`): a parameter whose optimum lies on
//! its bound is reported there ([`ActiveBound`]) and held fixed in the covariance (no σ,
//! no column in the rank). A free parameter with equal bounds is held at that value out
//! of the solver and reported [`ActiveBound::Fixed`] the same way.
//!
//! **Uncertainty.** With `J` the Jacobian of the weighted residuals along the physical
//! parameters (those on a bound left out) and the start states at the optimum, `N`
//! residuals, `P` its columns and `s² = ‖r‖²/(N − P)`, the covariance is `s²·(JᵀJ)⁻¹`
//! (Gauss–Newton, scaled by the residual variance, so a misstated noise variance scales
//! out). Columns
//! are normalised before the eigen-decomposition; a direction whose eigenvalue is below
//! `1e-12` of the largest is not identifiable, and every parameter with a share in such a
//! direction gets no σ ([`ParameterEstimate::sigma`] `None`; the rank is reported). The
//! residuals of sampled data are rarely white (quantisation, unmodelled dynamics), so
//! these σ are the usual optimistic ones.
//!
//! **Stopped where it started.** A start at a stationary point of a degenerate problem
//! (an unmeasured state at a term's singular point, `sqrt(0)`, whose sensitivity is
//! zero) ends the solver at once, as if converged. While no solve of the estimation has
//! moved the cost, the solver is asked to tell that apart ([`LmSettings::no_progress`]):
//! a solve that does not move the cost and whose Jacobian is rank-deficient ends
//! [`crate::Termination::NoProgress`], and the caller reports no estimate. A re-solve
//! after the cost has moved (more sub-steps at the estimate) that finds nothing to do is
//! converged.
//!
//! An estimator in sysid-core, stated in its README: like the initial-state fit it is a
//! generic step on sysid-core's own model, solver and integrator.

use nalgebra::{DMatrix, SymmetricEigen};

use crate::dataset::Experiment;
use crate::error::{CoreError, Result};
use crate::least_squares::{LmReport, LmSettings, levenberg_marquardt};
use crate::metrics::channel_metrics;
use crate::physical::{Estimation, ParametricDynamics};
use crate::stiff::{Substeps, resolve_substeps};

mod problem;
mod transform;

use problem::{Calibration, Segment};
use transform::Transform;

/// How the records are simulated in the solve.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Shooting {
    /// Each record from its one start state.
    #[default]
    FreeRun,
    /// Segments of `segment` samples, each from its own start state, continuity asked of
    /// the solver; then the free-run solve from there (module doc).
    Multiple {
        /// Samples per segment (at least 2; the last segment of a record takes the rest).
        segment: usize,
    },
}

/// Settings of [`estimate_parameters`].
#[derive(Debug, Clone, PartialEq)]
pub struct GreyboxOptions {
    /// RK4 steps per sample interval. Default `Auto { min: 2 }`: two, or as many as a
    /// stiff model needs along each record ([`crate::stiff`]; probed at the start values
    /// and again at the estimate, whose free run is solved again when it needs more).
    pub substeps: Substeps,
    /// Free run or multiple shooting first. Default free run.
    pub shooting: Shooting,
    /// Most Levenberg–Marquardt iterations per solve. Default 100.
    pub max_iterations: usize,
    /// Relative cost decrease at which a solve has converged. Default 1e-10.
    pub ftol: f64,
    /// A state beyond this magnitude is a diverged simulation (a rejected step).
    /// Default 1e6.
    pub blow_up: f64,
    /// Weight of a continuity defect in multiple shooting, in units of `1/σ` of the
    /// measured channels (a defect of one noise σ in any state costs `w²`). Default 10.
    pub continuity_weight: f64,
    /// The job's budget (default unlimited): every Jacobian (one per Levenberg–Marquardt
    /// iteration) charges the RK4 steps of its simulation, and the estimate stops with
    /// [`CoreError::BudgetExhausted`] once it is spent.
    pub budget: crate::Budget,
}

impl Default for GreyboxOptions {
    fn default() -> Self {
        Self {
            substeps: Substeps::Auto { min: 2 },
            shooting: Shooting::FreeRun,
            max_iterations: 100,
            ftol: 1e-10,
            blow_up: 1e6,
            continuity_weight: 10.0,
            budget: crate::Budget::default(),
        }
    }
}

/// What to calibrate on.
#[derive(Debug, Clone, Copy)]
pub struct GreyboxData<'a> {
    /// Output matrix `y = C x` (`outputs × states`).
    pub c: &'a DMatrix<f64>,
    /// Noise variance of each output (positive), in the output's unit squared.
    pub noise_variance: &'a [f64],
    /// The records (inputs as the model's, outputs as `C`'s rows; NaN = not measured).
    pub records: &'a [Experiment],
    /// A start state per record, or empty: the minimum-norm `C x = ỹ(t0)`.
    pub x0: &'a [Vec<f64>],
}

/// The bound a parameter's estimate sits on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ActiveBound {
    /// Its lower bound.
    Lower,
    /// Its upper bound.
    Upper,
    /// Both: equal bounds hold it at that value (never estimated).
    Fixed,
}

/// One free parameter's estimate.
#[derive(Debug, Clone, PartialEq)]
pub struct ParameterEstimate {
    /// Its name.
    pub name: String,
    /// Index among all the model's parameters.
    pub index: usize,
    /// The value the solve started from.
    pub start: f64,
    /// The estimate.
    pub value: f64,
    /// Its standard deviation (module doc); `None` when it sits on a bound or is not
    /// identifiable from these records.
    pub sigma: Option<f64>,
    /// Lower bound.
    pub lower: f64,
    /// Upper bound.
    pub upper: f64,
    /// The bound the estimate sits on, if any.
    pub active_bound: Option<ActiveBound>,
}

/// One Levenberg–Marquardt solve of the estimation.
#[derive(Debug, Clone, PartialEq)]
pub struct StageReport {
    /// How the records were simulated.
    pub shooting: Shooting,
    /// Residuals of the solve.
    pub residuals: usize,
    /// Quantities estimated (parameters and start states).
    pub estimated: usize,
    /// The solver's report (cost `‖r‖²` of the weighted residuals).
    pub report: LmReport,
    /// RK4 steps per sample interval of each record in this solve.
    pub substeps: Vec<usize>,
}

/// The estimate: the model with the estimated values, per-parameter estimates with σ,
/// their correlations, the start states, the solves and the free-run fit.
#[derive(Debug, Clone)]
pub struct GreyboxFit<D> {
    /// The model with the estimated parameter values.
    pub model: D,
    /// The free parameters' estimates, in the model's order (one held by equal bounds
    /// among them, on its bound).
    pub parameters: Vec<ParameterEstimate>,
    /// Correlations of the free parameters (NaN in the row and column of one without σ).
    pub correlation: DMatrix<f64>,
    /// Estimated start state of each record.
    pub x0: Vec<Vec<f64>>,
    /// Their standard deviations (NaN where not identifiable).
    pub x0_sigma: Vec<Vec<f64>>,
    /// The solves, in order; the last is the free run the estimates come from.
    pub stages: Vec<StageReport>,
    /// `s² = ‖r‖²/(N − P)` of the final free run, `P` the estimated quantities not on a
    /// bound (1 when the noise variances are right and the model explains the data).
    pub residual_variance_ratio: f64,
    /// Rank of the normalised `JᵀJ` and the number of its columns.
    pub rank: (usize, usize),
    /// Free-run fit % (`100·(1 − ‖y − ŷ‖/‖y − ȳ‖)`) per record and output.
    pub fit_percent: Vec<Vec<f64>>,
    /// Free-run state trajectories per record (`n × N`).
    pub states: Vec<DMatrix<f64>>,
    /// RK4 steps per sample interval of each record in the final free run.
    pub substeps: Vec<usize>,
}

impl<D> GreyboxFit<D> {
    /// The final (free-run) solve's report.
    pub fn report(&self) -> &LmReport {
        &self.stages[self.stages.len() - 1].report
    }
}

/// Progress of [`estimate_parameters_with`]: the stage (`"multiple shooting"`, `"free
/// run"`), the accepted step and the cost after it.
pub type GreyboxObserver<'o> = &'o mut dyn FnMut(&str, usize, f64);

/// [`estimate_parameters_with`] without progress.
pub fn estimate_parameters<D: ParametricDynamics>(
    model: &D,
    data: &GreyboxData<'_>,
    opts: &GreyboxOptions,
) -> Result<GreyboxFit<D>> {
    estimate_parameters_with(model, data, opts, &mut |_, _, _| {})
}

/// Estimate the free parameters of `model` and the start state of every record (module
/// doc). Errors (before any simulation): no free parameters, a start value outside its
/// bounds, shapes of `C`, the noise variances, the start states or the records'
/// channels that do not match the model, a non-positive noise variance, a segment under
/// 2 samples, no more measured values than estimated quantities. A start whose
/// simulation diverges is [`CoreError::Diverged`]; a solve that does not converge is
/// reported in [`StageReport::report`], not as an error. So is a start the solver cannot
/// leave: while no solve of the estimation has moved the cost, one that stops without
/// moving it at a rank-deficient Jacobian ends [`crate::Termination::NoProgress`] (e.g. an
/// unmeasured state started at a term's singular point, `sqrt(0)`, where its sensitivity
/// is zero); the fit is then the start, not an estimate.
pub fn estimate_parameters_with<D: ParametricDynamics>(
    model: &D,
    data: &GreyboxData<'_>,
    opts: &GreyboxOptions,
    observer: GreyboxObserver<'_>,
) -> Result<GreyboxFit<D>> {
    let n = model.n_states();
    let Free {
        free,
        transforms,
        z: z0,
        pinned,
    } = free_parameters(model)?;
    validate(model, data, opts)?;
    let weight: Vec<f64> = data.noise_variance.iter().map(|v| 1.0 / v.sqrt()).collect();
    let x0 = start_states(data, n)?;
    // Until a solve moves the cost, each one is asked whether it stopped where it started
    // (Termination::NoProgress); after that a solve that does not move is a re-solve from
    // an estimate (more sub-steps), which has simply converged.
    let mut settings = LmSettings {
        max_iterations: opts.max_iterations,
        ftol: opts.ftol,
        no_progress: true,
        ..LmSettings::default()
    };
    let mut stages = Vec::new();
    let mut z = z0;
    let mut starts = x0;
    let mut counts = record_substeps(model, data.records, &starts, opts)?;

    if let Shooting::Multiple { segment } = opts.shooting {
        let segments = shooting_segments(data.records, segment);
        let mean_weight = weight.iter().sum::<f64>() / weight.len() as f64;
        let mut problem = Calibration::new(
            model,
            data.c,
            weight.clone(),
            data.records,
            free.clone(),
            transforms.clone(),
            segments.clone(),
            opts.continuity_weight * mean_weight,
            counts.clone(),
            opts.blow_up,
        );
        let theta0 = shooting_start(&mut problem, &z, &starts, &segments, data)?;
        problem.stage = "multiple shooting";
        problem.observer = Some(&mut *observer);
        problem.budget = opts.budget.clone();
        let solution = levenberg_marquardt(&mut problem, &theta0, &settings)?;
        settings.no_progress &= !solution.report.moved();
        stages.push(StageReport {
            shooting: opts.shooting,
            residuals: problem.rows,
            estimated: problem.dimension(),
            report: solution.report,
            substeps: counts.clone(),
        });
        if stages[0].report.termination != crate::Termination::Diverged {
            let nf = free.len();
            z = solution.theta[..nf].to_vec();
            for (si, seg) in segments.iter().enumerate() {
                if seg.start == 0 {
                    starts[seg.record] = solution.theta[nf + si * n..nf + (si + 1) * n].to_vec();
                }
            }
        }
    }

    let segments = whole_records(data.records);
    let mut problem = Calibration::new(
        model,
        data.c,
        weight,
        data.records,
        free.clone(),
        transforms.clone(),
        segments,
        0.0,
        counts.clone(),
        opts.blow_up,
    );
    let mut theta0 = z.clone();
    for x in &starts {
        theta0.extend_from_slice(x);
    }
    // A diverging start is an error naming where (the solver would only say "diverged").
    let mut r = vec![0.0; problem.rows];
    if !problem.residuals_checked(&theta0, &mut r)? {
        let states = problem.trajectories(&theta0)?;
        return Err(first_divergence(&states, data.records, opts.blow_up));
    }
    problem.observer = Some(&mut *observer);
    problem.budget = opts.budget.clone();
    let rows = problem.rows;
    let dim = problem.dimension();
    let mut theta = theta0;
    for round in 0.. {
        let solution = levenberg_marquardt(&mut problem, &theta, &settings)?;
        settings.no_progress &= !solution.report.moved();
        theta = solution.theta;
        stages.push(StageReport {
            shooting: Shooting::FreeRun,
            residuals: rows,
            estimated: dim,
            report: solution.report,
            substeps: counts.clone(),
        });
        // The estimate may be stiffer than the start (a larger friction level): probe it,
        // and solve again from it with the larger counts (at most twice).
        if round == 2 || !matches!(opts.substeps, Substeps::Auto { .. }) {
            break;
        }
        let at = problem.model_at(&theta)?;
        let x0s: Vec<Vec<f64>> = (0..data.records.len())
            .map(|r| theta[free.len() + r * n..free.len() + (r + 1) * n].to_vec())
            .collect();
        let needed = record_substeps(&at, data.records, &x0s, opts)?;
        if needed.iter().zip(&counts).all(|(a, b)| a <= b) {
            break;
        }
        counts = counts.iter().zip(&needed).map(|(a, b)| *a.max(b)).collect();
        problem.substeps = counts.clone();
    }
    problem.observer = None;

    // Uncertainty along the physical parameters.
    let nf = free.len();
    let bounds: Vec<Option<ActiveBound>> = transforms
        .iter()
        .zip(&theta)
        .map(|(t, &z)| t.at_bound(z))
        .collect();
    problem.physical_columns = true;
    let mut jac = DMatrix::zeros(rows, dim);
    crate::least_squares::LeastSquaresProblem::jacobian(&mut problem, &theta, &[], &mut jac)?;
    let cost = stages[stages.len() - 1].report.final_cost();
    // A parameter on its bound is held there: no column of the covariance, no share in the
    // rank, and not an estimated quantity in `s²`'s degrees of freedom.
    let keep: Vec<usize> = (0..dim)
        .filter(|&j| j >= nf || bounds[j].is_none())
        .collect();
    let ratio = cost / (rows.saturating_sub(keep.len())).max(1) as f64;
    let (cov, rank) = covariance(&jac, &keep, ratio);

    let estimated = problem.model_at(&theta)?;
    // Every free parameter in the model's order: the solver's column of each one it moved
    // (`None` for one held by equal bounds, which stays at its value, on its bound).
    let mut listed: Vec<(usize, Option<usize>)> = free
        .iter()
        .enumerate()
        .map(|(fi, &j)| (j, Some(fi)))
        .chain(pinned.iter().map(|&j| (j, None)))
        .collect();
    listed.sort_by_key(|&(j, _)| j);
    let mut parameters = Vec::with_capacity(listed.len());
    for &(j, column) in &listed {
        let p = &model.parameters()[j];
        parameters.push(match column {
            Some(fi) => {
                let var = cov[(fi, fi)];
                ParameterEstimate {
                    name: p.name.clone(),
                    index: j,
                    start: p.value,
                    value: transforms[fi].value(theta[fi]),
                    sigma: (var.is_finite() && bounds[fi].is_none()).then(|| var.sqrt()),
                    lower: p.lower,
                    upper: p.upper,
                    active_bound: bounds[fi],
                }
            }
            None => ParameterEstimate {
                name: p.name.clone(),
                index: j,
                start: p.value,
                value: p.value,
                sigma: None,
                lower: p.lower,
                upper: p.upper,
                active_bound: Some(ActiveBound::Fixed),
            },
        });
    }
    let mut correlation = DMatrix::from_element(listed.len(), listed.len(), f64::NAN);
    for (a, &(_, ca)) in listed.iter().enumerate() {
        for (b, &(_, cb)) in listed.iter().enumerate() {
            let (Some(ca), Some(cb)) = (ca, cb) else {
                continue;
            };
            let d = (cov[(ca, ca)] * cov[(cb, cb)]).sqrt();
            if d.is_finite() && d > 0.0 {
                correlation[(a, b)] = cov[(ca, cb)] / d;
            }
        }
    }
    let x0: Vec<Vec<f64>> = (0..data.records.len())
        .map(|r| theta[nf + r * n..nf + (r + 1) * n].to_vec())
        .collect();
    let x0_sigma = (0..data.records.len())
        .map(|r| {
            (0..n)
                .map(|l| {
                    let j = nf + r * n + l;
                    cov[(j, j)].sqrt()
                })
                .collect()
        })
        .collect();
    let states = problem.trajectories(&theta)?;
    let mut fit_percent = Vec::with_capacity(states.len());
    for (exp, xs) in data.records.iter().zip(&states) {
        let yhat = data.c * xs;
        let mut fits = Vec::with_capacity(exp.n_outputs());
        for i in 0..exp.n_outputs() {
            let measured: Vec<f64> = exp.outputs().row(i).iter().copied().collect();
            let predicted: Vec<f64> = yhat.row(i).iter().copied().collect();
            fits.push(channel_metrics(&measured, &predicted).map_or(f64::NAN, |m| m.fit_percent));
        }
        fit_percent.push(fits);
    }
    Ok(GreyboxFit {
        model: estimated,
        parameters,
        correlation,
        x0,
        x0_sigma,
        stages,
        residual_variance_ratio: ratio,
        rank: (rank, keep.len()),
        fit_percent,
        states,
        substeps: counts,
    })
}

/// The weighted free-run residuals `(ỹ − C x)/σ` of `model` at its current parameter
/// values on `data`'s records, each simulated from its start state in `x0` (one per
/// record) with `substeps[record]` RK4 steps per sample interval — the residuals whose
/// squared norm [`estimate_parameters`] minimises in its free-run solve, computed by the
/// same code (given a fit's `model`, `x0` and `substeps`, `‖r‖²` is its final cost up to
/// rounding). `data.x0` is not read. `Ok(None)` when a simulation leaves the blow-up
/// bound; errors: shapes that do not match (as [`estimate_parameters`]).
pub fn free_run_residuals<D: ParametricDynamics>(
    model: &D,
    data: &GreyboxData<'_>,
    x0: &[Vec<f64>],
    substeps: &[usize],
    blow_up: f64,
) -> Result<Option<Vec<f64>>> {
    let n = model.n_states();
    validate_shapes(model, data)?;
    CoreError::check_len(
        "start states (one per record)",
        x0.len(),
        data.records.len(),
    )?;
    CoreError::check_len(
        "sub-step counts (one per record)",
        substeps.len(),
        data.records.len(),
    )?;
    if substeps.contains(&0) {
        return Err(CoreError::InvalidArgument {
            name: "substeps",
            value: 0.0,
            reason: "at least one RK4 step per sample interval",
        });
    }
    let mut theta = Vec::with_capacity(n * x0.len());
    for x in x0 {
        CoreError::check_len("start state", x.len(), n)?;
        theta.extend_from_slice(x);
    }
    let weight: Vec<f64> = data.noise_variance.iter().map(|v| 1.0 / v.sqrt()).collect();
    let segments = whole_records(data.records);
    let mut problem = Calibration::new(
        model,
        data.c,
        weight,
        data.records,
        Vec::new(),
        Vec::new(),
        segments,
        0.0,
        substeps.to_vec(),
        blow_up,
    );
    let mut r = vec![0.0; problem.rows];
    Ok(problem.residuals_checked(&theta, &mut r)?.then_some(r))
}

/// Each record's RK4 sub-steps for `model` from `starts` (`opts.substeps`, [`crate::stiff`]).
fn record_substeps<D: ParametricDynamics>(
    model: &D,
    records: &[Experiment],
    starts: &[Vec<f64>],
    opts: &GreyboxOptions,
) -> Result<Vec<usize>> {
    records
        .iter()
        .zip(starts)
        .map(|(exp, x0)| resolve_substeps(model, exp, x0, opts.substeps, opts.blow_up))
        .collect()
}

/// The free parameters' indices, their transforms and starting `z`. Errors: none free, a
/// start outside its bounds.
/// The free parameters the solver moves (their indices, transforms and starting `z`)
/// and those held by equal bounds (`lower == upper`, so the value is the bound).
struct Free {
    free: Vec<usize>,
    transforms: Vec<Transform>,
    z: Vec<f64>,
    pinned: Vec<usize>,
}

/// A free parameter with `lower == upper` is held at that value, out of the solver (no
/// column, no share in the rank, the covariance or `s²`'s degrees of freedom) and
/// reported on its bound without σ.
fn free_parameters<D: ParametricDynamics>(model: &D) -> Result<Free> {
    let mut free = Vec::new();
    let mut transforms = Vec::new();
    let mut z = Vec::new();
    let mut pinned = Vec::new();
    for (j, p) in model.parameters().iter().enumerate() {
        if p.estimation != Estimation::Free {
            continue;
        }
        if !(p.value.is_finite() && p.value >= p.lower && p.value <= p.upper) {
            return Err(CoreError::ParameterOutsideBounds {
                name: p.name.clone(),
                value: p.value,
                lower: p.lower,
                upper: p.upper,
            });
        }
        // The bounds were checked around the value: `upper <= lower` is `lower == upper`.
        if p.upper <= p.lower {
            pinned.push(j);
            continue;
        }
        let (t, z0) = Transform::new(p.lower, p.upper, p.value);
        free.push(j);
        transforms.push(t);
        z.push(z0);
    }
    if free.is_empty() {
        return Err(CoreError::NoFreeParameters {
            parameters: model.parameters().len(),
        });
    }
    Ok(Free {
        free,
        transforms,
        z,
        pinned,
    })
}

/// `C` against the model's states, the noise variances (one positive per output) and
/// every record's channels against the model's inputs and `C`'s rows.
fn validate_shapes<D: ParametricDynamics>(model: &D, data: &GreyboxData<'_>) -> Result<()> {
    let n = model.n_states();
    let p = data.c.nrows();
    if data.c.ncols() != n {
        return Err(CoreError::Shape {
            matrix: "C",
            rows: data.c.nrows(),
            cols: data.c.ncols(),
            expected_rows: p,
            expected_cols: n,
        });
    }
    crate::error::check_finite("C", data.c)?;
    CoreError::check_len(
        "noise variances (one per output)",
        data.noise_variance.len(),
        p,
    )?;
    for (i, &v) in data.noise_variance.iter().enumerate() {
        if !(v.is_finite() && v > 0.0) {
            return Err(CoreError::NonPositiveVariance {
                channel: format!("output {i}"),
                value: v,
            });
        }
    }
    for exp in data.records {
        CoreError::check_len(
            "input channels of a record vs the model",
            exp.n_inputs(),
            model.n_inputs(),
        )?;
        CoreError::check_len(
            "output channels of a record vs the rows of C",
            exp.n_outputs(),
            p,
        )?;
    }
    Ok(())
}

fn validate<D: ParametricDynamics>(
    model: &D,
    data: &GreyboxData<'_>,
    opts: &GreyboxOptions,
) -> Result<()> {
    let n = model.n_states();
    validate_shapes(model, data)?;
    if data.records.is_empty() {
        return Err(CoreError::TooFewSamples {
            what: "grey-box estimation (records)",
            found: 0,
            needed: 1,
        });
    }
    if !data.x0.is_empty() && data.x0.len() != data.records.len() {
        return Err(CoreError::Length {
            what: "start states (one per record)",
            found: data.x0.len(),
            expected: data.records.len(),
        });
    }
    for x in data.x0 {
        CoreError::check_len("start state", x.len(), n)?;
    }
    opts.substeps.validate()?;
    if let Shooting::Multiple { segment } = opts.shooting
        && segment < 2
    {
        return Err(CoreError::InvalidArgument {
            name: "segment",
            value: segment as f64,
            reason: "a shooting segment needs at least 2 samples",
        });
    }
    let mut measured = 0;
    for (e, exp) in data.records.iter().enumerate() {
        let count = exp.outputs().iter().filter(|v| !v.is_nan()).count();
        if count == 0 {
            return Err(CoreError::TooFewSamples {
                what: if e == 0 {
                    "grey-box estimation (measured values of the first record)"
                } else {
                    "grey-box estimation (measured values of a record)"
                },
                found: 0,
                needed: 1,
            });
        }
        measured += count;
    }
    let estimated = model
        .parameters()
        .iter()
        .filter(|p| p.estimation == Estimation::Free)
        .count()
        + n * data.records.len();
    if measured <= estimated {
        return Err(CoreError::TooFewSamples {
            what: "grey-box estimation (measured values vs estimated quantities)",
            found: measured,
            needed: estimated + 1,
        });
    }
    Ok(())
}

/// `x + C⁺(ỹ − C x)` over the measured entries of `y` (`x` unchanged where none is).
fn project(c: &DMatrix<f64>, pinv: &DMatrix<f64>, y: &[f64], x: &mut [f64]) {
    if y.iter().any(|v| v.is_nan()) {
        return;
    }
    let n = x.len();
    let innovation: Vec<f64> = (0..y.len())
        .map(|i| y[i] - (0..n).map(|l| c[(i, l)] * x[l]).sum::<f64>())
        .collect();
    for (l, xl) in x.iter_mut().enumerate() {
        *xl += (0..y.len())
            .map(|i| pinv[(l, i)] * innovation[i])
            .sum::<f64>();
    }
}

fn pseudo_inverse(c: &DMatrix<f64>) -> DMatrix<f64> {
    c.clone()
        .pseudo_inverse(1e-12)
        .unwrap_or_else(|_| DMatrix::zeros(c.ncols(), c.nrows()))
}

/// Given start states, or the minimum-norm `C x = ỹ(t0)` (zero where unmeasured).
fn start_states(data: &GreyboxData<'_>, n: usize) -> Result<Vec<Vec<f64>>> {
    if !data.x0.is_empty() {
        return Ok(data.x0.to_vec());
    }
    let pinv = pseudo_inverse(data.c);
    Ok(data
        .records
        .iter()
        .map(|exp| {
            let mut x = vec![0.0; n];
            let y: Vec<f64> = exp
                .output(0)
                .iter()
                .map(|v| if v.is_nan() { 0.0 } else { *v })
                .collect();
            project(data.c, &pinv, &y, &mut x);
            x
        })
        .collect())
}

/// Segments of `segment` samples per record (the last one takes the rest, and at least
/// 2 samples), linked to their successor.
fn shooting_segments(records: &[Experiment], segment: usize) -> Vec<Segment> {
    let mut out = Vec::new();
    for (record, exp) in records.iter().enumerate() {
        let len = exp.len();
        let mut start = 0;
        while start < len {
            let mut end = (start + segment).min(len);
            if len - end < 2 {
                end = len;
            }
            out.push(Segment {
                record,
                start,
                end,
                linked: end < len,
            });
            start = end;
        }
    }
    out
}

/// θ of the shooting solve: the parameters, then each segment's start from the model's
/// prediction along the previous segment with the measured part replaced
/// (`x + C⁺(ỹ − Cx)`); a record's first segment starts at its start state.
fn shooting_start<D: ParametricDynamics>(
    problem: &mut Calibration<'_, '_, D>,
    z: &[f64],
    starts: &[Vec<f64>],
    segments: &[Segment],
    data: &GreyboxData<'_>,
) -> Result<Vec<f64>> {
    let n = starts.first().map_or(0, Vec::len);
    let pinv = pseudo_inverse(data.c);
    let mut theta = z.to_vec();
    let mut previous: Option<(usize, Vec<f64>)> = None;
    for seg in segments {
        let mut x = match &previous {
            Some((record, x)) if *record == seg.record => x.clone(),
            _ => starts[seg.record].clone(),
        };
        if seg.start > 0 {
            project(
                data.c,
                &pinv,
                data.records[seg.record].output(seg.start),
                &mut x,
            );
        }
        theta.extend_from_slice(&x);
        // Predict along this segment alone to seed the next one.
        let mut probe = z.to_vec();
        probe.extend_from_slice(&x);
        let end = if seg.linked { seg.end + 1 } else { seg.end };
        let xs = problem.simulate_one(&probe, seg.record, seg.start, end)?;
        let last = xs.column(xs.ncols() - 1);
        let next = if last.iter().all(|v| v.is_finite()) {
            last.iter().copied().collect()
        } else {
            x.clone()
        };
        previous = Some((seg.record, next));
    }
    debug_assert_eq!(theta.len(), z.len() + segments.len() * n);
    Ok(theta)
}

/// The first divergence of free runs, as an error naming the time and state.
fn first_divergence(states: &[DMatrix<f64>], records: &[Experiment], blow_up: f64) -> CoreError {
    for (xs, exp) in states.iter().zip(records) {
        for k in 0..xs.ncols() {
            for l in 0..xs.nrows() {
                let v = xs[(l, k)];
                if !v.is_finite() || v.abs() > blow_up {
                    return CoreError::Diverged {
                        t: exp.time(k),
                        state: l,
                        value: v,
                    };
                }
            }
        }
    }
    CoreError::Diverged {
        t: f64::NAN,
        state: 0,
        value: f64::NAN,
    }
}

/// `s²·(JᵀJ)⁻¹` over the columns `keep` (others NaN), from the eigen-decomposition of the
/// column-normalised `JᵀJ`; entries touched by a non-identifiable direction are NaN.
/// Returns the covariance (all columns) and the rank.
fn covariance(jac: &DMatrix<f64>, keep: &[usize], ratio: f64) -> (DMatrix<f64>, usize) {
    let dim = jac.ncols();
    let mut cov = DMatrix::from_element(dim, dim, f64::NAN);
    let k = keep.len();
    if k == 0 {
        return (cov, 0);
    }
    let sub = jac.select_columns(keep.iter());
    let norms: Vec<f64> = (0..k).map(|j| sub.column(j).norm()).collect();
    let mut scaled = sub;
    for (j, &nj) in norms.iter().enumerate() {
        if nj > 0.0 {
            scaled.column_mut(j).scale_mut(1.0 / nj);
        }
    }
    let jtj = scaled.transpose() * &scaled;
    let eig = SymmetricEigen::new(jtj);
    let top = eig.eigenvalues.iter().copied().fold(0.0, f64::max);
    let tol = 1e-12 * top;
    let mut rank = 0;
    let mut unidentified = vec![false; k];
    let mut inv = DMatrix::zeros(k, k);
    for (e, &lambda) in eig.eigenvalues.iter().enumerate() {
        let v = eig.eigenvectors.column(e);
        if lambda > tol {
            rank += 1;
            inv.ger(1.0 / lambda, &v, &v, 1.0);
        } else {
            for (j, flag) in unidentified.iter_mut().enumerate() {
                // A share of more than 1e-3 in a null direction: not pinned down.
                if v[j].abs() > 1e-3 || norms[j] == 0.0 {
                    *flag = true;
                }
            }
        }
    }
    for a in 0..k {
        for b in 0..k {
            if unidentified[a] || unidentified[b] || norms[a] == 0.0 || norms[b] == 0.0 {
                continue;
            }
            cov[(keep[a], keep[b])] = ratio * inv[(a, b)] / (norms[a] * norms[b]);
        }
    }
    (cov, rank)
}

/// One unlinked segment per record, over the whole record (the free-run solve's split).
fn whole_records(records: &[Experiment]) -> Vec<Segment> {
    records
        .iter()
        .enumerate()
        .map(|(record, e)| Segment {
            record,
            start: 0,
            end: e.len(),
            linked: false,
        })
        .collect()
}

#[cfg(test)]
mod tests;
