//! The TOML model file of SPEC §5. Its keys are a contract (extend, never rename):
//! `states`, `inputs`, `A`, `B`, `measured` or `C` + `outputs`, `corrected`,
//! `noise_variance` (list or `"auto"`; `"auto"` when the key is left out), `units`, `intersample` (`"zoh"`, the default,
//! or `"foh"`: how the inputs behave between samples in MME and in free-run simulation,
//! for `mmenn estimate` and `mmenn discover`), and `[[terms]]` (`state`, `effect`, `term`, `coefficient`, and for a
//! transfer between two equations `into`; `coefficient` defaults to 1), and for physical
//! models `[parameters]` (`name = { value, unit, bounds, fixed }`, usable by name in every
//! expression) and `[mechanics]` (`q`, `qdot`, `mass`, `forces`: the mass-matrix form,
//! whose states are `q` then `qdot` when `states` is left out), and `[acquisition]`
//! (`pass_below_hz`, `bands` of `[centre Hz, real, imaginary]`: the filter the record's
//! input and output channels share, [`crate::acquisition`]), and `[x0_prior]`
//! (`state = { mean, std }`: a Gaussian prior on that state's value at the first sample of
//! every record, read by `mmenn estimate` only, [`parse_model_and_prior`]). `A` and `B`
//! are zero when left out.

use std::collections::BTreeMap;
use std::path::Path;

use mme_core::StatePrior;
use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};
use sysid_core::acquisition::AcquisitionFilter;
use sysid_core::{
    Estimation, InterSample, LinearModel, MechanicsSpec, ModelNames, Parameter, PhysicalModel,
    PhysicalTerm, TermModel, TermSpec,
};

use crate::acquisition::AcquisitionToml;
use crate::atomic::write_atomic;
use crate::error::{MmennError, ModelProblem, Result};

impl ModelSpec {
    /// The unit of a state, input, output or correction `d_<state>`: as the `[units]`
    /// table gives it, or for a correction without one, its state's unit per second
    /// (`rad/s` → `rad/s^2`, `m` → `m/s`).
    pub fn unit_of(&self, name: &str) -> Option<String> {
        if let Some(u) = self.units.get(name) {
            return Some(u.clone());
        }
        let state_unit = self.units.get(name.strip_prefix("d_")?)?;
        Some(per_second(state_unit))
    }

    /// The assumed model with its named terms, as `Dynamics` (the linear model alone when
    /// there are no terms), parameter values substituted into the expressions. Errors
    /// name the term and, for expressions, the column; a model with a `[mechanics]` part
    /// has no such form ([`ModelProblem::Mechanical`]: use [`ModelSpec::physical_model`]).
    pub fn term_model(&self) -> Result<TermModel, ModelProblem> {
        if self.mechanics.is_some() {
            return Err(ModelProblem::Mechanical { what: "this step" });
        }
        if !self.parameters.is_empty() {
            return match self.physical_model()?.term_model() {
                Some(r) => Ok(r?),
                None => Err(ModelProblem::Mechanical { what: "this step" }),
            };
        }
        let specs = self.terms.iter().map(|t| TermSpec {
            state: &t.state,
            into: t.into.as_deref(),
            effect: &t.effect,
            term: &t.term,
            coefficient: t.coefficient,
        });
        Ok(TermModel::from_specs(self.linear.clone(), specs)?)
    }

    /// `Err` naming the step `what` and the file `path` when the model corrects no
    /// equation (`corrected` missing or empty): the steps built on MME's correction
    /// (`estimate`, `discover`, `fit`, `compare`, `monitor`) would find `d̂ = 0` whatever
    /// the data, and say so before doing any work. The error suggests the rates of a
    /// `[mechanics]` part (forces left out enter there), else every state.
    pub fn refuse_uncorrected(&self, what: &'static str, path: &Path) -> Result<()> {
        if self.linear.n_corrections() > 0 {
            return Ok(());
        }
        let (names, why) = match &self.mechanics {
            Some(m) => (
                m.qdot.clone(),
                ": for [mechanics], the rates, where forces left out enter",
            ),
            None => (self.linear.state_names().to_vec(), ""),
        };
        let suggestion = names
            .iter()
            .map(|n| format!("\"{n}\""))
            .collect::<Vec<_>>()
            .join(", ");
        Err(MmennError::Model {
            path: path.to_path_buf(),
            line: None,
            column: None,
            problem: ModelProblem::Uncorrected {
                what,
                suggestion,
                why,
            },
        })
    }

    /// `Err` naming the step `what` and the file `path` when the model has a
    /// `[mechanics]` part: steps that change or read `A` and `B` (`fit --update-model
    /// regression`) cannot take the mass-matrix form, and say so before doing any work.
    pub fn refuse_mechanics(&self, what: &'static str, path: &Path) -> Result<()> {
        match self.mechanics {
            Some(_) => Err(MmennError::Model {
                path: path.to_path_buf(),
                line: None,
                column: None,
                problem: ModelProblem::Mechanical { what },
            }),
            None => Ok(()),
        }
    }

    /// `Err` naming the step `what` and the file `path` when the model has an
    /// `[acquisition]` table that the step would ignore (`estimate`, `greyest`, `monitor`,
    /// `discover`: their numbers would not be read through the filter as `predict`'s are).
    pub fn refuse_acquisition(&self, what: &'static str, path: &Path) -> Result<()> {
        match self.acquisition {
            Some(_) => Err(MmennError::Model {
                path: path.to_path_buf(),
                line: None,
                column: None,
                problem: ModelProblem::AcquisitionUnread { what },
            }),
            None => Ok(()),
        }
    }

    /// Whether the file uses `[parameters]` or `[mechanics]` (then its dynamics is a
    /// [`PhysicalModel`], which also gives `∂f/∂p`).
    pub fn is_physical(&self) -> bool {
        !self.parameters.is_empty() || self.mechanics.is_some()
    }

    /// The model as a [`PhysicalModel`]: linear part, parameters, terms and mechanics.
    /// Errors say which parameter, term or mechanics entry is wrong.
    pub fn physical_model(&self) -> Result<PhysicalModel, ModelProblem> {
        let states = self.linear.state_names();
        let position = |key: &'static str, name: &str| {
            states
                .iter()
                .position(|s| s == name)
                .ok_or_else(|| ModelProblem::UnknownName {
                    key,
                    name: name.to_owned(),
                    kind: "state",
                })
        };
        let mut terms = Vec::with_capacity(self.terms.len());
        for t in &self.terms {
            terms.push(PhysicalTerm {
                state: position("terms.state", &t.state)?,
                into: t
                    .into
                    .as_deref()
                    .map(|r| position("terms.into", r))
                    .transpose()?,
                effect: &t.effect,
                term: &t.term,
                coefficient: t.coefficient,
            });
        }
        let parameters = self
            .parameters
            .iter()
            .map(ParameterEntry::parameter)
            .collect();
        let mechanics = self.mechanics.as_ref().map(|m| MechanicsSpec {
            q: &m.q,
            qdot: &m.qdot,
            mass: &m.mass,
            forces: &m.forces,
        });
        Ok(PhysicalModel::new(
            self.linear.clone(),
            parameters,
            &terms,
            mechanics,
        )?)
    }
}

/// A named physical parameter as written in `[parameters]`:
/// `name = { value = 0.3, unit = "m", bounds = [0.1, 1.0], fixed = false }` (`unit`,
/// `bounds` and `fixed` optional; a parameter is free unless `fixed = true`).
#[derive(Debug, Clone, PartialEq)]
pub struct ParameterEntry {
    /// Its name, usable in every expression.
    pub name: String,
    /// Its value.
    pub value: f64,
    /// Its unit, as written.
    pub unit: Option<String>,
    /// Lower and upper bound, if given.
    pub bounds: Option<(f64, f64)>,
    /// Free (estimated) or fixed.
    pub estimation: Estimation,
    /// Standard deviation of an estimated value (written by a parameter estimator; `None`
    /// for a value that was not estimated).
    pub sigma: Option<f64>,
}

impl ParameterEntry {
    /// As `sysid_core`'s parameter (no bounds: `±inf`).
    pub fn parameter(&self) -> Parameter {
        let (lower, upper) = self.bounds.unwrap_or((f64::NEG_INFINITY, f64::INFINITY));
        Parameter {
            name: self.name.clone(),
            value: self.value,
            lower,
            upper,
            estimation: self.estimation,
        }
    }
}

/// The `[mechanics]` table: the mass-matrix form `M(q) q̈ = Q(q, q̇, u, p)`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MechanicsEntry {
    /// Generalized coordinates (state names).
    pub q: Vec<String>,
    /// Their rates (state names), in the same order.
    pub qdot: Vec<String>,
    /// The symmetric mass matrix, rows of expressions.
    pub mass: Vec<Vec<String>>,
    /// Generalized forces, one expression per coordinate.
    pub forces: Vec<String>,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct ParameterToml {
    value: f64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    unit: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    bounds: Option<[f64; 2]>,
    #[serde(default, skip_serializing_if = "is_false")]
    fixed: bool,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    sigma: Option<f64>,
}

fn is_false(b: &bool) -> bool {
    !*b
}

fn is_one(c: &f64) -> bool {
    c.to_bits() == 1.0_f64.to_bits()
}

fn one() -> f64 {
    1.0
}

/// Measurement noise variance: given per measured channel, or to be estimated.
#[derive(Debug, Clone, PartialEq)]
pub enum NoiseVariance {
    /// One positive variance per measured channel, in the channel's unit squared.
    Given(Vec<f64>),
    /// Estimate from the data.
    Auto,
}

/// A named nonlinear term as written in the file (validated against the model's names;
/// the expression itself is compiled by `sysid_core::terms`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TermEntry {
    /// State equation it enters.
    pub state: String,
    /// For a transfer: the state equation that receives the negated term (what `state`
    /// loses, `into` gains, under one coefficient). Absent for an ordinary term.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub into: Option<String>,
    /// Catalogue name of the effect.
    pub effect: String,
    /// The expression, in state, input and parameter names.
    pub term: String,
    /// Coefficient multiplying the expression (1 when left out).
    #[serde(default = "one", skip_serializing_if = "is_one")]
    pub coefficient: f64,
}

/// A model file in memory: the assumed linear model, noise, units and named terms.
#[derive(Debug, Clone, PartialEq)]
pub struct ModelSpec {
    /// The assumed linear model (names: states, inputs, outputs, corrected states).
    pub linear: LinearModel,
    /// Measurement noise variance.
    pub noise_variance: NoiseVariance,
    /// Units by state/input/output name.
    pub units: BTreeMap<String, String>,
    /// Named nonlinear terms.
    pub terms: Vec<TermEntry>,
    /// How the inputs behave between samples (`estimate`, `discover`; `fit` and
    /// `predict` hold them).
    pub intersample: InterSample,
    /// Named physical parameters, in name order (`[parameters]`; empty when none).
    pub parameters: Vec<ParameterEntry>,
    /// The mass-matrix part (`[mechanics]`), if any.
    pub mechanics: Option<MechanicsEntry>,
    /// The filter the records' input and output channels share (`[acquisition]`), if
    /// any: every command that judges the model reads the records through it
    /// ([`crate::acquisition`]).
    pub acquisition: Option<AcquisitionFilter>,
    /// Physical roles given to states by name (`[roles]`), replacing the ones `discover`
    /// infers from `A`, the units and the names (`discovery::StateRoles`): e.g. a level
    /// read in volts. Empty when none.
    pub roles: BTreeMap<String, discovery::Role>,
}

fn is_zoh(hold: &InterSample) -> bool {
    *hold == InterSample::Zoh
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
enum NoiseToml {
    Values(Vec<f64>),
    Word(String),
}

/// One entry of `[x0_prior]`: `state = { mean = …, std = … }`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct PriorToml {
    mean: f64,
    std: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct ModelToml {
    #[serde(default)]
    states: Vec<String>,
    #[serde(default)]
    inputs: Vec<String>,
    #[serde(rename = "A", default, skip_serializing_if = "Option::is_none")]
    a: Option<Vec<Vec<f64>>>,
    #[serde(rename = "B", default, skip_serializing_if = "Option::is_none")]
    b: Option<Vec<Vec<f64>>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    measured: Option<Vec<String>>,
    #[serde(rename = "C", default, skip_serializing_if = "Option::is_none")]
    c: Option<Vec<Vec<f64>>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    outputs: Option<Vec<String>>,
    #[serde(default)]
    corrected: Vec<String>,
    #[serde(default = "auto_noise")]
    noise_variance: NoiseToml,
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    units: BTreeMap<String, String>,
    #[serde(default, skip_serializing_if = "is_zoh")]
    intersample: InterSample,
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    parameters: BTreeMap<String, ParameterToml>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    mechanics: Option<MechanicsEntry>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    acquisition: Option<AcquisitionToml>,
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    x0_prior: BTreeMap<String, PriorToml>,
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    roles: BTreeMap<String, discovery::Role>,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    terms: Vec<TermEntry>,
}

/// `unit` divided by seconds: `…/s` → `…/s^2`, `…/s^k` → `…/s^(k+1)`, else `…/s`.
fn per_second(unit: &str) -> String {
    if let Some(base) = unit.strip_suffix("/s") {
        return format!("{base}/s^2");
    }
    if let Some((base, k)) = unit.rsplit_once("/s^")
        && let Ok(k) = k.parse::<u32>()
    {
        return format!("{base}/s^{}", k + 1);
    }
    format!("{unit}/s")
}

/// A model file without `noise_variance` estimates it.
fn auto_noise() -> NoiseToml {
    NoiseToml::Word("auto".into())
}

fn matrix(
    key: &'static str,
    rows: &[Vec<f64>],
    n_rows: usize,
    n_cols: usize,
) -> Result<DMatrix<f64>, ModelProblem> {
    if rows.len() != n_rows {
        return Err(ModelProblem::Rows {
            matrix: key,
            found: rows.len(),
            expected: n_rows,
        });
    }
    for (i, r) in rows.iter().enumerate() {
        if r.len() != n_cols {
            return Err(ModelProblem::RaggedRow {
                matrix: key,
                row: i,
                found: r.len(),
                expected: n_cols,
            });
        }
    }
    Ok(DMatrix::from_fn(n_rows, n_cols, |i, j| rows[i][j]))
}

fn selection(
    key: &'static str,
    names: &[String],
    states: &[String],
    rows: bool,
) -> Result<DMatrix<f64>, ModelProblem> {
    let n = states.len();
    let mut m = if rows {
        DMatrix::zeros(names.len(), n)
    } else {
        DMatrix::zeros(n, names.len())
    };
    for (k, name) in names.iter().enumerate() {
        let i = states
            .iter()
            .position(|s| s == name)
            .ok_or_else(|| ModelProblem::UnknownName {
                key,
                name: name.clone(),
                kind: "state",
            })?;
        if rows {
            m[(k, i)] = 1.0;
        } else {
            m[(i, k)] = 1.0;
        }
    }
    Ok(m)
}

/// Why `name` cannot name a state, input or output, if it cannot: names become CSV
/// header cells (beside the time column `t`) and parts of output file names, so they must
/// be non-empty, differ from `t`, carry no CSV separator, quote, line break, control
/// character, path separator or `..`, characters that file systems refuse, or
/// surrounding whitespace (the CSV reader trims cells).
pub fn name_problem(name: &str) -> Option<&'static str> {
    if name.is_empty() {
        return Some("it is empty");
    }
    if name == "t" {
        return Some("'t' is the time column of every data file");
    }
    if name.trim() != name {
        return Some("it has leading or trailing whitespace");
    }
    if name.chars().any(|c| c.is_control()) {
        return Some("it contains a control character or line break");
    }
    if name.contains([',', '"', '\'', ';']) {
        return Some("it contains a CSV separator or quote");
    }
    if name.contains(['/', '\\']) {
        return Some("it contains a path separator");
    }
    if name.contains("..") {
        return Some("it contains '..'");
    }
    if name.contains([':', '*', '?', '<', '>', '|']) {
        return Some("it contains a character file names cannot hold (: * ? < > |)");
    }
    if name.chars().count() > 64 {
        return Some("it is longer than 64 characters");
    }
    None
}

fn check_names(key: &'static str, names: &[String]) -> Result<(), ModelProblem> {
    for name in names {
        if let Some(reason) = name_problem(name) {
            return Err(ModelProblem::BadName {
                key,
                name: name.clone(),
                reason,
            });
        }
    }
    Ok(())
}

/// The `[x0_prior]` table checked against the states: every name a state, every mean
/// finite, every `std` positive and finite. In the states' order.
fn x0_prior(
    table: &BTreeMap<String, PriorToml>,
    states: &[String],
) -> Result<Vec<StatePrior>, ModelProblem> {
    for name in table.keys() {
        if !states.contains(name) {
            return Err(ModelProblem::UnknownName {
                key: "x0_prior",
                name: name.clone(),
                kind: "state",
            });
        }
    }
    let mut out = Vec::new();
    for state in states {
        let Some(p) = table.get(state) else {
            continue;
        };
        let bad = |field, value| ModelProblem::Prior {
            state: state.clone(),
            field,
            value,
        };
        if !p.mean.is_finite() {
            return Err(bad("mean", p.mean));
        }
        if !(p.std.is_finite() && p.std > 0.0) {
            return Err(bad("std", p.std));
        }
        out.push(StatePrior::new(state.clone(), p.mean, p.std));
    }
    Ok(out)
}

fn build_with_prior(mut raw: ModelToml) -> Result<(ModelSpec, Vec<StatePrior>), ModelProblem> {
    if raw.states.is_empty()
        && let Some(m) = &raw.mechanics
    {
        raw.states = m.q.iter().chain(&m.qdot).cloned().collect();
    }
    if raw.states.is_empty() {
        return Err(ModelProblem::NoStates);
    }
    check_names("states", &raw.states)?;
    check_names("inputs", &raw.inputs)?;
    if let Some(outputs) = &raw.outputs {
        check_names("outputs", outputs)?;
    }
    let n = raw.states.len();
    let m = raw.inputs.len();
    let a = match &raw.a {
        Some(a) => matrix("A", a, n, n)?,
        None => DMatrix::zeros(n, n),
    };
    let b = match &raw.b {
        Some(b) => matrix("B", b, n, m)?,
        None => DMatrix::zeros(n, m),
    };
    let (c, outputs) = match (&raw.measured, &raw.c) {
        (Some(_), Some(_)) => {
            return Err(ModelProblem::Conflict {
                a: "measured",
                b: "C",
            });
        }
        (None, None) => {
            return Err(ModelProblem::MissingKey {
                key: "measured",
                why: "say which states are measured (or give C and outputs)",
            });
        }
        (Some(meas), None) => (
            selection("measured", meas, &raw.states, true)?,
            meas.clone(),
        ),
        (None, Some(c)) => {
            let outputs = raw.outputs.clone().ok_or(ModelProblem::MissingKey {
                key: "outputs",
                why: "C is given, so its rows need names",
            })?;
            (matrix("C", c, outputs.len(), n)?, outputs)
        }
    };
    let e = selection("corrected", &raw.corrected, &raw.states, false)?;
    let prior = x0_prior(&raw.x0_prior, &raw.states)?;
    let noise_variance = match raw.noise_variance {
        NoiseToml::Word(w) if w == "auto" => NoiseVariance::Auto,
        NoiseToml::Word(w) => return Err(ModelProblem::NoiseWord(w)),
        NoiseToml::Values(v) => {
            if v.len() != outputs.len() {
                return Err(ModelProblem::NoiseLength {
                    found: v.len(),
                    expected: outputs.len(),
                });
            }
            if let Some((index, &value)) = v
                .iter()
                .enumerate()
                .find(|(_, x)| !(x.is_finite() && **x > 0.0))
            {
                return Err(ModelProblem::NonPositiveVariance { index, value });
            }
            NoiseVariance::Given(v)
        }
    };
    for name in raw.units.keys() {
        let is_correction = name
            .strip_prefix("d_")
            .is_some_and(|s| raw.states.iter().any(|c| c == s));
        if !raw.states.contains(name)
            && !raw.inputs.contains(name)
            && !outputs.contains(name)
            && !is_correction
        {
            return Err(ModelProblem::UnknownName {
                key: "units",
                name: name.clone(),
                kind: "state, input, output or d_<state>",
            });
        }
    }
    if let Some(name) = raw.roles.keys().find(|n| !raw.states.contains(n)) {
        return Err(ModelProblem::UnknownName {
            key: "roles",
            name: name.clone(),
            kind: "state",
        });
    }
    for t in &raw.terms {
        if !raw.states.contains(&t.state) {
            return Err(ModelProblem::UnknownName {
                key: "terms.state",
                name: t.state.clone(),
                kind: "state",
            });
        }
        if let Some(into) = &t.into
            && (!raw.states.contains(into) || into == &t.state)
        {
            return Err(ModelProblem::UnknownName {
                key: "terms.into",
                name: into.clone(),
                kind: "state other than the term's own",
            });
        }
    }
    let names = ModelNames {
        states: raw.states.clone(),
        inputs: raw.inputs.clone(),
        outputs,
        corrections: raw.corrected.clone(),
    };
    let linear = LinearModel::with_names(a, b, c, e, names)?;
    let parameters = raw
        .parameters
        .into_iter()
        .map(|(name, p)| ParameterEntry {
            name,
            value: p.value,
            unit: p.unit,
            bounds: p.bounds.map(|[lo, hi]| (lo, hi)),
            estimation: if p.fixed {
                Estimation::Fixed
            } else {
                Estimation::Free
            },
            sigma: p.sigma,
        })
        .collect();
    let acquisition = raw
        .acquisition
        .as_ref()
        .map(AcquisitionToml::filter)
        .transpose()?;
    let spec = ModelSpec {
        linear,
        noise_variance,
        units: raw.units,
        terms: raw.terms,
        intersample: raw.intersample,
        parameters,
        mechanics: raw.mechanics,
        acquisition,
        roles: raw.roles,
    };
    if spec.is_physical() {
        spec.physical_model()?;
    } else {
        spec.term_model()?;
    }
    Ok((spec, prior))
}

/// Line and column (1-based) of the first quoted occurrence of `expression` in `text`,
/// plus `column` characters into it: where an expression error points in the file.
fn locate(text: &str, expression: &str, column: usize) -> Option<(usize, usize)> {
    let quoted = format!("\"{expression}\"");
    let at = text
        .find(&quoted)
        .or_else(|| text.find(&format!("'{expression}'")))?;
    let (line, col) = line_col(text, at);
    Some((line, col + 1 + column))
}

/// The expression text and column an expression error in a model points at, if any.
fn expression_of(problem: &ModelProblem) -> Option<(&str, usize)> {
    use sysid_core::{ExprError, PhysicalError, TermError};
    let column = |e: &ExprError| match e {
        ExprError::Empty { column }
        | ExprError::UnexpectedCharacter { column, .. }
        | ExprError::InvalidNumber { column, .. }
        | ExprError::UnknownName { column, .. }
        | ExprError::UnknownFunction { column, .. }
        | ExprError::UnexpectedToken { column, .. }
        | ExprError::UnclosedParenthesis { column }
        | ExprError::UnmatchedParenthesis { column }
        | ExprError::TrailingInput { column, .. }
        | ExprError::TooDeep { column, .. } => *column,
        _ => 0,
    };
    match problem {
        ModelProblem::Physical(e) => match e.as_ref() {
            PhysicalError::Expression { text, source, .. } => Some((text, column(source))),
            _ => None,
        },
        ModelProblem::Term(e) => match e.as_ref() {
            TermError::Expression { text, source, .. } => Some((text, column(source))),
            _ => None,
        },
        _ => None,
    }
}

fn line_col(text: &str, offset: usize) -> (usize, usize) {
    let before = &text[..offset.min(text.len())];
    let line = before.matches('\n').count() + 1;
    let col = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
    (line, col)
}

/// Parse a model file's text; `path` is only used in errors. An `[x0_prior]` table is
/// checked and dropped (see [`parse_model_and_prior`]).
pub fn parse_model(path: &Path, text: &str) -> Result<ModelSpec> {
    parse_model_and_prior(path, text).map(|(spec, _)| spec)
}

/// Parse a model file's text with its `[x0_prior]` table: the Gaussian prior on the
/// initial state that `mmenn estimate` hands to MME ([`mme_core::MmeConfig::x0_prior`]),
/// in the states' order (empty without the table). The prior is not part of
/// [`ModelSpec`]: [`format_model`] does not write it.
pub fn parse_model_and_prior(path: &Path, text: &str) -> Result<(ModelSpec, Vec<StatePrior>)> {
    let err = |line, column, problem| MmennError::Model {
        path: path.to_path_buf(),
        line,
        column,
        problem,
    };
    let raw: ModelToml = toml::from_str(text).map_err(|e| {
        let (line, col) = e
            .span()
            .map(|s| line_col(text, s.start))
            .map_or((None, None), |(l, c)| (Some(l), Some(c)));
        err(
            line,
            col,
            ModelProblem::Syntax {
                message: e.message().trim().to_string(),
            },
        )
    })?;
    build_with_prior(raw).map_err(|p| {
        let at = expression_of(&p).and_then(|(expr, column)| locate(text, expr, column));
        err(at.map(|a| a.0), at.map(|a| a.1), p)
    })
}

/// Read a model file.
pub fn read_model(path: &Path) -> Result<ModelSpec> {
    read_model_and_prior(path).map(|(spec, _)| spec)
}

/// Read a model file with its `[x0_prior]` table ([`parse_model_and_prior`]).
pub fn read_model_and_prior(path: &Path) -> Result<(ModelSpec, Vec<StatePrior>)> {
    let text = std::fs::read_to_string(path).map_err(|source| MmennError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    parse_model_and_prior(path, &text)
}

fn rows_of(m: &DMatrix<f64>) -> Vec<Vec<f64>> {
    (0..m.nrows())
        .map(|i| m.row(i).iter().copied().collect())
        .collect()
}

/// Render a model as TOML text in the contract's keys: `measured` when `C` is a selection
/// (else `C` + `outputs`); `corrected` from `E`, which must be a selection. An
/// `[x0_prior]` table is not part of [`ModelSpec`] and is not written.
pub fn format_model(spec: &ModelSpec) -> Result<String> {
    let lin = &spec.linear;
    let states = lin.state_names().to_vec();
    let (measured, c, outputs) = match lin.measured_states() {
        Some(idx)
            if idx
                .iter()
                .zip(lin.output_names())
                .all(|(&i, o)| &states[i] == o) =>
        {
            (
                Some(idx.iter().map(|&i| states[i].clone()).collect()),
                None,
                None,
            )
        }
        _ => (
            None,
            Some(rows_of(lin.c())),
            Some(lin.output_names().to_vec()),
        ),
    };
    let corrected = match lin.corrected_states() {
        Some(idx) => idx.iter().map(|&i| states[i].clone()).collect(),
        None => {
            return Err(MmennError::Model {
                path: "<model being written>".into(),
                line: None,
                column: None,
                problem: ModelProblem::MissingKey {
                    key: "corrected",
                    why: "the model file can only express E as a selection of corrected states",
                },
            });
        }
    };
    let parameters = spec
        .parameters
        .iter()
        .map(|p| {
            (
                p.name.clone(),
                ParameterToml {
                    value: p.value,
                    unit: p.unit.clone(),
                    bounds: p.bounds.map(|(lo, hi)| [lo, hi]),
                    fixed: p.estimation == Estimation::Fixed,
                    sigma: p.sigma,
                },
            )
        })
        .collect();
    let raw = ModelToml {
        states,
        inputs: lin.input_names().to_vec(),
        a: Some(rows_of(lin.a())),
        b: if lin.n_inputs() > 0 {
            Some(rows_of(lin.b()))
        } else {
            None
        },
        measured,
        c,
        outputs,
        corrected,
        noise_variance: match &spec.noise_variance {
            NoiseVariance::Auto => NoiseToml::Word("auto".into()),
            NoiseVariance::Given(v) => NoiseToml::Values(v.clone()),
        },
        units: spec.units.clone(),
        intersample: spec.intersample,
        parameters,
        mechanics: spec.mechanics.clone(),
        acquisition: spec.acquisition.as_ref().map(AcquisitionToml::of),
        x0_prior: BTreeMap::new(),
        roles: spec.roles.clone(),
        terms: spec.terms.clone(),
    };
    toml::to_string(&raw).map_err(|e| MmennError::Model {
        path: "<model being written>".into(),
        line: None,
        column: None,
        problem: ModelProblem::Syntax {
            message: e.to_string(),
        },
    })
}

/// Write a model file atomically.
pub fn write_model(path: &Path, spec: &ModelSpec) -> Result<()> {
    write_atomic(path, format_model(spec)?.as_bytes())
}

/// A linear two-tank model with both levels read in volts (tests of `[roles]`).
#[cfg(test)]
pub(crate) const TWO_TANKS_IN_VOLTS: &str = r#"
states = ["h1", "h2"]
inputs = ["u"]
A = [[-0.02, 0.0], [0.02, -0.015]]
B = [[0.03], [0.0]]
C = [[0.0, 1.0]]
outputs = ["y"]
corrected = ["h2"]
units = { h1 = "V", h2 = "V", u = "V", y = "V" }
"#;

#[cfg(test)]
mod tests;
