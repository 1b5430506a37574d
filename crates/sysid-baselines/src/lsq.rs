//! Private adapter to argmin: nonlinear least squares `min ½‖r(θ)‖²` by argmin's trust
//! region method with a Steihaug–CG subproblem on the Gauss–Newton model
//! (gradient `Jᵀr`, Hessian `JᵀJ`): a Levenberg–Marquardt-type iteration. Parameters are
//! scaled by the column norms of the initial Jacobian, and convergence tests in the
//! style of MINPACK (Moré, Garbow & Hillstrom 1980) are added around argmin's solver.
//! Nothing of argmin leaks out of this file.

use std::cell::RefCell;

use argmin::core::{
    CostFunction, Error as ArgminError, Executor, Gradient, Hessian, IterState, KV, Problem,
    Solver, State, TerminationReason, TerminationStatus,
};
use argmin::solver::trustregion::{Steihaug, TrustRegion};
use nalgebra::{DMatrix, DVector};
use sysid_core::{IterationRecord, SolveReport, Termination};

use crate::error::{BaselineError, Result};

/// Residuals and, when asked for, their Jacobian.
pub(crate) type Linearised = (DVector<f64>, Option<DMatrix<f64>>);

/// A least-squares problem: residuals (and Jacobian) at `θ`; `Ok(None)` means the model
/// diverged there (cost +∞, the step is rejected).
pub(crate) trait LeastSquares {
    fn residuals(&self, theta: &[f64], jacobian: bool) -> Result<Option<Linearised>>;
}

/// Stopping rules.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Settings {
    /// Iteration budget.
    pub max_iterations: u64,
    /// Stop when every scaled-gradient component is at most `gtol·‖r‖` (the cosine of the
    /// angle between the residual and each scaled Jacobian column).
    pub gtol: f64,
    /// Stop when an accepted step reduces the cost by at most `ftol` relative.
    pub ftol: f64,
    /// Stop when `‖r‖ ≤ exact_rtol·‖y‖` (an exact fit to working precision).
    pub exact_rtol: f64,
    /// Norm of the data, for the exact-fit test.
    pub data_norm: f64,
}

/// Consecutive rejected trust-region steps after which the solve counts as stalled: each
/// rejection shrinks the radius at least 4×, so 10 of them shrink it by 10⁶.
const MAX_REJECTIONS: usize = 10;

/// Smallest over largest singular value of the column-scaled Jacobian below which the
/// parameters count as not identifiable: `JᵀJ` then has a condition number above 1e16,
/// beyond what f64 can invert.
pub(crate) const RANK_RTOL: f64 = 1e-8;

pub(crate) struct Outcome {
    pub theta: Vec<f64>,
    pub residuals: DVector<f64>,
    pub jacobian: DMatrix<f64>,
    pub report: SolveReport,
}

/// Residuals and scaled Jacobian at one point.
type Scaled2 = (DVector<f64>, DMatrix<f64>);
type Cached = (Vec<f64>, Option<Scaled2>);

struct Scaled<'a, P> {
    inner: &'a P,
    scale: Vec<f64>,
    cache: RefCell<Option<Cached>>,
    /// Where a failure of our own problem is kept (argmin's error type is untyped); it
    /// lives outside the problem because argmin drops the problem on error.
    failure: &'a RefCell<Option<BaselineError>>,
}

impl<P: LeastSquares> Scaled<'_, P> {
    fn theta(&self, z: &DVector<f64>) -> Vec<f64> {
        z.iter().zip(&self.scale).map(|(z, d)| z / d).collect()
    }

    fn fail(&self, e: BaselineError) -> ArgminError {
        *self.failure.borrow_mut() = Some(e);
        ArgminError::msg("least-squares problem failed")
    }

    /// Residuals and scaled Jacobian at `z`, cached for the last point.
    fn linearise(&self, z: &DVector<f64>) -> Result<Option<Scaled2>, ArgminError> {
        let key: Vec<f64> = z.iter().copied().collect();
        if let Some((k, v)) = self.cache.borrow().as_ref()
            && k.iter().zip(&key).all(|(a, b)| a.to_bits() == b.to_bits())
        {
            return Ok(v.clone());
        }
        let v = match self.inner.residuals(&self.theta(z), true) {
            Ok(Some((r, Some(mut j)))) => {
                for (c, d) in self.scale.iter().enumerate() {
                    j.column_mut(c).scale_mut(1.0 / d);
                }
                Some((r, j))
            }
            Ok(_) => None,
            Err(e) => return Err(self.fail(e)),
        };
        *self.cache.borrow_mut() = Some((key, v.clone()));
        Ok(v)
    }

    fn diverged(&self) -> ArgminError {
        ArgminError::msg("derivative requested where the model diverges")
    }
}

impl<P: LeastSquares> CostFunction for Scaled<'_, P> {
    type Param = DVector<f64>;
    type Output = f64;
    fn cost(&self, z: &Self::Param) -> Result<f64, ArgminError> {
        match self.inner.residuals(&self.theta(z), false) {
            Ok(Some((r, _))) => Ok(0.5 * r.norm_squared()),
            Ok(None) => Ok(f64::INFINITY),
            Err(e) => Err(self.fail(e)),
        }
    }
}

impl<P: LeastSquares> Gradient for Scaled<'_, P> {
    type Param = DVector<f64>;
    type Gradient = DVector<f64>;
    fn gradient(&self, z: &Self::Param) -> Result<Self::Gradient, ArgminError> {
        let (r, j) = self.linearise(z)?.ok_or_else(|| self.diverged())?;
        Ok(j.tr_mul(&r))
    }
}

impl<P: LeastSquares> Hessian for Scaled<'_, P> {
    type Param = DVector<f64>;
    type Hessian = DMatrix<f64>;
    fn hessian(&self, z: &Self::Param) -> Result<Self::Hessian, ArgminError> {
        let (_, j) = self.linearise(z)?.ok_or_else(|| self.diverged())?;
        Ok(j.tr_mul(&j))
    }
}

type St = IterState<DVector<f64>, DVector<f64>, (), DMatrix<f64>, (), f64>;

/// argmin's trust region with our stopping rules and an iteration log.
struct Stopping<S> {
    inner: S,
    settings: Settings,
    rejections: usize,
    reason: Option<Termination>,
    history: Vec<IterationRecord>,
    last_param: Option<DVector<f64>>,
}

impl<O, S: Solver<O, St>> Solver<O, St> for Stopping<S> {
    fn name(&self) -> &str {
        "trust region (Steihaug) with least-squares stopping rules"
    }

    fn init(
        &mut self,
        problem: &mut Problem<O>,
        state: St,
    ) -> Result<(St, Option<KV>), ArgminError> {
        let out = self.inner.init(problem, state)?;
        self.last_param = out.0.get_param().cloned();
        Ok(out)
    }

    fn next_iter(
        &mut self,
        problem: &mut Problem<O>,
        state: St,
    ) -> Result<(St, Option<KV>), ArgminError> {
        let (state, kv) = self.inner.next_iter(problem, state)?;
        let step = match (state.get_param(), &self.last_param) {
            (Some(p), Some(q)) => (p - q).norm(),
            _ => 0.0,
        };
        self.last_param = state.get_param().cloned();
        self.history.push(IterationRecord {
            iteration: self.history.len() + 1,
            cost: state.get_cost(),
            step_norm: step,
            step_length: if step > 0.0 { 1.0 } else { 0.0 },
        });
        Ok((state, kv))
    }

    fn terminate(&mut self, state: &St) -> TerminationStatus {
        let cost = state.get_cost();
        let prev = state.get_prev_cost();
        let s = self.settings;
        let r_norm = (2.0 * cost).sqrt();
        let done = |me: &mut Self, why| {
            me.reason = Some(why);
            TerminationStatus::Terminated(TerminationReason::SolverConverged)
        };
        if r_norm <= s.exact_rtol * s.data_norm {
            return done(self, Termination::Converged);
        }
        if let Some(g) = state.get_gradient()
            && g.amax() <= s.gtol * r_norm
        {
            return done(self, Termination::Converged);
        }
        if cost.to_bits() == prev.to_bits() {
            self.rejections += 1;
            if self.rejections >= MAX_REJECTIONS {
                return done(self, Termination::LineSearchFailed);
            }
        } else {
            self.rejections = 0;
            if prev.is_finite() && cost < prev && prev - cost <= s.ftol * cost {
                return done(self, Termination::Converged);
            }
        }
        TerminationStatus::NotTerminated
    }
}

/// Column norms of `J` (its scale) and the rank test on the scaled matrix.
fn scale_and_rank(j: &DMatrix<f64>, names: &[String]) -> Result<Vec<f64>> {
    let scale: Vec<f64> = j.column_iter().map(|c| c.norm()).collect();
    if let Some(i) = scale.iter().position(|d| !(d.is_finite() && *d > 0.0)) {
        return Err(BaselineError::Unidentifiable {
            name: names.get(i).cloned().unwrap_or_default(),
            ratio: 0.0,
        });
    }
    check_rank(j, &scale, names)?;
    Ok(scale)
}

/// Error when the column-scaled `J` is numerically rank deficient, naming the parameter
/// with the largest weight in the null direction.
pub(crate) fn check_rank(j: &DMatrix<f64>, scale: &[f64], names: &[String]) -> Result<()> {
    let mut js = j.clone();
    for (c, d) in scale.iter().enumerate() {
        js.column_mut(c).scale_mut(1.0 / d);
    }
    let svd = js.svd(false, true);
    let sv = &svd.singular_values;
    let (imin, smin) = sv.argmin();
    let smax = sv.max();
    let ratio = if smax > 0.0 { smin / smax } else { 0.0 };
    if ratio < RANK_RTOL {
        let name = svd
            .v_t
            .as_ref()
            .map(|vt| vt.row(imin).transpose().iamax())
            .and_then(|i| names.get(i).cloned())
            .unwrap_or_default();
        return Err(BaselineError::Unidentifiable { name, ratio });
    }
    Ok(())
}

/// Minimise `½‖r(θ)‖²` from `theta0`. `names` name the parameters in errors.
pub(crate) fn minimise<P: LeastSquares>(
    problem: &P,
    theta0: &[f64],
    names: &[String],
    settings: Settings,
) -> Result<Outcome> {
    let (r0, j0) = match problem.residuals(theta0, true)? {
        Some((r, Some(j))) => (r, j),
        _ => {
            return Err(BaselineError::Diverged {
                sample: 0,
                channel: "initial model".into(),
                value: f64::INFINITY,
            });
        }
    };
    let scale = scale_and_rank(&j0, names)?;
    let r0_norm = r0.norm();
    let mut report = SolveReport::default();
    let theta = if r0_norm <= settings.exact_rtol * settings.data_norm {
        report.termination = Some(Termination::Converged);
        theta0.to_vec()
    } else {
        let z0 =
            DVector::from_iterator(theta0.len(), theta0.iter().zip(&scale).map(|(t, d)| t * d));
        let failure = RefCell::new(None);
        let scaled = Scaled {
            inner: problem,
            scale: scale.clone(),
            cache: RefCell::new(None),
            failure: &failure,
        };
        let optimiser_error = |e: ArgminError| BaselineError::Optimiser { source: e.into() };
        // Radius in scaled units: a step of length ρ changes the outputs by about ρ, so the
        // current misfit is the natural first radius.
        let tr = TrustRegion::new(Steihaug::new().with_max_iters(10 * theta0.len() as u64 + 10))
            .with_radius(r0_norm)
            .and_then(|t| t.with_max_radius(1e8 * r0_norm))
            .map_err(optimiser_error)?;
        let solver = Stopping {
            inner: tr,
            settings,
            rejections: 0,
            reason: None,
            history: Vec::new(),
            last_param: None,
        };
        let run = Executor::new(scaled, solver)
            .configure(|s| s.param(z0).max_iters(settings.max_iterations))
            .ctrlc(false)
            .timer(false)
            .run();
        // A failure of our own problem is returned typed; argmin's own as a source.
        if let Some(stashed) = failure.borrow_mut().take() {
            return Err(stashed);
        }
        let mut result = run.map_err(optimiser_error)?;
        let solver = result.solver;
        report.termination = Some(solver.reason.unwrap_or(Termination::MaxIterations));
        report.iterations = solver.history;
        let z = result
            .state
            .take_best_param()
            .or_else(|| result.state.take_param())
            .ok_or(BaselineError::TooFewRows {
                what: "optimiser result",
                found: 0,
                needed: 1,
            })?;
        z.iter().zip(&scale).map(|(z, d)| z / d).collect()
    };
    match problem.residuals(&theta, true)? {
        Some((residuals, Some(jacobian))) => Ok(Outcome {
            theta,
            residuals,
            jacobian,
            report,
        }),
        _ => Err(BaselineError::Diverged {
            sample: 0,
            channel: "fitted model".into(),
            value: f64::INFINITY,
        }),
    }
}
