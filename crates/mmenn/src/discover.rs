//! `mmenn discover`: read the model and the records, run the discovery workflow
//! ([`discovery::workflow`]: rounds, noise floor, proof, claim and verdict — the decision
//! layer lives there), and write `discovery.json`, `model.discovered.toml`, `report.md`
//! and the before/after figures. MME enters the workflow through [`discovery::workflow::Mme`],
//! implemented here with mme-core.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use discovery::Verdict;
use discovery::workflow::{self, Observer};
use nalgebra::DMatrix;
use serde::Serialize;
use sysid_core::{Dataset, MmeEstimate, TermModel};

use crate::atomic::{ensure_dir, write_atomic};
use crate::error::{MmennError, Result};
use crate::estimate::{EstimateOptions, estimate_term_model_observed, mme_config};
use crate::model_file::{ModelSpec, NoiseVariance, TermEntry, write_model};
use crate::progress::{MmeProgress, NoProgress, Progress, ProgressSink};
use report::{figures, report};

pub use discovery::workflow::{
    Ambiguity, AssumedEntry, CONFIRM_COST, NamedEffect, Round, WorkflowConfig,
};

mod force;
mod report;

/// Options of [`run_discover`].
#[derive(Debug, Clone, PartialEq, Default)]
pub struct DiscoverOptions {
    /// MME settings.
    pub estimate: EstimateOptions,
    /// The workflow's settings (rounds, seed, initial-state window, trimming, the
    /// acceptance threshold, the hold-out fraction); `noise_given` is set from the model
    /// file.
    pub workflow: WorkflowConfig,
    /// [`run_discover`] prints the workflow's steps as lines on standard error (off by
    /// default; [`run_discover_with_progress`] reports to a sink instead and ignores it).
    pub progress: bool,
}

/// Fit %, RMSE (free-run, per measured channel) and `d̂` RMS (per corrected equation).
#[derive(Debug, Clone, PartialEq, Serialize, Default)]
pub struct Gap {
    /// Free-run fit % per channel.
    pub fit_percent: BTreeMap<String, f64>,
    /// Free-run RMSE per channel.
    pub rmse: BTreeMap<String, f64>,
    /// RMS of MME's `d̂` per corrected equation.
    pub d_rms: BTreeMap<String, f64>,
}

/// Before and after on one data set.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct GapPair {
    /// With the assumed model.
    pub before: Gap,
    /// With the discovered model.
    pub after: Gap,
}

/// Fit points (mean over the measured outputs) the discovered model may lose against the
/// assumed one on the estimation records before its terms are rejected: they were
/// calibrated on those records, so a drop there means the calibration or its free run
/// went wrong, whatever another record shows.
pub const ESTIMATION_DROP: f64 = 1.0;

/// Free-run fit points gained on the validation records, on every measured output,
/// that keep a discovered model whose estimation fit dropped (reported, not hidden).
pub const VALIDATION_GAIN: f64 = 10.0;

/// The guard against a discovered model that is worse on its own estimation records
/// (issue 20, item 6).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DegradationGuard {
    /// Mean free-run fit % over the outputs on the estimation records: assumed model
    /// minus discovered model (positive: the discovered model is worse).
    pub estimation_drop: f64,
    /// Smallest validation fit gain over the outputs (discovered minus assumed), when
    /// validation records were given.
    pub validation_gain: Option<f64>,
    /// Whether the discovered terms were rejected (the written model is the assumed one).
    pub rejected: bool,
    /// The decision in words.
    pub reason: String,
}

/// The guard's decision on the gaps of a run: `None` when the discovered model does not
/// lose more than [`ESTIMATION_DROP`] fit points on the estimation records.
pub fn degradation_guard(
    estimation: &GapPair,
    validation: Option<&GapPair>,
) -> Option<DegradationGuard> {
    let mean = |g: &Gap| {
        let v: Vec<f64> = g.fit_percent.values().copied().collect();
        if v.is_empty() {
            f64::NAN
        } else {
            v.iter().sum::<f64>() / v.len() as f64
        }
    };
    let drop = mean(&estimation.before) - mean(&estimation.after);
    // NaN (an output without a fit) counts as a drop: the guard then decides.
    if drop <= ESTIMATION_DROP {
        return None;
    }
    let gain = validation.and_then(|v| {
        v.before
            .fit_percent
            .iter()
            .map(|(name, b)| v.after.fit_percent.get(name).map_or(f64::NAN, |a| a - b))
            .reduce(f64::min)
    });
    // Without validation records there is nothing to weigh the drop against (the free
    // run from a window-fitted state can fall apart on a sensitive record even for the
    // true model): reported, not rejected.
    let kept = gain.is_none_or(|g| g >= VALIDATION_GAIN);
    let drop_text = if drop.is_finite() {
        format!("{drop:.1} fit points")
    } else {
        "an undefined amount (an output has no fit)".to_string()
    };
    let reason = match (gain, kept) {
        (Some(g), true) => format!(
            "the discovered model's free-run fit on the estimation records is {drop_text} \
             below the assumed model's (the records its terms were calibrated on), but it \
             gains {g:.1} points on every validation output (at least {VALIDATION_GAIN}), so \
             it is kept; check the estimation-record figures"
        ),
        (Some(g), false) => format!(
            "the discovered model's free-run fit on the estimation records is {drop_text} \
             below the assumed model's (the records its terms were calibrated on) and its \
             validation gain ({g:.1} points on the worst output) is below {VALIDATION_GAIN}: \
             its terms are rejected (model.discovered.toml is the assumed model; the \
             rejected one is model.rejected.toml)"
        ),
        (None, _) => format!(
            "the discovered model's free-run fit on the estimation records is {drop_text} \
             below the assumed model's (the records its terms were calibrated on); with no \
             validation records to weigh it against, the terms are kept — check the \
             estimation-record figures, or give validation records (--val) and the guard \
             rejects the terms unless every validation output gains at least \
             {VALIDATION_GAIN} points"
        ),
    };
    Some(DegradationGuard {
        estimation_drop: drop,
        validation_gain: gain,
        rejected: !kept,
        reason,
    })
}

/// `discovery.json`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DiscoverSummary {
    /// `found` if a round was accepted; `unexplained` if a round was rejected or the
    /// free-run search left a cost above the noise level; else `none`.
    pub verdict: Verdict,
    /// Every named effect, with its calibrated coefficient and the regression's interval.
    pub effects: Vec<NamedEffect>,
    /// Terms that improved the model (and are in `model.discovered.toml`) but did not
    /// bring its free-run cost down to the noise level, so they are not claimed as the
    /// missing physics (verdict `unexplained`).
    pub unconfirmed: Vec<NamedEffect>,
    /// The free-run cost (on the judging records, 1 = the noise level) below which named
    /// effects are claimed, or the model is judged to need none: the reference quantile
    /// of `judgement` when the bootstrap ran, else the fixed bound
    /// ([`discovery::workflow::claim_bound`]).
    pub claim_bound: f64,
    /// The judged statistic and its reference distribution under the pipeline that
    /// produced it (parametric bootstrap, see `discovery::judge`); `None` when no free-run
    /// search ran or the bootstrap could not complete (`judge_note` says why).
    pub judgement: Option<discovery::BootstrapJudgement>,
    /// Terms the free-run search kept that the judge's test showed unneeded (dropped
    /// from the model before the claim).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub passengers: Vec<String>,
    /// Why the bootstrap judge did not decide, when it did not.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub judge_note: Option<String>,
    /// Gap on the estimation data (`before`, `after`), and on validation data when given.
    pub gap: GapPair,
    /// Gap on the validation data.
    pub validation_gap: Option<GapPair>,
    /// When named effects were not claimed because the data cannot tell them from
    /// another set of terms (partial observation), the two explanations.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ambiguity: Option<Ambiguity>,
    /// The flexible stand-in on MME's `d̂` with the final model and its reference
    /// (`discovery::standin`); a `found` or `none` verdict needs it accepted.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub stand_in: Option<discovery::StandIn>,
    /// Why the stand-in did not decide, when it did not.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub stand_in_note: Option<String>,
    /// What the user should know about the estimated noise variance of the assumed
    /// model's MME run (`crate::estimate::noise_warnings`), and the degradation guard's
    /// reason when it fired.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub warnings: Vec<String>,
    /// The guard against a discovered model worse on its own estimation records, when it
    /// fired ([`degradation_guard`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub degradation: Option<DegradationGuard>,
    /// The augmented model file.
    pub model: String,
    /// Every round.
    pub rounds: Vec<Round>,
    /// How MME's first solve (the assumed model on the estimation records) ended:
    /// `exact` for a given `W`, otherwise the `W` search's ending (or the Gauss–Newton
    /// iteration's, when it failed at the final `W`). [`DiscoverSummary::mme_estimate`]
    /// says which, and whether it counts as converged.
    pub mme_termination: Option<sysid_core::Termination>,
    /// MME's first solve, with which part of it ended how, its ratios and the sampling
    /// band ([`crate::fit::MmeConvergence`]; `None` when it was not recorded). Unless it
    /// converged ([`crate::fit::MmeConvergence::converged`]), `mmenn discover` exits with
    /// status 3: `d̂`, and everything proposed from it, rest on an estimate that did not
    /// converge.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mme_estimate: Option<crate::fit::MmeConvergence>,
    /// Whether the effects were named as generalized forces of a mass-matrix model
    /// (`discovery::force`: intervals, the validation cost and the fixed noise-level bound
    /// decide; no bootstrap judge and no stand-in).
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub generalized_forces: bool,
}

/// MME for the workflow: mme-core with the model file's settings (`W`, noise variance,
/// sub-steps, inputs between samples).
struct MmeCore<'a> {
    spec: &'a ModelSpec,
    options: &'a EstimateOptions,
    /// The noise report of the first estimate (MME with the assumed model), kept for
    /// the warnings about an estimated noise variance.
    first_noise: std::sync::Mutex<Option<mme_core::NoiseReport>>,
    /// How the first estimate that ended ended (the workflow's first estimate: the
    /// assumed model, from the data start or, when that failed, from the retry).
    first_convergence: std::sync::Mutex<Option<crate::fit::MmeConvergence>>,
    /// The workflow's progress, into whose latest report each MME run's steps go as the
    /// note ([`MmeProgress::within`]).
    reported: &'a Reported<'a>,
}

impl MmeCore<'_> {
    /// MME on `data` with `model`, its steps noted in the workflow's progress.
    fn observed(
        &self,
        model: &TermModel,
        data: &Dataset,
        config: &mme_core::MmeConfig,
    ) -> Result<mme_core::MmeOutput> {
        let reported = self.reported;
        let frame = || reported.current();
        let steps = MmeProgress::within(reported.sink, &frame);
        estimate_term_model_observed(model, data, config, &steps)
    }

    /// Every MME run of the workflow (one or more per round) first checks the job's
    /// budget: a linear MME charges nothing itself, so a spent budget stops the workflow
    /// here, between its steps.
    fn check_budget(&self) -> Result<()> {
        self.options
            .budget
            .charge(0, "discover (MME of the workflow's next step)", 0, None)
            .map_err(|e| MmennError::Core {
                context: "discover",
                source: sysid_core::CoreError::BudgetExhausted(e),
            })
    }
}

impl workflow::Mme for MmeCore<'_> {
    type Error = MmennError;

    fn estimate(
        &self,
        model: &TermModel,
        data: &Dataset,
        start: Option<&[Vec<f64>]>,
    ) -> Result<MmeEstimate> {
        self.check_budget()?;
        let mut config = mme_config(self.spec, self.options);
        if let Some(x0s) = start {
            config.start = mme_core::StartTrajectory::Given(x0s.to_vec());
        }
        let out = self.observed(model, data, &config)?;
        if let Ok(mut first) = self.first_noise.lock()
            && first.is_none()
        {
            *first = Some(out.noise.clone());
        }
        if let Ok(mut first) = self.first_convergence.lock()
            && first.is_none()
        {
            *first = Some(crate::fit::MmeConvergence::of(
                crate::fit::MmeStage::Training,
                &out,
                data,
            ));
        }
        Ok(out.estimate)
    }

    fn estimate_fixed(
        &self,
        model: &TermModel,
        data: &Dataset,
        w: &DMatrix<f64>,
        noise: &[f64],
        start: Option<&[Vec<f64>]>,
    ) -> Result<MmeEstimate> {
        self.check_budget()?;
        let mut config = mme_config(self.spec, self.options);
        if let Some(x0s) = start {
            config.start = mme_core::StartTrajectory::Given(x0s.to_vec());
        }
        config.w = mme_core::WeightSpec::Matrix(w.clone());
        config.noise_variance = mme_core::NoiseSpec::Given(noise.to_vec());
        Ok(self.observed(model, data, &config)?.estimate)
    }
}

/// The task name of `discover`'s progress reports.
pub const DISCOVER_TASK: &str = "discover";

/// The workflow's steps as progress reports of one task, [`DISCOVER_TASK`]: `done` of
/// `total` steps of the workflow's plan (`discovery::workflow::Observer::steps`), the
/// [`Progress::stage`] naming the round and the step that begins.
struct Reported<'a> {
    sink: &'a dyn ProgressSink,
    stage: std::sync::Mutex<String>,
    /// The latest report (what an MME run of the step adds its note to).
    latest: std::sync::Mutex<Option<Progress>>,
}

impl Reported<'_> {
    /// The latest report, or the stage named so far when none was made yet.
    fn current(&self) -> Progress {
        if let Ok(latest) = self.latest.lock()
            && let Some(p) = latest.as_ref()
        {
            return p.clone();
        }
        let stage = self.stage.lock().map(|s| s.clone()).unwrap_or_default();
        Progress::new(DISCOVER_TASK, 0, None).with_stage(stage)
    }
}

impl Observer for Reported<'_> {
    fn stage(&self, round: usize, stage: &str) {
        if let Ok(mut s) = self.stage.lock() {
            *s = if round == 0 {
                stage.to_string()
            } else {
                format!("round {round}: {stage}")
            };
        }
    }

    fn steps(&self, done: usize, total: usize) {
        // The workflow names its steps (Observer::stage); done counts those finished.
        let stage = self.stage.lock().map(|s| s.clone()).unwrap_or_default();
        let report = Progress::new(DISCOVER_TASK, done, Some(total)).with_stage(stage);
        self.sink.report(&report);
        if let Ok(mut latest) = self.latest.lock() {
            *latest = Some(report);
        }
    }
}

/// [`DiscoverOptions::progress`] for library callers of [`run_discover`]: one line on
/// standard error per step of the workflow.
struct StageLines;

impl ProgressSink for StageLines {
    fn report(&self, p: &Progress) {
        if p.total != Some(p.done) {
            #[allow(clippy::print_stderr)]
            {
                eprintln!("{}", p.line());
            }
        }
    }
}

fn core(context: &'static str) -> impl FnOnce(sysid_core::CoreError) -> MmennError {
    move |source| MmennError::Core { context, source }
}

/// Free run of a model over every record of `data`, judged by discovery's validation
/// rule (`discovery::validation`, the rule its acceptance check judges a round by: each
/// record's initial state fitted to its first `window` samples, every sample scored —
/// through `sysid_core::judge_free_run`, the numbers `predict` and `compare` give for the
/// same model); fit % and RMSE per output pooled over the records (squared errors summed
/// over every record's samples, `sysid_core::score_rows` on the records side by side; for
/// one record the record's own numbers), and the simulated outputs of the first record
/// (the one the figures draw).
fn free_run_gap(model: &TermModel, data: &Dataset, window: usize) -> Result<(Gap, DMatrix<f64>)> {
    free_run_gap_of(model, model.linear(), data, window, false)
}

/// [`free_run_gap`] for any model, its outputs those of `linear`; with `stiff_aware`
/// (the mass-matrix path) the RK4 steps come from `sysid_core::auto_rk4` (4 unless the
/// model is stiff along the record), otherwise 4.
fn free_run_gap_of<D: sysid_core::Dynamics>(
    model: &D,
    linear: &sysid_core::LinearModel,
    data: &Dataset,
    window: usize,
    stiff_aware: bool,
) -> Result<(Gap, DMatrix<f64>)> {
    let names = linear.output_names();
    let total: usize = data.experiments().iter().map(|e| e.len()).sum();
    // Every record's measured and simulated outputs side by side.
    let mut measured = DMatrix::from_element(names.len(), total, f64::NAN);
    let mut simulated = DMatrix::from_element(names.len(), total, f64::NAN);
    let mut first: Option<DMatrix<f64>> = None;
    let mut at = 0;
    for exp in data.experiments() {
        let judged = discovery::validation::judge_record(model, linear, exp, window, stiff_aware)
            .map_err(core("judging the free run"))?;
        let len = exp.len();
        measured.columns_mut(at, len).copy_from(exp.outputs());
        simulated.columns_mut(at, len).copy_from(&judged.outputs);
        at += len;
        if first.is_none() {
            first = Some(judged.outputs);
        }
    }
    let channels = sysid_core::score_rows(names, &measured, &simulated, 0)
        .map_err(core("scoring the free run"))?;
    let mut gap = Gap::default();
    for (name, m) in &channels {
        gap.fit_percent.insert(name.clone(), m.fit_percent);
        gap.rmse.insert(name.clone(), m.rmse);
    }
    let first = first.ok_or(MmennError::Core {
        context: "judging the free run",
        source: sysid_core::CoreError::TooFewSamples {
            what: "records",
            found: 0,
            needed: 1,
        },
    })?;
    Ok((gap, first))
}

/// Run the discovery workflow and write `discovery.json`, `model.discovered.toml`,
/// `report.md` and figures into `out` (a line on standard error per step when
/// [`DiscoverOptions::progress`] is set).
pub fn run_discover(
    data_paths: &[PathBuf],
    model_path: &Path,
    val_paths: &[PathBuf],
    opts: &DiscoverOptions,
    out: &Path,
) -> Result<DiscoverSummary> {
    let progress: &dyn ProgressSink = if opts.progress {
        &StageLines
    } else {
        &NoProgress
    };
    run_discover_with_progress(data_paths, model_path, val_paths, opts, out, progress)
}

/// [`run_discover`] reporting its progress to `progress` as one task,
/// [`DISCOVER_TASK`], with a known total: the workflow's steps
/// (`discovery::workflow::Observer::steps`), so that a display can show an ETA. The task
/// is finished (`ProgressSink::finish`) when the workflow ends, whether it succeeded or
/// not; [`DiscoverOptions::progress`] is not used.
pub fn run_discover_with_progress(
    data_paths: &[PathBuf],
    model_path: &Path,
    val_paths: &[PathBuf],
    opts: &DiscoverOptions,
    out: &Path,
    progress: &dyn ProgressSink,
) -> Result<DiscoverSummary> {
    let (original, x0_prior) = crate::model_file::read_model_and_prior(model_path)?;
    if !x0_prior.is_empty() {
        return Err(MmennError::Model {
            path: model_path.to_path_buf(),
            line: None,
            column: None,
            problem: crate::error::ModelProblem::PriorUnread { what: "discover" },
        });
    }
    // Discovery's MME, proposals and free-run gaps would ignore an acquisition filter.
    original.refuse_acquisition("discover", model_path)?;
    original.refuse_uncorrected("discover", model_path)?;
    // Free-run simulations treat the inputs between samples as the model file says (the
    // records come back tagged with its `intersample`).
    let (data, val) = crate::data_file::read_with_validation(data_paths, val_paths, &original)?;
    ensure_dir(out)?;
    if original.mechanics.is_some() {
        // A mass matrix: missing effects are generalized forces per joint.
        return force::run_force_discover(&original, &data, val.as_ref(), opts, out, progress);
    }
    let base_model = original.term_model().map_err(|problem| MmennError::Model {
        path: model_path.to_path_buf(),
        line: None,
        column: None,
        problem,
    })?;
    // The model file's `[roles]` first, then any a library caller set (later ones win).
    let roles = original
        .roles
        .iter()
        .map(|(name, role)| (name.clone(), *role))
        .chain(opts.workflow.roles.iter().cloned())
        .collect();
    let config = WorkflowConfig {
        noise_given: matches!(original.noise_variance, NoiseVariance::Given(_)),
        roles,
        ..opts.workflow.clone()
    };
    let observer = Reported {
        sink: progress,
        stage: std::sync::Mutex::new(String::new()),
        latest: std::sync::Mutex::new(None),
    };
    let mme = MmeCore {
        spec: &original,
        options: &opts.estimate,
        first_noise: std::sync::Mutex::new(None),
        first_convergence: std::sync::Mutex::new(None),
        reported: &observer,
    };
    let outcome = workflow::run(
        &mme,
        &base_model,
        &original.units,
        &data,
        val.as_ref(),
        &config,
        &observer,
    );
    progress.finish(DISCOVER_TASK);
    let outcome = outcome?;

    let (mut before, y_before) = free_run_gap(&base_model, &data, opts.workflow.x0_window)?;
    before.d_rms = workflow::d_rms(&outcome.first_estimate);
    let mut spec = original.clone();
    spec.terms.extend(outcome.added.iter().map(|t| TermEntry {
        state: t.state.clone(),
        into: t.into.clone(),
        effect: t.effect.clone(),
        term: t.term.clone(),
        coefficient: t.coefficient,
    }));
    let final_model = &outcome.model;
    let (mut after, y_after) = free_run_gap(final_model, &data, opts.workflow.x0_window)?;
    if let Some(est) = &outcome.final_estimate {
        after.d_rms = workflow::d_rms(est);
    }
    let validation_runs = match &val {
        Some(v) => {
            let (before, y_before) = free_run_gap(&base_model, v, opts.workflow.x0_window)?;
            let (after, y_after) = free_run_gap(final_model, v, opts.workflow.x0_window)?;
            Some((GapPair { before, after }, y_before, y_after))
        }
        None => None,
    };
    let validation_gap = validation_runs.as_ref().map(|(g, _, _)| g.clone());
    let estimation_gap = GapPair { before, after };
    let degradation = if outcome.added.is_empty() {
        None
    } else {
        degradation_guard(&estimation_gap, validation_gap.as_ref())
    };
    let rejected = degradation.as_ref().is_some_and(|g| g.rejected);
    let mut written = if rejected {
        original.clone()
    } else {
        spec.clone()
    };
    if let NoiseVariance::Auto = original.noise_variance {
        written.noise_variance = NoiseVariance::Auto;
    }
    let rejected_path = out.join("model.rejected.toml");
    if rejected {
        let mut augmented = spec.clone();
        if let NoiseVariance::Auto = original.noise_variance {
            augmented.noise_variance = NoiseVariance::Auto;
        }
        write_model(&rejected_path, &augmented)?;
    } else if rejected_path.exists() {
        // A rerun into the same folder must not leave an earlier run's rejected model.
        std::fs::remove_file(&rejected_path).map_err(|source| MmennError::Io {
            path: rejected_path.clone(),
            source,
        })?;
    }
    write_model(&out.join("model.discovered.toml"), &written)?;
    let (mut verdict, mut effects, mut unconfirmed) =
        (outcome.verdict, outcome.effects, outcome.unconfirmed);
    if rejected {
        unconfirmed.append(&mut effects);
        verdict = Verdict::Unexplained;
    }
    let mut warnings = mme
        .first_noise
        .lock()
        .ok()
        .and_then(|n| n.clone())
        .map(|n| crate::estimate::noise_warnings(&outcome.first_estimate.output_names, &n))
        .unwrap_or_default();
    if let Some(g) = &degradation {
        warnings.push(g.reason.clone());
    }
    warnings.extend(role_hints(
        base_model.linear(),
        &original.units,
        &config.roles,
    )?);
    let summary = DiscoverSummary {
        verdict,
        effects,
        unconfirmed,
        claim_bound: outcome.claim_bound,
        judgement: outcome.judgement,
        judge_note: outcome.judge_note,
        passengers: outcome.passengers,
        ambiguity: outcome.ambiguity,
        stand_in: outcome.stand_in,
        stand_in_note: outcome.stand_in_note,
        warnings,
        degradation,
        gap: estimation_gap,
        validation_gap,
        model: "model.discovered.toml".into(),
        mme_termination: outcome.first_estimate.report.termination,
        mme_estimate: mme.first_convergence.lock().ok().and_then(|m| m.clone()),
        generalized_forces: false,
        rounds: outcome.rounds,
    };
    let val_outputs = match (&val, validation_runs) {
        (Some(v), Some((_, before, after))) => Some((v, before, after)),
        _ => None,
    };
    let text = report(&summary);
    write_outputs(
        &summary,
        &spec,
        (&data, y_before, y_after),
        val_outputs,
        &text,
        out,
    )?;
    Ok(summary)
}

/// Free-run outputs of one record set: the records, the assumed and the discovered
/// model's simulated outputs (`p × N`).
type GapOutputs<'a> = (&'a Dataset, DMatrix<f64>, DMatrix<f64>);

/// The figures, `discovery.json` and `report.md` (the report's `text` followed by the
/// figures) of a run.
fn write_outputs(
    summary: &DiscoverSummary,
    spec: &ModelSpec,
    estimation: GapOutputs<'_>,
    validation: Option<GapOutputs<'_>>,
    text: &str,
    out: &Path,
) -> Result<()> {
    let (data, before, after) = estimation;
    let estimation_run = report::GapRun {
        data,
        gap: &summary.gap,
        before,
        after,
    };
    let validation_run = match (validation, &summary.validation_gap) {
        (Some((data, before, after)), Some(gap)) => Some(report::GapRun {
            data,
            gap,
            before,
            after,
        }),
        _ => None,
    };
    let files = figures(summary, spec, &estimation_run, validation_run.as_ref(), out)?;
    write_atomic(
        &out.join("discovery.json"),
        serde_json::to_string_pretty(summary)?.as_bytes(),
    )?;
    let markdown = text.to_string() + &crate::html::figures_section(&files);
    crate::html::write_report(out, &markdown)
}

/// A warning per state whose unit hid the role its name gives (a level read in volts is
/// `other`: no orifice or overflow law is tried on it), naming the `[roles]` line that
/// would give it.
fn role_hints(
    linear: &sysid_core::LinearModel,
    units: &BTreeMap<String, String>,
    given: &[(String, discovery::Role)],
) -> Result<Vec<String>> {
    let hidden = discovery::StateRoles::unit_overrules_name(linear, units, given)?;
    Ok(hidden
        .into_iter()
        .map(|(state, by_unit, by_name)| {
            let laws = match by_name {
                discovery::Role::Level => "orifice or overflow",
                _ => "angle (gravity, input coupling)",
            };
            format!(
                "{state}: its name reads as a{} {} but its unit ({}) makes it {}, so no {laws} \
                 law was tried on it; if it is one, say so in the model file: [roles] {state} = \
                 \"{}\"",
                if by_name == discovery::Role::Angle {
                    "n"
                } else {
                    ""
                },
                crate::words::role(by_name),
                units.get(&state).map_or("?", String::as_str),
                crate::words::role(by_unit),
                crate::words::role(by_name),
            )
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A level read in volts is named in a warning with the `[roles]` line that gives its
    /// role; one given, or one in metres, is not.
    #[test]
    fn levels_hidden_by_their_unit_are_named_with_the_fix() {
        // h2 in metres: a level by its unit.
        let text = crate::model_file::TWO_TANKS_IN_VOLTS.replace("h2 = \"V\"", "h2 = \"m\"");
        let spec = crate::model_file::parse_model(Path::new("m.toml"), &text).unwrap();
        let hints = role_hints(&spec.linear, &spec.units, &[]).unwrap();
        assert_eq!(hints.len(), 1, "{hints:?}");
        assert!(
            hints[0].starts_with("h1: ") && hints[0].contains("[roles] h1 = \"level\""),
            "{hints:?}"
        );
        let given = [("h1".to_string(), discovery::Role::Level)];
        assert!(
            role_hints(&spec.linear, &spec.units, &given)
                .unwrap()
                .is_empty()
        );
    }

    fn gap(fits: &[(&str, f64)]) -> Gap {
        Gap {
            fit_percent: fits.iter().map(|(n, f)| (n.to_string(), *f)).collect(),
            ..Gap::default()
        }
    }

    fn pair(before: &[(&str, f64)], after: &[(&str, f64)]) -> GapPair {
        GapPair {
            before: gap(before),
            after: gap(after),
        }
    }

    /// A record of `ẋ = −0.7·x + u` (`x` measured, no noise) from `x(0) = 0.3` under the
    /// ZOH input `amplitude·sin(ω t)`, integrated by hand with the exact ZOH step.
    fn scalar_record(amplitude: f64, omega: f64, n: usize) -> sysid_core::Experiment {
        let (a, dt) = (-0.7_f64, 0.05);
        let decay = (a * dt).exp();
        let u: Vec<f64> = (0..n)
            .map(|k| amplitude * (omega * k as f64 * dt).sin())
            .collect();
        let mut x = vec![0.3; n];
        for k in 1..n {
            x[k] = decay * x[k - 1] + (decay - 1.0) / a * u[k - 1];
        }
        sysid_core::Experiment::new(
            0.0,
            dt,
            DMatrix::from_row_slice(1, n, &u),
            DMatrix::from_row_slice(1, n, &x),
        )
        .unwrap_or_else(|e| panic!("{e}"))
    }

    /// The gap of a dataset of several records pools them: squared errors summed over
    /// every record's samples give the RMSE, and over the pooled spread the fit %; the
    /// simulated outputs returned are the first record's. The assumed `ẋ = −x + u` misses
    /// the truth `ẋ = −0.7·x + u` far more on the second record (five times the input), so
    /// judging the first record alone gives other numbers.
    #[test]
    fn the_free_run_gap_pools_every_record() {
        let names = sysid_core::ModelNames {
            states: vec!["x".into()],
            inputs: vec!["u".into()],
            outputs: vec!["x".into()],
            corrections: vec!["x".into()],
        };
        let one = |v: f64| DMatrix::from_element(1, 1, v);
        let linear =
            sysid_core::LinearModel::with_names(one(-1.0), one(1.0), one(1.0), one(1.0), names)
                .unwrap_or_else(|e| panic!("{e}"));
        let model = TermModel::new(linear, vec![]).unwrap_or_else(|e| panic!("{e}"));
        let records = vec![scalar_record(0.2, 0.9, 600), scalar_record(1.0, 0.4, 900)];
        let data = Dataset::new(
            vec![sysid_core::Channel::new("u")],
            vec![sysid_core::Channel::new("x")],
            records.clone(),
        )
        .unwrap_or_else(|e| panic!("{e}"));
        let window = 50;
        let (gap, y) = free_run_gap(&model, &data, window).unwrap_or_else(|e| panic!("{e}"));

        // Each record judged alone by the validation rule, pooled by hand.
        let (mut sse, mut n, mut sum, mut sum_sq) = (0.0, 0usize, 0.0, 0.0);
        let mut first_alone = None;
        for exp in &records {
            let j = discovery::validation::judge_record(&model, model.linear(), exp, window, false)
                .unwrap_or_else(|e| panic!("{e}"));
            let m = &j.channels["x"];
            sse += m.rmse * m.rmse * m.samples as f64;
            n += m.samples;
            for &v in exp.outputs().iter() {
                sum += v;
                sum_sq += v * v;
            }
            first_alone.get_or_insert((m.rmse, m.fit_percent, j.outputs));
        }
        let nf = n as f64;
        let sst = sum_sq - sum * sum / nf;
        let (rmse, fit) = ((sse / nf).sqrt(), 100.0 * (1.0 - (sse / sst).sqrt()));
        let (rmse_first, fit_first, y_first) = first_alone.unwrap_or_else(|| panic!("no record"));
        assert!(
            (gap.rmse["x"] - rmse).abs() <= 1e-9 * rmse,
            "{} vs {rmse}",
            gap.rmse["x"]
        );
        assert!(
            (gap.fit_percent["x"] - fit).abs() <= 1e-6,
            "{} vs {fit}",
            gap.fit_percent["x"]
        );
        // Not the first record's numbers.
        assert!(
            rmse > 2.0 * rmse_first,
            "pooled {rmse} vs first {rmse_first}"
        );
        assert!(
            (fit - fit_first).abs() > 1.0,
            "pooled {fit} vs first {fit_first}"
        );
        // The figures' outputs: the first record's free run.
        assert_eq!(y.shape(), y_first.shape());
        assert!(
            y.iter()
                .zip(y_first.iter())
                .all(|(a, b)| (a - b).abs() <= 1e-12)
        );
    }

    #[test]
    fn a_model_no_worse_on_its_estimation_records_passes_the_guard() {
        // Better, equal, and within the allowed drop (mean over outputs).
        assert!(degradation_guard(&pair(&[("x", 40.0)], &[("x", 90.0)]), None).is_none());
        assert!(degradation_guard(&pair(&[("x", 40.0)], &[("x", 40.0)]), None).is_none());
        let within = pair(&[("x", 40.0), ("y", 60.0)], &[("x", 38.5), ("y", 60.0)]);
        assert!(degradation_guard(&within, None).is_none());
    }

    #[test]
    fn a_drop_without_validation_records_is_reported_not_rejected() {
        let g = degradation_guard(&pair(&[("theta2", 40.7)], &[("theta2", -216.0)]), None)
            .expect("guard fires");
        assert!(!g.rejected);
        assert!((g.estimation_drop - 256.7).abs() < 1e-9);
        assert_eq!(g.validation_gain, None);
        assert!(g.reason.contains("kept"), "{}", g.reason);
    }

    #[test]
    fn the_reported_case_is_rejected() {
        // Issue 20: estimation fit from 40.7 % to −216 % while the validation fit rose
        // (here by 4 points): rejected.
        let est = pair(&[("theta2", 40.7)], &[("theta2", -216.0)]);
        let val = pair(&[("theta2", 50.0)], &[("theta2", 54.0)]);
        let g = degradation_guard(&est, Some(&val)).expect("guard fires");
        assert!(g.rejected);
        assert!(g.reason.contains("rejected"), "{}", g.reason);
    }

    #[test]
    fn a_drop_is_kept_only_when_every_validation_output_gains_enough() {
        let est = pair(&[("a", 40.0), ("b", 50.0)], &[("a", 30.0), ("b", 50.0)]);
        let all = pair(&[("a", 20.0), ("b", 30.0)], &[("a", 35.0), ("b", 41.0)]);
        let g = degradation_guard(&est, Some(&all)).expect("guard fires");
        assert!(!g.rejected, "{}", g.reason);
        assert_eq!(g.validation_gain, Some(11.0));
        assert!(g.reason.contains("kept"));
        // One output gains less than the bound: rejected.
        let one = pair(&[("a", 20.0), ("b", 30.0)], &[("a", 35.0), ("b", 39.0)]);
        let g = degradation_guard(&est, Some(&one)).expect("guard fires");
        assert!(g.rejected);
        assert_eq!(g.validation_gain, Some(9.0));
    }

    #[test]
    fn an_output_without_a_fit_counts_as_a_drop() {
        let val = pair(&[("x", 40.0)], &[("x", 42.0)]);
        let g = degradation_guard(&pair(&[("x", 40.0)], &[("x", f64::NAN)]), Some(&val))
            .expect("guard fires");
        assert!(g.rejected);
        assert!(g.reason.contains("undefined"));
    }
}
