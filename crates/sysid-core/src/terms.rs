//! Named nonlinear terms of a model file (`[[terms]]`, SPEC §5) and the model they form
//! with the assumed linear part: `ẋ = A x + B u + Σ_k c_k·g_k(x, u)·e_{s_k}`, where term
//! `k` adds its coefficient `c_k` times its expression `g_k` to state equation `s_k`.
//!
//! A term may also be a **transfer** (`into`): the same flow `c_k·g_k` leaves equation
//! `s_k` and enters equation `into` with the opposite sign, so what one state loses
//! another gains (the outflow of an upper tank is the inflow of the lower one) under one
//! coefficient.
//!
//! The variables of every term expression are the model's **state names followed by its
//! input names**: index `i < n` is state `i`, index `n + j` is input `j`
//! ([`term_variables`]).

use nalgebra::DMatrix;
use thiserror::Error;

use crate::dynamics::Dynamics;
use crate::expr::{Expr, ExprError};
use crate::linear::LinearModel;

/// Errors building a [`TermModel`]; each names the offending term by its position in the
/// list (0-based) and its effect name.
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum TermError {
    /// The term's `state` is not a state of the model.
    #[error("term {index} ({effect}): unknown state '{state}' (states: {})", .known.join(", "))]
    UnknownState {
        /// Position of the term.
        index: usize,
        /// Its effect name.
        effect: String,
        /// The state name given.
        state: String,
        /// The model's state names.
        known: Vec<String>,
    },
    /// The term's state index is out of range.
    #[error("term {index} ({effect}): state index {state} is out of range for {n_states} states")]
    StateIndex {
        /// Position of the term.
        index: usize,
        /// Its effect name.
        effect: String,
        /// The state index given.
        state: usize,
        /// Number of states of the model.
        n_states: usize,
    },
    /// A transfer term's `into` is its own equation or out of range.
    #[error(
        "term {index} ({effect}): transfer into state index {into} must differ from its own \
         equation {state} and be below {n_states}"
    )]
    TransferTarget {
        /// Position of the term.
        index: usize,
        /// Its effect name.
        effect: String,
        /// The term's own equation.
        state: usize,
        /// The equation it transfers into.
        into: usize,
        /// Number of states of the model.
        n_states: usize,
    },
    /// The coefficient is NaN or infinite.
    #[error("term {index} ({effect}): coefficient {value} is not finite")]
    NonFiniteCoefficient {
        /// Position of the term.
        index: usize,
        /// Its effect name.
        effect: String,
        /// The coefficient given.
        value: f64,
    },
    /// The term's expression does not parse, or uses a name that is neither a state nor an
    /// input of the model.
    #[error("term {index} ({effect}) '{text}': {source}")]
    Expression {
        /// Position of the term.
        index: usize,
        /// Its effect name.
        effect: String,
        /// The expression text.
        text: String,
        /// What is wrong with it (with the column).
        source: ExprError,
    },
}

/// One named nonlinear term: `coefficient · expr(x, u)` added to the right-hand side of
/// state equation `state` (and, for a transfer, subtracted from equation `into`).
#[derive(Debug, Clone, PartialEq)]
pub struct Term {
    /// Index of the state equation it enters.
    pub state: usize,
    /// For a transfer: the equation that receives the negated term (what `state` loses,
    /// `into` gains). `None` for an ordinary term.
    pub into: Option<usize>,
    /// Catalogue name of the effect (e.g. `coulomb_friction`).
    pub effect: String,
    /// The term, over the model's state names followed by its input names.
    pub expr: Expr,
    /// Its coefficient.
    pub coefficient: f64,
}

impl Term {
    /// `coefficient · expr(x, u)`.
    pub fn eval(&self, x: &[f64], u: &[f64]) -> f64 {
        self.coefficient * self.expr.eval_parts(x, u)
    }

    /// Add the term to a right-hand side `dx`: `+value` to its equation and, for a
    /// transfer, `−value` to the receiving one.
    pub fn add_to(&self, x: &[f64], u: &[f64], dx: &mut [f64]) {
        self.add_scaled(self.expr.eval_parts(x, u), dx);
    }

    /// Add `coefficient·g` to equation `state` (and subtract it from `into`): the term
    /// at an already evaluated basis value `g`, for callers that vary coefficients.
    pub fn add_scaled(&self, g: f64, dx: &mut [f64]) {
        let v = self.coefficient * g;
        dx[self.state] += v;
        if let Some(into) = self.into {
            dx[into] -= v;
        }
    }
}

/// A term as written in a model file: state name, effect, expression text, coefficient,
/// and for a transfer the receiving state.
///
/// A tuple `(state, effect, term, coefficient)` converts into an ordinary term.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TermSpec<'a> {
    /// Name of the state equation it enters.
    pub state: &'a str,
    /// For a transfer: name of the state equation that receives the negated term.
    pub into: Option<&'a str>,
    /// Catalogue name of the effect.
    pub effect: &'a str,
    /// The expression text, in state and input names.
    pub term: &'a str,
    /// Its coefficient.
    pub coefficient: f64,
}

impl<'a> From<(&'a str, &'a str, &'a str, f64)> for TermSpec<'a> {
    fn from((state, effect, term, coefficient): (&'a str, &'a str, &'a str, f64)) -> Self {
        Self {
            state,
            into: None,
            effect,
            term,
            coefficient,
        }
    }
}

/// The variable names of term expressions for `linear`: its state names, then its input
/// names.
pub fn term_variables(linear: &LinearModel) -> Vec<&str> {
    linear
        .state_names()
        .iter()
        .chain(linear.input_names())
        .map(String::as_str)
        .collect()
}

/// One precompiled nonzero partial derivative `coefficient · ∂expr/∂var` of a term.
#[derive(Debug, Clone)]
struct Partial {
    row: usize,
    var: usize,
    coefficient: f64,
    expr: Expr,
}

/// The assumed linear model plus named nonlinear terms, as a [`Dynamics`]:
/// `f(x, u) = A x + B u + Σ_k c_k·g_k(x, u)·(e_{s_k} − e_{r_k})` (`e_{r_k}` only for a
/// transfer into `r_k`), with analytic Jacobians
/// `∂f/∂x = A + Σ_k c_k·(e_{s_k} − e_{r_k})·∂g_k/∂x` and likewise for `∂f/∂u`
/// (derivatives precompiled; evaluation allocates nothing).
///
/// ```
/// use nalgebra::DMatrix;
/// use sysid_core::{Dynamics, LinearModel, ModelNames, TermModel};
///
/// let names = ModelNames {
///     states: vec!["theta".into(), "omega".into()],
///     inputs: vec!["u".into()],
///     outputs: vec!["theta".into()],
///     corrections: vec!["d".into()],
/// };
/// let a = DMatrix::from_row_slice(2, 2, &[0.0, 1.0, -9.81, 0.0]);
/// let b = DMatrix::from_row_slice(2, 1, &[0.0, 1.0]);
/// let c = DMatrix::from_row_slice(1, 2, &[1.0, 0.0]);
/// let e = DMatrix::from_row_slice(2, 1, &[0.0, 1.0]);
/// let linear = LinearModel::with_names(a, b, c, e, names)?;
/// // The pendulum's gravity nonlinearity: −9.81·(sin θ − θ) on the ω equation.
/// let model = TermModel::from_specs(linear, [("omega", "gravity", "sin(theta) - theta", -9.81)])?;
/// let mut dx = [0.0; 2];
/// model.rhs(0.0, &[0.5, 0.0], &[0.0], &mut dx);
/// assert!((dx[1] + 9.81 * 0.5_f64.sin()).abs() < 1e-12);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[derive(Debug, Clone)]
pub struct TermModel {
    linear: LinearModel,
    terms: Vec<Term>,
    partials: Vec<Partial>,
}

impl TermModel {
    /// Combine a linear model with terms. Each term's state index must be in range, its
    /// coefficient finite, and every variable its expression uses must be a state or input
    /// name of `linear` (expressions are re-bound by name to [`term_variables`], so they
    /// may have been parsed over fewer names).
    pub fn new(linear: LinearModel, terms: Vec<Term>) -> Result<Self, TermError> {
        let n = linear.n_states();
        let variables = term_variables(&linear);
        let mut bound = Vec::with_capacity(terms.len());
        let mut partials = Vec::new();
        for (index, term) in terms.into_iter().enumerate() {
            let Term {
                state,
                into,
                effect,
                expr,
                coefficient,
            } = term;
            if state >= n {
                return Err(TermError::StateIndex {
                    index,
                    effect,
                    state,
                    n_states: n,
                });
            }
            if let Some(into) = into
                && (into == state || into >= n)
            {
                return Err(TermError::TransferTarget {
                    index,
                    effect,
                    state,
                    into,
                    n_states: n,
                });
            }
            if !coefficient.is_finite() {
                return Err(TermError::NonFiniteCoefficient {
                    index,
                    effect,
                    value: coefficient,
                });
            }
            let expression_error = |effect: &str, expr: &Expr, source| TermError::Expression {
                index,
                effect: effect.to_owned(),
                text: expr.to_string(),
                source,
            };
            let expr = if expr
                .variables()
                .iter()
                .map(String::as_str)
                .eq(variables.iter().copied())
            {
                expr
            } else {
                expr.with_variables(&variables)
                    .map_err(|e| expression_error(&effect, &expr, e))?
            };
            for var in expr.variables_used() {
                let d = expr
                    .derivative(var)
                    .map_err(|e| expression_error(&effect, &expr, e))?;
                if d.constant().is_some_and(|c| c.abs() == 0.0) {
                    continue;
                }
                if let Some(into) = into {
                    partials.push(Partial {
                        row: into,
                        var,
                        coefficient: -coefficient,
                        expr: d.clone(),
                    });
                }
                partials.push(Partial {
                    row: state,
                    var,
                    coefficient,
                    expr: d,
                });
            }
            bound.push(Term {
                state,
                into,
                effect,
                expr,
                coefficient,
            });
        }
        Ok(Self {
            linear,
            terms: bound,
            partials,
        })
    }

    /// Build from model-file terms: state name, effect, expression text and coefficient
    /// (tuples `(state, effect, term, coefficient)` work too). Errors name the term.
    pub fn from_specs<'a, I, S>(linear: LinearModel, specs: I) -> Result<Self, TermError>
    where
        I: IntoIterator<Item = S>,
        S: Into<TermSpec<'a>>,
    {
        let variables = term_variables(&linear);
        let mut terms = Vec::new();
        for (index, spec) in specs.into_iter().enumerate() {
            let spec: TermSpec<'a> = spec.into();
            let effect = spec.effect.to_owned();
            let position = |name: &str| {
                linear
                    .state_names()
                    .iter()
                    .position(|s| s == name)
                    .ok_or_else(|| TermError::UnknownState {
                        index,
                        effect: effect.clone(),
                        state: name.to_owned(),
                        known: linear.state_names().to_vec(),
                    })
            };
            let state = position(spec.state)?;
            let into = spec.into.map(position).transpose()?;
            let expr =
                Expr::parse(spec.term, &variables).map_err(|source| TermError::Expression {
                    index,
                    effect: effect.clone(),
                    text: spec.term.to_owned(),
                    source,
                })?;
            terms.push(Term {
                state,
                into,
                effect,
                expr,
                coefficient: spec.coefficient,
            });
        }
        Self::new(linear, terms)
    }

    /// The linear part.
    pub fn linear(&self) -> &LinearModel {
        &self.linear
    }

    /// The terms, with expressions over [`term_variables`] of the linear part.
    pub fn terms(&self) -> &[Term] {
        &self.terms
    }

    /// The linear part and the terms.
    pub fn into_parts(self) -> (LinearModel, Vec<Term>) {
        (self.linear, self.terms)
    }

    /// The nonlinear part only, `Σ_k c_k·g_k(x, u)·e_{s_k}`, written into `out` (`n` long).
    pub fn nonlinear_rhs(&self, x: &[f64], u: &[f64], out: &mut [f64]) {
        out.iter_mut().for_each(|v| *v = 0.0);
        for term in &self.terms {
            term.add_to(x, u, out);
        }
    }
}

impl Dynamics for TermModel {
    fn n_states(&self) -> usize {
        self.linear.n_states()
    }

    fn n_inputs(&self) -> usize {
        self.linear.n_inputs()
    }

    fn rhs(&self, t: f64, x: &[f64], u: &[f64], dx: &mut [f64]) {
        self.linear.rhs(t, x, u, dx);
        for term in &self.terms {
            term.add_to(x, u, dx);
        }
    }

    fn jacobians(&self, t: f64, x: &[f64], u: &[f64], a: &mut DMatrix<f64>, b: &mut DMatrix<f64>) {
        self.linear.jacobians(t, x, u, a, b);
        let n = self.linear.n_states();
        for p in &self.partials {
            let v = p.coefficient * p.expr.eval_parts(x, u);
            if p.var < n {
                a[(p.row, p.var)] += v;
            } else {
                b[(p.row, p.var - n)] += v;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::linear::ModelNames;

    /// States (theta, omega), input u; A, B arbitrary but fixed.
    fn pendulum() -> LinearModel {
        let names = ModelNames {
            states: vec!["theta".into(), "omega".into()],
            inputs: vec!["u".into()],
            outputs: vec!["theta".into()],
            corrections: vec!["d".into()],
        };
        let a = DMatrix::from_row_slice(2, 2, &[0.0, 1.0, -9.81, -0.1]);
        let b = DMatrix::from_row_slice(2, 1, &[0.0, 1.0]);
        let c = DMatrix::from_row_slice(1, 2, &[1.0, 0.0]);
        let e = DMatrix::from_row_slice(2, 1, &[0.0, 1.0]);
        LinearModel::with_names(a, b, c, e, names).unwrap_or_else(|e| panic!("{e}"))
    }

    fn build(specs: &[(&str, &str, &str, f64)]) -> Result<TermModel, TermError> {
        TermModel::from_specs(pendulum(), specs.iter().copied())
    }

    #[test]
    fn unknown_state_names_the_term() {
        let r = build(&[
            ("omega", "drag", "omega^2", 1.0),
            ("phi", "coulomb", "sign(omega)", 1.0),
        ]);
        assert_eq!(
            r.err(),
            Some(TermError::UnknownState {
                index: 1,
                effect: "coulomb".into(),
                state: "phi".into(),
                known: vec!["theta".into(), "omega".into()],
            })
        );
    }

    #[test]
    fn non_finite_coefficients_are_rejected() {
        for value in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
            let r = build(&[("omega", "drag", "omega*abs(omega)", value)]);
            assert!(
                matches!(r, Err(TermError::NonFiniteCoefficient { index: 0, ref effect, value: v })
                    if effect == "drag" && v.to_bits() == value.to_bits()),
                "{value}: {r:?}"
            );
        }
    }

    #[test]
    fn expression_errors_name_the_term_and_column() {
        let r = build(&[
            ("omega", "ok", "u", 1.0),
            ("theta", "typo", "sin(thta)", 1.0),
        ]);
        let Err(TermError::Expression {
            index,
            effect,
            text,
            source,
        }) = r
        else {
            panic!("{r:?}");
        };
        assert_eq!(
            (index, effect.as_str(), text.as_str()),
            (1, "typo", "sin(thta)")
        );
        assert!(
            matches!(source, ExprError::UnknownName { column: 4, ref name, .. } if name == "thta")
        );
        let r = build(&[("omega", "open", "(omega", 1.0)]);
        assert!(matches!(
            r,
            Err(TermError::Expression {
                source: ExprError::UnclosedParenthesis { column: 0 },
                ..
            })
        ));
    }

    #[test]
    fn prebuilt_terms_are_checked_and_rebound_by_name() {
        let expr = Expr::parse("u*cos(theta)", &["u", "theta"]).unwrap_or_else(|e| panic!("{e}"));
        let term = |state| Term {
            state,
            into: None,
            effect: "coupling".into(),
            expr: expr.clone(),
            coefficient: 2.0,
        };
        let r = TermModel::new(pendulum(), vec![term(2)]);
        assert!(matches!(
            r,
            Err(TermError::StateIndex {
                index: 0,
                state: 2,
                n_states: 2,
                ..
            })
        ));
        let model = TermModel::new(pendulum(), vec![term(1)]).unwrap_or_else(|e| panic!("{e}"));
        let bound = &model.terms()[0].expr;
        assert_eq!(bound.variables(), ["theta", "omega", "u"]);
        assert_eq!(bound.variables_used(), vec![0, 2]);
        let (x, u) = ([0.4, -1.0], [3.0]);
        assert!((model.terms()[0].eval(&x, &u) - 2.0 * 3.0 * 0.4_f64.cos()).abs() < 1e-15);
        // A variable the model does not have.
        let foreign = Expr::parse("h1^2", &["h1"]).unwrap_or_else(|e| panic!("{e}"));
        let r = TermModel::new(
            pendulum(),
            vec![Term {
                state: 0,
                into: None,
                effect: "tank".into(),
                expr: foreign,
                coefficient: 1.0,
            }],
        );
        assert!(matches!(
            r,
            Err(TermError::Expression {
                index: 0,
                source: ExprError::MissingVariable { .. },
                ..
            })
        ));
    }

    #[test]
    fn constant_terms_add_no_jacobian_entries() {
        let model = build(&[("omega", "bias", "0.2", 1.5)]).unwrap_or_else(|e| panic!("{e}"));
        assert!(model.partials.is_empty());
        let mut n = [9.0; 2];
        model.nonlinear_rhs(&[1.0, 2.0], &[3.0], &mut n);
        assert_eq!(n.map(f64::to_bits), [0.0, 0.2 * 1.5].map(f64::to_bits));
    }

    /// Two tanks, states (h1, h2): a transfer term is one flow under one coefficient —
    /// it moves exactly its value from one equation to the other, its Jacobian matches
    /// central differences, and bad targets are errors naming the term.
    #[test]
    fn transfer_terms_move_flow_between_equations() {
        let names = ModelNames {
            states: vec!["h1".into(), "h2".into()],
            inputs: vec!["u".into()],
            outputs: vec!["h1".into(), "h2".into()],
            corrections: vec!["d1".into(), "d2".into()],
        };
        let a = DMatrix::from_row_slice(2, 2, &[-0.06, 0.0, 0.06, -0.08]);
        let b = DMatrix::from_row_slice(2, 1, &[0.003, 0.0]);
        let linear = LinearModel::with_names(
            a,
            b,
            DMatrix::identity(2, 2),
            DMatrix::identity(2, 2),
            names,
        )
        .unwrap_or_else(|e| panic!("{e}"));
        let spec = |into| TermSpec {
            state: "h1",
            into,
            effect: "orifice_outflow",
            term: "sqrt(abs(h1))",
            coefficient: -0.03,
        };
        let model = TermModel::from_specs(linear.clone(), [spec(Some("h2"))])
            .unwrap_or_else(|e| panic!("{e}"));
        let (x, u) = ([0.3, 0.2], [5.0]);
        let mut with = [0.0; 2];
        let mut without = [0.0; 2];
        model.rhs(0.0, &x, &u, &mut with);
        linear.rhs(0.0, &x, &u, &mut without);
        let flow = -0.03 * 0.3_f64.sqrt();
        assert!((with[0] - without[0] - flow).abs() < 1e-15);
        assert!((with[1] - without[1] + flow).abs() < 1e-15);
        // Jacobian against central differences: step 1e-6, truncation O(h²) ≈ 1e-12 here,
        // rounding ≈ 1e-16/1e-6 = 1e-10.
        let mut ja = DMatrix::zeros(2, 2);
        let mut jb = DMatrix::zeros(2, 1);
        model.jacobians(0.0, &x, &u, &mut ja, &mut jb);
        let h = 1e-6;
        for j in 0..2 {
            let (mut xp, mut xm) = (x, x);
            xp[j] += h;
            xm[j] -= h;
            let (mut fp, mut fm) = ([0.0; 2], [0.0; 2]);
            model.rhs(0.0, &xp, &u, &mut fp);
            model.rhs(0.0, &xm, &u, &mut fm);
            for i in 0..2 {
                let fd = (fp[i] - fm[i]) / (2.0 * h);
                assert!(
                    (ja[(i, j)] - fd).abs() < 1e-8,
                    "({i},{j}) {} vs {fd}",
                    ja[(i, j)]
                );
            }
        }
        let r = TermModel::from_specs(linear.clone(), [spec(Some("h3"))]);
        assert!(
            matches!(r, Err(TermError::UnknownState { index: 0, ref state, .. }) if state == "h3")
        );
        let r = TermModel::from_specs(linear, [spec(Some("h1"))]);
        assert!(matches!(
            r,
            Err(TermError::TransferTarget {
                index: 0,
                state: 0,
                into: 0,
                ..
            })
        ));
    }
}
