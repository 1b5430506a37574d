//! Term selection by free-run simulation error: the last word on which named effects a
//! model needs. The regression on `d̂` is fast and names candidates, but MME's smoothing
//! distorts `d̂`'s shape systematically (peaks are flattened), and a systematic error is
//! "significant" to any regression test. The free-run error of the calibrated model has no
//! such bias: with the right terms its residual is the measurement noise.
//!
//! Stepwise on the calibrated free-run cost `J(S) = (1/M) Σ_c Σ_k r_ck² / R_c` over the `M`
//! measured values (≈ 1 for a correct model; coefficients of the terms in `S` and the
//! initial states re-fitted for every `S`):
//! - remove the term whose removal raises `J` least, if that rise is not significant;
//! - otherwise add the candidate that lowers `J` most, if that drop is significant;
//! - otherwise add the pair of candidates of one equation that lowers `J` most, if that
//!   drop is significant against χ²₂ (terms that only work together);
//! - stop when neither applies.
//!
//! A change is significant when `M·ΔJ · N_eff/N > χ²₁(1 − α)`: under a correct model
//! `M·ΔJ` for one spurious term is χ²₁; the free-run residual of a model that is still
//! wrong is coloured, and `N_eff/N = (1 − ρ₁)/(1 + ρ₁)` (lag-1 autocorrelation of the
//! residual of the larger of the two models compared) discounts that.

use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};
use sysid_core::{Dataset, TermModel};

use crate::augment::{
    CalibrationConfig, InitialState, OutputWeights, calibrate, free_run_cost, measured_values,
    simulate_outputs,
};
use crate::error::{DiscoveryError, Result};
use rayon::prelude::*;

use crate::screen::Screen;
use crate::stats::chi2_quantile;
pub use crate::term_set::RefineCandidate;
use crate::term_set::build;

mod polish;

/// Settings of [`refine_by_free_run`].
#[derive(Debug, Clone, PartialEq)]
pub struct RefineConfig {
    /// Significance level of each add/remove decision. Default 0.01.
    pub alpha: f64,
    /// Most add/remove steps. Default 12.
    pub max_steps: usize,
    /// Calibration settings (its `terms` and `weights` are set by the search).
    pub calibration: CalibrationConfig,
    /// How many of the best-ranked single candidates, and separately of the best-ranked
    /// pairs, are calibrated fully at each step (ranked by their score statistic, see
    /// the `screen` module); `usize::MAX` calibrates every one. Default 4.
    pub screen: usize,
}

impl Default for RefineConfig {
    fn default() -> Self {
        Self {
            alpha: 0.01,
            max_steps: 12,
            screen: 4,
            calibration: CalibrationConfig {
                initial_state: InitialState::Estimate,
                // Decisions need `J` to ~1/M; a relative 1e-8 is far below that.
                tolerance: 1e-8,
                // Candidates start near their fit (calibrated set, Gauss–Newton start for
                // the new term): one short stage guards against drift, then the record.
                horizons: vec![0.25, 1.0],
                ..CalibrationConfig::default()
            },
        }
    }
}

/// One decision of the search.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RefineStep {
    /// `add` or `remove`.
    pub action: String,
    /// Effect and term.
    pub effect: String,
    /// Term.
    pub term: String,
    /// Free-run cost before and after, on the records that judge the search: the held-out
    /// records when the caller gave some (validation records, or the held-out end of the
    /// estimation records), else the estimation records. For `calibrate parameter` steps
    /// it is the estimation-record cost the parameter was fitted on.
    pub cost: [f64; 2],
    /// `M·ΔJ·N_eff/N` against the χ² threshold.
    pub statistic: f64,
    /// The threshold.
    pub threshold: f64,
}

/// Result of the search.
#[derive(Debug, Clone)]
pub struct Refinement {
    /// Indices into `candidates` of the terms kept, in the order of `model`'s new terms.
    pub selected: Vec<usize>,
    /// The candidate list as the search left it: the given one with calibrated
    /// coefficients and, for terms whose shaping parameters were calibrated, re-written
    /// terms (same length and order as the list given).
    pub candidates: Vec<RefineCandidate>,
    /// The base model plus the kept terms, calibrated.
    pub model: TermModel,
    /// Calibrated initial states.
    pub x0: Vec<Vec<f64>>,
    /// Free-run cost of the base model alone (as given) and of the result — on the
    /// held-out records when there are any.
    pub cost: [f64; 2],
    /// The decisions taken.
    pub steps: Vec<RefineStep>,
    /// Standard error of each kept term's calibrated coefficient (order of `selected`):
    /// the Gauss–Newton covariance of the estimation-record fit, inflated by
    /// `√(N/N_eff)` of its residual's lag-1 autocorrelation, plus `parameter_variance`.
    pub coefficient_std: Vec<f64>,
    /// The part of each coefficient's variance that comes from the uncertainty of the
    /// set's calibrated shaping parameters (thresholds, velocities; see the `polish`
    /// module), already included in `coefficient_std`; a caller that recalibrates the
    /// coefficients adds it to the new conditional variances.
    pub parameter_variance: Vec<f64>,
}

/// What a free-run search works on, besides its candidates: the assumed model, the
/// records that calibrate, the records that judge, and the settings.
#[derive(Debug, Clone, Copy)]
pub struct Search<'a> {
    /// The assumed model the candidate terms are added to (its own terms stay fixed).
    pub base: &'a TermModel,
    /// The records coefficients are calibrated on.
    pub data: &'a Dataset,
    /// A starting guess of each of `data`'s initial states (re-fitted).
    pub x0: &'a [Vec<f64>],
    /// Noise variance per model output (weights of the free-run cost).
    pub noise_variance: &'a [f64],
    /// Held-out records that judge every candidate set; `None`: `data` judges.
    pub holdout: Option<Holdout<'a>>,
    /// Settings.
    pub config: &'a RefineConfig,
}

#[derive(Clone)]
struct Eval {
    model: TermModel,
    x0: Vec<Vec<f64>>,
    cost: f64,
    neff_ratio: f64,
    /// `(c/σ_c)²` of every term of the set, in set order (ranks removals).
    wald: Vec<f64>,
    /// Standard error of every term of the set, in set order (colour-inflated).
    std: Vec<f64>,
}

/// Calibrate the base model plus the terms `set`; `None` when the simulation diverges or
/// when one of the last `check_new` terms' coefficients is not distinguishable from zero.
fn evaluate(
    ctx: &Search<'_>,
    candidates: &[RefineCandidate],
    set: &[usize],
    check_new: usize,
) -> Result<Option<Eval>> {
    let Some(eval) = evaluate_on_data(ctx, candidates, set, check_new)? else {
        return Ok(None);
    };
    match ctx.holdout {
        None => Ok(Some(eval)),
        Some(h) => holdout_score(ctx, h, eval),
    }
}

/// Replace an evaluation's cost and residual colour by those on the held-out records:
/// coefficients as calibrated, initial states re-fitted there. `None` when the held-out
/// simulation diverges.
fn holdout_score(ctx: &Search<'_>, h: Holdout<'_>, mut eval: Eval) -> Result<Option<Eval>> {
    let cal = CalibrationConfig {
        weights: OutputWeights::NoiseVariance(ctx.noise_variance.to_vec()),
        ..ctx.config.calibration.clone()
    };
    let Ok(fit) = crate::augment::fit_initial_states(&eval.model, h.data, &[h.x0], &cal) else {
        return Ok(None);
    };
    if !fit.cost_after.is_finite() {
        return Ok(None);
    }
    eval.neff_ratio = residual_neff_ratio(&fit.model, h.data, &fit.x0, &ctx.config.calibration)?;
    eval.cost = fit.cost_after;
    Ok(Some(eval))
}

/// [`evaluate`] on the estimation records only.
fn evaluate_on_data(
    ctx: &Search<'_>,
    candidates: &[RefineCandidate],
    set: &[usize],
    check_new: usize,
) -> Result<Option<Eval>> {
    let Search {
        base,
        data,
        x0,
        noise_variance: noise,
        config,
        ..
    } = *ctx;
    let model = build(base, candidates, set)?;
    let first_new = base.terms().len();
    if set.is_empty() {
        // Nothing to calibrate: the base model's cost from the given initial states.
        let weights = OutputWeights::NoiseVariance(noise.to_vec());
        let Ok(cost) = free_run_cost(
            &model,
            model.linear(),
            data,
            x0,
            &weights,
            &config.calibration.integrator,
        ) else {
            return Ok(None);
        };
        if !cost.is_finite() {
            return Ok(None);
        }
        let neff_ratio = residual_neff_ratio(&model, data, x0, &config.calibration)?;
        return Ok(Some(Eval {
            model,
            x0: x0.to_vec(),
            cost,
            neff_ratio,
            wald: vec![],
            std: vec![],
        }));
    }
    let cal = CalibrationConfig {
        terms: Some((first_new..first_new + set.len()).collect()),
        weights: OutputWeights::NoiseVariance(noise.to_vec()),
        ..config.calibration.clone()
    };
    // A candidate set whose simulation diverges is simply not admissible.
    let Ok(fit) = calibrate(&model, data, x0, &cal) else {
        return Ok(None);
    };
    if !fit.cost_after.is_finite() {
        return Ok(None);
    }
    let neff_ratio = residual_neff_ratio(&fit.model, data, &fit.x0, &config.calibration)?;
    // Every coefficient of the set must be distinguishable from zero (calibration σ, white
    // residual): near-cancelling pairs of collinear terms with huge opposite coefficients
    // fit the record but name nothing. (Inflating σ for a coloured residual would block
    // every step while the model is still wrong; the caller's acceptance test — d̂ must
    // shrink, validation must improve — guards the end result.)
    let z = z_two_sided(config.alpha);
    let inflate = 1.0;
    let end = first_new + set.len();
    let significant = (end - check_new.min(set.len())..end).all(|k| {
        let (c, sd) = (fit.coefficients_after[k], fit.coefficient_std[k]);
        sd.is_finite() && c.abs() > z * sd * inflate
    });
    if !significant {
        return Ok(None);
    }
    let wald = (first_new..end)
        .map(|k| {
            let (c, sd) = (fit.coefficients_after[k], fit.coefficient_std[k]);
            if sd.is_finite() && sd > 0.0 {
                (c / sd).powi(2)
            } else {
                0.0
            }
        })
        .collect();
    let std = (first_new..end)
        .map(|k| fit.coefficient_std[k] / neff_ratio.sqrt())
        .collect();
    Ok(Some(Eval {
        model: fit.model,
        x0: fit.x0,
        cost: fit.cost_after,
        neff_ratio,
        wald,
        std,
    }))
}

/// One candidate set to calibrate: its key, the candidate list with starting
/// coefficients, the set, and how many of its last terms must be significant.
struct TrialSet<K> {
    key: K,
    cands: Vec<RefineCandidate>,
    set: Vec<usize>,
    check_new: usize,
}

/// Calibrate every trial (in parallel) and return the admissible one of least cost (the
/// first in order on ties, so the result does not depend on the thread count).
fn best_trial<K: Copy + Send + Sync>(
    ctx: &Search<'_>,
    trials: Vec<TrialSet<K>>,
) -> Result<Option<(K, Eval)>> {
    let results: Vec<Result<Option<Eval>>> = trials
        .par_iter()
        .map(|t| evaluate(ctx, &t.cands, &t.set, t.check_new))
        .collect();
    let mut best: Option<(K, Eval)> = None;
    for (t, r) in trials.iter().zip(results) {
        if let Some(e) = r?
            && best.as_ref().is_none_or(|(_, b)| e.cost < b.cost)
        {
            best = Some((t.key, e));
        }
    }
    Ok(best)
}

/// Smallest `M·ΔJ·N_eff/N` by which an exchange must improve the fit (same size: no χ²
/// test applies; the margin keeps near-ties from churning).
const SWAP_MARGIN: f64 = 1.0;

/// The set's indices in ascending order (identity of a term set).
fn sorted(set: &[usize]) -> Vec<usize> {
    let mut v = set.to_vec();
    v.sort_unstable();
    v
}

/// `set` without its entry at `pos`.
fn without(set: &[usize], pos: usize) -> Vec<usize> {
    set.iter()
        .enumerate()
        .filter(|(p, _)| *p != pos)
        .map(|(_, &i)| i)
        .collect()
}

/// Two-sided standard-normal quantile for level `alpha`: `z² = χ²₁(1 − α)`.
fn z_two_sided(alpha: f64) -> f64 {
    chi2_quantile(1.0 - alpha, 1.0).map_or(2.576, f64::sqrt)
}

/// `(1 − ρ₁)/(1 + ρ₁)` of the pooled free-run residual, clipped to (0, 1].
fn residual_neff_ratio(
    model: &TermModel,
    data: &Dataset,
    x0: &[Vec<f64>],
    cal: &CalibrationConfig,
) -> Result<f64> {
    let (mut num, mut den) = (0.0, 0.0);
    for (exp, x0e) in data.experiments().iter().zip(x0) {
        let y = simulate_outputs(model, model.linear().c(), x0e, exp, &cal.integrator)?;
        let r: DMatrix<f64> = exp.outputs() - y;
        for i in 0..r.nrows() {
            let row: Vec<f64> = r.row(i).iter().copied().filter(|v| v.is_finite()).collect();
            let mean = row.iter().sum::<f64>() / row.len().max(1) as f64;
            for k in 0..row.len() {
                den += (row[k] - mean).powi(2);
                if k + 1 < row.len() {
                    num += (row[k] - mean) * (row[k + 1] - mean);
                }
            }
        }
    }
    let rho = if den > 0.0 {
        (num / den).clamp(-0.99, 0.99)
    } else {
        0.0
    };
    Ok(((1.0 - rho) / (1.0 + rho)).clamp(1e-3, 1.0))
}

/// Held-out records for [`refine_with_holdout`]: data not used to calibrate, on which
/// every candidate set is judged (coefficients as calibrated, initial states re-fitted).
#[derive(Debug, Clone, Copy)]
pub struct Holdout<'a> {
    /// The records.
    pub data: &'a Dataset,
    /// A starting guess of each record's initial state.
    pub x0: &'a [Vec<f64>],
}

/// [`refine_with_holdout`] without held-out data: every decision on the estimation
/// records.
pub fn refine_by_free_run(
    base: &TermModel,
    candidates: &[RefineCandidate],
    initial: &[usize],
    data: &Dataset,
    x0: &[Vec<f64>],
    noise_variance: &[f64],
    config: &RefineConfig,
) -> Result<Refinement> {
    let search = Search {
        base,
        data,
        x0,
        noise_variance,
        holdout: None,
        config,
    };
    refine_with_holdout(&search, candidates, initial)
}

/// Stepwise selection of `candidates` by calibrated free-run cost, starting from
/// `initial` (indices into `candidates`, e.g. the regression's choice), on `search`'s
/// records (`x0` a starting guess per experiment; it is re-fitted).
///
/// With `search.holdout`, coefficients are calibrated on `search.data` but every
/// decision (and the reported costs) uses the free-run cost on the held-out records: a
/// combination of wrong terms that mimics the missing effect on one input rarely does so
/// on another.
pub fn refine_with_holdout(
    search: &Search<'_>,
    candidates: &[RefineCandidate],
    initial: &[usize],
) -> Result<Refinement> {
    let Search {
        base,
        data,
        noise_variance,
        holdout,
        config,
        ..
    } = *search;
    if !(config.alpha > 0.0 && config.alpha < 1.0) {
        return Err(DiscoveryError::InvalidConfig {
            field: "alpha",
            value: config.alpha,
            reason: "must lie in (0, 1)",
        });
    }
    if let Some(&bad) = initial.iter().find(|&&i| i >= candidates.len()) {
        return Err(DiscoveryError::InvalidConfig {
            field: "initial",
            value: bad as f64,
            reason: "index beyond the candidate list",
        });
    }
    let threshold = chi2_quantile(1.0 - config.alpha, 1.0)?;
    if config.screen == 0 {
        return Err(DiscoveryError::InvalidConfig {
            field: "screen",
            value: 0.0,
            reason: "at least 1 candidate per step",
        });
    }
    let ctx = *search;
    let m = measured_values(holdout.map_or(data, |h| h.data)) as f64;
    // Working copy: starting coefficients follow the latest calibration.
    let mut cands: Vec<RefineCandidate> = candidates.to_vec();
    let base_eval = evaluate(&ctx, &cands, &[], 0)?;
    // The starting set; when it is not admissible (diverges, or calibration fails), drop
    // its terms one at a time, keeping the best admissible subset at each size.
    let mut set: Vec<usize> = initial.to_vec();
    let mut current = loop {
        if let Some(e) = evaluate(&ctx, &cands, &set, 0)? {
            break e;
        }
        if set.is_empty() {
            return Err(DiscoveryError::InvalidConfig {
                field: "base model",
                value: f64::NAN,
                reason: "its free-run simulation diverges",
            });
        }
        let mut best: Option<(usize, Eval)> = None;
        for pos in 0..set.len() {
            let trial = without(&set, pos);
            if let Some(e) = evaluate(&ctx, &cands, &trial, 0)?
                && best.as_ref().is_none_or(|(_, b)| e.cost < b.cost)
            {
                best = Some((pos, e));
            }
        }
        match best {
            Some((pos, _)) => {
                set.remove(pos);
            }
            None => set.clear(),
        }
    };
    let cost_before = base_eval.as_ref().map_or(f64::NAN, |e| e.cost);
    let mut steps = Vec::new();
    let mut polished = vec![false; cands.len()];
    let polish_now = |cands: &mut [RefineCandidate],
                      set: &[usize],
                      current: &mut Eval,
                      steps: &mut Vec<RefineStep>,
                      polished: &mut [bool]| {
        polish::polish_set(&ctx, cands, set, current, steps, polished, m, threshold)
    };
    polish_now(&mut cands, &set, &mut current, &mut steps, &mut polished)?;
    let remove_step = |set: &mut Vec<usize>,
                       current: &mut Eval,
                       steps: &mut Vec<RefineStep>,
                       cands: &[RefineCandidate]|
     -> Result<bool> {
        // Removal: rank the set's terms by their Wald statistic, calibrate the weakest
        // fully without each, take the removal that costs least if it is not significant.
        let mut order: Vec<usize> = (0..set.len()).collect();
        order.sort_by(|&a, &b| {
            let wa = current.wald.get(a).copied().unwrap_or(0.0);
            let wb = current.wald.get(b).copied().unwrap_or(0.0);
            wa.total_cmp(&wb)
        });
        let trials = order
            .iter()
            .take(config.screen)
            .map(|&pos| TrialSet {
                key: pos,
                cands: cands.to_vec(),
                set: without(set, pos),
                check_new: 0,
            })
            .collect();
        let best_remove = best_trial(&ctx, trials)?;
        if let Some((pos, e)) = best_remove {
            let stat = m * (e.cost - current.cost) * current.neff_ratio;
            if stat < threshold {
                let c = &cands[set[pos]];
                steps.push(RefineStep {
                    action: "remove".into(),
                    effect: c.effect.clone(),
                    term: c.term.clone(),
                    cost: [current.cost, e.cost],
                    statistic: stat,
                    threshold,
                });
                set.remove(pos);
                *current = e;
                return Ok(true);
            }
        }
        Ok(false)
    };
    let mut visited: std::collections::BTreeSet<Vec<usize>> = std::collections::BTreeSet::new();
    visited.insert(sorted(&set));
    for _ in 0..config.max_steps {
        if remove_step(&mut set, &mut current, &mut steps, &cands)? {
            continue;
        }
        // Exchange, then addition: rank every candidate by its score statistic at the
        // current model, calibrate the best-ranked fully and take the one that helps most.
        let first_new = base.terms().len();
        let screen = Screen::new(
            &current.model,
            &(first_new..first_new + set.len()).collect::<Vec<_>>(),
            &current.x0,
            &cands,
            &set,
            data,
            noise_variance,
            &config.calibration.integrator,
        )?;
        // Exchange: a term of the set for a candidate of the same equation, when the
        // exchanged set fits better at the same size (a combination of wrong terms can
        // mimic a right one — Coulomb friction looks like viscous plus v|v| — and no
        // single removal or addition leaves such a local optimum).
        let mut swaps: Vec<(usize, usize, f64, f64)> = Vec::new();
        for pos in 0..set.len() {
            for i in 0..cands.len() {
                if set.contains(&i) || cands[i].state != cands[set[pos]].state {
                    continue;
                }
                if let Some((cost, c)) = screen.swap(pos, i) {
                    swaps.push((pos, i, cost, c));
                }
            }
        }
        swaps.sort_by(|a, b| a.2.total_cmp(&b.2));
        let mut trials = Vec::new();
        for &(pos, i, predicted, coefficient) in swaps.iter().take(config.screen) {
            // Without held-out data an exchange must at least promise a better fit here.
            if holdout.is_none() && predicted >= screen.cost() {
                break;
            }
            let mut trial = without(&set, pos);
            trial.push(i);
            if visited.contains(&sorted(&trial)) {
                continue;
            }
            let mut trial_cands = cands.clone();
            trial_cands[i].coefficient = coefficient;
            trials.push(TrialSet {
                key: (pos, i),
                cands: trial_cands,
                set: trial,
                check_new: 1,
            });
        }
        if let Some(((pos, i), e)) = best_trial(&ctx, trials)?
            && m * (current.cost - e.cost) * e.neff_ratio > SWAP_MARGIN
        {
            let (out, c) = (&cands[set[pos]], &cands[i]);
            steps.push(RefineStep {
                action: "exchange".into(),
                effect: format!("{} → {}", out.effect, c.effect),
                term: format!("{} → {}", out.term, c.term),
                cost: [current.cost, e.cost],
                statistic: m * (current.cost - e.cost) * e.neff_ratio,
                threshold: SWAP_MARGIN,
            });
            set.remove(pos);
            set.push(i);
            visited.insert(sorted(&set));
            current = e;
            polish_now(&mut cands, &set, &mut current, &mut steps, &mut polished)?;
            for (pos, &i) in set.iter().enumerate() {
                if let Some(t) = current.model.terms().get(first_new + pos) {
                    cands[i].coefficient = t.coefficient;
                }
            }
            continue;
        }
        let mut ranked: Vec<(usize, f64, f64)> = (0..cands.len())
            .filter(|i| !set.contains(i))
            .filter_map(|i| screen.single(i).map(|(drop, c)| (i, drop, c)))
            .collect();
        ranked.sort_by(|a, b| b.1.total_cmp(&a.1));
        let trials = ranked
            .iter()
            .take(config.screen)
            .map(|&(i, _, coefficient)| {
                let mut trial = set.clone();
                trial.push(i);
                let mut trial_cands = cands.clone();
                trial_cands[i].coefficient = coefficient;
                TrialSet {
                    key: i,
                    cands: trial_cands,
                    set: trial,
                    check_new: 1,
                }
            })
            .collect();
        match best_trial(&ctx, trials)? {
            Some((i, e)) if m * (current.cost - e.cost) * e.neff_ratio > threshold => {
                let c = &cands[i];
                steps.push(RefineStep {
                    action: "add".into(),
                    effect: c.effect.clone(),
                    term: c.term.clone(),
                    cost: [current.cost, e.cost],
                    statistic: m * (current.cost - e.cost) * e.neff_ratio,
                    threshold,
                });
                set.push(i);
                current = e;
                polish_now(&mut cands, &set, &mut current, &mut steps, &mut polished)?;
            }
            _ => {
                // No single term helps significantly: pairs within one equation (terms
                // that only work together, e.g. `v` and `x²v` of amplitude-dependent
                // damping), ranked by their joint score, judged against χ²₂.
                let pair_threshold = chi2_quantile(1.0 - config.alpha, 2.0)?;
                let mut pairs: Vec<((usize, usize), f64, [f64; 2])> = Vec::new();
                for i in 0..cands.len() {
                    for j in i + 1..cands.len() {
                        if set.contains(&i) || set.contains(&j) || cands[i].state != cands[j].state
                        {
                            continue;
                        }
                        if let Some((drop, c)) = screen.pair(i, j) {
                            pairs.push(((i, j), drop, c));
                        }
                    }
                }
                pairs.sort_by(|a, b| b.1.total_cmp(&a.1));
                let trials = pairs
                    .iter()
                    .take(config.screen)
                    .map(|&((i, j), _, [ci, cj])| {
                        let mut trial = set.clone();
                        trial.extend([i, j]);
                        let mut trial_cands = cands.clone();
                        trial_cands[i].coefficient = ci;
                        trial_cands[j].coefficient = cj;
                        TrialSet {
                            key: (i, j),
                            cands: trial_cands,
                            set: trial,
                            check_new: 2,
                        }
                    })
                    .collect();
                match best_trial(&ctx, trials)? {
                    Some(((i, j), e))
                        if m * (current.cost - e.cost) * e.neff_ratio > pair_threshold =>
                    {
                        for k in [i, j] {
                            let c = &cands[k];
                            steps.push(RefineStep {
                                action: "add (pair)".into(),
                                effect: c.effect.clone(),
                                term: c.term.clone(),
                                cost: [current.cost, e.cost],
                                statistic: m * (current.cost - e.cost) * e.neff_ratio,
                                threshold: pair_threshold,
                            });
                        }
                        set.extend([i, j]);
                        current = e;
                        polish_now(&mut cands, &set, &mut current, &mut steps, &mut polished)?;
                    }
                    _ => break,
                }
            }
        }
        // Later steps start from the calibrated coefficients.
        for (pos, &i) in set.iter().enumerate() {
            if let Some(t) = current.model.terms().get(first_new + pos) {
                cands[i].coefficient = t.coefficient;
            }
        }
    }
    // Terms that entered while the set was far from the data get their parameters now.
    polish_now(&mut cands, &set, &mut current, &mut steps, &mut polished)?;
    // Fewer terms for the same law: two terms of one shaped law at different parameters
    // become one, and an input gain beside a saturation (or dead zone) at the same
    // threshold becomes the other law alone — each kept unless it fits significantly
    // worse.
    polish::simplify(
        &ctx,
        &mut cands,
        &mut set,
        &mut current,
        &mut steps,
        m,
        threshold,
    )?;
    // Whatever stopped the search, end with no term whose removal is insignificant.
    while !set.is_empty() && remove_step(&mut set, &mut current, &mut steps, &cands)? {}
    // (Far from the noise level the terms are stand-ins that will not be claimed, and
    // their intervals stay conditional on the library's parameters.)
    let parameter_variance = if current.cost <= polish::POLISH_GATE {
        polish::parameter_variance(&ctx, &cands, &set, &current)?
    } else {
        vec![0.0; set.len()]
    };
    let coefficient_std = current
        .std
        .iter()
        .zip(&parameter_variance)
        .map(|(sd, v)| (sd * sd + v).sqrt())
        .collect();
    Ok(Refinement {
        selected: set,
        candidates: cands,
        parameter_variance,
        model: current.model,
        x0: current.x0,
        cost: [cost_before, current.cost],
        steps,
        coefficient_std,
    })
}

#[cfg(test)]
mod tests;
