//! Physical models: named parameters usable in every expression, and the mass-matrix
//! (joint-space) form of a mechanical system solved numerically at each evaluation.
//!
//! A [`PhysicalModel`] is
//!
//! ```text
//! ẋ = A x + B u + Σ_k c_k·g_k(x, u, p)·(e_{s_k} − e_{r_k})          (terms on other rows)
//!   + [ q̇ = v ;  v̇ = M(q, p)⁻¹ (Q(x, u, p) + Σ_k c_k·g_k(x, u, p)·(e_{s_k} − e_{r_k})) ]
//! ```
//!
//! where the bracket is the optional **mechanics** part: generalized coordinates `q`
//! (states), their rates `v = q̇` (states), a symmetric mass matrix `M` and generalized
//! forces `Q`, every entry an expression over the states, inputs and parameters. A term
//! whose equation is a rate `v_i` of a mechanical model is a **generalized force** on
//! coordinate `i` (it enters `Q_i`, so it is seen through `M⁻¹`); a term on any other
//! equation adds to `ẋ` directly, as in [`crate::TermModel`]. The mechanics part supplies
//! the kinematic rows `q̇_i = v_i` itself, so `A` should not repeat them.
//!
//! Each evaluation factors `M` (LU with partial pivoting on the stack, at most
//! [`MAX_DOF`] coordinates; a singular or non-finite `M` gives NaN accelerations, which
//! integrators report as a non-finite state) and solves for `v̇`.
//!
//! # Variables and parameters
//!
//! Every expression is over the model's **state names, then input names, then parameter
//! names** ([`PhysicalModel::variables`]); evaluation reads them from three slices
//! without copying ([`crate::Expr::eval3`]).
//!
//! # Derivatives
//!
//! All derivatives are symbolic (precompiled at construction): with `a = M⁻¹F`,
//! `F = Q + τ`, `∂a/∂z = M⁻¹(∂F/∂z − (∂M/∂z)·a)` for every state, input and parameter
//! `z`, one solve with the same factor per variable that appears in `M` or `F`.
//! [`Dynamics::jacobians`] gives `∂f/∂x` and `∂f/∂u`;
//! [`ParametricDynamics::parameter_jacobian`] gives `∂f/∂p`, the interface a grey-box
//! parameter estimator builds its sensitivities on (see the trait).

use nalgebra::DMatrix;
use thiserror::Error;

use crate::dynamics::Dynamics;
use crate::expr::{Expr, ExprError};
use crate::linear::LinearModel;
use crate::terms::{Term, TermModel};

mod solve;
#[cfg(test)]
mod tests;

pub use solve::MAX_DOF;
use solve::SmallLu;

/// Whether a parameter is estimated or held at its value.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Estimation {
    /// Free: a parameter estimator may change it (within its bounds).
    #[default]
    Free,
    /// Fixed at its value (a known constant such as `g`).
    Fixed,
}

/// A named physical parameter.
#[derive(Debug, Clone, PartialEq)]
pub struct Parameter {
    /// Its name, usable in every expression of the model.
    pub name: String,
    /// Its value.
    pub value: f64,
    /// Lower bound (`-inf` when unbounded).
    pub lower: f64,
    /// Upper bound (`+inf` when unbounded).
    pub upper: f64,
    /// Free or fixed.
    pub estimation: Estimation,
}

impl Parameter {
    /// A free, unbounded parameter.
    pub fn new(name: &str, value: f64) -> Self {
        Self {
            name: name.to_owned(),
            value,
            lower: f64::NEG_INFINITY,
            upper: f64::INFINITY,
            estimation: Estimation::Free,
        }
    }
}

/// The mechanics part as written: coordinate and rate state names, the mass matrix (rows
/// of expression texts, symmetric) and the generalized forces (one text per coordinate).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MechanicsSpec<'a> {
    /// Generalized coordinates `q` (state names).
    pub q: &'a [String],
    /// Their rates `q̇` (state names), in the same order.
    pub qdot: &'a [String],
    /// `M(q)`, `n × n` rows of expressions.
    pub mass: &'a [Vec<String>],
    /// `Q(q, q̇, u, p)`, `n` expressions.
    pub forces: &'a [String],
}

/// A model term as given to [`PhysicalModel::new`]: names resolved to state indices, the
/// expression text over [`PhysicalModel::variables`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PhysicalTerm<'a> {
    /// State equation index.
    pub state: usize,
    /// For a transfer, the receiving equation.
    pub into: Option<usize>,
    /// Catalogue name of the effect.
    pub effect: &'a str,
    /// Expression text.
    pub term: &'a str,
    /// Coefficient.
    pub coefficient: f64,
}

/// Errors building a [`PhysicalModel`]; each names what and where.
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum PhysicalError {
    /// A parameter's name is already a state or input name, or another parameter's.
    #[error("parameter '{name}' clashes with a {with} of the same name")]
    NameClash {
        /// The name.
        name: String,
        /// `state`, `input` or `parameter`.
        with: &'static str,
    },
    /// A parameter's value or bounds are not usable.
    #[error("parameter '{name}': {why} (value {value}, bounds [{lower}, {upper}])")]
    BadParameter {
        /// The parameter.
        name: String,
        /// Its value.
        value: f64,
        /// Lower bound.
        lower: f64,
        /// Upper bound.
        upper: f64,
        /// What is wrong.
        why: &'static str,
    },
    /// A parameter vector of the wrong length.
    #[error("{found} parameter values given for {expected} parameters")]
    ParameterCount {
        /// Values given.
        found: usize,
        /// Parameters of the model.
        expected: usize,
    },
    /// A mechanics coordinate or rate that is not a state, or used twice.
    #[error("mechanics.{key}: '{name}' {why}")]
    Coordinate {
        /// `q` or `qdot`.
        key: &'static str,
        /// The name.
        name: String,
        /// What is wrong.
        why: &'static str,
    },
    /// Mechanics parts of inconsistent sizes.
    #[error("mechanics.{key}: {found} where {expected} are needed")]
    Shape {
        /// Which part.
        key: &'static str,
        /// What was found (e.g. "3 rows").
        found: String,
        /// What was needed.
        expected: String,
    },
    /// More coordinates than the stack solver takes.
    #[error("mechanics: {n} coordinates, at most {max} are supported")]
    TooManyCoordinates {
        /// Coordinates given.
        n: usize,
        /// [`MAX_DOF`].
        max: usize,
    },
    /// The mass matrix is not symmetric as written.
    #[error(
        "mechanics.mass: entry [{row}][{col}] '{a}' differs from entry [{col}][{row}] '{b}' \
         (the mass matrix is symmetric)"
    )]
    Asymmetric {
        /// Row.
        row: usize,
        /// Column.
        col: usize,
        /// Text of `[row][col]`.
        a: String,
        /// Text of `[col][row]`.
        b: String,
    },
    /// An expression does not parse (or uses an unknown name).
    #[error("{place} '{text}': {source}")]
    Expression {
        /// Where: `mechanics.mass[0][1]`, `mechanics.forces[1]`, `terms[2] (friction)`.
        place: String,
        /// Its text.
        text: String,
        /// What is wrong with it, with the column.
        source: ExprError,
    },
    /// A term's state, transfer target or coefficient is invalid.
    #[error("terms[{index}] ({effect}): {why}")]
    BadTerm {
        /// Position of the term.
        index: usize,
        /// Its effect.
        effect: String,
        /// What is wrong.
        why: String,
    },
}

/// One precompiled nonzero partial derivative `coefficient·∂expr/∂var` entering row `row`
/// (a state equation, or for the mechanics a force or mass-matrix entry).
#[derive(Debug, Clone)]
struct Partial {
    row: usize,
    var: usize,
    coefficient: f64,
    expr: Expr,
}

/// A term over states, inputs and parameters.
#[derive(Debug, Clone)]
struct ParamTerm {
    state: usize,
    into: Option<usize>,
    effect: String,
    expr: Expr,
    coefficient: f64,
}

/// The compiled mechanics part.
#[derive(Debug, Clone)]
struct Mechanics {
    q: Vec<usize>,
    v: Vec<usize>,
    /// Row-major `n × n` entries.
    mass: Vec<Expr>,
    forces: Vec<Expr>,
    /// `∂M_ij/∂z` with `row = i·n + j`.
    dmass: Vec<Partial>,
    /// `∂F_i/∂z` (forces and the terms that are generalized forces), `row = i`.
    dforce: Vec<Partial>,
    /// Variables with at least one entry in `dmass` or `dforce`, ascending.
    vars: Vec<usize>,
    /// For each state, the coordinate it is the rate of (terms there are forces).
    rate_of: Vec<Option<usize>>,
}

/// A model with named parameters and, optionally, a mass-matrix part (module docs).
#[derive(Debug, Clone)]
pub struct PhysicalModel {
    linear: LinearModel,
    parameters: Vec<Parameter>,
    values: Vec<f64>,
    variables: Vec<String>,
    terms: Vec<ParamTerm>,
    /// Partials of the terms that add to `ẋ` directly, `row` = state equation.
    direct: Vec<Partial>,
    mechanics: Option<Mechanics>,
}

/// Grey-box access to a model's parameters: the values, their free/fixed flags and
/// bounds, a copy with other values, and the sensitivity `∂f/∂p` of the right-hand side.
///
/// A parameter estimator integrates the forward sensitivities `Ṡ = (∂f/∂x) S + ∂f/∂p`
/// (with [`Dynamics::jacobians`] for `∂f/∂x`) along a free run to get `∂x(t)/∂p`, and
/// from it the Jacobian of the output error for a least-squares step, then moves the free
/// parameters within their bounds with [`ParametricDynamics::with_parameters`]. Columns
/// of fixed parameters are computed too (zeroing or dropping them is the estimator's
/// choice).
pub trait ParametricDynamics: Dynamics {
    /// The parameters (name, value, bounds, free or fixed), in the model's order.
    fn parameters(&self) -> &[Parameter];

    /// The same model with parameter values `values` (one per parameter, in order).
    fn with_parameters(&self, values: &[f64]) -> Result<Self, PhysicalError>
    where
        Self: Sized;

    /// `∂f/∂p` at `(t, x, u)` written into `out` (`n_states × n_parameters`, already
    /// sized).
    fn parameter_jacobian(&self, t: f64, x: &[f64], u: &[f64], out: &mut DMatrix<f64>);
}

fn expression(place: String, text: &str) -> impl FnOnce(ExprError) -> PhysicalError + '_ {
    move |source| PhysicalError::Expression {
        place,
        text: text.to_owned(),
        source,
    }
}

/// Every nonzero symbolic partial of `expr` times `coefficient`, into `row`.
fn partials_of(
    expr: &Expr,
    row: usize,
    coefficient: f64,
    out: &mut Vec<Partial>,
) -> Result<(), ExprError> {
    for var in expr.variables_used() {
        let d = expr.derivative(var)?;
        if d.constant().is_some_and(|c| c.abs() == 0.0) {
            continue;
        }
        out.push(Partial {
            row,
            var,
            coefficient,
            expr: d,
        });
    }
    Ok(())
}

fn check_parameter(p: &Parameter) -> Result<(), PhysicalError> {
    let bad = |why| PhysicalError::BadParameter {
        name: p.name.clone(),
        value: p.value,
        lower: p.lower,
        upper: p.upper,
        why,
    };
    if !p.value.is_finite() {
        return Err(bad("the value is not finite"));
    }
    if p.lower.is_nan() || p.upper.is_nan() || p.lower > p.upper {
        return Err(bad("the bounds are not an interval"));
    }
    if p.value < p.lower || p.value > p.upper {
        return Err(bad("the value is outside its bounds"));
    }
    Ok(())
}

impl PhysicalModel {
    /// Build from the linear part (`A`, `B`, `C`, `E` and the names), the parameters, the
    /// terms (expressions over [`PhysicalModel::variables`]) and the optional mechanics.
    pub fn new(
        linear: LinearModel,
        parameters: Vec<Parameter>,
        terms: &[PhysicalTerm<'_>],
        mechanics: Option<MechanicsSpec<'_>>,
    ) -> Result<Self, PhysicalError> {
        let n = linear.n_states();
        let mut variables: Vec<String> = linear.state_names().to_vec();
        variables.extend(linear.input_names().iter().cloned());
        for (k, p) in parameters.iter().enumerate() {
            let with = if linear.state_names().contains(&p.name) {
                Some("state")
            } else if linear.input_names().contains(&p.name) {
                Some("input")
            } else if parameters[..k].iter().any(|o| o.name == p.name) {
                Some("parameter")
            } else {
                None
            };
            if let Some(with) = with {
                return Err(PhysicalError::NameClash {
                    name: p.name.clone(),
                    with,
                });
            }
            check_parameter(p)?;
            variables.push(p.name.clone());
        }
        let names: Vec<&str> = variables.iter().map(String::as_str).collect();

        let mechanics = match mechanics {
            Some(spec) => Some(compile_mechanics(&linear, spec, &names)?),
            None => None,
        };
        let rate_of = |s: usize| mechanics.as_ref().and_then(|m| m.rate_of[s]);

        let mut compiled = Vec::with_capacity(terms.len());
        let mut direct = Vec::new();
        let mut force_partials = Vec::new();
        for (index, t) in terms.iter().enumerate() {
            let bad = |why: String| PhysicalError::BadTerm {
                index,
                effect: t.effect.to_owned(),
                why,
            };
            if t.state >= n {
                return Err(bad(format!("state index {} is out of range", t.state)));
            }
            if let Some(r) = t.into
                && (r == t.state || r >= n)
            {
                return Err(bad(format!(
                    "transfer target {r} must differ from {} and be below {n}",
                    t.state
                )));
            }
            if !t.coefficient.is_finite() {
                return Err(bad(format!("coefficient {} is not finite", t.coefficient)));
            }
            let place = format!("terms[{index}] ({})", t.effect);
            let expr = Expr::parse(t.term, &names).map_err(expression(place.clone(), t.term))?;
            for (row, sign) in std::iter::once((t.state, 1.0)).chain(t.into.map(|r| (r, -1.0))) {
                let (target, out) = match rate_of(row) {
                    Some(i) => (i, &mut force_partials),
                    None => (row, &mut direct),
                };
                partials_of(&expr, target, sign * t.coefficient, out)
                    .map_err(expression(place.clone(), t.term))?;
            }
            compiled.push(ParamTerm {
                state: t.state,
                into: t.into,
                effect: t.effect.to_owned(),
                expr,
                coefficient: t.coefficient,
            });
        }
        let mechanics = mechanics.map(|mut m| {
            m.dforce.extend(force_partials);
            m.dforce.sort_by_key(|p| p.var);
            m.dmass.sort_by_key(|p| p.var);
            let mut vars: Vec<usize> = m.dforce.iter().chain(&m.dmass).map(|p| p.var).collect();
            vars.sort_unstable();
            vars.dedup();
            m.vars = vars;
            m
        });
        let values = parameters.iter().map(|p| p.value).collect();
        Ok(Self {
            linear,
            parameters,
            values,
            variables,
            terms: compiled,
            direct,
            mechanics,
        })
    }

    /// The linear part (names, `A`, `B`, `C`, `E`).
    pub fn linear(&self) -> &LinearModel {
        &self.linear
    }

    /// The variable names of every expression: states, inputs, parameters.
    pub fn variables(&self) -> &[String] {
        &self.variables
    }

    /// Whether the model has a mass-matrix part.
    pub fn is_mechanical(&self) -> bool {
        self.mechanics.is_some()
    }

    /// State indices of the mechanics part's coordinates `q` and of their rates `q̇`, in
    /// coordinate order (`None` without a mechanics part).
    pub fn mechanics_states(&self) -> Option<(&[usize], &[usize])> {
        self.mechanics
            .as_ref()
            .map(|m| (m.q.as_slice(), m.v.as_slice()))
    }

    /// The mass matrix `M(q)` at state `x` and inputs `u`, row-major into `m[..n·n]` for
    /// `n` coordinates; returns `n`. `None` (nothing written) without a mechanics part or
    /// when `m` holds fewer than `n·n` entries. Maps an acceleration into the generalized
    /// force that causes it: `Q = M(q)·q̈`.
    pub fn mass_matrix(&self, x: &[f64], u: &[f64], m: &mut [f64]) -> Option<usize> {
        let mech = self.mechanics.as_ref()?;
        let n = mech.q.len();
        let out = m.get_mut(..n * n)?;
        for (slot, e) in out.iter_mut().zip(&mech.mass) {
            *slot = e.eval3(x, u, &self.values);
        }
        Some(n)
    }

    /// The model as a [`TermModel`] with the parameter values substituted, when it has no
    /// mechanics part (`None` otherwise: `M⁻¹` is not a sum of named terms).
    pub fn term_model(&self) -> Option<Result<TermModel, crate::TermError>> {
        if self.mechanics.is_some() {
            return None;
        }
        let n_xu = self.linear.n_states() + self.linear.n_inputs();
        let mut values: Vec<Option<f64>> = vec![None; n_xu];
        values.extend(self.values.iter().map(|v| Some(*v)));
        let short: Vec<&str> = self.variables[..n_xu].iter().map(String::as_str).collect();
        let mut terms = Vec::with_capacity(self.terms.len());
        for (index, t) in self.terms.iter().enumerate() {
            let expr = match t.expr.substitute(&values).with_variables(&short) {
                Ok(e) => e,
                Err(source) => {
                    return Some(Err(crate::TermError::Expression {
                        index,
                        effect: t.effect.clone(),
                        text: t.expr.to_string(),
                        source,
                    }));
                }
            };
            terms.push(Term {
                state: t.state,
                into: t.into,
                effect: t.effect.clone(),
                expr,
                coefficient: t.coefficient,
            });
        }
        Some(TermModel::new(self.linear.clone(), terms))
    }

    /// Mass matrix (row-major into `m`) and total generalized force (into `f`): forces
    /// plus the terms on rate equations.
    fn mass_and_force(&self, mech: &Mechanics, x: &[f64], u: &[f64], m: &mut [f64], f: &mut [f64]) {
        let p = &self.values;
        for (slot, e) in m.iter_mut().zip(&mech.mass) {
            *slot = e.eval3(x, u, p);
        }
        for (slot, e) in f.iter_mut().zip(&mech.forces) {
            *slot = e.eval3(x, u, p);
        }
        for t in &self.terms {
            let v = t.coefficient * t.expr.eval3(x, u, p);
            if let Some(i) = mech.rate_of[t.state] {
                f[i] += v;
            }
            if let Some(r) = t.into
                && let Some(i) = mech.rate_of[r]
            {
                f[i] -= v;
            }
        }
    }

    /// Accelerations `a = M⁻¹F` and the factor of `M`.
    fn accelerations(&self, mech: &Mechanics, x: &[f64], u: &[f64]) -> (SmallLu, [f64; MAX_DOF]) {
        let n = mech.q.len();
        let mut m = [0.0; MAX_DOF * MAX_DOF];
        let mut a = [0.0; MAX_DOF];
        self.mass_and_force(mech, x, u, &mut m[..n * n], &mut a[..n]);
        let lu = SmallLu::factor(&m, n);
        lu.solve(&mut a);
        (lu, a)
    }

    /// Add `∂f/∂z` for every variable `z` in `[from, to)` into `out(row, z)`.
    fn add_partials(
        &self,
        x: &[f64],
        u: &[f64],
        from: usize,
        to: usize,
        mut out: impl FnMut(usize, usize, f64),
    ) {
        let p = &self.values;
        for d in &self.direct {
            if (from..to).contains(&d.var) {
                out(d.row, d.var, d.coefficient * d.expr.eval3(x, u, p));
            }
        }
        let Some(mech) = &self.mechanics else {
            return;
        };
        let n = mech.q.len();
        if from == 0 {
            for (&qi, &vi) in mech.q.iter().zip(&mech.v) {
                out(qi, vi, 1.0);
            }
        }
        let (lu, a) = self.accelerations(mech, x, u);
        let (mut fi, mut mi) = (0, 0);
        for &z in &mech.vars {
            while fi < mech.dforce.len() && mech.dforce[fi].var < z {
                fi += 1;
            }
            while mi < mech.dmass.len() && mech.dmass[mi].var < z {
                mi += 1;
            }
            if !(from..to).contains(&z) {
                continue;
            }
            // r = ∂F/∂z − (∂M/∂z)·a, then ∂a/∂z = M⁻¹ r.
            let mut r = [0.0; MAX_DOF];
            for d in mech.dforce[fi..].iter().take_while(|d| d.var == z) {
                r[d.row] += d.coefficient * d.expr.eval3(x, u, p);
            }
            for d in mech.dmass[mi..].iter().take_while(|d| d.var == z) {
                let (i, j) = (d.row / n, d.row % n);
                r[i] -= d.coefficient * d.expr.eval3(x, u, p) * a[j];
            }
            lu.solve(&mut r);
            for (i, &vi) in mech.v.iter().enumerate() {
                out(vi, z, r[i]);
            }
        }
    }
}

fn compile_mechanics(
    linear: &LinearModel,
    spec: MechanicsSpec<'_>,
    names: &[&str],
) -> Result<Mechanics, PhysicalError> {
    let states = linear.state_names();
    let n = spec.q.len();
    if n > MAX_DOF {
        return Err(PhysicalError::TooManyCoordinates { n, max: MAX_DOF });
    }
    if spec.qdot.len() != n {
        return Err(PhysicalError::Shape {
            key: "qdot",
            found: format!("{} names", spec.qdot.len()),
            expected: format!("{n} (one per coordinate)"),
        });
    }
    let mut seen: Vec<usize> = Vec::with_capacity(2 * n);
    let mut index = |key: &'static str, name: &String| -> Result<usize, PhysicalError> {
        let coordinate = |why| PhysicalError::Coordinate {
            key,
            name: name.clone(),
            why,
        };
        let i = states
            .iter()
            .position(|s| s == name)
            .ok_or(coordinate("is not a state"))?;
        if seen.contains(&i) {
            return Err(coordinate("is used twice in q and qdot"));
        }
        seen.push(i);
        Ok(i)
    };
    let q = spec
        .q
        .iter()
        .map(|s| index("q", s))
        .collect::<Result<Vec<_>, _>>()?;
    let v = spec
        .qdot
        .iter()
        .map(|s| index("qdot", s))
        .collect::<Result<Vec<_>, _>>()?;
    if spec.mass.len() != n {
        return Err(PhysicalError::Shape {
            key: "mass",
            found: format!("{} rows", spec.mass.len()),
            expected: format!("{n} (one per coordinate)"),
        });
    }
    if spec.forces.len() != n {
        return Err(PhysicalError::Shape {
            key: "forces",
            found: format!("{} expressions", spec.forces.len()),
            expected: format!("{n} (one per coordinate)"),
        });
    }
    let mut mass = Vec::with_capacity(n * n);
    let mut dmass = Vec::new();
    for (i, row) in spec.mass.iter().enumerate() {
        if row.len() != n {
            return Err(PhysicalError::Shape {
                key: "mass",
                found: format!("{} entries in row {i}", row.len()),
                expected: format!("{n}"),
            });
        }
        for (j, text) in row.iter().enumerate() {
            let place = format!("mechanics.mass[{i}][{j}]");
            let e = Expr::parse(text, names).map_err(expression(place.clone(), text))?;
            partials_of(&e, i * n + j, 1.0, &mut dmass).map_err(expression(place, text))?;
            mass.push(e);
        }
    }
    for i in 0..n {
        for j in 0..i {
            if mass[i * n + j] != mass[j * n + i] {
                return Err(PhysicalError::Asymmetric {
                    row: i,
                    col: j,
                    a: spec.mass[i][j].clone(),
                    b: spec.mass[j][i].clone(),
                });
            }
        }
    }
    let mut forces = Vec::with_capacity(n);
    let mut dforce = Vec::new();
    for (i, text) in spec.forces.iter().enumerate() {
        let place = format!("mechanics.forces[{i}]");
        let e = Expr::parse(text, names).map_err(expression(place.clone(), text))?;
        partials_of(&e, i, 1.0, &mut dforce).map_err(expression(place, text))?;
        forces.push(e);
    }
    let mut rate_of = vec![None; states.len()];
    for (i, &vi) in v.iter().enumerate() {
        rate_of[vi] = Some(i);
    }
    Ok(Mechanics {
        q,
        v,
        mass,
        forces,
        dmass,
        dforce,
        vars: Vec::new(),
        rate_of,
    })
}

impl Dynamics for PhysicalModel {
    fn n_states(&self) -> usize {
        self.linear.n_states()
    }

    fn n_inputs(&self) -> usize {
        self.linear.n_inputs()
    }

    fn rhs(&self, t: f64, x: &[f64], u: &[f64], dx: &mut [f64]) {
        self.linear.rhs(t, x, u, dx);
        let p = &self.values;
        let rate = |s: usize| self.mechanics.as_ref().and_then(|m| m.rate_of[s]);
        for term in &self.terms {
            let v = term.coefficient * term.expr.eval3(x, u, p);
            if rate(term.state).is_none() {
                dx[term.state] += v;
            }
            if let Some(r) = term.into
                && rate(r).is_none()
            {
                dx[r] -= v;
            }
        }
        if let Some(mech) = &self.mechanics {
            let (_, a) = self.accelerations(mech, x, u);
            for (i, (&qi, &vi)) in mech.q.iter().zip(&mech.v).enumerate() {
                dx[qi] += x[vi];
                dx[vi] += a[i];
            }
        }
    }

    fn jacobians(&self, t: f64, x: &[f64], u: &[f64], a: &mut DMatrix<f64>, b: &mut DMatrix<f64>) {
        self.linear.jacobians(t, x, u, a, b);
        let n = self.linear.n_states();
        let nu = self.linear.n_inputs();
        self.add_partials(x, u, 0, n + nu, |row, z, v| {
            if z < n {
                a[(row, z)] += v;
            } else {
                b[(row, z - n)] += v;
            }
        });
    }
}

impl ParametricDynamics for PhysicalModel {
    fn parameters(&self) -> &[Parameter] {
        &self.parameters
    }

    fn with_parameters(&self, values: &[f64]) -> Result<Self, PhysicalError> {
        if values.len() != self.parameters.len() {
            return Err(PhysicalError::ParameterCount {
                found: values.len(),
                expected: self.parameters.len(),
            });
        }
        let mut out = self.clone();
        for (p, &v) in out.parameters.iter_mut().zip(values) {
            p.value = v;
            check_parameter(p)?;
        }
        out.values = values.to_vec();
        Ok(out)
    }

    fn parameter_jacobian(&self, _t: f64, x: &[f64], u: &[f64], out: &mut DMatrix<f64>) {
        out.fill(0.0);
        let first = self.linear.n_states() + self.linear.n_inputs();
        let end = first + self.parameters.len();
        self.add_partials(x, u, first, end, |row, z, v| out[(row, z - first)] += v);
    }
}
