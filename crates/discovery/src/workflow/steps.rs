//! The workflow's steps between decisions: trimming, free runs, the noise floor of `d̂`,
//! the candidate list of a round, the alternative explanation of partial observation.

use super::*;

/// Drop `fraction` of the samples at each end of every record.
pub(super) fn trim_ends(samples: &[Samples], fraction: f64) -> crate::Result<Vec<Samples>> {
    samples
        .iter()
        .map(|s| {
            let n = s.len();
            let cut = ((n as f64) * fraction).floor() as usize;
            let keep = n.saturating_sub(2 * cut).max(1);
            let start = cut.min(n - keep);
            Samples::new(
                s.states().columns(start, keep).into_owned(),
                s.inputs().columns(start, keep).into_owned(),
                s.corrections().columns(start, keep).into_owned(),
            )
        })
        .collect()
}

/// Free-run states of `model` over one record from `x0` (default integrator, inputs
/// between samples as the record says).
pub(super) fn free_run_states(
    model: &TermModel,
    x0: &[f64],
    exp: &Experiment,
) -> sysid_core::Result<DMatrix<f64>> {
    sysid_core::simulate_experiment(
        model,
        x0,
        exp,
        0..exp.len(),
        &sysid_core::Integrator::default(),
        sysid_core::integrate::DEFAULT_BLOW_UP,
    )
}

/// The validation check of a round (the rule of [`crate::validation`]: initial state of
/// every record fitted to its first `window` samples, free run over the whole record,
/// `(1/M) Σ r²/R` with the noise variance `noise`): why `augmented` is rejected against
/// `current`, the model it augments, or `None` when it passes. It is rejected when its
/// free run fails on a record (diverges, or its initial state cannot be fitted) — the
/// reason names the record and the failure, no cost — or when its cost is not below
/// `current`'s. When `current`'s own run fails, `augmented`'s succeeding passes.
pub(super) fn validation_rejection(
    current: &TermModel,
    augmented: &TermModel,
    data: &Dataset,
    window: usize,
    noise: &[f64],
) -> Option<String> {
    let run = |m: &TermModel| {
        crate::validation::validation_run(m, m.linear(), data, window, noise, false)
    };
    let after = match run(augmented) {
        Ok(r) => r,
        Err(e) => {
            return Some(format!(
                "the augmented model fails on the validation data: {e}"
            ));
        }
    };
    let before = run(current).ok()?;
    (after.cost >= before.cost).then(|| {
        format!(
            "validation free-run error did not fall (initial state fitted to the first \
             {window} samples of every record): (1/M) Σ r²/R {:.4e} → {:.4e}; fit {} → {}",
            before.cost,
            after.cost,
            before.fit_summary(),
            after.fit_summary(),
        )
    })
}

/// RMS of MME's `d̂` per corrected equation, by name.
pub fn d_rms(est: &MmeEstimate) -> BTreeMap<String, f64> {
    let mut out = BTreeMap::new();
    for (i, name) in est.correction_names.iter().enumerate() {
        let (mut s, mut n) = (0.0, 0usize);
        for e in &est.experiments {
            for v in e.corrections.row(i).iter() {
                s += v * v;
                n += 1;
            }
        }
        out.insert(name.clone(), (s / n.max(1) as f64).sqrt());
    }
    out
}

/// Noise floor of `d̂`: simulate `model` itself (free-run from MME's `x̂(t0)`), add
/// measurement noise of the estimated variance, and run MME at the same `W` and `R`
/// (inputs between samples as the record says, for the simulation and for MME).
pub(super) fn noise_floor<M: Mme>(
    mme: &M,
    model: &TermModel,
    data: &Dataset,
    est: &MmeEstimate,
    seed: u64,
) -> Result<NoiseFloor, M::Error> {
    let c = model.linear().c();
    let mut experiments = Vec::new();
    for (i, (exp, e)) in data.experiments().iter().zip(&est.experiments).enumerate() {
        let x0: Vec<f64> = e.states.column(0).iter().copied().collect();
        let xs = free_run_states(model, &x0, exp).map_err(DiscoveryError::from)?;
        let noise = crate::judge::gaussian_noise(&est.noise_variance, exp.len(), seed, i as u64);
        let y = c * xs + noise;
        experiments.push(
            Experiment::new(exp.t0(), exp.dt(), exp.inputs().clone(), y)
                .map_err(DiscoveryError::from)?
                .with_intersample(exp.intersample()),
        );
    }
    let names = |v: Vec<String>| v.into_iter().map(Channel::new).collect::<Vec<_>>();
    let sim = Dataset::new(
        names(data.input_names()),
        names(data.output_names()),
        experiments,
    )
    .map_err(DiscoveryError::from)?;
    let out = match mme.estimate_fixed(model, &sim, &est.w, &est.noise_variance, None) {
        Ok(out) => out,
        Err(_) => {
            let x0s = x0_of(est);
            mme.estimate_fixed(model, &sim, &est.w, &est.noise_variance, Some(&x0s))?
        }
    };
    Ok(NoiseFloor::from_estimate(&out)?)
}

/// The search's set as `equation: term` lines (`a→b: term` for a transfer).
pub(super) fn term_labels(list: &[RefineCandidate], selected: &[usize]) -> Vec<String> {
    selected
        .iter()
        .map(|&i| {
            let c = &list[i];
            match &c.into {
                Some(r) => format!("{}→{r}: {}", c.state, c.term),
                None => format!("{}: {}", c.state, c.term),
            }
        })
        .collect()
}

/// When `refined` (indexing `chosen_from`) touches a state of free scale, the best set
/// `search` finds over `candidates` without those terms (starting from the others), with
/// both sets' judged costs; `None` when it touches none or the model has no such state.
pub(super) fn alternative_explanation(
    model: &TermModel,
    search: &Search<'_>,
    candidates: &[RefineCandidate],
    refined: &Refinement,
    chosen_from: &[RefineCandidate],
) -> crate::Result<Option<Ambiguity>> {
    let linear = model.linear();
    let free = crate::scale_free_states(linear);
    if free.is_empty() {
        return Ok(None);
    }
    let (touching, keep): (Vec<RefineCandidate>, Vec<RefineCandidate>) = refined
        .selected
        .iter()
        .map(|&i| chosen_from[i].clone())
        .partition(|c| crate::touches(c, linear, &free));
    if touching.is_empty() {
        return Ok(None);
    }
    let (list, start) = crate::ban_touching(candidates, &touching, &keep);
    let (alt, alt_list) = crate::refine_with_transfers(search, &list, &start)?;
    let names = linear.state_names();
    Ok(Some(Ambiguity {
        free_states: free.iter().map(|&j| names[j].clone()).collect(),
        named: term_labels(chosen_from, &refined.selected),
        named_cost: refined.cost[1],
        alternative: term_labels(&alt_list, &alt.selected),
        alternative_cost: alt.cost[1],
    }))
}

/// The candidate list of a round: every library term of the corrected equations, with
/// the regression's proposals (found or not in the library) as the starting set.
pub(super) fn round_candidates(
    model: &TermModel,
    units: &BTreeMap<String, String>,
    roles: &[(String, Role)],
    samples: &[Samples],
    proposed: &[FoundEffect],
) -> crate::Result<(Vec<RefineCandidate>, Vec<usize>)> {
    let linear = model.linear();
    let roles = StateRoles::infer(linear, units, roles)?;
    let library = LibraryConfig {
        connections: crate::term_connections(model),
        ..LibraryConfig::default()
    };
    let libraries = build_library(linear, &roles, units, samples, &library)?;
    let mut candidates: Vec<RefineCandidate> = Vec::new();
    for lib in &libraries {
        for c in &lib.candidates {
            candidates.push(RefineCandidate {
                effect: c.model_effect.name().to_string(),
                state: c.state.clone(),
                into: None,
                term: c.model_term.clone(),
                coefficient: 0.0,
                variables: c.variables.clone(),
                parameters: c.model_parameters.clone(),
            });
        }
    }
    let mut initial = Vec::new();
    for e in proposed {
        match candidates
            .iter()
            .position(|c| c.into.is_none() && c.state == e.state && c.term == e.model_term)
        {
            Some(i) => {
                candidates[i].coefficient = e.coefficient;
                initial.push(i);
            }
            None => {
                candidates.push(RefineCandidate {
                    effect: e.model_effect.clone(),
                    state: e.state.clone(),
                    into: None,
                    term: e.model_term.clone(),
                    coefficient: e.coefficient,
                    variables: vec![],
                    parameters: vec![],
                });
                initial.push(candidates.len() - 1);
            }
        }
    }
    Ok((candidates, initial))
}

/// `model` without the terms at `drop` (indices into its term list).
pub(super) fn without(model: &TermModel, drop: &[usize]) -> crate::Result<TermModel> {
    let (linear, terms) = model.clone().into_parts();
    let kept: Vec<_> = terms
        .into_iter()
        .enumerate()
        .filter(|(k, _)| !drop.contains(k))
        .map(|(_, t)| t)
        .collect();
    Ok(TermModel::new(linear, kept)?)
}

/// MME with the assumed model, the workflow's first estimate: from MME's data-based start,
/// and when that finds no finite solution, from the open-loop run of the model from
/// initial states fitted by free-run error on every record
/// ([`crate::augment::fit_initial_states`], default calibration settings). The
/// data-based start puts an unmeasured state at 0 (the minimum-norm `C⁺y`), where a term
/// such as a tank's `√|h|` has no finite slope: with the upper level unmeasured, a
/// Torricelli model of two cascaded tanks stopped there with "no finite rollout found".
/// When the retry fails too, the data-based start's error is returned.
pub(super) fn first_estimate<M: Mme>(
    mme: &M,
    model: &TermModel,
    data: &Dataset,
) -> Result<MmeEstimate, M::Error> {
    match mme.estimate(model, data, None) {
        Ok(e) => Ok(e),
        Err(error) => {
            let Ok(fit) =
                crate::augment::fit_initial_states(model, data, &[], &CalibrationConfig::default())
            else {
                return Err(error);
            };
            mme.estimate(model, data, Some(&fit.x0)).map_err(|_| error)
        }
    }
}

/// Initial states of every record from MME's `x̂(t0)`.
pub(super) fn x0_of(est: &MmeEstimate) -> Vec<Vec<f64>> {
    est.experiments
        .iter()
        .map(|e| e.states.column(0).iter().copied().collect())
        .collect()
}

/// The flexible stand-in on MME's estimate with the final `model` (`at_hand`, else run
/// here, from `previous`'s initial states when the data start fails): the stand-in or why
/// it did not run, and the estimate when it was run here.
pub(super) fn final_stand_in<M: Mme + Sync>(
    mme: &M,
    model: &TermModel,
    data: &Dataset,
    at_hand: Option<&MmeEstimate>,
    previous: &MmeEstimate,
    config: &WorkflowConfig,
) -> (Option<StandIn>, Option<String>, Option<MmeEstimate>) {
    let (est, fresh) = match at_hand {
        Some(e) => (e.clone(), false),
        None => match mme
            .estimate(model, data, None)
            .or_else(|_| mme.estimate(model, data, Some(&x0_of(previous))))
        {
            Ok(e) => (e, true),
            Err(e) => {
                return (
                    None,
                    Some(format!("MME with the final model failed: {e}")),
                    None,
                );
            }
        },
    };
    let standin_config = StandInConfig {
        draws: config.stand_in_draws,
        trim_fraction: config.trim_fraction,
        seed: config.seed.wrapping_add(29),
        ..StandInConfig::default()
    };
    let rerun = |sim: &Dataset, x0: &[Vec<f64>]| {
        mme.estimate_fixed(model, sim, &est.w, &est.noise_variance, None)
            .or_else(|_| mme.estimate_fixed(model, sim, &est.w, &est.noise_variance, Some(x0)))
            .ok()
    };
    let (s, note) = match crate::standin::stand_in(model, data, &est, &standin_config, rerun) {
        Ok(s) => (Some(s), None),
        Err(e) => (None, Some(format!("the stand-in could not run: {e}"))),
    };
    (s, note, fresh.then_some(est))
}
