//! What the workflow reports: named effects, the assumed entries linear terms adjust,
//! rounds, ambiguities.

use std::collections::BTreeMap;

use serde::Serialize;
use sysid_core::LinearModel;

use crate::localise::Localisation;
use crate::propose::Discovery;
use crate::refine::RefineStep;

/// A named effect as `discovery.json` reports it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct NamedEffect {
    /// Catalogue name.
    pub name: String,
    /// Equation (state) it enters.
    pub state: String,
    /// For a transfer: the equation (state) that receives the negated term — the flow
    /// leaves `state` and enters `into` (absent for an ordinary term).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub into: Option<String>,
    /// Expression, as written into the model.
    pub term: String,
    /// Coefficient calibrated by free-run simulation error.
    pub coefficient: f64,
    /// 95 % interval of `coefficient` (the free-run fit's Gauss–Newton standard error,
    /// inflated for residual colour; ±1.96 σ).
    pub ci95: Option<[f64; 2]>,
    /// 95 % interval of the regression on `d̂` (when the regression named it): of the
    /// regression's own, shrunk coefficient, not of `coefficient`.
    pub ci95_regression: Option<[f64; 2]>,
    /// Share of `d̂` it explains in the regression (when the regression named it).
    pub share_of_d: Option<f64>,
    /// Which stage named it.
    pub named_by: String,
    /// The term's shaping parameters by name (a saturation's `limit`, a dead zone's
    /// `width`, a smoothed Coulomb law's `eps`, a Stribeck `v_s`), as calibrated.
    #[serde(skip_serializing_if = "BTreeMap::is_empty")]
    pub parameters: BTreeMap<String, f64>,
    /// For a linear term (a bare state or input): the assumed model's entry it adds to.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub adjusts: Option<AssumedEntry>,
    /// Unit of the coefficient, when known (force-space discovery: the joint's
    /// generalized force over the term's unit).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub unit: Option<String>,
    /// The reading of the coefficient's sign (force-space discovery: as a force on the
    /// joint, negative on its own rate = opposing the motion).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reading: Option<String>,
}

impl NamedEffect {
    /// Whether the calibrated coefficient's 95 % interval excludes zero (`None` when no
    /// interval was computed). On real records, where the free-run cost stays far above
    /// the noise level and every χ² step test passes, this colour-inflated interval is
    /// what tells a term the data support from one that only bends the fit.
    pub fn interval_excludes_zero(&self) -> Option<bool> {
        self.ci95.map(|[lo, hi]| lo > 0.0 || hi < 0.0)
    }

    /// Where it enters, for reports: `d(h1)`, or `d(h1) and −d(h2) (transfer h1 → h2)`.
    pub fn equations(&self) -> String {
        match &self.into {
            None => format!("d({})", self.state),
            Some(r) => format!(
                "d({}) and −d({r}) (transfer {} → {r})",
                self.state, self.state
            ),
        }
    }
}

/// The entry of the assumed `A` or `B` that a linear named term adds to: a linear term
/// is a recalibration of the assumed model, and when it cancels the entry
/// (`effective ≈ 0`) the named effect beside it *replaces* the assumed law (an orifice
/// outflow replacing a linear one).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct AssumedEntry {
    /// `A` or `B`.
    pub matrix: &'static str,
    /// Row (state) name.
    pub row: String,
    /// Column (state or input) name.
    pub column: String,
    /// The assumed value.
    pub assumed: f64,
    /// Assumed value plus the term's coefficient.
    pub effective: f64,
    /// Whether the 95 % interval of `effective` (the coefficient's calibrated interval,
    /// shifted) contains 0: the assumed term is cancelled.
    pub cancelled: bool,
}

/// The assumed entry a bare-variable term `term` in equation `state` adds to.
pub(super) fn assumed_entry(
    lin: &LinearModel,
    state: &str,
    term: &str,
    coefficient: f64,
    ci: Option<[f64; 2]>,
) -> Option<AssumedEntry> {
    let row = lin.state_names().iter().position(|s| s == state)?;
    let (matrix, value) = match lin.state_names().iter().position(|s| s == term) {
        Some(j) => ("A", lin.a()[(row, j)]),
        None => {
            let j = lin.input_names().iter().position(|s| s == term)?;
            ("B", lin.b()[(row, j)])
        }
    };
    let effective = value + coefficient;
    Some(AssumedEntry {
        matrix,
        row: state.to_string(),
        column: term.to_string(),
        assumed: value,
        effective,
        cancelled: value != 0.0
            && ci.is_some_and(|[lo, hi]| lo + value <= 0.0 && 0.0 <= hi + value),
    })
}

/// One round of discovery.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Round {
    /// The selection's full report (verdict, effects, per-equation steps, roles).
    pub discovery: Discovery,
    /// Where `d̂` and the free-run error exceed their floors.
    pub localisation: Localisation,
    /// `d̂` RMS floor per corrected equation.
    pub floor_rms: Vec<f64>,
    /// Coefficients after free-run calibration (in the order of `discovery.effects`).
    pub calibrated: Vec<f64>,
    /// Free-run cost (`Σ r²/R`) of the model before the round and after it.
    pub calibration_cost: [f64; 2],
    /// The free-run search's add/remove decisions.
    pub refinement: Vec<RefineStep>,
    /// Why the round's terms were not accepted, when they were not.
    pub rejected: Option<String>,
}

/// Two sets of terms that both bring the free-run cost to the noise level, found when
/// the first touches an unmeasured state whose scale the measurements leave free (see
/// `gauge`): the search run again without the terms touching such states
/// found the second. Neither is claimed (verdict `unexplained`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Ambiguity {
    /// The states whose scale no measurement or known equation fixes.
    pub free_states: Vec<String>,
    /// The search's set (`equation: term`) and its judged free-run cost.
    pub named: Vec<String>,
    /// Its judged free-run cost.
    pub named_cost: f64,
    /// The set found without the named terms that touch `free_states`.
    pub alternative: Vec<String>,
    /// Its judged free-run cost.
    pub alternative_cost: f64,
}
