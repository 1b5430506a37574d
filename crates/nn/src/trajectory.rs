//! Training of a correction network on trajectories (thesis §7.1, future work): after
//! training on MME's `d̂`, the weights are adjusted by Levenberg–Marquardt so that the
//! hybrid model `ẋ = f(x, u) + E·NN(x, u)`, `y = C x`, simulated free-run over short
//! windows (multiple shooting), reproduces the measured outputs.
//!
//! Each window starts from a given state estimate (MME's smoothed `x̂` at the window's
//! first sample), so the shooting nodes are not extra unknowns and a window cannot carry
//! an error in from earlier windows. Residuals are measured minus simulated outputs at
//! every later sample of the window, divided by the channel's standard deviation. The
//! Jacobian with respect to the flat weight vector is taken by forward differences, one
//! simulation of all windows per weight (the networks have tens of weights), in parallel
//! over weights and bit-identical for any thread count; the solver is sysid-core's
//! Levenberg–Marquardt.

use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};
use sysid_core::{
    AcceptedStep, Control, CorrectedModel, Dynamics, Experiment, LeastSquaresProblem, LmSettings,
    Scaling, Termination, levenberg_marquardt,
};

use crate::correction::NetCorrection;
use crate::error::{NnError, Result};

mod shooting;
use shooting::{Buffers, Hybrid, Linearisation, Shooter, Window};

/// Most bytes the dense least-squares matrices of [`train_on_trajectories`] may take (the
/// Jacobian `rows × θ`, its normal matrix and a damped copy `θ × θ` twice): 2 GiB. The
/// unknowns `θ` are the weights plus one start state per window, so both grow with the
/// record length; a problem beyond this bound is refused before anything is allocated.
pub const MAX_TRAJECTORY_BYTES: u128 = 2 << 30;

/// Settings of [`train_on_trajectories`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct TrajectoryConfig {
    /// Sample intervals simulated per window (residuals at the `window` samples after the
    /// start). Windows tile each record without overlap; a shorter last window is kept.
    /// Default 100.
    pub window: usize,
    /// Without validation records, every `holdout_every`-th training window (the last of
    /// each group) is held out and used only for early stopping; 0 holds out nothing.
    /// Ignored when validation records are given. Default 5.
    pub holdout_every: usize,
    /// Maximum number of accepted LM steps. Default 30.
    pub max_iterations: usize,
    /// Stop after this many consecutive accepted steps whose held-out objective is above
    /// the best so far. Default 5.
    pub max_fail: usize,
    /// Initial damping of the workspace's Levenberg–Marquardt
    /// ([`sysid_core::least_squares`]), relative to its column scaling (so 1e-3 is
    /// Marquardt's classical start). Default 1e-3.
    pub mu_initial: f64,
    /// Give up ([`Termination::NoDescent`]) when the relative damping exceeds this
    /// without a step lowering the objective. Default 1e10.
    pub mu_max_ratio: f64,
    /// Stop when an accepted step lowers the training objective by less than this
    /// fraction. Default 1e-6.
    pub min_relative_decrease: f64,
    /// RK4 steps per sample interval. Inputs between samples follow each record's
    /// [`Experiment::intersample`]: held ([`sysid_core::InterSample::Zoh`]) or linear
    /// to the next sample ([`sysid_core::InterSample::Foh`]). Default 4.
    pub substeps: usize,
    /// States beyond this magnitude count as a diverged window. Default 1e12.
    pub blow_up: f64,
}

impl Default for TrajectoryConfig {
    fn default() -> Self {
        Self {
            window: 100,
            holdout_every: 5,
            max_iterations: 30,
            max_fail: 5,
            mu_initial: 1e-3,
            mu_max_ratio: 1e10,
            min_relative_decrease: 1e-6,
            substeps: 4,
            blow_up: sysid_core::integrate::DEFAULT_BLOW_UP,
        }
    }
}

impl TrajectoryConfig {
    /// Check every field is in range.
    pub fn validate(&self) -> Result<()> {
        let bad = |field, value, reason| {
            Err(NnError::InvalidConfig {
                field,
                value,
                reason,
            })
        };
        if self.window == 0 {
            return bad("window", 0.0, "must be ≥ 1");
        }
        if self.max_fail == 0 {
            return bad("max_fail", 0.0, "must be ≥ 1");
        }
        if self.substeps == 0 {
            return bad("substeps", 0.0, "must be ≥ 1");
        }
        if !(self.mu_initial.is_finite() && self.mu_initial > 0.0) {
            return bad("mu_initial", self.mu_initial, "must be finite and > 0");
        }
        if !(self.mu_max_ratio.is_finite() && self.mu_max_ratio > self.mu_initial) {
            return bad(
                "mu_max_ratio",
                self.mu_max_ratio,
                "must be finite and > mu_initial",
            );
        }
        if !(self.min_relative_decrease.is_finite() && self.min_relative_decrease >= 0.0) {
            return bad(
                "min_relative_decrease",
                self.min_relative_decrease,
                "must be finite and ≥ 0",
            );
        }
        if !(self.blow_up.is_finite() && self.blow_up > 0.0) {
            return bad("blow_up", self.blow_up, "must be finite and > 0");
        }
        Ok(())
    }
}

/// One record to shoot over: its inputs and measured outputs (NaN = not observed), and
/// the state estimate at every sample, from which each window starts. Windows are
/// simulated with the inputs between samples as the experiment's
/// [`Experiment::intersample`] says.
#[derive(Debug, Clone, Copy)]
pub struct ShootingRecord<'a> {
    /// Inputs (`m × N`) and measured outputs (`p × N`).
    pub experiment: &'a Experiment,
    /// State estimates `n × N` (MME's smoothed `x̂`); only window starts are read.
    pub states: &'a DMatrix<f64>,
}

/// State after one accepted step, passed to the progress callback.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TrajectoryProgress {
    /// Accepted steps so far.
    pub iteration: usize,
    /// Training objective (mean squared scaled residual).
    pub train_objective: f64,
    /// Held-out objective, when windows are held out.
    pub val_objective: Option<f64>,
    /// Damping after the step.
    pub mu: f64,
}

/// What the trajectory training did. Objectives are mean squared residuals in units of each channel's
/// standard deviation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrajectoryReport {
    /// Why it stopped: [`Termination::MaxIterations`] ([`TrajectoryConfig::max_iterations`]
    /// steps accepted), [`Termination::NoDescent`] (no step lowered the training objective
    /// before μ reached its limit), [`Termination::Converged`] (an accepted step lowered it
    /// by at most [`TrajectoryConfig::min_relative_decrease`]) or
    /// [`Termination::StoppedEarly`] (the held-out objective failed to improve
    /// [`TrajectoryConfig::max_fail`] times).
    pub termination: Termination,
    /// Accepted steps.
    pub iterations: usize,
    /// Step whose weights were returned (best held-out objective; the last step without
    /// held-out windows; 0 = the initial weights).
    pub best_iteration: usize,
    /// Training objective with every window started from the given state estimates and
    /// the initial weights (before the start states are fitted).
    pub objective_at_estimates: f64,
    /// Training objective per accepted step; index 0 is the initial network (with start
    /// states fitted to it).
    pub train_history: Vec<f64>,
    /// Held-out objective per accepted step (index 0 = initial); empty without held-out
    /// windows.
    pub val_history: Vec<f64>,
    /// Windows used for the steps.
    pub train_windows: usize,
    /// Windows held out for early stopping.
    pub val_windows: usize,
    /// Residual divisor per output channel (its standard deviation over all records).
    pub output_scale: Vec<f64>,
}

impl TrajectoryReport {
    /// Training objective of the initial weights.
    pub fn initial_train_objective(&self) -> f64 {
        self.train_history[0]
    }

    /// Training objective of the returned weights.
    pub fn final_train_objective(&self) -> f64 {
        self.train_history[self.best_iteration]
    }
}

/// Check the records' shapes against the model's (the model's own parts — network, `E`,
/// `C` — were checked against each other when it was built).
fn check_problem<F: Dynamics>(
    model: &CorrectedModel<F, NetCorrection>,
    records: &[ShootingRecord<'_>],
) -> Result<()> {
    let n = model.n_states();
    let m = model.n_inputs();
    let shape = |matrix, rows: usize, cols: usize, er: usize, ec: usize| {
        if rows == er && cols == ec {
            Ok(())
        } else {
            Err(NnError::Shape {
                matrix,
                rows,
                cols,
                expected_rows: er,
                expected_cols: ec,
            })
        }
    };
    let p = model.c().nrows();
    if records.is_empty() {
        return Err(NnError::TooFewSamples {
            what: "trajectory records",
            found: 0,
            needed: 1,
        });
    }
    for rec in records {
        let exp = rec.experiment;
        shape("record inputs", exp.n_inputs(), exp.len(), m, exp.len())?;
        shape("record outputs", exp.n_outputs(), exp.len(), p, exp.len())?;
        shape(
            "record states",
            rec.states.nrows(),
            rec.states.ncols(),
            n,
            exp.len(),
        )?;
        crate::error::check_finite("record states", rec.states)?;
        crate::error::check_finite("record inputs", exp.inputs())?;
    }
    Ok(())
}

/// Standard deviation of every output channel over all observed samples of all records
/// (a constant channel gets 1, so its residuals stay in its own units).
fn output_scales(records: &[ShootingRecord<'_>], p: usize) -> Vec<f64> {
    (0..p)
        .map(|o| {
            let vals = || {
                records
                    .iter()
                    .flat_map(|r| {
                        r.experiment
                            .outputs()
                            .row(o)
                            .iter()
                            .copied()
                            .collect::<Vec<_>>()
                    })
                    .filter(|v| v.is_finite())
            };
            let count = vals().count();
            if count < 2 {
                return 1.0;
            }
            let mean = vals().sum::<f64>() / count as f64;
            let var = vals().map(|v| (v - mean) * (v - mean)).sum::<f64>() / (count - 1) as f64;
            let sd = var.sqrt();
            if sd > 0.0 && sd.is_finite() { sd } else { 1.0 }
        })
        .collect()
}

/// Observed residual entries of a set of windows (the objective's denominator).
fn observed(records: &[ShootingRecord<'_>], windows: &[Window]) -> usize {
    windows
        .iter()
        .map(|w| {
            let out = records[w.record].experiment.outputs();
            (w.start + 1..=w.end)
                .map(|k| out.column(k).iter().filter(|v| !v.is_nan()).count())
                .sum::<usize>()
        })
        .sum()
}

/// Train the network of the hybrid model `ẋ = f(x, u) + E·NN([x; u])`, `y = C x` in
/// place (its weights, through [`CorrectedModel::correction_mut`]) so that the model
/// reproduces the records' measured outputs over short free-run windows (multiple
/// shooting, Bock & Plitt 1984). The model's own `x0`, integrator and blow-up bound are
/// not used: windows start from the records' states and are simulated with
/// [`TrajectoryConfig::substeps`] RK4 steps per sample, diverging beyond
/// [`TrajectoryConfig::blow_up`].
///
/// Unknowns are the flat weight vector and the start state of every training window
/// (initialised at the given estimates, so a biased `x̂` is not blamed on the network).
/// The objective is the mean over observed window samples of `((y_meas − y_sim)/σ_o)²`,
/// with `σ_o` the standard deviation of output channel `o` over all records. Each
/// iteration forms the forward-difference Jacobian of the residuals (step
/// `√ε·max(1, |θ_j|)`, start states in units of each state's standard deviation) and
/// takes a step of the workspace's Levenberg–Marquardt ([`sysid_core::least_squares`]),
/// which accepts a step only if the training objective falls — so the training objective
/// never increases. A window that diverges under trial weights rejects the step.
///
/// Held-out windows — every window of `val_records` when given, else every
/// [`TrajectoryConfig::holdout_every`]-th window of `train_records` — are scored with
/// their start states fitted for the current weights; the weights of the step with the
/// lowest held-out objective are returned.
///
/// Errors: invalid config, records whose shapes do not fit the model, no records or no
/// window with an observed sample, non-finite states or inputs, and
/// [`NnError::TrajectoryDiverged`] when the *initial* network already diverges on a
/// window. On error the model is unchanged.
pub fn train_on_trajectories<F: Dynamics>(
    model: &mut CorrectedModel<F, NetCorrection>,
    train_records: &[ShootingRecord<'_>],
    val_records: &[ShootingRecord<'_>],
    config: &TrajectoryConfig,
    progress: Option<&mut dyn FnMut(TrajectoryProgress)>,
) -> Result<TrajectoryReport> {
    config.validate()?;
    check_problem(model, train_records)?;
    if !val_records.is_empty() {
        check_problem(model, val_records)?;
    }
    let records: Vec<ShootingRecord<'_>> =
        train_records.iter().chain(val_records).copied().collect();
    let records = records.as_slice();
    let (n, m, q, p) = (
        model.n_states(),
        model.n_inputs(),
        model.correction().network().n_outputs(),
        model.c().nrows(),
    );
    let nw = model.correction().network().n_weights();

    // Windows tile each record: [0, L], [L, 2L], …; the last may be shorter.
    let mut train_w = Vec::new();
    let mut val_w = Vec::new();
    let mut index = 0usize;
    for (ri, rec) in records.iter().enumerate() {
        let len = rec.experiment.len();
        let mut start = 0;
        while start + 1 < len {
            let end = (start + config.window).min(len - 1);
            let w = Window {
                record: ri,
                start,
                end,
            };
            index += 1;
            if ri >= train_records.len()
                || (val_records.is_empty()
                    && config.holdout_every > 0
                    && index.is_multiple_of(config.holdout_every))
            {
                val_w.push(w);
            } else {
                train_w.push(w);
            }
            start = end;
        }
    }
    let m_train = observed(records, &train_w);
    if m_train == 0 {
        return Err(NnError::TooFewSamples {
            what: "observed samples in training windows",
            found: 0,
            needed: 1,
        });
    }
    let m_val = observed(records, &val_w);
    if m_val == 0 {
        val_w.clear();
    }
    let rows_train: usize = train_w.iter().map(|w| (w.end - w.start) * p).sum();
    // Memory bound before any allocation of the record's size (see MAX_TRAJECTORY_BYTES).
    let n_theta_planned = nw + n * train_w.len();
    let bytes = 8
        * (rows_train as u128 * n_theta_planned as u128
            + 2 * (n_theta_planned as u128).pow(2)
            + 2 * rows_train as u128);
    if bytes > MAX_TRAJECTORY_BYTES {
        return Err(NnError::TooLarge {
            what: "the trajectory training's Jacobian",
            rows: rows_train,
            columns: n_theta_planned,
            bytes,
            limit: MAX_TRAJECTORY_BYTES,
            hint: "train on a shorter record, or skip the trajectory training (--train-on-trajectories no)",
        });
    }
    let starts_of = |ws: &[Window]| -> Vec<f64> {
        ws.iter()
            .flat_map(|w| {
                records[w.record]
                    .states
                    .column(w.start)
                    .iter()
                    .copied()
                    .collect::<Vec<_>>()
            })
            .collect()
    };
    let x_hat = starts_of(&train_w);
    let val_starts = starts_of(&val_w);
    let x_scale = state_scales(train_records, n);

    let output_scale = output_scales(train_records, p);
    let shooter = Shooter {
        hybrid: &*model,
        records,
        inv_scale: output_scale.iter().map(|s| 1.0 / s).collect(),
        substeps: config.substeps,
        blow_up: config.blow_up,
    };
    let mut bufs = Buffers::new(n, m, q);
    // The working copy that trial points are loaded into (the given model stays as it is
    // until the end).
    let work = shooter.model();
    let mut r = DVector::zeros(rows_train);
    let diverged = |w: &Window| NnError::TrajectoryDiverged {
        record: w.record,
        sample: w.start,
    };
    shooter
        .residuals(&work, &train_w, &x_hat, r.as_mut_slice(), &mut bufs)
        .map_err(|wi| diverged(&train_w[wi]))?;
    let objective_at_estimates = r.norm_squared() / m_train as f64;
    // Start states first fitted with the weights fixed, as for held-out windows, so the
    // objective's history measures what the weights do.
    let mut starts = x_hat.clone();
    for (i, w) in train_w.iter().enumerate() {
        let sse = shooter.fitted_window_sse(
            &work,
            w,
            &x_hat[i * n..(i + 1) * n],
            &x_scale,
            &mut bufs,
            &mut starts[i * n..(i + 1) * n],
        );
        if !sse.is_finite() {
            return Err(diverged(w));
        }
    }
    shooter
        .residuals(&work, &train_w, &starts, r.as_mut_slice(), &mut bufs)
        .map_err(|wi| diverged(&train_w[wi]))?;
    let mut val_fitted = vec![0.0; n];
    let mut val_objective = |model: &Hybrid<'_, F>, bufs: &mut Buffers| -> Option<f64> {
        if val_w.is_empty() {
            return None;
        }
        let sse: f64 = val_w
            .iter()
            .enumerate()
            .map(|(i, w)| {
                let x0 = &val_starts[i * n..(i + 1) * n];
                shooter.fitted_window_sse(model, w, x0, &x_scale, bufs, &mut val_fitted)
            })
            .sum();
        Some(sse / m_val as f64)
    };

    // Unknowns θ = [weights; z], start states = x̂ + σ_x ⊙ z.
    let mut theta = vec![0.0; nw + x_hat.len()];
    theta[..nw].copy_from_slice(work.correction().network().weights());
    for (k, s) in starts.iter().enumerate() {
        theta[nw + k] = (s - x_hat[k]) / x_scale[k % n];
    }
    let mut val_history = Vec::new();
    let mut best = (f64::INFINITY, theta.clone(), 0usize);
    if let Some(v) = val_objective(&work, &mut bufs) {
        if !v.is_finite() {
            return Err(diverged(&val_w[0]));
        }
        val_history.push(v);
        best = (v, theta.clone(), 0);
    }
    let mut problem = TrajectoryProblem {
        shooter: &shooter,
        windows: &train_w,
        x_hat: &x_hat,
        x_scale: &x_scale,
        dims: (n, m, q),
        rows: rows_train,
        m_train,
        work,
        starts: starts.clone(),
        bufs,
        val_objective: &mut val_objective,
        val_history,
        best,
        fails: 0,
        max_fail: config.max_fail,
        progress,
    };
    let settings = LmSettings {
        max_iterations: config.max_iterations,
        mu_initial: config.mu_initial,
        mu_max: config.mu_max_ratio,
        ftol: config.min_relative_decrease,
        scaling: Scaling::Uniform,
        mu_floor_factor: 0.1,
        ..LmSettings::default()
    };
    let solution = levenberg_marquardt(&mut problem, &theta, &settings)
        .unwrap_or_else(|never: std::convert::Infallible| match never {});
    let TrajectoryProblem {
        val_history, best, ..
    } = problem;
    let iterations = solution.report.steps.len();
    let (weights, best_iteration) = if val_w.is_empty() {
        (&solution.theta[..nw], iterations)
    } else {
        (&best.1[..nw], best.2)
    };
    model
        .correction_mut()
        .weights_mut()
        .copy_from_slice(weights);
    let train_history = solution
        .report
        .cost_history()
        .iter()
        .map(|c| c / m_train as f64)
        .collect();
    Ok(TrajectoryReport {
        termination: solution.report.termination,
        iterations,
        best_iteration,
        objective_at_estimates,
        train_history,
        val_history,
        train_windows: train_w.len(),
        val_windows: val_w.len(),
        output_scale,
    })
}

/// The weights and training-window start states as one least-squares problem, with the
/// held-out bookkeeping after every accepted step.
struct TrajectoryProblem<'s, 'a, 'p, F: Dynamics, V> {
    shooter: &'s Shooter<'a, F>,
    windows: &'s [Window],
    x_hat: &'s [f64],
    x_scale: &'s [f64],
    dims: (usize, usize, usize),
    rows: usize,
    m_train: usize,
    /// The model at the point being evaluated.
    work: Hybrid<'a, F>,
    /// Start states at the point being evaluated.
    starts: Vec<f64>,
    bufs: Buffers,
    val_objective: &'s mut V,
    val_history: Vec<f64>,
    /// Lowest held-out objective, its θ and its step.
    best: (f64, Vec<f64>, usize),
    fails: usize,
    max_fail: usize,
    progress: Option<&'s mut (dyn FnMut(TrajectoryProgress) + 'p)>,
}

impl<'a, F: Dynamics, V: FnMut(&Hybrid<'a, F>, &mut Buffers) -> Option<f64>>
    TrajectoryProblem<'_, 'a, '_, F, V>
{
    /// Load `theta` into the working network and start states.
    fn load(&mut self, theta: &[f64]) {
        let w = self.work.correction_mut().weights_mut();
        let nw = w.len();
        let n = self.dims.0;
        w.copy_from_slice(&theta[..nw]);
        for (k, o) in self.starts.iter_mut().enumerate() {
            *o = self.x_hat[k] + self.x_scale[k % n] * theta[nw + k];
        }
    }
}

impl<'a, F: Dynamics, V: FnMut(&Hybrid<'a, F>, &mut Buffers) -> Option<f64>> LeastSquaresProblem
    for TrajectoryProblem<'_, 'a, '_, F, V>
{
    type Error = std::convert::Infallible;

    fn residual_count(&self) -> usize {
        self.rows
    }

    /// A window that diverges rejects the step.
    fn residuals(&mut self, theta: &[f64], r: &mut [f64]) -> Result<bool, Self::Error> {
        self.load(theta);
        Ok(self
            .shooter
            .residuals(&self.work, self.windows, &self.starts, r, &mut self.bufs)
            .is_ok())
    }

    fn jacobian(
        &mut self,
        theta: &[f64],
        r: &[f64],
        jac: &mut DMatrix<f64>,
    ) -> Result<(), Self::Error> {
        self.load(theta);
        Linearisation {
            shooter: self.shooter,
            model: &self.work,
            windows: self.windows,
            starts: &self.starts,
            theta,
            x_scale: self.x_scale,
            dims: self.dims,
        }
        .jacobian(r, jac);
        Ok(())
    }

    /// Score the held-out windows, keep the best weights, report progress, and stop
    /// after [`TrajectoryConfig::max_fail`] steps without a better held-out objective.
    fn accepted(&mut self, step: &AcceptedStep<'_>) -> Control {
        self.load(step.theta);
        let v = (self.val_objective)(&self.work, &mut self.bufs);
        if let Some(v) = v {
            self.val_history.push(v);
            if v < self.best.0 {
                self.best = (v, step.theta.to_vec(), step.iteration);
                self.fails = 0;
            } else {
                self.fails += 1;
            }
        }
        if let Some(cb) = self.progress.as_mut() {
            cb(TrajectoryProgress {
                iteration: step.iteration,
                train_objective: step.cost / self.m_train as f64,
                val_objective: v,
                mu: step.mu,
            });
        }
        if self.fails >= self.max_fail {
            Control::Stop
        } else {
            Control::Continue
        }
    }
}

/// Standard deviation of every state over all records' estimates (1 for a constant one).
fn state_scales(records: &[ShootingRecord<'_>], n: usize) -> Vec<f64> {
    (0..n)
        .map(|i| {
            let count: usize = records.iter().map(|r| r.states.ncols()).sum();
            if count < 2 {
                return 1.0;
            }
            let sum: f64 = records.iter().map(|r| r.states.row(i).sum()).sum();
            let mean = sum / count as f64;
            let ss: f64 = records
                .iter()
                .map(|r| {
                    r.states
                        .row(i)
                        .iter()
                        .map(|v| (v - mean) * (v - mean))
                        .sum::<f64>()
                })
                .sum();
            let sd = (ss / (count - 1) as f64).sqrt();
            if sd > 0.0 && sd.is_finite() { sd } else { 1.0 }
        })
        .collect()
}
