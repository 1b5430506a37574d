//! `mmenn compare`: the assumed model, a linear output-error model (the model file's own
//! `A`, `B` refitted), a black-box linear state-space model ([`LINEAR_SS_ROW`]: PO-MOESP
//! subspace start, free-run output-error refinement, order up to
//! [`CompareOptions::ss_max_order`] chosen on the held-out end of the first estimation
//! record, [`sysid_baselines::fit_linear_ss`]; MATLAB's `n4sid` then `pem`), a NARX
//! network (trained one-step, refined by free-run error with
//! [`CompareOptions::narx_focus`] = [`Focus::Simulation`]), a polynomial NARX model
//! ([`POLY_NARX_ROW`]: the NARX network's delays, monomials up to
//! [`PolyNarxChoice::degree`] of the newest lags, one-step least squares, refined by
//! free-run error with [`Focus::Simulation`]; off with
//! `poly_narx: None`) and the MME/NN hybrid model judged the same way on the same data
//! (thesis ch. 5): free-run simulation, fit %, R², RMSE and error variance per channel, on
//! estimation and validation data; compare plots with fit % in the legend, residual
//! correlation plots with 99 % bands, and `compare.json`.
//!
//! `--model` is any model mmenn writes ([`crate::model::LoadedModel`]). When it is more
//! than the linear assumed model (it has `[[terms]]`, e.g. a discovered model, or it is a
//! hybrid `model.json`), it gets its own row, [`GIVEN_MODEL_ROW`], judged by the one
//! free-run judge ([`crate::model::judge_free_run`]: the numbers `mmenn predict` gives on
//! the same record); the baselines start from its linear part. A baseline that cannot be
//! fitted has no numbers: the table, the report and the terminal say so, with the reason.
//!
//! Every state-space row (assumed model, given model, linear OE, MME/NN) is judged by the
//! one free-run judge of `sysid-core` on the first record of each dataset: initial state
//! fitted to the first `x0_window` samples, every sample scored; each table's title states
//! the record length and the window. The linear SS row is discrete-time and judged by the
//! same rule (its state by least squares on the first `x0_window` outputs, every sample
//! scored by the judge's scoring). It is SISO and fitted on the first estimation record; a
//! terms-only model file (zero `A`, `B`), which has no linear OE row, still gets it.
//! NARX and polynomial NARX start from their first measured delay window, which they do
//! not score. A linear SS, NARX or polynomial NARX model whose free run fails on a dataset
//! (leaves its divergence limits, or has no measured initial window) has no row in that
//! dataset's table (a [`Failure`] at [`FailedAt::FreeRun`]) and the comparison goes on.
//! [`compute_compare`] returns everything as values; [`write_compare`] writes the files.

use std::path::{Path, PathBuf};

use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};
pub use sysid_baselines::Refinement;
pub use sysid_baselines::poly_narx::Focus;
use sysid_baselines::{
    EvaluationTable, LinearSsConfig, LinearSsModel, NarxConfig, NarxModel, NarxOrders, OeConfig,
    OeModel, OrderCandidate, PolyNarxConfig, PolyNarxModel, ResidualAnalysis, ResidualConfig,
    SuggestionConfig, evaluate, fit_linear_ss, fit_narx, fit_oe, fit_poly_narx, predictions,
    residual_analysis, suggest_lags,
};
use sysid_core::{
    Dataset, Experiment, Horizon, InitialRule, JudgeOptions, Judgement, LinearModel, Model,
    Observation,
};

use crate::atomic::{ensure_dir, write_atomic};
use crate::error::{MmennError, Result};
use crate::fit::{
    FitOptions, FitOutcome, HybridModel, ValidationUse, compute_fit, judge_outputs, write_fit,
};
use crate::model::{LoadedModel, ModelKind, evaluation, judge_free_run};
use crate::model_file::ModelSpec;
use crate::plot::{Figure, Panels, Series};
use crate::progress::{NoProgress, ProgressSink, stage};

/// Progress task of the figures and reports.
const EVALUATION: &str = "figures and report";

/// Row label of the model given with `--model` when it is more than its linear part.
pub const GIVEN_MODEL_ROW: &str = "given model";

/// Row label of the polynomial NARX model.
pub const POLY_NARX_ROW: &str = "polynomial NARX";

/// Start of the linear state-space row's label; the full label names the chosen order,
/// e.g. `linear SS (subspace + OE, n = 2)` ([`LinearSsStructure::label`]).
pub const LINEAR_SS_ROW: &str = "linear SS (subspace + OE";

/// Where a model fell out of the comparison.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum FailedAt {
    /// Its fit failed: no row in any table.
    Fit,
    /// It was fitted, but its free run failed on one dataset (e.g. left its divergence
    /// limits): no row in that dataset's table.
    FreeRun,
    /// Its rows have numbers, but its residual analysis failed (e.g. a linear part whose
    /// state the outputs do not observe over the observer window): no residual analysis.
    Residuals,
}

impl std::fmt::Display for FailedAt {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            FailedAt::Fit => "not fitted",
            FailedAt::FreeRun => "free run failed",
            FailedAt::Residuals => "residual analysis failed",
        })
    }
}

/// A model that could not be fitted, or whose free run failed: it has no row of numbers.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Failure {
    /// Row label.
    pub model: String,
    /// Why.
    pub reason: String,
    /// Where it failed.
    pub at: FailedAt,
    /// For [`FailedAt::FreeRun`]: the dataset whose free run failed (`"estimation"` or
    /// `"validation"`); `None` for a failure that concerns every table.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub dataset: Option<String>,
}

impl Failure {
    /// Whether this failure belongs in the table of `dataset` (`"estimation"` or
    /// `"validation"`): a fit failure in every table, a free-run failure only in its own
    /// dataset's.
    pub fn concerns(&self, dataset: &str) -> bool {
        self.dataset.as_deref().is_none_or(|d| d == dataset)
    }
}

/// The polynomial NARX row of `compare`: its delays are the NARX network's
/// ([`CompareSummary::narx_orders`]); coefficients by one-step least squares, optionally
/// refined by free-run error ([`sysid_baselines::fit_poly_narx`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(default)]
pub struct PolyNarxChoice {
    /// Highest total degree of a monomial, 1 to 5 (1: a linear ARX model with a
    /// constant). Default 3.
    pub degree: usize,
    /// How many of the newest output lags and input taps (each channel) enter the
    /// monomials of degree ≥ 2 (at most the delays). Default 2.
    pub nonlinear_lags: usize,
    /// One-step least squares alone ([`Focus::Prediction`], the default, as MATLAB's
    /// `nlarx`), or refined by free-run error over the estimation data
    /// ([`Focus::Simulation`]). Only for [`PolyNarxMonomials::All`].
    pub focus: Focus,
    /// Which monomials the model keeps. Default [`PolyNarxMonomials::All`].
    pub monomials: PolyNarxMonomials,
}

impl Default for PolyNarxChoice {
    fn default() -> Self {
        Self {
            degree: 3,
            nonlinear_lags: 2,
            focus: Focus::Prediction,
            monomials: PolyNarxMonomials::All,
        }
    }
}

/// Which monomials a polynomial NARX row keeps.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum PolyNarxMonomials {
    /// Every monomial of the dictionary (MATLAB's `nlarx` with a polynomial regressor
    /// set).
    #[default]
    All,
    /// A sparse model (the reproduce's rule, docs/decisions/frols-count-kfold.md): FROLS
    /// (forward regression with orthogonal least squares, Billings) ranks at most
    /// [`FROLS_MAX_TERMS`] monomials on the first estimation record; every prefix count is
    /// scored by free run pooled over [`sysid_baselines::KFOLD_FOLDS`] contiguous folds of
    /// that record, each refitted without its fold ([`sysid_baselines::FrolsFit::kfold_scores`]);
    /// the smallest count within [`FROLS_COUNT_TOLERANCE`] of the best is kept, and FROLS
    /// runs again on every estimation record keeping that many terms. A count whose free
    /// run diverges on a fold is never kept, so the model is one that simulates.
    FrolsKfold,
}

/// Most monomials FROLS ranks for [`PolyNarxMonomials::FrolsKfold`] (the reproduce's cap).
pub const FROLS_MAX_TERMS: usize = 40;
/// Relative tolerance of the K-fold count rule: the smallest count whose pooled free-run
/// RMSE is within it of the best count's (docs/decisions/frols-count-kfold.md).
pub const FROLS_COUNT_TOLERANCE: f64 = 0.02;

/// The polynomial NARX model of a comparison, in `compare.json` and the report.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PolyNarxStructure {
    /// The settings asked for.
    #[serde(flatten)]
    pub choice: PolyNarxChoice,
    /// Delays (the NARX network's).
    pub orders: NarxOrders,
    /// Terms of the fitted model, constant included (`None`: not fitted).
    pub terms: Option<usize>,
    /// Numerical rank of its regressor matrix (equal to `terms` when the data determine
    /// every term).
    pub rank: Option<usize>,
    /// With [`PolyNarxMonomials::FrolsKfold`]: how the count was chosen (every prefix count's
    /// pooled K-fold free-run RMSE, `×` where its free run failed on a fold).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub selection: Option<String>,
}

/// The linear state-space row of `compare` (MATLAB's `n4sid` then `pem`): PO-MOESP
/// subspace initialisation, free-run output-error refinement, the order chosen on a
/// held-out part of the first estimation record ([`sysid_baselines::fit_linear_ss`]).
/// In `compare.json` and the report.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LinearSsStructure {
    /// Row label (with the chosen order; without it when the fit failed).
    pub label: String,
    /// Largest order tried.
    pub max_order: usize,
    /// Samples of the record it was fitted on (the first estimation record).
    pub samples: usize,
    /// State-initialisation window of the fit (samples): the error is summed after it.
    pub fit_window: usize,
    /// Whether an input bias was fitted on top of the record mean.
    pub input_bias: bool,
    /// Chosen order (`None`: not fitted).
    pub order: Option<usize>,
    /// Every order tried, with its held-out free-run RMSE.
    pub candidates: Vec<OrderCandidate>,
    /// MOESP singular values on the fitting part, relative to the largest.
    pub singular_values: Vec<f64>,
    /// Poles of the fitted model, `(re, im)` (discrete time).
    pub poles: Vec<(f64, f64)>,
    /// Why this order: the rule and each candidate's held-out RMSE, in words (and, when
    /// the refinement on the whole record failed, that the row's model is the held-out
    /// stage's).
    pub choice: String,
    /// Why the chosen order's refinement on the whole record failed, when it did: the
    /// row's model is then the one refined on the rest of the record and scored on its
    /// held-out end ([`sysid_baselines::LinearSsFit::final_refinement_failure`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub final_refinement_failure: Option<String>,
}

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
    /// What the NARX network's weights finally minimise: its one-step error alone
    /// ([`Focus::Prediction`], the default, as MATLAB's `nlarx`), or that training then
    /// refined by free-run error over the estimation data ([`Focus::Simulation`], MATLAB
    /// `nlarx`'s `Focus = "simulation"`; [`sysid_baselines::NarxConfig::focus`]).
    pub narx_focus: Focus,
    /// Free parameters of the output-error model (`"A[i,j]"`, `"B[i,j]"`); `None` = every
    /// entry of the corrected rows of A and B (the equations MME corrects).
    pub oe_free: Option<Vec<String>>,
    /// The polynomial NARX row (same delays as NARX); `None` = no such row.
    pub poly_narx: Option<PolyNarxChoice>,
    /// Largest order the linear state-space row tries (orders 1 to this, the smallest
    /// within 2 % of the best held-out free-run RMSE is kept). Default 6
    /// ([`LinearSsConfig`]'s).
    pub ss_max_order: usize,
}

impl Default for CompareOptions {
    fn default() -> Self {
        Self {
            fit: FitOptions::default(),
            narx_lags: None,
            max_narx_lag: 10,
            narx_focus: Focus::Prediction,
            oe_free: None,
            poly_narx: Some(PolyNarxChoice::default()),
            ss_max_order: LinearSsConfig::default().max_order,
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
    /// NARX delays used (na output lags, nb input taps from delay nk; they may differ
    /// when suggested) and how they were chosen.
    pub narx_orders: NarxOrders,
    /// What the NARX network's weights finally minimised ([`CompareOptions::narx_focus`]).
    pub narx_focus: Focus,
    /// With [`Focus::Simulation`]: what the free-run refinement of the NARX network did
    /// (iterations, training free-run RMSE per output before and after); `None` with
    /// [`Focus::Prediction`] or when the NARX was not fitted.
    pub narx_refinement: Option<Refinement>,
    /// How the NARX network was trained, in words (the report's sentence).
    pub narx_training: String,
    /// The polynomial NARX model (same delays), when asked for.
    pub poly_narx: Option<PolyNarxStructure>,
    /// The linear state-space model (order and how it was chosen).
    pub linear_ss: LinearSsStructure,
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
    /// Models whose residual analysis failed (at [`FailedAt::Residuals`]; their table rows
    /// stand).
    pub residual_failures: Vec<Failure>,
    /// Files written.
    pub files: Vec<String>,
    /// What the validation records were for (`None` without them): every row is judged
    /// on them, and under [`ValidationUse::Select`] the MME/NN also chose on them.
    pub validation_use: Option<ValidationUse>,
}

/// Whether the model file has no linear part: its `A` and `B` are all zero (its dynamics
/// are all in `[[terms]]`), or it is a `[mechanics]` model (its dynamics are the
/// mass-matrix equations). The one predicate behind both consequences: no "assumed model"
/// row (the given model's row judges the file), and a linear OE fit that fails is
/// explained by it (the fit starts where no coefficient moves the output).
fn has_no_linear_part(spec: &ModelSpec) -> bool {
    let lin = &spec.linear;
    spec.mechanics.is_some()
        || (lin.a().iter().all(|v| *v == 0.0) && lin.b().iter().all(|v| *v == 0.0))
}

/// Why a model file has no linear part, in words (see [`has_no_linear_part`]).
fn no_linear_part_words(spec: &ModelSpec) -> &'static str {
    if spec.mechanics.is_some() {
        "it is a [mechanics] model, its dynamics the mass-matrix equations"
    } else {
        "its A and B are zero, its dynamics all in [[terms]]"
    }
}

/// Why the linear OE fit failed: the error, explained when the default parameters were
/// free and the model file has no linear part (the fit started where no coefficient
/// moves the output), with the remedy and the linear baseline that stands.
fn oe_failure(spec: &ModelSpec, default_free: bool, e: &dyn std::error::Error) -> String {
    if !default_free || !has_no_linear_part(spec) {
        return with_causes(e);
    }
    // A and B to start from are the remedy unless the dynamics are mechanics.
    let remedy = if spec.mechanics.is_some() {
        ""
    } else {
        "give A and B (e.g. the terms linearised at an operating point) to get this row; "
    };
    format!(
        "the model file has no linear part ({}), so an output-error fit of its linear part \
         starts where no coefficient moves the output; {remedy}the '{LINEAR_SS_ROW}, n = …)' \
         row is the linear baseline here (a black-box state-space model fitted to the data \
         alone) ({})",
        no_linear_part_words(spec),
        with_causes(e)
    )
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

/// A state-space model judged by the one free-run judge on the first record of `data`,
/// on its outputs, the initial state fitted to the first `window` samples (every sample
/// scored): for a model file, the rule and numbers of `mmenn predict`.
fn judge_linear(lin: &LinearModel, data: &Dataset, window: usize) -> Result<Judgement> {
    sysid_core::judge_free_run(
        lin,
        &data.experiments()[0],
        &Observation::outputs(lin),
        &InitialRule::Fit {
            window: Some(window),
        },
        &JudgeOptions::default(),
    )
    .map_err(|source| MmennError::Core {
        context: "judging a linear model free-run",
        source,
    })
}

/// Every model of one comparison judged on one dataset: the table and each model's
/// predicted outputs on the first record (for the figures).
struct Judged {
    table: EvaluationTable,
    runs: Vec<(String, DMatrix<f64>)>,
    /// The hybrid model with the initial state its judgement found (residual analysis).
    hybrid: HybridModel,
    /// The hybrid's judged outputs on the first record (through its acquisition filter,
    /// when it has one: its residuals are those).
    hybrid_outputs: DMatrix<f64>,
    /// Models whose free run failed on this dataset (no row).
    failures: Vec<Failure>,
}

/// A delay-line model (NARX, polynomial NARX) free-run on every record of `data`: its
/// evaluation and its predicted outputs on the first record.
fn judge_delay_line<M: Model>(
    model: &M,
    data: &Dataset,
) -> Result<(sysid_baselines::Evaluation, DMatrix<f64>)> {
    let ev = evaluate(model, data, Horizon::FreeRun)?;
    let mut p = predictions(model, data, Horizon::FreeRun)?;
    Ok((ev, p.swap_remove(0).outputs))
}

/// The linear state-space model judged as the state-space rows are, on the first record of
/// `data`: its state fitted by least squares to the first `window` measured outputs (fewer
/// on a shorter record), a free run over the whole record, every sample scored. Returns
/// the evaluation and its outputs on that record.
fn judge_linear_ss(
    model: &LinearSsModel,
    data: &Dataset,
    window: usize,
) -> Result<(sysid_baselines::Evaluation, DMatrix<f64>)> {
    let exp = &data.experiments()[0];
    let judged = LinearSsModel {
        window: window.min(exp.len()).max(1),
        ..model.clone()
    };
    let run = judged.simulate(exp)?;
    let names = data.output_names();
    let scored =
        sysid_core::score_rows(&names, exp.outputs(), &run.outputs, 0).map_err(|source| {
            MmennError::Core {
                context: "scoring the linear state-space model's free run",
                source,
            }
        })?;
    let channels = names
        .into_iter()
        .filter_map(|name| {
            scored
                .get(&name)
                .map(|m| sysid_baselines::ChannelEvaluation { metrics: *m, name })
        })
        .collect();
    let ev = sysid_baselines::Evaluation {
        horizon: Horizon::FreeRun,
        channels,
        initial_samples: 0,
    };
    Ok((ev, run.outputs))
}

/// How the NARX network of `config` was trained, in words: one-step (series-parallel)
/// Levenberg–Marquardt and the restart choice, then, with [`Focus::Simulation`], the
/// free-run refinement's iterations and each output's training free-run RMSE before and
/// after (`refinement`, outputs named by `outputs`). `fitted` false: not fitted.
fn narx_training_words(
    config: &NarxConfig,
    fitted: bool,
    outputs: &[String],
    refinement: Option<&Refinement>,
) -> String {
    let network = match &config.network {
        sysid_baselines::NetworkChoice::Hidden { units, restarts } => format!(
            "one tanh layer of {units} unit{}, {restarts} initialisation{}",
            if *units == 1 { "" } else { "s" },
            if *restarts == 1 { "" } else { "s" },
        ),
        sysid_baselines::NetworkChoice::Sweep { .. } => "sized by the sweep".to_string(),
    };
    let choice = match config.selection {
        sysid_baselines::RestartSelection::FreeRunTraining => {
            "the one whose free run fits the estimation data best kept"
        }
        sysid_baselines::RestartSelection::OneStep => "the one of lowest one-step error kept",
    };
    let mut words = format!(
        "{network}, trained one-step (series-parallel: measured past outputs in every \
         regressor) by Levenberg–Marquardt, {choice}"
    );
    match (config.focus, refinement) {
        (Focus::Prediction, _) => {}
        (Focus::Simulation { max_iterations }, Some(r)) => {
            let rmse: Vec<String> = r
                .start_rmse
                .iter()
                .zip(&r.final_rmse)
                .enumerate()
                .map(|(i, (a, b))| {
                    let name = outputs.get(i).map_or("", String::as_str);
                    format!("{name} {a:.4e} → {b:.4e}").trim_start().to_string()
                })
                .collect();
            words.push_str(&format!(
                "; then refined by free-run error over the estimation data: {} \
                 Levenberg–Marquardt iteration{} (at most {max_iterations}), training \
                 free-run RMSE {}",
                r.iterations,
                if r.iterations == 1 { "" } else { "s" },
                rmse.join(", ")
            ));
        }
        (Focus::Simulation { max_iterations }, None) => words.push_str(&format!(
            "; its refinement by free-run error over the estimation data asked for (at \
             most {max_iterations} Levenberg–Marquardt iterations)"
        )),
    }
    if !fitted {
        words.push_str("; not fitted (see the models without numbers)");
    }
    words
}

/// An error and each cause its message does not already hold, joined by ": " (e.g. a
/// model's failure on a record and the divergence that caused it).
fn with_causes(e: &dyn std::error::Error) -> String {
    let mut msg = e.to_string();
    let mut cause = e.source();
    while let Some(c) = cause {
        let part = c.to_string();
        if !msg.contains(&part) {
            msg.push_str(": ");
            msg.push_str(&part);
        }
        cause = c.source();
    }
    msg
}

/// The models of one comparison (a baseline that could not be fitted is `None`).
struct Models<'a> {
    /// The model file's linear part; `None` when it is zero (the dynamics are all in
    /// `[[terms]]` or `[mechanics]`, judged in the given model's row).
    assumed: Option<&'a LinearModel>,
    oe: Option<&'a OeModel>,
    /// The linear state-space model and its row label.
    ss: Option<(&'a LinearSsModel, &'a str)>,
    narx: Option<&'a NarxModel>,
    poly: Option<&'a PolyNarxModel>,
    given: Option<&'a LoadedModel>,
    hybrid: &'a LoadedModel,
    window: usize,
}

fn judge_all(which: &str, title: &str, data: &Dataset, models: &Models<'_>) -> Result<Judged> {
    let mut table = EvaluationTable::new(title, Horizon::FreeRun);
    let mut runs = Vec::new();
    let mut failures = Vec::new();
    let names = data.output_names();
    let mut push = |label: &str, j: &Judgement, runs: &mut Vec<(String, DMatrix<f64>)>| {
        runs.push((label.to_string(), j.outputs.clone()));
        table.push(label, evaluation(j, &names))
    };
    if let Some(assumed) = models.assumed {
        let j = judge_linear(assumed, data, models.window)?;
        push("assumed model", &j, &mut runs)?;
    }
    if let Some(g) = models.given {
        let j = judge_free_run(
            g,
            &data.experiments()[0],
            &g.outputs(),
            &InitialRule::Fit {
                window: Some(models.window),
            },
        )?;
        push(GIVEN_MODEL_ROW, &j, &mut runs)?;
    }
    if let Some(oe) = models.oe {
        let j = judge_linear(&oe.model, data, models.window)?;
        push("linear OE", &j, &mut runs)?;
    }
    // A black-box model's free run can leave its limits (or find no initial window) on
    // data its fit did not see: that model has no row here, and the comparison goes on.
    let mut delay_line =
        |label: &str, judged: Result<(sysid_baselines::Evaluation, DMatrix<f64>)>| {
            match judged {
                Ok((ev, run)) => {
                    runs.push((label.to_string(), run));
                    table.push(label, ev)?;
                }
                Err(e) => failures.push(Failure {
                    model: label.into(),
                    reason: format!("free run on the {which} data: {}", with_causes(&e)),
                    at: FailedAt::FreeRun,
                    dataset: Some(which.to_string()),
                }),
            }
            Ok::<(), MmennError>(())
        };
    if let Some((ss, label)) = models.ss {
        delay_line(label, judge_linear_ss(ss, data, models.window))?;
    }
    if let Some(narx) = models.narx {
        delay_line("NARX", judge_delay_line(narx, data))?;
    }
    if let Some(poly) = models.poly {
        delay_line(POLY_NARX_ROW, judge_delay_line(poly, data))?;
    }
    let j = judge_outputs(models.hybrid, data, models.window)?;
    let mut hybrid = match &models.hybrid.hybrid {
        Some(file) => file.model()?,
        None => unreachable_hybrid()?,
    };
    hybrid.x0 = j.x0.clone();
    table.push("MME/NN", evaluation(&j, &names))?;
    let hybrid_outputs = j.outputs.clone();
    runs.push(("MME/NN".to_string(), j.outputs));
    Ok(Judged {
        table,
        runs,
        hybrid,
        hybrid_outputs,
        failures,
    })
}

/// `fit` always returns a hybrid model; this names the impossible case as an error.
fn unreachable_hybrid() -> Result<HybridModel> {
    Err(MmennError::Core {
        context: "the MME/NN model of the comparison",
        source: sysid_core::CoreError::InvalidArgument {
            name: "model kind",
            value: 0.0,
            reason: "fit did not return a hybrid model",
        },
    })
}

fn compare_figures(
    which: &str,
    exp: &Experiment,
    names: &[String],
    runs: &[(String, DMatrix<f64>)],
    tab: &EvaluationTable,
    units: &std::collections::BTreeMap<String, String>,
    out: &Path,
) -> Result<()> {
    let t = exp.times();
    for (i, name) in names.iter().enumerate() {
        let measured: Vec<f64> = exp.outputs().row(i).iter().copied().collect();
        let mut series = vec![Series::points(
            format!("{name} measured"),
            t.clone(),
            measured.clone(),
        )];
        // Measured − simulated per model (NaN where the record has no sample or the
        // model no prediction yet, e.g. NARX's delay line), in the colour of the model's
        // line above (the measurement is entry 0).
        let residuals: Vec<Series> = runs
            .iter()
            .enumerate()
            .map(|(k, (label, y))| {
                Series::line(
                    label.clone(),
                    t.clone(),
                    measured
                        .iter()
                        .zip(y.row(i).iter())
                        .map(|(m, s)| m - s)
                        .collect::<Vec<f64>>(),
                )
                .coloured(k + 1)
            })
            .collect();
        for (label, y) in runs {
            let fit = tab
                .rows()
                .iter()
                .find(|r| &r.label == label)
                .and_then(|r| r.evaluation.channel(name))
                .map_or(f64::NAN, |m| m.fit_percent);
            series.push(Series::line(
                format!("{label} (fit {fit:.1} %)"),
                t.clone(),
                y.row(i).iter().copied().collect::<Vec<f64>>(),
            ));
        }
        let y_label = match units.get(name) {
            Some(u) => format!("{name} ({u})"),
            None => name.clone(),
        };
        let fig = Panels::time_with_residuals(
            format!("{name}: free-run simulation, {which} data"),
            y_label,
            series,
            residuals,
        );
        fig.write(&out.join(compare_figure_file(which, name)))?;
    }
    Ok(())
}

fn compare_figure_file(which: &str, name: &str) -> String {
    format!("compare_{which}_{name}.svg")
}

/// A row label in file names: every run of characters other than letters and digits
/// becomes one `_`, none at the ends (`MME/NN` → `MME_NN`, `linear SS (subspace + OE,
/// n = 2)` → `linear_SS_subspace_OE_n_2`).
fn file_tag(label: &str) -> String {
    let mut tag = String::new();
    for c in label.chars() {
        if c.is_alphanumeric() {
            tag.push(c);
        } else if !tag.is_empty() && !tag.ends_with('_') {
            tag.push('_');
        }
    }
    tag.trim_end_matches('_').to_string()
}

fn residual_files(label: &str, r: &ResidualAnalysis) -> Vec<String> {
    let tag = file_tag(label);
    let mut files = Vec::new();
    for ch in &r.channels {
        files.push(format!("residual_acf_{tag}_{}.svg", ch.output));
        for x in &ch.cross {
            files.push(format!("residual_xcf_{tag}_{}_{}.svg", ch.output, x.input));
        }
    }
    files
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
                c.lags.iter().map(|&l| l as f64).collect::<Vec<f64>>(),
                c.values.clone(),
            )],
            bands: vec![("99 % band".into(), c.bound99)],
        };
        let file = format!("residual_acf_{}_{}.svg", file_tag(label), ch.output);
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
                    c.lags.iter().map(|&l| l as f64).collect::<Vec<f64>>(),
                    c.values.clone(),
                )],
                bands: vec![("99 % band".into(), c.bound99)],
            };
            let file = format!(
                "residual_xcf_{}_{}_{}.svg",
                file_tag(label),
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
/// validation data; write the table, figures and `compare.json` into `out`: reads the
/// files, [`compute_compare`], [`write_compare`].
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
    run_compare_outcome(data_paths, model_path, val_paths, opts, out, progress).map(|o| o.summary)
}

/// [`run_compare_with_progress`], returning everything it computed: the summary, and the
/// MME/NN fit ([`CompareOutcome::fit`], whose
/// [`FitSummary::decision_lines`](crate::fit::FitSummary::decision_lines) the command line
/// prints as `mmenn fit` does).
pub fn run_compare_outcome(
    data_paths: &[PathBuf],
    model_path: &Path,
    val_paths: &[PathBuf],
    opts: &CompareOptions,
    out: &Path,
    progress: &dyn ProgressSink,
) -> Result<CompareOutcome> {
    let loaded = LoadedModel::read(model_path)?;
    // Its hybrid row runs `fit`'s MME, which does not apply the table.
    loaded.refuse_x0_prior("compare")?;
    let (data, val) = crate::data_file::read_with_validation(data_paths, val_paths, &loaded.spec)?;
    let outcome = compute_compare_with_progress(&data, &loaded, val.as_ref(), opts, progress)?;
    progress.report(&crate::progress::Progress::new(EVALUATION, 0, None));
    write_compare(&outcome, out)?;
    progress.finish(EVALUATION);
    Ok(outcome)
}

/// Each model's predicted outputs on one record (`p × N`), by row label.
pub type Runs = Vec<(String, DMatrix<f64>)>;

/// Everything `mmenn compare` computes, as values ([`write_compare`] writes it).
#[derive(Debug, Clone)]
pub struct CompareOutcome {
    /// What `compare.json` holds.
    pub summary: CompareSummary,
    /// The MME/NN fit (written into `mme_nn/`).
    pub fit: FitOutcome,
    /// The first estimation record.
    pub estimation_record: Experiment,
    /// Each model's predicted outputs on it (`p × N`), by row label.
    pub estimation_runs: Runs,
    /// The first validation record and each model's predicted outputs on it.
    pub validation_runs: Option<(Experiment, Runs)>,
    /// The output channels, in order.
    pub outputs: Vec<String>,
    /// Units by channel name (the model file's).
    pub units: std::collections::BTreeMap<String, String>,
}

/// [`PolyNarxMonomials::FrolsKfold`] ([`sysid_baselines::fit_frols_kfold`]). Returns the
/// model, its terms (constant included) and the selection's line.
fn fit_frols_kfold(
    data: &Dataset,
    orders: NarxOrders,
    choice: &PolyNarxChoice,
) -> std::result::Result<(PolyNarxModel, usize, String), sysid_baselines::BaselineError> {
    let config = sysid_baselines::FrolsConfig {
        orders,
        degree: choice.degree,
        nonlinear_lags: choice.nonlinear_lags,
        max_terms: FROLS_MAX_TERMS,
        ..sysid_baselines::FrolsConfig::default()
    };
    let k = sysid_baselines::fit_frols_kfold(data, &config, FROLS_COUNT_TOLERANCE)?;
    let by_count: Vec<String> = k
        .scores
        .iter()
        .map(|s| s.value().map_or("×".into(), |v| format!("{v:.4e}")))
        .collect();
    let line = format!(
        "{} of {} ranked terms of {} candidates: the smallest count within {:.0} % of the \
         best pooled {}-fold free-run RMSE on the first estimation record ({:.4e}; counts \
         1–{}: {})",
        k.count,
        k.scores.len(),
        k.fit.candidates,
        100.0 * FROLS_COUNT_TOLERANCE,
        sysid_baselines::KFOLD_FOLDS,
        k.score,
        k.scores.len(),
        by_count.join(" ")
    );
    Ok((k.fit.model, k.fit.n_terms, line))
}

/// The linear state-space row's fit on the first record of `data`
/// ([`sysid_baselines::fit_linear_ss`], orders 1 to `opts.ss_max_order`); a fit that fails
/// is a [`Failure`] at [`FailedAt::Fit`] (no row). When only its last step, the chosen
/// order's refinement on the whole record, failed, the row's model is the held-out
/// stage's, and [`LinearSsStructure`] says so. Its state-initialisation window is
/// `LinearSsConfig`'s (50 samples), at most the judge's `window` and an eighth of the
/// record (the held-out quarter must be longer than it).
fn fit_linear_ss_row(
    data: &Dataset,
    opts: &CompareOptions,
    window: usize,
    progress: &dyn ProgressSink,
    failures: &mut Vec<Failure>,
) -> (LinearSsStructure, Option<LinearSsModel>) {
    let samples = data.experiments().first().map_or(0, Experiment::len);
    let defaults = LinearSsConfig::default();
    let config = LinearSsConfig {
        max_order: opts.ss_max_order,
        window: defaults.window.min(window).min(samples / 8).max(1),
        ..defaults
    };
    let mut structure = LinearSsStructure {
        label: format!("{LINEAR_SS_ROW})"),
        max_order: config.max_order,
        samples,
        fit_window: config.window,
        input_bias: config.fit_input_offset,
        order: None,
        candidates: Vec::new(),
        singular_values: Vec::new(),
        poles: Vec::new(),
        choice: String::new(),
        final_refinement_failure: None,
    };
    // Err: the reason of the failure (the row's). A failed refinement on the whole
    // record is no failure: the fit keeps the held-out stage's model and says why.
    let fitted = stage(progress, "linear SS fit", || {
        let first = data
            .window(0, 0, samples)
            .map_err(|e| format!("the first estimation record: {}", with_causes(&e)))?;
        fit_linear_ss(&first, &config).map_err(|e| with_causes(&e))
    });
    match fitted {
        Ok(f) => {
            let held = |c: &OrderCandidate| match (c.refined_rmse, &c.failure) {
                (Some(r), _) => format!("n = {}: {r:.4e}", c.order),
                (None, Some(why)) => format!("n = {}: failed ({why})", c.order),
                (None, None) => format!("n = {}: diverged", c.order),
            };
            let kept = match &f.final_refinement_failure {
                Some(why) => format!(
                    ", which failed ({why}): the row's model is the held-out stage's (refined on \
                     the rest, scored on the held-out end)"
                ),
                None => String::new(),
            };
            structure.choice = format!(
                "n = {}: the smallest order whose free-run RMSE on the held-out last {:.0} % of \
                 the first estimation record (after a fit on the rest, state from its first {} \
                 samples) is within {:.0} % of the best order's ({}); then refined on the whole \
                 record{}",
                f.order,
                100.0 * config.validation_fraction,
                config.window,
                100.0 * config.order_tolerance,
                f.candidates.iter().map(held).collect::<Vec<_>>().join(", "),
                kept
            );
            structure.final_refinement_failure = f.final_refinement_failure;
            structure.label = format!("{LINEAR_SS_ROW}, n = {})", f.order);
            structure.order = Some(f.order);
            structure.candidates = f.candidates;
            structure.singular_values = f.singular_values;
            structure.poles = f.model.poles();
            (structure, Some(f.model))
        }
        Err(reason) => {
            structure.choice = format!("not fitted: {reason}");
            failures.push(Failure {
                model: structure.label.clone(),
                reason,
                at: FailedAt::Fit,
                dataset: None,
            });
            (structure, None)
        }
    }
}

/// `mmenn compare` without files: fit every model on `data` and judge each free-run on
/// the first record of `data` and of `val`. State-space models (the assumed model, the
/// given model, the output-error fit, MME/NN) are judged by the one judge (initial state
/// fitted to the first `x0_window` samples, every sample scored), the linear SS model by
/// the same rule; NARX starts from its first measured delay window, which it does not
/// score.
pub fn compute_compare(
    data: &Dataset,
    loaded: &LoadedModel,
    val: Option<&Dataset>,
    opts: &CompareOptions,
) -> Result<CompareOutcome> {
    compute_compare_with_progress(data, loaded, val, opts, &NoProgress)
}

/// [`compute_compare`], reporting each baseline's fit and the MME/NN fit (its sweep and
/// refinement step by step) to `progress`. The results do not depend on the sink.
pub fn compute_compare_with_progress(
    data: &Dataset,
    loaded: &LoadedModel,
    val: Option<&Dataset>,
    opts: &CompareOptions,
    progress: &dyn ProgressSink,
) -> Result<CompareOutcome> {
    // MME/NN needs a corrected equation: say so before the baselines run (minutes on a
    // long record), not after.
    loaded.spec.refuse_uncorrected("compare", &loaded.path)?;
    let spec = loaded.spec.clone();
    let lin = spec.linear.clone();
    let data = &data.clone().with_intersample(spec.intersample);
    let val = val.map(|v| v.clone().with_intersample(spec.intersample));
    // A model file with an acquisition filter is more than its linear part: it gets its
    // own row, judged through the filter.
    let given = (loaded.kind != ModelKind::Assumed || spec.acquisition.is_some()).then_some(loaded);
    let window = opts.fit.x0_window;
    let oe_config = OeConfig {
        free: opts.oe_free.clone().unwrap_or_else(|| default_free(&spec)),
        ..OeConfig::default()
    };
    let mut failures = Vec::new();
    // A baseline that cannot be fitted (e.g. a free parameter the data cannot identify)
    // does not stop the comparison: it has no row, and the summary says why.
    let (oe_model, oe_parameters, oe_error) =
        match stage(progress, "linear OE fit", || fit_oe(&lin, data, &oe_config)) {
            Ok(f) => {
                let mut m = f.model;
                m.observer_window = window.max(10 * lin.n_states());
                (Some(m), f.parameters, None)
            }
            Err(e) => {
                let reason = oe_failure(&spec, opts.oe_free.is_none(), &e);
                failures.push(Failure {
                    model: "linear OE".into(),
                    reason: reason.clone(),
                    at: FailedAt::Fit,
                    dataset: None,
                });
                (None, Vec::new(), Some(reason))
            }
        };
    let (ss_structure, ss_model) = fit_linear_ss_row(data, opts, window, progress, &mut failures);
    let orders = match opts.narx_lags {
        Some(l) => NarxOrders {
            na: l,
            nb: l,
            nk: 1,
        },
        None => {
            let s = suggest_lags(
                data,
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
    let narx_config = NarxConfig {
        orders,
        seed: opts.fit.seed,
        focus: opts.narx_focus,
        ..NarxConfig::default()
    };
    let (narx, narx_refinement) = match stage(progress, "NARX fit", || fit_narx(data, &narx_config))
    {
        Ok(f) => (Some(f.model), f.refinement),
        Err(e) => {
            failures.push(Failure {
                model: "NARX".into(),
                reason: with_causes(&e),
                at: FailedAt::Fit,
                dataset: None,
            });
            (None, None)
        }
    };
    let narx_training = narx_training_words(
        &narx_config,
        narx.is_some(),
        &data.output_names(),
        narx_refinement.as_ref(),
    );
    let poly_narx = opts.poly_narx.map(|choice| {
        let fitted = stage(progress, "polynomial NARX fit", || match choice.monomials {
            PolyNarxMonomials::All => fit_poly_narx(
                data,
                &PolyNarxConfig {
                    orders,
                    degree: choice.degree,
                    nonlinear_lags: choice.nonlinear_lags,
                    focus: choice.focus,
                    ..PolyNarxConfig::default()
                },
            )
            .map(|f| (f.model.n_terms(), f.rank, None, f.model)),
            PolyNarxMonomials::FrolsKfold if choice.focus != Focus::Prediction => {
                Err(sysid_baselines::BaselineError::InvalidConfig {
                    field: "polynomial NARX focus",
                    value: 1.0,
                    reason: "the FROLS K-fold model is fitted by one-step least squares with \
                             its term count chosen by free run; the simulation focus \
                             applies to the model with every monomial",
                })
            }
            PolyNarxMonomials::FrolsKfold => fit_frols_kfold(data, orders, &choice)
                .map(|(model, n, line)| (n, n, Some(line), model)),
        });
        match fitted {
            Ok((terms, rank, selection, model)) => (
                PolyNarxStructure {
                    choice,
                    orders,
                    terms: Some(terms),
                    rank: Some(rank),
                    selection,
                },
                Some(model),
            ),
            Err(e) => {
                failures.push(Failure {
                    model: POLY_NARX_ROW.into(),
                    reason: with_causes(&e),
                    at: FailedAt::Fit,
                    dataset: None,
                });
                (
                    PolyNarxStructure {
                        choice,
                        orders,
                        terms: None,
                        rank: None,
                        selection: None,
                    },
                    None,
                )
            }
        }
    });
    let (poly_structure, poly) = match poly_narx {
        Some((s, m)) => (Some(s), m),
        None => (None, None),
    };
    let fit = compute_fit(data, &spec, val.as_ref(), &opts.fit, progress)?;
    let hybrid = LoadedModel::from_hybrid(Path::new("mme_nn/model.json"), fit.model.clone())?;
    // A zero linear part is no model of anything: no row for it when the model file's
    // own dynamics have theirs (the given model's row; without one, the assumed row is
    // the only row of the model file and stays).
    let no_linear_part = given.is_some() && has_no_linear_part(&spec);
    let models = Models {
        assumed: (!no_linear_part).then_some(&lin),
        oe: oe_model.as_ref(),
        ss: ss_model.as_ref().map(|m| (m, ss_structure.label.as_str())),
        narx: narx.as_ref(),
        poly: poly.as_ref(),
        given,
        hybrid: &hybrid,
        window,
    };
    let scope = |which: &str, d: &Dataset| {
        let exp = &d.experiments()[0];
        format!(
            "free-run simulation, {which} data, first record ({} samples; state-space models: initial state fitted to the first {} samples, every sample scored)",
            exp.len(),
            window.min(exp.len())
        )
    };
    let est = judge_all("estimation", &scope("estimation", data), data, &models)?;
    // The models whose free run failed on the data the residuals are analysed on.
    let mut res_failed: Vec<String> = est.failures.iter().map(|f| f.model.clone()).collect();
    failures.extend(est.failures);
    let (validation, validation_runs, (hybrid_res, hybrid_outputs), res_data) = match &val {
        Some(v) => {
            let j = judge_all("validation", &scope("validation", v), v, &models)?;
            res_failed = j.failures.iter().map(|f| f.model.clone()).collect();
            failures.extend(j.failures);
            (
                Some(j.table),
                Some((v.experiments()[0].clone(), j.runs)),
                (j.hybrid, j.hybrid_outputs),
                v,
            )
        }
        None => (
            None,
            None,
            (est.hybrid.clone(), est.hybrid_outputs.clone()),
            data,
        ),
    };
    let ran = |label: &str| !res_failed.iter().any(|f| f == label);
    let rc = ResidualConfig::default();
    let mut assumed_oe = OeModel::new(lin.clone());
    assumed_oe.observer_window = window.max(10 * lin.n_states());
    // A model whose residual analysis fails keeps its table rows; the summary says why.
    let mut residuals = Vec::new();
    let mut residual_failures = Vec::new();
    let res_which = if val.is_some() {
        "validation"
    } else {
        "estimation"
    };
    let mut analyse = |label: &str, r: sysid_baselines::Result<ResidualAnalysis>| match r {
        Ok(a) => residuals.push((label.to_string(), a)),
        Err(e) => residual_failures.push(Failure {
            model: label.into(),
            reason: format!("on the {res_which} data: {}", with_causes(&e)),
            at: FailedAt::Residuals,
            dataset: None,
        }),
    };
    if !no_linear_part {
        analyse(
            "assumed model",
            residual_analysis(&assumed_oe, res_data, 0, Horizon::FreeRun, &rc),
        );
    }
    if let Some(oe) = &oe_model {
        analyse(
            "linear OE",
            residual_analysis(oe, res_data, 0, Horizon::FreeRun, &rc),
        );
    }
    if let Some(ss) = ss_model.as_ref().filter(|_| ran(&ss_structure.label)) {
        // The judge's window on the analysed record; the residuals skip it.
        let len = res_data.experiments()[0].len();
        let judged = LinearSsModel {
            window: window.min(len).max(1),
            ..ss.clone()
        };
        analyse(
            &ss_structure.label,
            residual_analysis(&judged, res_data, 0, Horizon::FreeRun, &rc),
        );
    }
    if let Some(narx) = narx.as_ref().filter(|_| ran("NARX")) {
        analyse(
            "NARX",
            residual_analysis(narx, res_data, 0, Horizon::FreeRun, &rc),
        );
    }
    if let Some(poly) = poly.as_ref().filter(|_| ran(POLY_NARX_ROW)) {
        analyse(
            POLY_NARX_ROW,
            residual_analysis(poly, res_data, 0, Horizon::FreeRun, &rc),
        );
    }
    // Through an acquisition filter the hybrid's residuals are those of its judged
    // (filtered) outputs; otherwise of its free run from the judged state (the same run).
    analyse(
        "MME/NN",
        if fit.model.spec()?.acquisition.is_some() {
            sysid_baselines::analyse_prediction(
                &sysid_core::Prediction {
                    horizon: Horizon::FreeRun,
                    outputs: hybrid_outputs,
                    initial_samples: 0,
                },
                res_data,
                0,
                &rc,
            )
        } else {
            residual_analysis(&hybrid_res, res_data, 0, Horizon::FreeRun, &rc)
        },
    );
    let judge_rule = format!(
        "the one free-run judge: initial state fitted by least squares to the first {window} samples (from the minimum-norm solution of C x = y(t0)), every sample scored (the rule and numbers of `mmenn predict`)"
    );
    let mut initialisation = vec![(
        "assumed model".to_string(),
        format!(
            "{}{judge_rule}",
            if no_linear_part {
                format!(
                    "no row: the model file has no linear part ({}; judged in the \
                     '{GIVEN_MODEL_ROW}' row); the rule would be ",
                    no_linear_part_words(&spec)
                )
            } else if loaded.kind == ModelKind::Assumed && spec.acquisition.is_none() {
                String::new()
            } else if loaded.kind == ModelKind::Assumed {
                format!(
                    "the model file without its acquisition filter (read through it in the \
                     '{GIVEN_MODEL_ROW}' row); "
                )
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
                "{} as read from {}: {judge_rule}{}",
                loaded.kind,
                loaded.path.display(),
                if loaded.stored_state().is_some() {
                    "; the state stored in the model is a second start of the fit"
                } else {
                    ""
                }
            ),
        ));
    }
    initialisation.push(("linear OE".to_string(), judge_rule.clone()));
    initialisation.push((
        ss_structure.label.clone(),
        format!(
            "as the state-space rows: its state (discrete time) fitted by least squares to the first {window} measured outputs (fewer on a shorter record; minimum-norm when they do not determine it), then a free run, every sample scored; its fit used the same rule with a {}-sample window",
            ss_structure.fit_window
        ),
    ));
    let delay_window = orders.na.max(orders.nb + orders.nk - 1);
    initialisation.push((
        "NARX".to_string(),
        format!(
            "the first {delay_window} measured samples seed the delay line and are skipped (NARX predicts only measured channels)"
        ),
    ));
    if opts.poly_narx.is_some() {
        initialisation.push((
            POLY_NARX_ROW.to_string(),
            format!(
                "as NARX (the same delays): starts from its first measured delay window; the first {delay_window} measured samples seed the delay line and are skipped"
            ),
        ));
    }
    initialisation.push((
        "MME/NN".to_string(),
        format!("{judge_rule}; MME's x̂(t0) of the training record (stored in mme_nn/model.json) is a second start of the fit"),
    ));
    initialisation.push((
        "residual analysis".to_string(),
        format!(
            "the assumed model and linear OE start from a least-squares state over the first {} samples, which the residuals skip; linear SS from its judged state over the first {window} samples (fewer on a shorter record), which the residuals skip; NARX and polynomial NARX as above; MME/NN from its judged initial state",
            window.max(10 * lin.n_states())
        ),
    ));
    let outputs = data.output_names();
    let mut files = vec!["mme_nn/".to_string()];
    let mut figure_files = |which: &str| {
        for name in &outputs {
            files.push(compare_figure_file(which, name));
        }
    };
    figure_files("estimation");
    if val.is_some() {
        figure_files("validation");
    }
    for (label, r) in &residuals {
        files.extend(residual_files(label, r));
    }
    files.push("compare.json".into());
    files.push("report.md".into());
    files.push("report.html".into());
    let summary = CompareSummary {
        estimation: est.table,
        validation,
        narx_orders: orders,
        narx_focus: opts.narx_focus,
        narx_refinement,
        narx_training,
        poly_narx: poly_structure,
        linear_ss: ss_structure,
        oe_parameters,
        oe_error,
        failures,
        given_model: loaded.kind,
        initialisation,
        residuals,
        residual_failures,
        files,
        validation_use: val.is_some().then_some(opts.fit.validation_use),
    };
    Ok(CompareOutcome {
        summary,
        fit,
        estimation_record: data.experiments()[0].clone(),
        estimation_runs: est.runs,
        validation_runs,
        outputs,
        units: spec.units.clone(),
    })
}

/// Write what [`compute_compare`] computed into `out`: `mme_nn/` (the fit), the compare
/// and residual figures, `compare.json` and `report.md`.
pub fn write_compare(o: &CompareOutcome, out: &Path) -> Result<()> {
    ensure_dir(out)?;
    write_fit(&o.fit, &out.join("mme_nn"))?;
    let s = &o.summary;
    compare_figures(
        "estimation",
        &o.estimation_record,
        &o.outputs,
        &o.estimation_runs,
        &s.estimation,
        &o.units,
        out,
    )?;
    if let (Some((exp, runs)), Some(tab)) = (&o.validation_runs, &s.validation) {
        compare_figures("validation", exp, &o.outputs, runs, tab, &o.units, out)?;
    }
    for (label, r) in &s.residuals {
        residual_figure(label, r, out)?;
    }
    write_atomic(
        &out.join("compare.json"),
        serde_json::to_string_pretty(s)?.as_bytes(),
    )?;
    crate::html::write_report(out, &compare_report(s))?;
    Ok(())
}

fn table_md(t: &EvaluationTable, dataset: &str, failures: &[Failure]) -> String {
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
        // A free-run failure on the other dataset leaves this table's row in place.
        if t.rows().iter().any(|r| r.label == f.model) || !f.concerns(dataset) {
            continue;
        }
        s.push_str(&format!(
            "| {} | — | {}: {} | | | |\n",
            f.model,
            f.at,
            f.reason.replace('|', "/").replace('\n', " ")
        ));
    }
    s
}

fn compare_report(s: &CompareSummary) -> String {
    let mut r = String::from(
        "# Model comparison\n\nEvery number below is **free-run simulation** (inputs only after the initial condition).\n\n",
    );
    r.push_str(&table_md(&s.estimation, "estimation", &s.failures));
    if let Some(v) = &s.validation {
        r.push('\n');
        r.push_str(&table_md(v, "validation", &s.failures));
        r.push_str(match s.validation_use {
            Some(ValidationUse::Select) => {
                "\nThe MME/NN made its choices on the validation records (`--val-use \
                 select`: the sweep's test set, early stopping, the guard); the baselines did \
                 not, so its row there is favoured.\n"
            }
            _ => {
                "\nEvery model was fitted and chosen on the estimation records; the \
                 validation records were only judged (`--val-use score`).\n"
            }
        });
    }
    if !s.failures.is_empty() {
        r.push_str("\n## Models without numbers\n\n");
        for f in &s.failures {
            r.push_str(&format!("- **{}** ({}): {}\n", f.model, f.at, f.reason));
        }
    }
    if !s.residual_failures.is_empty() {
        r.push_str("\n## Residual analyses that failed\n\n");
        for f in &s.residual_failures {
            r.push_str(&format!("- **{}**: {}\n", f.model, f.reason));
        }
    }
    r.push_str("\n## Initial conditions\n\n");
    for (m, how) in &s.initialisation {
        r.push_str(&format!("- **{m}**: {how}\n"));
    }
    r.push_str(&format!(
        "\nNARX delays: na = {}, nb = {}, nk = {}. NARX network: {}.\n\n",
        s.narx_orders.na, s.narx_orders.nb, s.narx_orders.nk, s.narx_training
    ));
    match &s.poly_narx {
        Some(p) => {
            r.push_str(&format!(
                "Polynomial NARX: the same delays, monomials of total degree up to {} in the newest {} output lags and input taps (scaled by the training record), coefficients by one-step least squares{}",
                p.choice.degree,
                p.choice.nonlinear_lags,
                match p.choice.focus {
                    Focus::Prediction => String::new(),
                    Focus::Simulation { max_iterations } => format!(
                        ", then by free-run error over the estimation data (at most {max_iterations} Levenberg–Marquardt iterations)"
                    ),
                }
            ));
            match (p.terms, p.rank, &p.selection) {
                (Some(t), _, Some(line)) => r.push_str(&format!(
                    "; sparse, the terms ranked by FROLS and their count by K-fold free run: \
                     {t} terms ({line}).\n\n"
                )),
                (Some(t), Some(k), None) => r.push_str(&format!("; {t} terms, rank {k}.\n\n")),
                _ => r.push_str(" (not fitted).\n\n"),
            }
        }
        None => r.push_str("Polynomial NARX: off.\n\n"),
    }
    let ss = &s.linear_ss;
    match ss.order {
        Some(_) => {
            let poles: Vec<String> = ss
                .poles
                .iter()
                .map(|(re, im)| {
                    if *im == 0.0 {
                        format!("{re:.4}")
                    } else {
                        format!("{re:.4}{im:+.4}i")
                    }
                })
                .collect();
            r.push_str(&format!(
                "Linear SS (black box, as `n4sid` then `pem`): PO-MOESP on the first estimation record ({} samples), then free-run output error, orders 1 to {}; chosen {}. Poles (discrete time): {}.\n\n",
                ss.samples,
                ss.max_order,
                ss.choice,
                poles.join(", ")
            ));
        }
        None => r.push_str(&format!("Linear SS: {}.\n\n", ss.choice)),
    }
    r.push_str("Output-error parameters (±1σ):\n\n");
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

#[cfg(test)]
mod tests {
    use super::*;

    /// A free-run failure is listed in its own dataset's table only (the terminal and
    /// report printed the estimation record's divergence under the validation table too);
    /// a fit failure in every table.
    #[test]
    fn a_free_run_failure_concerns_its_own_dataset_only() {
        let f = |at, dataset: Option<&str>| Failure {
            model: POLY_NARX_ROW.into(),
            reason: "diverged".into(),
            at,
            dataset: dataset.map(str::to_string),
        };
        let est = f(FailedAt::FreeRun, Some("estimation"));
        assert!(est.concerns("estimation") && !est.concerns("validation"));
        let fit = f(FailedAt::Fit, None);
        assert!(fit.concerns("estimation") && fit.concerns("validation"));
        let t = EvaluationTable::new("validation", Horizon::FreeRun);
        let md = table_md(
            &t,
            "validation",
            &[est, f(FailedAt::FreeRun, Some("validation"))],
        );
        assert_eq!(md.matches("polynomial NARX").count(), 1, "{md}");
    }

    fn spec(a: &str, b: &str, terms: bool) -> ModelSpec {
        let mut text = format!(
            "states = [\"theta\", \"omega\"]\ninputs = [\"u\"]\nA = {a}\nB = {b}\n\
             measured = [\"theta\"]\ncorrected = [\"omega\"]\nnoise_variance = [0.01]\n"
        );
        if terms {
            text.push_str(
                "\n[[terms]]\nstate = \"omega\"\neffect = \"pendulum\"\n\
                 term = \"-19.62*theta - 0.2*omega - 2*u\"\ncoefficient = 1.0\n",
            );
        }
        crate::model_file::parse_model(Path::new("m.toml"), &text).unwrap()
    }

    /// One predicate: no linear part when A and B are all zero or the file is a
    /// `[mechanics]` model; a non-zero entry anywhere (a kinematic row, a damping term in
    /// the corrected row, an input gain) is a linear part.
    #[test]
    fn no_linear_part_is_zero_a_and_b_or_mechanics() {
        let zero = spec("[[0.0, 0.0], [0.0, 0.0]]", "[[0.0], [0.0]]", true);
        assert!(has_no_linear_part(&zero));
        for (a, b) in [
            ("[[0.0, 1.0], [0.0, 0.0]]", "[[0.0], [0.0]]"),
            ("[[0.0, 0.0], [0.0, -0.1]]", "[[0.0], [0.0]]"),
            ("[[0.0, 0.0], [0.0, 0.0]]", "[[0.0], [1.0]]"),
        ] {
            assert!(!has_no_linear_part(&spec(a, b, true)), "A = {a}, B = {b}");
        }
        let rigid = crate::model_file::read_model(
            &Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/two_link/rigid_body.toml"),
        )
        .unwrap();
        assert!(rigid.mechanics.is_some());
        assert!(has_no_linear_part(&rigid));
        // The linear OE failure is explained by the same predicate, with the remedy
        // that fits the file; free parameters given by hand keep the bare error.
        let e = std::io::Error::other("singular");
        let why = oe_failure(&zero, true, &e);
        assert!(
            why.contains("A and B are zero") && why.contains("give A and B"),
            "{why}"
        );
        assert!(why.ends_with("(singular)"), "{why}");
        let why = oe_failure(&rigid, true, &e);
        assert!(
            why.contains("[mechanics] model") && !why.contains("give A and B"),
            "{why}"
        );
        assert_eq!(oe_failure(&zero, false, &e), "singular");
        let linear = spec("[[0.0, 1.0], [0.0, 0.0]]", "[[0.0], [0.0]]", true);
        assert_eq!(oe_failure(&linear, true, &e), "singular");
    }
}
