//! The K-fold guard ([`GuardHeldOut::Folds`], and [`GuardHeldOut::LastFifthRetrained`] as
//! its one-stretch case): the first training record is cut into K
//! contiguous stretches; for each, the networks are trained again without it (its `d̂`
//! pairs and its samples in the shooting windows left out; the free-run selection does
//! not score it) and physics alone, the network and the refined network are run free over
//! it from a state fitted to its first samples, started from MME's `x̂` there. A
//! candidate's score pools its K squared errors: per channel `√(mean_k RMSE_k²)` over
//! `√(mean_k σ_k²)` (σ_k: the stretch's output spread), averaged over channels — one
//! stretch gives the last-fifth guard's normalised error. MME's `x̂`, `d̂` come from the
//! whole record (a smoother: the samples next to a stretch carry some of its information).

use std::collections::BTreeMap;
use std::ops::Range;
use std::sync::atomic::{AtomicUsize, Ordering};

use nalgebra::DMatrix;
use nn::{Mlp, ShootingRecord};
use rayon::prelude::*;
use sysid_core::{Dataset, Experiment, MmeEstimate};

use super::guard::{self, CandidateScore, FoldScores, GuardCandidate, GuardHeldOut, GuardReport};
use super::{
    FitOptions, TrainingSet, hybrid_loaded, judge_outputs, split_last_fifth, train_networks,
    training_pairs_without,
};
use crate::error::{MmennError, Result};
use crate::model_file::ModelSpec;
use crate::progress::{NoProgress, Progress, ProgressSink};

/// Shortest stretch the guard cuts: shorter records fall back to the last fifth.
const MIN_STRETCH: usize = 8;

/// Choose among `candidates` (trained on the whole record) by the K-fold guard; returns
/// the report and the whole-record network of the kept kind.
#[allow(clippy::too_many_arguments)]
pub(super) fn choose_by_folds(
    spec: &ModelSpec,
    est: &MmeEstimate,
    data: &Dataset,
    x0: &[f64],
    held: GuardHeldOut,
    candidates: Vec<(GuardCandidate, Mlp)>,
    opts: &FitOptions,
    progress: &dyn ProgressSink,
) -> Result<(GuardReport, Mlp)> {
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
        let (mut report, kept) = guard::choose(
            spec,
            candidates,
            &last,
            exp.dt(),
            opts.substeps,
            opts.network_domain,
        )?;
        report.held_out = format!(
            "{} ({held} asked for: fewer than 2 stretches or stretches shorter than \
             {MIN_STRETCH} samples of {len})",
            report.held_out
        );
        return Ok((report, kept));
    }
    let kinds: Vec<GuardCandidate> = candidates.iter().map(|(c, _)| *c).collect();
    const TASK: &str = "K-fold guard";
    let done = AtomicUsize::new(0);
    progress.report(&Progress::new(TASK, 0, Some(folds)));
    let per_fold: Vec<Result<FoldScores>> = stretches
        .par_iter()
        .map(|stretch| {
            let scores = fold(spec, est, data, x0, stretch.clone(), &kinds, opts);
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
        .map(|(i, &c)| pooled(c, per_fold.iter().map(|f| &f.candidates[i])))
        .collect();
    let w = window(stretches[0].len(), opts);
    let description = if held == GuardHeldOut::LastFifthRetrained {
        let r = &stretches[0];
        format!(
            "the last fifth of the first training record (samples {}..{}; the network sweep, \
             selection and trajectory training ran again without it), run free from a state \
             fitted to its first {w} samples from MME's x̂ there",
            r.start, r.end
        )
    } else {
        format!(
            "{folds} contiguous stretches of the first training record ({len} samples; for \
             each, the network sweep, selection and trajectory training ran again without \
             it), each run free from a state fitted to its first {w} samples from MME's x̂ \
             there; scores pool the {folds} stretches' squared errors"
        )
    };
    Ok(guard::decide(scores, candidates, description, per_fold))
}

/// Samples fitted for a stretch's initial state.
fn window(stretch: usize, opts: &FitOptions) -> usize {
    opts.x0_window.min(stretch / 2).max(1)
}

/// One stretch: train without it, judge every kind over it.
fn fold(
    spec: &ModelSpec,
    est: &MmeEstimate,
    data: &Dataset,
    x0: &[f64],
    stretch: Range<usize>,
    kinds: &[GuardCandidate],
    opts: &FitOptions,
) -> Result<FoldScores> {
    let core = |context: &'static str| move |source| MmennError::Core { context, source };
    let (x, d) = training_pairs_without(
        est,
        data,
        opts.trim_fraction,
        Some(&stretch),
        opts.network_inputs,
    );
    let (fit, test) = split_last_fifth(&x, &d);
    // Shooting records: the first record's pieces before and after the stretch, the other
    // records whole.
    let first = &data.experiments()[0];
    let states = &est.experiments[0].states;
    let mut pieces: Vec<(Experiment, DMatrix<f64>)> = Vec::new();
    for r in [0..stretch.start, stretch.end..first.len()] {
        if r.len() >= 2 {
            pieces.push((
                first
                    .window(r.start, r.end)
                    .map_err(core("cutting a K-fold guard piece"))?,
                states.columns(r.start, r.len()).into_owned(),
            ));
        }
    }
    let mut shooting: Vec<ShootingRecord<'_>> = pieces
        .iter()
        .map(|(experiment, states)| ShootingRecord { experiment, states })
        .collect();
    shooting.extend(data.experiments().iter().zip(&est.experiments).skip(1).map(
        |(experiment, e)| ShootingRecord {
            experiment,
            states: &e.states,
        },
    ));
    let set = TrainingSet {
        fit,
        test,
        data,
        skip: Some(stretch.clone()),
        shooting,
    };
    let t = train_networks(spec, &set, None, x0, opts, &NoProgress)?;
    let segment = data
        .window(0, stretch.start, stretch.end)
        .map_err(core("cutting a K-fold guard stretch"))?;
    let start: Vec<f64> = states.column(stretch.start).iter().copied().collect();
    let w = window(stretch.len(), opts);
    let mut candidates = Vec::with_capacity(kinds.len());
    for &kind in kinds {
        let net = match kind {
            GuardCandidate::PhysicsAlone => guard::zero_network(&t.network)?,
            GuardCandidate::Network => t.before.clone(),
            GuardCandidate::Refined => t.network.clone(),
        };
        let judged = hybrid_loaded(
            spec,
            &net,
            &start,
            first.dt(),
            opts.substeps,
            opts.network_domain,
        )
        .and_then(|(_, loaded)| judge_outputs(&loaded, &segment, w));
        candidates.push(guard::score(kind, judged));
    }
    Ok(FoldScores {
        samples: (stretch.start, stretch.end),
        candidates,
    })
}

/// A kind's score over every stretch: per channel the root of the mean squared error and
/// of the mean output variance; failed when any stretch failed.
fn pooled<'a>(
    candidate: GuardCandidate,
    folds: impl Iterator<Item = &'a CandidateScore>,
) -> CandidateScore {
    let mut mse: BTreeMap<String, Vec<f64>> = BTreeMap::new();
    let mut var: BTreeMap<String, Vec<f64>> = BTreeMap::new();
    for (k, f) in folds.enumerate() {
        if f.held_out_error.is_none() {
            return CandidateScore {
                candidate,
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
        held_out_error: error.is_finite().then_some(error),
        rmse,
        fit_percent,
        failure: (!error.is_finite()).then(|| "non-finite pooled free-run error".to_string()),
    }
}
