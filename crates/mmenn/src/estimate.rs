//! `mmenn estimate`: run MME on data files with a model file and write `estimate.csv`,
//! `summary.json`, figures and `report.md`.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use mme_core::{MmeConfig, MmeOutput, NoiseSpec, NonlinearModel, WeightSpec};
use serde::Serialize;
use sysid_core::Dataset;

use crate::atomic::{ensure_dir, write_atomic};
use crate::data_file::read_dataset;
use crate::error::{MmennError, Result};
use crate::model_file::{ModelSpec, NoiseVariance};

mod outputs;

use outputs::{EstimateColumns, estimate_report, figures_of, write_columns_csv};
pub use outputs::{
    estimate_figures, estimate_figures_with_target, write_estimate_csv, write_figures,
};

/// How `W` is chosen on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum WeightChoice {
    /// By the covariance constraint.
    #[default]
    Auto,
    /// `W = value·I` (per unit time).
    Value(f64),
}

impl std::str::FromStr for WeightChoice {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, Self::Err> {
        if s == "auto" {
            return Ok(Self::Auto);
        }
        match s.parse::<f64>() {
            Ok(v) if v.is_finite() && v > 0.0 => Ok(Self::Value(v)),
            _ => Err(format!("'{s}' is neither \"auto\" nor a positive number")),
        }
    }
}

/// Options of [`run_estimate`].
#[derive(Debug, Clone, PartialEq, Default)]
pub struct EstimateOptions {
    /// `W`.
    pub w: WeightChoice,
    /// Sub-steps per sample interval (`None`: chosen from the model).
    pub substeps: Option<usize>,
    /// The job's budget (default unlimited; the CLI's `--budget SECONDS`): MME stops with
    /// `CoreError::BudgetExhausted`, naming the stage and how far it got, once it is spent.
    pub budget: sysid_core::Budget,
    /// The nonlinear estimator's iteration settings (a model with named terms; ignored by
    /// the linear one). Default [`mme_core::IterationOptions::default`] (50 Gauss–Newton
    /// iterations per solve).
    pub iterations: mme_core::IterationOptions,
    /// Gaussian prior on the initial state of every record (default empty: free). `mmenn
    /// estimate` fills it from the model file's `[x0_prior]` table when it is empty here.
    pub x0_prior: Vec<mme_core::StatePrior>,
}

/// The MME configuration a model file and options imply.
pub fn mme_config(spec: &ModelSpec, opts: &EstimateOptions) -> MmeConfig {
    MmeConfig {
        w: match opts.w {
            WeightChoice::Auto => WeightSpec::default(),
            WeightChoice::Value(v) => WeightSpec::Scalar(v),
        },
        noise_variance: match &spec.noise_variance {
            NoiseVariance::Given(v) => NoiseSpec::Given(v.clone()),
            NoiseVariance::Auto => NoiseSpec::Auto,
        },
        substeps: opts.substeps,
        budget: opts.budget.clone(),
        iterations: opts.iterations,
        x0_prior: opts.x0_prior.clone(),
        ..MmeConfig::default()
    }
}

/// The spec's term model as mme-core's nonlinear model (states, outputs, corrections
/// named as in the spec).
fn nonlinear_model(spec: &ModelSpec) -> Result<NonlinearModel<sysid_core::TermModel>> {
    let dynamics = spec.term_model().map_err(|problem| MmennError::Model {
        path: "<model>".into(),
        line: None,
        column: None,
        problem,
    })?;
    nonlinear_of(dynamics)
}

/// A model file with a `[mechanics]` (mass-matrix) part as mme-core's nonlinear model.
fn nonlinear_physical(spec: &ModelSpec) -> Result<NonlinearModel<sysid_core::PhysicalModel>> {
    let dynamics = spec.physical_model().map_err(|problem| MmennError::Model {
        path: "<model>".into(),
        line: None,
        column: None,
        problem,
    })?;
    let lin = spec.linear.clone();
    let names = sysid_core::ModelNames {
        states: lin.state_names().to_vec(),
        inputs: lin.input_names().to_vec(),
        outputs: lin.output_names().to_vec(),
        corrections: lin.correction_names().to_vec(),
    };
    Ok(NonlinearModel::new(
        dynamics,
        lin.c().clone(),
        lin.e().clone(),
        names,
    )?)
}

/// A term model as mme-core's nonlinear model (names from its linear part).
fn nonlinear_of(dynamics: sysid_core::TermModel) -> Result<NonlinearModel<sysid_core::TermModel>> {
    let lin = dynamics.linear();
    let names = sysid_core::ModelNames {
        states: lin.state_names().to_vec(),
        inputs: lin.input_names().to_vec(),
        outputs: lin.output_names().to_vec(),
        corrections: lin.correction_names().to_vec(),
    };
    let (c, e) = (lin.c().clone(), lin.e().clone());
    Ok(NonlinearModel::new(dynamics, c, e, names)?)
}

/// Run MME with the model file's assumed model: the exact linear sweep, or the
/// iterated-linearisation estimator when the model has named terms.
pub fn estimate_spec(spec: &ModelSpec, data: &Dataset, config: &MmeConfig) -> Result<MmeOutput> {
    estimate_spec_observed(spec, data, config, &mme_core::NoObserver)
}

/// [`estimate_spec`], telling `observer` each step as it runs (`mme_core::observe`;
/// [`crate::progress::MmeProgress`] turns them into progress reports). The result does
/// not depend on the observer.
pub fn estimate_spec_observed(
    spec: &ModelSpec,
    data: &Dataset,
    config: &MmeConfig,
    observer: &dyn mme_core::MmeObserver,
) -> Result<MmeOutput> {
    if spec.mechanics.is_some() {
        let model = nonlinear_physical(spec)?;
        return mme_core::estimate_nonlinear_with_observer(&model, data, config, observer)
            .map_err(|e| name_terms(spec, e));
    }
    if spec.terms.is_empty() {
        return mme_core::estimate_with_observer(&spec.linear, data, config, observer)
            .map_err(|e| name_terms(spec, e));
    }
    let model = nonlinear_model(spec)?;
    mme_core::estimate_nonlinear_with_observer(&model, data, config, observer)
        .map_err(|e| name_terms(spec, e))
}

/// [`estimate_spec`] for a model already in memory (a linear model with named terms).
pub fn estimate_term_model(
    model: &sysid_core::TermModel,
    data: &Dataset,
    config: &MmeConfig,
) -> Result<MmeOutput> {
    estimate_term_model_observed(model, data, config, &mme_core::NoObserver)
}

/// [`estimate_term_model`], telling `observer` each step as it runs (see
/// [`estimate_spec_observed`]).
pub fn estimate_term_model_observed(
    model: &sysid_core::TermModel,
    data: &Dataset,
    config: &MmeConfig,
    observer: &dyn mme_core::MmeObserver,
) -> Result<MmeOutput> {
    if model.terms().is_empty() {
        return Ok(mme_core::estimate_with_observer(
            model.linear(),
            data,
            config,
            observer,
        )?);
    }
    let names = model.linear().state_names().to_vec();
    let described: Vec<(String, Option<String>, String)> = model
        .terms()
        .iter()
        .map(|t| {
            (
                names[t.state].clone(),
                t.into.map(|r| names[r].clone()),
                format!("{} = {}·({})", t.effect, t.coefficient, t.expr),
            )
        })
        .collect();
    let nonlinear = nonlinear_of(model.clone())?;
    mme_core::estimate_nonlinear_with_observer(&nonlinear, data, config, observer)
        .map_err(|e| with_terms(&described, e))
}

/// An MME error with names attached: an unobservable initial state with its state's name
/// and what helps; a non-finite model error with the named terms of the equation it names.
pub(crate) fn name_terms(spec: &ModelSpec, e: mme_core::MmeError) -> MmennError {
    // The pivot of an unobservable initial state is a state index (no pivoting).
    if let mme_core::MmeError::NotObservable { pivot, .. } = &e
        && let Some(state) = spec.linear.state_names().get(*pivot)
    {
        return MmennError::MmeUnobservable {
            state: state.clone(),
            source: e,
        };
    }
    let described: Vec<(String, Option<String>, String)> = spec
        .terms
        .iter()
        .map(|t| {
            (
                t.state.clone(),
                t.into.clone(),
                format!("{} = {}·({})", t.effect, t.coefficient, t.term),
            )
        })
        .collect();
    with_terms(&described, e)
}

/// `e` with the descriptions of the terms (`(state, into, description)`) that enter the
/// equation a non-finite-model error names.
fn with_terms(described: &[(String, Option<String>, String)], e: mme_core::MmeError) -> MmennError {
    let terms: Vec<&str> = match &e {
        mme_core::MmeError::NonFiniteModel { state, .. } => described
            .iter()
            .filter(|(s, into, _)| s == state || into.as_deref() == Some(state.as_str()))
            .map(|(_, _, d)| d.as_str())
            .collect(),
        _ => Vec::new(),
    };
    if terms.is_empty() {
        MmennError::Mme(e)
    } else {
        MmennError::MmeTerms {
            source: e,
            terms: terms.join(", "),
        }
    }
}

/// The JSON summary of an estimate (stable field names).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct EstimateSummary {
    /// `W` used, rows of the `q × q` matrix (per unit time).
    pub w: Vec<Vec<f64>>,
    /// Diagonal of `W` by corrected state.
    pub w_by_correction: BTreeMap<String, f64>,
    /// Noise variance used, per measured channel.
    pub noise_variance: BTreeMap<String, f64>,
    /// How the noise variance was obtained (`given` or `marginal_likelihood`).
    pub noise_method: mme_core::NoiseMethod,
    /// The noise estimator's full report (difference-based cross-check, likelihood).
    pub noise: mme_core::NoiseReport,
    /// The model-free references an estimated noise variance was judged against, per
    /// measured channel: `[second differences, spectral floor]` (the floor `null` when the
    /// records are too short for it); empty when the noise variance was given.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub noise_references: BTreeMap<String, (f64, Option<f64>)>,
    /// Sample variance of measurement minus estimate, per measured channel.
    pub residual_variance: BTreeMap<String, f64>,
    /// Residual variance divided by noise variance, per measured channel (≈ 1 when the
    /// covariance constraint holds).
    pub residual_to_noise: BTreeMap<String, f64>,
    /// How the automatic `W` search ended, when it ran.
    pub w_search: Option<mme_core::WSearch>,
    /// Sub-steps per sample interval.
    pub substeps: usize,
    /// Value of the MME cost at the optimum.
    pub cost: f64,
    /// The solver's report (termination, iterations, phase times).
    pub report: sysid_core::SolveReport,
    /// Number of samples over all experiments.
    pub samples: usize,
    /// Missing (empty or NaN) samples of each measured channel, over all experiments;
    /// MME skips them.
    pub missing: BTreeMap<String, usize>,
    /// Wall time per phase of the whole command, seconds.
    pub phase_seconds: BTreeMap<String, f64>,
    /// Samples per second of the final sweep (samples / time of the sweep phase).
    pub sweep_samples_per_second: Option<f64>,
    /// Samples reported as outliers (largest first): against the robust estimate when it
    /// ran, else by the neighbour screen (`mme_core::screen_outliers`).
    pub outliers: Vec<mme_core::Outlier>,
    /// Passes of the robust estimate (`None`: not robust).
    pub robust_passes: Option<usize>,
    /// Files written.
    pub files: Vec<String>,
    /// What the user should know about these numbers (see [`noise_warnings`]).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub warnings: Vec<String>,
    /// How the estimate ended, judged as `fit` judges its training estimate (a `W` search
    /// not bracketed below 1 within the sampling band counts as converged:
    /// docs/decisions/mme-ratio-tolerance.md); `None` for the robust estimate, whose
    /// ratio target is not 1.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub convergence: Option<crate::fit::MmeConvergence>,
    /// The Gaussian prior on the initial state MME used (the model file's `[x0_prior]`),
    /// by state; absent when every initial state was free.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub x0_prior: BTreeMap<String, PriorEntry>,
}

/// One state's initial-state prior as `summary.json` records it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct PriorEntry {
    /// Prior mean at the first sample.
    pub mean: f64,
    /// Prior standard deviation.
    pub std: f64,
}

/// How much larger than the difference-based scatter an estimated noise variance may be
/// before [`noise_warnings`] says the model's misfit was probably taken as noise.
pub const NOISE_MISFIT_RATIO: f64 = 10.0;

/// Warnings about an estimated (`auto`) noise variance: a channel whose likelihood
/// estimate exceeds [`NOISE_MISFIT_RATIO`] × the difference-based one (normalised second
/// differences, which see the sample-to-sample scatter and over-, not under-, estimate
/// the noise when the signal itself curves between samples). There the likelihood has
/// explained a deterministic misfit of the model as measurement noise, `W` is small and
/// `d̂` says little; giving the sensor's noise variance is the remedy. When the likelihood
/// was degenerate and a model-free reference was used, one warning says what it misses:
/// second differences are too large on signals that curve between samples, the spectral
/// floor too small behind a sensor's anti-aliasing filter. Nothing for a given noise
/// variance.
pub fn noise_warnings(names: &[String], noise: &mme_core::NoiseReport) -> Vec<String> {
    if noise.difference_based.len() != noise.variance.len() {
        return Vec::new();
    }
    if noise.method == mme_core::NoiseMethod::DifferenceBased {
        // The likelihood ran to R → 0 and the fallback was used.
        return vec![format!(
            "{}: the noise variance comes from second differences of the measurements \
             (the likelihood was degenerate). That estimate is too large when the signal \
             itself curves between samples (oscillations with few samples per period), \
             and W and d̂ inherit the error. Give the sensor's noise variance \
             (noise_variance = [...]) when you know it.",
            names.join(", ")
        )];
    }
    if noise.method == mme_core::NoiseMethod::SpectralFloor {
        return vec![format!(
            "{}: the noise variance is the spectral floor of the measurements (the lowest \
             band of their periodogram; the likelihood was degenerate). It bounds the white \
             part of the noise from above and is below it when the sensor filters its \
             noise near the Nyquist frequency; W and d̂ inherit the error. Give the \
             sensor's noise variance (noise_variance = [...]) when you know it.",
            names.join(", ")
        )];
    }
    names
        .iter()
        .zip(noise.variance.iter().zip(&noise.difference_based))
        .filter(|(_, (ml, diff))| {
            diff.is_finite() && **diff > 0.0 && ml.is_finite() && **ml > NOISE_MISFIT_RATIO * **diff
        })
        .map(|(name, (ml, diff))| {
            format!(
                "{name}: the estimated noise variance {ml:.3e} is {:.0}× the sample-to-sample \
                 scatter ({diff:.3e}, from second differences): the model's misfit was \
                 probably taken as measurement noise, which leaves W small and d̂ near \
                 zero. Give the sensor's noise variance (noise_variance = [...]) instead \
                 of \"auto\".",
                ml / diff
            )
        })
        .collect()
}

fn by_name(names: &[String], v: &[f64]) -> BTreeMap<String, f64> {
    names.iter().cloned().zip(v.iter().copied()).collect()
}

fn row(m: &nalgebra::DMatrix<f64>, i: usize) -> Vec<f64> {
    m.row(i).iter().copied().collect()
}

/// Robust MME (Huber, see [`mme_core::robust`]) with the model file's assumed model.
pub fn estimate_spec_robust(
    spec: &ModelSpec,
    data: &Dataset,
    config: &MmeConfig,
    robust: &mme_core::RobustConfig,
) -> Result<mme_core::RobustOutput> {
    estimate_spec_robust_observed(spec, data, config, robust, &mme_core::NoObserver)
}

/// [`estimate_spec_robust`], telling `observer` each step as it runs (see
/// [`estimate_spec_observed`]).
pub fn estimate_spec_robust_observed(
    spec: &ModelSpec,
    data: &Dataset,
    config: &MmeConfig,
    robust: &mme_core::RobustConfig,
    observer: &dyn mme_core::MmeObserver,
) -> Result<mme_core::RobustOutput> {
    if spec.mechanics.is_some() {
        let model = nonlinear_physical(spec)?;
        return mme_core::estimate_nonlinear_robust_with_observer(
            &model, data, config, robust, observer,
        )
        .map_err(|e| name_terms(spec, e));
    }
    if spec.terms.is_empty() {
        return Ok(mme_core::estimate_robust_with_observer(
            &spec.linear,
            data,
            config,
            robust,
            observer,
        )?);
    }
    let model = nonlinear_model(spec)?;
    mme_core::estimate_nonlinear_robust_with_observer(&model, data, config, robust, observer)
        .map_err(|e| name_terms(spec, e))
}

/// Samples standing out from the cubic through their neighbours by more than this many
/// noise standard deviations (of that difference; the record's robust spread of it when
/// larger) are reported by a plain (not robust) estimate (`mme_core::screen_outliers`).
pub const OUTLIER_SCREEN_SIGMA: f64 = 8.0;

/// Read data and model files, run MME, write every output into `out`.
pub fn run_estimate(
    data_paths: &[PathBuf],
    model_path: &Path,
    opts: &EstimateOptions,
    out: &Path,
) -> Result<EstimateSummary> {
    run_estimate_with(data_paths, model_path, opts, None, out)
}

/// [`run_estimate`], robust when `robust` is given: outliers are then reported against
/// the Huber estimate; otherwise by a screen against the neighbours
/// ([`OUTLIER_SCREEN_SIGMA`]). Reads the files, [`compute_estimate`], [`write_estimate`].
/// The model may be any model file or a hybrid `model.json` (its model-file part).
pub fn run_estimate_with(
    data_paths: &[PathBuf],
    model_path: &Path,
    opts: &EstimateOptions,
    robust: Option<&mme_core::RobustConfig>,
    out: &Path,
) -> Result<EstimateSummary> {
    run_estimate_with_progress(
        data_paths,
        model_path,
        opts,
        robust,
        out,
        &crate::progress::NoProgress,
    )
}

/// [`run_estimate_with`], reporting MME's steps to `progress` as notes of the task
/// [`crate::progress::MME_TASK`] ([`crate::progress::MmeProgress`]); the caller reports
/// the task's start and end (a [`crate::progress::stage`] around this call). The
/// results do not depend on the sink.
pub fn run_estimate_with_progress(
    data_paths: &[PathBuf],
    model_path: &Path,
    opts: &EstimateOptions,
    robust: Option<&mme_core::RobustConfig>,
    out: &Path,
    progress: &dyn crate::progress::ProgressSink,
) -> Result<EstimateSummary> {
    let clock = Instant::now();
    let loaded = crate::model::LoadedModel::read(model_path)?;
    let spec = loaded.spec;
    spec.refuse_acquisition("estimate", model_path)?;
    spec.refuse_uncorrected("estimate", model_path)?;
    // The model file's `[x0_prior]`, unless the options already carry a prior.
    let with_prior;
    let opts = if opts.x0_prior.is_empty() && !loaded.x0_prior.is_empty() {
        with_prior = EstimateOptions {
            x0_prior: loaded.x0_prior,
            ..opts.clone()
        };
        &with_prior
    } else {
        opts
    };
    let data = read_dataset(
        data_paths,
        spec.linear.input_names(),
        spec.linear.output_names(),
        &spec.units,
    )?;
    let read = clock.elapsed().as_secs_f64();
    let observer = crate::progress::MmeProgress::new(progress, crate::progress::MME_TASK);
    let mut outcome = compute_estimate_owned(data, &spec, opts, robust, &observer)?;
    outcome
        .summary
        .phase_seconds
        .insert("read".to_string(), read);
    progress.report(
        &crate::progress::Progress::new(crate::progress::MME_TASK, 0, None)
            .with_stage("writing the results"),
    );
    write_estimate(&outcome, out)
}

/// Everything `mmenn estimate` computes, as values ([`write_estimate`] writes it).
#[derive(Debug, Clone)]
pub struct EstimateOutcome {
    /// What `summary.json` holds (its file list without the figures, which
    /// [`write_estimate`] adds).
    pub summary: EstimateSummary,
    /// MME's result: `x̂`, `d̂`, `W`, noise, the `W` curve.
    pub output: MmeOutput,
    /// The data estimated on (inputs held as the model says).
    pub data: Dataset,
    /// The model.
    pub spec: ModelSpec,
    /// Residual-to-noise ratio the `W` search aims at (1, or the Huber variance factor).
    pub target_ratio: f64,
}

/// `mmenn estimate` without files: MME on `data` (robust when `robust` is given), the
/// outlier report and the summary.
pub fn compute_estimate(
    data: &Dataset,
    spec: &ModelSpec,
    opts: &EstimateOptions,
    robust: Option<&mme_core::RobustConfig>,
) -> Result<EstimateOutcome> {
    compute_estimate_owned(data.clone(), spec, opts, robust, &mme_core::NoObserver)
}

/// [`compute_estimate`], reporting MME's steps to `progress` as notes of the task
/// [`crate::progress::MME_TASK`] (see [`run_estimate_with_progress`]). The results do not
/// depend on the sink.
pub fn compute_estimate_with_progress(
    data: &Dataset,
    spec: &ModelSpec,
    opts: &EstimateOptions,
    robust: Option<&mme_core::RobustConfig>,
    progress: &dyn crate::progress::ProgressSink,
) -> Result<EstimateOutcome> {
    let observer = crate::progress::MmeProgress::new(progress, crate::progress::MME_TASK);
    compute_estimate_owned(data.clone(), spec, opts, robust, &observer)
}

/// [`compute_estimate`] keeping `data` (no copy of the record).
fn compute_estimate_owned(
    data: Dataset,
    spec: &ModelSpec,
    opts: &EstimateOptions,
    robust: Option<&mme_core::RobustConfig>,
    observer: &dyn mme_core::MmeObserver,
) -> Result<EstimateOutcome> {
    spec.refuse_acquisition("estimate", Path::new("<model>"))?;
    spec.refuse_uncorrected("estimate", Path::new("<model>"))?;
    let mut phases = BTreeMap::new();
    // MME follows the model file's inputs-between-samples setting.
    let data = data.with_intersample(spec.intersample);
    let clock = Instant::now();
    let config = mme_config(spec, opts);
    let (result, outliers, robust_passes) = match robust {
        Some(r) => {
            let ro = estimate_spec_robust_observed(spec, &data, &config, r, observer)?;
            (ro.output, ro.outliers, Some(ro.passes))
        }
        None => {
            let result = estimate_spec_observed(spec, &data, &config, observer)?;
            let outliers = mme_core::screen_outliers(
                &data,
                spec.linear.output_names(),
                &result.estimate.noise_variance,
                OUTLIER_SCREEN_SIGMA,
            )?;
            (result, outliers, None)
        }
    };
    phases.insert("estimate".to_string(), clock.elapsed().as_secs_f64());
    let est = &result.estimate;
    let mut files: Vec<String> = (0..est.experiments.len()).map(estimate_csv_name).collect();
    let target_ratio = robust.map_or(1.0, |r| mme_core::robust::huber_variance(r.huber_c));
    let samples = data.total_samples();
    let sweep_time = est
        .report
        .phase_seconds
        .iter()
        .find(|(n, _)| n == "sweep" || n == "gauss_newton")
        .map(|(_, s)| *s);
    let w_diag: Vec<f64> = (0..est.w.nrows()).map(|i| est.w[(i, i)]).collect();
    let ratio: Vec<f64> = est
        .residual_variance
        .iter()
        .zip(&est.noise_variance)
        .map(|(r, n)| r / n)
        .collect();
    files.push("summary.json".into());
    files.push("report.md".into());
    files.push("report.html".into());
    let summary = EstimateSummary {
        w: (0..est.w.nrows()).map(|i| row(&est.w, i)).collect(),
        w_by_correction: by_name(&est.correction_names, &w_diag),
        noise_variance: by_name(&est.output_names, &est.noise_variance),
        noise_method: result.noise.method,
        noise: result.noise.clone(),
        noise_references: if result.noise.difference_based.len() == est.output_names.len() {
            est.output_names
                .iter()
                .zip(&result.noise.difference_based)
                .enumerate()
                .map(|(i, (name, d))| {
                    let floor = result.noise.spectral_floor.get(i).copied().flatten();
                    (name.clone(), (*d, floor))
                })
                .collect()
        } else {
            BTreeMap::new()
        },
        residual_variance: by_name(&est.output_names, &est.residual_variance),
        residual_to_noise: by_name(&est.output_names, &ratio),
        w_search: result.w_search.clone(),
        substeps: est.experiments.first().map_or(1, |e| e.substeps),
        cost: est.cost,
        report: est.report.clone(),
        samples,
        missing: est
            .output_names
            .iter()
            .enumerate()
            .map(|(i, name)| {
                let n = data
                    .experiments()
                    .iter()
                    .map(|e| e.outputs().row(i).iter().filter(|v| v.is_nan()).count())
                    .sum();
                (name.clone(), n)
            })
            .collect(),
        phase_seconds: phases,
        sweep_samples_per_second: sweep_time.filter(|s| *s > 0.0).map(|s| samples as f64 / s),
        outliers,
        robust_passes,
        files,
        warnings: noise_warnings(&est.output_names, &result.noise),
        convergence: robust.is_none().then(|| {
            crate::fit::MmeConvergence::of(crate::fit::MmeStage::Training, &result, &data)
        }),
        x0_prior: opts
            .x0_prior
            .iter()
            .map(|p| {
                (
                    p.state.clone(),
                    PriorEntry {
                        mean: p.mean,
                        std: p.std,
                    },
                )
            })
            .collect(),
    };
    Ok(EstimateOutcome {
        summary,
        output: result,
        data,
        spec: spec.clone(),
        target_ratio,
    })
}

fn estimate_csv_name(i: usize) -> String {
    if i == 0 {
        "estimate.csv".to_string()
    } else {
        format!("estimate_{i}.csv")
    }
}

/// Write what [`compute_estimate`] computed into `out`: `estimate*.csv`, the figures,
/// `report.md` and `summary.json` (atomically, each file). Returns the summary as written
/// (its file list with the figures, and the time the writing took).
pub fn write_estimate(o: &EstimateOutcome, out: &Path) -> Result<EstimateSummary> {
    let clock = Instant::now();
    ensure_dir(out)?;
    let est = &o.output.estimate;
    let mut summary = o.summary.clone();
    // The CSV files and the figures are independent: written side by side, from one
    // set of columns for the first experiment.
    let first = EstimateColumns::of(&est.experiments[0]);
    let (csvs, drawn) = rayon::join(
        || -> Result<()> {
            write_columns_csv(&out.join(estimate_csv_name(0)), est, &first)?;
            for i in 1..est.experiments.len() {
                write_estimate_csv(&out.join(estimate_csv_name(i)), est, i)?;
            }
            Ok(())
        },
        || figures_of(&o.output, &o.data, &o.spec, out, o.target_ratio, &first),
    );
    csvs?;
    let mut figures = Vec::new();
    for p in drawn? {
        figures.push(
            p.file_name()
                .map(|f| f.to_string_lossy().into_owned())
                .unwrap_or_default(),
        );
    }
    let at = est.experiments.len();
    summary.files.splice(at..at, figures);
    crate::html::write_report(out, &estimate_report(&summary, &o.spec))?;
    summary
        .phase_seconds
        .insert("write".to_string(), clock.elapsed().as_secs_f64());
    write_atomic(
        &out.join("summary.json"),
        serde_json::to_string_pretty(&summary)?.as_bytes(),
    )?;
    Ok(summary)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn report(variance: Vec<f64>, difference_based: Vec<f64>) -> mme_core::NoiseReport {
        mme_core::NoiseReport {
            method: mme_core::NoiseMethod::MarginalLikelihood,
            variance,
            difference_based,
            spectral_floor: Vec::new(),
            likelihood_alpha: Some(1.0),
            neg2_log_likelihood: Some(0.0),
            evaluations: 1,
        }
    }

    /// Only the channel whose likelihood estimate exceeds 10× the scatter is named; a
    /// given noise variance (no difference-based estimate) warns about nothing.
    #[test]
    fn noise_warnings_name_the_channel_that_took_the_misfit() {
        let names = vec!["y".to_string(), "z".to_string()];
        let w = noise_warnings(&names, &report(vec![1.2e-4, 2e-6], vec![1e-6, 1e-6]));
        assert_eq!(w.len(), 1, "{w:?}");
        assert!(w[0].starts_with("y:") && w[0].contains("120×"), "{}", w[0]);
        assert!(noise_warnings(&names, &report(vec![9e-6, 1e-6], vec![1e-6, 1e-6])).is_empty());
        assert!(noise_warnings(&names, &report(vec![1.0, 1.0], vec![])).is_empty());
        let mut fallback = report(vec![1e-6, 1e-6], vec![1e-6, 1e-6]);
        fallback.method = mme_core::NoiseMethod::DifferenceBased;
        let w = noise_warnings(&names, &fallback);
        assert!(w.len() == 1 && w[0].starts_with("y, z:"), "{w:?}");
    }

    /// A state no output can see (`z` is driven by the input and feeds nothing) leaves the
    /// initial state undetermined: the error names that state, with what helps; the
    /// states before it are determined (the pivot is `z`'s index).
    #[test]
    fn unobservable_initial_state_is_named() {
        let spec = crate::model_file::parse_model(
            std::path::Path::new("m.toml"),
            "states = [\"x\", \"z\"]\ninputs = [\"u\"]\n\
             A = [[-1.0, 0.0], [0.0, -2.0]]\nB = [[1.0], [1.0]]\n\
             measured = [\"x\"]\ncorrected = [\"x\"]\nnoise_variance = [1e-4]\n",
        )
        .unwrap();
        let n = 50;
        let u = nalgebra::DMatrix::from_fn(1, n, |_, k| (k as f64 * 0.3).sin());
        let y = nalgebra::DMatrix::from_fn(1, n, |_, k| (k as f64 * 0.2).cos());
        let data = sysid_core::Dataset::new(
            vec![sysid_core::Channel::new("u")],
            vec![sysid_core::Channel::new("x")],
            vec![sysid_core::Experiment::new(0.0, 0.1, u, y).unwrap()],
        )
        .unwrap();
        let config = mme_config(
            &spec,
            &EstimateOptions {
                w: WeightChoice::Value(10.0),
                ..Default::default()
            },
        );
        let err = estimate_spec(&spec, &data, &config).unwrap_err();
        assert!(
            matches!(&err, MmennError::MmeUnobservable { state, .. } if state == "z"),
            "{err}"
        );
        let text = err.to_string();
        assert!(
            text.contains("'z'") && text.contains("a few samples later"),
            "{text}"
        );
    }
}
