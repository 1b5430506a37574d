//! `mmenn greyest`: grey-box parameter estimation of a physical model file (what MATLAB's
//! `nlgreyest` does). The free parameters of `[parameters]` (within their bounds) and the
//! start state of every record are calibrated by free-run output error weighted by the
//! model's noise variances, optionally after a multiple-shooting solve
//! ([`sysid_core::greybox`]). Writes `model.toml` (the same model with the estimates and
//! their `sigma`, which `mmenn show` prints), `greyest.json` (estimates, σ, correlations,
//! start states, the solver reports, fit per output and record) and `report.md`.
//!
//! Each record is judged twice, by predict's code ([`PredictCheck`]): from the calibrated
//! start state (the fit the estimate was made for) and as `mmenn predict` judges the written
//! model by default, with a warning when the second is much worse ([`START_RELIANCE`]).
//!
//! With [`GreyestOptions::starts`] above 0 the estimation also runs from that many seeded
//! starts and keeps the lowest final cost, listing every start, the distinct minima and an
//! identifiability warning when another minimum is nearly as good with materially
//! different parameters ([`multistart`]).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::Serialize;
use sysid_core::{
    ActiveBound, Estimation, Experiment, GreyboxData, GreyboxFit, GreyboxOptions, PhysicalModel,
    Shooting, Substeps, estimate_parameters_with,
};

use crate::atomic::{ensure_dir, write_atomic};
use crate::data_file::{read_table, table_to_experiment};
use crate::error::{MmennError, ModelProblem, Result};
use crate::model::{LoadedModel, ModelDynamics};
use crate::model_file::{ModelSpec, NoiseVariance, format_model};
use crate::predict::{InitialChoice, PredictOptions};
use crate::progress::{NoProgress, Progress, ProgressSink};

pub mod multistart;

pub use multistart::MultiStart;

/// Options of [`run_greyest`].
#[derive(Debug, Clone, PartialEq)]
pub struct GreyestOptions {
    /// Multiple-shooting segment length in samples before the free run (`None`: free
    /// run only).
    pub segment: Option<usize>,
    /// RK4 steps per sample interval: `Auto { min: 2 }` (the default, the CLI's
    /// `--substeps auto`) takes two, or as many as a stiff model needs along each record
    /// (`sysid_core::stiff`); `Fixed(n)` exactly `n`.
    pub substeps: sysid_core::Substeps,
    /// Most Levenberg–Marquardt iterations per solve. Default 100.
    pub max_iterations: usize,
    /// The job's budget (default unlimited; the CLI's `--budget SECONDS`): the estimate
    /// stops with `CoreError::BudgetExhausted` once it is spent.
    pub budget: sysid_core::Budget,
    /// Where the calibration starts named states of every record's initial state (the
    /// CLI's `--x0 NAME=VALUE`); the other states start from the minimum-norm solution of
    /// `C x = y(t0)`. For an unmeasured state whose default start (0) is a singular point
    /// of a term, e.g. a level under `sqrt`. Default none.
    pub x0_start: Vec<(String, f64)>,
    /// Seeded starts besides the model file's own (the CLI's `--starts N`). Default 0:
    /// the file's start only. Start `k` (1..=`starts`) draws each free parameter from
    /// `ChaCha8Rng::seed_from_u64(seed + k)`: a non-zero start value `v` becomes
    /// `v·exp(0.7·z)`, `z ~ N(0, 1)`, sign kept; a zero one uniform within its bounds
    /// when both are finite, else `s·z` on its allowed side with `s` the magnitude of the
    /// file's own start's estimate of it (or its σ; 0 when neither is usable); a draw outside its bounds (or on one) moves halfway
    /// between `v` and that bound. Every start runs the same estimation; the lowest final
    /// free-run cost is kept (ties: the lower index, the file's own start being 0); a start
    /// that fails is listed with its error ([`multistart`]).
    pub starts: usize,
    /// Seed of the seeded starts (the CLI's `--seed S`). Default 1.
    pub seed: u64,
}

impl Default for GreyestOptions {
    fn default() -> Self {
        Self {
            segment: None,
            substeps: sysid_core::Substeps::Auto { min: 2 },
            max_iterations: 100,
            budget: sysid_core::Budget::default(),
            x0_start: Vec::new(),
            starts: 0,
            seed: 1,
        }
    }
}

/// One parameter in `greyest.json`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ParameterSummary {
    /// Name.
    pub name: String,
    /// Unit, as the model file gives it.
    pub unit: Option<String>,
    /// Value the solve started from.
    pub start: f64,
    /// Estimate.
    pub value: f64,
    /// Standard deviation (`null`: on a bound or not identifiable).
    pub sigma: Option<f64>,
    /// Bounds, if any.
    pub bounds: Option<(f64, f64)>,
    /// `"lower"` or `"upper"` when the estimate sits on that bound;
    /// [`FIXED_BY_EQUAL_BOUNDS`] when its bounds are equal (a free parameter held at that
    /// value, not estimated).
    pub active_bound: Option<&'static str>,
}

/// `active_bound` of a free parameter whose bounds are equal (`bounds = [v, v]`): held at
/// `v`, neither estimated nor on one side of an interval.
pub const FIXED_BY_EQUAL_BOUNDS: &str = "fixed_by_equal_bounds";

impl ParameterSummary {
    /// Where it is held, in words, when it sits on a bound: "on its lower bound", "on its
    /// upper bound", or "fixed by equal bounds" (`report.md` and the terminal).
    pub fn held(&self) -> Option<String> {
        self.active_bound.map(|b| {
            if b == FIXED_BY_EQUAL_BOUNDS {
                "fixed by equal bounds".to_string()
            } else {
                format!("on its {b} bound")
            }
        })
    }
}

/// One record in `greyest.json`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RecordSummary {
    /// The data file.
    pub file: String,
    /// Samples.
    pub samples: usize,
    /// Estimated start state by state name.
    pub x0: BTreeMap<String, f64>,
    /// Its σ by state name (`null` where not identifiable).
    pub x0_sigma: BTreeMap<String, Option<f64>>,
    /// Free-run fit % per output.
    pub fit_percent: BTreeMap<String, f64>,
    /// RK4 steps per sample interval of its final free run (more than the minimum where
    /// the model is stiff along this record).
    pub substeps: usize,
    /// Free-run RMSE per output from the calibrated start state (the output's unit; the
    /// free run `fit_percent` scores).
    pub rmse: BTreeMap<String, f64>,
    /// The estimated model judged on this record as `mmenn predict --model model.toml`
    /// judges it by default: start state fitted to the first samples, not calibrated
    /// with the parameters (`null` when that free run fails; see `as_predict_error`).
    pub as_predict: Option<PredictCheck>,
    /// Why the free run judged as `mmenn predict` judges it failed, when it did.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub as_predict_error: Option<String>,
}

/// The estimated model judged on an estimation record by `mmenn predict`'s default rule
/// ([`crate::predict::PredictOptions::default`]), so that `greyest` and `predict` give one
/// number for one model on one record. Beside the calibrated-start fit it shows how much
/// the fit owes to a start state calibrated together with the parameters: for a model
/// with an integrating state (a position driven by a force), that start can absorb a
/// drift the model does not explain.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PredictCheck {
    /// How the start state was obtained (predict's rule, in words).
    pub x0_rule: String,
    /// The start state predict fitted, by state name.
    pub x0: BTreeMap<String, f64>,
    /// RK4 steps per sample interval of predict's free run (its `auto`).
    pub substeps: Option<usize>,
    /// Free-run fit % per output.
    pub fit_percent: BTreeMap<String, f64>,
    /// Free-run RMSE per output (the output's unit).
    pub rmse: BTreeMap<String, f64>,
}

/// The predict-judged RMSE above this multiple of the calibrated-start RMSE is flagged in
/// the report and on the terminal (the fit leans on its calibrated start state).
pub const START_RELIANCE: f64 = 1.5;

impl RecordSummary {
    /// The outputs whose predict-judged RMSE exceeds [`START_RELIANCE`] × the
    /// calibrated-start RMSE, with the ratio.
    pub fn leans_on_start(&self) -> Vec<(String, f64)> {
        let Some(p) = &self.as_predict else {
            return Vec::new();
        };
        self.rmse
            .iter()
            .filter_map(|(k, &cal)| {
                let judged = *p.rmse.get(k)?;
                let ratio = judged / cal;
                (cal > 0.0 && ratio.is_finite() && ratio > START_RELIANCE)
                    .then(|| (k.clone(), ratio))
            })
            .collect()
    }
}

/// One solve in `greyest.json`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StageSummary {
    /// `"multiple shooting"` or `"free run"`.
    pub shooting: String,
    /// Residuals.
    pub residuals: usize,
    /// Quantities estimated.
    pub estimated: usize,
    /// Why it stopped, in words.
    pub termination: String,
    /// Whether it converged.
    pub converged: bool,
    /// Iterations (Jacobians formed).
    pub iterations: usize,
    /// Weighted cost `Σ r²` at the start.
    pub initial_cost: f64,
    /// Weighted cost at the end.
    pub final_cost: f64,
}

/// What `greyest.json` holds.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct GreyestSummary {
    /// The model file read.
    pub model: String,
    /// How the residuals were weighted.
    pub weighting: String,
    /// Free parameters, in the model's order.
    pub parameters: Vec<ParameterSummary>,
    /// Names of the rows and columns of `correlation`.
    pub correlation_names: Vec<String>,
    /// Correlations of the free parameters (`null` for one without σ).
    pub correlation: Vec<Vec<Option<f64>>>,
    /// Per record: start state, fit.
    pub records: Vec<RecordSummary>,
    /// The solves, in order (the last is the free run the estimates come from).
    pub stages: Vec<StageSummary>,
    /// `s² = Σ r²/(N − P)` of the final free run (1 when the noise variances are right
    /// and the model explains the data; the σ are scaled by it).
    pub residual_variance_ratio: f64,
    /// Rank of the normalised `JᵀJ` and its number of columns.
    pub rank: (usize, usize),
    /// Files written.
    pub files: Vec<String>,
    /// The starts, their minima and the identifiability warnings (`--starts N`; absent
    /// from `greyest.json` without it).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub multi_start: Option<MultiStart>,
}

/// Everything `mmenn greyest` computes ([`write_greyest`] writes it).
#[derive(Debug, Clone)]
pub struct GreyestOutcome {
    /// What `greyest.json` holds.
    pub summary: GreyestSummary,
    /// The model file with the estimates and their σ.
    pub spec: ModelSpec,
    /// The estimator's result.
    pub fit: GreyboxFit<PhysicalModel>,
    /// The records it was estimated on, in order (for the figures).
    pub records: Vec<Experiment>,
}

impl GreyestOutcome {
    /// A parameter's summary by name.
    pub fn parameter(&self, name: &str) -> Option<&ParameterSummary> {
        self.summary.parameters.iter().find(|p| p.name == name)
    }
}

fn core(context: &'static str) -> impl FnOnce(sysid_core::CoreError) -> MmennError {
    move |source| MmennError::Core { context, source }
}

/// The physical model of a loaded model file; any other kind is an error naming the file.
fn physical_of(model: &LoadedModel) -> Result<&PhysicalModel> {
    match &model.dynamics {
        ModelDynamics::Physical(m) => Ok(m),
        _ => Err(MmennError::Model {
            path: model.path.clone(),
            line: None,
            column: None,
            problem: ModelProblem::MissingKey {
                key: "parameters",
                why: "grey-box estimation calibrates the free parameters of a [parameters] \
                      table",
            },
        }),
    }
}

/// Read the model and data files, [`compute_greyest`], [`write_greyest`] into `out`.
pub fn run_greyest(
    model_path: &Path,
    data: &[PathBuf],
    opts: &GreyestOptions,
    out: &Path,
    progress: &dyn ProgressSink,
) -> Result<GreyestOutcome> {
    let names: Vec<String> = data.iter().map(|p| p.display().to_string()).collect();
    run_greyest_named(model_path, data, &names, opts, out, progress)
}

/// [`run_greyest`] with the records named `names` in the summary and report (e.g. the
/// file the user gave, where `data` are copies prepared from it with `--map`).
pub fn run_greyest_named(
    model_path: &Path,
    data: &[PathBuf],
    names: &[String],
    opts: &GreyestOptions,
    out: &Path,
    progress: &dyn ProgressSink,
) -> Result<GreyestOutcome> {
    let model = LoadedModel::read(model_path)?;
    physical_of(&model)?;
    model.refuse_x0_prior("greyest")?;
    let mut records = Vec::with_capacity(data.len());
    for p in data {
        let table = read_table(p)?;
        let exp = table_to_experiment(
            &table,
            model.spec.linear.input_names(),
            model.spec.linear.output_names(),
        )?;
        records.push(exp.with_intersample(model.spec.intersample));
    }
    let mut outcome = compute_greyest(&model, &records, names, opts, progress)?;
    write_greyest(&mut outcome, out)?;
    Ok(outcome)
}

/// [`compute_greyest`] without progress.
pub fn compute_greyest_quietly(
    model: &LoadedModel,
    records: &[Experiment],
    names: &[String],
    opts: &GreyestOptions,
) -> Result<GreyestOutcome> {
    compute_greyest(model, records, names, opts, &NoProgress)
}

/// Calibrate `model` (a physical model file) on `records` (outputs in the model's output
/// order, named `names` in the summary).
pub fn compute_greyest(
    model: &LoadedModel,
    records: &[Experiment],
    names: &[String],
    opts: &GreyestOptions,
    progress: &dyn ProgressSink,
) -> Result<GreyestOutcome> {
    model.spec.refuse_acquisition("greyest", &model.path)?;
    let physical = physical_of(model)?;
    let lin = &model.spec.linear;
    let (variances, weighting) = match &model.spec.noise_variance {
        NoiseVariance::Given(v) => (
            v.clone(),
            "each output's error divided by its noise σ (noise_variance of the model file)"
                .to_owned(),
        ),
        NoiseVariance::Auto => (
            vec![1.0; lin.n_outputs()],
            "unweighted (noise_variance = \"auto\": give the variances to weight the \
             outputs; σ are scaled by the residual variance either way)"
                .to_owned(),
        ),
    };
    let gopts = GreyboxOptions {
        substeps: opts.substeps,
        shooting: opts
            .segment
            .map_or(Shooting::FreeRun, |segment| Shooting::Multiple { segment }),
        max_iterations: opts.max_iterations,
        budget: opts.budget.clone(),
        ..GreyboxOptions::default()
    };
    // Start states: the minimum-norm C x = y(t0), with the states named in `x0_start` set.
    let mut set = Vec::with_capacity(opts.x0_start.len());
    for (name, value) in &opts.x0_start {
        let Some(i) = lin.state_names().iter().position(|s| s == name) else {
            return Err(MmennError::UnknownState {
                option: "--x0",
                name: name.clone(),
                states: lin.state_names().join(", "),
            });
        };
        set.push((i, *value));
    }
    let starts: Vec<Vec<f64>> = if set.is_empty() {
        Vec::new()
    } else {
        records
            .iter()
            .map(|r| {
                let y0: Vec<f64> = r.output(0).to_vec();
                let mut x = sysid_core::measured_start(lin.c(), &y0);
                for &(i, v) in &set {
                    x[i] = v;
                }
                x
            })
            .collect()
    };
    let data = GreyboxData {
        c: lin.c(),
        noise_variance: &variances,
        records,
        x0: &starts,
    };
    let (fit, multi_start) = if opts.starts == 0 {
        let mut observer = |stage: &str, k: usize, cost: f64| {
            progress.report(
                &Progress::new(format!("grey-box estimation ({stage})"), k, None)
                    .with_note(format!("cost {cost:.4e}")),
            );
        };
        let fit = estimate_parameters_with(physical, &data, &gopts, &mut observer)
            .map_err(core("grey-box estimation"));
        progress.finish("grey-box estimation (multiple shooting)");
        progress.finish("grey-box estimation (free run)");
        (fit?, None)
    } else {
        let (fit, starts) =
            multistart::run(physical, &data, &gopts, opts.starts, opts.seed, progress)
                .map_err(core("grey-box estimation"))?;
        (fit, Some(starts))
    };

    let mut spec = model.spec.clone();
    for est in &fit.parameters {
        if let Some(entry) = spec.parameters.iter_mut().find(|p| p.name == est.name) {
            entry.value = est.value;
            entry.sigma = est.sigma;
        }
    }
    let unit_of = |name: &str| {
        spec.parameters
            .iter()
            .find(|p| p.name == name)
            .and_then(|p| p.unit.clone())
    };
    let parameters = fit
        .parameters
        .iter()
        .map(|p| ParameterSummary {
            name: p.name.clone(),
            unit: unit_of(&p.name),
            start: p.start,
            value: p.value,
            sigma: p.sigma,
            bounds: (p.lower.is_finite() || p.upper.is_finite()).then_some((p.lower, p.upper)),
            // Equal bounds hold the parameter at its value (sysid-core keeps it out of the
            // solver and marks it `Fixed`).
            active_bound: p.active_bound.map(|b| match b {
                ActiveBound::Lower => "lower",
                ActiveBound::Upper => "upper",
                ActiveBound::Fixed => FIXED_BY_EQUAL_BOUNDS,
            }),
        })
        .collect();
    let finite = |v: f64| v.is_finite().then_some(v);
    let nf = fit.parameters.len();
    let correlation = (0..nf)
        .map(|a| (0..nf).map(|b| finite(fit.correlation[(a, b)])).collect())
        .collect();
    let states = lin.state_names();
    let outputs = lin.output_names();
    // One judge: each record's free run scored by predict's code, from the calibrated start
    // (the numbers `fit_percent` comes from) and by predict's default rule.
    let loaded = LoadedModel::from_spec(&model.path, spec.clone())?;
    let checks: Vec<(
        BTreeMap<String, f64>,
        std::result::Result<PredictCheck, String>,
    )> = records
        .iter()
        .enumerate()
        .map(|(r, exp)| judged_as_predict(&loaded, exp, &fit.x0[r], fit.substeps[r]))
        .collect();
    let records_out = records
        .iter()
        .zip(checks)
        .enumerate()
        .map(|(r, (exp, (rmse, check)))| RecordSummary {
            file: names
                .get(r)
                .cloned()
                .unwrap_or_else(|| format!("record {r}")),
            samples: exp.len(),
            x0: states
                .iter()
                .cloned()
                .zip(fit.x0[r].iter().copied())
                .collect(),
            x0_sigma: states
                .iter()
                .cloned()
                .zip(fit.x0_sigma[r].iter().map(|v| finite(*v)))
                .collect(),
            fit_percent: outputs
                .iter()
                .cloned()
                .zip(fit.fit_percent[r].iter().copied())
                .collect(),
            substeps: fit.substeps[r],
            rmse,
            as_predict_error: check.as_ref().err().cloned(),
            as_predict: check.ok(),
        })
        .collect();
    let stages = fit
        .stages
        .iter()
        .map(|s| {
            // The solver's verdict (sysid-core's grey-box estimation asks for it): a solve
            // that never moved from a start where the data do not determine every quantity
            // is a start at a stationary point (e.g. an unmeasured state at a term's
            // singular point, sqrt(0)), not an estimate.
            let stuck = s.report.termination == sysid_core::Termination::NoProgress;
            let (rank, of) = s.report.rank.unwrap_or(fit.rank);
            StageSummary {
                shooting: match s.shooting {
                    Shooting::FreeRun => "free run".into(),
                    Shooting::Multiple { segment } => {
                        format!("multiple shooting ({segment}-sample segments)")
                    }
                },
                residuals: s.residuals,
                estimated: s.estimated,
                termination: if stuck {
                    format!(
                        "stopped where it started (not converged): the cost did not move and \
                         the data determine only {rank} of the {of} estimated quantities there — a \
                         start at a stationary point, e.g. an unmeasured state at a term's \
                         singular point such as sqrt(0); start it elsewhere (--x0 NAME=VALUE)"
                    )
                } else if s.report.termination == sysid_core::Termination::NoDescent
                    && !s.report.stationary()
                {
                    format!(
                        "stopped: no damped step lowered the cost although the gradient is not \
                         small there (largest cosine between a Jacobian column and the \
                         residual {:.1e}, stationary at most {:.0e}): the Jacobian may not \
                         describe the residuals (not converged)",
                        s.report.gradient_cosine.unwrap_or(f64::NAN),
                        sysid_core::STATIONARY_COSINE
                    )
                } else {
                    crate::words::termination(Some(s.report.termination)).to_owned()
                },
                // No damped step lowering the cost at a point where the gradient is at
                // rounding level is a stationary point, not a failure.
                converged: s.report.stationary(),
                iterations: s.report.iterations,
                initial_cost: s.report.initial_cost,
                final_cost: s.report.final_cost(),
            }
        })
        .collect();
    let summary = GreyestSummary {
        model: model.path.display().to_string(),
        weighting,
        parameters,
        correlation_names: fit.parameters.iter().map(|p| p.name.clone()).collect(),
        correlation,
        records: records_out,
        stages,
        residual_variance_ratio: fit.residual_variance_ratio,
        rank: fit.rank,
        files: Vec::new(),
        multi_start,
    };
    Ok(GreyestOutcome {
        summary,
        spec,
        fit,
        records: records.to_vec(),
    })
}

/// The calibrated-start RMSE per output (empty if predict's code cannot run that free
/// run, which the estimator just ran) and the record judged by predict's default rule.
fn judged_as_predict(
    model: &LoadedModel,
    exp: &Experiment,
    x0: &[f64],
    substeps: usize,
) -> (
    BTreeMap<String, f64>,
    std::result::Result<PredictCheck, String>,
) {
    let rmse_of = |o: &crate::predict::PredictOutcome| -> BTreeMap<String, f64> {
        o.summary
            .free_run
            .channels
            .iter()
            .map(|(k, m)| (k.clone(), m.rmse))
            .collect()
    };
    let calibrated = crate::predict::compute_predict_record_with(
        model,
        exp,
        model.outputs(),
        &PredictOptions {
            x0: InitialChoice::Given(x0.to_vec()),
            x0_window: None,
            horizon: None,
            score_from: None,
        },
        Substeps::Fixed(substeps),
    )
    .map(|o| rmse_of(&o))
    .unwrap_or_default();
    let judged = crate::predict::compute_predict_record(
        model,
        exp,
        model.outputs(),
        &PredictOptions::default(),
    )
    .map(|o| PredictCheck {
        x0_rule: o.summary.free_run.x0_source.clone(),
        x0: model
            .spec
            .linear
            .state_names()
            .iter()
            .cloned()
            .zip(o.summary.free_run.x0.iter().copied())
            .collect(),
        substeps: o.summary.substeps,
        fit_percent: o
            .summary
            .free_run
            .channels
            .iter()
            .map(|(k, m)| (k.clone(), m.fit_percent))
            .collect(),
        rmse: rmse_of(&o),
    })
    .map_err(|e| e.to_string());
    (calibrated, judged)
}

/// The figure of record `k` (1-based in its name): each output measured and simulated
/// free-run from the calibrated start (the estimator's final free run), over the
/// residual; none when the record has no final free run of its length.
fn record_figure(outcome: &GreyestOutcome, k: usize) -> Option<crate::plot::Panels> {
    let exp = outcome.records.get(k)?;
    let states = outcome.fit.states.get(k)?;
    let lin = &outcome.spec.linear;
    let names = lin.output_names();
    let labels: Vec<String> = names
        .iter()
        .enumerate()
        .map(|(i, name)| {
            let fit = outcome
                .fit
                .fit_percent
                .get(k)
                .and_then(|f| f.get(i))
                .copied()
                .unwrap_or(f64::NAN);
            format!("{name} free run from the calibrated start (fit {fit:.2} %)")
        })
        .collect();
    let file = outcome
        .summary
        .records
        .get(k)
        .map_or_else(String::new, |r| format!(" ({})", r.file));
    crate::plot::Panels::outputs_with_residuals(
        format!("grey-box estimate, record {}{file}", k + 1),
        names,
        &outcome.spec.units,
        exp,
        &(lin.c() * states),
        &labels,
    )
    .ok()
}

/// Write `model.toml`, `greyest.json`, `report.md`, `report.html` and a figure per record
/// (`greyest_record_K.svg`: measured and simulated outputs over the residual) into `out`
/// (atomically, each).
pub fn write_greyest(outcome: &mut GreyestOutcome, out: &Path) -> Result<()> {
    ensure_dir(out)?;
    let mut figures = Vec::new();
    for k in 0..outcome.records.len() {
        if let Some(panels) = record_figure(outcome, k) {
            let name = format!("greyest_record_{}.svg", k + 1);
            panels.write(&out.join(&name))?;
            figures.push(name);
        }
    }
    let mut files: Vec<String> = ["model.toml", "greyest.json", "report.md", "report.html"]
        .iter()
        .map(|f| (*f).to_owned())
        .collect();
    files.extend(figures.iter().cloned());
    outcome.summary.files = files;
    write_atomic(
        &out.join("model.toml"),
        format!(
            "# Grey-box estimate by `mmenn greyest` (see greyest.json, report.md): free \
             parameters with their sigma.\n{}",
            format_model(&outcome.spec)?
        )
        .as_bytes(),
    )?;
    let json = serde_json::to_string_pretty(&outcome.summary).map_err(|e| MmennError::Io {
        path: out.join("greyest.json"),
        source: std::io::Error::other(e),
    })?;
    write_atomic(&out.join("greyest.json"), json.as_bytes())?;
    let markdown = report(outcome) + &crate::html::figures_section(&figures);
    crate::html::write_report(out, &markdown)?;
    Ok(())
}

fn number(v: f64) -> String {
    crate::show::number(v)
}

/// `q 97.14 % (RMSE 2.36e-3 m)` per output.
pub fn fit_words(
    fit: &BTreeMap<String, f64>,
    rmse: &BTreeMap<String, f64>,
    spec: &ModelSpec,
) -> String {
    fit.iter()
        .map(|(k, v)| match rmse.get(k) {
            Some(e) => {
                let unit = spec.unit_of(k).map(|u| format!(" {u}")).unwrap_or_default();
                format!("{k} {v:.2} % (RMSE {e:.4e}{unit})")
            }
            None => format!("{k} {v:.2} %"),
        })
        .collect::<Vec<_>>()
        .join(", ")
}

/// The record judged as `mmenn predict` judges it, and the warning when the calibrated
/// start carries the fit (report and terminal).
pub fn predict_lines(r: &RecordSummary, spec: &ModelSpec) -> Vec<String> {
    let mut lines = Vec::new();
    match (&r.as_predict, &r.as_predict_error) {
        (Some(p), _) => {
            let steps = p
                .substeps
                .map(|n| format!(", {n} RK4 steps per sample"))
                .unwrap_or_default();
            lines.push(format!(
                "as `mmenn predict` judges it (start state by its default rule: {}{steps}): {}",
                p.x0_rule,
                fit_words(&p.fit_percent, &p.rmse, spec)
            ));
        }
        (None, Some(e)) => lines.push(format!(
            "as `mmenn predict` judges it (its default start-state rule): the free run failed: {e}"
        )),
        (None, None) => {}
    }
    let leans = r.leans_on_start();
    if !leans.is_empty() {
        let which: Vec<String> = leans
            .iter()
            .map(|(k, ratio)| format!("{ratio:.1}× for {k}"))
            .collect();
        lines.push(format!(
            "the fit leans on its calibrated start state: from a start fitted to the \
             record's first samples the free-run RMSE is {} the calibrated start's. That \
             start was estimated together with the parameters and can absorb what the \
             model does not explain (with an integrating state such as a position, a \
             drift); `mmenn predict` cannot calibrate it on new records, so expect its \
             numbers there, not these",
            which.join(", ")
        ));
    }
    lines
}

/// The short report.
pub fn report(outcome: &GreyestOutcome) -> String {
    let s = &outcome.summary;
    let mut md = String::from("# Grey-box parameter estimate\n\n");
    md.push_str(&format!(
        "Model `{}`; free parameters and the start state of every record calibrated by \
         free-run output error ({}), Levenberg–Marquardt with exact sensitivities.\n\n",
        s.model, s.weighting
    ));
    md.push_str(
        "| parameter | start | estimate | ±σ | unit | bounds |\n|---|---|---|---|---|---|\n",
    );
    for p in &s.parameters {
        let sigma = match (p.sigma, p.held()) {
            (Some(v), _) => format!("±{}", number(v)),
            (None, Some(held)) => format!("— ({held})"),
            (None, None) => "— (not identifiable)".into(),
        };
        let bounds = p.bounds.map_or("—".into(), |(lo, hi)| {
            format!("[{}, {}]", number(lo), number(hi))
        });
        md.push_str(&format!(
            "| {} | {} | {} | {} | {} | {} |\n",
            p.name,
            number(p.start),
            number(p.value),
            sigma,
            p.unit.as_deref().unwrap_or(""),
            bounds
        ));
    }
    let fixed: Vec<&str> = outcome
        .spec
        .parameters
        .iter()
        .filter(|p| p.estimation == Estimation::Fixed)
        .map(|p| p.name.as_str())
        .collect();
    if !fixed.is_empty() {
        md.push_str(&format!("\nFixed: {}.\n", fixed.join(", ")));
    }
    md.push_str(&format!(
        "\nσ from the Gauss–Newton covariance scaled by the residual variance ratio s² = {} \
         (rank {} of {}); residuals of sampled data are rarely white, so they are \
         optimistic.\n",
        number(s.residual_variance_ratio),
        s.rank.0,
        s.rank.1
    ));
    let unidentified: Vec<&str> = s
        .parameters
        .iter()
        .filter(|p| p.sigma.is_none() && p.active_bound.is_none())
        .map(|p| p.name.as_str())
        .collect();
    if !unidentified.is_empty() {
        md.push_str(&format!(
            "\n**Not identifiable from these records**: {} (JᵀJ has rank {} of {}: only \
             combinations of them are pinned down, and their values above are one point of \
             a valley). Fix some of them at known values (e.g. weighed masses) and estimate \
             the rest.\n",
            unidentified.join(", "),
            s.rank.0,
            s.rank.1
        ));
    }
    let nf = s.correlation_names.len();
    let mut strong = Vec::new();
    for a in 0..nf {
        for b in a + 1..nf {
            if let Some(r) = s.correlation[a][b]
                && r.abs() > 0.9
            {
                strong.push(format!(
                    "{}–{} {:+.3}",
                    s.correlation_names[a], s.correlation_names[b], r
                ));
            }
        }
    }
    md.push_str(&if strong.is_empty() {
        "No pair of estimates is correlated beyond ±0.9 (greyest.json has the matrix).\n".into()
    } else {
        format!(
            "Strongly correlated (|r| > 0.9; the data pin down a combination): {}.\n",
            strong.join(", ")
        )
    });
    md.push_str("\n## Solves\n\n| solve | residuals | estimated | iterations | cost start | cost end | ended |\n|---|---|---|---|---|---|---|\n");
    for st in &s.stages {
        md.push_str(&format!(
            "| {} | {} | {} | {} | {} | {} | {} |\n",
            st.shooting,
            st.residuals,
            st.estimated,
            st.iterations,
            number(st.initial_cost),
            number(st.final_cost),
            st.termination
        ));
    }
    md.push_str("\n## Free-run fit (estimation records)\n\n");
    for r in &s.records {
        md.push_str(&format!(
            "- `{}` ({} samples, {} RK4 steps per sample), from the calibrated start x0 = \
             {}: {}\n",
            r.file,
            r.samples,
            r.substeps,
            r.x0.iter()
                .map(|(k, v)| format!("{k} {}", number(*v)))
                .collect::<Vec<_>>()
                .join(", "),
            fit_words(&r.fit_percent, &r.rmse, &outcome.spec)
        ));
        for line in predict_lines(r, &outcome.spec) {
            md.push_str(&format!("  - {line}\n"));
        }
    }
    md.push_str(
        "\nThese are fits on the records the parameters were estimated on; judge the \
         model on other records with `mmenn predict --model model.toml` (its default \
         rule is the second line of each record above).\n",
    );
    if let Some(ms) = &s.multi_start {
        md.push_str(&ms.markdown());
    }
    md
}
