//! `mmenn fit` and `mmenn predict`: the MME/NN hybrid model (thesis ch. 4). MME gives
//! `x̂(t)`, `d̂(t)`; a network learns `(x̂, u) → d̂`; by default its weights are then trained
//! on the training trajectories (thesis §7.1; [`TrajectorySummary`]); the plant model
//! `ẋ = f(x, u) + E·NN(x, u)` then predicts free-run from an initial state. Every step
//! (MME, network selection, trajectory training, free runs, `predict`) treats the inputs
//! between samples as the model file's `intersample` says; `model.json` keeps the model
//! file, so `predict` follows the setting the model was fitted with.
//!
//! The hybrid is never kept when it is worse than the physics it starts from: the guard
//! ([`GuardReport`]) runs the assumed model alone, the network before trajectory training
//! and after it free on held-out training data (the last fifth of the first training
//! record, or K folds) and keeps the best; the report says which and why, and whether
//! the trajectory training hurt. Validation records are only judged, unless they are
//! given for choosing too ([`ValidationUse::Select`], the thesis's use: then the guard
//! judges on the first of them, the sweep tests on them and the trajectory training stops
//! early on them, and their fit is optimistic). Under [`DomainPolicy::Checked`] (the command line's
//! default) each network candidate first meets an amplitude stress check and holds its
//! edge value outside its training box when it fails ([`DomainCheck`]).
//!
//! Nor is a hybrid built on an MME estimate that did not converge, unless asked for: every
//! estimate [`compute_fit`] runs (on the training records, again after the regression
//! update, on the validation records when they choose, and the K-fold guard's on each fold) is checked as
//! soon as it ends, and one that ended anything but `exact` or `converged` — or a `W`
//! search `not_bracketed` below 1 within the sampling band of a correct model
//! ([`MmeConvergence::converged`], docs/decisions/mme-ratio-tolerance.md) — makes it return
//! [`MmennError::MmeNotConverged`] before any network is trained on it, naming the estimate
//! ([`MmeStage`], and the fold), its ending and its residual/noise variance ratios. Under
//! [`UnconvergedMme::Warn`] (what `mmenn fit` and `mmenn compare` use) it goes on, and
//! [`FitSummary::mme_estimates`] (`mme_estimates` in `summary.json`) and
//! [`FitSummary::mme_converged`] say so; `mmenn fit` then writes its results for
//! inspection and exits with status 3.

use std::collections::BTreeMap;
use std::ops::Range;
use std::path::{Path, PathBuf};

use nalgebra::DMatrix;
use nn::{Mlp, SweepConfig, SweepRow};
use serde::Serialize;
use sysid_core::{Dataset, Experiment, MmeEstimate};

use crate::error::{MmennError, Result};
use crate::estimate::{EstimateOptions, estimate_spec, mme_config};
/// `model.json` lives in [`crate::hybrid`]; these names stay reachable from here.
pub use crate::hybrid::{HYBRID_FORMAT, HybridFile, HybridModel, hybrid_model};
/// The free-run report is the judge's ([`crate::model`]); it stays reachable from here.
pub use crate::model::FreeRunReport;
use crate::model::{InitialRule, Judgement, LoadedModel, ModelDynamics, ModelKind, judge_free_run};
use crate::model_file::{ModelSpec, format_model};
/// `predict` lives in [`crate::predict`]; these names stay reachable from here.
pub use crate::predict::{
    InitialChoice, PredictOptions, PredictSummary, run_predict, run_predict_with,
};
pub use choices::{
    DomainPolicy, HiddenChoice, ModelUpdateChoice, NetworkEnsemble, NetworkInputs,
    NetworkSelection, Training, ValidationUse,
};
pub use convergence::{
    FoldEstimate, MmeConvergence, MmeStage, SAMPLING_BAND_Z, UnconvergedMme, sampling_band,
};
pub use guard::{
    CandidateScore, DomainCheck, FoldScores, GuardCandidate, GuardHeldOut, GuardReport,
    STRESS_FACTOR, StressChannel, StressCheck, StressVerdict, stress_input,
};
pub use output::write_fit;
use trajectory::train_network_on_trajectories;
pub use trajectory::{TrajectoryChoice, TrajectorySummary};

mod choices;
mod convergence;
mod d_figures;
mod folds;
pub(crate) mod guard;
mod output;
mod trajectory;

/// Options of [`run_fit`].
#[derive(Debug, Clone, PartialEq)]
pub struct FitOptions {
    /// MME's `W` and sub-steps.
    pub estimate: EstimateOptions,
    /// Network size.
    pub hidden: HiddenChoice,
    /// Initialisations per size.
    pub inits: usize,
    /// Seed of every random choice (initialisations, validation split).
    pub seed: u64,
    /// Fraction of samples dropped at each end of every record before training (the
    /// smoother's end effects make `d̂` least reliable there). Default 0.02.
    pub trim_fraction: f64,
    /// RK4 sub-steps per sample interval in free-run simulation. Default 4.
    pub substeps: usize,
    /// Samples used to fit the initial state of validation records. Default 200.
    pub x0_window: usize,
    /// Largest network tried by the automatic sizing sweep. Default 10 (thesis §3.1).
    pub max_hidden: usize,
    /// Whether to update the assumed model by regression first (thesis §4.3.3).
    pub update: ModelUpdateChoice,
    /// How the network is picked from the sweep.
    pub selection: NetworkSelection,
    /// Whether the network is then trained on trajectories (thesis §7.1;
    /// `--train-on-trajectories` on the command line).
    pub train_on_trajectories: TrajectoryChoice,
    /// Settings of that training (its `substeps` is replaced by [`FitOptions::substeps`]).
    pub trajectory: nn::TrajectoryConfig,
    /// How the networks are trained. Default [`Training::Trainlm`].
    pub training: Training,
    /// One network or the average of the equally good ones. Default
    /// [`NetworkEnsemble::Single`].
    pub ensemble: NetworkEnsemble,
    /// Where the guard judges physics alone, the network and the refined network unless
    /// validation data choose ([`ValidationUse::Select`]). Default [`GuardHeldOut::LastFifth`].
    pub guard: GuardHeldOut,
    /// What the network does outside the box its training pairs spanned, or how the
    /// guard decides it per candidate. Default [`DomainPolicy::Extrapolate`] (the thesis
    /// method, unchecked: the library's default is unchanged, and `cargo xtask reproduce`
    /// relies on it). The command line's default is [`DomainPolicy::Checked`]: a network
    /// candidate that fails the guard's amplitude stress check (the held-out input scaled
    /// by [`STRESS_FACTOR`] about its mean) holds ([`nn::Domain::Hold`]); the others
    /// extrapolate. `--network-domain hold` (or `--hold-network-domain`) for
    /// [`DomainPolicy::Hold`]. The network sweep's free-run selection and the trajectory
    /// training use [`DomainPolicy::initial`].
    pub network_domain: DomainPolicy,
    /// What the network reads: `(x̂, u)` or the states alone. Default
    /// [`NetworkInputs::StatesAndInputs`] (the thesis; `--network-inputs states` on the
    /// command line for the states alone).
    pub network_inputs: NetworkInputs,
    /// What happens when an MME estimate the fit builds on does not converge. Default
    /// [`UnconvergedMme::Refuse`]: [`compute_fit`] returns
    /// [`MmennError::MmeNotConverged`] before training any network. The command line uses
    /// [`UnconvergedMme::Warn`] (and exits with status 3 after writing the results).
    pub on_unconverged_mme: UnconvergedMme,
    /// What validation records are for: scoring only (the default) or also the fit's
    /// choices ([`ValidationUse`]; `--val-use` on the command line).
    pub validation_use: ValidationUse,
}

/// Index of the network whose hybrid model simulates the training record best free-run,
/// and its sum of squared output errors (observed samples of every channel, first
/// experiment, samples in `skip` not scored; inputs between samples as its
/// `intersample` says).
fn select_by_free_run(
    spec: &ModelSpec,
    networks: &[Mlp],
    data: &Dataset,
    x0: &[f64],
    substeps: usize,
    domain: nn::Domain,
    skip: Option<&Range<usize>>,
) -> Result<(usize, f64)> {
    let exp = &data.experiments()[0];
    let c = spec.linear.c();
    let mut best: Option<(usize, f64)> = None;
    for (i, net) in networks.iter().enumerate() {
        let model = hybrid_model(spec, net.clone(), x0, substeps, domain)?;
        let Ok(xs) = model.simulate_experiment_states(x0, exp, 0..exp.len()) else {
            continue;
        };
        let y = c * xs;
        let mut sse = 0.0;
        for k in (0..exp.len()).filter(|k| skip.is_none_or(|r| !r.contains(k))) {
            for (j, m) in exp.output(k).iter().enumerate() {
                if !m.is_nan() {
                    sse += (m - y[(j, k)]).powi(2);
                }
            }
        }
        if sse.is_finite() && best.is_none_or(|(_, b)| sse < b) {
            best = Some((i, sse));
        }
    }
    best.ok_or(MmennError::Core {
        context: "choosing the network by free-run error",
        source: sysid_core::CoreError::Diverged {
            t: exp.t0(),
            state: 0,
            value: f64::NAN,
        },
    })
}

impl Default for FitOptions {
    fn default() -> Self {
        Self {
            estimate: EstimateOptions::default(),
            hidden: HiddenChoice::Auto,
            inits: 10,
            seed: 1,
            trim_fraction: 0.02,
            substeps: 4,
            x0_window: 200,
            max_hidden: 10,
            update: ModelUpdateChoice::None,
            selection: NetworkSelection::CorrectionMse,
            train_on_trajectories: TrajectoryChoice::default(),
            trajectory: nn::TrajectoryConfig::default(),
            training: Training::Trainlm,
            ensemble: NetworkEnsemble::Single,
            guard: GuardHeldOut::LastFifth,
            network_domain: DomainPolicy::Extrapolate,
            network_inputs: NetworkInputs::StatesAndInputs,
            on_unconverged_mme: UnconvergedMme::Refuse,
            validation_use: ValidationUse::Score,
        }
    }
}

/// Training pairs `([x̂; u], d̂)` from an estimate, ends trimmed.
pub fn training_pairs(
    est: &MmeEstimate,
    data: &Dataset,
    trim_fraction: f64,
) -> (DMatrix<f64>, DMatrix<f64>) {
    training_pairs_without(
        est,
        data,
        trim_fraction,
        None,
        NetworkInputs::StatesAndInputs,
    )
}

/// Training pairs `([x̂; u], d̂)` (or `(x̂, d̂)` for a states-only network) without the
/// samples `skip` of the first record.
fn training_pairs_without(
    est: &MmeEstimate,
    data: &Dataset,
    trim_fraction: f64,
    skip: Option<&Range<usize>>,
    inputs: NetworkInputs,
) -> (DMatrix<f64>, DMatrix<f64>) {
    let n = est.state_names.len();
    let m = match inputs {
        NetworkInputs::StatesAndInputs => data.input_channels().len(),
        NetworkInputs::States => 0,
    };
    let q = est.correction_names.len();
    let mut cols_x = Vec::new();
    let mut cols_d = Vec::new();
    for (i, (e, exp)) in est.experiments.iter().zip(data.experiments()).enumerate() {
        let d = e.corrections_at_samples();
        let len = e.len();
        let cut = ((len as f64) * trim_fraction).floor() as usize;
        let skipped = |k: &usize| i == 0 && skip.is_some_and(|r| r.contains(k));
        for k in (cut..len.saturating_sub(cut)).filter(|k| !skipped(k)) {
            cols_x.extend(e.states.column(k).iter().copied());
            cols_x.extend(exp.input(k).iter().take(m).copied());
            cols_d.extend(d.column(k).iter().copied());
        }
    }
    let count = cols_x.len() / (n + m).max(1);
    (
        DMatrix::from_column_slice(n + m, count, &cols_x),
        DMatrix::from_column_slice(q, count, &cols_d),
    )
}

/// The hybrid model of a model file, a network, a stored initial state and sub-steps, as
/// a loaded model (what `model.json` holds, in memory).
pub(crate) fn hybrid_loaded(
    spec: &ModelSpec,
    network: &Mlp,
    x0: &[f64],
    dt: f64,
    substeps: usize,
    domain: nn::Domain,
) -> Result<(HybridFile, LoadedModel)> {
    let file = HybridFile {
        format: HYBRID_FORMAT.into(),
        model_toml: format_model(spec)?,
        network: network.clone(),
        x0: x0.to_vec(),
        dt,
        substeps,
        domain,
    };
    let model = hybrid_model(spec, network.clone(), x0, substeps, domain)?;
    let loaded = LoadedModel {
        path: PathBuf::from("model.json"),
        kind: ModelKind::Hybrid,
        spec: spec.clone(),
        integrator: model.integrator,
        dynamics: ModelDynamics::Hybrid(model),
        hybrid: Some(file.clone()),
        x0_prior: Vec::new(),
    };
    Ok((file, loaded))
}

/// The one free-run judge on the first record of `data`, on the model's outputs, the
/// initial state fitted to the first `window` samples.
pub(crate) fn judge_outputs(
    model: &LoadedModel,
    data: &Dataset,
    window: usize,
) -> Result<Judgement> {
    judge_free_run(
        model,
        &data.experiments()[0],
        &model.outputs(),
        &InitialRule::Fit {
            window: Some(window),
        },
    )
}

/// MME's `x̂` at the first sample of the first record: where free runs of the training
/// record start.
fn first_state(est: &MmeEstimate) -> Vec<f64> {
    est.experiments[0]
        .states
        .column(0)
        .iter()
        .copied()
        .collect()
}

fn row(m: &DMatrix<f64>, i: usize) -> Vec<f64> {
    m.row(i).iter().copied().collect()
}

/// What `mmenn fit` reports.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FitSummary {
    /// Hidden units of the chosen network (of the merged one, for an ensemble).
    pub hidden: usize,
    /// The chosen sweep row.
    pub chosen: SweepRow,
    /// How it was chosen.
    pub selection: NetworkSelection,
    /// How the networks were trained.
    pub training: Training,
    /// Sweep rows averaged into the network (`ensemble: band`; empty for one network).
    pub ensemble_rows: Vec<usize>,
    /// Free-run sum of squared output errors on the training record of the chosen network
    /// (when chosen by free-run error).
    pub free_run_sse: Option<f64>,
    /// Number of training pairs.
    pub training_pairs: usize,
    /// Where the sweep's test MSE came from.
    pub test_source: String,
    /// MME's `W` diagonal on the training data.
    pub w_by_correction: BTreeMap<String, f64>,
    /// How MME's solve on the training data ended (`exact` for a given `W`, otherwise
    /// the `W` search's ending: `converged`, `not_bracketed`, …); the estimate the network
    /// learns from (after the regression update, when asked for). Every estimate, with
    /// its stage and residual/noise variance ratios: [`FitSummary::mme_estimates`].
    pub mme_termination: Option<sysid_core::Termination>,
    /// How every MME estimate the fit ran ended, in order: the training estimate, the
    /// re-estimate after the regression update (when asked for), the validation estimate
    /// (when validation data choose, [`ValidationUse::Select`]), then each of the K-fold guard's estimates that did
    /// not converge (its fold's [`FoldScores::unconverged_mme`]). Any that did not converge
    /// ([`MmeConvergence::converged`]) makes `mmenn fit` exit with status 3, and is only
    /// here under [`UnconvergedMme::Warn`] (otherwise [`compute_fit`] refuses).
    pub mme_estimates: Vec<MmeConvergence>,
    /// The automatic `W` search on the training data, when it ran.
    pub w_search: Option<mme_core::WSearch>,
    /// The regression update of the assumed model, when asked for (coefficients ± σ).
    pub model_update: Option<Vec<mme_core::CorrectionRegression>>,
    /// Free-run on the training record(s), first experiment.
    pub train: FreeRunReport,
    /// Free-run on the validation record, when given.
    pub validation: Option<FreeRunReport>,
    /// Trajectory training of the network, when asked for (`refinement` in
    /// `summary.json`, for the readers of that file).
    pub refinement: Option<TrajectorySummary>,
    /// Which of physics alone, the network before and after refinement was kept, judged
    /// free-run on held-out data (never a test record), and whether refinement hurt.
    pub guard: GuardReport,
    /// The box of the network's training pairs, `(name, low, high)` per network input
    /// (states, then inputs): where the correction was learnt.
    pub network_box: Vec<(String, f64, f64)>,
    /// What the kept network does outside that box (how it was decided:
    /// [`GuardReport::domain`]).
    pub network_domain: nn::Domain,
    /// What the network reads.
    pub network_inputs: NetworkInputs,
    /// Files written.
    pub files: Vec<String>,
    /// What the validation records were for (`None` without them): only judged, or also
    /// chosen on (then their fit is optimistic).
    pub validation_use: Option<ValidationUse>,
}

impl FitSummary {
    /// Whether every MME estimate the fit ran converged ([`MmeConvergence::converged`]).
    pub fn mme_converged(&self) -> bool {
        self.mme_estimates.iter().all(MmeConvergence::converged)
    }

    /// The MME estimates that did not converge, in the order they ran (empty when
    /// [`FitSummary::mme_converged`]).
    pub fn unconverged_mme(&self) -> Vec<&MmeConvergence> {
        self.mme_estimates
            .iter()
            .filter(|m| !m.converged())
            .collect()
    }

    /// What the validation records were for, in one sentence (`None` without them).
    pub fn validation_use_line(&self) -> Option<&'static str> {
        self.validation_use.map(|u| match u {
            ValidationUse::Score => {
                "The validation records were scored only: every choice of the fit was made \
                 on the training records (`--val-use score`), so their fit is an independent \
                 number."
            }
            ValidationUse::Select => {
                "The validation records also chose the model (`--val-use select`: the \
                 sweep's test set, trajectory training's early stopping and the guard), so \
                 their fit is optimistic; judge the model on a further record with `predict`."
            }
        })
    }
}

/// Run MME on the data, train the network (sweep or fixed size), build the hybrid model,
/// judge it free-run on the training and (if given) validation data, and write
/// `model.json`, `sweep.csv`, `summary.json`, figures and `report.md` into `out`.
pub fn run_fit(
    data_paths: &[PathBuf],
    model_path: &Path,
    val_paths: &[PathBuf],
    opts: &FitOptions,
    out: &Path,
) -> Result<FitSummary> {
    run_fit_with_progress(
        data_paths,
        model_path,
        val_paths,
        opts,
        out,
        &crate::progress::NoProgress,
    )
}

/// [`run_fit`], reporting the MME estimate and the network sizing sweep (one step per
/// trained network) to `progress`. The results do not depend on the sink. Reads the
/// files, [`compute_fit`], [`write_fit`]. The model may be any model file (with or
/// without `[[terms]]`, e.g. `discover`'s `model.discovered.toml`) or a hybrid
/// `model.json`, whose model-file part is the assumed model (its network is replaced).
pub fn run_fit_with_progress(
    data_paths: &[PathBuf],
    model_path: &Path,
    val_paths: &[PathBuf],
    opts: &FitOptions,
    out: &Path,
    progress: &dyn crate::progress::ProgressSink,
) -> Result<FitSummary> {
    let loaded = LoadedModel::read(model_path)?;
    loaded.refuse_x0_prior("fit")?;
    let spec = loaded.spec;
    spec.refuse_uncorrected("fit", model_path)?;
    if opts.update == ModelUpdateChoice::Regression {
        spec.refuse_mechanics("fit --update-model regression", model_path)?;
    }
    // The regression update changes A and B only, so channel names stay valid for both.
    let (data, val) = crate::data_file::read_with_validation(data_paths, val_paths, &spec)?;
    let outcome = compute_fit(&data, &spec, val.as_ref(), opts, progress)?;
    write_fit(&outcome, out)?;
    Ok(outcome.summary)
}

/// Everything `mmenn fit` computes, as values ([`write_fit`] writes it).
#[derive(Debug, Clone)]
pub struct FitOutcome {
    /// What `summary.json` holds.
    pub summary: FitSummary,
    /// What `model.json` holds.
    pub model: HybridFile,
    /// The assumed model (after the regression update, when asked for).
    pub spec: ModelSpec,
    /// The network sizing sweep (`sweep.csv`).
    pub sweep: Vec<SweepRow>,
    /// Index of the chosen sweep row.
    pub chosen: usize,
    /// The free-run judgement on the first training record.
    pub train: Judgement,
    /// The free-run judgement on the first validation record, when given.
    pub validation: Option<Judgement>,
    /// The first training record.
    pub train_record: Experiment,
    /// The first validation record, when given.
    pub validation_record: Option<Experiment>,
    /// MME's `d̂` at the training pairs (`q × pairs`).
    pub d_train: DMatrix<f64>,
    /// The network's output at the training pairs (`q × pairs`).
    pub d_network: DMatrix<f64>,
    /// The network's inputs at the training pairs (`(n + m) × pairs`: x̂ then u; `n ×
    /// pairs` for a states-only network).
    pub x_train: DMatrix<f64>,
}

impl FitOutcome {
    /// Whether every MME estimate the hybrid was built on converged
    /// ([`FitSummary::mme_converged`]; false only under [`UnconvergedMme::Warn`]).
    pub fn mme_converged(&self) -> bool {
        self.summary.mme_converged()
    }
}

/// The files [`write_fit`] writes, in order.
fn fit_files(spec: &ModelSpec, validation: bool, inputs: NetworkInputs) -> Vec<String> {
    let mut files = vec!["compare_train.svg".to_string()];
    if validation {
        files.push("compare_validation.svg".into());
    }
    for name in spec.linear.correction_names() {
        files.push(format!("nn_d_{name}.svg"));
        for var in network_variables(spec, inputs) {
            files.push(format!("nn_d_{name}_vs_{var}.svg"));
        }
    }
    for f in [
        "sweep.csv",
        "sweep.svg",
        "model.json",
        "summary.json",
        "report.md",
        "report.html",
    ] {
        files.push(f.into());
    }
    files
}

/// `mmenn fit` without files: MME on `data`, the network sweep (and refinement), the
/// hybrid model, and its free-run judgements on the first training and validation record
/// (the one judge: initial state fitted to the first `x0_window` samples from the
/// minimum-norm start and the model's `x̂(t0)`, every sample scored).
///
/// Each MME estimate is checked as it ends: one that did not converge returns
/// [`MmennError::MmeNotConverged`] before any network is trained, unless
/// [`FitOptions::on_unconverged_mme`] is [`UnconvergedMme::Warn`]
/// ([`FitSummary::mme_estimates`] records every estimate's ending either way).
pub fn compute_fit(
    data: &Dataset,
    spec: &ModelSpec,
    val: Option<&Dataset>,
    opts: &FitOptions,
    progress: &dyn crate::progress::ProgressSink,
) -> Result<FitOutcome> {
    spec.refuse_uncorrected("fit", Path::new("<model>"))?;
    if opts.update == ModelUpdateChoice::Regression {
        // The regression updates A and B; a `[mechanics]` model's dynamics are M⁻¹Q.
        spec.refuse_mechanics("fit --update-model regression", Path::new("<model>"))?;
    }
    let mut spec = spec.clone();
    // The measurement model (`[acquisition]`): MME, the network sweep, the guard and the
    // trajectory training work on the records deconvolved by the filter (inputs and
    // outputs), with the model between the filters (`spec`, without it); the written
    // model carries the filter, and the train and validation judgements read the
    // recorded records through it, as `predict` does.
    let acquisition = spec.acquisition.take();
    let recorded = data.clone().with_intersample(spec.intersample);
    let recorded_val = val.map(|v| v.clone().with_intersample(spec.intersample));
    let (data, val) = match &acquisition {
        Some(f) => (
            crate::acquisition::deconvolved_dataset(f, &recorded)?,
            recorded_val
                .as_ref()
                .map(|v| crate::acquisition::deconvolved_dataset(f, v))
                .transpose()?,
        ),
        None => (recorded.clone(), recorded_val.clone()),
    };
    let data = &data;
    // The validation records the fit chooses on: none unless they are given for
    // choosing too (`ValidationUse::Select`); otherwise every choice is made on the
    // training records as without them, and they are only judged at the end.
    let select_val = match opts.validation_use {
        ValidationUse::Select => val.as_ref(),
        ValidationUse::Score => None,
    };
    let config = mme_config(&spec, &opts.estimate);
    // Every estimate is checked as it ends: a refused one costs no network training.
    let mut mme_estimates = Vec::new();
    let mut check = |stage: MmeStage, out: &mme_core::MmeOutput, data: &Dataset| -> Result<()> {
        let report = MmeConvergence::of(stage, out, data);
        if !report.converged() && opts.on_unconverged_mme == UnconvergedMme::Refuse {
            return Err(MmennError::MmeNotConverged { report });
        }
        mme_estimates.push(report);
        Ok(())
    };
    let mut result = crate::progress::stage(progress, crate::progress::MME_TASK, || {
        let steps = crate::progress::MmeProgress::new(progress, crate::progress::MME_TASK);
        crate::estimate::estimate_spec_observed(&spec, data, &config, &steps)
    })?;
    check(MmeStage::Training, &result, data)?;
    let mut update_report = None;
    if opts.update == ModelUpdateChoice::Regression {
        let up = mme_core::update_model(
            &spec.linear,
            data,
            &result.estimate,
            &mme_core::UpdateConfig::default(),
        )?;
        spec.linear = up.model.clone();
        result = estimate_spec(&spec, data, &config)?;
        check(MmeStage::RegressionUpdate, &result, data)?;
        update_report = Some(up.regressions);
    }
    let lin = spec.linear.clone();
    let est = &result.estimate;
    let pairs = |est: &MmeEstimate, data: &Dataset| {
        training_pairs_without(est, data, opts.trim_fraction, None, opts.network_inputs)
    };
    let (x_train, d_train) = pairs(est, data);

    // The sweep's test set: MME on the validation data at the training W and noise when
    // they choose, else the last 20 % of the training pairs.
    let (fit_pairs, test_pairs, test_source, val_est) = match select_val {
        Some(v) => {
            let mut vconf = config.clone();
            vconf.w = mme_core::WeightSpec::Matrix(est.w.clone());
            vconf.noise_variance = mme_core::NoiseSpec::Given(est.noise_variance.clone());
            let vres = estimate_spec(&spec, v, &vconf)?;
            check(MmeStage::Validation, &vres, v)?;
            let (xv, dv) = pairs(&vres.estimate, v);
            (
                (x_train.clone(), d_train.clone()),
                (xv, dv),
                "MME on the validation data at the training W and noise".to_string(),
                Some(vres.estimate),
            )
        }
        None => {
            let (fit, test) = split_last_fifth(&x_train, &d_train);
            let why = if val.is_some() {
                "validation data scored only"
            } else {
                "no validation data given"
            };
            (
                fit,
                test,
                format!("last 20 % of the training pairs ({why})"),
                None,
            )
        }
    };
    let x0 = first_state(est);
    let val_pair = val_est.as_ref().zip(select_val);
    let whole = TrainingSet {
        fit: fit_pairs,
        test: test_pairs,
        data,
        skip: None,
        shooting: trajectory::shooting(data, est),
    };
    let Trained {
        sweep,
        chosen,
        free_run_sse,
        ensemble_rows,
        before: before_refinement,
        network,
        mut refinement,
    } = train_networks(&spec, &whole, val_pair, &x0, opts, progress)?;
    let hidden_units = network.hidden().first().copied().unwrap_or(0);

    let exp0 = &data.experiments()[0];
    // The guard: physics alone, the network before and after refinement, judged free-run
    // on held-out data; the best is kept.
    let mut candidates = vec![
        (
            guard::GuardCandidate::PhysicsAlone,
            guard::zero_network(&network)?,
        ),
        (guard::GuardCandidate::Network, before_refinement.clone()),
    ];
    let refined = network.clone();
    if refinement.is_some() {
        candidates.push((guard::GuardCandidate::Refined, network.clone()));
    }
    // The held-out data (the validation record when it chooses, else the last fifth of the
    // first training record): the last-fifth guard judges on them, and under `DomainPolicy::Checked` the
    // stress check scales their input (the K-fold guard's too).
    let held = guard::held_out(data, select_val, est, &x0, opts)?;
    let (candidates, domain_check) = guard::check_domains(
        &spec,
        candidates,
        &held,
        exp0.dt(),
        opts.substeps,
        opts.network_domain,
    )?;
    let (guard_report, network, kept_domain) = match (opts.guard, select_val) {
        (kind @ (GuardHeldOut::Folds(_) | GuardHeldOut::LastFifthRetrained), None) => {
            folds::choose_by_folds(
                &spec,
                est,
                data,
                &x0,
                kind,
                candidates,
                domain_check,
                opts,
                progress,
            )?
        }
        _ => guard::choose(
            &spec,
            candidates,
            &held,
            exp0.dt(),
            opts.substeps,
            domain_check,
        )?,
    };
    // The K-fold guard's estimates that did not converge (only under `Warn`).
    mme_estimates.extend(
        guard_report
            .folds
            .iter()
            .flat_map(|f| f.unconverged_mme.iter().cloned()),
    );
    // The model as written: with the acquisition filter, judged on the recorded records.
    spec.acquisition = acquisition;
    let (file, loaded) =
        hybrid_loaded(&spec, &network, &x0, exp0.dt(), opts.substeps, kept_domain)?;
    let train_j = judge_outputs(&loaded, &recorded, opts.x0_window)?;
    let train = FreeRunReport::of(&train_j);
    let validation_j = match &recorded_val {
        Some(v) => Some(judge_outputs(&loaded, v, opts.x0_window)?),
        None => None,
    };
    let validation = validation_j.as_ref().map(FreeRunReport::of);
    // Whether trajectory training helped on the validation record: the networks before
    // and after it judged as the kept model is (the one judge, the kept model's domain),
    // so the kept one's numbers are the validation report's, and both are judged one way
    // (the guard judges each with the domain its stress check gave it, which may differ).
    if let (Some(r), Some(v)) = (refinement.as_mut(), &recorded_val) {
        let fits = |net: &Mlp| {
            hybrid_loaded(&spec, net, &x0, exp0.dt(), opts.substeps, kept_domain)
                .and_then(|(_, loaded)| judge_outputs(&loaded, v, opts.x0_window))
                .ok()
                .map(|j| {
                    j.channels
                        .into_iter()
                        .map(|(k, m)| (k, m.fit_percent))
                        .collect()
                })
        };
        r.validation_fit_before = fits(&before_refinement);
        r.validation_fit_after = fits(&refined);
        r.validation_domain = Some(kept_domain);
    }
    let d_network = network.predict(&x_train)?;
    let w_by_correction = lin
        .correction_names()
        .iter()
        .enumerate()
        .map(|(i, n)| (n.clone(), est.w[(i, i)]))
        .collect();
    let summary = FitSummary {
        hidden: hidden_units,
        chosen: sweep.rows[chosen].clone(),
        selection: opts.selection,
        training: opts.training,
        ensemble_rows,
        free_run_sse,
        training_pairs: x_train.ncols(),
        test_source,
        w_by_correction,
        mme_termination: est.report.termination,
        mme_estimates,
        w_search: result.w_search.clone(),
        model_update: update_report,
        train,
        validation,
        refinement,
        guard: guard_report,
        network_box: {
            let sc = network.input_scaler();
            network_variables(&spec, opts.network_inputs)
                .into_iter()
                .zip(sc.centre().iter().zip(sc.half_range()))
                .map(|(n, (c, h))| (n, c - h, c + h))
                .collect()
        },
        network_domain: kept_domain,
        network_inputs: opts.network_inputs,
        files: fit_files(&spec, val.is_some(), opts.network_inputs),
        validation_use: val.is_some().then_some(opts.validation_use),
    };
    Ok(FitOutcome {
        summary,
        model: file,
        spec,
        sweep: sweep.rows,
        chosen,
        train: train_j,
        validation: validation_j,
        train_record: recorded.experiments()[0].clone(),
        validation_record: recorded_val.as_ref().map(|v| v.experiments()[0].clone()),
        d_train,
        d_network,
        x_train,
    })
}

/// Training pairs: inputs `[x̂; u]` and targets `d̂`, one column each.
type Pairs = (DMatrix<f64>, DMatrix<f64>);

/// The pairs split into the first 80 % (fit) and the last 20 % (test).
fn split_last_fifth(x: &DMatrix<f64>, d: &DMatrix<f64>) -> (Pairs, Pairs) {
    let k = x.ncols();
    let cut = k - k / 5;
    (
        (
            x.columns(0, cut).into_owned(),
            d.columns(0, cut).into_owned(),
        ),
        (
            x.columns(cut, k - cut).into_owned(),
            d.columns(cut, k - cut).into_owned(),
        ),
    )
}

/// What one network training reads: the sweep's fit and test pairs, the record the
/// free-run selection simulates (first experiment; samples in `skip` not scored), and the
/// shooting records of trajectory training.
struct TrainingSet<'a> {
    fit: Pairs,
    test: Pairs,
    data: &'a Dataset,
    skip: Option<Range<usize>>,
    shooting: Vec<nn::ShootingRecord<'a>>,
}

/// What one network training gives: the sweep, the row chosen, the network before
/// trajectory training and the network after it (the same network without it).
struct Trained {
    sweep: nn::SweepResult,
    chosen: usize,
    free_run_sse: Option<f64>,
    ensemble_rows: Vec<usize>,
    before: Mlp,
    network: Mlp,
    refinement: Option<TrajectorySummary>,
}

fn sweep_config(opts: &FitOptions) -> SweepConfig {
    let config = SweepConfig {
        hidden_sizes: match opts.hidden {
            HiddenChoice::Auto => (1..=opts.max_hidden.max(1)).collect(),
            HiddenChoice::Fixed(h) => vec![h],
        },
        inits: opts.inits,
        seed: opts.seed,
        ..SweepConfig::default()
    };
    match opts.training {
        Training::Trainlm => config,
        Training::Accelerated => SweepConfig {
            lm: nn::LmConfig {
                damping: nn::Damping::TrainlmThenGainRatio,
                acceleration: nn::Acceleration::Geodesic,
                ..config.lm
            },
            ..config
        },
    }
}

/// The network sizing sweep on `set`'s pairs, the selection, the ensemble and the
/// trajectory training, as `opts` say.
fn train_networks(
    spec: &ModelSpec,
    set: &TrainingSet<'_>,
    val_pair: Option<(&MmeEstimate, &Dataset)>,
    x0: &[f64],
    opts: &FitOptions,
    progress: &dyn crate::progress::ProgressSink,
) -> Result<Trained> {
    let sweep_config = sweep_config(opts);
    const SWEEP: &str = "network sizing sweep";
    let on_run = |p: nn::SweepProgress| {
        progress.report(
            &crate::progress::Progress::new(SWEEP, p.done, Some(p.total)).with_note(format!(
                "{} hidden, init {}: test MSE {:.3e}",
                p.hidden, p.init, p.test_mse
            )),
        );
    };
    progress.report(&crate::progress::Progress::new(
        SWEEP,
        0,
        Some(sweep_config.hidden_sizes.len() * sweep_config.inits),
    ));
    let sweep = nn::sizing_sweep(
        &set.fit.0,
        &set.fit.1,
        &set.test.0,
        &set.test.1,
        &sweep_config,
        Some(&on_run),
    );
    progress.finish(SWEEP);
    let sweep = sweep?;
    let (chosen, free_run_sse) = match opts.selection {
        NetworkSelection::CorrectionMse => (sweep.chosen, None),
        NetworkSelection::FreeRun => {
            let (i, sse) = select_by_free_run(
                spec,
                &sweep.networks,
                set.data,
                x0,
                opts.substeps,
                opts.network_domain.initial(),
                set.skip.as_ref(),
            )?;
            (i, Some(sse))
        }
    };
    let (mut network, ensemble_rows) = match opts.ensemble {
        NetworkEnsemble::Single => (sweep.networks[chosen].clone(), Vec::new()),
        NetworkEnsemble::Band => {
            let rows = nn::band_members(&sweep.rows, &sweep_config.selection);
            let members: Vec<Mlp> = rows.iter().map(|&i| sweep.networks[i].clone()).collect();
            (nn::ensemble::average(&members)?, rows)
        }
    };
    let before = network.clone();
    let refinement = match opts.train_on_trajectories {
        TrajectoryChoice::None => None,
        TrajectoryChoice::Trajectory => Some(train_network_on_trajectories(
            spec,
            &mut network,
            &set.shooting,
            val_pair,
            x0,
            opts,
            progress,
        )?),
    };
    Ok(Trained {
        sweep,
        chosen,
        free_run_sse,
        ensemble_rows,
        before,
        network,
        refinement,
    })
}

/// The network's inputs by name: every state, then every input (none for a states-only
/// network).
fn network_variables(spec: &ModelSpec, inputs: NetworkInputs) -> Vec<String> {
    let seen: &[String] = match inputs {
        NetworkInputs::StatesAndInputs => spec.linear.input_names(),
        NetworkInputs::States => &[],
    };
    spec.linear
        .state_names()
        .iter()
        .chain(seen)
        .cloned()
        .collect()
}
