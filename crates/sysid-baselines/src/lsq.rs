//! The output-error baselines' least-squares problems on the workspace's one
//! Levenberg–Marquardt solver ([`sysid_core::least_squares`], MINPACK column scaling):
//! the problem form the baselines write (residuals and, when asked for, their Jacobian;
//! `None` where the model diverges), the rank test that names an unidentifiable
//! parameter before the solve, and the exact-fit test.

use nalgebra::{DMatrix, DVector};
use sysid_core::{
    LeastSquaresProblem, LmSettings, Scaling, SolveReport, Termination, levenberg_marquardt,
};

use crate::error::{BaselineError, Result};

/// Residuals and, when asked for, their Jacobian.
pub(crate) type Linearised = (DVector<f64>, Option<DMatrix<f64>>);

/// A least-squares problem: residuals (and Jacobian) at `θ`; `Ok(None)` means the model
/// diverged there (the step is rejected).
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
    /// The solver's damping scale.
    pub scaling: Scaling,
}

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

/// A baseline problem as the solver's.
struct Adapter<'a, P> {
    inner: &'a P,
    rows: usize,
}

impl<P: LeastSquares> LeastSquaresProblem for Adapter<'_, P> {
    type Error = BaselineError;

    fn residual_count(&self) -> usize {
        self.rows
    }

    fn residuals(&mut self, theta: &[f64], r: &mut [f64]) -> Result<bool> {
        Ok(match self.inner.residuals(theta, false)? {
            Some((v, _)) if v.len() == r.len() => {
                r.copy_from_slice(v.as_slice());
                true
            }
            _ => false,
        })
    }

    /// The solver asks for Jacobians only where the residuals were computed.
    fn jacobian(&mut self, theta: &[f64], _: &[f64], jac: &mut DMatrix<f64>) -> Result<()> {
        match self.inner.residuals(theta, true)? {
            Some((_, Some(j))) => {
                jac.copy_from(&j);
                Ok(())
            }
            _ => Err(diverged("model during the fit")),
        }
    }
}

fn diverged(channel: &str) -> BaselineError {
    BaselineError::Diverged {
        sample: 0,
        channel: channel.into(),
        value: f64::INFINITY,
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

/// Minimise `‖r(θ)‖²` from `theta0`, after the rank test at the start. `names` name the
/// parameters in errors; `what` names the model in a divergence error.
pub(crate) fn minimise<P: LeastSquares>(
    problem: &P,
    theta0: &[f64],
    names: &[String],
    what: &str,
    settings: Settings,
) -> Result<Outcome> {
    let (r0, j0) = match problem.residuals(theta0, true)? {
        Some((r, Some(j))) => (r, j),
        _ => return Err(diverged(&format!("initial {what}"))),
    };
    scale_and_rank(&j0, names)?;
    solve(problem, theta0, r0.len(), what, settings)
}

/// [`minimise`] without the rank test: for linear-in-parameters models whose terms may be
/// nearly collinear on the data, where the damping carries the step (the minimum-norm
/// start already holds the undetermined directions at zero).
pub(crate) fn minimise_damped<P: LeastSquares>(
    problem: &P,
    theta0: &[f64],
    what: &str,
    settings: Settings,
) -> Result<Outcome> {
    let rows = match problem.residuals(theta0, false)? {
        Some((r, _)) => r.len(),
        None => return Err(diverged(&format!("initial {what}"))),
    };
    solve(problem, theta0, rows, what, settings)
}

fn solve<P: LeastSquares>(
    problem: &P,
    theta0: &[f64],
    rows: usize,
    what: &str,
    settings: Settings,
) -> Result<Outcome> {
    let exact = settings.exact_rtol * settings.data_norm;
    let lm = LmSettings {
        max_iterations: usize::try_from(settings.max_iterations).unwrap_or(usize::MAX),
        gtol: settings.gtol,
        ftol: settings.ftol,
        exact_cost: exact * exact,
        scaling: settings.scaling,
        ..LmSettings::default()
    };
    let mut adapter = Adapter {
        inner: problem,
        rows,
    };
    let solution = levenberg_marquardt(&mut adapter, theta0, &lm)?;
    if solution.report.termination == Termination::Diverged {
        return Err(diverged(&format!("initial {what}")));
    }
    let report = solution.report.to_solve_report();
    let theta = solution.theta;
    match problem.residuals(&theta, true)? {
        Some((residuals, Some(jacobian))) => Ok(Outcome {
            theta,
            residuals,
            jacobian,
            report,
        }),
        _ => Err(diverged(&format!("fitted {what}"))),
    }
}
