//! One loader for every model mmenn writes, one in-memory model that simulates itself, and
//! one free-run judge.
//!
//! [`LoadedModel::read`] tells the formats apart by content: text whose first non-blank
//! character is `{` is `fit`'s hybrid `model.json` (format tag [`crate::hybrid::HYBRID_FORMAT`]);
//! anything else is read as a model-file TOML (an assumed model, with or without
//! `[[terms]]`, e.g. `discover`'s `model.discovered.toml`). Either way the result simulates
//! itself free-run, the inputs between samples as the model's `intersample` says.
//!
//! [`judge_free_run`] runs the one free-run judge of `sysid-core`
//! ([`sysid_core::judge`]) on a loaded model, used by `fit`, `predict` and `compare`, so
//! the same model on the same record gets the same numbers in each. Its rule (stated in
//! every report it feeds):
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
//!
//! A model whose file has an `[acquisition]` table ([`crate::acquisition`]) is judged
//! through it: the record's inputs and outputs pass through the filter's inverse, the
//! initial state is fitted and the model run on that record, and the simulated channels
//! pass through the filter before they are scored against the *recorded* outputs.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use nalgebra::DMatrix;
use serde::Serialize;
use sysid_core::{
    ChannelMetrics, Dynamics, Experiment, Horizon, Integrator, InterSample, JudgeOptions,
    PhysicalModel, TermModel, simulate_experiment, simulate_with,
};
pub use sysid_core::{InitialRule, Judgement, Observation, ScoredWindow};

use crate::error::{MmennError, ModelProblem, Result};
use crate::hybrid::{HybridFile, HybridModel};
use crate::model_file::{ModelSpec, parse_model_and_prior};

/// Free-run metrics of a model per judged channel of one record, by the one judge
/// ([`judge_free_run`]).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FreeRunReport {
    /// Always free-run simulation.
    pub horizon: Horizon,
    /// Initial state used.
    pub x0: Vec<f64>,
    /// How the initial state was obtained (the judge's rule, in words).
    pub x0_source: String,
    /// The samples scored.
    pub scored: ScoredWindow,
    /// Metrics per channel present in the data.
    pub channels: BTreeMap<String, ChannelMetrics>,
}

impl FreeRunReport {
    /// The report of a free-run judgement.
    pub fn of(j: &Judgement) -> Self {
        Self {
            horizon: j.horizon,
            x0: j.x0.clone(),
            x0_source: j.x0_rule.clone(),
            scored: j.scored,
            channels: j.channels.clone(),
        }
    }
}

/// Which of mmenn's model files a model came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ModelKind {
    /// A model-file TOML without named terms: the linear assumed model.
    Assumed,
    /// A model-file TOML with `[[terms]]` (e.g. `discover`'s `model.discovered.toml`).
    WithTerms,
    /// A model-file TOML with `[parameters]` or a `[mechanics]` (mass-matrix) part.
    Physical,
    /// `fit`'s `model.json`: the model file plus a network correction.
    Hybrid,
}

impl std::fmt::Display for ModelKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            ModelKind::Assumed => "assumed model (model file, no terms)",
            ModelKind::WithTerms => "model file with named terms",
            ModelKind::Physical => {
                "physical model file (named parameters; terms, or the mass-matrix form of \
                 [mechanics])"
            }
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
    /// Named parameters, terms and an optional mass-matrix part.
    Physical(PhysicalModel),
}

impl Dynamics for ModelDynamics {
    fn n_states(&self) -> usize {
        match self {
            ModelDynamics::Terms(m) => m.n_states(),
            ModelDynamics::Hybrid(m) => m.n_states(),
            ModelDynamics::Physical(m) => m.n_states(),
        }
    }
    fn n_inputs(&self) -> usize {
        match self {
            ModelDynamics::Terms(m) => m.n_inputs(),
            ModelDynamics::Hybrid(m) => m.n_inputs(),
            ModelDynamics::Physical(m) => m.n_inputs(),
        }
    }
    fn rhs(&self, t: f64, x: &[f64], u: &[f64], dx: &mut [f64]) {
        match self {
            ModelDynamics::Terms(m) => m.rhs(t, x, u, dx),
            ModelDynamics::Hybrid(m) => m.rhs(t, x, u, dx),
            ModelDynamics::Physical(m) => m.rhs(t, x, u, dx),
        }
    }
    fn jacobians(&self, t: f64, x: &[f64], u: &[f64], a: &mut DMatrix<f64>, b: &mut DMatrix<f64>) {
        match self {
            ModelDynamics::Terms(m) => m.jacobians(t, x, u, a, b),
            ModelDynamics::Hybrid(m) => m.jacobians(t, x, u, a, b),
            ModelDynamics::Physical(m) => m.jacobians(t, x, u, a, b),
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
    /// The model file's `[x0_prior]` table (empty without one, and for a hybrid
    /// `model.json`), which only `estimate` applies.
    pub x0_prior: Vec<mme_core::StatePrior>,
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
            let (spec, x0_prior) = parse_model_and_prior(path, text)?;
            let mut model = Self::from_spec(path, spec)?;
            model.x0_prior = x0_prior;
            Ok(model)
        }
    }

    /// A model-file model (assumed, or with named terms).
    pub fn from_spec(path: &Path, spec: ModelSpec) -> Result<Self> {
        let (kind, dynamics) = if spec.is_physical() {
            let model = spec.physical_model().map_err(|p| model_error(path, p))?;
            (ModelKind::Physical, ModelDynamics::Physical(model))
        } else {
            let terms = spec.term_model().map_err(|p| model_error(path, p))?;
            let kind = if spec.terms.is_empty() {
                ModelKind::Assumed
            } else {
                ModelKind::WithTerms
            };
            (kind, ModelDynamics::Terms(terms))
        };
        Ok(Self {
            path: path.to_path_buf(),
            kind,
            spec,
            dynamics,
            integrator: Integrator::Rk4 { substeps: 4 },
            hybrid: None,
            x0_prior: Vec::new(),
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
            x0_prior: Vec::new(),
        })
    }

    /// Refuse a model file with an `[x0_prior]` table for a step that does not apply it
    /// (every step but `estimate`).
    pub fn refuse_x0_prior(&self, what: &'static str) -> Result<()> {
        if self.x0_prior.is_empty() {
            Ok(())
        } else {
            Err(model_error(&self.path, ModelProblem::PriorUnread { what }))
        }
    }

    /// How its free runs treat the inputs between samples.
    pub fn intersample(&self) -> InterSample {
        self.spec.intersample
    }

    /// The filter the records' channels share (`[acquisition]`), if the model has one.
    pub fn acquisition(&self) -> Option<&sysid_core::acquisition::AcquisitionFilter> {
        self.spec.acquisition.as_ref()
    }

    /// `exp` as the model runs on it: through the acquisition filter's inverse (inputs and
    /// outputs, named `outputs` in errors) when the model has one, else as it is.
    pub fn record_for_model(&self, exp: &Experiment, outputs: &[String]) -> Result<Experiment> {
        match self.acquisition() {
            Some(f) => crate::acquisition::deconvolved(f, exp, outputs),
            None => Ok(exp.clone()),
        }
    }

    /// The state the file stores (a hybrid model's training `x̂(t0)`), if any.
    pub fn stored_state(&self) -> Option<&[f64]> {
        self.hybrid.as_ref().map(|h| h.x0.as_slice())
    }

    /// Free-run states (`n × N`) over `exp`'s inputs from `x0`, the inputs between samples
    /// as the model says (a record read as the model reads it, through its own grid when
    /// band-limited: [`simulate_experiment`]).
    pub fn simulate_states(&self, x0: &[f64], exp: &Experiment) -> Result<DMatrix<f64>> {
        if exp.intersample() == self.intersample() {
            return simulate_experiment(
                &self.dynamics,
                x0,
                exp,
                0..exp.len(),
                &self.integrator,
                BLOW_UP,
            )
            .map_err(core("free-run simulation of the model"));
        }
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

impl LoadedModel {
    /// How the one judge simulates this model: its integrator, the blow-up bound, and its
    /// stored state (a hybrid model's training `x̂(t0)`) as a second start of the
    /// initial-state fit.
    pub fn judge_options(&self) -> JudgeOptions {
        JudgeOptions {
            integrator: self.integrator,
            blow_up: BLOW_UP,
            stored_state: self.stored_state().map(<[f64]>::to_vec),
            ..JudgeOptions::default()
        }
    }

    /// The model's outputs (`C` and its output names) as judged channels.
    pub fn outputs(&self) -> Observation {
        Observation::outputs(&self.spec.linear)
    }

    /// The channels a data file can be compared on (see [`Observation::present`]).
    pub fn present(&self, has_column: impl Fn(&str) -> bool) -> Observation {
        Observation::present(&self.spec.linear, has_column)
    }
}

/// A judgement as an evaluation-table row (the channels `names`, in order).
pub fn evaluation(j: &Judgement, names: &[String]) -> sysid_baselines::Evaluation {
    sysid_baselines::Evaluation {
        horizon: j.horizon,
        channels: names
            .iter()
            .filter_map(|n| {
                j.channels
                    .get(n)
                    .map(|m| sysid_baselines::ChannelEvaluation {
                        name: n.clone(),
                        metrics: *m,
                    })
            })
            .collect(),
        initial_samples: j.scored.first,
    }
}

/// [`sysid_core::judge_free_run`] on a loaded model: the record's inputs held as the model
/// says, its integrator, its stored state as a second start (rule in the module
/// documentation). `exp`'s output rows are the channels of `obs`, in order.
///
/// With an acquisition filter, the judgement's states are the model's on the deconvolved
/// record, its `outputs` the simulated channels through the filter, and its metrics those
/// outputs against `exp`'s recorded outputs.
pub fn judge_free_run(
    model: &LoadedModel,
    exp: &Experiment,
    obs: &Observation,
    rule: &InitialRule,
) -> Result<Judgement> {
    let exp = exp.clone().with_intersample(model.intersample());
    let inner = model.record_for_model(&exp, &obs.names)?;
    let mut j =
        sysid_core::judge_free_run(&model.dynamics, &inner, obs, rule, &model.judge_options())
            .map_err(core("judging the model free-run"))?;
    if let Some(f) = model.acquisition() {
        j.outputs = crate::acquisition::filter_rows(f, &j.outputs, exp.dt(), false)?;
        if !obs.names.is_empty() {
            j.channels = sysid_core::score(&obs.names, &exp, &j.outputs, 0)
                .map_err(core("scoring the model through its acquisition filter"))?;
        }
        j.x0_rule.push_str(
            ", on the record's inputs and outputs deconvolved by the model's acquisition \
             filter; the simulated outputs passed through the filter are scored against the \
             recorded ones",
        );
    }
    Ok(j)
}

/// [`sysid_core::judge_k_step`] on a loaded model, beside `free` (from [`judge_free_run`]
/// on the same record). A model with an acquisition filter has no k-step prediction
/// ([`MmennError::AcquisitionKStep`]: the filter acts on whole records).
pub fn judge_k_step(
    model: &LoadedModel,
    exp: &Experiment,
    obs: &Observation,
    k: usize,
    free: &Judgement,
) -> Result<Judgement> {
    if model.acquisition().is_some() {
        return Err(MmennError::AcquisitionKStep);
    }
    let exp = exp.clone().with_intersample(model.intersample());
    sysid_core::judge_k_step(&model.dynamics, &exp, obs, k, free, &model.judge_options())
        .map_err(core("k-step prediction"))
}
