//! Calibration of the parameters that shape a term: an input saturation's limit, a dead
//! zone's width, a smoothed Coulomb law's transition velocity, a Stribeck velocity. The
//! library writes them from fixed rules (quantiles of `|u|`, a fraction of the velocity's
//! RMS), and a term at the wrong threshold is a wrong model: the search then piles up a
//! second threshold or a Stribeck hump to make up for it. So once such a term enters the
//! set, its parameter is fitted like its coefficient — by free-run error on the
//! estimation records — through a golden-section search on the parameter's logarithm
//! (the cost is smooth in it but not cheap: every point is a full calibration of the
//! set's coefficients and initial states).
//!
//! Also here, because both exist for threshold terms: the uncertainty a calibrated
//! parameter adds to the coefficients' intervals, and the end-of-search identity move
//! that rewrites an input gain plus a saturation as a dead zone (and back).

use crate::augment::measured_values;
use crate::catalogue::Effect;
use crate::error::Result;
use crate::stats::chi2_quantile;

use super::{Eval, RefineCandidate, RefineConfig, RefineStep, Search, evaluate, evaluate_on_data};

/// The parameters of a model effect that shape its term (indices into
/// [`Effect::parameters`]); the smoothing `eps` of a Stribeck term stays with its
/// Coulomb partner's rule.
fn shaping_parameters(effect: Effect) -> &'static [usize] {
    match effect {
        Effect::InputSaturation
        | Effect::DeadZone
        | Effect::CoulombFrictionSmooth
        | Effect::Overflow => &[0],
        Effect::StribeckFrictionSmooth => &[0],
        _ => &[],
    }
}

/// The search interval: a factor `SPAN` either side of the library's value (the
/// library's smoothing velocity is 1 % of the velocity RMS; a real transition can be
/// several times wider).
const SPAN: f64 = 10.0;
/// The search interval's factor for `effect`: an overflow's rim lies among the level's
/// values (the library starts it at a high quantile of them, and a level that spills
/// piles up just above its rim), so it is searched within a factor 1.5; far outside the
/// data the cost is flat and a wide bracket only wastes evaluations.
fn span_of(effect: Effect) -> f64 {
    match effect {
        Effect::Overflow => 1.5,
        _ => SPAN,
    }
}
/// Golden-section evaluations per parameter: the bracket `ln(SPAN²)` shrinks by 0.618
/// per evaluation, to about 1.4 % of the parameter after 14.
const EVALUATIONS: usize = 14;

/// The search's settings with calibrations of one stage over the whole record: trials
/// here start from the current calibration, close to their optimum, so the growing
/// horizons that guard a cold start are not needed.
fn one_stage(config: &RefineConfig) -> RefineConfig {
    let mut config = config.clone();
    config.calibration.horizons = vec![1.0];
    config
}

/// The candidate `cand` with parameter `q` set to `value` (term re-written from the
/// effect's template); `None` when the candidate cannot be re-written.
fn with_parameter(cand: &RefineCandidate, q: usize, value: f64) -> Option<RefineCandidate> {
    let effect = Effect::from_name(&cand.effect)?;
    let mut parameters = cand.parameters.clone();
    *parameters.get_mut(q)? = value;
    let vars: Vec<&str> = cand.variables.iter().map(String::as_str).collect();
    if vars.len() != effect.slots().len() {
        return None;
    }
    Some(RefineCandidate {
        term: effect.template(&vars, &parameters),
        parameters,
        ..cand.clone()
    })
}

/// Fit the shaping parameters of the term at position `pos` of `set`: each trial value
/// re-calibrates the set's coefficients and initial states from `current`'s (a
/// parameter off by a factor pulls the other coefficients along, so fixing them would
/// bias it); the chosen value is then evaluated in full. Returns the
/// re-written candidate, the full evaluation of the set with it (judged as `evaluate`
/// judges) and the step to record, or `None` when no value lowers the
/// estimation-record cost significantly.
pub(super) fn polish(
    ctx: &Search<'_>,
    cands: &[RefineCandidate],
    set: &[usize],
    pos: usize,
    current: &Eval,
) -> Result<Option<(RefineCandidate, Eval, RefineStep)>> {
    let i = set[pos];
    let Some(effect) = Effect::from_name(&cands[i].effect) else {
        return Ok(None);
    };
    let shaping = shaping_parameters(effect);
    if shaping.is_empty() || cands[i].parameters.len() != effect.parameters().len() {
        return Ok(None);
    }
    let config = one_stage(ctx.config);
    let trial_ctx = Search {
        config: &config,
        x0: &current.x0,
        ..*ctx
    };
    let cost_at = |cands: &[RefineCandidate]| -> Result<f64> {
        Ok(evaluate_on_data(&trial_ctx, cands, set, 0)?.map_or(f64::INFINITY, |e| e.cost))
    };
    let start_term = cands[i].term.clone();
    let start_cost = cost_at(cands)?;
    let mut best_cost = start_cost;
    let mut work = cands.to_vec();
    for &q in shaping {
        let p0 = work[i].parameters[q];
        if !(p0.is_finite() && p0 > 0.0) {
            continue;
        }
        let trial_cost = |s: f64| -> Result<(f64, Option<RefineCandidate>)> {
            let Some(c) = with_parameter(&work[i], q, s.exp()) else {
                return Ok((f64::INFINITY, None));
            };
            let mut trial = work.clone();
            trial[i] = c.clone();
            Ok((cost_at(&trial)?, Some(c)))
        };
        let ratio = (5f64.sqrt() - 1.0) / 2.0;
        let span = span_of(effect);
        let (mut a, mut b) = (p0.ln() - span.ln(), p0.ln() + span.ln());
        let mut x1 = b - ratio * (b - a);
        let mut x2 = a + ratio * (b - a);
        let (mut f1, mut c1) = trial_cost(x1)?;
        let (mut f2, mut c2) = trial_cost(x2)?;
        for _ in 2..EVALUATIONS {
            if f1 <= f2 {
                b = x2;
                (x2, f2, c2) = (x1, f1, c1.clone());
                x1 = b - ratio * (b - a);
                (f1, c1) = trial_cost(x1)?;
            } else {
                a = x1;
                (x1, f1, c1) = (x2, f2, c2.clone());
                x2 = a + ratio * (b - a);
                (f2, c2) = trial_cost(x2)?;
            }
        }
        let (f, c) = if f1 <= f2 { (f1, c1) } else { (f2, c2) };
        if let Some(c) = c
            && f < best_cost
        {
            best_cost = f;
            work[i] = c;
        }
    }
    // A parameter is a degree of freedom like a coefficient: moved from the library's
    // value only when the estimation records say so significantly (`M·ΔJ` above
    // χ²₁(1 − α)); otherwise the documented starting rule stands.
    let measured = measured_values(ctx.data);
    let threshold = chi2_quantile(1.0 - ctx.config.alpha, 1.0)?;
    if best_cost.is_nan() || (start_cost - best_cost) * measured as f64 <= threshold {
        return Ok(None);
    }
    let Some(eval) = evaluate(ctx, &work, set, 0)? else {
        return Ok(None);
    };
    let step = RefineStep {
        action: "calibrate parameter".into(),
        effect: work[i].effect.clone(),
        term: format!("{start_term} → {}", work[i].term),
        cost: [start_cost, best_cost],
        statistic: 0.0,
        threshold: 0.0,
    };
    Ok(Some((work[i].clone(), eval, step)))
}

/// Largest judged cost (1 = the noise level) at which shaping parameters are calibrated.
pub(super) const POLISH_GATE: f64 = 3.0;

/// Calibrate the shaping parameters (thresholds, velocity scales) of every term of `set`
/// not calibrated yet (`polished` is indexed like `cands`), keeping a re-written term
/// unless the judged cost rises significantly (`M·ΔJ` above `threshold`, the price of
/// one parameter: the parameter is fitted on the estimation records, so on held-out
/// ones it may lose a little to noise).
#[allow(clippy::too_many_arguments)]
pub(super) fn polish_set(
    ctx: &Search<'_>,
    cands: &mut [RefineCandidate],
    set: &[usize],
    current: &mut Eval,
    steps: &mut Vec<RefineStep>,
    polished: &mut [bool],
    m: f64,
    threshold: f64,
) -> Result<()> {
    // Far from the noise level something larger than a threshold's shape is missing;
    // the terms are polished once the set gets close (every calibration here is a full
    // free-run fit, and stand-ins of an unexplained effect are not worth them).
    if current.cost > POLISH_GATE {
        return Ok(());
    }
    let first_new = ctx.base.terms().len();
    for pos in 0..set.len() {
        let i = set[pos];
        if std::mem::replace(&mut polished[i], true) {
            continue;
        }
        for (p, &k) in set.iter().enumerate() {
            if let Some(t) = current.model.terms().get(first_new + p) {
                cands[k].coefficient = t.coefficient;
            }
        }
        if let Some((cand, eval, step)) = polish(ctx, cands, set, pos, current)?
            && m * (eval.cost - current.cost) < threshold
        {
            cands[i] = cand;
            *current = eval;
            steps.push(step);
        }
    }
    Ok(())
}

/// The end-of-search simplifications: [`merge_same_law`], then [`simplify_input_pair`].
#[allow(clippy::too_many_arguments)]
pub(super) fn simplify(
    ctx: &Search<'_>,
    cands: &mut [RefineCandidate],
    set: &mut Vec<usize>,
    current: &mut Eval,
    steps: &mut Vec<RefineStep>,
    m: f64,
    threshold: f64,
) -> Result<()> {
    merge_same_law(ctx, cands, set, current, steps, m, threshold)?;
    simplify_input_pair(ctx, cands, set, current, steps, m, threshold)
}

/// Two terms of one shaped law — same effect with shaping parameters, same equation,
/// transfer target and variables, different parameters — are usually one law at a
/// parameter between them (two dead zones at 0.28 and 0.22 with coefficients −1.3 and
/// +0.34 stand in for one at 0.3 with −0.96). Try that: keep the term with the larger
/// coefficient, give it the sum, calibrate its parameter again, and take the merged set
/// unless it fits significantly worse (`M·ΔJ·N_eff/N` above `threshold`). Repeats while a
/// merge is taken.
#[allow(clippy::too_many_arguments)]
pub(super) fn merge_same_law(
    ctx: &Search<'_>,
    cands: &mut [RefineCandidate],
    set: &mut Vec<usize>,
    current: &mut Eval,
    steps: &mut Vec<RefineStep>,
    m: f64,
    threshold: f64,
) -> Result<()> {
    let first_new = ctx.base.terms().len();
    loop {
        let coefficient = |eval: &Eval, p: usize| {
            eval.model
                .terms()
                .get(first_new + p)
                .map_or(0.0, |t| t.coefficient)
        };
        let same_law = |a: &RefineCandidate, b: &RefineCandidate| {
            a.effect == b.effect
                && a.state == b.state
                && a.into == b.into
                && a.variables == b.variables
                && a.term != b.term
                && Effect::from_name(&a.effect).is_some_and(|e| !shaping_parameters(e).is_empty())
        };
        let pair = (0..set.len())
            .flat_map(|a| (a + 1..set.len()).map(move |b| (a, b)))
            .find(|&(a, b)| same_law(&cands[set[a]], &cands[set[b]]));
        let Some((a, b)) = pair else {
            return Ok(());
        };
        let (ca, cb) = (coefficient(current, a), coefficient(current, b));
        let (keep, drop) = if ca.abs() >= cb.abs() { (a, b) } else { (b, a) };
        let mut trial_cands = cands.to_vec();
        for (p, &k) in set.iter().enumerate() {
            trial_cands[k].coefficient = coefficient(current, p);
        }
        trial_cands[set[keep]].coefficient = ca + cb;
        let trial: Vec<usize> = set
            .iter()
            .enumerate()
            .filter(|&(p, _)| p != drop)
            .map(|(_, &i)| i)
            .collect();
        let Some(mut merged) = evaluate(ctx, &trial_cands, &trial, 0)? else {
            return Ok(());
        };
        let pos = trial.iter().position(|&i| i == set[keep]).unwrap_or(0);
        if let Some((cand, eval, _)) = polish(ctx, &trial_cands, &trial, pos, &merged)?
            && eval.cost < merged.cost
        {
            trial_cands[trial[pos]] = cand;
            merged = eval;
        }
        let statistic = m * (merged.cost - current.cost) * current.neff_ratio;
        if statistic >= threshold {
            return Ok(());
        }
        steps.push(RefineStep {
            action: "merge".into(),
            effect: cands[set[keep]].effect.clone(),
            term: format!(
                "{} + {} → {}",
                cands[set[keep]].term, cands[set[drop]].term, trial_cands[trial[pos]].term
            ),
            cost: [current.cost, merged.cost],
            statistic,
            threshold,
        });
        cands.clone_from_slice(&trial_cands);
        *set = trial;
        *current = merged;
    }
}

/// The identity move at the end of the search (see [`input_identity`]): rewrite an input
/// gain and a saturation (or dead zone) at the same threshold as the other law alone,
/// unless that fits significantly worse (`M·ΔJ` above `threshold`).
fn simplify_input_pair(
    ctx: &Search<'_>,
    cands: &mut [RefineCandidate],
    set: &mut Vec<usize>,
    current: &mut Eval,
    steps: &mut Vec<RefineStep>,
    m: f64,
    threshold: f64,
) -> Result<()> {
    let first_new = ctx.base.terms().len();
    let coefficients: Vec<f64> = (0..set.len())
        .map(|p| {
            current
                .model
                .terms()
                .get(first_new + p)
                .map_or(0.0, |t| t.coefficient)
        })
        .collect();
    if let Some((pg, pl, k, replacement)) = input_identity(cands, set, &coefficients) {
        let mut trial_cands = cands.to_vec();
        trial_cands[k] = replacement;
        let mut trial: Vec<usize> = set
            .iter()
            .enumerate()
            .filter(|(p, _)| *p != pg && *p != pl)
            .map(|(_, &i)| i)
            .collect();
        trial.push(k);
        if let Some(e) = evaluate(ctx, &trial_cands, &trial, 0)?
            && m * (e.cost - current.cost) * current.neff_ratio < threshold
        {
            steps.push(RefineStep {
                action: "simplify".into(),
                effect: format!(
                    "{} + {} → {}",
                    cands[set[pg]].effect, cands[set[pl]].effect, trial_cands[k].effect
                ),
                term: format!(
                    "{} + {} → {}",
                    cands[set[pg]].term, cands[set[pl]].term, trial_cands[k].term
                ),
                cost: [current.cost, e.cost],
                statistic: m * (e.cost - current.cost) * current.neff_ratio,
                threshold,
            });
            cands.clone_from_slice(&trial_cands);
            *set = trial;
            *current = e;
        }
    }
    Ok(())
}

/// Step in `ln p` of the profile used for a shaping parameter's uncertainty.
const PROFILE_STEP: f64 = 0.05;

/// The variance each term's coefficient gains from the uncertainty of the set's shaping
/// parameters (one entry per position of `set`): the calibrated coefficients are
/// conditional on the parameters, so their Gauss–Newton σ is too narrow when a parameter
/// is itself estimated. From the profile at `ln p ± h` (everything else re-calibrated):
/// `Var(ln p) = 2 / (M·∂²J/∂(ln p)²)` (`M·J` is a χ² in the residual), inflated by
/// `N/N_eff` like the coefficients, and the profile's slope `∂c_k/∂ln p` carries it to
/// every coefficient: `Var_k += (∂c_k/∂ln p)²·Var(ln p)`. A parameter whose profile is
/// not convex there contributes nothing (it was not moved from the library's value, or
/// the data cannot tell).
pub(super) fn parameter_variance(
    ctx: &Search<'_>,
    cands: &[RefineCandidate],
    set: &[usize],
    current: &Eval,
) -> Result<Vec<f64>> {
    let mut extra = vec![0.0; set.len()];
    let first_new = ctx.base.terms().len();
    let measured = measured_values(ctx.data);
    let config = one_stage(ctx.config);
    let trial_ctx = Search {
        config: &config,
        x0: &current.x0,
        ..*ctx
    };
    for &i in set {
        let Some(effect) = Effect::from_name(&cands[i].effect) else {
            continue;
        };
        if cands[i].parameters.len() != effect.parameters().len() {
            continue;
        }
        for &q in shaping_parameters(effect) {
            let p = cands[i].parameters[q];
            if !(p.is_finite() && p > 0.0) {
                continue;
            }
            let mut evals = Vec::with_capacity(3);
            for s in [-PROFILE_STEP, 0.0, PROFILE_STEP] {
                let Some(c) = with_parameter(&cands[i], q, p * s.exp()) else {
                    break;
                };
                let mut trial = cands.to_vec();
                trial[i] = c;
                match evaluate_on_data(&trial_ctx, &trial, set, 0)? {
                    Some(e) => evals.push(e),
                    None => break,
                }
            }
            let [minus, centre, plus] = evals.as_slice() else {
                continue;
            };
            let curvature =
                (plus.cost + minus.cost - 2.0 * centre.cost) / (PROFILE_STEP * PROFILE_STEP);
            if !(curvature.is_finite() && curvature > 0.0) {
                continue;
            }
            let var_log_p = 2.0 / (measured as f64 * curvature) / centre.neff_ratio;
            for (k, e) in extra.iter_mut().enumerate() {
                let coefficient = |ev: &Eval| {
                    ev.model
                        .terms()
                        .get(first_new + k)
                        .map_or(f64::NAN, |t| t.coefficient)
                };
                let slope = (coefficient(plus) - coefficient(minus)) / (2.0 * PROFILE_STEP);
                if slope.is_finite() {
                    *e += slope * slope * var_log_p;
                }
            }
        }
    }
    Ok(extra)
}

/// The input-nonlinearity identity `sat_L(u) = u − dz_L(u)` (the saturation term is the
/// excess over the limit, the dead-zone term the part below the width): `g·u + s·sat_L`
/// with `g ≈ −s` is the single term `−s·dz_L`, and `g·u + s·dz_L` with `g ≈ −s` is
/// `−s·sat_L`. The search can reach the two-term form (the input gain first, then the
/// other law at the right threshold); this move offers the one-term form. Returns the
/// positions in `set` of the gain and the law, and the replacement (the complementary
/// law at the same threshold, coefficient `−s`, re-written from `cands`' own entry for
/// it, whose index is returned too).
pub(super) fn input_identity(
    cands: &[RefineCandidate],
    set: &[usize],
    coefficients: &[f64],
) -> Option<(usize, usize, usize, RefineCandidate)> {
    for (pg, &g) in set.iter().enumerate() {
        let gain = &cands[g];
        if gain.effect != Effect::InputGain.name() || gain.into.is_some() {
            continue;
        }
        for (pl, &l) in set.iter().enumerate() {
            let law = &cands[l];
            let other = match Effect::from_name(&law.effect) {
                Some(Effect::InputSaturation) => Effect::DeadZone,
                Some(Effect::DeadZone) => Effect::InputSaturation,
                _ => continue,
            };
            if law.state != gain.state
                || law.into.is_some()
                || law.variables.first() != Some(&gain.term)
                || law.parameters.len() != 1
            {
                continue;
            }
            let Some(k) = (0..cands.len()).find(|&k| {
                let c = &cands[k];
                !set.contains(&k)
                    && c.effect == other.name()
                    && c.state == law.state
                    && c.into.is_none()
                    && c.variables == law.variables
            }) else {
                continue;
            };
            let Some(mut replacement) = with_parameter(&cands[k], 0, law.parameters[0]) else {
                continue;
            };
            replacement.coefficient = -coefficients.get(pl).copied().unwrap_or(0.0);
            return Some((pg, pl, k, replacement));
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Re-writing a saturation term at another limit changes only the limit.
    #[test]
    fn parameters_rewrite_the_template() {
        let cand = RefineCandidate {
            effect: "input_saturation".into(),
            state: "v".into(),
            into: None,
            term: Effect::InputSaturation.template(&["u"], &[0.865]),
            coefficient: -0.5,
            variables: vec!["u".into()],
            parameters: vec![0.865],
        };
        let c = with_parameter(&cand, 0, 1.0).unwrap_or_else(|| panic!("rewrite"));
        assert_eq!(c.term, Effect::InputSaturation.template(&["u"], &[1.0]));
        assert_eq!(c.parameters, vec![1.0]);
        assert!(with_parameter(&cand, 1, 1.0).is_none());
        let unknown = RefineCandidate {
            variables: vec![],
            ..cand
        };
        assert!(with_parameter(&unknown, 0, 1.0).is_none());
    }

    /// `sign(u)·max(|u| − L, 0) = u − sign(u)·min(|u|, L)` at sample points, so the
    /// identity move's replacement is exact: `g·u + s·sat_L = −s·dz_L` when `g = −s`.
    #[test]
    fn saturation_plus_gain_is_a_dead_zone() {
        let vars = ["u"];
        let sat = Effect::InputSaturation.template(&vars, &[0.3]);
        let dz = Effect::DeadZone.template(&vars, &[0.3]);
        let sat = sysid_core::Expr::parse(&sat, &vars).unwrap_or_else(|e| panic!("{e}"));
        let dz = sysid_core::Expr::parse(&dz, &vars).unwrap_or_else(|e| panic!("{e}"));
        for u in [-1.3, -0.31, -0.2, 0.0, 0.05, 0.29, 0.3, 0.7, 2.0] {
            let two = -0.9 * u + 0.9 * sat.eval_parts(&[], &[u]);
            let one = -0.9 * dz.eval_parts(&[], &[u]);
            assert!((two - one).abs() < 1e-14, "u = {u}: {two} vs {one}");
        }
        let cand = |effect: Effect, term: String, parameters: Vec<f64>| RefineCandidate {
            effect: effect.name().into(),
            state: "v".into(),
            into: None,
            term,
            coefficient: 0.0,
            variables: if parameters.is_empty() {
                vec![]
            } else {
                vec!["u".into()]
            },
            parameters,
        };
        let cands = vec![
            cand(Effect::InputGain, "u".into(), vec![]),
            cand(
                Effect::InputSaturation,
                Effect::InputSaturation.template(&vars, &[0.3]),
                vec![0.3],
            ),
            cand(
                Effect::DeadZone,
                Effect::DeadZone.template(&vars, &[0.1]),
                vec![0.1],
            ),
        ];
        let (pg, pl, k, r) =
            input_identity(&cands, &[0, 1], &[-0.9, 0.9]).unwrap_or_else(|| panic!("no move"));
        assert_eq!((pg, pl, k), (0, 1, 2));
        assert_eq!(r.term, Effect::DeadZone.template(&vars, &[0.3]));
        assert!((r.coefficient + 0.9).abs() < 1e-15);
        assert!(input_identity(&cands, &[1], &[0.9]).is_none());
    }
}
