//! The discovery workflow: the rounds, the noise floor of `d̂`, the acceptance of a
//! round, the claim and the verdict — the whole decision layer, with MME passed in
//! through [`Mme`] so that this crate never calls mme-core.
//!
//! A round: MME → noise floor of `d̂` (MME on data simulated from the current model
//! itself with the same noise, `W` and `R`) → proposal from `d̂` ([`crate::propose`]) →
//! free-run search over the catalogue ([`crate::refine_with_transfers`]) → proof (MME
//! with the augmented model leaves less to correct; validation free run no worse) →
//! next round, at most `max_rounds`. The verdict is judged against the bootstrap
//! reference of the protocol that produced it ([`crate::judge`]), the claimed terms
//! pruned of passengers by the same test.

use std::collections::BTreeMap;

use nalgebra::DMatrix;
use sysid_core::{Channel, Dataset, Experiment, MmeEstimate, TermModel};

use crate::error::DiscoveryError;
use crate::floor::NoiseFloor;
use crate::judge::BootstrapJudgement;
use crate::localise::{FreeRun, LocaliseConfig, localise};
use crate::propose::{DiscoveryConfig, FoundEffect, Verdict, propose};
use crate::refine::{Holdout, RefineCandidate, RefineConfig, Refinement, Search};
use crate::samples::{Samples, samples_from_estimate};
use crate::standin::{StandIn, StandInConfig};
use crate::{
    CalibrationConfig, Effect, InitialState, LibraryConfig, OutputWeights, Role, StateRoles,
    build_library, calibrate, measured_values,
};
use holdout::{holdout_initial_states, recalibrate_on, split_records};

mod context;
mod holdout;
mod plan;
mod report;
mod steps;

pub use context::claim_bound;
use context::{JudgeContext, noise_level_bound};
use plan::Plan;
pub use plan::{FINAL_STEPS, Observer, STEPS_PER_ROUND, Silent};

pub use report::{Ambiguity, AssumedEntry, NamedEffect, Round};
pub use steps::d_rms;
use steps::{
    alternative_explanation, final_stand_in, first_estimate, free_run_states, noise_floor,
    round_candidates, trim_ends, validation_rejection, without, x0_of,
};

/// Largest free-run cost `J = (1/M) Σ r²/R` (1 for a right model and right noise
/// variance) at which named effects are claimed when `R` is estimated and the bootstrap
/// judge cannot run: twice the noise power leaves room for an estimated `R` and a
/// coloured residual, but not for a missing effect. With `R` given, it also ends the
/// rounds: a round that leaves the cost above it is not proven by MME.
pub const CONFIRM_COST: f64 = 2.0;

/// MME as the workflow needs it, implemented by the caller (the facade, with mme-core).
pub trait Mme {
    /// The caller's error; discovery's own errors convert into it.
    type Error: From<DiscoveryError> + std::fmt::Display;

    /// MME with `model` on `data`, `W` and the noise variance as the caller configured
    /// them (given, or estimated). `start`: initial states (one per record) whose
    /// open-loop run starts the solver instead of its default data-based start — the
    /// workflow retries with them when the default start fails (a term like `√|h|` on an
    /// unmeasured state is singular where the data-based start puts that state, at 0).
    fn estimate(
        &self,
        model: &TermModel,
        data: &Dataset,
        start: Option<&[Vec<f64>]>,
    ) -> Result<MmeEstimate, Self::Error>;

    /// MME with `model` on `data` at a fixed weight `w` and noise variance `noise`
    /// (the noise floor's run); `start` as in [`Mme::estimate`].
    fn estimate_fixed(
        &self,
        model: &TermModel,
        data: &Dataset,
        w: &DMatrix<f64>,
        noise: &[f64],
        start: Option<&[Vec<f64>]>,
    ) -> Result<MmeEstimate, Self::Error>;
}

/// Settings of [`run`].
#[derive(Debug, Clone, PartialEq)]
pub struct WorkflowConfig {
    /// Most discover–augment rounds.
    pub max_rounds: usize,
    /// Seed of the noise-floor simulation and of the bootstrap judge.
    pub seed: u64,
    /// Samples used to fit free-run initial states of validation records.
    pub x0_window: usize,
    /// Fraction of samples dropped at each end of every record before selection: a
    /// smoother's `d̂` is least reliable at the ends (end effects), and on a decaying
    /// response the ends carry the largest states, hence the most leverage. Default 0.05.
    pub trim_fraction: f64,
    /// Smallest relative drop of `d̂`'s mean square (over its floor) that accepts a
    /// round's terms. Default 0.1.
    pub min_d_drop: f64,
    /// Without validation records, the fraction at the end of every estimation record
    /// held out to judge the free-run search's candidate sets (coefficients are calibrated
    /// on the rest). 0 judges on the estimation records themselves. Default 0.5 (0.3
    /// named quadratic drag for viscous damping on the decaying MSD record, whose last
    /// 30 % holds only small velocities; 0.2 and 0.5 named it right).
    pub holdout_fraction: f64,
    /// Whether the noise variance is given (`true`) or estimated by MME (`false`).
    pub noise_given: bool,
    /// Reference draws of the flexible stand-in (`standin`), which a `found` or
    /// `none` verdict must also pass; 0 skips it. Default 12.
    pub stand_in_draws: usize,
    /// Roles given by the user, by state name, replacing the inferred ones
    /// ([`StateRoles::infer`]): e.g. a level read in volts, whose unit alone makes it
    /// [`Role::Other`]. Default none.
    pub roles: Vec<(String, Role)>,
}

impl Default for WorkflowConfig {
    fn default() -> Self {
        Self {
            max_rounds: 3,
            seed: 1,
            x0_window: 200,
            trim_fraction: 0.05,
            min_d_drop: 0.1,
            holdout_fraction: 0.5,
            noise_given: false,
            stand_in_draws: 12,
            roles: Vec::new(),
        }
    }
}

/// A term the workflow added to the assumed model, as a model file writes it.
#[derive(Debug, Clone, PartialEq)]
pub struct AddedTerm {
    /// State equation it enters.
    pub state: String,
    /// For a transfer: the equation that receives the negated term.
    pub into: Option<String>,
    /// Catalogue name of the effect.
    pub effect: String,
    /// The expression, in state and input names.
    pub term: String,
    /// Its coefficient.
    pub coefficient: f64,
}

/// What [`run`] decided.
#[derive(Debug, Clone)]
pub struct Outcome {
    /// `found` if a claimed set of terms brings the model to the noise level;
    /// `unexplained` if a round was rejected, terms stayed unconfirmed or the model stays
    /// above the noise level; else `none`.
    pub verdict: Verdict,
    /// Every claimed effect, with its calibrated coefficient and intervals.
    pub effects: Vec<NamedEffect>,
    /// Terms that improved the model (and are in [`Outcome::model`]) but were not claimed.
    pub unconfirmed: Vec<NamedEffect>,
    /// The judged cost below which effects are claimed: the bootstrap reference quantile
    /// when the judge ran, else [`claim_bound`].
    pub claim_bound: f64,
    /// The judged statistic and its bootstrap reference.
    pub judgement: Option<BootstrapJudgement>,
    /// Why the bootstrap judge did not decide, when it did not.
    pub judge_note: Option<String>,
    /// Terms dropped as passengers (with the judged cost without them).
    pub passengers: Vec<String>,
    /// When nothing was claimed because two explanations fit (partial observation).
    pub ambiguity: Option<Ambiguity>,
    /// Every round.
    pub rounds: Vec<Round>,
    /// The final model: the assumed one plus [`Outcome::added`].
    pub model: TermModel,
    /// Terms appended to the assumed model, in order.
    pub added: Vec<AddedTerm>,
    /// MME with the assumed model.
    pub first_estimate: MmeEstimate,
    /// MME with the final model, when it ran on exactly that model.
    pub final_estimate: Option<MmeEstimate>,
    /// The flexible stand-in on MME's `d̂` with the final model and its reference (see
    /// `standin`): it decides between `found`/`none` and `unexplained`, and is
    /// evidence of what remains on an `unexplained` verdict when MME's estimate with the
    /// final model is at hand. `None` when it did not run: an `unexplained` verdict
    /// without that estimate, switched off, or failed (`stand_in_note` says why).
    pub stand_in: Option<StandIn>,
    /// Why the stand-in did not decide, when it ran and failed.
    pub stand_in_note: Option<String>,
}

/// Run the discovery workflow on `data` (estimation records) with the assumed `model`
/// (with its unit annotations `units`), judging candidate sets on `validation` when
/// given (else on the held-out end of every estimation record).
///
/// MME's own failure on the assumed model is returned as the caller's error; after an
/// accepted round, a model MME cannot handle ends the search.
pub fn run<M: Mme + Sync>(
    mme: &M,
    model: &TermModel,
    units: &BTreeMap<String, String>,
    data: &Dataset,
    validation: Option<&Dataset>,
    config: &WorkflowConfig,
    observer: &dyn Observer,
) -> Result<Outcome, M::Error> {
    let observer = &Plan::new(observer, config.max_rounds.max(1));
    let outcome = run_planned(mme, model, units, data, validation, config, observer);
    observer.finish();
    outcome
}

/// [`run`] with its steps counted.
fn run_planned<M: Mme + Sync>(
    mme: &M,
    model: &TermModel,
    units: &BTreeMap<String, String>,
    data: &Dataset,
    validation: Option<&Dataset>,
    config: &WorkflowConfig,
    observer: &Plan<'_>,
) -> Result<Outcome, M::Error> {
    observer.stage(0, "MME with the assumed model");
    let first = first_estimate(mme, model, data)?;
    let x0_guess: Vec<f64> = first.experiments[0]
        .states
        .column(0)
        .iter()
        .copied()
        .collect();
    let n_assumed = model.terms().len();

    let mut current = model.clone();
    let mut added: Vec<AddedTerm> = Vec::new();
    let mut result = first.clone();
    let mut rounds = Vec::new();
    let mut effects: Vec<NamedEffect> = Vec::new();
    let mut first_verdict = None;
    let mut any_rejected = false;
    let mut ambiguity = None;
    // Free-run cost (held-out when given) of the last accepted model.
    let mut accepted_cost = f64::NAN;
    // Whether `result` is MME's estimate with the final model.
    let mut d_after_known = true;
    // Measured values of the records that judged the last free-run search.
    let mut judged_measured = measured_values(data);
    // The protocol of the last free-run search, and of the last round whose terms were
    // kept (what judges the verdict).
    let mut last_ctx: Option<JudgeContext> = None;
    let mut claim_ctx: Option<JudgeContext> = None;
    let mut confirm_cost_stop = false;
    // The bound against which an ambiguity was declared.
    let mut ambiguity_bound: Option<f64> = None;
    for round_no in 1..=config.max_rounds.max(1) {
        let est = &result;
        observer.stage(round_no, "noise floor of d̂");
        // After an accepted round, a model MME cannot handle ends the search (the first
        // round's failure is the user's problem and is reported as an error).
        let floor = match noise_floor(mme, &current, data, est, config.seed) {
            Ok(f) => f,
            Err(_) if !rounds.is_empty() => break,
            Err(e) => return Err(e),
        };
        observer.stage(round_no, "proposal from d̂");
        let all_samples = samples_from_estimate(est, data)?;
        let samples = trim_ends(&all_samples, config.trim_fraction)?;
        let found = propose(
            current.linear(),
            units,
            &samples,
            &floor,
            &DiscoveryConfig {
                library: LibraryConfig {
                    connections: crate::term_connections(&current),
                    ..LibraryConfig::default()
                },
                roles: config.roles.clone(),
                ..DiscoveryConfig::default()
            },
        )?;
        first_verdict.get_or_insert(found.verdict);
        let exp = &data.experiments()[0];
        let x0: Vec<f64> = est.experiments[0]
            .states
            .column(0)
            .iter()
            .copied()
            .collect();
        let xs = free_run_states(&current, &x0, exp).map_err(DiscoveryError::from)?;
        let simulated = current.linear().c() * xs;
        let fr = FreeRun {
            measured: exp.outputs(),
            simulated: &simulated,
            noise_variance: &est.noise_variance,
        };
        let localisation = localise(
            current.linear(),
            &all_samples[0],
            exp.t0(),
            exp.dt(),
            &floor,
            Some(&fr),
            &LocaliseConfig::default(),
        )?;
        // The regression's terms: those of `found` equations, and also those of
        // `unexplained` ones (MME's shrinkage can leave a right term explaining too little
        // of d̂; the free-run search and the proof below decide).
        let proposed: Vec<FoundEffect> = found
            .equations
            .iter()
            .flat_map(|e| e.terms.iter().cloned())
            .collect();
        // With nothing proposed in the first round while `d̂` is above its floor (the
        // regression saw a disagreement it could not name — or `d̂` is so shrunk that it
        // cannot), the free-run search still runs, from the empty set: it adds what
        // lowers the free-run cost significantly, and otherwise measures the assumed
        // model's cost on the judging records, which decides `none` against
        // `unexplained` below. In later rounds the previous search already screened
        // every candidate.
        let stop_now =
            found.verdict == Verdict::None || (proposed.is_empty() && !rounds.is_empty());
        // This round's record, once its outcome is known (each path below builds it once).
        let floor_rms = floor.rms.clone();
        let round = move |refinement, calibrated, calibration_cost, rejected| Round {
            discovery: found,
            localisation,
            floor_rms,
            refinement,
            calibrated,
            calibration_cost,
            rejected,
        };
        if stop_now {
            rounds.push(round(vec![], vec![], [f64::NAN; 2], None));
            break;
        }
        // The regression names candidates; the free-run search decides (see
        // `crate::refine`): every library term of the corrected equations is a
        // candidate, the regression's choice the starting set, coefficients calibrated by
        // free-run simulation error for every set tried.
        let (candidates, initial) =
            round_candidates(&current, units, &config.roles, &samples, &proposed)?;
        let x0s = x0_of(est);
        // Validation records, when given, judge every candidate set (coefficients are
        // calibrated on the estimation data only).
        let val_x0: Option<Vec<Vec<f64>>> = match validation {
            Some(v) => Some(holdout_initial_states(
                &current,
                v,
                &x0_guess,
                config.x0_window,
            )?),
            None => None,
        };
        // Without them, the end of every estimation record is held out (initial states
        // from MME's x̂ at the split).
        let split = match validation {
            None => split_records(data, est, config.holdout_fraction)?,
            Some(_) => None,
        };
        let holdout = match (validation, &val_x0, &split) {
            (Some(v), Some(x), _) => Some(Holdout { data: v, x0: x }),
            (None, _, Some(sp)) => Some(Holdout {
                data: &sp.hold,
                x0: &sp.hold_x0,
            }),
            _ => None,
        };
        judged_measured = measured_values(holdout.map_or(data, |h| h.data));
        let (cal_data, cal_x0) = match &split {
            Some(sp) => (&sp.cal, &sp.cal_x0),
            None => (data, &x0s),
        };
        // Flows the assumed model already routes between two equations are also tried as
        // transfers (one coefficient, both equations; see `crate::transfer`), and the
        // better search is kept with the candidate list it indexes.
        observer.stage(round_no, "free-run search over the catalogue");
        let refine_config = RefineConfig::default();
        let search = Search {
            base: &current,
            data: cal_data,
            x0: cal_x0,
            noise_variance: &est.noise_variance,
            holdout,
            config: &refine_config,
        };
        let (refined, chosen_from) = crate::refine_with_transfers(&search, &candidates, &initial)?;
        let first_new_term = current.terms().len();
        let ctx = JudgeContext {
            model: if refined.selected.is_empty() {
                current.clone()
            } else {
                refined.model.clone()
            },
            new_terms: (first_new_term..first_new_term + refined.selected.len()).collect(),
            cal: cal_data.clone(),
            cal_x0: cal_x0.clone(),
            hold: holdout.map(|h| (h.data.clone(), h.x0.to_vec())),
            noise_variance: est.noise_variance.clone(),
        };
        last_ctx = Some(ctx.clone());
        // The held-out half chose the terms; their coefficients (and intervals) come
        // from the whole estimation records.
        let refined = match &split {
            Some(_) if !refined.selected.is_empty() => {
                recalibrate_on(refined, &current, data, &x0s, &est.noise_variance)
            }
            _ => refined,
        };
        if refined.selected.is_empty() {
            rounds.push(round(refined.steps, vec![], refined.cost, None));
            break;
        }
        // A set that reaches the noise level but touches a state of free scale is
        // claimed only when the search, run again without its terms touching such states,
        // cannot reach the noise level too. "Reaching the noise level" is judged as the
        // verdict is: against the bootstrap reference of the set's own protocol (only
        // computed when the model has states of free scale, the only case in which an
        // alternative is sought).
        let mut claim_now = claim_bound(config.noise_given, judged_measured);
        if !crate::scale_free_states(current.linear()).is_empty() {
            observer.add();
            observer.stage(round_no, "bootstrap judge (ambiguity test)");
            if let Ok(j) = ctx.judge(config.seed) {
                claim_now = j.threshold;
            }
        }
        if refined.cost[1] <= claim_now
            && let Some(found_too) =
                alternative_explanation(&current, &search, &candidates, &refined, &chosen_from)?
            && found_too.alternative_cost <= claim_now
        {
            let why = format!(
                "ambiguous: {{{}}} and, without its terms touching {}, {{{}}} both reach \
                 the noise level (judged cost {:.4} and {:.4} ≤ {claim_now:.4}); the \
                 scale of an unmeasured state is free, so neither is claimed",
                found_too.named.join(", "),
                found_too.free_states.join(", "),
                found_too.alternative.join(", "),
                found_too.named_cost,
                found_too.alternative_cost,
            );
            rounds.push(round(refined.steps, vec![], refined.cost, Some(why)));
            ambiguity = Some(found_too);
            ambiguity_bound = Some(claim_now);
            any_rejected = true;
            break;
        }
        let candidates = chosen_from;
        let first_new = current.terms().len();
        let effects_before_round = effects.len();
        let added_before_round = added.len();
        let calibrated: Vec<f64> = refined.model.terms()[first_new..]
            .iter()
            .map(|t| t.coefficient)
            .collect();
        let augmented = refined.model.clone();
        for (pos, (&i, c)) in refined.selected.iter().zip(&calibrated).enumerate() {
            let ci95_calibrated = refined
                .coefficient_std
                .get(pos)
                .filter(|sd| sd.is_finite())
                .map(|sd| [c - 1.96 * sd, c + 1.96 * sd]);
            let cand = &candidates[i];
            added.push(AddedTerm {
                state: cand.state.clone(),
                into: cand.into.clone(),
                effect: cand.effect.clone(),
                term: cand.term.clone(),
                coefficient: *c,
            });
            // Report the regression's evidence for it when the regression named it.
            // (A transfer's regression evidence covers only its own equation: not reported.)
            let regression = proposed.iter().find(|e| {
                cand.into.is_none() && e.state == cand.state && e.model_term == cand.term
            });
            effects.push(NamedEffect {
                name: cand.effect.clone(),
                state: cand.state.clone(),
                into: cand.into.clone(),
                term: cand.term.clone(),
                coefficient: *c,
                ci95_regression: regression.map(|e| e.ci95),
                share_of_d: regression.map(|e| e.share_of_d),
                parameters: Effect::from_name(&cand.effect)
                    .map(|e| {
                        e.parameters()
                            .iter()
                            .zip(&cand.parameters)
                            .map(|(n, v)| (n.to_string(), *v))
                            .collect()
                    })
                    .unwrap_or_default(),
                adjusts: report::assumed_entry(
                    current.linear(),
                    &cand.state,
                    &cand.term,
                    *c,
                    ci95_calibrated,
                ),
                ci95: ci95_calibrated,
                unit: None,
                reading: None,
                named_by: if regression.is_some() {
                    "regression on d̂, kept by free-run search".into()
                } else {
                    "free-run search".into()
                },
            });
        }
        // Terms that leave the free-run cost far above the noise level will not be claimed:
        // keep the better model (its free-run error fell on the judged records) but skip
        // MME's proof and stop — more rounds would only pile up stand-ins.
        // With `R` estimated the cost is relative to MME's R̂ with the model *before* the
        // round, which a wrong model biases (its correction absorbs part of the noise:
        // on a pendulum missing sin θ, R̂ of ω was a third of the truth); the MME proof
        // below re-estimates R with the augmented model, and the claim is judged against
        // that. So this shortcut applies to a given `R` only.
        if config.noise_given && refined.cost[1] > CONFIRM_COST && refined.cost[1] < refined.cost[0]
        {
            // Kept without MME's proof, but not without the validation check.
            if let Some(why) = validation.and_then(|v| {
                validation_rejection(
                    &current,
                    &augmented,
                    v,
                    config.x0_window,
                    &est.noise_variance,
                )
            }) {
                rounds.push(round(refined.steps, calibrated, refined.cost, Some(why)));
                effects.truncate(effects_before_round);
                added.truncate(added_before_round);
                any_rejected = true;
                break;
            }
            rounds.push(round(
                refined.steps,
                calibrated,
                refined.cost,
                Some(format!(
                    "free-run cost {:.4e} stays above {CONFIRM_COST} × the noise level: the \
                     terms improve the model but are not claimed (MME not rerun)",
                    refined.cost[1]
                )),
            ));
            accepted_cost = refined.cost[1];
            current = augmented;
            d_after_known = false;
            confirm_cost_stop = true;
            claim_ctx = Some(ctx);
            break;
        }
        // Proof before acceptance: the augmented model must leave MME less to correct
        // (total d̂ mean square, relative to the floor, down by at least `min_d_drop`), and,
        // when validation data are given, simulate them free-run no worse than before.
        observer.stage(round_no, "MME with the augmented model (proof)");
        let new_result = match mme
            .estimate(&augmented, data, None)
            .or_else(|_| mme.estimate(&augmented, data, Some(&x0_of(&result))))
        {
            Ok(r) => r,
            Err(e) => {
                rounds.push(round(
                    refined.steps,
                    calibrated,
                    refined.cost,
                    Some(format!("MME failed on the augmented model: {e}")),
                ));
                effects.truncate(effects_before_round);
                added.truncate(added_before_round);
                any_rejected = true;
                break;
            }
        };
        let ms = |e: &MmeEstimate| {
            d_rms(e)
                .values()
                .zip(&floor.rms)
                .map(|(d, f)| (d / f.max(f64::MIN_POSITIVE)).powi(2))
                .sum::<f64>()
        };
        let (ms_before, ms_after) = (ms(&result), ms(&new_result));
        let mut rejection = None;
        let shrank = ms_after <= (1.0 - config.min_d_drop) * ms_before;
        if !shrank {
            rejection = Some(format!(
                "d̂ did not shrink: mean square / floor² {ms_before:.4e} → {ms_after:.4e}"
            ));
        } else if let Some(v) = validation {
            // Both models judged alike, by the rule the report judges them by
            // (`crate::validation`): a free run that diverges or does not improve on the
            // model it augments rejects the round.
            rejection = validation_rejection(
                &current,
                &augmented,
                v,
                config.x0_window,
                &result.noise_variance,
            );
        }
        let accepted = rejection.is_none();
        rounds.push(round(refined.steps, calibrated, refined.cost, rejection));
        if !accepted {
            effects.truncate(effects_before_round);
            added.truncate(added_before_round);
            any_rejected = true;
            break;
        }
        // With R estimated, the round's cost is relative to MME's R with the model before
        // the round, which a far-off model inflates (MME puts unexplained dynamics into
        // the residual); MME with the augmented model estimates R again, and the claim
        // is judged against the smaller estimate, channel by channel (never the larger).
        let inflation = if config.noise_given {
            1.0
        } else {
            est.noise_variance
                .iter()
                .zip(&new_result.noise_variance)
                .map(|(before, after)| before / after)
                .filter(|r| r.is_finite())
                .fold(1.0, f64::max)
        };
        accepted_cost = refined.cost[1] * inflation;
        // With `R` estimated, the claim is judged against MME's R̂ with the model under
        // judgement (the augmented one), channel by channel.
        let mut claim = ctx;
        if !config.noise_given {
            for (r, after) in claim
                .noise_variance
                .iter_mut()
                .zip(&new_result.noise_variance)
            {
                if after.is_finite() && *after > 0.0 {
                    *r = *after;
                }
            }
        }
        claim_ctx = Some(claim);
        current = augmented;
        result = new_result;
    }

    observer.rounds_over();
    // Found: a round was accepted. Unexplained: the library fitted something but the proof
    // failed (never name an effect that does not make the model better).
    // With nothing named, the free-run search's last cost decides between `none` (the
    // model already simulates the (held-out) data to the noise level) and `unexplained`.
    let measured = judged_measured;
    let last_cost = rounds
        .last()
        .map(|r| r.calibration_cost[1])
        .filter(|c| c.is_finite());
    let at_noise_level = |j: f64| j <= noise_level_bound(measured);
    // Named effects are claimed only when they bring the free-run cost down to the noise
    // level; otherwise a combination of catalogue terms may be standing in for something
    // outside the catalogue, or for the right effect in the wrong place.
    //
    // The judged cost is compared with its reference distribution under the pipeline
    // that produced it (`crate::judge`: the model simulated with noise, initial states
    // re-estimated, coefficients recalibrated, the same records judging), so that what
    // the pipeline estimates does not deny a right answer. When that bootstrap cannot
    // run, the fixed bounds decide.
    let mut claim = claim_bound(config.noise_given, measured);
    let mut judgement = None;
    let mut judge_note = None;
    let judged_ctx = if !effects.is_empty() && !confirm_cost_stop {
        claim_ctx.as_ref()
    } else if effects.is_empty() && !any_rejected {
        last_ctx.as_ref().filter(|c| c.new_terms.is_empty())
    } else {
        None
    };
    if let Some(ctx) = judged_ctx {
        observer.stage(rounds.len(), "bootstrap judge (verdict)");
        match ctx.judge(config.seed) {
            Ok(j) => {
                claim = j.threshold;
                judgement = Some(j);
            }
            Err(e) => judge_note = Some(format!("the bootstrap judge could not run: {e}")),
        }
    }
    // Parsimony: of a claimed set, every term must be needed by the same test — a term
    // whose removal (the others recalibrated by the protocol) still leaves the statistic
    // within the reference is dropped (a passenger), and the rest are recalibrated on
    // the whole estimation records.
    let mut passengers: Vec<String> = Vec::new();
    if let (Some(j), Some(ctx)) = (&judgement, judged_ctx)
        && j.accepts()
        && !effects.is_empty()
        && ctx.new_terms.len() > 1
    {
        observer.stage(rounds.len(), "pruning passengers");
        let calibration = RefineConfig::default().calibration;
        let protocol = ctx.protocol(&calibration);
        let dropped =
            crate::judge::prune(&ctx.model, &ctx.new_terms, &protocol, j.threshold)?.dropped;
        if !dropped.is_empty() && current.terms().len() == ctx.model.terms().len() {
            let first_new = ctx.new_terms[0];
            let n_new = ctx.new_terms.len();
            let effects_first = effects.len().saturating_sub(n_new);
            let mut drop_terms: Vec<usize> = dropped.iter().map(|(k, _)| *k).collect();
            drop_terms.sort_unstable();
            for &k in drop_terms.iter().rev() {
                let entry = added.remove(k - n_assumed);
                let e = effects_first + (k - first_new);
                if e < effects.len() {
                    effects.remove(e);
                }
                let stat = dropped
                    .iter()
                    .find(|(d, _)| *d == k)
                    .map_or(f64::NAN, |d| d.1);
                passengers.push(format!(
                    "{} in d({}): {} (without it the judged cost is {stat:.4}, within the \
                     reference quantile {:.4})",
                    entry.effect, entry.state, entry.term, j.threshold
                ));
            }
            current = without(&current, &drop_terms)?;
            let kept_new: Vec<usize> = (first_new..current.terms().len()).collect();
            let calibration_config = CalibrationConfig {
                terms: Some(kept_new.clone()),
                initial_state: InitialState::Estimate,
                weights: OutputWeights::NoiseVariance(ctx.noise_variance.clone()),
                ..calibration
            };
            if let Ok(fit) = calibrate(&current, data, &x0_of(&result), &calibration_config)
                && fit.cost_after.is_finite()
            {
                for &k in &kept_new {
                    let c = fit.coefficients_after[k];
                    added[k - n_assumed].coefficient = c;
                    let e = effects_first + (k - first_new);
                    if let Some(effect) = effects.get_mut(e) {
                        effect.coefficient = c;
                    }
                }
                current = fit.model;
            }
            d_after_known = false;
        }
    }
    if judgement.is_none()
        && let Some(b) = ambiguity_bound
    {
        claim = b;
    }
    let mut unconfirmed = Vec::new();
    let claimed = match &judgement {
        Some(j) => j.accepts(),
        None => !(accepted_cost.is_nan() || accepted_cost > claim),
    };
    if !effects.is_empty() && (confirm_cost_stop || !claimed) {
        unconfirmed = std::mem::take(&mut effects);
    }
    let verdict = if !effects.is_empty() {
        Verdict::Found
    } else if any_rejected || !unconfirmed.is_empty() {
        Verdict::Unexplained
    } else {
        match (&judgement, last_cost) {
            (Some(j), _) if j.accepts() => Verdict::None,
            (Some(_), _) => Verdict::Unexplained,
            (None, Some(j)) if at_noise_level(j) => Verdict::None,
            (None, Some(_)) => Verdict::Unexplained,
            (None, None) => first_verdict.unwrap_or(Verdict::None),
        }
    };
    // The flexible stand-in: a verdict that says nothing is left must also leave MME
    // nothing predictable to correct.
    let mut verdict = verdict;
    let mut stand_in = None;
    let mut stand_in_note = None;
    // On an `unexplained` verdict it runs too when MME's estimate with the final model is
    // at hand, as evidence of what remains (a predictable d̂ points at a missing law of
    // the states and inputs; an unpredictable one at noise or disturbances); it cannot
    // change that verdict.
    let decides = matches!(verdict, Verdict::Found | Verdict::None);
    if config.stand_in_draws > 0 && (decides || d_after_known) {
        observer.stage(rounds.len(), "flexible stand-in on d̂ (reference draws)");
        let at_hand = d_after_known.then_some(&result);
        let (s, note, fresh) = final_stand_in(mme, &current, data, at_hand, &result, config);
        if let Some(s) = &s
            && decides
            && !s.accepts()
        {
            verdict = Verdict::Unexplained;
            unconfirmed.append(&mut effects);
        }
        stand_in = s;
        stand_in_note = note;
        if let Some(est) = fresh {
            result = est;
            d_after_known = true;
        }
    }
    Ok(Outcome {
        verdict,
        effects,
        unconfirmed,
        claim_bound: claim,
        judgement,
        judge_note,
        passengers,
        ambiguity,
        rounds,
        model: current,
        added,
        first_estimate: first,
        final_estimate: d_after_known.then_some(result),
        stand_in,
        stand_in_note,
    })
}

#[cfg(test)]
mod tests;
