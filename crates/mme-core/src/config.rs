//! Configuration of the estimator (`W`, noise variance, sub-steps, iteration budget) and
//! its validation against a model, before any expensive work.

use nalgebra::DMatrix;

use crate::error::{MmeError, Result};

/// How the correction weight `W` (`q × q`, per unit time) is chosen.
///
/// A piece of `d` held for `h` seconds costs `h·dᵀWd`, so a given `W` means the same at
/// any sample rate and sub-step count.
#[derive(Debug, Clone, PartialEq)]
pub enum WeightSpec {
    /// `W = α·shape`, with `α` found by the covariance constraint (see [`AutoWeight`]).
    Auto(AutoWeight),
    /// `W = w·I` (every correction weighted alike).
    Scalar(f64),
    /// `W = diag(w)`, one entry per correction.
    Diagonal(Vec<f64>),
    /// A full symmetric positive-definite `W`.
    Matrix(DMatrix<f64>),
}

impl Default for WeightSpec {
    fn default() -> Self {
        WeightSpec::Auto(AutoWeight::default())
    }
}

/// The fixed shape of an automatically scaled `W = α·shape`.
#[derive(Debug, Clone, PartialEq, Default)]
pub enum WeightShape {
    /// `I_q`.
    #[default]
    Identity,
    /// `diag(v)`, all entries positive.
    Diagonal(Vec<f64>),
    /// A symmetric positive-definite matrix.
    Matrix(DMatrix<f64>),
}

/// Settings of the automatic `W` (covariance constraint, thesis §2.2–2.3).
///
/// The scale `α` of `W = α·shape` is the root, in `log α`, of
///
/// `ρ(α) = Σ_i Σ_k r_ik² / R_i  /  Σ_i n_i  =  target_ratio`,
///
/// where `r_ik = ỹ_ik − (C x̂_k)_i` runs over every observed sample of every measured
/// channel in every experiment and `n_i` is channel `i`'s number of observed samples.
/// `ρ` is the observation-weighted mean of `residual_variance_i / R_i`; it equals the plain
/// mean over channels whenever every channel has the same number of observed samples, and
/// unlike the plain mean it is provably non-decreasing in `α` (the data misfit of a
/// penalised least-squares problem never falls when the penalty grows).
#[derive(Debug, Clone, PartialEq)]
pub struct AutoWeight {
    /// Shape of `W` (default identity).
    pub shape: WeightShape,
    /// First `α` tried (default 1). The bracket is grown from here by factors of 100.
    pub initial: f64,
    /// Target of `ρ(α)` (default 1: residual variance equals noise variance).
    pub target_ratio: f64,
    /// Stop when `|ρ(α)/target − 1|` is below this (default 1e-3).
    pub tolerance: f64,
    /// Budget of sweeps for bracketing and root finding together (default 80).
    pub max_evaluations: usize,
}

impl Default for AutoWeight {
    fn default() -> Self {
        Self {
            shape: WeightShape::Identity,
            initial: 1.0,
            target_ratio: 1.0,
            tolerance: 1e-3,
            max_evaluations: 80,
        }
    }
}

/// How the measurement-noise variance `R = diag(R_i)` is obtained.
#[derive(Debug, Clone, PartialEq, Default)]
pub enum NoiseSpec {
    /// Known variances, one per model output channel, in the model's output order.
    Given(Vec<f64>),
    /// Estimated from the data by maximum restricted marginal likelihood (see
    /// [`crate::noise`]), scanning `W = α·shape` with the configured `W` (or the
    /// automatic `W`'s shape) as the shape. The `W` actually used afterwards is still the
    /// one [`MmeConfig::w`] asks for.
    #[default]
    Auto,
}

/// Iteration budget of the nonlinear (Gauss–Newton) estimator.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IterationOptions {
    /// Most Gauss–Newton iterations per solve (default 50).
    pub max_iterations: usize,
    /// Converged when the relative decrease of `J` in an iteration is below this
    /// (default 1e-10).
    pub cost_tolerance: f64,
    /// Also converged when `J` falls by less than this in each of
    /// [`IterationOptions::plateau_iterations`] iterations running (default 1e-3). `J`
    /// is in units of the noise variance (`Σ r²/R + h·Σ dᵀWd`, minus twice a
    /// log-likelihood up to a constant), so this is a change no statistic of the estimate
    /// can see; it ends the slow crawl of damped steps along a kink of the model (a
    /// `max(·, 0)` law) that the relative test would follow to the iteration limit.
    pub cost_plateau: f64,
    /// Iterations running that must each gain less than [`IterationOptions::cost_plateau`]
    /// (default 3).
    pub plateau_iterations: usize,
    /// Most halvings of the step in the line search (default 30).
    pub max_halvings: usize,
    /// Magnitude beyond which a state counts as diverged (default 1e12).
    pub blow_up: f64,
}

impl Default for IterationOptions {
    fn default() -> Self {
        Self {
            max_iterations: 50,
            cost_tolerance: 1e-10,
            cost_plateau: 1e-3,
            plateau_iterations: 3,
            max_halvings: 30,
            blow_up: 1e12,
        }
    }
}

/// Starting trajectory of the nonlinear estimator (ignored by the linear one).
#[derive(Debug, Clone, PartialEq, Default)]
pub enum StartTrajectory {
    /// From the data: at each sample, the minimum-norm state reproducing the observed
    /// outputs (`x = C⁺ỹ`, unmeasured directions 0, a missing sample keeps the previous
    /// value), with `d = 0`. Not a trajectory of the model, so the first Gauss–Newton step
    /// is taken in full; its closed-loop rollout keeps the model near the data even on long
    /// records. When that first step finds no finite rollout (an unmeasured state at 0,
    /// where a term such as `√|h|` has no usable slope), the estimator replaces this start
    /// by a fitted one: the measured directions as here, the directions the outputs do not
    /// determine from the model's open-loop run from the initial state whose free run fits
    /// the first 200 samples. Where the data-based start works, nothing changes; when the
    /// fitted start fails too, the error ([`crate::MmeError::StartFailed`]) names both.
    /// When the iteration from the data-based start sticks instead (a line search that
    /// cannot lower the cost although the linearisation predicts it can: the first full
    /// step landed where the model's laws are flat, such as a level below empty), the
    /// experiment restarts once from the fitted start and the lower-cost end is kept.
    #[default]
    FromData,
    /// Given initial states, one per experiment (`n` each); the start is the open-loop
    /// rollout of the model from them with `d = 0`.
    Given(Vec<Vec<f64>>),
}

/// A Gaussian prior on one state's initial value `x_i(t0) ~ N(mean, std²)`, in every
/// experiment (see [`MmeConfig::x0_prior`]).
#[derive(Debug, Clone, PartialEq)]
pub struct StatePrior {
    /// The state's name (one of the model's state names).
    pub state: String,
    /// Prior mean of the state at the first sample (finite).
    pub mean: f64,
    /// Prior standard deviation (positive and finite), in the state's unit.
    pub std: f64,
}

impl StatePrior {
    /// A prior `N(mean, std²)` on state `state`.
    pub fn new(state: impl Into<String>, mean: f64, std: f64) -> Self {
        Self {
            state: state.into(),
            mean,
            std,
        }
    }
}

/// Configuration of an MME estimate.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct MmeConfig {
    /// The correction weight `W` (default: automatic, identity shape).
    pub w: WeightSpec,
    /// The measurement-noise variance (default: estimated).
    pub noise_variance: NoiseSpec,
    /// Sub-steps `s` per sample interval (`d` is constant on each of the `s` pieces).
    /// `None` chooses `s` from the model (see [`crate::discretize::default_substeps`]):
    /// the smallest `s ≥ 1` with `dt/s ≤ τ_min/10`, `τ_min = 1/max|λ(A)|`, capped at 64
    /// (the nonlinear estimator, with `A` its Jacobian at the start, lets a stiff model's
    /// fast relaxation modes need only stability: [`crate::discretize::nonlinear_substeps`]).
    pub substeps: Option<usize>,
    /// Iteration budget of the nonlinear estimator (ignored by the linear one).
    pub iterations: IterationOptions,
    /// Starting trajectory of the nonlinear estimator (ignored by the linear one).
    pub start: StartTrajectory,
    /// The job's budget (default unlimited): every sweep of the linear estimator and every
    /// iteration of the nonlinear one charges its sub-steps, and the estimate stops with
    /// [`sysid_core::CoreError::BudgetExhausted`] (inside [`crate::MmeError::Core`]) once it
    /// is spent.
    pub budget: sysid_core::Budget,
    /// Gaussian prior on the initial state, per state by name (default empty: every
    /// initial state free, as in the classical MME). A state with a prior adds
    /// `(x_i(t0) − mean)²/std²` to `J` in every experiment; the others stay free (diffuse).
    /// It acts on the estimate and on the automatic `W` search; the noise-variance
    /// likelihood ([`NoiseSpec::Auto`]) stays the restricted (diffuse-initial-state) one.
    pub x0_prior: Vec<StatePrior>,
}

/// A validated initial-state prior in information form, in the model's state order.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Prior {
    /// `1/std²` per state (0 for a state without a prior).
    pub info: Vec<f64>,
    /// Prior mean per state (0 for a state without a prior, never read there).
    pub mean: Vec<f64>,
}

impl Prior {
    /// `Σ_i info_i (x_i − mean_i)²`, the prior's share of `J`.
    pub fn cost(&self, x0: &[f64]) -> f64 {
        self.info
            .iter()
            .zip(&self.mean)
            .zip(x0)
            .filter(|((info, _), _)| **info > 0.0)
            .map(|((info, m), x)| info * (x - m) * (x - m))
            .sum()
    }
}

/// Check the initial-state prior against the model's state names: every name known and
/// given once, every mean finite, every standard deviation positive and finite. `None`
/// when no state has a prior.
pub(crate) fn resolve_prior(priors: &[StatePrior], states: &[String]) -> Result<Option<Prior>> {
    if priors.is_empty() {
        return Ok(None);
    }
    let n = states.len();
    let mut info = vec![0.0; n];
    let mut mean = vec![0.0; n];
    for p in priors {
        let Some(i) = states.iter().position(|s| *s == p.state) else {
            return Err(MmeError::UnknownState {
                setting: "initial-state prior",
                name: p.state.clone(),
            });
        };
        let bad = |field, value, reason| MmeError::InvalidPrior {
            state: p.state.clone(),
            field,
            value,
            reason,
        };
        if info[i] > 0.0 {
            return Err(bad("state", f64::NAN, "given more than once"));
        }
        if !p.mean.is_finite() {
            return Err(bad("mean", p.mean, "must be finite"));
        }
        if !(p.std.is_finite() && p.std > 0.0) {
            return Err(bad("std", p.std, "must be positive and finite"));
        }
        let inv = 1.0 / (p.std * p.std);
        if !(inv.is_finite() && inv > 0.0) {
            return Err(bad(
                "std",
                p.std,
                "its inverse square overflows or underflows",
            ));
        }
        info[i] = inv;
        mean[i] = p.mean;
    }
    Ok(Some(Prior { info, mean }))
}

/// A `W` validated against the number of corrections: either fixed, or a shape to scale.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum ResolvedWeight {
    /// Use this `W`.
    Fixed(DMatrix<f64>),
    /// Scale this shape automatically.
    Auto {
        shape: DMatrix<f64>,
        opts: AutoWeight,
    },
}

/// Check a `W` specification against `q` corrections.
pub(crate) fn resolve_weight(spec: &WeightSpec, q: usize) -> Result<ResolvedWeight> {
    match spec {
        WeightSpec::Scalar(w) => {
            positive_setting("W", *w)?;
            Ok(ResolvedWeight::Fixed(DMatrix::identity(q, q) * *w))
        }
        WeightSpec::Diagonal(v) => Ok(ResolvedWeight::Fixed(diagonal("W", v, q)?)),
        WeightSpec::Matrix(m) => {
            check_spd("W", m, q)?;
            Ok(ResolvedWeight::Fixed(m.clone()))
        }
        WeightSpec::Auto(opts) => {
            positive_setting("initial", opts.initial)?;
            positive_setting("target_ratio", opts.target_ratio)?;
            positive_setting("tolerance", opts.tolerance)?;
            if opts.max_evaluations < 3 {
                return Err(MmeError::InvalidSetting {
                    name: "max_evaluations",
                    value: opts.max_evaluations as f64,
                    reason: "need at least 3 sweeps",
                });
            }
            let shape = match &opts.shape {
                WeightShape::Identity => DMatrix::identity(q, q),
                WeightShape::Diagonal(v) => diagonal("W shape", v, q)?,
                WeightShape::Matrix(m) => {
                    check_spd("W shape", m, q)?;
                    m.clone()
                }
            };
            Ok(ResolvedWeight::Auto {
                shape,
                opts: opts.clone(),
            })
        }
    }
}

fn positive_setting(name: &'static str, v: f64) -> Result<()> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(MmeError::InvalidSetting {
            name,
            value: v,
            reason: "must be positive and finite",
        })
    }
}

fn diagonal(what: &'static str, v: &[f64], q: usize) -> Result<DMatrix<f64>> {
    if v.len() != q {
        return Err(MmeError::Dimension {
            what,
            rows: v.len(),
            cols: 1,
            expected_rows: q,
            expected_cols: 1,
        });
    }
    if v.iter().any(|x| !(x.is_finite() && *x > 0.0)) {
        return Err(MmeError::NotPositiveDefinite {
            matrix: what,
            reason: "a diagonal entry is not positive and finite",
        });
    }
    Ok(DMatrix::from_diagonal(
        &nalgebra::DVector::from_column_slice(v),
    ))
}

/// Check that `m` is `q × q`, finite, symmetric (to 1e-12 relative) and positive definite.
pub(crate) fn check_spd(what: &'static str, m: &DMatrix<f64>, q: usize) -> Result<()> {
    if m.nrows() != q || m.ncols() != q {
        return Err(MmeError::Dimension {
            what,
            rows: m.nrows(),
            cols: m.ncols(),
            expected_rows: q,
            expected_cols: q,
        });
    }
    if m.iter().any(|x| !x.is_finite()) {
        return Err(MmeError::NotPositiveDefinite {
            matrix: what,
            reason: "non-finite entry",
        });
    }
    let scale = m.amax();
    for i in 0..q {
        for j in 0..i {
            // Symmetry to round-off of the largest entry.
            if (m[(i, j)] - m[(j, i)]).abs() > 1e-12 * scale {
                return Err(MmeError::NotPositiveDefinite {
                    matrix: what,
                    reason: "not symmetric",
                });
            }
        }
    }
    if m.clone().cholesky().is_none() {
        return Err(MmeError::NotPositiveDefinite {
            matrix: what,
            reason: "Cholesky factorisation failed",
        });
    }
    Ok(())
}

/// Check given noise variances against the model's output names.
pub(crate) fn check_noise(values: &[f64], outputs: &[String]) -> Result<()> {
    if values.len() != outputs.len() {
        return Err(MmeError::Dimension {
            what: "noise variance",
            rows: values.len(),
            cols: 1,
            expected_rows: outputs.len(),
            expected_cols: 1,
        });
    }
    for (v, name) in values.iter().zip(outputs) {
        if !(v.is_finite() && *v > 0.0) {
            return Err(MmeError::NonPositiveVariance {
                channel: name.clone(),
                value: *v,
            });
        }
    }
    Ok(())
}

/// Check the iteration options.
pub(crate) fn check_iterations(it: &IterationOptions) -> Result<()> {
    if it.max_iterations == 0 {
        return Err(MmeError::InvalidSetting {
            name: "max_iterations",
            value: 0.0,
            reason: "need at least one iteration",
        });
    }
    positive_setting("cost_tolerance", it.cost_tolerance)?;
    positive_setting("cost_plateau", it.cost_plateau)?;
    if it.plateau_iterations == 0 {
        return Err(MmeError::InvalidSetting {
            name: "plateau_iterations",
            value: 0.0,
            reason: "need at least one iteration",
        });
    }
    positive_setting("blow_up", it.blow_up)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn iteration_option_errors_are_typed() {
        let ok = IterationOptions::default();
        assert!(check_iterations(&ok).is_ok());
        for (bad, name) in [
            (
                IterationOptions {
                    cost_plateau: 0.0,
                    ..ok
                },
                "cost_plateau",
            ),
            (
                IterationOptions {
                    cost_plateau: f64::NAN,
                    ..ok
                },
                "cost_plateau",
            ),
            (
                IterationOptions {
                    plateau_iterations: 0,
                    ..ok
                },
                "plateau_iterations",
            ),
        ] {
            match check_iterations(&bad) {
                Err(MmeError::InvalidSetting { name: n, .. }) => assert_eq!(n, name),
                other => panic!("{name}: {other:?}"),
            }
        }
    }

    #[test]
    fn weight_errors_are_typed() {
        let bad = DMatrix::from_row_slice(2, 2, &[1.0, 2.0, 2.0, 1.0]); // eigenvalues 3, −1
        assert!(matches!(
            resolve_weight(&WeightSpec::Matrix(bad), 2),
            Err(MmeError::NotPositiveDefinite { matrix: "W", .. })
        ));
        let asym = DMatrix::from_row_slice(2, 2, &[2.0, 0.5, 0.0, 2.0]);
        assert!(matches!(
            resolve_weight(&WeightSpec::Matrix(asym), 2),
            Err(MmeError::NotPositiveDefinite {
                reason: "not symmetric",
                ..
            })
        ));
        assert!(matches!(
            resolve_weight(&WeightSpec::Diagonal(vec![1.0]), 2),
            Err(MmeError::Dimension { what: "W", .. })
        ));
        assert!(matches!(
            resolve_weight(&WeightSpec::Scalar(-1.0), 1),
            Err(MmeError::InvalidSetting { name: "W", .. })
        ));
        let auto = AutoWeight {
            shape: WeightShape::Diagonal(vec![1.0, 0.0]),
            ..Default::default()
        };
        assert!(matches!(
            resolve_weight(&WeightSpec::Auto(auto), 2),
            Err(MmeError::NotPositiveDefinite {
                matrix: "W shape",
                ..
            })
        ));
    }

    #[test]
    fn prior_errors_are_typed_and_name_the_state() {
        let states = vec!["h1".to_string(), "h2".to_string()];
        assert_eq!(resolve_prior(&[], &states), Ok(None));
        let ok = resolve_prior(&[StatePrior::new("h2", 3.0, 0.5)], &states)
            .unwrap()
            .unwrap();
        assert_eq!(ok.info, vec![0.0, 4.0]);
        assert_eq!(ok.mean, vec![0.0, 3.0]);
        // The state without a prior costs nothing: (4 − 3)²·4.
        assert!((ok.cost(&[100.0, 4.0]) - 4.0).abs() < 1e-15);
        let field_of = |p: StatePrior| match resolve_prior(&[p], &states) {
            Err(MmeError::InvalidPrior { state, field, .. }) => (state, field),
            other => panic!("{other:?}"),
        };
        assert_eq!(
            field_of(StatePrior::new("h1", 1.0, -1.0)),
            ("h1".to_string(), "std")
        );
        assert_eq!(
            field_of(StatePrior::new("h1", 1.0, 0.0)),
            ("h1".to_string(), "std")
        );
        assert_eq!(
            field_of(StatePrior::new("h2", 1.0, f64::INFINITY)),
            ("h2".to_string(), "std")
        );
        assert_eq!(
            field_of(StatePrior::new("h2", f64::NAN, 1.0)),
            ("h2".to_string(), "mean")
        );
        assert!(matches!(
            resolve_prior(&[StatePrior::new("h3", 1.0, 1.0)], &states),
            Err(MmeError::UnknownState { ref name, .. }) if name == "h3"
        ));
        assert!(matches!(
            resolve_prior(
                &[StatePrior::new("h1", 1.0, 1.0), StatePrior::new("h1", 2.0, 1.0)],
                &states
            ),
            Err(MmeError::InvalidPrior { ref state, field: "state", .. }) if state == "h1"
        ));
    }

    #[test]
    fn noise_errors_name_the_channel() {
        let names = vec!["x".to_string(), "v".to_string()];
        assert!(matches!(
            check_noise(&[1.0, 0.0], &names),
            Err(MmeError::NonPositiveVariance { ref channel, .. }) if channel == "v"
        ));
        assert!(matches!(
            check_noise(&[1.0], &names),
            Err(MmeError::Dimension { .. })
        ));
        assert!(check_noise(&[1.0, 2.0], &names).is_ok());
    }
}
