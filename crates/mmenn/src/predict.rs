//! `mmenn predict`: any model mmenn writes ([`crate::model::LoadedModel`]) simulated over a
//! new record's inputs, judged by the one free-run judge ([`crate::model::judge_free_run`]:
//! initial state estimated from this record, every sample scored) on every state column
//! and every model output column the record has, and optionally k steps ahead beside it.
//! Writes `prediction.csv` (states, outputs, k-step columns), `prediction.json`, a figure
//! per judged channel and `report.md`.

use std::collections::BTreeMap;
use std::path::Path;

use serde::Serialize;
use sysid_core::{ChannelMetrics, Horizon};

use crate::atomic::{ensure_dir, write_atomic};
use crate::data_file::{read_table, table_to_experiment, write_csv};
use crate::error::Result;
use crate::fit::FreeRunReport;
use crate::model::{
    InitialRule, Judgement, LoadedModel, ModelKind, Observation, ScoredWindow, judge_free_run,
    judge_k_step,
};
use crate::plot::{Figure, Series};

/// How `mmenn predict` gets its initial state.
#[derive(Debug, Clone, PartialEq, Default)]
pub enum InitialChoice {
    /// Fit it to the first samples of the record's judged channels (see
    /// [`crate::model`] for the rule).
    #[default]
    Fit,
    /// Use this state.
    Given(Vec<f64>),
}

/// Options of [`run_predict_with`].
#[derive(Debug, Clone, PartialEq)]
pub struct PredictOptions {
    /// Initial state.
    pub x0: InitialChoice,
    /// Samples the initial-state fit uses (`None`: the whole record). Default 200.
    pub x0_window: Option<usize>,
    /// k of a k-step-ahead prediction beside the free run (`None`: free run only).
    pub horizon: Option<usize>,
}

impl Default for PredictOptions {
    fn default() -> Self {
        Self {
            x0: InitialChoice::Fit,
            x0_window: Some(200),
            horizon: None,
        }
    }
}

/// What `mmenn predict` reports (`prediction.json`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PredictSummary {
    /// Which kind of model was read.
    pub model_kind: ModelKind,
    /// Free-run simulation: the initial state, its rule and metrics per judged channel
    /// (states by name, then model outputs).
    pub free_run: FreeRunReport,
    /// The samples the free-run metrics score.
    pub scored: ScoredWindow,
    /// k-step-ahead prediction, when asked for (its own rule and scored window).
    pub k_step: Option<Judgement>,
    /// Files written.
    pub files: Vec<String>,
}

/// [`run_predict_with`] with free run only, the initial-state fit over `window` samples.
pub fn run_predict(
    model: &Path,
    data_path: &Path,
    x0: &InitialChoice,
    window: usize,
    out: &Path,
) -> Result<PredictSummary> {
    let opts = PredictOptions {
        x0: x0.clone(),
        x0_window: Some(window),
        horizon: None,
    };
    run_predict_with(model, data_path, &opts, out)
}

/// Load any model mmenn writes, judge it on the record and write the results into `out`.
pub fn run_predict_with(
    model_path: &Path,
    data_path: &Path,
    opts: &PredictOptions,
    out: &Path,
) -> Result<PredictSummary> {
    let model = LoadedModel::read(model_path)?;
    let table = read_table(data_path)?;
    let obs = Observation::present(&model, |n| table.column_index(n).is_some());
    let lin = &model.spec.linear;
    let exp = table_to_experiment(&table, lin.input_names(), &obs.names)?
        .with_intersample(model.intersample());
    let rule = match &opts.x0 {
        InitialChoice::Given(x) => InitialRule::Given(x.clone()),
        InitialChoice::Fit => InitialRule::Fit {
            window: opts.x0_window,
        },
    };
    let free = judge_free_run(&model, &exp, &obs, &rule)?;
    let k_step = match opts.horizon {
        Some(k) => Some(judge_k_step(&model, &exp, &obs, k, &free)?),
        None => None,
    };
    ensure_dir(out)?;
    let mut files = Vec::new();

    // prediction.csv: t, every state, every output that is not a state, k-step columns.
    let t = exp.times();
    let y = lin.c() * &free.states;
    let mut header = vec!["t".to_string()];
    let mut cols: Vec<Vec<f64>> = Vec::new();
    for (i, s) in lin.state_names().iter().enumerate() {
        header.push(s.clone());
        cols.push(free.states.row(i).iter().copied().collect());
    }
    for (i, o) in lin.output_names().iter().enumerate() {
        if !lin.state_names().contains(o) {
            header.push(o.clone());
            cols.push(y.row(i).iter().copied().collect());
        }
    }
    if let Some(ks) = &k_step {
        let k = opts.horizon.unwrap_or(0);
        for (i, name) in obs.names.iter().enumerate() {
            header.push(format!("{name}_{k}step"));
            cols.push(ks.outputs.row(i).iter().copied().collect());
        }
    }
    let mut refs: Vec<&[f64]> = vec![&t];
    refs.extend(cols.iter().map(Vec::as_slice));
    write_csv(&out.join("prediction.csv"), &header, &refs)?;
    files.push("prediction.csv".to_string());

    for (i, name) in obs.names.iter().enumerate() {
        let fit = |j: &Judgement| j.channels.get(name).map_or(f64::NAN, |m| m.fit_percent);
        let mut series = vec![
            Series::points(
                format!("{name} measured"),
                t.clone(),
                exp.outputs().row(i).iter().copied().collect(),
            ),
            Series::line(
                format!("free-run simulation (fit {:.1} %)", fit(&free)),
                t.clone(),
                free.outputs.row(i).iter().copied().collect(),
            ),
        ];
        if let Some(ks) = &k_step {
            series.push(Series::line(
                format!("{} (fit {:.1} %)", ks.horizon, fit(ks)),
                t.clone(),
                ks.outputs.row(i).iter().copied().collect(),
            ));
        }
        let fig = Figure {
            title: format!("{name}: {} on new data", model.kind),
            x_label: "t (s)".into(),
            y_label: name.clone(),
            series,
            bands: vec![],
        };
        let file = format!("prediction_{name}.svg");
        fig.write(&out.join(&file))?;
        files.push(file);
    }
    files.push("prediction.json".into());
    files.push("report.md".into());
    files.push("report.html".into());
    let summary = PredictSummary {
        model_kind: model.kind,
        free_run: FreeRunReport {
            horizon: Horizon::FreeRun,
            x0: free.x0.clone(),
            x0_source: free.x0_rule.clone(),
            channels: free.channels.clone(),
        },
        scored: free.scored,
        k_step,
        files,
    };
    write_atomic(
        &out.join("prediction.json"),
        serde_json::to_string_pretty(&summary)?.as_bytes(),
    )?;
    crate::html::write_report(out, &report(&summary))?;
    Ok(summary)
}

fn table(channels: &BTreeMap<String, ChannelMetrics>) -> String {
    let mut s = String::from(
        "| channel | fit % | R² | RMSE | error variance | samples |\n|---|---|---|---|---|---|\n",
    );
    for (n, m) in channels {
        s.push_str(&format!(
            "| {n} | {:.2} | {:.5} | {:.4e} | {:.4e} | {} |\n",
            m.fit_percent, m.r2, m.rmse, m.error_variance, m.samples
        ));
    }
    s
}

fn report(s: &PredictSummary) -> String {
    let mut r = format!("# Prediction on new data\n\nModel: {}.\n\n", s.model_kind);
    r.push_str(&format!(
        "## {} — samples {}..{} (t = {} … {} s)\n\nInitial state x0 = {}: {}.\n\n",
        s.free_run.horizon,
        s.scored.first,
        s.scored.end,
        s.scored.t_first,
        s.scored.t_last,
        crate::words::numbers(&s.free_run.x0),
        s.free_run.x0_source
    ));
    if s.free_run.channels.is_empty() {
        r.push_str("The record has no column of a state or model output to compare with.\n");
    } else {
        r.push_str(&table(&s.free_run.channels));
    }
    if let Some(k) = &s.k_step {
        r.push_str(&format!(
            "\n## {} — samples {}..{} (t = {} … {} s)\n\n{}.\n\n",
            k.horizon,
            k.scored.first,
            k.scored.end,
            k.scored.t_first,
            k.scored.t_last,
            k.k_step_rule.as_deref().unwrap_or("")
        ));
        r.push_str(&table(&k.channels));
    }
    r.push_str(crate::words::METRICS_MEANING);
    r.push_str(&crate::html::figures_section(&s.files));
    r
}
