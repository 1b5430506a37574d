//! A set of candidate terms over an assumed model: the candidate type the free-run
//! search (`crate::refine`) and its screening (`crate::screen`) share, and the model a
//! set of them makes.

use serde::{Deserialize, Serialize};
use sysid_core::{TermModel, TermSpec};

use crate::error::Result;

/// A candidate term for the free-run search.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RefineCandidate {
    /// Effect name.
    pub effect: String,
    /// Equation (state name) it enters.
    pub state: String,
    /// For a transfer: the equation (state name) that receives the negated term — one
    /// coefficient for a flow that leaves `state` and enters `into` (see
    /// [`sysid_core::Term::into`]). `None` for an ordinary term.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub into: Option<String>,
    /// Integrable expression (model form).
    pub term: String,
    /// Starting coefficient (e.g. from the regression on `d̂`; 0 if unknown).
    pub coefficient: f64,
    /// The variables the effect's template reads, in slot order (see
    /// [`crate::Effect::template`]); empty when unknown. With `parameters`, lets the
    /// search re-write the term for other parameter values.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub variables: Vec<String>,
    /// The term's parameter values (thresholds, velocity scales) in
    /// [`crate::Effect::parameters`] order; empty when it has none or they are unknown.
    /// The search calibrates the ones that shape the term (see the `polish` module).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub parameters: Vec<f64>,
}

/// `base` plus the candidates of `set`, at their `coefficient`s.
pub(crate) fn build(
    base: &TermModel,
    candidates: &[RefineCandidate],
    set: &[usize],
) -> Result<TermModel> {
    let names = base.linear().state_names();
    let mut specs: Vec<(String, Option<String>, String, String, f64)> = base
        .terms()
        .iter()
        .map(|t| {
            (
                names[t.state].clone(),
                t.into.map(|r| names[r].clone()),
                t.effect.clone(),
                t.expr.to_string(),
                t.coefficient,
            )
        })
        .collect();
    for &i in set {
        let c = &candidates[i];
        specs.push((
            c.state.clone(),
            c.into.clone(),
            c.effect.clone(),
            c.term.clone(),
            c.coefficient,
        ));
    }
    Ok(TermModel::from_specs(
        base.linear().clone(),
        specs.iter().map(|(s, r, e, t, k)| TermSpec {
            state: s,
            into: r.as_deref(),
            effect: e,
            term: t,
            coefficient: *k,
        }),
    )?)
}
