//! The one nonlinear least-squares solver of the workspace: Levenberg–Marquardt on
//! `S(θ) = ‖r(θ)‖²` for problems of a few to a few hundred parameters, used by
//! discovery's calibration, the initial-state fit, nn's trajectory refinement and the
//! output-error baselines (nn's `trainlm`, which exploits the network's structure, is
//! the one other LM loop).
//!
//! Each iteration solves `(JᵀJ + μ·D²) δ = −Jᵀr` by Cholesky, with MINPACK's column
//! scaling (Moré 1978; `D = diag(d_j)`, `d_j` the largest norm column `j` of the
//! Jacobian has had so far, so the damping is invariant to the units of each parameter)
//! and the gain-ratio update of `μ` of Nielsen (Madsen, Nielsen & Tingleff, *Methods for
//! Non-Linear Least Squares Problems*, DTU 2004, §3.2): with `ρ` the actual over the
//! predicted decrease, an accepted step (`S` falls) multiplies `μ` by
//! `max(1/3, 1 − (2ρ − 1)³)` (the floor `1/3` is a setting) and resets `ν = 2`; a rejected one multiplies `μ` by `ν` and
//! doubles `ν`. A trial whose residuals cannot be computed (the model diverges there)
//! is a rejected step. The cost never increases.
//!
//! Written by hand because argmin has no Levenberg–Marquardt solver (its trust region
//! with a Steihaug subproblem crept along the curved valleys of near-integrating
//! output-error models), and the `levenberg-marquardt` crate wants the problem to own its
//! parameters and cannot reject a diverging trial without a NaN.

use nalgebra::{Cholesky, DMatrix, DVector};

use crate::estimate::{IterationRecord, SolveReport, Termination};

/// A least-squares problem: residuals and their Jacobian at a point. The solver only
/// reads and writes the slices and matrix it passes, so an implementation that keeps its
/// own buffers allocates nothing per evaluation.
pub trait LeastSquaresProblem {
    /// The problem's own error (a simulation that fails for a reason other than
    /// diverging, a bad shape); it ends the solve.
    type Error;

    /// Number of residuals (fixed during a solve).
    fn residual_count(&self) -> usize;

    /// Write the residuals at `theta` into `r` (length [`Self::residual_count`]).
    /// `Ok(false)` means the model cannot be evaluated there (e.g. its simulation
    /// diverges): a trial step there is rejected.
    fn residuals(&mut self, theta: &[f64], r: &mut [f64]) -> Result<bool, Self::Error>;

    /// Write the Jacobian `∂r/∂θ` at `theta` into `jac` (`residual_count × θ`); `r` holds
    /// the residuals there (for forward differences).
    fn jacobian(
        &mut self,
        theta: &[f64],
        r: &[f64],
        jac: &mut DMatrix<f64>,
    ) -> Result<(), Self::Error>;

    /// Called after every accepted step; [`Control::Stop`] ends the solve with
    /// [`Termination::StoppedEarly`] (early stopping on held-out data, progress reports).
    fn accepted(&mut self, _step: &AcceptedStep<'_>) -> Control {
        Control::Continue
    }
}

/// What the solver passes to [`LeastSquaresProblem::accepted`].
#[derive(Debug, Clone, Copy)]
pub struct AcceptedStep<'a> {
    /// Accepted steps so far, from 1.
    pub iteration: usize,
    /// The new point.
    pub theta: &'a [f64],
    /// Its cost `‖r‖²`.
    pub cost: f64,
    /// The damping after the step.
    pub mu: f64,
}

/// Whether the solve goes on after an accepted step.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Control {
    /// Go on.
    Continue,
    /// End the solve here.
    Stop,
}

/// The damping matrix `D²` of [`levenberg_marquardt`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Scaling {
    /// MINPACK's: `d_j` the largest norm column `j` has had, so the solve does not
    /// depend on the units of each parameter (physical coefficients, initial states).
    #[default]
    Columns,
    /// One `d` for every parameter, the largest column norm seen: damping towards the
    /// steepest-descent step, as `trainlm`'s `μI` (network weights, where a parameter
    /// with a small column is a direction the data hardly determine, and scaling it up
    /// lets the step run along it).
    Uniform,
    /// Marquardt's `D² = diag(JᵀJ)` of the current Jacobian (no memory of earlier
    /// columns): the linear state-space baseline's order choice was tuned with it.
    Current,
}

/// Settings of [`levenberg_marquardt`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LmSettings {
    /// Most iterations (each one Jacobian, then trials until one is accepted or `μ`
    /// passes `mu_max`). Default 100.
    pub max_iterations: usize,
    /// Initial damping (relative to the column scaling `D²`, so `1e-3` weights the
    /// gradient direction a thousandth of the Gauss–Newton one). Default 1e-3.
    pub mu_initial: f64,
    /// The solve ends with [`Termination::NoDescent`] when `μ` exceeds this without a
    /// decrease. Default 1e16.
    pub mu_max: f64,
    /// Converged when an accepted step lowers `S` by at most `ftol·S` (relative to the
    /// cost before the step). Default 1e-10.
    pub ftol: f64,
    /// Converged when every column of the scaled Jacobian is at most `gtol` from
    /// orthogonal to the residual (`|J_jᵀr| ≤ gtol·d_j·‖r‖`, MINPACK's gradient test).
    /// Default 0 (only an exactly zero gradient).
    pub gtol: f64,
    /// Converged when an accepted scaled step is at most `xtol` times the scaled point
    /// (`‖Dδ‖ ≤ xtol·‖Dθ‖`). Default 0 (off).
    pub xtol: f64,
    /// Converged when `S ≤ exact_cost` (an exact fit). Default 0.
    pub exact_cost: f64,
    /// The damping matrix. Default [`Scaling::Columns`].
    pub scaling: Scaling,
    /// Smallest factor on `μ` after an accepted step (Nielsen's `1/3`; trainlm's `0.1`
    /// for networks, whose steps it pays to let approach Gauss–Newton fast). Default 1/3.
    pub mu_floor_factor: f64,
    /// Report a solve that stopped where it started as [`Termination::NoProgress`]
    /// instead of [`Termination::Converged`] or [`Termination::NoDescent`]: its cost did
    /// not move from the start ([`LmReport::moved`] false) and the column-normalised
    /// `JᵀJ` of its last Jacobian (taken where the cost still was the start's) is
    /// rank-deficient (an eigenvalue at most `1e-12` of the largest, or a zero column).
    /// For calibrations of physical models, where that is a start at a singular point;
    /// a network's Jacobian is rank-deficient as a rule. Default false.
    pub no_progress: bool,
}

impl Default for LmSettings {
    fn default() -> Self {
        Self {
            max_iterations: 100,
            mu_initial: 1e-3,
            mu_max: 1e16,
            ftol: 1e-10,
            gtol: 0.0,
            xtol: 0.0,
            exact_cost: 0.0,
            scaling: Scaling::Columns,
            mu_floor_factor: 1.0 / 3.0,
            no_progress: false,
        }
    }
}

/// How a solve went.
#[derive(Debug, Clone, PartialEq)]
pub struct LmReport {
    /// Why it stopped.
    pub termination: Termination,
    /// One record per accepted step (cost `‖r‖²` after it, norm of the step).
    pub steps: Vec<IterationRecord>,
    /// Cost `‖r‖²` at the start.
    pub initial_cost: f64,
    /// Iterations run (Jacobians formed).
    pub iterations: usize,
    /// Residual evaluations at trial points.
    pub trials: usize,
    /// Damping at the end.
    pub mu: f64,
    /// Rank of the column-normalised `JᵀJ` and its number of columns, when the test of
    /// [`LmSettings::no_progress`] ran (a solve that did not move); `None` otherwise.
    pub rank: Option<(usize, usize)>,
    /// MINPACK's gradient measure at the last Jacobian: the largest cosine between a
    /// column of `J` and the residual, `max_j |J_jᵀr| / (‖J_j‖·‖r‖)` (zero columns left
    /// out); `None` when no Jacobian was formed. At a stationary point it is at rounding
    /// level; a solve that ends [`Termination::NoDescent`] with it large had a Jacobian
    /// that does not describe its residuals ([`LmReport::stationary`]).
    pub gradient_cosine: Option<f64>,
}

/// Largest gradient cosine ([`LmReport::gradient_cosine`]) at which a solve that found no
/// descending step counts as stationary: a Gauss–Newton step from such a point could
/// lower `‖r‖²` by about `p·1e-8` of itself at most, within a hundred times the default
/// relative convergence tolerance's reach over `p` parameters.
pub const STATIONARY_COSINE: f64 = 1e-4;

impl LmReport {
    /// Whether the solve ended at a stationary point: [`Termination::Converged`], or
    /// [`Termination::NoDescent`] (no damped step lowered the cost) with a gradient cosine
    /// at most [`STATIONARY_COSINE`] at the last Jacobian.
    pub fn stationary(&self) -> bool {
        match self.termination {
            Termination::Converged => true,
            Termination::NoDescent => self.gradient_cosine.is_some_and(|c| c <= STATIONARY_COSINE),
            _ => false,
        }
    }

    /// Cost before every accepted step and after the last: index 0 is the start.
    pub fn cost_history(&self) -> Vec<f64> {
        std::iter::once(self.initial_cost)
            .chain(self.steps.iter().map(|s| s.cost))
            .collect()
    }

    /// Cost at the end.
    pub fn final_cost(&self) -> f64 {
        self.steps.last().map_or(self.initial_cost, |s| s.cost)
    }

    /// Whether the cost moved: it fell by more than `1e-9` of the start's (both finite).
    /// A solve that diverged at its start did not move.
    pub fn moved(&self) -> bool {
        let (start, end) = (self.initial_cost, self.final_cost());
        start.is_finite()
            && end.is_finite()
            && (start - end).abs() > 1e-9 * start.abs().max(f64::MIN_POSITIVE)
    }

    /// As the workspace's general [`SolveReport`].
    pub fn to_solve_report(&self) -> SolveReport {
        SolveReport {
            termination: Some(self.termination),
            iterations: self.steps.clone(),
            phase_seconds: Vec::new(),
        }
    }
}

/// The solver's answer: the best point found, its residuals and the report.
#[derive(Debug, Clone, PartialEq)]
pub struct LmSolution {
    /// The parameters at the end (the lowest cost seen).
    pub theta: Vec<f64>,
    /// Residuals there.
    pub residuals: DVector<f64>,
    /// How the solve went.
    pub report: LmReport,
}

/// Minimise `‖r(θ)‖²` from `theta0` by Levenberg–Marquardt (module doc).
///
/// When the residuals cannot be computed at `theta0` the solve ends at once with
/// [`Termination::Diverged`]. Errors: those of the problem.
pub fn levenberg_marquardt<P: LeastSquaresProblem + ?Sized>(
    problem: &mut P,
    theta0: &[f64],
    settings: &LmSettings,
) -> Result<LmSolution, P::Error> {
    let p = theta0.len();
    let rows = problem.residual_count();
    let mut theta = theta0.to_vec();
    let mut r = DVector::zeros(rows);
    let mut report = LmReport {
        termination: Termination::MaxIterations,
        steps: Vec::new(),
        initial_cost: f64::INFINITY,
        iterations: 0,
        trials: 0,
        mu: settings.mu_initial,
        rank: None,
        gradient_cosine: None,
    };
    let finish = |theta, residuals, report| LmSolution {
        theta,
        residuals,
        report,
    };
    if !problem.residuals(&theta, r.as_mut_slice())? || !r.iter().all(|v| v.is_finite()) {
        report.termination = Termination::Diverged;
        return Ok(finish(theta, r, report));
    }
    let mut cost = r.norm_squared();
    report.initial_cost = cost;
    if cost <= settings.exact_cost {
        report.termination = Termination::Converged;
        return Ok(finish(theta, r, report));
    }
    if p == 0 {
        report.termination = Termination::Exact;
        return Ok(finish(theta, r, report));
    }
    let mut jac = DMatrix::zeros(rows, p);
    let mut jtj = DMatrix::zeros(p, p);
    let mut a = DMatrix::zeros(p, p);
    let mut g = DVector::zeros(p);
    let mut delta = DVector::zeros(p);
    let mut trial = vec![0.0; p];
    let mut trial_r = DVector::zeros(rows);
    let mut d = vec![0.0f64; p];
    let mut mu = settings.mu_initial;
    let mut nu = 2.0;
    while report.iterations < settings.max_iterations {
        report.iterations += 1;
        problem.jacobian(&theta, r.as_slice(), &mut jac)?;
        jtj.gemm_tr(1.0, &jac, &jac, 0.0);
        g.gemv_tr(1.0, &jac, &r, 0.0);
        // MINPACK's scaling: each column's largest norm so far (1 for a zero column).
        for (j, dj) in d.iter_mut().enumerate() {
            let norm = jtj[(j, j)].sqrt();
            *dj = if norm.is_finite() { dj.max(norm) } else { *dj };
            if *dj == 0.0 {
                *dj = if norm > 0.0 { norm } else { 1.0 };
            }
        }
        if settings.scaling == Scaling::Current {
            for (j, dj) in d.iter_mut().enumerate() {
                *dj = jtj[(j, j)].max(1e-300).sqrt();
            }
        }
        if settings.scaling == Scaling::Uniform {
            let top = d.iter().copied().fold(0.0, f64::max);
            d.fill(top);
        }
        let r_norm = cost.sqrt();
        report.gradient_cosine = Some(
            g.iter()
                .enumerate()
                .filter(|&(j, _)| jtj[(j, j)] > 0.0)
                .map(|(j, gj)| gj.abs() / (jtj[(j, j)].sqrt() * r_norm.max(f64::MIN_POSITIVE)))
                .fold(
                    0.0,
                    |a: f64, c| if c.is_nan() { f64::INFINITY } else { a.max(c) },
                ),
        );
        if g.iter()
            .zip(&d)
            .all(|(gj, dj)| gj.abs() <= settings.gtol * dj * r_norm)
        {
            report.termination = Termination::Converged;
            break;
        }
        // Trials until one lowers the cost or μ runs out.
        let mut step = None;
        while mu <= settings.mu_max {
            a.copy_from(&jtj);
            for (j, dj) in d.iter().enumerate() {
                a[(j, j)] += mu * dj * dj;
            }
            if let Some(chol) = Cholesky::new(std::mem::replace(&mut a, DMatrix::zeros(0, 0))) {
                delta.copy_from(&g);
                delta.neg_mut();
                chol.solve_mut(&mut delta);
                a = chol.unpack();
                for ((t, th), dl) in trial.iter_mut().zip(&theta).zip(delta.iter()) {
                    *t = th + dl;
                }
                if trial.iter().all(|v| v.is_finite()) {
                    report.trials += 1;
                    if problem.residuals(&trial, trial_r.as_mut_slice())? {
                        let new_cost = trial_r.norm_squared();
                        if new_cost < cost {
                            // Predicted decrease of the linear model: −gᵀδ + μ‖Dδ‖².
                            let scaled: f64 =
                                delta.iter().zip(&d).map(|(dl, dj)| (dl * dj).powi(2)).sum();
                            let predicted = -g.dot(&delta) + mu * scaled;
                            let rho = (cost - new_cost) / predicted.max(f64::MIN_POSITIVE);
                            mu *= (1.0 - (2.0 * rho - 1.0).powi(3)).max(settings.mu_floor_factor);
                            nu = 2.0;
                            step = Some((scaled.sqrt(), new_cost));
                            break;
                        }
                    }
                }
            } else {
                // The factorisation failed: a's storage went with it.
                a = DMatrix::zeros(p, p);
            }
            mu *= nu;
            nu *= 2.0;
        }
        let Some((scaled_step, new_cost)) = step else {
            report.termination = Termination::NoDescent;
            break;
        };
        let decrease = cost - new_cost;
        let before = cost;
        std::mem::swap(&mut theta, &mut trial);
        std::mem::swap(&mut r, &mut trial_r);
        cost = new_cost;
        report.steps.push(IterationRecord {
            iteration: report.steps.len() + 1,
            cost,
            step_norm: delta.norm(),
            step_length: 1.0,
        });
        let control = problem.accepted(&AcceptedStep {
            iteration: report.steps.len(),
            theta: &theta,
            cost,
            mu,
        });
        if control == Control::Stop {
            report.termination = Termination::StoppedEarly;
            break;
        }
        let scaled_theta: f64 = theta
            .iter()
            .zip(&d)
            .map(|(t, dj)| (t * dj).powi(2))
            .sum::<f64>()
            .sqrt();
        if cost <= settings.exact_cost
            || decrease <= settings.ftol * before
            || scaled_step <= settings.xtol * scaled_theta
        {
            report.termination = Termination::Converged;
            break;
        }
    }
    report.mu = mu;
    // Stopped where it started (LmSettings::no_progress). The loop ran, so `jtj` is the
    // last Jacobian's, taken at a point of the start's cost.
    if settings.no_progress
        && report.iterations > 0
        && matches!(
            report.termination,
            Termination::Converged | Termination::NoDescent
        )
        && !report.moved()
    {
        let rank = normalised_rank(&jtj);
        report.rank = Some((rank, p));
        if rank < p {
            report.termination = Termination::NoProgress;
        }
    }
    Ok(finish(theta, r, report))
}

/// Rank of `JᵀJ` with its columns normalised (`JᵀJ_ij / (‖J_i‖·‖J_j‖)`): eigenvalues above
/// `1e-12` of the largest. A zero or non-finite column counts as a lost rank; when the
/// decomposition does not converge the other columns count as independent (no verdict
/// without one).
fn normalised_rank(jtj: &DMatrix<f64>) -> usize {
    let p = jtj.nrows();
    let keep: Vec<usize> = (0..p)
        .filter(|&j| {
            let d = jtj[(j, j)];
            d.is_finite() && d > 0.0
        })
        .collect();
    if keep.is_empty() {
        return 0;
    }
    let norms: Vec<f64> = keep.iter().map(|&j| jtj[(j, j)].sqrt()).collect();
    let k = keep.len();
    let scaled = DMatrix::from_fn(k, k, |a, b| jtj[(keep[a], keep[b])] / (norms[a] * norms[b]));
    if !scaled.iter().all(|v| v.is_finite()) {
        return k;
    }
    let Some(eig) = nalgebra::SymmetricEigen::try_new(scaled, f64::EPSILON, 10_000) else {
        return k;
    };
    let top = eig.eigenvalues.iter().copied().fold(0.0, f64::max);
    eig.eigenvalues.iter().filter(|&&l| l > 1e-12 * top).count()
}

/// Forward-difference Jacobian of `residuals` at `theta` (residuals `r` there), step
/// `h_j = rel·max(|θ_j|, floor)` rounded to a representable one. A perturbed point
/// whose residuals cannot be computed gives a zero column. For problems whose exact
/// Jacobian is out of reach.
pub fn forward_difference<E>(
    mut residuals: impl FnMut(&[f64], &mut [f64]) -> Result<bool, E>,
    theta: &[f64],
    r: &[f64],
    step: (f64, f64),
    jac: &mut DMatrix<f64>,
) -> Result<(), E> {
    let (rel, floor) = step;
    let mut t = theta.to_vec();
    for j in 0..theta.len() {
        let h = rel * theta[j].abs().max(floor);
        t[j] = theta[j] + h;
        let h = t[j] - theta[j];
        let mut col = jac.column_mut(j);
        let ok = residuals(&t, col.as_mut_slice())?;
        if ok {
            for (c, r0) in col.iter_mut().zip(r) {
                *c = (*c - r0) / h;
            }
        } else {
            col.fill(0.0);
        }
        t[j] = theta[j];
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Rosenbrock as least squares: r = (10(θ₂ − θ₁²), 1 − θ₁), minimum (1, 1), S = 0.
    struct Rosenbrock {
        diverge_beyond: f64,
    }

    impl LeastSquaresProblem for Rosenbrock {
        type Error = ();
        fn residual_count(&self) -> usize {
            2
        }
        fn residuals(&mut self, t: &[f64], r: &mut [f64]) -> Result<bool, ()> {
            if t[0].abs() > self.diverge_beyond {
                return Ok(false);
            }
            r[0] = 10.0 * (t[1] - t[0] * t[0]);
            r[1] = 1.0 - t[0];
            Ok(true)
        }
        fn jacobian(&mut self, t: &[f64], _: &[f64], j: &mut DMatrix<f64>) -> Result<(), ()> {
            j[(0, 0)] = -20.0 * t[0];
            j[(0, 1)] = 10.0;
            j[(1, 0)] = -1.0;
            j[(1, 1)] = 0.0;
            Ok(())
        }
    }

    #[test]
    fn solves_rosenbrock_from_the_textbook_start() {
        let mut p = Rosenbrock {
            diverge_beyond: f64::INFINITY,
        };
        let sol = levenberg_marquardt(&mut p, &[-1.2, 1.0], &LmSettings::default()).unwrap();
        assert!(
            (sol.theta[0] - 1.0).abs() < 1e-6 && (sol.theta[1] - 1.0).abs() < 1e-6,
            "{:?} {:?}",
            sol.theta,
            sol.report
        );
        let h = sol.report.cost_history();
        assert!(h.windows(2).all(|w| w[1] < w[0]), "{h:?}");
        assert_eq!(sol.report.termination, Termination::Converged);
    }

    /// `r = (θ − 1, θ + 1)` (minimum θ = 0, `‖r‖² = 2`), with the Jacobian's sign flipped
    /// when `wrong`, and the residuals rounded to multiples of 1e-6 when `coarse` (a cost
    /// evaluated to a finite precision, as a simulated one is).
    struct Pair {
        wrong: bool,
        coarse: bool,
    }

    impl LeastSquaresProblem for Pair {
        type Error = ();
        fn residual_count(&self) -> usize {
            2
        }
        fn residuals(&mut self, t: &[f64], r: &mut [f64]) -> Result<bool, ()> {
            r[0] = t[0] - 1.0;
            r[1] = t[0] + 1.0;
            if self.coarse {
                for v in r.iter_mut() {
                    *v = (*v * 1e6).round() / 1e6;
                }
            }
            Ok(true)
        }
        fn jacobian(&mut self, _: &[f64], _: &[f64], j: &mut DMatrix<f64>) -> Result<(), ()> {
            let s = if self.wrong { -1.0 } else { 1.0 };
            j[(0, 0)] = s;
            // A sensitivity known to 1e-10, as an integrated one is.
            j[(1, 0)] = s * (1.0 + 1e-10);
            Ok(())
        }
    }

    /// No damped step lowers the cost in both cases; only the one whose gradient is at
    /// rounding level is a stationary point.
    #[test]
    fn no_descent_is_stationary_only_with_a_small_gradient() {
        // 1e-9 from the minimum: the cost, known to 1e-6, is 2 there and at every point a
        // step can reach; the gradient, from a Jacobian known to 1e-10, is 1e-10.
        let at_min = levenberg_marquardt(
            &mut Pair {
                wrong: false,
                coarse: true,
            },
            &[1e-9],
            &LmSettings::default(),
        )
        .unwrap();
        assert_eq!(
            at_min.report.termination,
            Termination::NoDescent,
            "{:?}",
            at_min.report
        );
        let c = at_min.report.gradient_cosine.unwrap();
        assert!(c < 1e-8 && c > 0.0, "cosine {c}");
        assert!(at_min.report.stationary());
        // A Jacobian of the wrong sign: every step goes uphill.
        let wrong = levenberg_marquardt(
            &mut Pair {
                wrong: true,
                coarse: false,
            },
            &[0.5],
            &LmSettings::default(),
        )
        .unwrap();
        assert_eq!(wrong.report.termination, Termination::NoDescent);
        let c = wrong.report.gradient_cosine.unwrap();
        // |Jᵀr| = 2·0.5 = 1 over ‖J‖·‖r‖ = √2·√2.5 (to the Jacobian's 1e-10).
        assert!((c - 1.0 / 5f64.sqrt()).abs() < 1e-9, "cosine {c}");
        assert!(!wrong.report.stationary());
    }

    /// `r = (θ₁θ₂ − 1, θ₁θ₂ − 2)`: at the origin every column of the Jacobian is zero, so
    /// the gradient is zero and the solve stops at once, where it started.
    struct Product;

    impl LeastSquaresProblem for Product {
        type Error = ();
        fn residual_count(&self) -> usize {
            2
        }
        fn residuals(&mut self, t: &[f64], r: &mut [f64]) -> Result<bool, ()> {
            r[0] = t[0] * t[1] - 1.0;
            r[1] = t[0] * t[1] - 2.0;
            Ok(true)
        }
        fn jacobian(&mut self, t: &[f64], _: &[f64], j: &mut DMatrix<f64>) -> Result<(), ()> {
            for row in 0..2 {
                j[(row, 0)] = t[1];
                j[(row, 1)] = t[0];
            }
            Ok(())
        }
    }

    #[test]
    fn a_start_at_a_singular_stationary_point_is_no_progress_when_asked() {
        let asked = LmSettings {
            no_progress: true,
            ..LmSettings::default()
        };
        let sol = levenberg_marquardt(&mut Product, &[0.0, 0.0], &asked).unwrap();
        assert_eq!(sol.report.termination, Termination::NoProgress);
        assert_eq!(sol.report.rank, Some((0, 2)));
        assert!(!sol.report.moved());
        assert_eq!(sol.theta, vec![0.0, 0.0]);
        // Not asked: the same stop reads as converged, as before.
        let sol = levenberg_marquardt(&mut Product, &[0.0, 0.0], &LmSettings::default()).unwrap();
        assert_eq!(sol.report.termination, Termination::Converged);
        assert_eq!(sol.report.rank, None);
        // A solve that moves is converged, asked or not, with the same numbers.
        let mut p = Rosenbrock {
            diverge_beyond: f64::INFINITY,
        };
        let plain = levenberg_marquardt(&mut p, &[-1.2, 1.0], &LmSettings::default()).unwrap();
        let checked = levenberg_marquardt(&mut p, &[-1.2, 1.0], &asked).unwrap();
        assert_eq!(checked.report.termination, Termination::Converged);
        assert!(checked.report.moved());
        assert_eq!(plain, checked);
    }

    #[test]
    fn a_diverging_trial_is_a_rejected_step_and_a_diverging_start_is_reported() {
        // The region |θ₁| ≤ 1.25 contains the path from (−1.2, 1) to the minimum only
        // if rejected steps shrink back inside it.
        let mut p = Rosenbrock {
            diverge_beyond: 1.25,
        };
        let sol = levenberg_marquardt(&mut p, &[-1.2, 1.0], &LmSettings::default()).unwrap();
        assert!((sol.theta[0] - 1.0).abs() < 1e-6, "{:?}", sol.theta);
        let sol = levenberg_marquardt(&mut p, &[2.0, 1.0], &LmSettings::default()).unwrap();
        assert_eq!(sol.report.termination, Termination::Diverged);
        assert_eq!(sol.theta, vec![2.0, 1.0]);
    }

    /// An exponential fit y = a·exp(−b·t) to exact data: the forward-difference
    /// Jacobian and the stop hook.
    struct Decay {
        t: Vec<f64>,
        y: Vec<f64>,
        stop_after: usize,
    }

    impl LeastSquaresProblem for Decay {
        type Error = ();
        fn residual_count(&self) -> usize {
            self.t.len()
        }
        fn residuals(&mut self, th: &[f64], r: &mut [f64]) -> Result<bool, ()> {
            for ((ri, t), y) in r.iter_mut().zip(&self.t).zip(&self.y) {
                *ri = y - th[0] * (-th[1] * t).exp();
            }
            Ok(true)
        }
        fn jacobian(&mut self, th: &[f64], r: &[f64], j: &mut DMatrix<f64>) -> Result<(), ()> {
            let (t, y) = (self.t.clone(), self.y.clone());
            let f = |th: &[f64], out: &mut [f64]| {
                for ((o, t), y) in out.iter_mut().zip(&t).zip(&y) {
                    *o = y - th[0] * (-th[1] * t).exp();
                }
                Ok(true)
            };
            forward_difference(f, th, r, (f64::EPSILON.sqrt(), 1.0), j)
        }
        fn accepted(&mut self, step: &AcceptedStep<'_>) -> Control {
            if step.iteration >= self.stop_after {
                Control::Stop
            } else {
                Control::Continue
            }
        }
    }

    #[test]
    fn fits_an_exponential_with_forward_differences_and_stops_when_told() {
        let t: Vec<f64> = (0..40).map(|k| 0.1 * k as f64).collect();
        let y: Vec<f64> = t.iter().map(|t| 2.5 * (-0.8 * t).exp()).collect();
        let mut p = Decay {
            t,
            y,
            stop_after: usize::MAX,
        };
        let sol = levenberg_marquardt(&mut p, &[1.0, 0.1], &LmSettings::default()).unwrap();
        assert!(
            (sol.theta[0] - 2.5).abs() < 1e-6 && (sol.theta[1] - 0.8).abs() < 1e-6,
            "{:?}",
            sol.theta
        );
        p.stop_after = 2;
        let sol = levenberg_marquardt(&mut p, &[1.0, 0.1], &LmSettings::default()).unwrap();
        assert_eq!(sol.report.termination, Termination::StoppedEarly);
        assert_eq!(sol.report.steps.len(), 2);
    }
}
