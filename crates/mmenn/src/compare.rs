//! `mmenn compare`: the assumed model, a linear output-error model, a NARX network and the
//! MME/NN hybrid model judged the same way on the same data (thesis ch. 5): free-run
//! simulation, fit %, R², RMSE and error variance per channel, on estimation and
//! validation data; compare plots with fit % in the legend, residual correlation plots
//! with 99 % bands, and `compare.json`.
//!
//! `--model` is any model mmenn writes ([`crate::model::LoadedModel`]). When it is more
//! than the linear assumed model (it has `[[terms]]`, e.g. a discovered model, or it is a
//! hybrid `model.json`), it gets its own row, [`GIVEN_MODEL_ROW`], judged by the one
//! free-run judge ([`crate::model::judge_free_run`]: the numbers `mmenn predict` gives on
//! the same record); the baselines start from its linear part. A baseline that cannot be
//! fitted has no numbers: the table, the report and the terminal say so, with the reason.

use std::path::{Path, PathBuf};

use serde::Serialize;
use sysid_baselines::{
    Evaluation, EvaluationTable, NarxConfig, NarxModel, NarxOrders, OeConfig, OeModel,
    ResidualAnalysis, ResidualConfig, SuggestionConfig, evaluate, fit_narx, fit_oe, predictions,
    residual_analysis, suggest_lags,
};
use sysid_core::{Dataset, Horizon, Model};

use crate::atomic::{ensure_dir, write_atomic};
use crate::error::{MmennError, Result};
use crate::fit::{FitOptions, HybridFile, HybridModel};
use crate::model::{InitialRule, LoadedModel, ModelKind, Observation, judge_free_run};
use crate::model_file::{ModelSpec, write_model};
use crate::plot::{Figure, Panels, Series};
use crate::progress::{NoProgress, ProgressSink, stage};

/// Progress task of the free-run evaluation, residual analysis and figures.
const EVALUATION: &str = "free-run evaluation and figures";

/// Row label of the model given with `--model` when it is more than its linear part.
pub const GIVEN_MODEL_ROW: &str = "given model";

/// A model that could not be fitted: it has no row of numbers.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Failure {
    /// Row label.
    pub model: String,
    /// Why.
    pub reason: String,
}

/// A model's free-run simulation over a dataset, one prediction per experiment.
type SimFn<'a> = dyn Fn(&Dataset) -> Result<Vec<sysid_core::Prediction>> + 'a;

/// Options of [`run_compare`].
#[derive(Debug, Clone, PartialEq)]
pub struct CompareOptions {
    /// MME/NN settings.
    pub fit: FitOptions,
    /// NARX delays (same for outputs and inputs); `None` = suggested from PACF/XCF,
    /// capped at `max_narx_lag`.
    pub narx_lags: Option<usize>,
    /// Cap of the suggested NARX delays.
    pub max_narx_lag: usize,
    /// Free parameters of the output-error model (`"A[i,j]"`, `"B[i,j]"`); `None` = every
    /// entry of the corrected rows of A and B (the equations MME corrects).
    pub oe_free: Option<Vec<String>>,
}

impl Default for CompareOptions {
    fn default() -> Self {
        Self {
            fit: FitOptions::default(),
            narx_lags: None,
            max_narx_lag: 10,
            oe_free: None,
        }
    }
}

/// What `mmenn compare` reports.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CompareSummary {
    /// Free-run table on the estimation data.
    pub estimation: EvaluationTable,
    /// Free-run table on the validation data, when given.
    pub validation: Option<EvaluationTable>,
    /// NARX delays used (na = nb) and how they were chosen.
    pub narx_orders: NarxOrders,
    /// Output-error parameters with ±1σ.
    pub oe_parameters: Vec<sysid_baselines::ParameterEstimate>,
    /// Why the output-error fit failed, when it did (it then has no row).
    pub oe_error: Option<String>,
    /// Every model that could not be fitted, with the reason (no row in the tables).
    pub failures: Vec<Failure>,
    /// What `--model` was.
    pub given_model: ModelKind,
    /// How each model gets its initial condition.
    pub initialisation: Vec<(String, String)>,
    /// Residual analysis (free-run) of each model on the validation data (or the
    /// estimation data without validation).
    pub residuals: Vec<(String, ResidualAnalysis)>,
    /// Files written.
    pub files: Vec<String>,
}

fn default_free(spec: &ModelSpec) -> Vec<String> {
    let lin = &spec.linear;
    let rows = lin.corrected_states().unwrap_or_default();
    let mut free = Vec::new();
    for &i in &rows {
        for j in 0..lin.n_states() {
            free.push(format!("A[{i},{j}]"));
        }
        for j in 0..lin.n_inputs() {
            free.push(format!("B[{i},{j}]"));
        }
    }
    free
}

/// The hybrid model with its initial state from the one free-run judge on `data`'s first
/// experiment (the rule and numbers of `mmenn predict`: fitted to the first `window`
/// samples). The records carry the model file's `intersample`, which this fit and the
/// hybrid model's free runs (`Model::simulate`) follow, and so do the linear baselines
/// (the assumed model and the output-error fit are `OeModel`s, simulated and fitted with
/// the exact discretisation of each record's hold); NARX reads the samples only.
fn hybrid_for(file: &HybridFile, data: &Dataset, window: usize) -> Result<HybridModel> {
    let loaded = LoadedModel::from_hybrid(Path::new("mme_nn/model.json"), file.clone())?;
    let judged = judge_free_run(
        &loaded,
        &data.experiments()[0],
        &Observation::outputs(&loaded),
        &InitialRule::Fit {
            window: Some(window),
        },
    )?;
    let mut model = file.model()?;
    model.x0 = judged.x0;
    Ok(model)
}

/// The models of one comparison (a baseline that could not be fitted is `None`).
struct Models<'a> {
    assumed: &'a OeModel,
    oe: Option<&'a OeModel>,
    narx: Option<&'a NarxModel>,
    given: Option<&'a LoadedModel>,
    window: usize,
}

/// The given model's free run on the first experiment of `data` by the one free-run
/// judge (initial state fitted to the first `window` samples), with what it observed.
fn run_given(
    given: &LoadedModel,
    data: &Dataset,
    window: usize,
) -> Result<(crate::model::Judgement, Observation)> {
    let obs = Observation::outputs(given);
    let j = judge_free_run(
        given,
        &data.experiments()[0],
        &obs,
        &InitialRule::Fit {
            window: Some(window),
        },
    )?;
    Ok((j, obs))
}

/// The given model judged on the first experiment of `data` by the one free-run judge.
fn judge_given(given: &LoadedModel, data: &Dataset, window: usize) -> Result<Evaluation> {
    let (j, obs) = run_given(given, data, window)?;
    Ok(j.evaluation(&obs.names))
}

/// The given model's free run on the first experiment, as a prediction.
fn given_prediction(
    given: &LoadedModel,
    data: &Dataset,
    window: usize,
) -> Result<Vec<sysid_core::Prediction>> {
    let (j, _) = run_given(given, data, window)?;
    Ok(vec![sysid_core::Prediction {
        horizon: Horizon::FreeRun,
        outputs: j.outputs,
        initial_samples: 0,
    }])
}

fn table(
    title: &str,
    data: &Dataset,
    models: &Models<'_>,
    hybrid: &HybridModel,
) -> Result<EvaluationTable> {
    let mut t = EvaluationTable::new(title, Horizon::FreeRun);
    t.push(
        "assumed model",
        evaluate(models.assumed, data, Horizon::FreeRun)?,
    )?;
    if let Some(g) = models.given {
        t.push(GIVEN_MODEL_ROW, judge_given(g, data, models.window)?)?;
    }
    if let Some(oe) = models.oe {
        t.push("linear OE", evaluate(oe, data, Horizon::FreeRun)?)?;
    }
    if let Some(narx) = models.narx {
        t.push("NARX", evaluate(narx, data, Horizon::FreeRun)?)?;
    }
    t.push("MME/NN", evaluate(hybrid, data, Horizon::FreeRun)?)?;
    Ok(t)
}

fn compare_figures(
    which: &str,
    data: &Dataset,
    models: &[(&str, &SimFn<'_>)],
    tab: &EvaluationTable,
    units: &std::collections::BTreeMap<String, String>,
    out: &Path,
) -> Result<Vec<String>> {
    let exp = &data.experiments()[0];
    let t = exp.times();
    let preds: Vec<(&str, sysid_core::Prediction)> = models
        .iter()
        .map(|(n, f)| f(data).map(|mut p| (*n, p.swap_remove(0))))
        .collect::<Result<_>>()?;
    let mut files = Vec::new();
    for (i, name) in data.output_names().iter().enumerate() {
        let measured: Vec<f64> = exp.outputs().row(i).iter().copied().collect();
        let mut series = vec![Series::points(
            format!("{name} measured"),
            t.clone(),
            measured.clone(),
        )];
        // Measured − simulated per model (NaN where the record has no sample or the
        // model no prediction yet, e.g. NARX's delay line).
        let residuals: Vec<Series> = preds
            .iter()
            .enumerate()
            .map(|(k, (label, p))| {
                Series::line(
                    *label,
                    t.clone(),
                    measured
                        .iter()
                        .zip(p.outputs.row(i).iter())
                        .map(|(m, s)| m - s)
                        .collect(),
                )
                // The colour of the model's line above (the measurement is entry 0).
                .coloured(k + 1)
            })
            .collect();
        for (label, p) in &preds {
            let fit = tab
                .rows()
                .iter()
                .find(|r| r.label == *label)
                .and_then(|r| r.evaluation.channel(name))
                .map_or(f64::NAN, |m| m.fit_percent);
            series.push(Series::line(
                format!("{label} (fit {fit:.1} %)"),
                t.clone(),
                p.outputs.row(i).iter().copied().collect(),
            ));
        }
        let y_label = match units.get(name) {
            Some(u) => format!("{name} ({u})"),
            None => name.clone(),
        };
        let fig = Panels {
            top: Figure {
                title: format!("{name}: free-run simulation, {which} data"),
                x_label: "t (s)".into(),
                y_label: y_label.clone(),
                series,
                bands: vec![],
            },
            bottom: Figure {
                title: "residual: measured − simulated".into(),
                x_label: "t (s)".into(),
                y_label,
                series: residuals,
                bands: vec![],
            },
        };
        let file = format!("compare_{which}_{name}.svg");
        fig.write(&out.join(&file))?;
        files.push(file);
    }
    Ok(files)
}

fn residual_figure(label: &str, r: &ResidualAnalysis, out: &Path) -> Result<Vec<String>> {
    let mut files = Vec::new();
    for ch in &r.channels {
        let c = &ch.autocorrelation;
        let fig = Figure {
            title: format!(
                "{label}: residual autocorrelation of {} ({})",
                ch.output, r.horizon
            ),
            x_label: "lag".into(),
            y_label: "ACF".into(),
            series: vec![Series::points(
                "ACF",
                c.lags.iter().map(|&l| l as f64).collect(),
                c.values.clone(),
            )],
            bands: vec![("99 % band".into(), c.bound99)],
        };
        let file = format!(
            "residual_acf_{}_{}.svg",
            label.replace(['/', ' '], "_"),
            ch.output
        );
        fig.write(&out.join(&file))?;
        files.push(file);
        for x in &ch.cross {
            let c = &x.correlogram;
            let fig = Figure {
                title: format!(
                    "{label}: residual {} against input {} ({})",
                    ch.output, x.input, r.horizon
                ),
                x_label: "lag".into(),
                y_label: "XCF".into(),
                series: vec![Series::points(
                    "XCF",
                    c.lags.iter().map(|&l| l as f64).collect(),
                    c.values.clone(),
                )],
                bands: vec![("99 % band".into(), c.bound99)],
            };
            let file = format!(
                "residual_xcf_{}_{}_{}.svg",
                label.replace(['/', ' '], "_"),
                ch.output,
                x.input
            );
            fig.write(&out.join(&file))?;
            files.push(file);
        }
    }
    Ok(files)
}

/// Fit every model on the estimation data and compare them free-run on it and on the
/// validation data; write the table, figures and `compare.json` into `out`.
pub fn run_compare(
    data_paths: &[PathBuf],
    model_path: &Path,
    val_paths: &[PathBuf],
    opts: &CompareOptions,
    out: &Path,
) -> Result<CompareSummary> {
    run_compare_with_progress(data_paths, model_path, val_paths, opts, out, &NoProgress)
}

/// [`run_compare`], reporting each baseline's fit, the MME/NN fit (its sweep and
/// refinement step by step) and the evaluation to `progress`. The results do not depend
/// on the sink.
pub fn run_compare_with_progress(
    data_paths: &[PathBuf],
    model_path: &Path,
    val_paths: &[PathBuf],
    opts: &CompareOptions,
    out: &Path,
    progress: &dyn ProgressSink,
) -> Result<CompareSummary> {
    let loaded = LoadedModel::read(model_path)?;
    let spec = loaded.spec.clone();
    let lin = spec.linear.clone();
    let (data, val) = crate::data_file::read_with_validation(data_paths, val_paths, &spec)?;
    ensure_dir(out)?;
    // `fit` reads a model file: a hybrid model's model-file part is written out for it.
    let fit_model_path = if loaded.kind == ModelKind::Hybrid {
        let p = out.join("model.toml");
        write_model(&p, &spec)?;
        p
    } else {
        model_path.to_path_buf()
    };
    let given = (loaded.kind != ModelKind::Assumed).then_some(&loaded);

    // Both linear models get their initial state the same way as the hybrid model: least
    // squares over the first `x0_window` samples (which their metrics then skip).
    let window = opts.fit.x0_window.max(10 * lin.n_states());
    let mut assumed = OeModel::new(lin.clone());
    assumed.observer_window = window;
    let oe_config = OeConfig {
        free: opts.oe_free.clone().unwrap_or_else(|| default_free(&spec)),
        ..OeConfig::default()
    };
    let mut failures = Vec::new();
    // A baseline that cannot be fitted (e.g. a free parameter the data cannot identify)
    // does not stop the comparison: it has no row, and the summary says why.
    let (oe_model, oe_parameters, oe_error) = match stage(progress, "linear OE fit", || {
        fit_oe(&lin, &data, &oe_config)
    }) {
        Ok(f) => {
            let mut m = f.model;
            m.observer_window = window;
            (Some(m), f.parameters, None)
        }
        Err(e) => {
            failures.push(Failure {
                model: "linear OE".into(),
                reason: e.to_string(),
            });
            (None, Vec::new(), Some(e.to_string()))
        }
    };
    let orders = match opts.narx_lags {
        Some(l) => NarxOrders {
            na: l,
            nb: l,
            nk: 1,
        },
        None => {
            let s = suggest_lags(
                &data,
                &SuggestionConfig {
                    max_lag: opts.max_narx_lag,
                    ..SuggestionConfig::default()
                },
            )?;
            NarxOrders {
                na: s.orders.na.max(1),
                nb: s.orders.nb.max(1),
                nk: s.orders.nk,
            }
        }
    };
    let narx = match stage(progress, "NARX fit", || {
        fit_narx(
            &data,
            &NarxConfig {
                orders,
                seed: opts.fit.seed,
                ..NarxConfig::default()
            },
        )
    }) {
        Ok(f) => Some(f.model),
        Err(e) => {
            failures.push(Failure {
                model: "NARX".into(),
                reason: e.to_string(),
            });
            None
        }
    };
    let fit_dir = out.join("mme_nn");
    crate::fit::run_fit_with_progress(
        data_paths,
        &fit_model_path,
        val_paths,
        &opts.fit,
        &fit_dir,
        progress,
    )?;
    progress.report(&crate::progress::Progress::new(EVALUATION, 0, None));
    let text =
        std::fs::read_to_string(fit_dir.join("model.json")).map_err(|source| MmennError::Io {
            path: fit_dir.join("model.json"),
            source,
        })?;
    let file: HybridFile = serde_json::from_str(&text)?;
    let models = Models {
        assumed: &assumed,
        oe: oe_model.as_ref(),
        narx: narx.as_ref(),
        given,
        window: opts.fit.x0_window,
    };

    let mut files = vec!["mme_nn/".to_string()];
    if loaded.kind == ModelKind::Hybrid {
        files.push("model.toml".into());
    }
    let hybrid_est = hybrid_for(&file, &data, opts.fit.x0_window)?;
    let estimation = table(
        "free-run simulation, estimation data",
        &data,
        &models,
        &hybrid_est,
    )?;
    type Sim<'a> = Box<dyn Fn(&Dataset) -> Result<Vec<sysid_core::Prediction>> + 'a>;
    let sims = |h: &HybridModel| -> Vec<(&'static str, Sim<'_>)> {
        let h = h.clone();
        let mut v: Vec<(&'static str, Sim<'_>)> = vec![(
            "assumed model",
            Box::new(|d: &Dataset| Ok(predictions(&assumed, d, Horizon::FreeRun)?)),
        )];
        if let Some(g) = given {
            let w = opts.fit.x0_window;
            v.push((
                GIVEN_MODEL_ROW,
                Box::new(move |d: &Dataset| given_prediction(g, d, w)),
            ));
        }
        if let Some(oe) = &oe_model {
            v.push((
                "linear OE",
                Box::new(move |d: &Dataset| Ok(predictions(oe, d, Horizon::FreeRun)?)),
            ));
        }
        if let Some(narx) = &narx {
            v.push((
                "NARX",
                Box::new(move |d: &Dataset| Ok(predictions(narx, d, Horizon::FreeRun)?)),
            ));
        }
        v.push((
            "MME/NN",
            Box::new(move |d: &Dataset| {
                Ok(vec![h.simulate(&d.experiments()[0]).map_err(|source| {
                    MmennError::Core {
                        context: "MME/NN free run",
                        source,
                    }
                })?])
            }),
        ));
        v
    };
    let est_sims = sims(&hybrid_est);
    let refs: Vec<(&str, &SimFn<'_>)> = est_sims.iter().map(|(n, f)| (*n, f.as_ref())).collect();
    files.extend(compare_figures(
        "estimation",
        &data,
        &refs,
        &estimation,
        &spec.units,
        out,
    )?);

    let (validation, hybrid_res, res_data) = match &val {
        Some(v) => {
            let hv = hybrid_for(&file, v, opts.fit.x0_window)?;
            let tab = table("free-run simulation, validation data", v, &models, &hv)?;
            let val_sims = sims(&hv);
            let refs: Vec<(&str, &SimFn<'_>)> =
                val_sims.iter().map(|(n, f)| (*n, f.as_ref())).collect();
            files.extend(compare_figures(
                "validation",
                v,
                &refs,
                &tab,
                &spec.units,
                out,
            )?);
            (Some(tab), hv, v)
        }
        None => (None, hybrid_est.clone(), &data),
    };
    let rc = ResidualConfig::default();
    let mut residuals = vec![(
        "assumed model".to_string(),
        residual_analysis(&assumed, res_data, 0, Horizon::FreeRun, &rc)?,
    )];
    if let Some(oe) = &oe_model {
        residuals.push((
            "linear OE".to_string(),
            residual_analysis(oe, res_data, 0, Horizon::FreeRun, &rc)?,
        ));
    }
    if let Some(narx) = &narx {
        residuals.push((
            "NARX".to_string(),
            residual_analysis(narx, res_data, 0, Horizon::FreeRun, &rc)?,
        ));
    }
    residuals.push((
        "MME/NN".to_string(),
        residual_analysis(&hybrid_res, res_data, 0, Horizon::FreeRun, &rc)?,
    ));
    for (label, r) in &residuals {
        files.extend(residual_figure(label, r, out)?);
    }
    let mut initialisation = vec![(
        "assumed model".to_string(),
        format!(
            "{}initial state estimated by least squares from the first {window} samples, which the metrics skip",
            if loaded.kind == ModelKind::Assumed {
                String::new()
            } else {
                format!(
                    "the linear part of the model file (its {} named terms{} are in the '{GIVEN_MODEL_ROW}' row); ",
                    spec.terms.len(),
                    if loaded.kind == ModelKind::Hybrid {
                        " and network"
                    } else {
                        ""
                    }
                )
            }
        ),
    )];
    if given.is_some() {
        initialisation.push((
            GIVEN_MODEL_ROW.to_string(),
            format!(
                "{} as read from {}: initial state fitted by least squares to the first {} samples, every sample scored (the rule and numbers of `mmenn predict`)",
                loaded.kind,
                model_path.display(),
                opts.fit.x0_window
            ),
        ));
    }
    initialisation.push((
        "linear OE".to_string(),
        "same as the assumed model".to_string(),
    ));
    initialisation.push((
        "NARX".to_string(),
        format!(
            "the first {} measured samples seed the delay line and are skipped (NARX predicts only measured channels)",
            orders.na.max(orders.nb + orders.nk - 1)
        ),
    ));
    initialisation.push((
        "MME/NN".to_string(),
        format!(
            "initial state fitted to the first {} samples (not skipped), as for the given model and `mmenn predict`; every state is simulated",
            opts.fit.x0_window
        ),
    ));
    files.push("compare.json".into());
    files.push("report.md".into());
    files.push("report.html".into());
    let summary = CompareSummary {
        estimation,
        validation,
        narx_orders: orders,
        oe_parameters,
        oe_error,
        failures,
        given_model: loaded.kind,
        initialisation,
        residuals,
        files,
    };
    write_atomic(
        &out.join("compare.json"),
        serde_json::to_string_pretty(&summary)?.as_bytes(),
    )?;
    crate::html::write_report(out, &compare_report(&summary))?;
    progress.finish(EVALUATION);
    Ok(summary)
}

fn table_md(t: &EvaluationTable, failures: &[Failure]) -> String {
    // The title names the horizon already ("free-run simulation, …").
    let horizon = t.horizon().to_string();
    let heading = if t.title().contains(&horizon) {
        t.title().to_string()
    } else {
        format!("{} ({horizon})", t.title())
    };
    let mut s = format!(
        "### {heading}\n\n| model | channel | fit % | R² | RMSE | error variance |\n|---|---|---|---|---|---|\n"
    );
    for row in t.rows() {
        for ch in &row.evaluation.channels {
            let m = &ch.metrics;
            s.push_str(&format!(
                "| {} | {} | {:.2} | {:.5} | {:.4e} | {:.4e} |\n",
                row.label, ch.name, m.fit_percent, m.r2, m.rmse, m.error_variance
            ));
        }
    }
    for f in failures {
        s.push_str(&format!(
            "| {} | — | not fitted: {} | | | |\n",
            f.model,
            f.reason.replace('|', "/").replace('\n', " ")
        ));
    }
    s
}

fn compare_report(s: &CompareSummary) -> String {
    let mut r = String::from(
        "# Model comparison\n\nEvery number below is **free-run simulation** (inputs only after the initial condition).\n\n",
    );
    r.push_str(&table_md(&s.estimation, &s.failures));
    if let Some(v) = &s.validation {
        r.push('\n');
        r.push_str(&table_md(v, &s.failures));
    }
    if !s.failures.is_empty() {
        r.push_str("\n## Models that could not be fitted\n\n");
        for f in &s.failures {
            r.push_str(&format!("- **{}**: {}\n", f.model, f.reason));
        }
    }
    r.push_str("\n## Initial conditions\n\n");
    for (m, how) in &s.initialisation {
        r.push_str(&format!("- **{m}**: {how}\n"));
    }
    r.push_str(&format!(
        "\nNARX delays: na = {}, nb = {}, nk = {}.\n\nOutput-error parameters (±1σ):\n\n",
        s.narx_orders.na, s.narx_orders.nb, s.narx_orders.nk
    ));
    if s.oe_parameters.is_empty() {
        r.push_str("- none (the output-error model was not fitted)\n");
    }
    for p in &s.oe_parameters {
        r.push_str(&format!("- {}: {:.6} ± {:.2e}\n", p.name, p.value, p.std));
    }
    r.push_str(crate::words::METRICS_MEANING);
    r.push_str(
        "\nFigures: `compare_*.svg` show the measured output, every model's free run (fit % \
         in the legend) and, below, each model's residual (measured − simulated); \
         `residual_acf_*.svg` and `residual_xcf_*.svg` show the free-run residual's \
         autocorrelation and its cross-correlation with each input, with the 99 % band \
         ±2.58/√N of white noise: values outside the band mean the residual still holds \
         dynamics the model misses (expected for the assumed model, a warning for the \
         others).\n",
    );
    r.push_str(&crate::html::figures_section(&s.files));
    r
}
