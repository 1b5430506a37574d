//! What judges the free-run search of a round: validation records with fitted initial
//! states, or the held-out end of every estimation record, and the recalibration of the
//! chosen terms on the whole estimation records afterwards.

use sysid_core::{Channel, Dataset, Experiment, InitialStateFit, TermModel, fit_initial_state};

use crate::error::Result;
use crate::refine::{RefineConfig, Refinement};
use crate::{CalibrationConfig, OutputWeights, calibrate};

/// Initial states of every record, fitted to its first `window` samples with `model`.
pub(super) fn holdout_initial_states(
    model: &TermModel,
    data: &Dataset,
    guess: &[f64],
    window: usize,
) -> Result<Vec<Vec<f64>>> {
    let fit = InitialStateFit {
        window,
        ..InitialStateFit::default()
    };
    data.experiments()
        .iter()
        .map(|exp| {
            Ok(fit_initial_state(
                model,
                model.linear().c(),
                exp,
                guess,
                &fit,
            )?)
        })
        .collect()
}

/// Calibrate the kept terms of `refined` on `data` (all estimation records), replacing
/// its model, coefficients' standard errors and initial states; unchanged when that
/// calibration fails.
pub(super) fn recalibrate_on(
    mut refined: Refinement,
    base: &TermModel,
    data: &Dataset,
    x0: &[Vec<f64>],
    noise: &[f64],
) -> Refinement {
    let first_new = base.terms().len();
    let end = refined.model.terms().len();
    let config = CalibrationConfig {
        terms: Some((first_new..end).collect()),
        weights: OutputWeights::NoiseVariance(noise.to_vec()),
        ..RefineConfig::default().calibration
    };
    if let Ok(fit) = calibrate(&refined.model, data, x0, &config)
        && fit.cost_after.is_finite()
    {
        refined.coefficient_std = fit.coefficient_std[first_new..end]
            .iter()
            .zip(&refined.parameter_variance)
            .map(|(sd, v)| (sd * sd + v).sqrt())
            .collect();
        refined.model = fit.model;
        refined.x0 = fit.x0;
    }
    refined
}

/// Estimation records cut in two for the free-run search: the first part calibrates, the
/// last `fraction` judges.
pub(super) struct Split {
    pub(super) cal: Dataset,
    pub(super) cal_x0: Vec<Vec<f64>>,
    pub(super) hold: Dataset,
    pub(super) hold_x0: Vec<Vec<f64>>,
}

/// Cut every record at `1 − fraction` of its length; initial states of both parts from
/// MME's `x̂`. `None` when `fraction` is 0 or a part would be shorter than 50 samples.
pub(super) fn split_records(
    data: &Dataset,
    est: &sysid_core::MmeEstimate,
    fraction: f64,
) -> Result<Option<Split>> {
    if !(fraction > 0.0 && fraction < 1.0) {
        return Ok(None);
    }
    const MIN_PART: usize = 50;
    let (mut cal, mut hold) = (Vec::new(), Vec::new());
    let (mut cal_x0, mut hold_x0) = (Vec::new(), Vec::new());
    for (exp, e) in data.experiments().iter().zip(&est.experiments) {
        let n = exp.len();
        let k = ((n as f64) * (1.0 - fraction)).round() as usize;
        if k < MIN_PART || n.saturating_sub(k) < MIN_PART || e.states.ncols() < n {
            return Ok(None);
        }
        let part = |from: usize, len: usize| {
            Experiment::new(
                exp.t0() + from as f64 * exp.dt(),
                exp.dt(),
                exp.inputs().columns(from, len).into_owned(),
                exp.outputs().columns(from, len).into_owned(),
            )
            .map(|part| part.with_intersample(exp.intersample()))
        };
        cal.push(part(0, k)?);
        hold.push(part(k, n - k)?);
        cal_x0.push(e.states.column(0).iter().copied().collect());
        hold_x0.push(e.states.column(k).iter().copied().collect());
    }
    let names = |v: Vec<String>| v.into_iter().map(Channel::new).collect::<Vec<_>>();
    let dataset = |exps| Dataset::new(names(data.input_names()), names(data.output_names()), exps);
    Ok(Some(Split {
        cal: dataset(cal)?,
        cal_x0,
        hold: dataset(hold)?,
        hold_x0,
    }))
}
