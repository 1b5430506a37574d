//! Output-error fitting of a continuous-time linear model (thesis §5.1): chosen free
//! entries of `A(θ)` and `B(θ)`, started from a physics model, fitted by minimising the
//! free-run simulation error over every experiment (each simulated exactly for its inputs
//! between samples, held or linear), with ±1σ from the Jacobian and a stability check.

use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};
use sysid_core::{Dataset, LinearModel, Scaling, SolveReport};

use crate::discrete::SampleStep;
use crate::error::{BaselineError, Result, check_config};
use crate::free_params::{FreeParameter, parse_free_parameters};
use crate::lsq::{self, LeastSquares, Linearised, Settings, check_rank};
use crate::oe_model::{OeModel, state_from_window};
use crate::oe_sim::{OeProblem, X0Layout};

/// How the initial state of each experiment is treated while fitting.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum InitialStateTreatment {
    /// Estimated jointly with the model (`n` extra parameters per experiment), started
    /// from a least-squares estimate on the first samples under the initial model.
    #[default]
    Estimate,
    /// Zero for every experiment.
    Zero,
    /// Known, one state vector (`n` values) per experiment.
    Given(Vec<Vec<f64>>),
}

/// Settings of [`fit_oe`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct OeConfig {
    /// Free entries, named `"A[i,j]"` / `"B[i,j]"` (0-based). Default: none (then only
    /// initial states are fitted, if estimated).
    pub free: Vec<String>,
    /// Initial states. Default [`InitialStateTreatment::Estimate`].
    pub initial_state: InitialStateTreatment,
    /// Iteration budget of the trust-region solver. Default 200.
    pub max_iterations: u64,
    /// Stop when every scaled-gradient component is at most this times `‖r‖` (cosine of
    /// the angle between the residual and each Jacobian column, MINPACK's `gtol`).
    /// Default 1e-10.
    pub gradient_tolerance: f64,
    /// Stop when an accepted step reduces the cost by at most this, relative.
    /// Default 1e-14 (only round-off is left).
    pub cost_tolerance: f64,
}

impl Default for OeConfig {
    fn default() -> Self {
        Self {
            free: Vec::new(),
            initial_state: InitialStateTreatment::Estimate,
            max_iterations: 200,
            gradient_tolerance: 1e-10,
            cost_tolerance: 1e-14,
        }
    }
}

impl OeConfig {
    /// Check the numeric fields.
    pub fn validate(&self) -> Result<()> {
        check_config(
            "max_iterations",
            self.max_iterations as f64,
            "must be at least 1",
            self.max_iterations >= 1,
        )?;
        check_config(
            "gradient_tolerance",
            self.gradient_tolerance,
            "must be finite and > 0",
            self.gradient_tolerance.is_finite() && self.gradient_tolerance > 0.0,
        )?;
        check_config(
            "cost_tolerance",
            self.cost_tolerance,
            "must be finite and ≥ 0",
            self.cost_tolerance.is_finite() && self.cost_tolerance >= 0.0,
        )
    }
}

/// One estimated parameter with its ±1σ.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ParameterEstimate {
    /// `A[i,j]`, `B[i,j]`, or `x0[e][state]` for an initial state.
    pub name: String,
    /// Starting value.
    pub initial: f64,
    /// Estimate.
    pub value: f64,
    /// Standard deviation from `σ²(JᵀJ)⁻¹`.
    pub std: f64,
}

/// Whether the fitted `A` is stable.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum StabilityVerdict {
    /// Every eigenvalue has a negative real part.
    Stable,
    /// The largest real part is zero within round-off (integrator, undamped mode).
    Marginal,
    /// Some eigenvalue has a positive real part.
    Unstable,
}

/// Eigenvalues of the fitted `A` and the verdict.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Stability {
    /// Eigenvalues as `(real, imaginary)`.
    pub eigenvalues: Vec<(f64, f64)>,
    /// Verdict on the largest real part; "zero" means within `1e-9·max(1, ‖A‖)`.
    pub verdict: StabilityVerdict,
}

impl Stability {
    /// Eigenvalues and verdict of a state matrix.
    pub fn of(a: &DMatrix<f64>) -> Self {
        let eig = a.complex_eigenvalues();
        let eigenvalues: Vec<(f64, f64)> = eig.iter().map(|z| (z.re, z.im)).collect();
        let tol = 1e-9 * a.norm().max(1.0);
        let max_re = eigenvalues
            .iter()
            .map(|e| e.0)
            .fold(f64::NEG_INFINITY, f64::max);
        let verdict = if max_re > tol {
            StabilityVerdict::Unstable
        } else if max_re >= -tol {
            StabilityVerdict::Marginal
        } else {
            StabilityVerdict::Stable
        };
        Self {
            eigenvalues,
            verdict,
        }
    }
}

/// Result of [`fit_oe`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct OeFit {
    /// The fitted model, set to estimate its initial state from data
    /// ([`crate::X0Policy::FromData`]) when simulated on new experiments.
    pub model: OeModel,
    /// The free entries of `A` and `B`, in the order given.
    pub parameters: Vec<ParameterEstimate>,
    /// Initial state per experiment (estimated ones carry a σ, fixed ones σ = 0).
    pub initial_states: Vec<Vec<ParameterEstimate>>,
    /// Covariance of every estimated parameter (free entries, then initial states), in
    /// the order of `parameters` followed by `initial_states`.
    pub covariance: DMatrix<f64>,
    /// Sum of squared output errors at the optimum.
    pub sse: f64,
    /// `σ² = SSE/(N − p)`, pooled over every output channel.
    pub residual_variance: f64,
    /// Number of measured output samples `N` used.
    pub samples: usize,
    /// Stability of the fitted `A`.
    pub stability: Stability,
    /// How the solver ended, with its iteration history (cost = ½·SSE).
    pub report: SolveReport,
}

impl LeastSquares for OeProblem<'_> {
    fn residuals(&self, theta: &[f64], jacobian: bool) -> Result<Option<Linearised>> {
        Ok(self
            .evaluate(theta, jacobian)?
            .map(|e| (e.residuals, e.jacobian)))
    }
}

/// Check that the data's channels are the model's, in order.
pub(crate) fn check_channels(data: &Dataset, inputs: &[String], outputs: &[String]) -> Result<()> {
    for (kind, found, expected) in [
        ("input", data.input_names(), inputs),
        ("output", data.output_names(), outputs),
    ] {
        if found.len() != expected.len() {
            return Err(BaselineError::Dimension {
                what: if kind == "input" {
                    "input channels of the data vs the model"
                } else {
                    "output channels of the data vs the model"
                },
                found: found.len(),
                expected: expected.len(),
            });
        }
        for (position, (f, e)) in found.iter().zip(expected).enumerate() {
            if f != e {
                return Err(BaselineError::ChannelMismatch {
                    kind,
                    position,
                    found: f.clone(),
                    expected: e.clone(),
                });
            }
        }
    }
    Ok(())
}

/// Fit the free entries of `A` and `B` (and the initial states) of `initial` to the data
/// by minimising `Σ_experiments Σ_k Σ_channels (ŷ − y)²` over measured samples, where `ŷ`
/// is the exact free-run simulation for each experiment's
/// [`intersample`](sysid_core::Experiment::intersample): zero-order hold for held inputs,
/// first-order hold (`x⁺ = Ad x + Bd u_k + Γ₂ (u_{k+1} − u_k)`) for inputs linear between
/// samples, so a fit to `foh` records is the exact `foh` model.
///
/// The data's input and output channels must be the model's (names, in order). Errors:
/// invalid config, bad or duplicate free-parameter names, channel mismatch, a given
/// initial state of the wrong size, fewer measured samples than parameters, a parameter
/// the data cannot identify, a diverging initial model. Not converging within the budget
/// is reported in [`OeFit::report`].
pub fn fit_oe(initial: &LinearModel, data: &Dataset, config: &OeConfig) -> Result<OeFit> {
    config.validate()?;
    let free = parse_free_parameters(&config.free, initial)?;
    check_channels(data, initial.input_names(), initial.output_names())?;
    let experiments = data.experiments();
    if experiments.is_empty() {
        return Err(BaselineError::TooFewRows {
            what: "experiments",
            found: 0,
            needed: 1,
        });
    }
    let n = initial.n_states();
    let layout = match &config.initial_state {
        InitialStateTreatment::Estimate => X0Layout::Estimated,
        InitialStateTreatment::Zero => X0Layout::Fixed(vec![DVector::zeros(n); experiments.len()]),
        InitialStateTreatment::Given(x0s) => {
            if x0s.len() != experiments.len() {
                return Err(BaselineError::Dimension {
                    what: "given initial states vs experiments",
                    found: x0s.len(),
                    expected: experiments.len(),
                });
            }
            if let Some(bad) = x0s.iter().find(|x| x.len() != n) {
                return Err(BaselineError::Dimension {
                    what: "given initial state vs model states",
                    found: bad.len(),
                    expected: n,
                });
            }
            X0Layout::Fixed(x0s.iter().map(|x| DVector::from_column_slice(x)).collect())
        }
    };
    let problem = OeProblem {
        base: initial,
        free: &free,
        experiments,
        x0: layout,
    };
    let n_par = problem.n_params();
    let n_res = problem.n_residuals();
    if n_par == 0 {
        return Err(BaselineError::InvalidConfig {
            field: "free",
            value: 0.0,
            reason: "nothing to estimate: no free entries and initial states not estimated",
        });
    }
    if n_res <= n_par {
        return Err(BaselineError::TooFewRows {
            what: "measured output samples for the output-error fit",
            found: n_res,
            needed: n_par + 1,
        });
    }

    let names = parameter_names(&free, &problem, experiments.len(), n);
    let theta0 = initial_parameters(initial, &free, &problem, data)?;
    let data_norm = experiments
        .iter()
        .flat_map(|e| e.outputs().iter())
        .filter(|v| !v.is_nan())
        .map(|v| v * v)
        .sum::<f64>()
        .sqrt();
    let settings = Settings {
        max_iterations: config.max_iterations,
        gtol: config.gradient_tolerance,
        ftol: config.cost_tolerance,
        // Round-off of a float simulation is ~1e-15 relative; 1e-13 leaves room for its
        // growth over long records.
        exact_rtol: 1e-13,
        data_norm,
        scaling: Scaling::Columns,
    };
    let outcome = lsq::minimise(&problem, &theta0, &names, "model", settings)?;

    let sse = outcome.residuals.norm_squared();
    let dof = (n_res - n_par) as f64;
    let sigma2 = sse / dof;
    let covariance = covariance(&outcome.jacobian, sigma2, &names)?;
    let estimate = |i: usize| ParameterEstimate {
        name: names[i].clone(),
        initial: theta0[i],
        value: outcome.theta[i],
        std: covariance[(i, i)].max(0.0).sqrt(),
    };
    let parameters: Vec<ParameterEstimate> = (0..free.len()).map(estimate).collect();
    let initial_states = (0..experiments.len())
        .map(|e| match &problem.x0 {
            X0Layout::Estimated => (0..n).map(|i| estimate(free.len() + e * n + i)).collect(),
            X0Layout::Fixed(x0s) => (0..n)
                .map(|i| ParameterEstimate {
                    name: format!("x0[{e}][{}]", initial.state_names()[i]),
                    initial: x0s[e][i],
                    value: x0s[e][i],
                    std: 0.0,
                })
                .collect(),
        })
        .collect();
    let (a, b) = problem.matrices(&outcome.theta);
    let fitted = initial.with_ab(a, b)?;
    let stability = Stability::of(fitted.a());
    Ok(OeFit {
        model: OeModel::new(fitted),
        parameters,
        initial_states,
        covariance,
        sse,
        residual_variance: sigma2,
        samples: n_res,
        stability,
        report: outcome.report,
    })
}

fn parameter_names(
    free: &[FreeParameter],
    problem: &OeProblem<'_>,
    experiments: usize,
    n: usize,
) -> Vec<String> {
    let mut names: Vec<String> = free.iter().map(|p| p.name.clone()).collect();
    if matches!(problem.x0, X0Layout::Estimated) {
        for e in 0..experiments {
            for i in 0..n {
                names.push(format!("x0[{e}][{}]", problem.base.state_names()[i]));
            }
        }
    }
    names
}

/// Free entries from the physics model; estimated initial states from a least-squares fit
/// to the first `10·n` samples under that model (zero if those do not determine it).
fn initial_parameters(
    initial: &LinearModel,
    free: &[FreeParameter],
    problem: &OeProblem<'_>,
    data: &Dataset,
) -> Result<Vec<f64>> {
    let mut theta: Vec<f64> = free.iter().map(|p| p.value_in(initial)).collect();
    if matches!(problem.x0, X0Layout::Estimated) {
        let n = initial.n_states();
        for exp in data.experiments() {
            let step = SampleStep::new(initial.a(), initial.b(), exp.dt(), exp.intersample())?;
            let window = (10 * n).min(exp.len());
            let x0 =
                state_from_window(initial, &step, exp, 0, window).unwrap_or_else(|_| vec![0.0; n]);
            theta.extend(x0);
        }
    }
    Ok(theta)
}

/// `σ²(JᵀJ)⁻¹`, computed on the column-scaled Jacobian for conditioning.
fn covariance(j: &DMatrix<f64>, sigma2: f64, names: &[String]) -> Result<DMatrix<f64>> {
    let scale: Vec<f64> = j.column_iter().map(|c| c.norm()).collect();
    if let Some(i) = scale.iter().position(|d| !(d.is_finite() && *d > 0.0)) {
        return Err(BaselineError::Unidentifiable {
            name: names.get(i).cloned().unwrap_or_default(),
            ratio: 0.0,
        });
    }
    check_rank(j, &scale, names)?;
    let mut js = j.clone();
    for (c, d) in scale.iter().enumerate() {
        js.column_mut(c).scale_mut(1.0 / d);
    }
    let info = js.tr_mul(&js);
    let inv =
        info.cholesky()
            .map(|ch| ch.inverse())
            .ok_or_else(|| BaselineError::Unidentifiable {
                name: names.first().cloned().unwrap_or_default(),
                ratio: 0.0,
            })?;
    let p = scale.len();
    Ok(DMatrix::from_fn(p, p, |r, c| {
        sigma2 * inv[(r, c)] / (scale[r] * scale[c])
    }))
}
