//! The one validation rule of discovery: how a model is judged on a validation record —
//! by the workflow's acceptance check of a round ([`crate::workflow`]), by the
//! force-space discovery's check ([`crate::force`]) and by the report of `mmenn discover`.
//!
//! - **initial state**: fitted to the first `window` samples of the record
//!   (`sysid_core::judge_free_run` with [`InitialRule::Fit`]: Levenberg–Marquardt from the
//!   minimum-norm solution of `C x = y(t0)`); never to the whole record, which can tune
//!   the state onto a model's unstable manifold and hide a free run that diverges from any
//!   state the start of the record determines.
//! - **free run and scoring**: the whole record simulated from that state, every sample
//!   scored (fit %, RMSE per output); RK4 with 4 steps per sample, or with the steps a
//!   stiff model needs along the record (`stiff_aware`, `sysid_core::auto_rk4`).
//! - **cost** of a dataset: `(1/M) Σ r²/R` over every record's scored samples, the same
//!   residuals weighted by the noise variance per output (for one output a decreasing
//!   function of its fit %).
//! - **failure**: a free run that blows up or leaves finite values, or an initial-state
//!   fit whose every start fails, is an error naming the record
//!   ([`DiscoveryError::ValidationRun`]), never a number.

use sysid_core::judge::{InitialRule, JudgeOptions, Judgement, Observation};
use sysid_core::{CoreError, Dataset, Dynamics, Experiment, LinearModel};

use crate::error::{DiscoveryError, Result};

/// A model judged on every record of a validation dataset by the rule of this module.
#[derive(Debug, Clone)]
pub struct ValidationRun {
    /// One judgement per record, in order.
    pub records: Vec<Judgement>,
    /// `(1/M) Σ r²/R` over every scored sample of every record.
    pub cost: f64,
}

/// The rule's judgement of `model` (outputs those of `linear`) on one record: initial
/// state fitted to its first `window` samples, free run over the whole record, every
/// sample scored; with `stiff_aware` the RK4 steps come from `sysid_core::auto_rk4` (4
/// unless the model is stiff along the record), otherwise 4.
///
/// Errors: as `sysid_core::judge_free_run` (a fit whose every start fails, a free run
/// that diverges, a `window` of 0, channel rows that do not match).
pub fn judge_record<D: Dynamics + ?Sized>(
    model: &D,
    linear: &LinearModel,
    exp: &Experiment,
    window: usize,
    stiff_aware: bool,
) -> sysid_core::Result<Judgement> {
    let obs = Observation::outputs(linear);
    let mut opts = JudgeOptions::default();
    if stiff_aware {
        opts.integrator = sysid_core::auto_rk4(model, exp, &obs.matrix, 4, opts.blow_up)?;
    }
    sysid_core::judge_free_run(
        model,
        exp,
        &obs,
        &InitialRule::Fit {
            window: Some(window),
        },
        &opts,
    )
}

/// [`judge_record`] on every record of `data`, and the cost `(1/M) Σ r²/R` with the
/// noise variance `noise` per output.
///
/// Errors: `noise` of the wrong length or not positive and finite
/// ([`DiscoveryError::Length`], [`DiscoveryError::InvalidConfig`]); a record whose
/// judgement fails or whose simulated outputs are not finite
/// ([`DiscoveryError::ValidationRun`], naming the record).
pub fn validation_run<D: Dynamics + ?Sized>(
    model: &D,
    linear: &LinearModel,
    data: &Dataset,
    window: usize,
    noise: &[f64],
    stiff_aware: bool,
) -> Result<ValidationRun> {
    let names = linear.output_names();
    if noise.len() != names.len() {
        return Err(DiscoveryError::Length {
            what: "noise variances vs the model's outputs",
            found: noise.len(),
            expected: names.len(),
        });
    }
    if let Some(&r) = noise.iter().find(|r| !(r.is_finite() && **r > 0.0)) {
        return Err(DiscoveryError::InvalidConfig {
            field: "noise variance",
            value: r,
            reason: "must be positive and finite",
        });
    }
    let (mut sum, mut count) = (0.0, 0usize);
    let mut records = Vec::with_capacity(data.experiments().len());
    for (record, exp) in data.experiments().iter().enumerate() {
        let failed = |source| DiscoveryError::ValidationRun {
            record,
            window,
            source,
        };
        let judged = judge_record(model, linear, exp, window, stiff_aware).map_err(failed)?;
        if let Some(k) = (0..judged.outputs.ncols())
            .find(|&k| judged.outputs.column(k).iter().any(|v| !v.is_finite()))
        {
            return Err(failed(CoreError::InvalidArgument {
                name: "simulated output",
                value: k as f64,
                reason: "is not finite at this sample",
            }));
        }
        for (name, r) in names.iter().zip(noise) {
            if let Some(m) = judged.channels.get(name) {
                sum += m.rmse * m.rmse / r * m.samples as f64;
                count += m.samples;
            }
        }
        records.push(judged);
    }
    Ok(ValidationRun {
        records,
        cost: sum / count.max(1) as f64,
    })
}

impl ValidationRun {
    /// Fit % of every output on every record, as `output: fit %` (`record k, output:
    /// fit %` when there are several records), joined by `, `.
    pub fn fit_summary(&self) -> String {
        let several = self.records.len() > 1;
        let mut parts = Vec::new();
        for (k, j) in self.records.iter().enumerate() {
            for (name, m) in &j.channels {
                parts.push(if several {
                    format!("record {k}, {name}: {:.2} %", m.fit_percent)
                } else {
                    format!("{name}: {:.2} %", m.fit_percent)
                });
            }
        }
        parts.join(", ")
    }
}
