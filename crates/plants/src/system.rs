//! The [`TruthSystem`] trait every plant implements (truth dynamics, assumed linear model,
//! truth correction, units, recipes: [`Recipe`] says which), the [`TruthCorrection`] adapter to
//! `sysid_core::Correction`, and helpers shared by the plants.

use std::collections::BTreeMap;
use std::fmt;
use std::str::FromStr;

use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};
use sysid_core::{Correction, Dynamics, LinearModel, ModelNames};

use crate::error::{PlantError, Result};
use crate::params::ParamInfo;
use crate::signals::Excitation;

/// Which experiment of a system to generate.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Recipe {
    /// The training (estimation) experiment.
    #[default]
    Train,
    /// The test (validation) experiment: a different input and initial state.
    Test,
}

impl fmt::Display for Recipe {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Recipe::Train => "train",
            Recipe::Test => "test",
        })
    }
}

impl FromStr for Recipe {
    type Err = PlantError;
    fn from_str(s: &str) -> Result<Self> {
        match s {
            "train" => Ok(Recipe::Train),
            "test" => Ok(Recipe::Test),
            other => Err(PlantError::UnknownRecipe {
                name: other.to_string(),
            }),
        }
    }
}

/// What one recipe (training or test experiment) of a plant consists of.
#[derive(Debug, Clone, PartialEq)]
pub struct RecipeSpec {
    /// Initial state `x(t0)`, in the plant's state order and units.
    pub x0: Vec<f64>,
    /// One excitation per input channel, sampled on the experiment grid and held between
    /// samples.
    pub inputs: Vec<Excitation>,
    /// Default record length, s (the last sample is at `t0 + duration`).
    pub duration: f64,
}

/// A simulated truth system with its assumed linear model.
///
/// The truth is `ẋ = f_truth(x, u)` (the [`Dynamics`] impl); the assumed model is
/// `ẋ = A x + B u + E d`, and the truth correction is `d = Eᵀ(f_truth − (A x + B u))`, the
/// exact model error on the corrected rows (the uncorrected rows agree exactly).
pub trait TruthSystem: Dynamics {
    /// Registry name (e.g. `msd_cubic`).
    fn name(&self) -> &'static str;
    /// One-line description with the equation.
    fn description(&self) -> &'static str;
    /// Physical parameters `(name, value, unit)`.
    fn parameters(&self) -> Vec<ParamInfo>;
    /// Default sample rate, Hz.
    fn default_fs(&self) -> f64;
    /// Default measurement-noise variance per measured channel (units²).
    fn default_noise_variance(&self) -> Vec<f64>;
    /// The assumed linear model, with names; `C` selects the measured states and `E`
    /// the corrected state equations.
    fn assumed_model(&self) -> Result<LinearModel>;
    /// The truth correction `d = f_truth − f_assumed` on the corrected rows, in closed
    /// form; `d.len()` equals the number of corrected states.
    fn truth_correction(&self, x: &[f64], u: &[f64], d: &mut [f64]);
    /// Units of every state, input and correction (`d_<state>`).
    fn units(&self) -> BTreeMap<String, String>;
    /// Initial state, inputs and duration of a recipe.
    fn recipe(&self, recipe: Recipe) -> RecipeSpec;
}

impl<T: TruthSystem + ?Sized> TruthSystem for Box<T> {
    fn name(&self) -> &'static str {
        (**self).name()
    }
    fn description(&self) -> &'static str {
        (**self).description()
    }
    fn parameters(&self) -> Vec<ParamInfo> {
        (**self).parameters()
    }
    fn default_fs(&self) -> f64 {
        (**self).default_fs()
    }
    fn default_noise_variance(&self) -> Vec<f64> {
        (**self).default_noise_variance()
    }
    fn assumed_model(&self) -> Result<LinearModel> {
        (**self).assumed_model()
    }
    fn truth_correction(&self, x: &[f64], u: &[f64], d: &mut [f64]) {
        (**self).truth_correction(x, u, d)
    }
    fn units(&self) -> BTreeMap<String, String> {
        (**self).units()
    }
    fn recipe(&self, recipe: Recipe) -> RecipeSpec {
        (**self).recipe(recipe)
    }
}

/// A plant's truth correction as a [`Correction`], e.g. to check a hybrid model
/// `ẋ = A x + B u + E·g(x, u)` with the perfect `g` against the truth.
#[derive(Debug, Clone)]
pub struct TruthCorrection<P> {
    plant: P,
    q: usize,
}

impl<P: TruthSystem> TruthCorrection<P> {
    /// Wrap a plant; reads the correction count from its assumed model.
    pub fn new(plant: P) -> Result<Self> {
        let q = plant.assumed_model()?.n_corrections();
        Ok(Self { plant, q })
    }

    /// The wrapped plant.
    pub fn plant(&self) -> &P {
        &self.plant
    }
}

impl<P: TruthSystem> Correction for TruthCorrection<P> {
    fn n_states(&self) -> usize {
        self.plant.n_states()
    }
    fn n_inputs(&self) -> usize {
        self.plant.n_inputs()
    }
    fn n_outputs(&self) -> usize {
        self.q
    }
    fn eval(&self, x: &[f64], u: &[f64], d: &mut [f64]) {
        self.plant.truth_correction(x, u, d)
    }
}

/// The model error of any linear model against a truth, on the model's corrected rows:
/// `d = Eᵀ(f_truth(x, u) − (A x + B u))`, with `E` a selection (the corrected rows are
/// read from `E`'s unit entries; a general `E` uses the least-squares `E⁺`).
///
/// Use it for models other than a plant's own assumed model, e.g. the double
/// pendulum's linearised physics model or a regression-updated model.
pub fn model_error<D: Dynamics + ?Sized>(
    truth: &D,
    model: &LinearModel,
    x: &[f64],
    u: &[f64],
    d: &mut [f64],
) {
    let n = truth.n_states();
    let mut ft = vec![0.0; n];
    let mut fa = vec![0.0; n];
    truth.rhs(0.0, x, u, &mut ft);
    model.rhs(0.0, x, u, &mut fa);
    let diff = nalgebra::DVector::from_fn(n, |i, _| ft[i] - fa[i]);
    let dd = match model.corrected_states() {
        Some(_) => model.e().transpose() * diff,
        None => {
            let e = model.e();
            let pinv = e
                .clone()
                .pseudo_inverse(1e-12)
                .unwrap_or_else(|_| e.transpose());
            pinv * diff
        }
    };
    d.copy_from_slice(dd.as_slice());
}

/// Build a named linear model whose `C` selects `measured` and whose `E` selects
/// `corrected` (state names).
pub(crate) fn selection_model(
    a: DMatrix<f64>,
    b: DMatrix<f64>,
    states: &[&str],
    inputs: &[&str],
    measured: &[&str],
    corrected: &[&str],
) -> Result<LinearModel> {
    let n = states.len();
    let index = |name: &str| {
        states
            .iter()
            .position(|s| *s == name)
            .ok_or_else(|| sysid_core::CoreError::UnknownName {
                kind: "state",
                name: name.to_string(),
            })
    };
    let mut c = DMatrix::zeros(measured.len(), n);
    for (r, name) in measured.iter().enumerate() {
        c[(r, index(name)?)] = 1.0;
    }
    let mut e = DMatrix::zeros(n, corrected.len());
    for (k, name) in corrected.iter().enumerate() {
        e[(index(name)?, k)] = 1.0;
    }
    let own = |v: &[&str]| v.iter().map(|s| s.to_string()).collect::<Vec<_>>();
    let names = ModelNames {
        states: own(states),
        inputs: own(inputs),
        outputs: own(measured),
        corrections: own(corrected),
    };
    Ok(LinearModel::with_names(a, b, c, e, names)?)
}

/// Units map from `(state, unit, unit of its derivative)` and `(input, unit)`; every state
/// also gets `d_<state>` in its derivative unit.
pub(crate) fn unit_map(
    states: &[(&str, &str, &str)],
    inputs: &[(&str, &str)],
) -> BTreeMap<String, String> {
    let mut m = BTreeMap::new();
    for (s, unit, rate) in states {
        m.insert(s.to_string(), unit.to_string());
        m.insert(format!("d_{s}"), rate.to_string());
    }
    for (u, unit) in inputs {
        m.insert(u.to_string(), unit.to_string());
    }
    m
}
