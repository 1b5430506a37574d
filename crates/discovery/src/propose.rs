//! The "what" of discovery: per corrected equation, test `d̂` against its noise floor,
//! select catalogue terms, and give the verdict `found` / `none` / `unexplained`, in a
//! serialisable report shaped for `discovery.json` (SPEC §5).
//!
//! # Verdicts (per equation, then overall)
//!
//! With `MS = mean(d̂²)`, the floor's RMS `σ_f` and its effective-sample ratio `ρ`
//! ([`NoiseFloor`]), over `N` samples:
//!
//! * `d̂` is **significant** when `MS/σ_f² > max(min_signal_ratio, χ²_{1−α}(ν)/ν)` with
//!   `ν = ρ·N` and `α = signal_alpha`: under a correct model `MS/σ_f²` behaves like
//!   `χ²_ν/ν`, and the fixed minimum ratio (default 1.5, i.e. RMS 22 % above the floor)
//!   absorbs the uncertainty of the floor itself. A zero floor makes any nonzero `d̂`
//!   significant.
//! * `share_above_floor = (MS − MS_res)/(MS − σ_f²)`, clamped to `[0, 1]`: how much of
//!   the part of `d̂` that is *not* noise the selected terms explain (`MS_res` is the
//!   mean squared residual of the regression).
//! * **`none`**: `d̂` is not significant. Terms the regression may still pick are kept in
//!   the equation's report but never named as effects.
//! * **`found`**: `d̂` is significant, at least one term is selected and
//!   `share_above_floor ≥ min_share` (default 0.75).
//! * **`unexplained`**: `d̂` is significant but the library explains less than that — the
//!   selected terms (if any) are reported as tentative only.
//!
//! Overall: `found` if any equation is `found` (its terms are the named effects),
//! otherwise `unexplained` if any equation is, otherwise `none`.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};
use sysid_core::LinearModel;

use crate::candidates::{EquationLibrary, LibraryConfig, build_library};
use crate::error::{DiscoveryError, Result};
use crate::floor::NoiseFloor;
use crate::roles::{EquationKind, Role, StateRoles};
use crate::samples::Samples;
use crate::select::{Design, Screened, SelectedTerm, SelectionConfig, StepAction, select};
use crate::stats::chi2_quantile;

/// Settings of [`propose`].
#[derive(Debug, Clone, PartialEq)]
pub struct DiscoveryConfig {
    /// Which effects to try and their data-derived parameters.
    pub library: LibraryConfig,
    /// Stepwise selection settings.
    pub selection: SelectionConfig,
    /// Share of `d̂`'s mean square above the floor that the selected terms must explain
    /// for `found` (in (0, 1]). Default 0.75.
    pub min_share: f64,
    /// Significance level of "`d̂` exceeds its floor" (in (0, 1)). Default 0.01.
    pub signal_alpha: f64,
    /// Smallest `MS(d̂)/floor²` that counts as significant (≥ 1). Default 1.5.
    pub min_signal_ratio: f64,
    /// Role overrides by state name (see [`StateRoles::infer`]).
    pub roles: Vec<(String, Role)>,
}

impl Default for DiscoveryConfig {
    fn default() -> Self {
        Self {
            library: LibraryConfig::default(),
            selection: SelectionConfig::default(),
            min_share: 0.75,
            signal_alpha: 0.01,
            min_signal_ratio: 1.5,
            roles: Vec::new(),
        }
    }
}

impl DiscoveryConfig {
    /// Check ranges before any work.
    pub fn validate(&self) -> Result<()> {
        self.library.validate()?;
        self.selection.validate()?;
        let bad = |field, value, reason| {
            Err(DiscoveryError::InvalidConfig {
                field,
                value,
                reason,
            })
        };
        if !(self.min_share > 0.0 && self.min_share <= 1.0) {
            return bad("min_share", self.min_share, "must be in (0, 1]");
        }
        if !(self.signal_alpha > 0.0 && self.signal_alpha < 1.0) {
            return bad("signal_alpha", self.signal_alpha, "must be in (0, 1)");
        }
        if !(self.min_signal_ratio.is_finite() && self.min_signal_ratio >= 1.0) {
            return bad(
                "min_signal_ratio",
                self.min_signal_ratio,
                "must be finite and >= 1",
            );
        }
        Ok(())
    }
}

/// The verdict of discovery.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Verdict {
    /// Named effects explain the significant part of `d̂`.
    Found,
    /// `d̂` is within its noise floor: no significant missing effect.
    None,
    /// `d̂` is significant but the library does not explain it.
    Unexplained,
}

/// An outside candidate the data cannot rule out in place of a selected term.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Alias {
    /// Effect name.
    pub name: String,
    /// Its term.
    pub term: String,
}

/// One named term with its coefficient, uncertainty and share of `d̂`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FoundEffect {
    /// Catalogue name of the effect.
    pub name: String,
    /// State equation it enters.
    pub state: String,
    /// The term as regressed (e.g. `sign(omega)`).
    pub term: String,
    /// Its coefficient (least squares on `d̂`; shrunk by MME's `W`, see `augment`).
    pub coefficient: f64,
    /// 95 % confidence interval of the coefficient (autocorrelation-corrected).
    #[serde(with = "crate::json::nullable_pair")]
    pub ci95: [f64; 2],
    /// Pratt share of `d̂`'s mean square (the shares of an equation add up to its `R²`).
    pub share_of_d: f64,
    /// Human label.
    pub label: String,
    /// What the sign of the coefficient means physically.
    pub reading: String,
    /// Standard error of the coefficient.
    #[serde(with = "crate::json::nullable")]
    pub std_error: f64,
    /// Two-sided p-value of a zero coefficient.
    #[serde(with = "crate::json::nullable")]
    pub p_value: f64,
    /// Unique share of what the other terms leave unexplained.
    pub partial_r2: f64,
    /// Effect name written into the model (the smooth variant for jumps).
    pub model_effect: String,
    /// Term written into the model.
    pub model_term: String,
    /// Unit of the coefficient when units are known.
    pub coefficient_unit: Option<String>,
    /// Alternatives the data cannot rule out (near-collinear, or fitting not significantly
    /// worse in this term's place); empty when the name is unambiguous.
    pub aliases: Vec<Alias>,
}

/// One screened candidate.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ScreenedCandidate {
    /// Effect name.
    pub name: String,
    /// Its term.
    pub term: String,
    /// Why it was left out.
    pub why: Screened,
}

/// One accepted selection step, by name.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StepRecord {
    /// What happened.
    pub action: StepAction,
    /// Effect entering (or leaving; the first of a pair).
    pub name: String,
    /// Its term.
    pub term: String,
    /// The term that left in an exchange.
    pub replaced: Option<String>,
    /// The second term of a pair.
    pub with: Option<String>,
    /// Partial F (N_eff-scaled); `None` for exchanges.
    pub f: Option<f64>,
    /// p-value; `None` for exchanges.
    pub p_value: Option<f64>,
    /// Level compared with; `None` for exchanges.
    pub level: Option<f64>,
    /// Effective samples of the residual.
    pub n_eff: f64,
}

/// Discovery on one corrected equation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EquationReport {
    /// The state whose equation this is.
    pub state: String,
    /// Its kind.
    pub kind: EquationKind,
    /// The equation's verdict.
    pub verdict: Verdict,
    /// Samples used (all experiments).
    pub samples: usize,
    /// RMS of `d̂`.
    pub d_rms: f64,
    /// RMS of the floor.
    pub floor_rms: f64,
    /// `MS(d̂)/floor²`; `None` for a zero floor.
    pub signal_ratio: Option<f64>,
    /// The ratio `d̂` had to exceed.
    pub signal_threshold: f64,
    /// Whether `d̂` is significant against the floor.
    pub significant: bool,
    /// Uncentred `R²` of the regression.
    pub r2: f64,
    /// Share of `d̂`'s mean square above the floor that the terms explain.
    pub share_above_floor: f64,
    /// RMS of the regression residual.
    pub residual_rms: f64,
    /// Effective samples of the final residual.
    pub n_eff: f64,
    /// Effective samples of the full-model residual, used by the selection tests.
    pub n_eff_full: Option<f64>,
    /// Candidates tried.
    pub candidates: usize,
    /// Selected terms (named effects when the verdict is `found`, tentative otherwise).
    pub terms: Vec<FoundEffect>,
    /// Candidates screened out before selection.
    pub screened: Vec<ScreenedCandidate>,
    /// The selection path.
    pub steps: Vec<StepRecord>,
}

/// The result of discovery; serialises to the `verdict` / `effects` part of
/// `discovery.json` plus per-equation detail.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Discovery {
    /// Overall verdict.
    pub verdict: Verdict,
    /// Named effects (the terms of every `found` equation).
    pub effects: Vec<FoundEffect>,
    /// Per corrected equation.
    pub equations: Vec<EquationReport>,
    /// Roles used, by state name.
    pub roles: Vec<(String, Role)>,
}

/// Name the physical effects the assumed `model` misses from MME's output.
///
/// `units` maps state and input names to units (may be empty; `d_<state>` entries give
/// equation units); `samples` holds per experiment `x̂`, `u` and `d̂` at the samples;
/// `floor` what `d̂` looks like under a correct model (one entry per corrected equation).
///
/// Errors: invalid config, `E` not a selection, shapes or non-finite values in
/// `samples`, a floor of the wrong length, fewer than 3 samples.
pub fn propose(
    model: &LinearModel,
    units: &BTreeMap<String, String>,
    samples: &[Samples],
    floor: &NoiseFloor,
    config: &DiscoveryConfig,
) -> Result<Discovery> {
    config.validate()?;
    let (n, m, q) = (model.n_states(), model.n_inputs(), model.n_corrections());
    if samples.is_empty() {
        return Err(DiscoveryError::TooFewSamples {
            what: "experiments",
            found: 0,
            needed: 1,
        });
    }
    for (e, s) in samples.iter().enumerate() {
        s.check(e, n, m, q)?;
    }
    if floor.len() != q {
        return Err(DiscoveryError::Length {
            what: "noise floor equations",
            found: floor.len(),
            expected: q,
        });
    }
    let roles = StateRoles::infer(model, units, &config.roles)?;
    let library = build_library(model, &roles, units, samples, &config.library)?;
    let mut equations = Vec::with_capacity(library.len());
    for eq in &library {
        equations.push(propose_equation(eq, samples, floor, config)?);
    }
    let effects = equations
        .iter()
        .filter(|e| e.verdict == Verdict::Found)
        .flat_map(|e| e.terms.iter().cloned())
        .collect();
    let verdict = if equations.iter().any(|e| e.verdict == Verdict::Found) {
        Verdict::Found
    } else if equations.iter().any(|e| e.verdict == Verdict::Unexplained) {
        Verdict::Unexplained
    } else {
        Verdict::None
    };
    Ok(Discovery {
        verdict,
        effects,
        equations,
        roles: model
            .state_names()
            .iter()
            .cloned()
            .zip(roles.roles.iter().copied())
            .collect(),
    })
}

/// The regression problem of one equation: `d̂` and every candidate evaluated at `(x̂, u)`.
pub fn equation_design(eq: &EquationLibrary, samples: &[Samples]) -> Design {
    let mut y = Vec::new();
    let mut segments = Vec::with_capacity(samples.len());
    for s in samples {
        y.extend(s.corrections().row(eq.correction).iter());
        segments.push(s.len());
    }
    let columns = eq
        .candidates
        .iter()
        .map(|c| {
            samples
                .iter()
                .flat_map(|s| {
                    (0..s.len()).map(move |k| {
                        let (x, u) = s.point(k);
                        c.expr.eval_parts(x, u)
                    })
                })
                .collect()
        })
        .collect();
    Design {
        y,
        columns,
        segments,
    }
}

fn propose_equation(
    eq: &EquationLibrary,
    samples: &[Samples],
    floor: &NoiseFloor,
    config: &DiscoveryConfig,
) -> Result<EquationReport> {
    let design = equation_design(eq, samples);
    let selection = select(&design, &config.selection)?;
    let nf = selection.n as f64;
    let ms = selection.sum_squares / nf;
    let ms_res = selection.sse / nf;
    let floor_rms = floor.rms[eq.correction];
    let floor_ms = floor_rms * floor_rms;
    let nu = (floor.neff_ratio[eq.correction] * nf).max(1.0);
    let chi = chi2_quantile(1.0 - config.signal_alpha, nu)? / nu;
    let signal_threshold = config.min_signal_ratio.max(chi);
    let (signal_ratio, significant) = if floor_ms > 0.0 {
        let r = ms / floor_ms;
        (Some(r), r > signal_threshold)
    } else {
        (None, ms > 0.0)
    };
    let share_above_floor = if ms > floor_ms {
        ((ms - ms_res) / (ms - floor_ms)).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let verdict = if !significant {
        Verdict::None
    } else if !selection.terms.is_empty() && share_above_floor >= config.min_share {
        Verdict::Found
    } else {
        Verdict::Unexplained
    };
    let candidates = &eq.candidates;
    let name = |k: usize| candidates[k].effect.name().to_string();
    let term = |k: usize| candidates[k].term.clone();
    let terms = selection
        .terms
        .iter()
        .map(|t| found_effect(eq, t))
        .collect();
    let screened = selection
        .screened
        .iter()
        .map(|&(k, why)| ScreenedCandidate {
            name: name(k),
            term: term(k),
            why,
        })
        .collect();
    let finite = |v: f64| v.is_finite().then_some(v);
    let steps = selection
        .steps
        .iter()
        .map(|s| StepRecord {
            action: s.action,
            name: name(s.candidate),
            term: term(s.candidate),
            replaced: s.replaced.map(term),
            with: s.with.map(term),
            f: finite(s.f),
            p_value: finite(s.p_value),
            level: finite(s.level),
            n_eff: s.n_eff,
        })
        .collect();
    Ok(EquationReport {
        state: eq.state.clone(),
        kind: eq.kind,
        verdict,
        samples: selection.n,
        d_rms: ms.sqrt(),
        floor_rms,
        signal_ratio,
        signal_threshold,
        significant,
        r2: selection.r2,
        share_above_floor,
        residual_rms: ms_res.sqrt(),
        n_eff: selection.n_eff,
        n_eff_full: selection.n_eff_full,
        candidates: candidates.len(),
        terms,
        screened,
        steps,
    })
}

fn found_effect(eq: &EquationLibrary, t: &SelectedTerm) -> FoundEffect {
    let c = &eq.candidates[t.candidate];
    FoundEffect {
        name: c.effect.name().to_string(),
        state: c.state.clone(),
        term: c.term.clone(),
        coefficient: t.coefficient,
        ci95: t.ci95,
        share_of_d: t.share,
        label: c.effect.label().to_string(),
        reading: c.effect.reading(t.coefficient).to_string(),
        std_error: t.std_error,
        p_value: t.p_value,
        partial_r2: t.partial_r2,
        model_effect: c.model_effect.name().to_string(),
        model_term: c.model_term.clone(),
        coefficient_unit: c.coefficient_unit.clone(),
        aliases: t
            .aliases
            .iter()
            .map(|&k| Alias {
                name: eq.candidates[k].effect.name().to_string(),
                term: eq.candidates[k].term.clone(),
            })
            .collect(),
    }
}
