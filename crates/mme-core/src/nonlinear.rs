//! MME with a nonlinear assumed model `ẋ = f(t, x, u) + E d`, `y = C x`: iterated
//! linearisation (Gauss–Newton, in the closed-loop iLQR form).
//!
//! Each iteration linearises the RK4 sub-step map `x_{j+1} = F(x_j, u, d_j)` (inputs
//! held at `u_k`, or for [`InterSample::Foh`] records linear between `u_k` and `u_{k+1}`
//! at each RK4 stage time, as `sysid_core::simulate_with` integrates them) about the
//! current trajectory (`Φ_j`, `Γ_j` from the private module `linearize`, affine offset
//! `c_j = F(x̄_j, d̄_j) − Φ_j x̄_j − Γ_j d̄_j`), solves the time-varying linear–quadratic
//! problem exactly with the sweep, and rolls the *nonlinear* map out with the sweep's
//! feedback: `d_j = d̄_j + t(d*_j − d̄_j) − F_j(x_j − x̄_j − t(x*_j − x̄_j))`,
//! `x_0 = x̄_0 + t(x*_0 − x̄_0)`, halving `t` until the true `J` decreases by at least
//! 1e-4 of the predicted decrease (Armijo). The feedback keeps long rollouts next to the
//! data (Li & Todorov 2004; Tassa, Erez & Todorov 2012). For a linear `f` the first full
//! step is the exact optimum of the RK4-discretised problem.
//!
//! Termination: `Converged` when an iteration lowers `J` by less than
//! `cost_tolerance·J` (or the predicted decrease is that small), or when
//! `plateau_iterations` iterations running each lower it by less than `cost_plateau` (`J`
//! is in noise-variance units, so that is a change no statistic of the estimate sees),
//! `LineSearchFailed` when
//! no step length lowers `J` although the linearisation predicts a decrease,
//! `MaxIterations` otherwise. An experiment started from the data
//! ([`StartTrajectory::FromData`]) whose line search fails restarts once from the fitted
//! start (`start.rs`) before the estimate gives up, and keeps the lower-cost end.

use nalgebra::DMatrix;
use sysid_core::{
    Dataset, Dynamics, ExperimentEstimate, InterSample, IterationRecord, MmeEstimate, ModelNames,
    SolveReport, Termination,
};

use sysid_core::bandlimited::BL_FACTOR;

use crate::binding::{Binding, bind};
use crate::config::{IterationOptions, MmeConfig, NoiseSpec, ResolvedWeight, StartTrajectory};
use crate::config::{Prior, check_iterations, check_noise, resolve_prior, resolve_weight};
use crate::discretize::{nonlinear_substeps, substeps_for};
use crate::error::{MmeError, Result};
use crate::estimate::{Phases, assemble, resolve_noise};
use crate::evaluate::{Solve, Summary};
use crate::kernel::sweep;
use crate::linearize::Rk4;
use crate::observe::{MmeEvent, MmeObserver, MmePhase, NoObserver};
use crate::result::MmeOutput;
use crate::sweep::{LogDet, Problem, SteadyState, StepModel, Workspace, gains};
use crate::tune_w::tune;
use sysid_core::tangent::StepInput;

mod start;

/// A nonlinear assumed model `ẋ = f(t, x, u) + E d`, `y = C x`, with names.
#[derive(Debug, Clone)]
pub struct NonlinearModel<F> {
    dynamics: F,
    c: DMatrix<f64>,
    e: DMatrix<f64>,
    names: ModelNames,
}

impl<F: Dynamics> NonlinearModel<F> {
    /// Build and check shapes: `C` is `p × n`, `E` is `n × q`, names match
    /// (`n = dynamics.n_states()`, `m = dynamics.n_inputs()`).
    pub fn new(dynamics: F, c: DMatrix<f64>, e: DMatrix<f64>, names: ModelNames) -> Result<Self> {
        let (n, m) = (dynamics.n_states(), dynamics.n_inputs());
        let dim = |what, rows, cols, er, ec| {
            if rows != er || cols != ec {
                Err(MmeError::Dimension {
                    what,
                    rows,
                    cols,
                    expected_rows: er,
                    expected_cols: ec,
                })
            } else {
                Ok(())
            }
        };
        dim("C", c.nrows(), c.ncols(), names.outputs.len(), n)?;
        dim("E", e.nrows(), e.ncols(), n, names.corrections.len())?;
        dim("state names", names.states.len(), 1, n, 1)?;
        dim("input names", names.inputs.len(), 1, m, 1)?;
        for (kind, list) in [
            ("state", &names.states),
            ("input", &names.inputs),
            ("output", &names.outputs),
            ("correction", &names.corrections),
        ] {
            sysid_core::dataset::check_unique(kind, list.iter().map(String::as_str))?;
        }
        sysid_core::error::check_finite("C", &c)?;
        sysid_core::error::check_finite("E", &e)?;
        Ok(Self {
            dynamics,
            c,
            e,
            names,
        })
    }

    /// The right-hand side `f`.
    pub fn dynamics(&self) -> &F {
        &self.dynamics
    }
    /// `C`.
    pub fn c(&self) -> &DMatrix<f64> {
        &self.c
    }
    /// `E`.
    pub fn e(&self) -> &DMatrix<f64> {
        &self.e
    }
    /// Names of states, inputs, outputs and corrections.
    pub fn names(&self) -> &ModelNames {
        &self.names
    }
}

/// MME estimate with a nonlinear assumed model; see [`estimate_nonlinear_with_report`].
pub fn estimate_nonlinear<F: Dynamics>(
    model: &NonlinearModel<F>,
    data: &Dataset,
    config: &MmeConfig,
) -> Result<MmeEstimate> {
    estimate_nonlinear_with_report(model, data, config).map(|o| o.estimate)
}

/// MME estimate with a nonlinear assumed model, with the `W` curve and noise report.
///
/// `report.iterations` is the Gauss–Newton history of the final solve (at the final `W`);
/// `report.termination` is its ending when it did not converge, otherwise the `W`
/// search's ending (or `Converged` for a fixed `W`). The automatic `W` and the noise
/// likelihood warm-start every solve from the previous trajectory; the likelihood uses the
/// linearisation at the converged trajectory (Laplace approximation).
pub fn estimate_nonlinear_with_report<F: Dynamics>(
    model: &NonlinearModel<F>,
    data: &Dataset,
    config: &MmeConfig,
) -> Result<MmeOutput> {
    estimate_nonlinear_with_observer(model, data, config, &NoObserver)
}

/// [`estimate_nonlinear_with_report`], telling `observer` each step as it runs (see
/// [`crate::observe`]: the noise-variance search's evaluations, the `W` trials, the final
/// solve, and every Gauss–Newton iteration within each of those solves). The result is
/// the same, bit for bit, whatever the observer.
pub fn estimate_nonlinear_with_observer<F: Dynamics>(
    model: &NonlinearModel<F>,
    data: &Dataset,
    config: &MmeConfig,
    observer: &dyn MmeObserver,
) -> Result<MmeOutput> {
    let mut clock = Phases::new();
    let weight = resolve_weight(&config.w, model.e.ncols())?;
    if let NoiseSpec::Given(v) = &config.noise_variance {
        check_noise(v, &model.names.outputs)?;
    }
    check_iterations(&config.iterations)?;
    let mut run = NonlinearRun::new(model, data, config, observer)?;
    clock.mark("validate");

    let noise = resolve_noise(
        &mut run,
        &weight,
        config,
        data,
        &model.names.outputs,
        observer,
    )?;
    clock.mark("noise");
    let inv_r: Vec<f64> = noise.variance.iter().map(|v| 1.0 / v).collect();
    let mut w_curve = Vec::new();
    let (w, w_search) = match &weight {
        ResolvedWeight::Fixed(w) => (w.clone(), None),
        ResolvedWeight::Auto { shape, opts } => {
            observer.event(&MmeEvent::Phase(MmePhase::WeightSearch));
            let search = tune(&mut run, shape, &inv_r, opts, &mut w_curve, observer)?;
            (shape * search.alpha, Some(search))
        }
    };
    clock.mark("tune_w");
    observer.event(&MmeEvent::Phase(MmePhase::FinalSolve));
    let summary = run.solve(&w, &inv_r, LogDet::Skip)?;
    clock.mark("gauss_newton");

    let termination = match (run.termination, &w_search) {
        (Termination::Converged, Some(s)) => s.termination,
        (t, _) => t,
    };
    let experiments = run.estimates(data);
    let names = &model.names;
    let estimate = assemble(
        &names.states,
        &names.corrections,
        &names.outputs,
        experiments,
        w,
        &noise,
        &summary,
        SolveReport {
            termination: Some(termination),
            iterations: run.history.clone(),
            phase_seconds: clock.done(),
        },
    );
    Ok(MmeOutput {
        estimate,
        w_curve,
        w_search,
        noise,
    })
}

/// One experiment's grid.
#[derive(Debug, Clone, Copy)]
struct Grid {
    samples: usize,
    substeps: usize,
    h: f64,
    t0: f64,
    steps: usize,
    /// How the inputs behave between samples.
    hold: InterSample,
    /// The model's inputs per point of [`NonlinearRun::bound`]: `m`.
    m: usize,
    /// Whether [`NonlinearRun::bound`] holds the band-limited grid (`BL_FACTOR` points per
    /// sample interval) rather than the samples.
    band_limited: bool,
}

impl Grid {
    /// The input over sub-step `j` given the samples `ua = u_k`, `ub = u_{k+1}` of its
    /// interval `k = j / s` (`ub` is read only for a first-order hold).
    ///
    /// For a band-limited input `ua` is the interval's grid ([`Grid::interval`]) and `ub`
    /// is empty.
    fn stage_input<'u>(&self, j: usize, ua: &'u [f64], ub: &'u [f64]) -> StepInput<'u> {
        if self.band_limited {
            return StepInput::Grid {
                points: ua,
                per_interval: BL_FACTOR,
                from: (j % self.substeps) as f64 / self.substeps as f64,
                per: 1.0 / self.substeps as f64,
            };
        }
        self.hold
            .step_input(ua, ub, j % self.substeps, self.substeps)
    }

    /// The inputs of sub-step `j`'s sample interval `k = j / s`, from the experiment's
    /// bound inputs (no copy): `(u_k, u_{k+1})` (the second empty for held inputs, never
    /// read), or the interval's `BL_FACTOR + 1` grid points and an empty second.
    fn interval<'b>(&self, bound: &'b [f64], j: usize) -> (&'b [f64], &'b [f64]) {
        let (k, m) = (j / self.substeps, self.m);
        if self.band_limited {
            let first = k * BL_FACTOR * m;
            return (&bound[first..first + (BL_FACTOR + 1) * m], &[]);
        }
        let ua = &bound[k * m..(k + 1) * m];
        match self.hold {
            InterSample::Zoh => (ua, &[]),
            InterSample::Foh | InterSample::Bl => (ua, &bound[(k + 1) * m..(k + 2) * m]),
        }
    }
}

/// A trajectory: states at every sub-step (`n × (steps+1)`) and pieces (`q × steps`).
#[derive(Debug, Clone)]
struct Traj {
    x: Vec<f64>,
    d: Vec<f64>,
    /// Whether `x` is a rollout of the model with `d` (false for the data-based start).
    consistent: bool,
}

/// A step the line search accepted: the rollout, its cost and the step length.
struct Accepted {
    traj: Traj,
    cost: f64,
    t: f64,
}

/// Where a model evaluation happens, to name a non-finite value.
struct Where<'a> {
    experiment: usize,
    time: f64,
    point: &'a [f64],
    states: &'a [String],
}

impl Where<'_> {
    /// Error at the first non-finite entry of `values`, a column-major matrix with `rows`
    /// rows (row = state equation; `what(column)` describes the column).
    fn check(&self, values: &[f64], rows: usize, what: impl Fn(usize) -> String) -> Result<()> {
        match values.iter().position(|v| !v.is_finite()) {
            None => Ok(()),
            Some(i) => {
                let (r, c) = if rows == 1 {
                    (i, 0)
                } else {
                    (i % rows, i / rows)
                };
                Err(MmeError::NonFiniteModel {
                    experiment: self.experiment,
                    time: self.time,
                    state: self.states.get(r).cloned().unwrap_or_default(),
                    what: what(c),
                    value: values[i],
                    point: self.point.to_vec(),
                })
            }
        }
    }
}

/// The cost of a trajectory.
#[derive(Debug, Clone)]
struct Eval {
    sse: Vec<f64>,
    count: Vec<usize>,
    correction_cost: f64,
    cost: f64,
}

struct NonlinearRun<'a, F> {
    model: &'a NonlinearModel<F>,
    data: &'a Dataset,
    binding: Binding,
    grids: Vec<Grid>,
    /// Per experiment, the model's inputs in model order, point after point: the samples,
    /// or the band-limited grid ([`Grid::band_limited`]); read by every sub-step without a
    /// copy.
    bound: Vec<Vec<f64>>,
    trajs: Vec<Traj>,
    opts: IterationOptions,
    rk: Rk4,
    ws: Workspace,
    history: Vec<IterationRecord>,
    termination: Termination,
    budget: sysid_core::Budget,
    /// Per experiment: why the data-based start failed, once the fitted start has
    /// replaced it (`None`: not replaced).
    data_start_failure: Vec<Option<MmeError>>,
    /// Per experiment: whether a stuck iteration may still restart once from the fitted
    /// start (only from [`StartTrajectory::FromData`]; see [`Self::solve`]).
    restart_left: Vec<bool>,
    /// Prior on every experiment's initial state (`None`: free).
    prior: Option<Prior>,
    /// Whether the solves use [`Self::prior`] (off for the noise likelihood).
    prior_on: bool,
    /// Told of every Gauss–Newton iteration.
    observer: &'a dyn MmeObserver,
}

impl<'a, F: Dynamics> NonlinearRun<'a, F> {
    fn new(
        model: &'a NonlinearModel<F>,
        data: &'a Dataset,
        config: &MmeConfig,
        observer: &'a dyn MmeObserver,
    ) -> Result<Self> {
        let (n, q) = (model.dynamics.n_states(), model.e.ncols());
        if n == 0 {
            return Err(MmeError::NoStates);
        }
        let binding = bind(&model.names.inputs, &model.names.outputs, data)?;
        let m = model.dynamics.n_inputs();
        let mut run = Self {
            model,
            data,
            grids: Vec::new(),
            bound: Vec::new(),
            trajs: Vec::new(),
            opts: config.iterations,
            rk: Rk4::new(n, m, q),
            ws: Workspace::default(),
            history: Vec::new(),
            termination: Termination::MaxIterations,
            binding,
            budget: config.budget.clone(),
            data_start_failure: vec![None; data.experiments().len()],
            restart_left: vec![
                matches!(config.start, StartTrajectory::FromData);
                data.experiments().len()
            ],
            prior: resolve_prior(&config.x0_prior, &model.names.states)?,
            prior_on: true,
            observer,
        };
        if let StartTrajectory::Given(x0s) = &config.start
            && x0s.len() != data.experiments().len()
        {
            return Err(MmeError::Dimension {
                what: "initial states",
                rows: x0s.len(),
                cols: 1,
                expected_rows: data.experiments().len(),
                expected_cols: 1,
            });
        }
        for (e, exp) in data.experiments().iter().enumerate() {
            let x_first = run.data_states(e, 0);
            let s = match config.substeps {
                Some(_) => substeps_for(config.substeps, &DMatrix::zeros(n, n), exp.dt())?,
                None => {
                    let mut a = DMatrix::zeros(n, n);
                    let mut b = DMatrix::zeros(n, m);
                    let u = run.input(e, 0);
                    let mut f = vec![0.0; n];
                    model.dynamics.rhs(exp.t0(), &x_first, &u, &mut f);
                    let at = Where {
                        experiment: e,
                        time: exp.t0(),
                        point: &x_first,
                        states: &model.names.states,
                    };
                    at.check(&f, 1, |_| "f".to_string())?;
                    model
                        .dynamics
                        .jacobians(exp.t0(), &x_first, &u, &mut a, &mut b);
                    // Column-major: entry (r, c) at c·n + r is ∂f_r/∂x_c.
                    at.check(a.as_slice(), n, |c| {
                        format!("∂f/∂{}", model.names.states[c])
                    })?;
                    nonlinear_substeps(&a, exp.dt())
                }
            };
            crate::discretize::check_grid(e, exp.len(), s, n, q, true)?;
            let steps = (exp.len() - 1) * s;
            let grid = match exp.intersample() {
                InterSample::Bl => exp.band_limited_grid(),
                InterSample::Zoh | InterSample::Foh => None,
            };
            let points = grid.unwrap_or(exp.inputs().as_slice());
            let bound: Vec<f64> = points
                .chunks_exact(exp.n_inputs().max(1))
                .flat_map(|p| run.binding.inputs.iter().map(move |&row| p[row]))
                .collect();
            run.bound.push(bound);
            run.grids.push(Grid {
                samples: exp.len(),
                substeps: s,
                h: exp.dt() / s as f64,
                t0: exp.t0(),
                steps,
                hold: exp.intersample(),
                m: run.binding.inputs.len(),
                band_limited: grid.is_some(),
            });
            let traj = match &config.start {
                StartTrajectory::FromData => run.data_trajectory(e),
                StartTrajectory::Given(x0s) => {
                    if x0s[e].len() != n {
                        return Err(MmeError::Dimension {
                            what: "initial state",
                            rows: x0s[e].len(),
                            cols: 1,
                            expected_rows: n,
                            expected_cols: 1,
                        });
                    }
                    run.open_loop(e, &x0s[e])?
                }
            };
            run.trajs.push(traj);
        }
        Ok(run)
    }

    /// The initial-state prior, when there is one and it is switched on.
    fn active_prior(&self) -> Option<&Prior> {
        self.prior.as_ref().filter(|_| self.prior_on)
    }

    fn input(&self, e: usize, k: usize) -> Vec<f64> {
        let exp = &self.data.experiments()[e];
        self.binding
            .inputs
            .iter()
            .map(|&row| exp.inputs()[(row, k)])
            .collect()
    }

    /// Residuals and correction cost of a trajectory.
    fn evaluate(&self, e: usize, traj: &Traj, w: &DMatrix<f64>, inv_r: &[f64]) -> Eval {
        let g = self.grids[e];
        let (n, q) = (self.model.dynamics.n_states(), self.model.e.ncols());
        let p = inv_r.len();
        let exp = &self.data.experiments()[e];
        let mut sse = vec![0.0; p];
        let mut count = vec![0usize; p];
        for k in 0..g.samples {
            let x = &traj.x[k * g.substeps * n..(k * g.substeps + 1) * n];
            for i in 0..p {
                let y = exp.outputs()[(self.binding.outputs[i], k)];
                if !y.is_nan() {
                    let r = y - (0..n).map(|a| self.model.c[(i, a)] * x[a]).sum::<f64>();
                    sse[i] += r * r;
                    count[i] += 1;
                }
            }
        }
        let mut correction_cost = 0.0;
        for j in 0..g.steps {
            let d = &traj.d[j * q..(j + 1) * q];
            for a in 0..q {
                for b in 0..q {
                    correction_cost += g.h * d[a] * w[(a, b)] * d[b];
                }
            }
        }
        let mut cost = sse.iter().zip(inv_r).map(|(s, r)| s * r).sum::<f64>() + correction_cost;
        if let Some(prior) = self.active_prior() {
            cost += prior.cost(&traj.x[..n]);
        }
        Eval {
            sse,
            count,
            correction_cost,
            cost,
        }
    }

    /// Linearise about `traj` into `(Φ_j, Γ_j, c_j)` for every step. Errors with
    /// [`MmeError::NonFiniteModel`] at the first sub-step where the map or its derivatives
    /// are not finite (they would poison the sweep).
    fn linearise(&mut self, e: usize, traj: &Traj) -> Result<(Vec<f64>, Vec<f64>, Vec<f64>)> {
        let g = self.grids[e];
        let (n, q) = (self.model.dynamics.n_states(), self.model.e.ncols());
        let mut phi = vec![0.0; g.steps * n * n];
        let mut gamma = vec![0.0; g.steps * n * q];
        let mut offset = vec![0.0; g.steps * n];
        let mut xn = vec![0.0; n];
        for j in 0..g.steps {
            let (ua, ub) = g.interval(&self.bound[e], j);
            let t = g.t0 + j as f64 * g.h;
            let x = &traj.x[j * n..(j + 1) * n];
            let d = &traj.d[j * q..(j + 1) * q];
            let (ph, ga) = (
                &mut phi[j * n * n..(j + 1) * n * n],
                &mut gamma[j * n * q..(j + 1) * n * q],
            );
            self.rk.step_jacobians(
                &self.model.dynamics,
                &self.model.e,
                t,
                g.h,
                x,
                &g.stage_input(j, ua, ub),
                d,
                &mut xn,
                ph,
                ga,
            );
            let at = Where {
                experiment: e,
                time: t,
                point: x,
                states: &self.model.names.states,
            };
            let names = &self.model.names;
            let map_ok = [&xn[..], &ph[..], &ga[..]]
                .iter()
                .all(|v| v.iter().all(|x| x.is_finite()));
            if !map_ok {
                // Name the equation: f itself at the step's start, when it is the culprit.
                let mut f = vec![0.0; n];
                let mut buf = vec![0.0; g.m];
                let u0 = g.stage_input(j, ua, ub).at(0.0, &mut buf).to_vec();
                self.model.dynamics.rhs(t, x, &u0, &mut f);
                at.check(&f, 1, |_| "f".to_string())?;
            }
            at.check(&xn, 1, |_| "the sub-step map x(t + h)".to_string())?;
            at.check(ph, n, |c| {
                format!("the sub-step map's derivative by '{}'", names.states[c])
            })?;
            at.check(ga, n, |c| {
                format!(
                    "the sub-step map's derivative by d_{}",
                    names.corrections[c]
                )
            })?;
            for r in 0..n {
                let lin: f64 = (0..n).map(|c| ph[c * n + r] * x[c]).sum::<f64>()
                    + (0..q).map(|c| ga[c * n + r] * d[c]).sum::<f64>();
                offset[j * n + r] = xn[r] - lin;
            }
        }
        Ok((phi, gamma, offset))
    }

    /// Solve the linearised problem of experiment `e`; returns the LQ optimum
    /// `(x* at every sub-step, d*, J_lq, logdets)`; the gains stay in `self.ws`.
    fn lq_step(
        &mut self,
        e: usize,
        traj: &Traj,
        w: &DMatrix<f64>,
        inv_r: &[f64],
        logdet: LogDet,
    ) -> Result<(Traj, f64, f64, f64)> {
        let g = self.grids[e];
        let (n, q) = (self.model.dynamics.n_states(), self.model.e.ncols());
        let (phi, gamma, offset) = self.linearise(e, traj)?;
        let exp = &self.data.experiments()[e];
        let pr = Problem {
            n,
            q,
            samples: g.samples,
            substeps: g.substeps,
            h: g.h,
            w,
            c: &self.model.c,
            inv_r,
            outputs: exp.outputs(),
            out_map: &self.binding.outputs,
            experiment: e,
            t0: g.t0,
            steady: SteadyState::Never,
            prior: self.prior.as_ref().filter(|_| self.prior_on),
        };
        let steps = StepModel::Tv {
            phi: &phi,
            gamma: &gamma,
            offset: &offset,
        };
        let mut states = vec![0.0; n * g.samples];
        let mut d = vec![0.0; q * g.steps];
        let out = sweep(&pr, &steps, &mut self.ws, &mut states, &mut d, logdet)?;
        // x* at every sub-step from the linear recursion.
        let mut x = vec![0.0; n * (g.steps + 1)];
        x[..n].copy_from_slice(&states[..n]);
        for j in 0..g.steps {
            for r in 0..n {
                let v = offset[j * n + r]
                    + (0..n)
                        .map(|c| phi[j * n * n + c * n + r] * x[j * n + c])
                        .sum::<f64>()
                    + (0..q)
                        .map(|c| gamma[j * n * q + c * n + r] * d[j * q + c])
                        .sum::<f64>();
                x[(j + 1) * n + r] = v;
            }
        }
        Ok((
            Traj {
                x,
                d,
                consistent: false,
            },
            out.cost(inv_r),
            out.logdet_s,
            out.logdet_p0,
        ))
    }

    /// One Gauss–Newton step of experiment `e` from `cur` (cost `cost`, infinite for a
    /// start that is not a rollout): the LQ optimum, then the Armijo line search over
    /// closed-loop rollouts. Returns the accepted step, if any, and whether the predicted
    /// decrease is below the tolerance.
    fn attempt(
        &mut self,
        e: usize,
        cur: &Traj,
        cost: f64,
        w: &DMatrix<f64>,
        inv_r: &[f64],
    ) -> Result<(Option<Accepted>, bool)> {
        let tol = self.opts.cost_tolerance;
        let (star, j_lq, _, _) = self.lq_step(e, cur, w, inv_r, LogDet::Skip)?;
        let predicted = cost - j_lq;
        // A NaN prediction counts as large.
        let small = predicted <= tol * j_lq.abs().max(f64::MIN_POSITIVE);
        let mut t = 1.0;
        for _ in 0..=self.opts.max_halvings {
            if let Some(tr) = self.rollout(e, cur, &star, t) {
                let j_new = self.evaluate(e, &tr, w, inv_r).cost;
                let enough = if cost.is_finite() {
                    j_new <= cost - 1e-4 * t * predicted.max(0.0) && j_new < cost
                } else {
                    j_new.is_finite()
                };
                if enough {
                    return Ok((
                        Some(Accepted {
                            traj: tr,
                            cost: j_new,
                            t,
                        }),
                        small,
                    ));
                }
            }
            t *= 0.5;
        }
        Ok((None, small))
    }

    /// Closed-loop rollout at step length `t`; `None` if it diverges.
    fn rollout(&mut self, e: usize, cur: &Traj, star: &Traj, t: f64) -> Option<Traj> {
        let g = self.grids[e];
        let (n, q) = (self.model.dynamics.n_states(), self.model.e.ncols());
        let mut x = vec![0.0; n * (g.steps + 1)];
        let mut d = vec![0.0; q * g.steps];
        for ((xi, c), st) in x.iter_mut().zip(&cur.x).zip(&star.x).take(n) {
            *xi = c + t * (st - c);
        }
        let mut xc: Vec<f64> = x[..n].to_vec();
        let mut dev = vec![0.0; n];
        for j in 0..g.steps {
            let (fg, _) = gains(&self.ws, g.steps, n, q, j);
            for i in 0..n {
                let target = cur.x[j * n + i] + t * (star.x[j * n + i] - cur.x[j * n + i]);
                dev[i] = xc[i] - target;
            }
            for a in 0..q {
                let base = cur.d[j * q + a] + t * (star.d[j * q + a] - cur.d[j * q + a]);
                let fb: f64 = (0..n).map(|c| fg[c * q + a] * dev[c]).sum();
                d[j * q + a] = base - fb;
            }
            let (ua, ub) = g.interval(&self.bound[e], j);
            let time = g.t0 + j as f64 * g.h;
            self.rk.step(
                &self.model.dynamics,
                &self.model.e,
                time,
                g.h,
                &mut xc,
                &g.stage_input(j, ua, ub),
                &d[j * q..(j + 1) * q],
            );
            if xc
                .iter()
                .any(|v| !v.is_finite() || v.abs() > self.opts.blow_up)
            {
                return None;
            }
            x[(j + 1) * n..(j + 2) * n].copy_from_slice(&xc);
        }
        Some(Traj {
            x,
            d,
            consistent: true,
        })
    }

    fn estimates(&self, data: &Dataset) -> Vec<ExperimentEstimate> {
        let (n, q) = (self.model.dynamics.n_states(), self.model.e.ncols());
        data.experiments()
            .iter()
            .zip(&self.grids)
            .zip(&self.trajs)
            .map(|((exp, g), tr)| ExperimentEstimate {
                t0: exp.t0(),
                dt: exp.dt(),
                substeps: g.substeps,
                states: DMatrix::from_fn(n, g.samples, |i, k| tr.x[k * g.substeps * n + i]),
                corrections: DMatrix::from_column_slice(q, g.steps, &tr.d),
            })
            .collect()
    }
}

impl<F: Dynamics> Solve for NonlinearRun<'_, F> {
    fn n_states(&self) -> usize {
        self.model.dynamics.n_states()
    }

    fn n_corrections(&self) -> usize {
        self.model.e.ncols()
    }

    fn pieces(&self) -> Vec<(usize, f64)> {
        self.grids.iter().map(|g| (g.steps, g.h)).collect()
    }

    fn use_prior(&mut self, on: bool) {
        self.prior_on = on;
    }

    fn solve(&mut self, w: &DMatrix<f64>, inv_r: &[f64], logdet: LogDet) -> Result<Summary> {
        let experiments = self.trajs.len();
        let tol = self.opts.cost_tolerance;
        let mut costs: Vec<f64> = (0..experiments)
            .map(|e| {
                let tr = &self.trajs[e];
                if tr.consistent {
                    self.evaluate(e, tr, w, inv_r).cost
                } else {
                    f64::INFINITY
                }
            })
            .collect();
        self.history.clear();
        self.termination = Termination::MaxIterations;
        // Per experiment: the trajectory a stuck iteration left and its cost, kept while
        // the restart from the fitted start runs (the lower-cost end is kept).
        let mut stuck: Vec<Option<(Traj, f64)>> = vec![None; experiments];
        let mut stuck_e = vec![false; experiments];
        // Iterations running whose gain was below `cost_plateau`.
        let mut plateau = 0usize;
        for iteration in 1..=self.opts.max_iterations {
            let before: f64 = costs.iter().sum();
            let (mut step_norm, mut step_length) = (0.0, 1.0_f64);
            let mut failed = false;
            stuck_e.fill(false);
            let mut small_prediction = true;
            for (e, cost_e) in costs.iter_mut().enumerate() {
                self.budget
                    .charge(
                        self.grids[e].steps as u64,
                        "nonlinear MME iteration",
                        iteration - 1,
                        Some(self.opts.max_iterations),
                    )
                    .map_err(sysid_core::CoreError::from)?;
                let mut cur = self.trajs[e].clone();
                let (mut accepted, mut small) = self.attempt(e, &cur, *cost_e, w, inv_r)?;
                if accepted.is_none() && !cur.consistent && self.data_start_failure[e].is_none() {
                    // The data-based start gave no finite rollout: replace it by the fitted
                    // start (`start.rs`) and try again; errors name both starts.
                    let g = self.grids[e];
                    let data_start = MmeError::Breakdown {
                        experiment: e,
                        step: 0,
                        time: g.t0,
                        what: "no finite rollout found",
                    };
                    let both = |fitted: MmeError| MmeError::StartFailed {
                        experiment: e,
                        data_start: Box::new(data_start.clone()),
                        fitted_start: Box::new(fitted),
                    };
                    cur = self.fitted_trajectory(e).map_err(both)?;
                    self.trajs[e] = cur.clone();
                    self.data_start_failure[e] = Some(data_start.clone());
                    // Already on the fitted start: a later restart would repeat it.
                    self.restart_left[e] = false;
                    (accepted, small) = self.attempt(e, &cur, *cost_e, w, inv_r).map_err(both)?;
                }
                small_prediction &= small;
                match accepted {
                    Some(Accepted {
                        traj: tr,
                        cost: j_new,
                        t,
                    }) => {
                        let dx0: f64 = (0..self.n_states())
                            .map(|i| (tr.x[i] - cur.x[i]).powi(2))
                            .sum();
                        let dd: f64 = tr.d.iter().zip(&cur.d).map(|(a, b)| (a - b).powi(2)).sum();
                        step_norm += dx0 + dd;
                        step_length = step_length.min(t);
                        self.trajs[e] = tr;
                        *cost_e = j_new;
                    }
                    None => {
                        failed = true;
                        stuck_e[e] = true;
                        step_length = 0.0;
                    }
                }
            }
            let after: f64 = costs.iter().sum();
            self.history.push(IterationRecord {
                iteration,
                cost: after,
                step_norm: step_norm.sqrt(),
                step_length,
            });
            self.observer.event(&MmeEvent::Iteration {
                iteration,
                max_iterations: self.opts.max_iterations,
                cost: after,
                relative_change: (before - after).abs() / after.abs(),
                tolerance: tol,
            });
            if failed && !small_prediction {
                // A data-based start can lead the first full step into a region where the
                // linearisation no longer predicts the model (a level driven below empty,
                // where the outflow laws are flat), and the iteration sticks there far from
                // any fit. Each such experiment restarts once from the fitted start
                // (`start.rs`); the lower-cost end of the two is kept.
                let mut restarted = false;
                for e in 0..experiments {
                    if !(stuck_e[e] && self.restart_left[e]) {
                        continue;
                    }
                    self.restart_left[e] = false;
                    if let Ok(fresh) = self.fitted_trajectory(e) {
                        stuck[e] = Some((self.trajs[e].clone(), costs[e]));
                        self.trajs[e] = fresh;
                        costs[e] = f64::INFINITY;
                        restarted = true;
                    }
                }
                if restarted {
                    continue;
                }
                self.termination = Termination::LineSearchFailed;
                break;
            }
            if !after.is_finite() {
                continue;
            }
            if small_prediction || (before - after).abs() <= tol * after.abs() {
                self.termination = Termination::Converged;
                break;
            }
            // A restart leaves `before` infinite: the count starts again.
            let gain = before - after;
            if !failed && gain.is_finite() && gain < self.opts.cost_plateau {
                plateau += 1;
            } else {
                plateau = 0;
            }
            if plateau >= self.opts.plateau_iterations {
                self.termination = Termination::Converged;
                break;
            }
        }
        for (e, kept) in stuck.into_iter().enumerate() {
            if let Some((tr, cost)) = kept
                && (costs[e].is_nan() || costs[e] >= cost)
            {
                self.trajs[e] = tr;
                self.termination = Termination::LineSearchFailed;
            }
        }
        // Summary of the final trajectories.
        let p = inv_r.len();
        let mut total = Summary {
            sse: vec![0.0; p],
            count: vec![0; p],
            correction_cost: 0.0,
            cost: 0.0,
            logdet_s: 0.0,
            logdet_p0: 0.0,
        };
        for e in 0..experiments {
            let tr = self.trajs[e].clone();
            if !tr.consistent {
                let no_rollout = MmeError::Breakdown {
                    experiment: e,
                    step: 0,
                    time: self.grids[e].t0,
                    what: "no finite rollout found",
                };
                return Err(match &self.data_start_failure[e] {
                    Some(data_start) => MmeError::StartFailed {
                        experiment: e,
                        data_start: Box::new(data_start.clone()),
                        fitted_start: Box::new(no_rollout),
                    },
                    None => no_rollout,
                });
            }
            let ev = self.evaluate(e, &tr, w, inv_r);
            for i in 0..p {
                total.sse[i] += ev.sse[i];
                total.count[i] += ev.count[i];
            }
            total.correction_cost += ev.correction_cost;
            total.cost += ev.cost;
            if logdet == LogDet::Accumulate {
                let (_, _, ls, lp) = self.lq_step(e, &tr, w, inv_r, LogDet::Accumulate)?;
                total.logdet_s += ls;
                total.logdet_p0 += lp;
            }
        }
        Ok(total)
    }
}
