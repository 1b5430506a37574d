//! The judge of a discovered model: its free-run cost on the judging records, and the
//! reference distribution of that cost under the pipeline that produced it.
//!
//! A right model with the right noise variance scores a free-run cost `J = (1/M) Σ r²/R`
//! near 1, but not exactly: the pipeline estimates initial states (on records that may
//! be short and lightly damped), calibrates the new terms' coefficients on one part of
//! the data and judges them on another, and simulates with its own integrator. The
//! textbook bound `1 + 3√(2/M)` ignores all of that and denies right answers at low
//! noise, where these effects are a sizeable fraction of σ.
//!
//! [`judge`] therefore computes the statistic by a fixed *protocol* and its reference
//! distribution by a parametric bootstrap of the same protocol: the model under test is
//! simulated over every record's inputs by the adaptive Dormand–Prince integrator at tight
//! tolerance (not the pipeline's RK4, so that the integrator's error is part of the
//! reference), seeded Gaussian noise of the judging variance is added (missing samples
//! stay missing), and the protocol is rerun on each draw — re-estimating the initial
//! states, recalibrating the new terms on the calibration records and re-fitting the
//! initial states of the judging records. The draws run in parallel, each with its own
//! ChaCha8 stream, so the result does not depend on the thread count.
//!
//! The threshold is the `level` quantile of a scaled χ² matched to the draws' mean and
//! variance (Satterthwaite), which is smoother than an order statistic of ~24 draws and
//! keeps the right skew of a sum of squares.
//!
//! A second statistic looks at what remains rather than how much: the *structure* of the
//! judged free-run residual, a portmanteau (Ljung–Box) sum of its squared
//! autocorrelations at lags `1..=L` per channel and record. A stand-in that matches the
//! residual's size but not its shape (an effect outside the catalogue imitated by
//! catalogue terms) leaves it coloured. Its reference comes from the same draws — the
//! free-run residual of a right model is not white either (estimated initial states and
//! coefficients leave slow components), and the bootstrap carries that. A model is
//! accepted only when both statistics lie within their references (the structure at
//! the 0.999 quantile, see [`JudgeConfig::structure_level`]).

use nalgebra::DMatrix;
use rand::SeedableRng;
use rand::rngs::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use sysid_core::integrate::DEFAULT_BLOW_UP;
use sysid_core::{Dataset, DpOptions, Experiment, Integrator, TermModel, simulate_experiment};

use crate::augment::{CalibrationConfig, InitialState, OutputWeights, calibrate};
use crate::error::{DiscoveryError, Result};
use crate::stats::chi2_quantile;

/// The records and settings of one judging protocol.
#[derive(Debug, Clone, Copy)]
pub struct Protocol<'a> {
    /// The records the new terms are calibrated on.
    pub cal: &'a Dataset,
    /// Starting guesses of `cal`'s initial states (re-fitted).
    pub cal_x0: &'a [Vec<f64>],
    /// The records that judge (coefficients fixed, initial states re-fitted); `None`:
    /// `cal` judges itself.
    pub hold: Option<(&'a Dataset, &'a [Vec<f64>])>,
    /// Noise variance per output: the cost's weights, and the bootstrap's noise.
    pub noise_variance: &'a [f64],
    /// Calibration settings (integrator, horizons, tolerance); `terms`, `weights` and
    /// `initial_state` are set by the protocol.
    pub calibration: &'a CalibrationConfig,
}

/// Settings of [`judge`].
#[derive(Debug, Clone, PartialEq)]
pub struct JudgeConfig {
    /// Bootstrap draws (≥ 8). Default 24.
    pub draws: usize,
    /// Quantile of the reference distribution below which the statistic is accepted.
    /// Default 0.99.
    pub level: f64,
    /// Quantile of the structure statistic's reference below which it is accepted.
    /// Default 0.999: a check for residuals clearly coloured, not a second test at the
    /// cost's level (two tests at 0.99 would deny a right model twice as often, and the
    /// draws do not re-estimate a term's shaping parameters — a Coulomb law's transition
    /// velocity — whose estimation error leaves a little colour on the actual record:
    /// on the independent suite's servo with dry friction, ε fitted 0.0206 against 0.02
    /// gave Q at the reference's 0.997 quantile).
    pub structure_level: f64,
    /// Seed of the bootstrap noise.
    pub seed: u64,
    /// Integrator that simulates the bootstrap records. Default Dormand–Prince at
    /// rtol 1e-10, atol 1e-12.
    pub truth_integrator: Integrator,
}

impl Default for JudgeConfig {
    fn default() -> Self {
        Self {
            draws: 24,
            level: 0.99,
            structure_level: 0.999,
            seed: 17,
            truth_integrator: truth_integrator(),
        }
    }
}

/// The integrator that simulates bootstrap records (the judge's and the stand-in's):
/// Dormand–Prince at rtol 1e-10, atol 1e-12, not the pipeline's RK4, so that the
/// integrator's error is part of every reference.
pub(crate) fn truth_integrator() -> Integrator {
    Integrator::DormandPrince(DpOptions {
        rtol: 1e-10,
        atol: 1e-12,
        ..DpOptions::default()
    })
}

/// The judged free-run cost and its bootstrap reference distribution (named apart from
/// `sysid_core::Judgement`, the one free-run judge's scores of a model on a record).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BootstrapJudgement {
    /// Free-run cost of the model on the judging records, by the protocol.
    pub statistic: f64,
    /// The protocol's cost on every bootstrap draw that completed.
    pub reference: Vec<f64>,
    /// Draws asked for.
    pub draws: usize,
    /// Draws whose simulation or calibration failed (left out of `reference`).
    pub failed: usize,
    /// Mean of `reference`.
    pub mean: f64,
    /// Standard deviation of `reference`.
    pub sd: f64,
    /// The `level` quantile of the scaled χ² matched to `reference`.
    pub threshold: f64,
    /// The quantile level.
    pub level: f64,
    /// Upper-tail probability of `statistic` under the matched scaled χ².
    pub p_value: f64,
    /// The structure left in the judged free-run residual and its reference; `None`
    /// when too few draws gave one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub structure: Option<Structure>,
}

/// The residual-structure statistic (see the module documentation) and its reference.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Structure {
    /// Ljung–Box `Q = N(N+2) Σ_{l=1..L} ρ_l²/(N−l)` of the judged free-run residual,
    /// summed over channels and records.
    pub statistic: f64,
    /// Lags `L` per channel and record.
    pub lags: usize,
    /// `Q` on every bootstrap draw that completed.
    pub reference: Vec<f64>,
    /// The `level` quantile of the scaled χ² matched to `reference`.
    pub threshold: f64,
    /// The quantile level ([`JudgeConfig::structure_level`]).
    pub level: f64,
    /// Upper-tail probability of `statistic` under that scaled χ².
    pub p_value: f64,
}

impl BootstrapJudgement {
    /// Whether the statistic — and the residual's structure, when measured — lies
    /// within its reference distribution.
    pub fn accepts(&self) -> bool {
        self.statistic.is_finite()
            && self.statistic <= self.threshold
            && self
                .structure
                .as_ref()
                .is_none_or(|s| s.statistic.is_finite() && s.statistic <= s.threshold)
    }
}

/// Lags of the structure statistic: 20, fewer on records shorter than 200 samples.
fn structure_lags(len: usize) -> usize {
    (len / 10).clamp(1, 20)
}

/// Ljung–Box `Q` over lags `1..=L` of every output channel of every record: residuals
/// `y − C x_sim` (missing samples skipped pairwise), each channel's autocorrelation
/// normalised by its own variance.
fn structure_of(
    model: &TermModel,
    data: &Dataset,
    x0: &[Vec<f64>],
    integrator: &Integrator,
) -> Option<f64> {
    let c = model.linear().c();
    let mut q = 0.0;
    for (exp, x0e) in data.experiments().iter().zip(x0) {
        let sim = crate::augment::simulate_outputs(model, c, x0e, exp, integrator).ok()?;
        let lags = structure_lags(exp.len());
        for ch in 0..sim.nrows() {
            let r: Vec<f64> = (0..exp.len())
                .map(|k| exp.outputs()[(ch, k)] - sim[(ch, k)])
                .collect();
            let valid: Vec<f64> = r.iter().copied().filter(|v| v.is_finite()).collect();
            let n = valid.len();
            if n <= lags + 2 {
                continue;
            }
            let mean = valid.iter().sum::<f64>() / n as f64;
            let var = valid.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n as f64;
            if var.is_nan() || var <= 0.0 {
                continue;
            }
            let nf = n as f64;
            for l in 1..=lags {
                let (mut acc, mut pairs) = (0.0, 0usize);
                for k in l..r.len() {
                    let (a, b) = (r[k], r[k - l]);
                    if a.is_finite() && b.is_finite() {
                        acc += (a - mean) * (b - mean);
                        pairs += 1;
                    }
                }
                if pairs == 0 {
                    continue;
                }
                let rho = acc / nf / var;
                q += nf * (nf + 2.0) * rho * rho / (nf - l as f64);
            }
        }
    }
    q.is_finite().then_some(q)
}

/// The protocol's cost of `model` on the records of `protocol` (whose outputs may be
/// bootstrap draws): when `new_terms` is not empty their coefficients are recalibrated
/// on `cal` (initial states estimated with them); then, with judging records, the
/// initial states are re-fitted there and the cost is theirs. `None` when a simulation
/// diverges.
fn protocol_cost(
    model: &TermModel,
    new_terms: &[usize],
    cal: &Dataset,
    cal_x0: &[Vec<f64>],
    hold: Option<(&Dataset, &[Vec<f64>])>,
    protocol: &Protocol<'_>,
) -> Option<(f64, Option<f64>)> {
    let weights = OutputWeights::NoiseVariance(protocol.noise_variance.to_vec());
    let cal_config = CalibrationConfig {
        terms: Some(new_terms.to_vec()),
        initial_state: InitialState::Estimate,
        weights: weights.clone(),
        ..protocol.calibration.clone()
    };
    let fitted = calibrate(model, cal, cal_x0, &cal_config).ok()?;
    if !fitted.cost_after.is_finite() {
        return None;
    }
    let integrator = &protocol.calibration.integrator;
    let Some((hold, hold_x0)) = hold else {
        let structure = structure_of(&fitted.model, cal, &fitted.x0, integrator);
        return Some((fitted.cost_after, structure));
    };
    let judged =
        crate::augment::fit_initial_states(&fitted.model, hold, &[hold_x0], &cal_config).ok()?;
    if !judged.cost_after.is_finite() {
        return None;
    }
    let structure = structure_of(&judged.model, hold, &judged.x0, integrator);
    Some((judged.cost_after, structure))
}

/// Initial states of `model` fitted on every record of `data` (coefficients fixed).
fn fitted_x0(
    model: &TermModel,
    data: &Dataset,
    x0: &[Vec<f64>],
    protocol: &Protocol<'_>,
) -> Result<Vec<Vec<f64>>> {
    let config = CalibrationConfig {
        weights: OutputWeights::NoiseVariance(protocol.noise_variance.to_vec()),
        ..protocol.calibration.clone()
    };
    Ok(crate::augment::fit_initial_states(model, data, &[x0], &config)?.x0)
}

/// Zero-mean Gaussian noise, `variances.len() × len`, row by row from
/// `ChaCha8Rng::seed_from_u64(seed)` on stream `stream` (the same stream as the
/// simulators' noise, so a floor is reproducible from its seed).
pub(crate) fn gaussian_noise(
    variances: &[f64],
    len: usize,
    seed: u64,
    stream: u64,
) -> DMatrix<f64> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(stream);
    let mut out = DMatrix::zeros(variances.len(), len);
    for (i, &v) in variances.iter().enumerate() {
        let sd = v.max(0.0).sqrt();
        for k in 0..len {
            let z: f64 = StandardNormal.sample(&mut rng);
            out[(i, k)] = sd * z;
        }
    }
    out
}

/// One bootstrap copy of `data`: `model` simulated from `x0` by `integrator`, plus
/// Gaussian noise of `variance` from stream `stream + e` of `seed`; missing samples stay
/// missing.
pub(crate) fn draw(
    model: &TermModel,
    data: &Dataset,
    x0: &[Vec<f64>],
    variance: &[f64],
    integrator: &Integrator,
    seed: u64,
    stream: u64,
) -> Result<Dataset> {
    let c = model.linear().c();
    let mut experiments = Vec::with_capacity(data.experiments().len());
    for (e, (exp, x0e)) in data.experiments().iter().zip(x0).enumerate() {
        let xs = simulate_experiment(model, x0e, exp, 0..exp.len(), integrator, DEFAULT_BLOW_UP)
            .map_err(|source| DiscoveryError::Simulation {
                experiment: e,
                source,
            })?;
        let mut y: DMatrix<f64> = c * xs;
        let noise = gaussian_noise(variance, y.ncols(), seed, stream + e as u64);
        for ch in 0..variance.len() {
            for k in 0..y.ncols() {
                y[(ch, k)] = if exp.outputs()[(ch, k)].is_nan() {
                    f64::NAN
                } else {
                    y[(ch, k)] + noise[(ch, k)]
                };
            }
        }
        experiments.push(
            Experiment::new(exp.t0(), exp.dt(), exp.inputs().clone(), y)?
                .with_intersample(exp.intersample()),
        );
    }
    Ok(Dataset::new(
        data.input_channels().to_vec(),
        data.output_channels().to_vec(),
        experiments,
    )?)
}

/// Judge `model` (whose terms `new_terms` were calibrated on `protocol.cal`) by the
/// protocol, against the protocol's own reference distribution (see the module doc).
///
/// Errors: `draws < 8`, `level` outside (0.5, 1), a noise variance that is not positive
/// and finite, records not matching the model, the model's own simulation diverging on
/// the records, or fewer than half of the draws completing.
pub fn judge(
    model: &TermModel,
    new_terms: &[usize],
    protocol: &Protocol<'_>,
    config: &JudgeConfig,
) -> Result<BootstrapJudgement> {
    if config.draws < 8 {
        return Err(DiscoveryError::InvalidConfig {
            field: "draws",
            value: config.draws as f64,
            reason: "at least 8",
        });
    }
    for (field, value) in [
        ("level", config.level),
        ("structure_level", config.structure_level),
    ] {
        if !(value > 0.5 && value < 1.0) {
            return Err(DiscoveryError::InvalidConfig {
                field,
                value,
                reason: "must lie in (0.5, 1)",
            });
        }
    }
    if let Some(&v) = protocol
        .noise_variance
        .iter()
        .find(|v| !(v.is_finite() && **v > 0.0))
    {
        return Err(DiscoveryError::InvalidConfig {
            field: "noise_variance",
            value: v,
            reason: "must be positive and finite",
        });
    }
    let (statistic, structure_statistic) = protocol_cost(
        model,
        new_terms,
        protocol.cal,
        protocol.cal_x0,
        protocol.hold,
        protocol,
    )
    .map_or((f64::INFINITY, None), |(j, q)| (j, q));
    // The model's own initial states on every record: the bootstrap's truth.
    let cal_x0 = fitted_x0(model, protocol.cal, protocol.cal_x0, protocol)?;
    let hold_x0 = match protocol.hold {
        Some((data, x0)) => Some(fitted_x0(model, data, x0, protocol)?),
        None => None,
    };
    let n_cal = protocol.cal.experiments().len() as u64;
    let costs: Vec<Option<(f64, Option<f64>)>> = (0..config.draws)
        .into_par_iter()
        .map(|b| -> Result<Option<(f64, Option<f64>)>> {
            let stream = (b as u64) << 20;
            let cal = draw(
                model,
                protocol.cal,
                &cal_x0,
                protocol.noise_variance,
                &config.truth_integrator,
                config.seed,
                stream,
            )?;
            let hold = match (protocol.hold, &hold_x0) {
                (Some((data, _)), Some(x0)) => Some(draw(
                    model,
                    data,
                    x0,
                    protocol.noise_variance,
                    &config.truth_integrator,
                    config.seed,
                    stream + n_cal,
                )?),
                _ => None,
            };
            let hold_ref = match (&hold, &hold_x0) {
                (Some(d), Some(x0)) => Some((d, x0.as_slice())),
                _ => None,
            };
            Ok(protocol_cost(
                model, new_terms, &cal, &cal_x0, hold_ref, protocol,
            ))
        })
        .collect::<Result<Vec<_>>>()?;
    let reference: Vec<f64> = costs.iter().flatten().map(|c| c.0).collect();
    let structure_reference: Vec<f64> = costs.iter().flatten().filter_map(|c| c.1).collect();
    let failed = config.draws - reference.len();
    if reference.len() * 2 < config.draws {
        return Err(DiscoveryError::TooFewSamples {
            what: "completed bootstrap draws of the judging protocol",
            found: reference.len(),
            needed: config.draws.div_ceil(2),
        });
    }
    let n = reference.len() as f64;
    let mean = reference.iter().sum::<f64>() / n;
    let var = reference.iter().map(|j| (j - mean).powi(2)).sum::<f64>() / (n - 1.0);
    let sd = var.sqrt();
    let (threshold, p_value) = scaled_chi2(mean, var, config.level, statistic);
    let structure = match structure_statistic {
        Some(q) if structure_reference.len() * 2 >= config.draws => {
            let m = structure_reference.len() as f64;
            let mean = structure_reference.iter().sum::<f64>() / m;
            let var = structure_reference
                .iter()
                .map(|v| (v - mean).powi(2))
                .sum::<f64>()
                / (m - 1.0);
            let (threshold, p_value) = scaled_chi2(mean, var, config.structure_level, q);
            Some(Structure {
                statistic: q,
                lags: structure_lags(
                    protocol
                        .hold
                        .map_or(protocol.cal, |h| h.0)
                        .experiments()
                        .iter()
                        .map(Experiment::len)
                        .max()
                        .unwrap_or(0),
                ),
                reference: structure_reference,
                threshold,
                level: config.structure_level,
                p_value,
            })
        }
        _ => None,
    };
    Ok(BootstrapJudgement {
        statistic,
        reference,
        draws: config.draws,
        failed,
        mean,
        sd,
        threshold,
        level: config.level,
        p_value,
        structure,
    })
}

/// The `level` quantile of `s·χ²_k` with mean `mean` and variance `var`
/// (`s = var/(2·mean)`, `k = 2·mean²/var`), and the upper-tail probability of `x`.
fn scaled_chi2(mean: f64, var: f64, level: f64, x: f64) -> (f64, f64) {
    if !(var > 0.0 && mean > 0.0) {
        let p = if x <= mean { 1.0 } else { 0.0 };
        return (mean, p);
    }
    let s = var / (2.0 * mean);
    let k = 2.0 * mean * mean / var;
    let threshold = chi2_quantile(level, k).map_or(mean + 3.0 * var.sqrt(), |q| s * q);
    let p = if x.is_finite() {
        statrs_upper_tail(x / s, k)
    } else {
        0.0
    };
    (threshold, p)
}

/// The protocol's cost of `model` (see [`judge`]) on the actual records, without a
/// reference distribution: `∞` when a simulation diverges.
pub fn statistic(model: &TermModel, new_terms: &[usize], protocol: &Protocol<'_>) -> f64 {
    protocol_cost(
        model,
        new_terms,
        protocol.cal,
        protocol.cal_x0,
        protocol.hold,
        protocol,
    )
    .map_or(f64::INFINITY, |(j, _)| j)
}

/// Backward elimination by the judge's own test: while the set `new_terms` has more than
/// one term, the term whose removal (the others recalibrated by the protocol) leaves the
/// smallest statistic is dropped if that statistic still lies within `threshold` — the
/// data cannot show it is needed.
pub fn prune(
    model: &TermModel,
    new_terms: &[usize],
    protocol: &Protocol<'_>,
    threshold: f64,
) -> Result<Pruned> {
    // Work with original indices; `kept` lists the original indices still in.
    let mut kept: Vec<usize> = new_terms.to_vec();
    let mut dropped = Vec::new();
    let mut current = model.clone();
    while kept.len() > 1 {
        let trials: Vec<(usize, TermModel, Vec<usize>)> = (0..kept.len())
            .map(|pos| {
                let drop_original = kept[pos];
                let remaining: Vec<usize> = kept
                    .iter()
                    .copied()
                    .filter(|&k| k != drop_original)
                    .collect();
                let (m, idx) = without_terms(model, new_terms, &remaining, &current)?;
                Ok((drop_original, m, idx))
            })
            .collect::<Result<_>>()?;
        let stats: Vec<f64> = trials
            .par_iter()
            .map(|(_, m, idx)| statistic(m, idx, protocol))
            .collect();
        let Some((best, &s)) = stats
            .iter()
            .enumerate()
            .filter(|(_, s)| s.is_finite())
            .min_by(|a, b| a.1.total_cmp(b.1))
        else {
            break;
        };
        if s > threshold {
            break;
        }
        let (drop_original, _, _) = &trials[best];
        dropped.push((*drop_original, s));
        kept.retain(|k| k != drop_original);
        let (m, _) = without_terms(model, new_terms, &kept, &current)?;
        current = m;
    }
    let (model, kept) = without_terms(model, new_terms, &kept, &current)?;
    Ok(Pruned {
        model,
        kept,
        dropped,
    })
}

/// What [`prune`] leaves.
#[derive(Debug, Clone)]
#[cfg_attr(
    not(test),
    expect(
        dead_code,
        reason = "the workflow reads `dropped`; the unit tests read all"
    )
)]
pub struct Pruned {
    /// The model without the dropped terms.
    pub model: TermModel,
    /// Indices in `model` of the surviving new terms.
    pub kept: Vec<usize>,
    /// Indices (in the model given to [`prune`]) of the dropped terms, with the statistic
    /// each removal left, in the order dropped.
    pub dropped: Vec<(usize, f64)>,
}

/// `model` keeping, of its terms `new_terms`, only `keep` (original indices), with the
/// kept terms' coefficients taken from `coefficients_from` where it holds them; the other
/// terms of `model` stay. Returns the model and the kept terms' indices in it.
fn without_terms(
    model: &TermModel,
    new_terms: &[usize],
    keep: &[usize],
    coefficients_from: &TermModel,
) -> Result<(TermModel, Vec<usize>)> {
    let mut terms = Vec::new();
    let mut idx = Vec::new();
    for (k, t) in model.terms().iter().enumerate() {
        if new_terms.contains(&k) && !keep.contains(&k) {
            continue;
        }
        if keep.contains(&k) {
            idx.push(terms.len());
        }
        let mut t = t.clone();
        if let Some(same) = coefficients_from
            .terms()
            .iter()
            .find(|o| o.state == t.state && o.into == t.into && o.expr == t.expr)
        {
            t.coefficient = same.coefficient;
        }
        terms.push(t);
    }
    Ok((TermModel::new(model.linear().clone(), terms)?, idx))
}

/// `P(χ²_k > x)`.
fn statrs_upper_tail(x: f64, k: f64) -> f64 {
    use statrs::distribution::{ChiSquared, ContinuousCDF};
    ChiSquared::new(k).map_or(f64::NAN, |d| d.sf(x))
}

#[cfg(test)]
mod tests {
    use super::*;
    use sysid_core::{Channel, InterSample, simulate_with};

    use crate::test_support::oscillator;

    /// A record of `truth` (Dormand–Prince, tight) driven by a sum of incommensurate
    /// sines held between samples, with noise of variance `r` (its own seed).
    fn record(truth: &TermModel, n: usize, r: f64, seed: u64) -> Dataset {
        let dt = 0.05;
        let u = DMatrix::from_fn(1, n, |_, k| {
            let t = k as f64 * dt;
            1.5 * (0.7 * t).sin() + (1.9 * t + 1.0).sin() + 0.6 * (3.1 * t + 2.0).sin()
        });
        let xs = simulate_with(
            truth,
            &[0.3, 0.0],
            0.0,
            dt,
            &u,
            InterSample::Zoh,
            &JudgeConfig::default().truth_integrator,
            DEFAULT_BLOW_UP,
        )
        .unwrap_or_else(|e| panic!("{e}"));
        let mut y: DMatrix<f64> = truth.linear().c() * xs;
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        for k in 0..n {
            let z: f64 = StandardNormal.sample(&mut rng);
            y[(0, k)] += r.sqrt() * z;
        }
        let exp = Experiment::new(0.0, dt, u, y).unwrap_or_else(|e| panic!("{e}"));
        Dataset::new(vec![Channel::new("u")], vec![Channel::new("x")], vec![exp])
            .unwrap_or_else(|e| panic!("{e}"))
    }

    /// The truth (cubic spring −2 x³) judged on its own protocol is accepted; the same
    /// term with its coefficient frozen 15 % off (nothing recalibrated) is rejected; and
    /// a useless second term rides along only until `prune` drops it.
    #[test]
    fn right_model_accepted_wrong_rejected_passenger_pruned() {
        let truth = oscillator(&[("cubic_stiffness", "x^3", -2.0)]);
        let r = 1e-4;
        let cal = record(&truth, 1200, r, 5);
        let hold = record(&truth, 1200, r, 6);
        let x0 = vec![vec![0.3, 0.0]];
        let calibration = CalibrationConfig {
            horizons: vec![0.25, 1.0],
            tolerance: 1e-8,
            ..CalibrationConfig::default()
        };
        let noise = [r];
        let protocol = Protocol {
            cal: &cal,
            cal_x0: &x0,
            hold: Some((&hold, &x0)),
            noise_variance: &noise,
            calibration: &calibration,
        };
        let config = JudgeConfig::default();
        let right = judge(&truth, &[0], &protocol, &config).unwrap_or_else(|e| panic!("{e}"));
        assert!(right.accepts(), "{right:?}");
        assert!(right.mean > 0.9 && right.mean < 1.2, "{right:?}");
        let structure = right
            .structure
            .as_ref()
            .unwrap_or_else(|| panic!("{right:?}"));
        // Ljung–Box over 20 lags of a nearly white residual: mean near 20.
        let m = structure.reference.iter().sum::<f64>() / structure.reference.len() as f64;
        assert!(m > 10.0 && m < 40.0, "{structure:?}");
        let off = oscillator(&[("cubic_stiffness", "x^3", -2.3)]);
        let wrong = judge(&off, &[], &protocol, &config).unwrap_or_else(|e| panic!("{e}"));
        assert!(!wrong.accepts(), "{wrong:?}");
        // The same test is deterministic.
        let again = judge(&truth, &[0], &protocol, &config).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(right, again);
        let with_passenger = oscillator(&[
            ("cubic_stiffness", "x^3", -2.0),
            ("quadratic_drag", "v*abs(v)", 0.0),
        ]);
        let Pruned {
            model: kept,
            kept: idx,
            dropped,
        } = prune(&with_passenger, &[0, 1], &protocol, right.threshold)
            .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(dropped.len(), 1, "{dropped:?}");
        assert_eq!(dropped[0].0, 1);
        assert_eq!(idx, vec![0]);
        assert_eq!(kept.terms().len(), 1);
        assert_eq!(kept.terms()[0].effect, "cubic_stiffness");
    }

    /// The structure statistic: about `L` for a right model's residual (white noise),
    /// above the χ²_L 0.999 quantile for a model whose coefficient is 1 % off.
    #[test]
    fn structure_separates_white_from_coloured_residuals() {
        let truth = oscillator(&[("cubic_stiffness", "x^3", -2.0)]);
        let r = 1e-4;
        let data = record(&truth, 2000, r, 9);
        let x0 = vec![vec![0.3, 0.0]];
        let rk = Integrator::Rk4 { substeps: 4 };
        let dp = JudgeConfig::default().truth_integrator;
        let white = structure_of(&truth, &data, &x0, &dp).unwrap_or(f64::NAN);
        let white_rk = structure_of(&truth, &data, &x0, &rk).unwrap_or(f64::NAN);
        assert!(
            (white - white_rk).abs() < 0.01 * white,
            "{white} vs {white_rk}"
        );
        // χ²_20 has mean 20, sd 6.3 (its 0.999 quantile is 45.3).
        assert!(white > 5.0 && white < 45.3, "{white}");
        // A cubic coefficient 1 % off leaves a slow, coloured free-run error.
        let off = oscillator(&[("cubic_stiffness", "x^3", -2.02)]);
        let coloured = structure_of(&off, &data, &x0, &rk).unwrap_or(f64::NAN);
        assert!(coloured > 45.3, "{coloured}");
    }

    #[test]
    fn scaled_chi2_matches_chi2_when_scale_is_one() {
        // mean k, variance 2k: s = 1, the plain χ²_k quantile.
        let k = 10.0;
        let (q, p) = scaled_chi2(k, 2.0 * k, 0.99, k);
        let exact = chi2_quantile(0.99, k).unwrap();
        assert!((q - exact).abs() < 1e-9, "{q} vs {exact}");
        assert!(p > 0.3 && p < 0.6, "p at the mean {p}");
    }

    #[test]
    fn scaled_chi2_of_a_normalised_cost() {
        // J = χ²_M / M: mean 1, variance 2/M; its 0.99 quantile ≈ 1 + 2.326·√(2/M).
        let m = 5000.0;
        let (q, _) = scaled_chi2(1.0, 2.0 / m, 0.99, 1.0);
        let normal = 1.0 + 2.326 * (2.0_f64 / m).sqrt();
        assert!((q - normal).abs() < 0.005, "{q} vs {normal}");
    }
}
