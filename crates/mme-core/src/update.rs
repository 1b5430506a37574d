//! Regression update of the assumed linear model from MME's output (thesis §2.6 and
//! §4.3.3 "Updated Model"): regress each correction component `d̂_a` on `[x̂, u]` by least
//! squares and fold the coefficients into the corrected rows, `A' = A + EΘ_x`,
//! `B' = B + EΘ_u`.
//!
//! **Uncertainty.** The naive OLS standard error `σ̂·√((XᵀX)⁻¹)_ii` assumes independent
//! rows. `d̂` is a smoothed signal, so the regression residuals are strongly
//! autocorrelated and the naive `σ` is optimistic (often by an order of magnitude). Each
//! coefficient therefore also carries `σ_eff = σ·√((1+ρ)/(1−ρ))`, with `ρ` the lag-1
//! autocorrelation of the residuals (the variance inflation of a mean under AR(1) errors;
//! equivalently an effective sample size `N(1−ρ)/(1+ρ)`; e.g. Bence 1995, *Ecology*
//! 76:628–639). Use `σ_eff` for intervals.

use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};
use sysid_core::{Dataset, InterSample, LinearModel, MmeEstimate};

use crate::binding::bind;
use crate::error::{MmeError, Result};

/// Which points enter the regression.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RegressionPoints {
    /// Every correction piece against the state at the piece's midpoint (linear
    /// interpolation between samples) and the input there (held, or interpolated for
    /// records with [`sysid_core::InterSample::Foh`]): no half-piece lag.
    #[default]
    PieceMidpoints,
    /// The piece starting at each sample (all but the last) against `x̂` and `u` there.
    Samples,
}

/// Whether to fit a constant term.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Intercept {
    /// No constant (the updated model stays `A x + B u`).
    #[default]
    None,
    /// Fit a constant per correction; it is reported but cannot enter `A` or `B`.
    Fit,
}

/// Settings of the model update.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct UpdateConfig {
    /// Regression points (default piece midpoints).
    pub points: RegressionPoints,
    /// Constant term (default none).
    pub intercept: Intercept,
}

/// One regression coefficient with its standard errors.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Coefficient {
    /// Regressor name (a state, an input, or `1` for the intercept).
    pub regressor: String,
    /// Estimate.
    pub value: f64,
    /// Naive OLS standard error (independent rows assumed; optimistic for `d̂`).
    pub sigma: f64,
    /// Standard error inflated for the residuals' lag-1 autocorrelation.
    pub sigma_effective: f64,
}

/// The regression of one correction component.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CorrectionRegression {
    /// Correction name.
    pub correction: String,
    /// Coefficients on the states, then the inputs (then the intercept, if fitted).
    pub coefficients: Vec<Coefficient>,
    /// Residual variance `RSS/(rows − regressors)`.
    pub residual_variance: f64,
    /// `1 − RSS/SST` of the fit.
    pub r2: f64,
    /// Lag-1 autocorrelation of the residuals (within experiments).
    pub lag1_autocorrelation: f64,
    /// Rows used.
    pub rows: usize,
    /// Effective number of independent rows `rows·(1−ρ)/(1+ρ)`.
    pub effective_rows: f64,
}

/// The updated model and the regressions behind it.
#[derive(Debug, Clone, PartialEq)]
pub struct ModelUpdate {
    /// `A + EΘ_x`, `B + EΘ_u`, same `C`, `E` and names.
    pub model: LinearModel,
    /// `Θ_x`, `q × n`.
    pub theta_x: DMatrix<f64>,
    /// `Θ_u`, `q × m`.
    pub theta_u: DMatrix<f64>,
    /// One regression per correction.
    pub regressions: Vec<CorrectionRegression>,
}

/// Regress `d̂` on `[x̂, u]` and update the corrected rows of `A` and `B`.
///
/// `estimate` must come from `model` on `data` (same experiments; channels matched by
/// name).
pub fn update_model(
    model: &LinearModel,
    data: &Dataset,
    estimate: &MmeEstimate,
    config: &UpdateConfig,
) -> Result<ModelUpdate> {
    let binding = bind(model.input_names(), model.output_names(), data)?;
    let (n, m, q) = (model.n_states(), model.n_inputs(), model.n_corrections());
    if estimate.experiments.len() != data.experiments().len() {
        return Err(MmeError::Dimension {
            what: "estimate experiments",
            rows: estimate.experiments.len(),
            cols: 1,
            expected_rows: data.experiments().len(),
            expected_cols: 1,
        });
    }
    let intercept = config.intercept == Intercept::Fit;
    let cols = n + m + usize::from(intercept);
    // Rows: (regressors, targets, experiment) in time order.
    let mut xrows: Vec<f64> = Vec::new();
    let mut targets: Vec<Vec<f64>> = vec![Vec::new(); q];
    let mut breaks: Vec<usize> = Vec::new();
    for (exp, est) in data.experiments().iter().zip(&estimate.experiments) {
        let s = est.substeps;
        if est.states.nrows() != n
            || est.states.ncols() != exp.len()
            || est.corrections.nrows() != q
        {
            return Err(MmeError::Dimension {
                what: "estimate states",
                rows: est.states.nrows(),
                cols: est.states.ncols(),
                expected_rows: n,
                expected_cols: exp.len(),
            });
        }
        breaks.push(targets[0].len());
        let pieces = est.corrections.ncols();
        for j in 0..pieces {
            let k = j / s;
            let frac = match config.points {
                RegressionPoints::PieceMidpoints => ((j % s) as f64 + 0.5) / s as f64,
                RegressionPoints::Samples => {
                    if j % s != 0 {
                        continue;
                    }
                    0.0
                }
            };
            for i in 0..n {
                let a = est.states[(i, k)];
                let b = est.states[(i, (k + 1).min(exp.len() - 1))];
                xrows.push(a + frac * (b - a));
            }
            for &row in &binding.inputs {
                let ua = exp.inputs()[(row, k)];
                xrows.push(match exp.intersample() {
                    InterSample::Zoh => ua,
                    InterSample::Foh | InterSample::Bl => {
                        let ub = exp.inputs()[(row, (k + 1).min(exp.len() - 1))];
                        ua + frac * (ub - ua)
                    }
                });
            }
            if intercept {
                xrows.push(1.0);
            }
            for (a, t) in targets.iter_mut().enumerate() {
                t.push(est.corrections[(a, j)]);
            }
        }
    }
    let rows = targets[0].len();
    let names: Vec<String> = model
        .state_names()
        .iter()
        .chain(model.input_names())
        .cloned()
        .chain(intercept.then(|| "1".to_string()))
        .collect();
    let x = DMatrix::from_row_slice(rows, cols, &xrows);
    let mut theta_x = DMatrix::zeros(q, n);
    let mut theta_u = DMatrix::zeros(q, m);
    let mut regressions = Vec::with_capacity(q);
    for (a, t) in targets.iter().enumerate() {
        let name = model.correction_names()[a].clone();
        let singular = || MmeError::SingularRegression {
            correction: name.clone(),
            rows,
            columns: cols,
        };
        if rows <= cols {
            return Err(singular());
        }
        let y = DVector::from_column_slice(t);
        let qr = x.clone().qr();
        let r = qr.r();
        let rmax = r.diagonal().amax();
        if !r.diagonal().iter().all(|v| v.abs() > 1e-10 * rmax) {
            return Err(singular());
        }
        let qty = qr.q().transpose() * &y;
        let beta = r.solve_upper_triangular(&qty).ok_or_else(singular)?;
        let resid = &y - &x * &beta;
        let rss = resid.norm_squared();
        let dof = (rows - cols) as f64;
        let var = rss / dof;
        let mean = y.mean();
        let sst: f64 = y.iter().map(|v| (v - mean).powi(2)).sum();
        // (XᵀX)⁻¹ = R⁻¹R⁻ᵀ; its diagonal is the row norms² of R⁻¹.
        let rinv = r.clone().try_inverse().ok_or_else(singular)?;
        let rho = lag1(resid.as_slice(), &breaks).clamp(0.0, 0.999);
        let inflation = ((1.0 + rho) / (1.0 - rho)).sqrt();
        let coefficients = (0..cols)
            .map(|c| {
                let sigma = (var * rinv.row(c).norm_squared()).sqrt();
                Coefficient {
                    regressor: names[c].clone(),
                    value: beta[c],
                    sigma,
                    sigma_effective: sigma * inflation,
                }
            })
            .collect();
        for c in 0..n {
            theta_x[(a, c)] = beta[c];
        }
        for c in 0..m {
            theta_u[(a, c)] = beta[n + c];
        }
        regressions.push(CorrectionRegression {
            correction: name,
            coefficients,
            residual_variance: var,
            r2: if sst > 0.0 { 1.0 - rss / sst } else { f64::NAN },
            lag1_autocorrelation: rho,
            rows,
            effective_rows: rows as f64 * (1.0 - rho) / (1.0 + rho),
        });
    }
    let a_new = model.a() + model.e() * &theta_x;
    let b_new = model.b() + model.e() * &theta_u;
    let updated = model.with_ab(a_new, b_new)?;
    Ok(ModelUpdate {
        model: updated,
        theta_x,
        theta_u,
        regressions,
    })
}

/// Lag-1 autocorrelation of `r`, not pairing rows across experiment boundaries.
fn lag1(r: &[f64], breaks: &[usize]) -> f64 {
    let mean = r.iter().sum::<f64>() / r.len() as f64;
    let den: f64 = r.iter().map(|v| (v - mean).powi(2)).sum();
    let mut num = 0.0;
    for k in 1..r.len() {
        if breaks.contains(&k) {
            continue;
        }
        num += (r[k] - mean) * (r[k - 1] - mean);
    }
    if den > 0.0 { num / den } else { 0.0 }
}
