//! The hybrid model file `model.json` written by `mmenn fit` (format tag, checks on
//! reading) and the plant model it builds, `ẋ = f(x, u) + E·NN(x, u)` as sysid-core's
//! [`CorrectedModel`]. `f` is the model file's dynamics ([`AssumedDynamics`]): the linear
//! model with named terms, or a `[mechanics]` model's `M(q)⁻¹·Q` (where `E·NN` is an
//! acceleration added to the rates, as MME's correction is).

use std::path::Path;

use nalgebra::DMatrix;
use nn::{Domain, Mlp, NetCorrection};
use serde::{Deserialize, Serialize};
use sysid_core::{CorrectedModel, Dynamics, PhysicalModel, TermModel};

use crate::error::{MmennError, Result};
use crate::model_file::{ModelSpec, parse_model};

/// Format tag of `model.json`.
pub const HYBRID_FORMAT: &str = "mmenn-hybrid/1";

/// The hybrid model as saved in `model.json`: the assumed model (model-file TOML text, with
/// its `intersample`), the trained network, the training initial state and the integration
/// settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct HybridFile {
    /// Always [`HYBRID_FORMAT`].
    pub format: String,
    /// The assumed model, in the model-file format.
    pub model_toml: String,
    /// The network `(x, u) → d` (inputs: states then inputs; outputs: corrections).
    pub network: Mlp,
    /// Initial state of the training record (MME's `x̂(t0)`).
    pub x0: Vec<f64>,
    /// Sample period of the training data, s.
    pub dt: f64,
    /// RK4 sub-steps per sample interval in free-run simulation.
    pub substeps: usize,
    /// What the network does outside the box its training pairs spanned (absent in
    /// files written before it existed: [`Domain::Extrapolate`]).
    #[serde(default)]
    pub domain: Domain,
}

/// The completed plant model: the assumed dynamics plus the network.
pub type HybridModel = CorrectedModel<AssumedDynamics, NetCorrection>;

/// The model file's own dynamics under a hybrid: a state-space model with named terms,
/// or a mass-matrix (`[mechanics]`) model.
#[derive(Debug, Clone)]
pub enum AssumedDynamics {
    /// `ẋ = A x + B u + Σ terms` (parameter values substituted).
    Terms(Box<TermModel>),
    /// `M(q) q̈ = Q(q, q̇, u) + Σ terms`, solved for `q̈` at every evaluation.
    Physical(Box<PhysicalModel>),
}

impl AssumedDynamics {
    /// The model file's dynamics: [`AssumedDynamics::Physical`] when it has a
    /// `[mechanics]` part, else its terms.
    pub fn of(spec: &ModelSpec) -> std::result::Result<Self, crate::error::ModelProblem> {
        if spec.mechanics.is_some() {
            return Ok(Self::Physical(Box::new(spec.physical_model()?)));
        }
        Ok(Self::Terms(Box::new(spec.term_model()?)))
    }
}

impl Dynamics for AssumedDynamics {
    fn n_states(&self) -> usize {
        match self {
            Self::Terms(m) => m.n_states(),
            Self::Physical(m) => m.n_states(),
        }
    }
    fn n_inputs(&self) -> usize {
        match self {
            Self::Terms(m) => m.n_inputs(),
            Self::Physical(m) => m.n_inputs(),
        }
    }
    fn rhs(&self, t: f64, x: &[f64], u: &[f64], dx: &mut [f64]) {
        match self {
            Self::Terms(m) => m.rhs(t, x, u, dx),
            Self::Physical(m) => m.rhs(t, x, u, dx),
        }
    }
    fn jacobians(&self, t: f64, x: &[f64], u: &[f64], a: &mut DMatrix<f64>, b: &mut DMatrix<f64>) {
        match self {
            Self::Terms(m) => m.jacobians(t, x, u, a, b),
            Self::Physical(m) => m.jacobians(t, x, u, a, b),
        }
    }
}

impl HybridFile {
    /// Parse and check `model.json` text (`path` only names the file in errors): the
    /// format tag, `dt` finite and > 0, `substeps` in `1..=MAX_SUBSTEPS`, the model-file
    /// part, an initial state of finite numbers, one per state.
    pub fn parse(path: &Path, text: &str) -> Result<Self> {
        let problem = |line, column, message: String| MmennError::Model {
            path: path.to_path_buf(),
            line,
            column,
            problem: crate::error::ModelProblem::Syntax { message },
        };
        let file: HybridFile = serde_json::from_str(text)
            .map_err(|e| problem(Some(e.line()), Some(e.column()), e.to_string()))?;
        if file.format != HYBRID_FORMAT {
            return Err(problem(
                None,
                None,
                format!("format is '{}', expected '{HYBRID_FORMAT}'", file.format),
            ));
        }
        if !(file.dt.is_finite() && file.dt > 0.0) {
            return Err(problem(
                None,
                None,
                format!("dt = {} must be finite and > 0", file.dt),
            ));
        }
        if !(1..=mme_core::discretize::MAX_SUBSTEPS).contains(&file.substeps) {
            return Err(problem(
                None,
                None,
                format!(
                    "substeps = {} must be in 1..={}",
                    file.substeps,
                    mme_core::discretize::MAX_SUBSTEPS
                ),
            ));
        }
        let n = file.spec()?.linear.n_states();
        if file.x0.len() != n || file.x0.iter().any(|v| !v.is_finite()) {
            return Err(problem(
                None,
                None,
                format!("x0 must hold {n} finite numbers, got {:?}", file.x0),
            ));
        }
        Ok(file)
    }

    /// The model-file part (its `intersample` is how `predict` treats the inputs between
    /// samples).
    pub fn spec(&self) -> Result<ModelSpec> {
        parse_model(Path::new("model.json:model_toml"), &self.model_toml)
    }

    /// Build the simulatable hybrid model.
    pub fn model(&self) -> Result<HybridModel> {
        let spec = self.spec()?;
        hybrid_model(
            &spec,
            self.network.clone(),
            &self.x0,
            self.substeps,
            self.domain,
        )
    }
}

fn model_problem(problem: crate::error::ModelProblem) -> MmennError {
    MmennError::Model {
        path: "<model>".into(),
        line: None,
        column: None,
        problem,
    }
}

/// Build `ẋ = f(x, u) + E·NN(x, u)` from a model file and a network, which acts outside
/// its training box as `domain` says.
pub fn hybrid_model(
    spec: &ModelSpec,
    network: Mlp,
    x0: &[f64],
    substeps: usize,
    domain: Domain,
) -> Result<HybridModel> {
    let lin = &spec.linear;
    let base = AssumedDynamics::of(spec).map_err(model_problem)?;
    // A network with as many inputs as the model has states reads the states alone.
    let corr =
        NetCorrection::for_model(network, lin.n_states(), lin.n_inputs())?.with_domain(domain);
    let mut model = CorrectedModel::new(
        base,
        corr,
        lin.e().clone(),
        lin.c().clone(),
        lin.output_names().to_vec(),
    )
    .map_err(|source| MmennError::Core {
        context: "building the hybrid model",
        source,
    })?;
    model.x0 = x0.to_vec();
    model.integrator = sysid_core::Integrator::Rk4 {
        substeps: substeps.max(1),
    };
    Ok(model)
}
