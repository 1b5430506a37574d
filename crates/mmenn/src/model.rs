//! One loader for every model mmenn writes, one in-memory model that simulates itself, and
//! one free-run judge.
//!
//! [`LoadedModel::read`] tells the formats apart by content: text whose first non-blank
//! character is `{` is `fit`'s hybrid `model.json` (format tag [`crate::fit::HYBRID_FORMAT`]);
//! anything else is read as a model-file TOML (an assumed model, with or without
//! `[[terms]]`, e.g. `discover`'s `model.discovered.toml`). Either way the result simulates
//! itself free-run, the inputs between samples as the model's `intersample` says.
//!
//! [`judge_free_run`] is the one free-run evaluation of a loaded model on a record, used by
//! `predict` and by `compare`'s model-file row, so the same model on the same record gets
//! the same numbers in both. Its rule (stated in every report it feeds):
//!
//! - **initial state**: the `x0` minimising the squared error of the judged channels over
//!   the first `window` samples of the record (Levenberg–Marquardt,
//!   [`sysid_core::fit_initial_state`]; every sample when `window` is `None`), started from
//!   the minimum-norm solution of `C x = y(t0)` and, for a model that stores a state (a
//!   hybrid model's training `x̂(t0)`), also from that state, keeping the fit with the
//!   smaller squared error over the window (the stored state on a tie);
//! - **scored window**: every sample of the record (the fitting window is not skipped),
//!   missing measurements skipped;
//! - **metrics**: fit %, R², RMSE and error variance per judged channel.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use nalgebra::{DMatrix, DVector};
use serde::Serialize;
use sysid_core::{
    ChannelMetrics, Dynamics, Experiment, Horizon, InitialStateFit, Integrator, InterSample,
    TermModel, channel_metrics, fit_initial_state, simulate_with,
};

use crate::error::{MmennError, ModelProblem, Result};
use crate::fit::{HybridFile, HybridModel};
use crate::model_file::{ModelSpec, parse_model};

/// Which of mmenn's model files a model came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ModelKind {
    /// A model-file TOML without named terms: the linear assumed model.
    Assumed,
    /// A model-file TOML with `[[terms]]` (e.g. `discover`'s `model.discovered.toml`).
    WithTerms,
    /// `fit`'s `model.json`: the model file plus a network correction.
    Hybrid,
}

impl std::fmt::Display for ModelKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            ModelKind::Assumed => "assumed model (model file, no terms)",
            ModelKind::WithTerms => "model file with named terms",
            ModelKind::Hybrid => "MME/NN hybrid model (model.json)",
        })
    }
}

/// The right-hand side of a loaded model.
#[derive(Debug, Clone)]
#[allow(clippy::large_enum_variant)] // one per loaded model: size does not matter
pub enum ModelDynamics {
    /// Linear model plus named terms (no terms: the linear model).
    Terms(TermModel),
    /// Linear model plus named terms plus a network correction.
    Hybrid(HybridModel),
}

impl Dynamics for ModelDynamics {
    fn n_states(&self) -> usize {
        match self {
            ModelDynamics::Terms(m) => m.n_states(),
            ModelDynamics::Hybrid(m) => m.n_states(),
        }
    }
    fn n_inputs(&self) -> usize {
        match self {
            ModelDynamics::Terms(m) => m.n_inputs(),
            ModelDynamics::Hybrid(m) => m.n_inputs(),
        }
    }
    fn rhs(&self, t: f64, x: &[f64], u: &[f64], dx: &mut [f64]) {
        match self {
            ModelDynamics::Terms(m) => m.rhs(t, x, u, dx),
            ModelDynamics::Hybrid(m) => m.rhs(t, x, u, dx),
        }
    }
    fn jacobians(&self, t: f64, x: &[f64], u: &[f64], a: &mut DMatrix<f64>, b: &mut DMatrix<f64>) {
        match self {
            ModelDynamics::Terms(m) => m.jacobians(t, x, u, a, b),
            ModelDynamics::Hybrid(m) => m.jacobians(t, x, u, a, b),
        }
    }
}

/// Any model mmenn writes, in memory.
#[derive(Debug, Clone)]
pub struct LoadedModel {
    /// Where it was read from (or a description when built in memory).
    pub path: PathBuf,
    /// Which file format it came from.
    pub kind: ModelKind,
    /// The model-file part: names, units, `C`, terms, `intersample`.
    pub spec: ModelSpec,
    /// The right-hand side.
    pub dynamics: ModelDynamics,
    /// Integrator of its free runs (a hybrid model's own RK4 sub-steps; RK4 with 4
    /// sub-steps for a model file).
    pub integrator: Integrator,
    /// The hybrid file, for a hybrid model.
    pub hybrid: Option<HybridFile>,
}

/// Bound on simulated states beyond which a free run counts as diverged.
const BLOW_UP: f64 = 1e12;

fn model_error(path: &Path, problem: ModelProblem) -> MmennError {
    MmennError::Model {
        path: path.to_path_buf(),
        line: None,
        column: None,
        problem,
    }
}

fn core(context: &'static str) -> impl FnOnce(sysid_core::CoreError) -> MmennError {
    move |source| MmennError::Core { context, source }
}

impl LoadedModel {
    /// Read any model mmenn writes (see the module documentation for how the format is
    /// told apart). Errors name the file and, for syntax errors, line and column.
    pub fn read(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|source| MmennError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        Self::parse(path, &text)
    }

    /// Parse a model's text (`path` only names it in errors).
    pub fn parse(path: &Path, text: &str) -> Result<Self> {
        let body = text.trim_start_matches('\u{feff}').trim_start();
        if body.is_empty() {
            return Err(model_error(
                path,
                ModelProblem::NotAModel {
                    why: "the file is empty".into(),
                },
            ));
        }
        if body.starts_with('{') {
            let file = HybridFile::parse(path, text)?;
            Self::from_hybrid(path, file)
        } else if body.starts_with('t') && body.lines().next().is_some_and(|l| l.contains(',')) {
            Err(model_error(
                path,
                ModelProblem::NotAModel {
                    why: "its first line looks like a CSV header (a data file, not a model)".into(),
                },
            ))
        } else {
            Self::from_spec(path, parse_model(path, text)?)
        }
    }

    /// A model-file model (assumed, or with named terms).
    pub fn from_spec(path: &Path, spec: ModelSpec) -> Result<Self> {
        let terms = spec.term_model().map_err(|p| model_error(path, p))?;
        Ok(Self {
            path: path.to_path_buf(),
            kind: if spec.terms.is_empty() {
                ModelKind::Assumed
            } else {
                ModelKind::WithTerms
            },
            spec,
            dynamics: ModelDynamics::Terms(terms),
            integrator: Integrator::Rk4 { substeps: 4 },
            hybrid: None,
        })
    }

    /// A hybrid model from its parsed `model.json`.
    pub fn from_hybrid(path: &Path, file: HybridFile) -> Result<Self> {
        let spec = file.spec()?;
        let model = file.model()?;
        Ok(Self {
            path: path.to_path_buf(),
            kind: ModelKind::Hybrid,
            spec,
            integrator: model.integrator,
            dynamics: ModelDynamics::Hybrid(model),
            hybrid: Some(file),
        })
    }

    /// How its free runs treat the inputs between samples.
    pub fn intersample(&self) -> InterSample {
        self.spec.intersample
    }

    /// The state the file stores (a hybrid model's training `x̂(t0)`), if any.
    pub fn stored_state(&self) -> Option<&[f64]> {
        self.hybrid.as_ref().map(|h| h.x0.as_slice())
    }

    /// Free-run states (`n × N`) over `exp`'s inputs from `x0`, the inputs between samples
    /// as the model says.
    pub fn simulate_states(&self, x0: &[f64], exp: &Experiment) -> Result<DMatrix<f64>> {
        simulate_with(
            &self.dynamics,
            x0,
            exp.t0(),
            exp.dt(),
            exp.inputs(),
            self.intersample(),
            &self.integrator,
            BLOW_UP,
        )
        .map_err(core("free-run simulation of the model"))
    }
}

/// Which channels a judgement scores: names and the rows mapping the state to them
/// (`p × n`), in the order of the record's output rows.
#[derive(Debug, Clone, PartialEq)]
pub struct Observation {
    /// Channel names.
    pub names: Vec<String>,
    /// `p × n` map from the state to the channels.
    pub matrix: DMatrix<f64>,
}

impl Observation {
    /// The model's outputs (`C` and its output names).
    pub fn outputs(model: &LoadedModel) -> Self {
        let lin = &model.spec.linear;
        Self {
            names: lin.output_names().to_vec(),
            matrix: lin.c().clone(),
        }
    }

    /// The channels a data file can be compared on: every state present by name, then
    /// every model output present by name that is not also a state name.
    pub fn present(model: &LoadedModel, has_column: impl Fn(&str) -> bool) -> Self {
        let lin = &model.spec.linear;
        let n = lin.n_states();
        let mut names = Vec::new();
        let mut rows: Vec<Vec<f64>> = Vec::new();
        for (i, s) in lin.state_names().iter().enumerate() {
            if has_column(s) {
                names.push(s.clone());
                rows.push((0..n).map(|j| if i == j { 1.0 } else { 0.0 }).collect());
            }
        }
        for (i, o) in lin.output_names().iter().enumerate() {
            if has_column(o) && !lin.state_names().contains(o) {
                names.push(o.clone());
                rows.push(lin.c().row(i).iter().copied().collect());
            }
        }
        let matrix = DMatrix::from_fn(rows.len(), n, |r, c| rows[r][c]);
        Self { names, matrix }
    }
}

/// How the free-run judge gets its initial state.
#[derive(Debug, Clone, PartialEq, Default)]
pub enum InitialRule {
    /// Fitted to the first `window` samples of the record (`None`: every sample).
    Fit {
        /// Samples from the start of the record used in the fit.
        window: Option<usize>,
    },
    /// This state.
    Given(Vec<f64>),
    /// The judge's default: fitted to the first 200 samples.
    #[default]
    Default,
}

impl InitialRule {
    fn window(&self) -> Option<usize> {
        match self {
            InitialRule::Fit { window } => *window,
            InitialRule::Default => Some(200),
            InitialRule::Given(_) => None,
        }
    }
}

/// The samples a judgement scored.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ScoredWindow {
    /// First scored sample (0-based).
    pub first: usize,
    /// One past the last scored sample.
    pub end: usize,
    /// Time of the first scored sample, s.
    pub t_first: f64,
    /// Time of the last scored sample, s.
    pub t_last: f64,
}

/// One model judged on one record.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Judgement {
    /// Free-run simulation, or k-step prediction.
    pub horizon: Horizon,
    /// Initial state of the free run.
    pub x0: Vec<f64>,
    /// The initial-state rule, in words.
    pub x0_rule: String,
    /// The samples scored.
    pub scored: ScoredWindow,
    /// How a k-step prediction was started (absent for free run).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub k_step_rule: Option<String>,
    /// Metrics per judged channel.
    pub channels: BTreeMap<String, ChannelMetrics>,
    /// Simulated states (`n × N`; for k-step, the free-run states its starts use).
    #[serde(skip)]
    pub states: DMatrix<f64>,
    /// Predicted channels (`p × N`, NaN where a k-step prediction has no value).
    #[serde(skip)]
    pub outputs: DMatrix<f64>,
}

impl Judgement {
    /// As an evaluation-table row.
    pub fn evaluation(&self, names: &[String]) -> sysid_baselines::Evaluation {
        sysid_baselines::Evaluation {
            horizon: self.horizon,
            channels: names
                .iter()
                .filter_map(|n| {
                    self.channels
                        .get(n)
                        .map(|m| sysid_baselines::ChannelEvaluation {
                            name: n.clone(),
                            metrics: *m,
                        })
                })
                .collect(),
            initial_samples: self.scored.first,
        }
    }
}

/// The minimum-norm solution of `C x = y(t0)` over the channels measured at `t0` (zero
/// when none is).
fn initial_guess(model: &LoadedModel, obs: &Observation, exp: &Experiment) -> Vec<f64> {
    let n = model.spec.linear.n_states();
    let y = exp.output(0);
    let rows: Vec<usize> = (0..obs.names.len()).filter(|&i| !y[i].is_nan()).collect();
    if rows.is_empty() {
        return vec![0.0; n];
    }
    let c = DMatrix::from_fn(rows.len(), n, |r, j| obs.matrix[(rows[r], j)]);
    let rhs = DVector::from_iterator(rows.len(), rows.iter().map(|&i| y[i]));
    match c.svd(true, true).solve(&rhs, 1e-12) {
        Ok(x) if x.iter().all(|v| v.is_finite()) => x.iter().copied().collect(),
        _ => vec![0.0; n],
    }
}

/// Squared output error of the free response from `x0` over the fit's window.
fn window_cost(
    model: &LoadedModel,
    obs: &Observation,
    exp: &Experiment,
    x0: &[f64],
    fit: &InitialStateFit,
) -> sysid_core::Result<f64> {
    let len = fit.window.min(exp.len());
    let u = exp.inputs().columns(0, len).into_owned();
    let xs = simulate_with(
        &model.dynamics,
        x0,
        exp.t0(),
        exp.dt(),
        &u,
        model.intersample(),
        &fit.integrator,
        fit.blow_up,
    )?;
    let y = &obs.matrix * xs;
    let mut cost = 0.0;
    for k in 0..len {
        for (i, m) in exp.output(k).iter().enumerate() {
            if !m.is_nan() {
                cost += (m - y[(i, k)]).powi(2);
            }
        }
    }
    Ok(if cost.is_finite() {
        cost
    } else {
        f64::INFINITY
    })
}

/// No starting point was tried (cannot happen: the minimum-norm start always is).
fn unreachable_start() -> Result<(Vec<f64>, &'static str)> {
    Err(MmennError::Core {
        context: "fitting the initial state to the record",
        source: sysid_core::CoreError::InvalidArgument {
            name: "starting points",
            value: 0.0,
            reason: "no starting point for the initial-state fit",
        },
    })
}

fn metrics(
    obs: &Observation,
    exp: &Experiment,
    predicted: &DMatrix<f64>,
    first: usize,
) -> Result<BTreeMap<String, ChannelMetrics>> {
    let mut out = BTreeMap::new();
    for (i, name) in obs.names.iter().enumerate() {
        let measured: Vec<f64> = exp.outputs().row(i).iter().skip(first).copied().collect();
        let sim: Vec<f64> = predicted.row(i).iter().skip(first).copied().collect();
        out.insert(
            name.clone(),
            channel_metrics(&measured, &sim).map_err(core("judging the model"))?,
        );
    }
    Ok(out)
}

fn check_rows(obs: &Observation, exp: &Experiment) -> Result<()> {
    if obs.matrix.nrows() != exp.n_outputs() || obs.names.len() != exp.n_outputs() {
        return Err(MmennError::Core {
            context: "judging the model",
            source: sysid_core::CoreError::Length {
                what: "judged channels vs the record's output rows",
                found: obs.names.len(),
                expected: exp.n_outputs(),
            },
        });
    }
    Ok(())
}

/// The one free-run judge (rule in the module documentation): initial state by `rule`,
/// free run over the whole record, every sample scored. `exp`'s output rows are the
/// channels of `obs`, in order.
pub fn judge_free_run(
    model: &LoadedModel,
    exp: &Experiment,
    obs: &Observation,
    rule: &InitialRule,
) -> Result<Judgement> {
    check_rows(obs, exp)?;
    let n = model.spec.linear.n_states();
    let exp = &exp.clone().with_intersample(model.intersample());
    let (x0, x0_rule) = match rule {
        InitialRule::Given(x) => {
            if x.len() != n || x.iter().any(|v| !v.is_finite()) {
                return Err(MmennError::Core {
                    context: "the given initial state",
                    source: sysid_core::CoreError::Length {
                        what: "initial state (finite numbers, one per state)",
                        found: x.len(),
                        expected: n,
                    },
                });
            }
            (x.clone(), "given".to_string())
        }
        _ if obs.names.is_empty() => {
            let x = model.stored_state().map_or(vec![0.0; n], <[f64]>::to_vec);
            let why = if model.stored_state().is_some() {
                "the training record's x̂(t0) stored in the model: the record has no channel to fit it to"
            } else {
                "zero: the record has no channel to fit it to"
            };
            (x, why.to_string())
        }
        _ => {
            let window = rule.window().unwrap_or(exp.len()).clamp(1, exp.len());
            let fit = InitialStateFit {
                window,
                integrator: model.integrator,
                blow_up: BLOW_UP,
                ..InitialStateFit::default()
            };
            let mut starts = Vec::new();
            if let Some(x) = model.stored_state() {
                starts.push((x.to_vec(), "the state stored in the model"));
            }
            starts.push((
                initial_guess(model, obs, exp),
                "the minimum-norm solution of C x = y(t0)",
            ));
            let mut best: Option<(Vec<f64>, f64, &str)> = None;
            let mut first_error = None;
            for (guess, label) in starts {
                match fit_initial_state(&model.dynamics, &obs.matrix, exp, &guess, &fit)
                    .and_then(|x| window_cost(model, obs, exp, &x, &fit).map(|c| (x, c)))
                {
                    Ok((x, cost)) if best.as_ref().is_none_or(|b| cost < b.1) => {
                        best = Some((x, cost, label));
                    }
                    Ok(_) => {}
                    Err(e) => {
                        first_error.get_or_insert(e);
                    }
                }
            }
            let (x, start) = match (best, first_error) {
                (Some((x, _, label)), _) => (x, label),
                (None, Some(e)) => return Err(core("fitting the initial state to the record")(e)),
                (None, None) => unreachable_start()?,
            };
            (
                x,
                format!(
                    "least-squares fit of the free response to the first {window} of {} samples ({}), started from {start}",
                    exp.len(),
                    obs.names.join(", ")
                ),
            )
        }
    };
    let states = model.simulate_states(&x0, exp)?;
    let outputs = &obs.matrix * &states;
    let channels = if obs.names.is_empty() {
        BTreeMap::new()
    } else {
        metrics(obs, exp, &outputs, 0)?
    };
    Ok(Judgement {
        horizon: Horizon::FreeRun,
        x0,
        x0_rule,
        scored: ScoredWindow {
            first: 0,
            end: exp.len(),
            t_first: exp.t0(),
            t_last: exp.time(exp.len() - 1),
        },
        k_step_rule: None,
        channels,
        states,
        outputs,
    })
}

/// k-step-ahead prediction beside a free run (`free`, from [`judge_free_run`] on the same
/// record): the prediction of sample `j` starts at sample `j − k` from the free-run state
/// there with every state a judged channel measures directly (a row selecting that one
/// state) replaced by its measurement, and simulates `k` samples. Samples `k..N` are
/// scored.
pub fn judge_k_step(
    model: &LoadedModel,
    exp: &Experiment,
    obs: &Observation,
    k: usize,
    free: &Judgement,
) -> Result<Judgement> {
    check_rows(obs, exp)?;
    let len = exp.len();
    if k == 0 || k >= len {
        return Err(MmennError::Core {
            context: "k-step prediction",
            source: sysid_core::CoreError::InvalidArgument {
                name: "horizon",
                value: k as f64,
                reason: "must be at least 1 and shorter than the record",
            },
        });
    }
    let exp = &exp.clone().with_intersample(model.intersample());
    let n = model.spec.linear.n_states();
    // Channels that measure one state directly: (row, state).
    let direct: Vec<(usize, usize)> = (0..obs.names.len())
        .filter_map(|i| {
            let row = obs.matrix.row(i);
            let nz: Vec<usize> = (0..n).filter(|&j| row[j] != 0.0).collect();
            (nz.len() == 1 && (row[nz[0]] - 1.0).abs() <= 0.0).then(|| (i, nz[0]))
        })
        .collect();
    let mut outputs = DMatrix::from_element(obs.names.len(), len, f64::NAN);
    for j in k..len {
        let start = j - k;
        let mut x: Vec<f64> = free.states.column(start).iter().copied().collect();
        let y = exp.output(start);
        for &(row, state) in &direct {
            if !y[row].is_nan() {
                x[state] = y[row];
            }
        }
        let u = exp.inputs().columns(start, k + 1).into_owned();
        let xs = simulate_with(
            &model.dynamics,
            &x,
            exp.time(start),
            exp.dt(),
            &u,
            model.intersample(),
            &model.integrator,
            BLOW_UP,
        )
        .map_err(core("k-step prediction"))?;
        let yk = &obs.matrix * xs.column(k);
        outputs.column_mut(j).copy_from(&yk);
    }
    let names: Vec<String> = direct.iter().map(|&(r, _)| obs.names[r].clone()).collect();
    Ok(Judgement {
        horizon: Horizon::Steps(k),
        x0: free.x0.clone(),
        x0_rule: free.x0_rule.clone(),
        scored: ScoredWindow {
            first: k,
            end: len,
            t_first: exp.time(k),
            t_last: exp.time(len - 1),
        },
        k_step_rule: Some(format!(
            "each sample predicted {k} samples ahead from the free-run state {k} samples earlier, with the directly measured states ({}) reset to their measurements there",
            if names.is_empty() {
                "none".to_string()
            } else {
                names.join(", ")
            }
        )),
        channels: metrics(obs, exp, &outputs, k)?,
        states: free.states.clone(),
        outputs,
    })
}
