//! The K-fold guard ([`GuardHeldOut::Folds`], and [`GuardHeldOut::LastFifthRetrained`] as
//! its one-stretch case): the first training record is cut into K
//! contiguous stretches; for each, MME runs again on the pieces before and after it and
//! on the other records, each on its own (at the whole record's `W` and noise variance: a
//! smoother's `x̂`, `d̂` next to a stretch would otherwise carry information from inside
//! it; docs/decisions/guard-leak-free-mme.md; a piece MME cannot observe on its own is left
//! out of that fold and named in [`FoldScores::left_out`]), the networks are trained on
//! that estimate,
//! and physics alone, the network and the refined network are run free over the stretch
//! from a state fitted to its first `w` samples, started from MME's `x̂` on those `w`
//! samples alone. A candidate's score pools its K squared errors: per channel
//! `√(mean_k RMSE_k²)` over `√(mean_k σ_k²)` (σ_k: the stretch's output spread), averaged
//! over channels — one stretch gives the last-fifth guard's normalised error.

use std::collections::BTreeMap;
use std::ops::Range;
use std::sync::atomic::{AtomicUsize, Ordering};

use nn::{Mlp, ShootingRecord};
use rayon::prelude::*;
use sysid_core::{Dataset, MmeEstimate};

use super::guard::{
    self, Candidate, CandidateScore, DomainCheck, FoldScores, GuardCandidate, GuardHeldOut,
    GuardReport,
};
use super::{
    FitOptions, FoldEstimate, MmeConvergence, Trained, TrainingSet, UnconvergedMme, first_state,
    hybrid_loaded, judge_outputs, split_last_fifth, train_networks, training_pairs_without,
};
use crate::error::{MmennError, Result};
use crate::estimate::{estimate_spec, mme_config};
use crate::model_file::ModelSpec;
use crate::progress::{NoProgress, Progress, ProgressSink};

/// Shortest stretch the guard cuts: shorter records fall back to the last fifth.
const MIN_STRETCH: usize = 8;

/// Choose among `candidates` (trained on the whole record, each with its domain: the
/// stretches' networks of a kind are judged with that kind's domain) by the K-fold guard;
/// returns the report, the whole-record network of the kept kind and its domain.
#[allow(clippy::too_many_arguments)]
pub(super) fn choose_by_folds(
    spec: &ModelSpec,
    est: &MmeEstimate,
    data: &Dataset,
    x0: &[f64],
    held: GuardHeldOut,
    candidates: Vec<Candidate>,
    domain: DomainCheck,
    opts: &FitOptions,
    progress: &dyn ProgressSink,
) -> Result<(GuardReport, Mlp, nn::Domain)> {
    let exp = &data.experiments()[0];
    let len = exp.len();
    // The stretches: K equal ones, or the last fifth alone.
    let (folds, stretches): (usize, Vec<Range<usize>>) = match held {
        GuardHeldOut::Folds(k) if k >= 2 => (
            k,
            (0..k).map(|i| (i * len / k)..((i + 1) * len / k)).collect(),
        ),
        GuardHeldOut::Folds(k) => (k, Vec::new()),
        _ => (1, std::iter::once((len - len / 5)..len).collect()),
    };
    if stretches.is_empty() || stretches.iter().any(|r| r.len() < MIN_STRETCH) {
        let last = guard::held_out(data, None, est, x0, opts)?;
        let (mut report, kept, kept_domain) =
            guard::choose(spec, candidates, &last, exp.dt(), opts.substeps, domain)?;
        report.held_out = format!(
            "{} ({held} asked for: fewer than 2 stretches or stretches shorter than \
             {MIN_STRETCH} samples of {len})",
            report.held_out
        );
        return Ok((report, kept, kept_domain));
    }
    let kinds: Vec<(GuardCandidate, nn::Domain)> =
        candidates.iter().map(|(c, _, d)| (*c, *d)).collect();
    const TASK: &str = "K-fold guard";
    let done = AtomicUsize::new(0);
    progress.report(&Progress::new(TASK, 0, Some(folds)));
    let count = stretches.len();
    let per_fold: Vec<Result<FoldScores>> = stretches
        .par_iter()
        .enumerate()
        .map(|(i, stretch)| {
            let which = (i + 1, count);
            let scores = fold(spec, est, data, x0, stretch.clone(), which, &kinds, opts);
            let n = done.fetch_add(1, Ordering::Relaxed) + 1;
            progress.report(&Progress::new(TASK, n, Some(folds)));
            scores
        })
        .collect();
    progress.finish(TASK);
    let per_fold = per_fold.into_iter().collect::<Result<Vec<_>>>()?;
    let scores = kinds
        .iter()
        .enumerate()
        .map(|(i, &(c, d))| {
            pooled(
                c,
                guard::scored_domain(c, d),
                per_fold.iter().map(|f| &f.candidates[i]),
            )
        })
        .collect();
    let w = window(stretches[0].len(), opts);
    // Stretches whose first window MME could not estimate, and where they started instead.
    let fallbacks: Vec<String> = per_fold
        .iter()
        .filter_map(|f| {
            let g = f.start_guess.as_deref()?;
            let from = g.split("starts from ").nth(1).unwrap_or(g);
            Some(format!("{}..{} from {from}", f.samples.0, f.samples.1))
        })
        .collect();
    let fallback_note = if fallbacks.is_empty() {
        String::new()
    } else {
        format!(
            " (where that MME failed, the guess instead: {})",
            fallbacks.join("; ")
        )
    };
    let description = if held == GuardHeldOut::LastFifthRetrained {
        let r = &stretches[0];
        format!(
            "the last fifth of the first training record (samples {}..{}; MME, the network \
             sweep, selection and trajectory training ran again without it), run free from a \
             state fitted to its first {w} samples, started from MME on those samples \
             alone{fallback_note}",
            r.start, r.end
        )
    } else {
        format!(
            "{folds} contiguous stretches of the first training record ({len} samples; for \
             each, MME, the network sweep, selection and trajectory training ran again \
             without it), each run free from a state fitted to its first {w} samples, started \
             from MME on those samples alone{fallback_note}; scores pool the {folds} \
             stretches' squared errors"
        )
    };
    Ok(guard::decide(
        scores,
        candidates,
        description,
        per_fold,
        domain,
    ))
}

/// Samples fitted for a stretch's initial state.
fn window(stretch: usize, opts: &FitOptions) -> usize {
    opts.x0_window.min(stretch / 2).max(1)
}

/// One stretch (fold `which.0` of `which.1`, from 1): MME and the networks without it,
/// every kind judged over it.
#[allow(clippy::too_many_arguments)]
fn fold(
    spec: &ModelSpec,
    est: &MmeEstimate,
    data: &Dataset,
    x0: &[f64],
    stretch: Range<usize>,
    which: (usize, usize),
    kinds: &[(GuardCandidate, nn::Domain)],
    opts: &FitOptions,
) -> Result<FoldScores> {
    let core = |context: &'static str| move |source| MmennError::Core { context, source };
    let Without {
        trained: t,
        start,
        left_out,
        start_guess,
        unconverged_mme,
    } = train_without(spec, est, data, x0, stretch.clone(), which, opts)?;
    let first = &data.experiments()[0];
    let segment = data
        .window(0, stretch.start, stretch.end)
        .map_err(core("cutting a K-fold guard stretch"))?;
    let w = window(stretch.len(), opts);
    let mut candidates = Vec::with_capacity(kinds.len());
    for &(kind, domain) in kinds {
        let net = match kind {
            GuardCandidate::PhysicsAlone => guard::zero_network(&t.network)?,
            GuardCandidate::Network => t.before.clone(),
            GuardCandidate::Refined => t.network.clone(),
        };
        let judged = hybrid_loaded(spec, &net, &start, first.dt(), opts.substeps, domain)
            .and_then(|(_, loaded)| judge_outputs(&loaded, &segment, w));
        candidates.push(guard::score(
            kind,
            guard::scored_domain(kind, domain),
            judged,
        ));
    }
    Ok(FoldScores {
        samples: (stretch.start, stretch.end),
        candidates,
        left_out,
        start_guess,
        unconverged_mme,
    })
}

/// What [`train_without`] gives.
struct Without {
    /// The networks trained without the stretch.
    trained: Trained,
    /// The stretch's starting state.
    start: Vec<f64>,
    /// What was left out of the training.
    left_out: Vec<String>,
    /// How the start was found when MME on its first window failed.
    start_guess: Option<String>,
    /// The estimates without the stretch that did not converge (only under
    /// [`UnconvergedMme::Warn`]: under `Refuse` the first one is returned as an error).
    unconverged_mme: Vec<MmeConvergence>,
}

/// The networks trained without `stretch` (MME on each piece and record on its own; pairs,
/// shooting windows and the free-run selection on those), the state the stretch's free
/// run starts from (MME on its first `w` samples alone), and what was left out because MME
/// could not estimate it on its own (a piece, or its first samples). Nothing else of the
/// stretch is read.
///
/// Each estimate without the stretch is checked as it ends ([`MmeConvergence::converged`]):
/// under [`UnconvergedMme::Refuse`] one that did not converge is returned as
/// [`MmennError::MmeNotConverged`] naming the fold (`which`: its index from 1 and the number
/// of folds), the stretch and the record, before any of the fold's networks is trained;
/// under [`UnconvergedMme::Warn`] it is kept in [`Without::unconverged_mme`].
fn train_without(
    spec: &ModelSpec,
    est: &MmeEstimate,
    data: &Dataset,
    x0: &[f64],
    stretch: Range<usize>,
    which: (usize, usize),
    opts: &FitOptions,
) -> Result<Without> {
    let core = |context: &'static str| move |source| MmennError::Core { context, source };
    // MME at the whole record's W and noise variance (the W search is not repeated).
    let mut config = mme_config(spec, &opts.estimate);
    config.w = mme_core::WeightSpec::Matrix(est.w.clone());
    config.noise_variance = mme_core::NoiseSpec::Given(est.noise_variance.clone());
    // The records without the stretch: the first record's pieces before and after it, then
    // the other records, each estimated by MME on its own (so no estimate reads the
    // stretch). A piece MME cannot estimate on its own (too short to observe the state)
    // is left out of this fold's training and named in its scores.
    let first = &data.experiments()[0];
    let mut records = Vec::new();
    for r in [0..stretch.start, stretch.end..first.len()] {
        if r.len() >= MIN_STRETCH {
            let piece = first
                .window(r.start, r.end)
                .map_err(core("cutting a K-fold guard piece"))?;
            records.push((format!("samples {}..{}", r.start, r.end), piece));
        }
    }
    for (i, e) in data.experiments().iter().enumerate().skip(1) {
        records.push((format!("record {}", i + 1), e.clone()));
    }
    let mut kept = Vec::new();
    // MME's last state of the piece before the stretch and first state of the piece after
    // it: leak-free starting guesses when MME cannot estimate the stretch's first window.
    let (mut before_last, mut after_first): (Option<Vec<f64>>, Option<Vec<f64>>) = (None, None);
    let mut rest_est: Option<MmeEstimate> = None;
    let mut left_out = Vec::new();
    let mut unconverged_mme = Vec::new();
    let mut last_error = None;
    for (index, (name, record)) in records.into_iter().enumerate() {
        // A state that decays within a sample or two (a fast lag) is barely seen by the
        // outputs from where a piece starts, and MME may find that start unobservable
        // (Cascaded Tanks' pump lag: pieces starting at samples 204–210 fail, at 215 not);
        // the piece then starts 1, 2, 4, … samples later, at most the protocol's
        // state-initialisation window `w` (those samples are only dropped, nothing of the
        // stretch is added).
        let mut outcome = Err(None);
        let latest = opts.x0_window.min(record.len().saturating_sub(MIN_STRETCH));
        let skips = std::iter::once(0).chain(
            std::iter::successors(Some(1usize), |s| s.checked_mul(2)).take_while(|&s| s <= latest),
        );
        for skip in skips {
            let piece = record
                .window(skip, record.len())
                .map_err(core("cutting a K-fold guard piece"))?;
            let one = Dataset::new(
                data.input_channels().to_vec(),
                data.output_channels().to_vec(),
                vec![piece],
            )
            .map_err(core("the training records without a K-fold guard stretch"))?;
            match estimate_spec(spec, &one, &config) {
                Ok(out) => {
                    let report = MmeConvergence::of_fold(
                        &out,
                        &one,
                        FoldEstimate {
                            index: which.0,
                            folds: which.1,
                            stretch: (stretch.start, stretch.end),
                            record: if skip > 0 {
                                format!("{name} from its sample {skip}")
                            } else {
                                name.clone()
                            },
                        },
                    );
                    if !report.converged() {
                        if opts.on_unconverged_mme == UnconvergedMme::Refuse {
                            return Err(MmennError::MmeNotConverged { report });
                        }
                        unconverged_mme.push(report);
                    }
                    outcome = Ok((skip, one, out.estimate));
                    break;
                }
                Err(e) => outcome = Err(Some(e)),
            }
        }
        match outcome {
            Ok((skip, one, e)) => {
                let states = &e.experiments[0].states;
                let column = |j: usize| states.column(j).iter().copied().collect::<Vec<f64>>();
                if index == 0 && name.starts_with("samples 0..") && stretch.start > 0 {
                    before_last = Some(column(states.ncols() - 1));
                } else if name == format!("samples {}..{}", stretch.end, first.len()) {
                    after_first = Some(column(0));
                }
                if skip > 0 {
                    left_out.push(format!(
                        "the first {skip} sample(s) of {name} (MME could not observe the \
                         state where it started)"
                    ));
                }
                match rest_est.as_mut() {
                    None => rest_est = Some(e),
                    Some(r) => r.experiments.extend(e.experiments),
                }
                kept.extend(one.experiments().iter().cloned());
            }
            Err(why) => {
                if let Some(e) = &why {
                    left_out.push(format!("{name} (MME: {e})"));
                }
                last_error = why;
            }
        }
    }
    // No record left: MME's own reason for the last one.
    let rest_est = match (rest_est, last_error) {
        (Some(e), _) => e,
        (None, Some(e)) => return Err(e),
        (None, None) => {
            return Err(MmennError::Nn(nn::NnError::TooFewSamples {
                what: "training records without a K-fold guard stretch",
                found: 0,
                needed: 1,
            }));
        }
    };
    let rest = Dataset::new(
        data.input_channels().to_vec(),
        data.output_channels().to_vec(),
        kept,
    )
    .map_err(core("the training records without a K-fold guard stretch"))?;
    let (x, d) = training_pairs_without(
        &rest_est,
        &rest,
        opts.trim_fraction,
        None,
        opts.network_inputs,
    );
    let (fit, test) = split_last_fifth(&x, &d);
    let shooting: Vec<ShootingRecord<'_>> = rest
        .experiments()
        .iter()
        .zip(&rest_est.experiments)
        .map(|(experiment, e)| ShootingRecord {
            experiment,
            states: &e.states,
        })
        .collect();
    let rest_x0 = first_state(&rest_est);
    let set = TrainingSet {
        fit,
        test,
        data: &rest,
        skip: None,
        shooting,
    };
    let t = train_networks(spec, &set, None, &rest_x0, opts, &NoProgress)?;
    let w = window(stretch.len(), opts);
    // The starting guess from the samples the protocol lets a model see: MME on the
    // stretch's first w samples alone. When that short run fails (a state its outputs
    // barely see), MME's last state of the piece before the stretch (one sample earlier),
    // else its first state of the piece after it (a later time), else the whole record's
    // x̂(t0), which read the stretch; the fold's report says which.
    let window_start = data
        .window(
            0,
            stretch.start,
            stretch.start + w.max(2).min(stretch.len()),
        )
        .map_err(core("cutting a K-fold guard window"))
        .and_then(|first_w| estimate_spec(spec, &first_w, &config));
    let (start, guess) = match window_start {
        Ok(out) => (
            out.estimate.experiments[0]
                .states
                .column(0)
                .iter()
                .copied()
                .collect(),
            None,
        ),
        Err(why) => {
            let (state, from) = fallback_start(before_last, after_first, x0);
            (
                state,
                Some(format!(
                    "MME on its first {w} samples failed ({why}); its free run starts from \
                     {from}"
                )),
            )
        }
    };
    Ok(Without {
        trained: t,
        start,
        left_out,
        start_guess: guess,
        unconverged_mme,
    })
}

/// The free run's starting guess when MME cannot estimate a stretch's first window: the
/// piece before's last state (one sample earlier), else the piece after's first state (a
/// later time), else the whole record's `x̂(t0)` (whose MME read the stretch); with what
/// it is.
fn fallback_start(
    before_last: Option<Vec<f64>>,
    after_first: Option<Vec<f64>>,
    x0: &[f64],
) -> (Vec<f64>, &'static str) {
    match (before_last, after_first) {
        (Some(b), _) => (
            b,
            "MME's last state of the piece before it, one sample earlier",
        ),
        (None, Some(a)) => (a, "MME's first state of the piece after it, a later time"),
        (None, None) => (
            x0.to_vec(),
            "the whole record's x̂(t0), whose MME read the stretch",
        ),
    }
}

/// A kind's score over every stretch: per channel the root of the mean squared error and
/// of the mean output variance; failed when any stretch failed.
fn pooled<'a>(
    candidate: GuardCandidate,
    domain: Option<nn::Domain>,
    folds: impl Iterator<Item = &'a CandidateScore>,
) -> CandidateScore {
    let mut mse: BTreeMap<String, Vec<f64>> = BTreeMap::new();
    let mut var: BTreeMap<String, Vec<f64>> = BTreeMap::new();
    for (k, f) in folds.enumerate() {
        if f.held_out_error.is_none() {
            return CandidateScore {
                candidate,
                domain,
                held_out_error: None,
                rmse: BTreeMap::new(),
                fit_percent: BTreeMap::new(),
                failure: Some(format!(
                    "stretch {}: {}",
                    k + 1,
                    f.failure.as_deref().unwrap_or("no score")
                )),
            };
        }
        for (name, r) in &f.rmse {
            mse.entry(name.clone()).or_default().push(r * r);
            // fit % = 100 (1 − RMSE / σ) ⇒ σ = RMSE / (1 − fit % / 100).
            let sigma = f
                .fit_percent
                .get(name)
                .map_or(f64::NAN, |fit| r / (1.0 - fit / 100.0));
            var.entry(name.clone()).or_default().push(sigma * sigma);
        }
    }
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    let rmse: BTreeMap<String, f64> = mse
        .iter()
        .map(|(n, v)| (n.clone(), mean(v).sqrt()))
        .collect();
    let fit_percent: BTreeMap<String, f64> = rmse
        .iter()
        .map(|(n, r)| (n.clone(), 100.0 * (1.0 - r / mean(&var[n]).sqrt())))
        .collect();
    let fits: Vec<f64> = fit_percent.values().copied().collect();
    let error = if !fits.is_empty() && fits.iter().all(|f| f.is_finite()) {
        fits.iter().map(|f| 1.0 - f / 100.0).sum::<f64>() / fits.len() as f64
    } else {
        rmse.values().sum::<f64>() / rmse.len().max(1) as f64
    };
    CandidateScore {
        candidate,
        domain,
        held_out_error: error.is_finite().then_some(error),
        rmse,
        fit_percent,
        failure: (!error.is_finite()).then(|| "non-finite pooled free-run error".to_string()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    /// What a fold trains and where its free run starts depend on the held-out stretch
    /// only through its first `w` samples: changing every later sample of the stretch
    /// leaves the networks (before and after trajectory training) and the starting state
    /// identical to the bit, with MME's `W` and noise variance held. The whole-record
    /// smoother, which the guard used before docs/decisions/guard-leak-free-mme.md, does
    /// see the change right after the stretch (checked, so the test can tell the two apart).
    /// Records written by the independent Python/scipy generator (`fixtures/discovery_suite`).
    #[test]
    fn a_stretch_reaches_its_fold_only_through_its_window() {
        let case = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../fixtures/discovery_suite/cases/msd_cubic_hard");
        let mut spec = crate::model_file::read_model(&case.join("model.toml")).unwrap();
        // MME's hyperparameters held, as the guard holds them (the file's variance is
        // estimated from the data otherwise).
        spec.noise_variance = crate::model_file::NoiseVariance::Given(vec![2e-5]);
        let (data, _) =
            crate::data_file::read_with_validation(&[case.join("est.csv")], &[], &spec).unwrap();
        let opts = FitOptions {
            estimate: crate::estimate::EstimateOptions {
                w: crate::estimate::WeightChoice::Value(1e3),
                ..Default::default()
            },
            max_hidden: 2,
            inits: 1,
            train_on_trajectories: super::super::TrajectoryChoice::Trajectory,
            trajectory: nn::TrajectoryConfig {
                window: 100,
                max_iterations: 2,
                ..Default::default()
            },
            ..FitOptions::default()
        };
        let len = data.experiments()[0].len();
        let stretch = (len / 5)..(2 * len / 5);
        let w = window(stretch.len(), &opts);
        // The same record with every sample of the stretch after its window changed.
        let exp = &data.experiments()[0];
        let mut outputs = exp.outputs().clone();
        for k in (stretch.start + w)..stretch.end {
            outputs[(0, k)] += 0.05 * (k as f64 * 0.37).sin();
        }
        let changed_exp =
            sysid_core::Experiment::new(exp.t0(), exp.dt(), exp.inputs().clone(), outputs)
                .unwrap()
                .with_intersample(exp.intersample());
        let changed = Dataset::new(
            data.input_channels().to_vec(),
            data.output_channels().to_vec(),
            vec![changed_exp],
        )
        .unwrap();
        let config = mme_config(&spec, &opts.estimate);
        let run = |d: &Dataset| {
            let est = estimate_spec(&spec, d, &config).unwrap().estimate;
            let x0 = super::super::first_state(&est);
            let Without {
                trained: t,
                start,
                left_out,
                start_guess: guess,
                unconverged_mme,
            } = train_without(&spec, &est, d, &x0, stretch.clone(), (2, 5), &opts).unwrap();
            assert!(left_out.is_empty(), "{left_out:?}");
            assert!(guess.is_none(), "{guess:?}");
            assert!(unconverged_mme.is_empty(), "{unconverged_mme:?}");
            (est, t, start)
        };
        let (est_a, a, start_a) = run(&data);
        let (est_b, b, start_b) = run(&changed);
        assert_eq!(est_a.w, est_b.w);
        assert_eq!(est_a.noise_variance, est_b.noise_variance);
        assert_eq!(a.before, b.before);
        assert_eq!(a.network, b.network);
        assert_eq!(start_a, start_b);
        assert!(a.refinement.is_some());
        // The whole-record smoother's states just after the stretch (training pairs of the
        // leaky guard) did move.
        let k = stretch.end;
        let moved = (0..2)
            .map(|i| {
                (est_a.experiments[0].states[(i, k)] - est_b.experiments[0].states[(i, k)]).abs()
            })
            .fold(0.0, f64::max);
        assert!(
            moved > 0.0,
            "the whole-record smoother did not see the change"
        );
    }

    /// A fold whose MME (on the records without its stretch) does not converge: refused
    /// under the default policy, naming the fold, its stretch, the record and the ending;
    /// recorded in the fold's scores under `Warn`. The whole record's estimate converged
    /// (its `W`, noise variance and `x̂(t0)` are what the guard is given); the fold's runs
    /// are limited to one Gauss–Newton iteration. The case's assumed model with a cubic
    /// spring term (so MME iterates), on its records (the independent generator's).
    #[test]
    fn a_fold_whose_mme_did_not_converge_is_refused_or_recorded() {
        use super::super::{MmeStage, TrajectoryChoice, UnconvergedMme};
        use sysid_core::Termination;
        let case = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../fixtures/discovery_suite/cases/msd_cubic_hard");
        let spec = crate::model_file::parse_model(
            Path::new("cubic.toml"),
            r#"
states = ["x", "v"]
inputs = ["u"]
A = [[0.0, 1.0], [-4.0, -0.4]]
B = [[0.0], [0.5]]
measured = ["x"]
corrected = ["v"]
noise_variance = [2e-5]
intersample = "foh"

[[terms]]
state = "v"
effect = "cubic spring"
term = "x^3"
coefficient = -1.0
"#,
        )
        .unwrap();
        let (data, _) =
            crate::data_file::read_with_validation(&[case.join("est.csv")], &[], &spec).unwrap();
        let estimate = crate::estimate::EstimateOptions {
            w: crate::estimate::WeightChoice::Value(1e3),
            ..Default::default()
        };
        let whole = estimate_spec(&spec, &data, &mme_config(&spec, &estimate))
            .unwrap()
            .estimate;
        assert_eq!(whole.report.termination, Some(Termination::Converged));
        let x0 = super::super::first_state(&whole);
        let opts = |policy| FitOptions {
            estimate: crate::estimate::EstimateOptions {
                iterations: mme_core::IterationOptions {
                    max_iterations: 1,
                    ..Default::default()
                },
                ..estimate.clone()
            },
            hidden: super::super::HiddenChoice::Fixed(1),
            inits: 1,
            train_on_trajectories: TrajectoryChoice::None,
            on_unconverged_mme: policy,
            ..FitOptions::default()
        };
        let len = data.experiments()[0].len();
        let stretch = (len / 5)..(2 * len / 5);
        let kinds = [(GuardCandidate::PhysicsAlone, nn::Domain::Extrapolate)];
        let run = |policy| {
            fold(
                &spec,
                &whole,
                &data,
                &x0,
                stretch.clone(),
                (2, 5),
                &kinds,
                &opts(policy),
            )
        };
        let before = format!("samples 0..{}", stretch.start);
        let after = format!("samples {}..{len}", stretch.end);

        let Err(MmennError::MmeNotConverged { report }) = run(UnconvergedMme::Refuse) else {
            panic!("a fold whose MME stopped at the iteration limit was not refused");
        };
        assert_eq!(report.stage, MmeStage::GuardFold);
        assert_eq!(report.termination, Some(Termination::MaxIterations));
        let f = report.fold.as_ref().unwrap();
        assert_eq!((f.index, f.folds), (2, 5));
        assert_eq!(f.stretch, (stretch.start, stretch.end));
        assert_eq!(f.record, before);
        let message = MmennError::MmeNotConverged {
            report: report.clone(),
        }
        .to_string();
        for part in [
            "K-fold guard estimate",
            &format!(
                "fold 2 of 5 (stretch samples {}..{} held out), on {before}",
                stretch.start, stretch.end
            ),
            "did not converge",
            "Gauss–Newton iteration at the given W: stopped at the iteration limit",
        ] {
            assert!(message.contains(part), "{part:?} not in {message}");
        }

        let scores = run(UnconvergedMme::Warn).unwrap();
        let records: Vec<&str> = scores
            .unconverged_mme
            .iter()
            .map(|m| m.fold.as_ref().unwrap().record.as_str())
            .collect();
        assert_eq!(records, [before.as_str(), after.as_str()]);
        for m in &scores.unconverged_mme {
            assert_eq!(m.stage, MmeStage::GuardFold);
            assert_eq!(m.termination, Some(Termination::MaxIterations), "{m}");
            assert!(!m.converged());
        }
        let json = serde_json::to_value(&scores).unwrap();
        assert_eq!(
            json["unconverged_mme"][0]["fold"]["index"],
            serde_json::json!(2)
        );
    }

    #[test]
    fn a_failed_window_falls_back_to_the_neighbouring_pieces_before_the_leaky_state() {
        let x0 = [9.0, 9.0];
        let (s, why) = fallback_start(Some(vec![1.0, 2.0]), Some(vec![3.0, 4.0]), &x0);
        assert_eq!((s, why.contains("before")), (vec![1.0, 2.0], true));
        let (s, why) = fallback_start(None, Some(vec![3.0, 4.0]), &x0);
        assert_eq!((s, why.contains("after")), (vec![3.0, 4.0], true));
        let (s, why) = fallback_start(None, None, &x0);
        assert_eq!(
            (s, why.contains("read the stretch")),
            (vec![9.0, 9.0], true)
        );
    }
}
