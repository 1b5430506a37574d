//! `mmenn predict`: any model mmenn writes ([`crate::model::LoadedModel`]) simulated over a
//! new record's inputs, judged by the one free-run judge ([`crate::model::judge_free_run`]:
//! initial state estimated from this record, every sample scored) on every state column
//! and every model output column the record has, and optionally k steps ahead beside it.
//! Writes `prediction.csv` (states, outputs, k-step columns), `prediction.json`, a figure
//! per judged channel and `report.md`.
//!
//! `prediction.csv` has `t`, a column per state, a column per model output that is not a
//! state, then per judged channel `<name>`: `<name>_predicted` (the free run's value that
//! is scored), `<name>_measured` and `<name>_error` (= `<name>_measured` −
//! `<name>_predicted`), then the k-step columns (`<name>_<k>step`). Compare
//! `<name>_predicted` with `<name>_measured`: a judged channel that is a state also has its
//! column `<name>`, the state itself, which is not what is scored when the model has an
//! acquisition filter.
//!
//! A model with an `[acquisition]` table ([`crate::acquisition`]) runs on the record's
//! inputs and outputs deconvolved by the filter; its states in `prediction.csv` are the
//! model's there (not filtered), its outputs (and every `<name>_predicted` column) pass
//! through the filter, and those are scored against the recorded outputs. It has no
//! k-step prediction.

use std::collections::BTreeMap;
use std::path::Path;

use nalgebra::DMatrix;
use serde::Serialize;
use sysid_core::{ChannelMetrics, Dataset, Experiment, Substeps};

use crate::atomic::{ensure_dir, write_atomic};
use crate::data_file::{Table, read_table, table_to_experiment, write_csv};
use crate::error::Result;
use crate::model::{
    FreeRunReport, InitialRule, Judgement, LoadedModel, ModelKind, Observation, ScoredWindow,
    judge_free_run, judge_k_step,
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
    /// First sample (0-based) the metrics score (`None`: every sample). The benchmark
    /// protocols score after the initialisation window: `x0_window` and `score_from` both
    /// 50 (Cascaded Tanks, Silverbox) or 20 (EMPS) reproduce `nonlinear_benchmarks`.
    pub score_from: Option<usize>,
}

impl Default for PredictOptions {
    fn default() -> Self {
        Self {
            x0: InitialChoice::Fit,
            x0_window: Some(200),
            horizon: None,
            score_from: None,
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
    /// RK4 steps per sample interval of the free run (`None`: a hybrid model's own
    /// integrator).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub substeps: Option<usize>,
    /// k-step-ahead prediction, when asked for (its own rule and scored window).
    pub k_step: Option<Judgement>,
    /// A hybrid model's network along the free run: how often it was asked outside the
    /// box its training pairs spanned, and what it did there.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub network_domain: Option<NetworkDomainReport>,
    /// Files written.
    pub files: Vec<String>,
}

/// Where a hybrid's free run took its network (`nn::NetCorrection::in_domain`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct NetworkDomainReport {
    /// What the network does outside its training box.
    pub domain: nn::Domain,
    /// Samples of the free run at which `[x; u]` lies outside the box.
    pub outside: usize,
    /// Samples of the free run.
    pub samples: usize,
}

impl NetworkDomainReport {
    /// Fraction of the free run's samples outside the box.
    pub fn fraction(&self) -> f64 {
        self.outside as f64 / self.samples.max(1) as f64
    }

    /// One sentence for people: how often, and what the network did there.
    pub fn sentence(&self) -> String {
        format!(
            "the free run asked the network outside the box of its training data at {} of {} \
             samples ({:.1} %); {}",
            self.outside,
            self.samples,
            100.0 * self.fraction(),
            match self.domain {
                nn::Domain::Hold => "held at the box's edge there",
                nn::Domain::Extrapolate => {
                    "extrapolated there (fit --hold-network-domain holds it at the edge)"
                }
            }
        )
    }

    /// The report of `model`'s network along the free-run `states` (`n × N`) driven by
    /// `exp`'s inputs, or `None` for a model without a network (a model file, or a hybrid
    /// whose guard kept physics alone: a network that is zero everywhere).
    pub fn of(model: &LoadedModel, exp: &Experiment, states: &DMatrix<f64>) -> Option<Self> {
        let file = model.hybrid.as_ref()?;
        if crate::fit::guard::is_zero_network(&file.network) {
            return None;
        }
        let corr =
            nn::NetCorrection::for_model(file.network.clone(), states.nrows(), exp.n_inputs())
                .ok()?;
        let mut x = vec![0.0; states.nrows()];
        let samples = states.ncols().min(exp.len());
        let outside = (0..samples)
            .filter(|&k| {
                for (i, v) in x.iter_mut().enumerate() {
                    *v = states[(i, k)];
                }
                !corr.in_domain(&x, exp.input(k))
            })
            .count();
        Some(Self {
            domain: file.domain,
            outside,
            samples,
        })
    }
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
        score_from: None,
    };
    run_predict_with(model, data_path, &opts, out)
}

/// Load any model mmenn writes, judge it on the record and write the results into `out`:
/// reads the files, [`compute_predict`], [`write_predict`].
pub fn run_predict_with(
    model_path: &Path,
    data_path: &Path,
    opts: &PredictOptions,
    out: &Path,
) -> Result<PredictSummary> {
    run_predict_substeps(model_path, data_path, opts, None, out)
}

/// [`run_predict_with`] with the free run's RK4 steps per sample interval stated (the
/// CLI's `--substeps`; `None`: [`default_substeps`]).
pub fn run_predict_substeps(
    model_path: &Path,
    data_path: &Path,
    opts: &PredictOptions,
    substeps: Option<Substeps>,
    out: &Path,
) -> Result<PredictSummary> {
    let model = LoadedModel::read(model_path)?;
    let table = read_table(data_path)?;
    let substeps = substeps.unwrap_or_else(|| default_substeps(&model));
    let outcome = compute_predict_with(&model, &table, opts, substeps)?;
    write_predict(&outcome, out)?;
    Ok(outcome.summary)
}

/// A model's free-run steps when none are stated: `Auto` with at least the model's own
/// RK4 count (4 for a model file), so a model that is not stiff keeps it.
pub fn default_substeps(model: &LoadedModel) -> Substeps {
    match model.integrator {
        sysid_core::Integrator::Rk4 { substeps } => Substeps::Auto { min: substeps },
        sysid_core::Integrator::DormandPrince(_) => Substeps::Auto { min: 4 },
    }
}

/// Everything `mmenn predict` computes, as values ([`write_predict`] writes it).
#[derive(Debug, Clone)]
pub struct PredictOutcome {
    /// What `prediction.json` holds.
    pub summary: PredictSummary,
    /// The record judged (inputs and the judged channels, held as the model says).
    pub record: Experiment,
    /// The judged channels.
    pub observation: Observation,
    /// The free-run judgement (states `n × N`, judged channels `p × N`).
    pub free: Judgement,
    /// What `prediction.csv` holds: `t`, every state, every output that is not a state,
    /// then per judged channel `<channel>_predicted` (the scored value),
    /// `<channel>_measured` and `<channel>_error`, then the k-step columns
    /// (`<channel>_<k>step`), as (header, values) pairs.
    pub columns: Vec<(String, Vec<f64>)>,
    /// A title for its figures (what kind of model).
    pub model_kind: ModelKind,
}

impl PredictOutcome {
    /// A column of `prediction.csv` by name.
    pub fn column(&self, name: &str) -> Option<&[f64]> {
        self.columns
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, v)| v.as_slice())
    }
}

/// `mmenn predict` without files: the model judged free-run (and k steps ahead, when
/// asked for) by the one judge on every state column and every model-output column the
/// record has.
pub fn compute_predict(
    model: &LoadedModel,
    data: &Table,
    opts: &PredictOptions,
) -> Result<PredictOutcome> {
    compute_predict_with(model, data, opts, default_substeps(model))
}

/// [`compute_predict`] with the free run's RK4 steps per sample interval stated (a model
/// file's; a hybrid model keeps its own integrator).
pub fn compute_predict_with(
    model: &LoadedModel,
    data: &Table,
    opts: &PredictOptions,
    substeps: Substeps,
) -> Result<PredictOutcome> {
    let obs = model.present(|n| data.column_index(n).is_some());
    let exp = table_to_experiment(data, model.spec.linear.input_names(), &obs.names)?;
    compute_predict_record_with(model, &exp, obs, opts, substeps)
}

/// [`compute_predict`] on the first record of a dataset in memory: judged on every state
/// and model output among its output channels. Its input channels must be the model's,
/// in order.
pub fn compute_predict_on(
    model: &LoadedModel,
    data: &Dataset,
    opts: &PredictOptions,
) -> Result<PredictOutcome> {
    let names = data.output_names();
    let inputs = data.input_names();
    if inputs.as_slice() != model.spec.linear.input_names() {
        return Err(crate::error::MmennError::Core {
            context: "the record to predict: its input channels must be the model's, in order",
            source: sysid_core::CoreError::Length {
                what: "input channels of the record vs the model",
                found: inputs.len(),
                expected: model.spec.linear.n_inputs(),
            },
        });
    }
    let obs = model.present(|n| names.iter().any(|c| c == n));
    let exp = &data.experiments()[0];
    let rows: Vec<usize> = obs
        .names
        .iter()
        .filter_map(|n| names.iter().position(|c| c == n))
        .collect();
    let outputs = exp.outputs().select_rows(rows.iter());
    let record =
        Experiment::new(exp.t0(), exp.dt(), exp.inputs().clone(), outputs).map_err(|source| {
            crate::error::MmennError::Core {
                context: "the record to predict",
                source,
            }
        })?;
    compute_predict_record(model, &record, obs, opts)
}

/// [`compute_predict`] on a record whose output rows are the channels of `obs`, in order
/// (its inputs are held between samples as the model says).
pub fn compute_predict_record(
    model: &LoadedModel,
    record: &Experiment,
    obs: Observation,
    opts: &PredictOptions,
) -> Result<PredictOutcome> {
    compute_predict_record_with(model, record, obs, opts, default_substeps(model))
}

/// [`compute_predict_record`] with the free run's RK4 steps per sample interval stated:
/// `Auto` probes the record for a stiff model (`sysid_core::stiff`), `Fixed` is taken as
/// given; a hybrid model keeps its own integrator either way.
pub fn compute_predict_record_with(
    model: &LoadedModel,
    record: &Experiment,
    obs: Observation,
    opts: &PredictOptions,
    substeps: Substeps,
) -> Result<PredictOutcome> {
    let lin = &model.spec.linear;
    let exp = record.clone().with_intersample(model.intersample());
    let rule = match &opts.x0 {
        InitialChoice::Given(x) => InitialRule::Given(x.clone()),
        InitialChoice::Fit => InitialRule::Fit {
            window: opts.x0_window,
        },
    };
    if opts.horizon.is_some() && model.acquisition().is_some() {
        return Err(crate::error::MmennError::AcquisitionKStep);
    }
    // The record the model runs on: through its acquisition filter's inverse, if it has one.
    let inner = model.record_for_model(&exp, &obs.names)?;
    let requested = substeps;
    let (mut model, mut substeps) = with_substeps(model, &inner, &obs, &rule, requested)?;
    let mut free = judge_free_run(&model, &exp, &obs, &rule)?;
    // The count is the judged start's: the first probe ran from the measured channels'
    // first values with every other state at 0, which may be a singular point of the
    // model (an unmeasured level under `sqrt` asks for the most steps there), or may need
    // fewer steps than the judged start (a stiff model, a start far from the measured
    // one). Probe the judged start and judge again with its count; if that judge's start
    // asks for still more, take it (never judge with fewer than the final start needs).
    if let (Some(s), Substeps::Auto { min }) = (substeps, requested) {
        let again = probe_count(&model, &inner, &free.x0, min)?;
        if again != s {
            model.integrator = sysid_core::Integrator::Rk4 { substeps: again };
            free = judge_free_run(&model, &exp, &obs, &rule)?;
            substeps = Some(again);
            let last = probe_count(&model, &inner, &free.x0, min)?;
            if last > again {
                model.integrator = sysid_core::Integrator::Rk4 { substeps: last };
                free = judge_free_run(&model, &exp, &obs, &rule)?;
                substeps = Some(last);
            }
        }
    }
    let model = &model;
    let mut k_step = match opts.horizon {
        Some(k) => Some(judge_k_step(model, &exp, &obs, k, &free)?),
        None => None,
    };
    if let Some(first) = opts.score_from {
        if first >= exp.len() {
            return Err(crate::error::MmennError::ScoreFromBeyondRecord {
                first,
                len: exp.len(),
            });
        }
        let rescore = |j: &mut Judgement| -> Result<()> {
            let from = first.max(j.scored.first);
            j.channels = sysid_core::score(&obs.names, &exp, &j.outputs, from)
                .map_err(core("scoring from --score-from"))?;
            j.scored = sysid_core::ScoredWindow::of(&exp, from, j.scored.end);
            Ok(())
        };
        rescore(&mut free)?;
        if let Some(ks) = k_step.as_mut() {
            rescore(ks)?;
        }
    }
    // The model's outputs as recorded: through its acquisition filter, if it has one.
    let y = match model.acquisition() {
        Some(f) => crate::acquisition::filter_rows(f, &(lin.c() * &free.states), exp.dt(), false)?,
        None => lin.c() * &free.states,
    };
    let mut columns = vec![("t".to_string(), exp.times())];
    for (i, s) in lin.state_names().iter().enumerate() {
        columns.push((s.clone(), free.states.row(i).iter().copied().collect()));
    }
    for (i, o) in lin.output_names().iter().enumerate() {
        if !lin.state_names().contains(o) {
            columns.push((o.clone(), y.row(i).iter().copied().collect()));
        }
    }
    // Per judged channel: the free run's value that is scored (through the acquisition
    // filter, if the model has one; a judged state's own column is the state itself), the
    // measured channel and the error between them (NaN where missing).
    for (i, name) in obs.names.iter().enumerate() {
        let predicted: Vec<f64> = free.outputs.row(i).iter().copied().collect();
        let measured: Vec<f64> = exp.outputs().row(i).iter().copied().collect();
        let error: Vec<f64> = measured
            .iter()
            .zip(&predicted)
            .map(|(m, p)| m - p)
            .collect();
        columns.push((format!("{name}_predicted"), predicted));
        columns.push((format!("{name}_measured"), measured));
        columns.push((format!("{name}_error"), error));
    }
    if let Some(ks) = &k_step {
        let k = opts.horizon.unwrap_or(0);
        for (i, name) in obs.names.iter().enumerate() {
            columns.push((
                format!("{name}_{k}step"),
                ks.outputs.row(i).iter().copied().collect(),
            ));
        }
    }
    let mut files = vec!["prediction.csv".to_string()];
    files.extend(obs.names.iter().map(|n| format!("prediction_{n}.svg")));
    files.push("prediction.json".into());
    files.push("report.md".into());
    files.push("report.html".into());
    let summary = PredictSummary {
        model_kind: model.kind,
        free_run: FreeRunReport::of(&free),
        scored: free.scored,
        substeps,
        k_step,
        network_domain: NetworkDomainReport::of(model, &inner, &free.states),
        files,
    };
    Ok(PredictOutcome {
        summary,
        record: exp,
        observation: obs,
        free,
        columns,
        model_kind: model.kind,
    })
}

/// The model with the RK4 count `substeps` asks for on `exp` (a model file's; a hybrid
/// model keeps its own integrator, count `None`): `Auto` probes a free run from the given
/// start, or from the measured channels' first values.
fn with_substeps(
    model: &LoadedModel,
    exp: &Experiment,
    obs: &Observation,
    rule: &InitialRule,
    substeps: Substeps,
) -> Result<(LoadedModel, Option<usize>)> {
    let mut model = model.clone();
    if model.kind == ModelKind::Hybrid {
        return Ok((model, None));
    }
    let count = match substeps.validate().map_err(core("--substeps"))? {
        Substeps::Fixed(s) => s,
        Substeps::Auto { min } => {
            let x0 = match rule {
                InitialRule::Given(x) => x.clone(),
                _ => sysid_core::measured_start(&obs.matrix, exp.output(0)),
            };
            probe_count(&model, exp, &x0, min)?
        }
    };
    model.integrator = sysid_core::Integrator::Rk4 { substeps: count };
    Ok((model, Some(count)))
}

/// [`sysid_core::probe_substeps`] of `model` on `exp` from `x0`.
fn probe_count(model: &LoadedModel, exp: &Experiment, x0: &[f64], min: usize) -> Result<usize> {
    if x0.len() != model.spec.linear.n_states() {
        return Ok(min);
    }
    sysid_core::probe_substeps(&model.dynamics, exp, x0, min, 1e12)
        .map(|p| p.substeps)
        .map_err(core("choosing the RK4 sub-steps of the free run"))
}

fn core(context: &'static str) -> impl FnOnce(sysid_core::CoreError) -> crate::error::MmennError {
    move |source| crate::error::MmennError::Core { context, source }
}

/// Write what [`compute_predict`] computed into `out`: `prediction.csv`, a figure per
/// judged channel, `prediction.json` and `report.md` (atomically, each file).
pub fn write_predict(o: &PredictOutcome, out: &Path) -> Result<()> {
    ensure_dir(out)?;
    let header: Vec<String> = o.columns.iter().map(|(n, _)| n.clone()).collect();
    let refs: Vec<&[f64]> = o.columns.iter().map(|(_, v)| v.as_slice()).collect();
    write_csv(&out.join("prediction.csv"), &header, &refs)?;
    let t = o.record.times();
    let free = &o.free;
    for (i, name) in o.observation.names.iter().enumerate() {
        let mut series = vec![
            Series::points(
                format!("{name} measured"),
                t.clone(),
                o.record
                    .outputs()
                    .row(i)
                    .iter()
                    .copied()
                    .collect::<Vec<f64>>(),
            ),
            Series::line(
                format!("free-run simulation (fit {:.1} %)", free.fit_percent(name)),
                t.clone(),
                free.outputs.row(i).iter().copied().collect::<Vec<f64>>(),
            ),
        ];
        if let Some(ks) = &o.summary.k_step {
            series.push(Series::line(
                format!("{} (fit {:.1} %)", ks.horizon, ks.fit_percent(name)),
                t.clone(),
                ks.outputs.row(i).iter().copied().collect::<Vec<f64>>(),
            ));
        }
        let fig = Figure {
            title: format!("{name}: {} on new data", o.model_kind),
            x_label: "t (s)".into(),
            y_label: name.clone(),
            series,
            bands: vec![],
        };
        fig.write(&out.join(format!("prediction_{name}.svg")))?;
    }
    write_atomic(
        &out.join("prediction.json"),
        serde_json::to_string_pretty(&o.summary)?.as_bytes(),
    )?;
    crate::html::write_report(out, &report(&o.summary))?;
    Ok(())
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

/// Which columns of `prediction.csv` the metrics compare (`report.md`).
const SCORED_COLUMNS: &str = "\nIn `prediction.csv` the metrics compare `<channel>_predicted` (the \
     free run's value that is scored; with an `[acquisition]` table, through the filter) with \
     `<channel>_measured`; `<channel>_error` is their difference. A column named by a state \
     holds the model's state (with an `[acquisition]` table, on the deconvolved record, not \
     filtered): compare `<channel>_predicted`, not `<channel>`, with the measurement.\n";

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
    if let Some(steps) = s.substeps {
        r.push_str(&format!(
            "Classical RK4, {steps} steps per sample interval.\n\n"
        ));
    }
    if s.free_run.channels.is_empty() {
        r.push_str("The record has no column of a state or model output to compare with.\n");
    } else {
        r.push_str(&table(&s.free_run.channels));
        r.push_str(SCORED_COLUMNS);
    }
    if let Some(d) = &s.network_domain {
        r.push_str(&format!("\nNetwork: {}.\n", d.sentence()));
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
