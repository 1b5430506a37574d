//! A discrete-time linear state-space baseline for single-input single-output records:
//! subspace initialisation ([`crate::subspace`], PO-MOESP), then free-run output-error
//! refinement, with the order chosen on held-out data.
//!
//! **Model.** `v_k = u_k − u_off`, `y_k = y_off + d·v_k + Σ_j y_j,k`, where each section
//! `j` is a second-order block in observer form,
//! `x⁺ = [[−a1, 1], [−a2, 0]] x + [b1, b2]ᵀ v`, `y_j = x₁` (transfer function
//! `(b1 z + b2)/(z² + a1 z + a2)`, real or complex poles alike), or one first-order block
//! `x⁺ = λ x + b v`. This parallel form is the realisation of the transfer function by
//! partial fractions; unlike a full `(A, B, C, D)` it has no similarity freedom, so the
//! least-squares problem is identifiable (`2n + 1` parameters for order `n`, plus the
//! input offset).
//!
//! **Criterion.** The benchmark's own: the initial state is the least-squares fit to the
//! first `window` measured outputs under the model (a function of the parameters), and
//! the error is summed over the samples after that window. Fitting `x0` freely over the
//! whole record instead lets an almost-integrating model hide an input bias in its initial
//! velocity; judged with a window-estimated `x0`, such a model drifts (EMPS).
//!
//! **Steps** of [`fit_linear_ss`]: `y_off`, `u_off` = means of the record; for each order
//! `n ≤ max_order`, MOESP on the first `1 − validation_fraction` of the record, the poles
//! of its `A` grouped into sections (complex pairs; real poles paired in increasing order;
//! one left over for odd `n`), the numerators, `d` and `x0` by linear least squares, then
//! the free-run refinement on that part and the free-run RMSE on the held-out rest (state
//! from its first `window` samples). The chosen order is the smallest whose held-out RMSE
//! is within `order_tolerance` of the best; its refined model is refined again on the
//! whole record. When that last refinement fails (a parameter not identifiable on the
//! whole record, a divergence), the fit keeps the chosen order's model from the held-out
//! stage (refined on the fitting part, scored on the held-out rest) and says why in
//! [`LinearSsFit::final_refinement_failure`].

use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};
use sysid_core::{Dataset, SolveReport};

use crate::error::{BaselineError, Result, check_config};
use crate::subspace::moesp;
use free_run::{refine, rmse_after};
use init::subspace_model;
pub use model::{LinearSsModel, Section};
use model::{Record, diverged};

mod free_run;
mod init;
mod model;

/// Settings of [`fit_linear_ss`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct LinearSsConfig {
    /// Largest order tried. Default 6.
    pub max_order: usize,
    /// A fixed order instead of the held-out choice. Default `None`.
    pub order: Option<usize>,
    /// MOESP block rows `s` (lowered to fit short records). Default 20.
    pub horizon: usize,
    /// State-initialisation window (samples), in fitting and simulation. Default 50.
    pub window: usize,
    /// Held-out tail of the record for the order choice, in (0, 0.5]. Default 0.25.
    pub validation_fraction: f64,
    /// The smallest order within this relative margin of the best held-out RMSE is
    /// chosen. Default 0.02.
    pub order_tolerance: f64,
    /// Fit an input bias on top of the record mean. Default true.
    pub fit_input_offset: bool,
    /// Levenberg–Marquardt iterations of each refinement. Default 300.
    pub max_iterations: u64,
    /// Hold one pole at `z = 1` (a known integrator: the subspace pole nearest 1 is moved
    /// there); orders then start at 2. Default false.
    pub integrator: bool,
}

impl Default for LinearSsConfig {
    fn default() -> Self {
        Self {
            max_order: 6,
            order: None,
            horizon: 20,
            window: 50,
            validation_fraction: 0.25,
            order_tolerance: 0.02,
            fit_input_offset: true,
            max_iterations: 300,
            integrator: false,
        }
    }
}

impl LinearSsConfig {
    /// Check every field.
    pub fn validate(&self) -> Result<()> {
        check_config(
            "max_order",
            self.max_order as f64,
            "must be ≥ 1",
            self.max_order >= 1,
        )?;
        if let Some(n) = self.order {
            check_config("order", n as f64, "must be ≥ 1", n >= 1)?;
        }
        check_config(
            "horizon",
            self.horizon as f64,
            "must be ≥ 2",
            self.horizon >= 2,
        )?;
        check_config(
            "window",
            self.window as f64,
            "must be ≥ 1",
            self.window >= 1,
        )?;
        check_config(
            "validation_fraction",
            self.validation_fraction,
            "must be in (0, 0.5]",
            self.validation_fraction > 0.0 && self.validation_fraction <= 0.5,
        )?;
        check_config(
            "order_tolerance",
            self.order_tolerance,
            "must be finite and ≥ 0",
            self.order_tolerance.is_finite() && self.order_tolerance >= 0.0,
        )?;
        check_config(
            "max_iterations",
            self.max_iterations as f64,
            "must be ≥ 1",
            self.max_iterations >= 1,
        )
    }
}

/// One order tried in the held-out choice.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct OrderCandidate {
    /// Model order `n`.
    pub order: usize,
    /// Held-out free-run RMSE of the subspace model (before refinement); `None` if it
    /// diverged or failed.
    pub subspace_rmse: Option<f64>,
    /// Held-out free-run RMSE after refinement on the fitting part.
    pub refined_rmse: Option<f64>,
    /// Why the order failed, if it did.
    pub failure: Option<String>,
}

/// Result of [`fit_linear_ss`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LinearSsFit {
    /// The chosen order's model refined on the whole record; when that refinement failed
    /// ([`LinearSsFit::final_refinement_failure`]), its model from the held-out stage
    /// (refined on the fitting part, the one the held-out RMSE scored).
    pub model: LinearSsModel,
    /// The subspace model of the chosen order on the whole record, before refinement
    /// (its `x0` fitted from its window like the refined one).
    pub subspace: LinearSsModel,
    /// Chosen order.
    pub order: usize,
    /// MOESP singular values on the fitting part (normalised by the largest).
    pub singular_values: Vec<f64>,
    /// Every order tried.
    pub candidates: Vec<OrderCandidate>,
    /// Free-run RMSE of `model` on the whole record after its window.
    pub training_rmse: f64,
    /// The solver report of `model`'s refinement: on the whole record, or on the fitting
    /// part when the whole-record refinement failed.
    pub report: SolveReport,
    /// Why the refinement of the chosen order on the whole record failed, when it did
    /// (`model` is then the held-out stage's); `None` when it succeeded.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub final_refinement_failure: Option<String>,
}

/// Fit the linear state-space baseline to the first experiment of `data` (one input, one
/// output; missing samples are not allowed). See the module documentation for the steps.
///
/// A failure of the last step, the chosen order's refinement on the whole record, is no
/// error: the held-out stage's model of that order is returned, the failure recorded in
/// [`LinearSsFit::final_refinement_failure`].
///
/// Errors: invalid config, not SISO, more than one experiment, missing samples, a record
/// too short for the horizon and window, every order failing, or the model returned
/// diverging on the whole record.
pub fn fit_linear_ss(data: &Dataset, config: &LinearSsConfig) -> Result<LinearSsFit> {
    config.validate()?;
    if data.experiments().len() != 1 {
        return Err(BaselineError::Dimension {
            what: "experiments (the linear state-space baseline fits one record)",
            found: data.experiments().len(),
            expected: 1,
        });
    }
    let exp = &data.experiments()[0];
    let output = data.output_names().first().cloned().unwrap_or_default();
    let probe = LinearSsModel {
        sections: Vec::new(),
        d: 0.0,
        input_offset: 0.0,
        output_offset: 0.0,
        window: config.window,
        output: output.clone(),
    };
    let (u, y) = probe.signals(exp)?;
    if let Some(k) = y.iter().position(|v| !v.is_finite()) {
        return Err(BaselineError::NoInitialWindow {
            experiment: 0,
            window: k,
        });
    }
    let len = u.len();
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    let base = LinearSsModel {
        input_offset: mean(&u),
        output_offset: mean(&y),
        ..probe
    };
    let split = ((1.0 - config.validation_fraction) * len as f64).round() as usize;
    let (fit_part, held) = (
        Record {
            u: &u[..split],
            y: &y[..split],
        },
        Record {
            u: &u[split..],
            y: &y[split..],
        },
    );
    if held.u.len() <= config.window + 1 {
        return Err(BaselineError::TooFewRows {
            what: "held-out samples after the initialisation window",
            found: held.u.len(),
            needed: config.window + 2,
        });
    }
    // The horizon is lowered until the Hankel matrix has at least twice as many columns
    // (N − 2s + 1) as rows (4s for one input and one output).
    let mut s = config.horizon;
    while s > 2 && split + 1 < 2 * s + 2 * (4 * s) {
        s -= 1;
    }
    let centred = |v: &[f64], c: f64| DMatrix::from_fn(1, v.len(), |_, k| v[k] - c);
    let mo = moesp(
        &centred(fit_part.u, base.input_offset),
        &centred(fit_part.y, base.output_offset),
        s,
    )?;
    let sv0 = mo.singular_values().first().copied().unwrap_or(1.0);
    let singular_values = mo.singular_values().iter().map(|v| v / sv0).collect();
    let orders: Vec<usize> = match config.order {
        Some(n) => vec![n],
        None => {
            let low = if config.integrator { 2 } else { 1 };
            (low..=config.max_order.min(mo.max_order())).collect()
        }
    };
    let mut candidates = Vec::new();
    // Each order's model refined on the fitting part, with its solver report.
    let mut refined: Vec<Option<(LinearSsModel, SolveReport)>> = Vec::new();
    for &n in &orders {
        let attempt = subspace_model(
            &mo,
            n,
            &base,
            &fit_part,
            config.fit_input_offset,
            config.integrator,
        )
        .and_then(|m0| {
            let sub = rmse_after(&m0, &held);
            Ok((sub, refine(&m0, &fit_part, config, base.input_offset)?))
        });
        match attempt {
            Ok((sub, (m1, report))) => {
                candidates.push(OrderCandidate {
                    order: n,
                    subspace_rmse: sub,
                    refined_rmse: rmse_after(&m1, &held),
                    failure: None,
                });
                refined.push(Some((m1, report)));
            }
            Err(e) => {
                candidates.push(OrderCandidate {
                    order: n,
                    subspace_rmse: None,
                    refined_rmse: None,
                    failure: Some(e.to_string()),
                });
                refined.push(None);
            }
        }
    }
    let best = candidates
        .iter()
        .filter_map(|c| c.refined_rmse)
        .fold(f64::INFINITY, f64::min);
    let chosen = candidates
        .iter()
        .position(|c| {
            c.refined_rmse
                .is_some_and(|r| r <= best * (1.0 + config.order_tolerance))
        })
        .ok_or_else(|| BaselineError::Diverged {
            sample: split,
            channel: format!(
                "held-out record: every order failed ({})",
                candidates
                    .iter()
                    .map(|c| format!(
                        "n = {}: {}",
                        c.order,
                        c.failure.clone().unwrap_or_else(|| "diverged".into())
                    ))
                    .collect::<Vec<_>>()
                    .join("; ")
            ),
            value: f64::NAN,
        })?;
    let order = candidates[chosen].order;
    let (start, start_report) = refined[chosen].clone().ok_or_else(|| diverged(split))?;
    let whole = Record { u: &u, y: &y };
    // The whole-record refinement, or why it failed (an error, or a refined model whose
    // free run diverges on the record).
    let refined_whole = refine(&start, &whole, config, base.input_offset)
        .map_err(|e| e.to_string())
        .and_then(|(m, report)| match rmse_after(&m, &whole) {
            Some(rmse) => Ok((m, report, rmse)),
            None => Err(diverged(0).to_string()),
        });
    let (model, report, training_rmse, final_refinement_failure) = match refined_whole {
        Ok((m, report, rmse)) => (m, report, rmse, None),
        Err(why) => {
            let rmse = rmse_after(&start, &whole).ok_or_else(|| BaselineError::Diverged {
                sample: 0,
                channel: format!(
                    "linear state-space output of the held-out stage's model on the whole \
                     record (kept because the whole-record refinement failed: {why})"
                ),
                value: f64::INFINITY,
            })?;
            (start, start_report, rmse, Some(why))
        }
    };
    // The subspace-only model of the chosen order on the whole record.
    let mo_all = moesp(
        &centred(&u, base.input_offset),
        &centred(&y, base.output_offset),
        s,
    )?;
    let subspace = subspace_model(
        &mo_all,
        order,
        &base,
        &whole,
        config.fit_input_offset,
        config.integrator,
    )?;
    Ok(LinearSsFit {
        model,
        subspace,
        order,
        singular_values,
        candidates,
        training_rmse,
        report,
        final_refinement_failure,
    })
}
