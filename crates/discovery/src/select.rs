//! Term selection for one corrected equation: forward–backward stepwise regression of
//! `d̂` on candidate columns, with partial F-tests whose degrees of freedom count
//! autocorrelated samples by their effective number, a variance-inflation guard against
//! collinear candidates, and exchange moves so that the greedy order cannot lock in a
//! wrong but correlated set.
//!
//! # The model and its tests
//!
//! `y = Σ_{k∈S} β_k g_k + e` with **no implicit intercept** (a constant is the candidate
//! `constant_bias`), so sums of squares are uncentred: `SST = Σ y²`, `R² = 1 − SSE/SST`.
//!
//! The residual `e` of a regression on `d̂` is autocorrelated (`d̂` is smooth). With `N`
//! samples and `N_eff` effective ones (Bartlett's formula with an AR-smoothed
//! autocorrelation, [`crate::stats::effective_sample_size`]; for AR(1) residuals
//! `N(1 − ρ₁)/(1 + ρ₁)`), the coefficient covariance is taken as
//! `s²(XᵀX)⁻¹·N/N_eff` with `s² = SSE/(N − p)` (Bartlett; exact for AR(1) errors and slowly
//! varying regressors, conservative otherwise). Accordingly the partial F statistic of a
//! term is
//!
//! `F = (SSE_without − SSE_with) / (SSE_with/(N − p)) · N_eff/N`,  compared with
//! `F(1, N_eff − p)`,
//!
//! and the 95 % interval is `β ± t_{0.975}(N_eff − p)·se`. A test with `N_eff − p < 1` is
//! not significant.
//!
//! **Which residual gives `N_eff`.** During selection, the residual of the *full* model
//! (the projection of `y` onto all usable candidates; eigenvalues of the scaled Gram
//! matrix below `1e-10` of the largest are dropped) — the library's best estimate of the
//! noise process. The residual of an incomplete model would still hold the smooth signal
//! of the terms not yet entered, whose correlation time would shrink `N_eff` to a handful
//! and stall selection before the second term of a two-term effect. When `y` is not
//! explained by the library at all, the full residual is smooth too and the tests stay
//! conservative, as they should. (With fewer than `2K` samples the current model's
//! residual is used instead.) The reported intervals of the final terms use the `N_eff` of
//! the *final* residual.
//!
//! # The procedure (Efroymson's stepwise regression with Miller's exchange step)
//!
//! Let `K` be the number of usable candidates (after screening). Each round tries, in
//! order, and takes the first move that succeeds:
//!
//! 1. **remove** the term with the smallest F if its p-value exceeds
//!    `α_out = removal_factor·α/K`;
//! 2. **exchange** a member for an outside candidate when that lowers SSE at the same
//!    size (Miller, *Subset Selection in Regression*, 2002, §3.5). This matters for curved
//!    effects over a narrow range: `sqrt(h)` ≈ `a + b·h` there, and a greedy start on `1`
//!    and `h` would otherwise never reach `{h, sqrt(h)}`. Exchanges come before additions
//!    so that the leftover curvature of a wrong pair is not "explained" by adding a third,
//!    spurious term;
//! 3. **add** the admissible candidate that lowers SSE most if its p-value is below
//!    `α_in = α/K` (Bonferroni over the candidates, so the family-wise chance of
//!    admitting a term on pure noise is about `α`);
//! 4. **add a pair** — the admissible pair of outside candidates that lowers SSE most —
//!    if its joint F test (2 numerator degrees of freedom) has a p-value below
//!    `α/(K(K−1)/2)` (Bonferroni over the pairs). This catches *suppressor* pairs that
//!    single steps miss: on a pendulum driven below resonance, `sin θ − θ ≈ −θ³/6` and
//!    `u cos θ − u ≈ −u θ²/2` are strongly anti-correlated (θ follows u), their true
//!    combination nearly cancels, and neither helps much on its own.
//!
//! A set is **admissible** when every member's variance inflation factor
//! `VIF_j = [(ZᵀZ/N)⁻¹]_jj` (uncentred, columns scaled to unit RMS) is at most `max_vif`:
//! nearly collinear candidates (`v` and `tanh(v/ε)` for a large `ε`, two close saturation
//! limits) cannot both enter. Sets already visited are not revisited, so the loop ends; a
//! final backward pass removes any term left with `p > α_out`.
//!
//! Before selecting, candidates that are not finite on the data, identically zero, or an
//! exact multiple of an earlier candidate (cosine ≥ 1 − 1e-9) are screened out.
//!
//! # Shares of `d̂`
//!
//! * `share` (Pratt's measure) `= β_j·Σ g_j y / Σ y²`: the shares add up to `R²`; a
//!   negative share means the term suppresses another (collinearity).
//! * `partial_r2 = (SSE_{−j} − SSE)/SSE_{−j}`: the part of what the other terms leave
//!   that term `j` explains uniquely.
//!
//! # Aliases: alternatives the data cannot rule out
//!
//! Each selected term lists the outside candidates that could stand in its place:
//! those with uncentred cosine ≥ `alias_cosine` to it, and those for which the model with
//! the term swapped for the candidate (same size, admissible) fits *not significantly
//! worse*: `F = (SSE_swap − SSE)/(SSE/(N − p))·N_eff/N` below the `1 − alias_level`
//! quantile of `F(1, N_eff − p)`. E.g. weak damping on a record where `v` and `v·|v|`
//! look alike: the report names the better fit and says the other is not excluded.

use std::collections::BTreeSet;

use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

use crate::error::{DiscoveryError, Result};
use crate::stats::{f_upper_tail, t_quantile};

use search::{Problem, State, partial_f, sorted, try_add, try_add_pair, try_exchange, try_remove};

mod search;

/// Settings of stepwise selection.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SelectionConfig {
    /// Family-wise significance level of admitting a term (split over the candidates,
    /// Bonferroni). In (0, 1); default 0.01.
    pub alpha: f64,
    /// A term leaves when its p-value exceeds `removal_factor·α/K` (≥ 1, so that a term
    /// just admitted is not removed at once). Default 2.
    pub removal_factor: f64,
    /// Most terms per equation (≥ 1). Default 6.
    pub max_terms: usize,
    /// Largest variance inflation factor allowed in a selected set (> 1). Default 1000.
    pub max_vif: f64,
    /// Cosine similarity (uncentred) at or above which an outside candidate is listed as
    /// an alias of a selected term: an alternative the data can hardly tell apart.
    /// In (0, 1]; default 0.99.
    pub alias_cosine: f64,
    /// Level of the swap test that also lists an outside candidate as an alias when
    /// replacing a selected term by it does not fit significantly worse (see the module
    /// doc). In (0, 1); default 0.05.
    pub alias_level: f64,
}

impl Default for SelectionConfig {
    fn default() -> Self {
        Self {
            alpha: 0.01,
            removal_factor: 2.0,
            max_terms: 6,
            max_vif: 1000.0,
            alias_cosine: 0.99,
            alias_level: 0.05,
        }
    }
}

impl SelectionConfig {
    /// Check ranges before any work.
    pub fn validate(&self) -> Result<()> {
        let bad = |field, value, reason| {
            Err(DiscoveryError::InvalidConfig {
                field,
                value,
                reason,
            })
        };
        if !(self.alpha > 0.0 && self.alpha < 1.0) {
            return bad("alpha", self.alpha, "must be in (0, 1)");
        }
        if !(self.removal_factor.is_finite() && self.removal_factor >= 1.0) {
            return bad(
                "removal_factor",
                self.removal_factor,
                "must be finite and >= 1",
            );
        }
        if self.max_terms == 0 {
            return bad("max_terms", 0.0, "must be at least 1");
        }
        if self.max_vif.is_nan() || self.max_vif <= 1.0 {
            return bad("max_vif", self.max_vif, "must be greater than 1");
        }
        if !(self.alias_cosine > 0.0 && self.alias_cosine <= 1.0) {
            return bad("alias_cosine", self.alias_cosine, "must be in (0, 1]");
        }
        if !(self.alias_level > 0.0 && self.alias_level < 1.0) {
            return bad("alias_level", self.alias_level, "must be in (0, 1)");
        }
        Ok(())
    }
}

/// Why a candidate was left out before selection.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", tag = "reason")]
pub enum Screened {
    /// Not finite at some sample.
    NonFinite {
        /// First offending sample (over the concatenated experiments).
        sample: usize,
    },
    /// Zero at every sample.
    Zero,
    /// An exact multiple of an earlier candidate.
    Duplicate {
        /// Index of that candidate.
        of: usize,
    },
}

/// What a selection step did.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum StepAction {
    /// A candidate entered.
    Add,
    /// A term left.
    Remove,
    /// A term was exchanged for a candidate.
    Exchange,
    /// Two candidates entered together.
    AddPair,
}

/// One accepted step.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Step {
    /// What happened.
    pub action: StepAction,
    /// The candidate that entered (add, exchange) or left (remove).
    pub candidate: usize,
    /// The member that left in an exchange.
    pub replaced: Option<usize>,
    /// The second candidate of a pair.
    pub with: Option<usize>,
    /// Partial F statistic (N_eff-scaled) of the term added or removed (NaN for exchanges).
    #[serde(with = "crate::json::nullable")]
    pub f: f64,
    /// Its p-value (NaN for exchanges).
    #[serde(with = "crate::json::nullable")]
    pub p_value: f64,
    /// The level it was compared with (NaN for exchanges).
    #[serde(with = "crate::json::nullable")]
    pub level: f64,
    /// Effective samples used by the test (the model's own residual for exchanges).
    pub n_eff: f64,
    /// Residual sum of squares after the step.
    pub sse: f64,
}

/// One selected term with its uncertainty and share.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SelectedTerm {
    /// Index of the candidate.
    pub candidate: usize,
    /// Least-squares coefficient.
    pub coefficient: f64,
    /// Standard error (autocorrelation-corrected).
    #[serde(with = "crate::json::nullable")]
    pub std_error: f64,
    /// 95 % confidence interval.
    #[serde(with = "crate::json::nullable_pair")]
    pub ci95: [f64; 2],
    /// Two-sided p-value of `β = 0`.
    #[serde(with = "crate::json::nullable")]
    pub p_value: f64,
    /// Unique share of what the other terms leave: `(SSE_{−j} − SSE)/SSE_{−j}`.
    pub partial_r2: f64,
    /// Pratt share `β_j Σ g_j y / Σ y²` (the shares add up to `R²`).
    pub share: f64,
    /// Outside candidates that could stand in for this term (near-collinear, or a swap
    /// that does not fit significantly worse; see the module doc).
    pub aliases: Vec<usize>,
}

/// The result of selection on one equation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Selection {
    /// Selected terms, by candidate index.
    pub terms: Vec<SelectedTerm>,
    /// Samples used.
    pub n: usize,
    /// Effective samples of the final residual (of `y` itself when nothing is selected).
    pub n_eff: f64,
    /// Effective samples of the full-model residual used by the tests during selection
    /// (`None` when there were too few samples for the full model).
    pub n_eff_full: Option<f64>,
    /// `Σ y²`.
    pub sum_squares: f64,
    /// Residual sum of squares of the final model.
    pub sse: f64,
    /// Uncentred `R² = 1 − SSE/Σy²` (0 when `y` is zero).
    pub r2: f64,
    /// Candidates usable after screening (`K`).
    pub usable: usize,
    /// Screened-out candidates with the reason.
    pub screened: Vec<(usize, Screened)>,
    /// The accepted steps, in order.
    pub steps: Vec<Step>,
}

/// A regression problem: the response and candidate columns over concatenated
/// experiments of the given lengths.
#[derive(Debug, Clone, PartialEq)]
pub struct Design {
    /// Response (`N`).
    pub y: Vec<f64>,
    /// Candidate columns, each `N` long.
    pub columns: Vec<Vec<f64>>,
    /// Lengths of the experiments making up the `N` samples (they add up to `N`).
    pub segments: Vec<usize>,
}

/// Run stepwise selection on `design` (see the module doc).
///
/// Errors: invalid config; columns or segments whose lengths do not match `y`; a
/// non-finite response.
pub fn select(design: &Design, config: &SelectionConfig) -> Result<Selection> {
    config.validate()?;
    let n = design.y.len();
    let seg_total: usize = design.segments.iter().sum();
    if seg_total != n {
        return Err(DiscoveryError::Length {
            what: "experiment lengths vs samples",
            found: seg_total,
            expected: n,
        });
    }
    for c in &design.columns {
        if c.len() != n {
            return Err(DiscoveryError::Length {
                what: "candidate column",
                found: c.len(),
                expected: n,
            });
        }
    }
    if let Some(k) = design.y.iter().position(|v| !v.is_finite()) {
        return Err(DiscoveryError::NonFinite {
            what: "response",
            experiment: 0,
            row: 0,
            sample: k,
        });
    }
    if n < 3 {
        return Err(DiscoveryError::TooFewSamples {
            what: "term selection",
            found: n,
            needed: 3,
        });
    }
    let nf = n as f64;
    let kk = design.columns.len();

    // Screening and scaling.
    let mut screened: Vec<(usize, Screened)> = Vec::new();
    let mut scale = vec![1.0; kk];
    let mut usable_cols: Vec<usize> = Vec::new();
    for (k, col) in design.columns.iter().enumerate() {
        if let Some(s) = col.iter().position(|v| !v.is_finite()) {
            screened.push((k, Screened::NonFinite { sample: s }));
            continue;
        }
        let ms = col.iter().map(|v| v * v).sum::<f64>() / nf;
        if ms.sqrt() < f64::MIN_POSITIVE.sqrt() {
            screened.push((k, Screened::Zero));
            continue;
        }
        scale[k] = ms.sqrt();
        usable_cols.push(k);
    }
    let mut gram = DMatrix::zeros(kk, kk);
    for (a, &i) in usable_cols.iter().enumerate() {
        for &j in &usable_cols[a..] {
            let ci = &design.columns[i];
            let cj = &design.columns[j];
            let g = ci.iter().zip(cj).map(|(x, y)| x * y).sum::<f64>() / (nf * scale[i] * scale[j]);
            gram[(i, j)] = g;
            gram[(j, i)] = g;
        }
    }
    let b: Vec<f64> = (0..kk)
        .map(|k| {
            if usable_cols.contains(&k) {
                design.columns[k]
                    .iter()
                    .zip(&design.y)
                    .map(|(x, y)| x * y)
                    .sum::<f64>()
                    / (nf * scale[k])
            } else {
                0.0
            }
        })
        .collect();
    let mut active: Vec<usize> = Vec::new();
    for &k in &usable_cols {
        if let Some(&j) = active.iter().find(|&&j| gram[(j, k)].abs() >= 1.0 - 1e-9) {
            screened.push((k, Screened::Duplicate { of: j }));
        } else {
            active.push(k);
        }
    }
    screened.sort_by_key(|(k, _)| *k);
    let usable = active.len();
    let yy = design.y.iter().map(|v| v * v).sum::<f64>() / nf;
    let mut problem = Problem {
        design,
        scale,
        gram,
        b,
        yy,
        n,
        n_eff_ref: None,
    };
    if usable > 0 && n >= 2 * usable {
        let r = problem.full_residual(&active);
        problem.n_eff_ref = Some(problem.n_eff(&r));
    }
    let alpha_in = config.alpha / usable.max(1) as f64;
    let alpha_out = (config.removal_factor * alpha_in).min(1.0);
    let pairs = (usable * usable.saturating_sub(1) / 2).max(1);
    let alpha_pair = config.alpha / pairs as f64;

    let mut state = State {
        set: Vec::new(),
        sse: yy * nf,
        n_eff: problem.n_eff(&design.y),
    };
    let mut visited: BTreeSet<Vec<usize>> = BTreeSet::new();
    visited.insert(Vec::new());
    let mut steps: Vec<Step> = Vec::new();
    let max_rounds = 10 * usable + 10;

    for _ in 0..max_rounds {
        if let Some(step) = try_remove(&problem, &mut state, alpha_out, Some(&visited))? {
            visited.insert(sorted(&state.set));
            steps.push(step);
            continue;
        }
        if let Some(step) = try_exchange(&problem, &mut state, &active, config, &visited)? {
            visited.insert(sorted(&state.set));
            steps.push(step);
            continue;
        }
        if let Some(step) = try_add(&problem, &mut state, &active, alpha_in, config, &visited)? {
            visited.insert(sorted(&state.set));
            steps.push(step);
            continue;
        }
        if let Some(step) =
            try_add_pair(&problem, &mut state, &active, alpha_pair, config, &visited)?
        {
            visited.insert(sorted(&state.set));
            steps.push(step);
            continue;
        }
        break;
    }
    // Final backward pass: no insignificant term stays, visited or not.
    while let Some(step) = try_remove(&problem, &mut state, alpha_out, None)? {
        steps.push(step);
    }
    finish(&problem, &active, state, config, usable, screened, steps)
}

/// Exact least squares on the final set (QR of the unscaled columns) and the term
/// statistics.
fn finish(
    problem: &Problem<'_>,
    active: &[usize],
    state: State,
    config: &SelectionConfig,
    usable: usize,
    screened: Vec<(usize, Screened)>,
    steps: Vec<Step>,
) -> Result<Selection> {
    let n = problem.n;
    let design = problem.design;
    let sum_squares: f64 = design.y.iter().map(|v| v * v).sum();
    let mut set = state.set.clone();
    set.sort_unstable();
    let p = set.len();
    if p == 0 {
        return Ok(Selection {
            terms: Vec::new(),
            n,
            n_eff: state.n_eff,
            n_eff_full: problem.n_eff_ref,
            sum_squares,
            sse: sum_squares,
            r2: 0.0,
            usable,
            screened,
            steps,
        });
    }
    let x = DMatrix::from_fn(n, p, |i, j| design.columns[set[j]][i]);
    let y = DVector::from_column_slice(&design.y);
    let qr = x.clone().qr();
    let r = qr.r();
    let qty = qr.q().transpose() * &y;
    let beta = r
        .solve_upper_triangular(&qty)
        .ok_or(DiscoveryError::TooFewSamples {
            what: "independent selected columns",
            found: 0,
            needed: p,
        })?;
    let resid = &y - &x * &beta;
    let sse = resid.norm_squared();
    let n_eff = problem.n_eff(resid.as_slice());
    let rinv = r
        .clone()
        .try_inverse()
        .ok_or(DiscoveryError::TooFewSamples {
            what: "independent selected columns",
            found: 0,
            needed: p,
        })?;
    let xtx_inv = &rinv * rinv.transpose();
    let df = n_eff - p as f64;
    let s2 = if n > p {
        sse / (n - p) as f64
    } else {
        f64::NAN
    };
    let inflation = n as f64 / n_eff;
    let test_n_eff = problem.test_n_eff(n_eff);
    let tq = if df >= 1.0 {
        t_quantile(0.975, df)?
    } else {
        f64::INFINITY
    };
    let mut terms = Vec::with_capacity(p);
    for (j, &k) in set.iter().enumerate() {
        let se = (s2 * xtx_inv[(j, j)] * inflation).sqrt();
        let b = beta[j];
        let p_value = if df >= 1.0 && se > 0.0 {
            f_upper_tail((b / se).powi(2), 1.0, df)?
        } else if se == 0.0 && b != 0.0 {
            0.0
        } else {
            1.0
        };
        let mut rest = set.clone();
        rest.remove(j);
        let sse_without = problem.fit(&rest).map_or(sum_squares, |f| f.mse * n as f64);
        let partial_r2 = if sse_without > 0.0 {
            ((sse_without - sse) / sse_without).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let gy: f64 = design.columns[k]
            .iter()
            .zip(&design.y)
            .map(|(a, b)| a * b)
            .sum();
        let share = if sum_squares > 0.0 {
            b * gy / sum_squares
        } else {
            0.0
        };
        let mut aliases: Vec<usize> = Vec::new();
        for c in 0..design.columns.len() {
            if c == k || set.contains(&c) {
                continue;
            }
            if problem.gram[(k, c)].abs() >= config.alias_cosine {
                aliases.push(c);
                continue;
            }
            if !active.contains(&c) {
                continue;
            }
            let mut swapped = set.clone();
            swapped[j] = c;
            let Some(fit) = problem.fit(&swapped) else {
                continue;
            };
            if fit.max_vif > config.max_vif {
                continue;
            }
            let sse_swap = fit.mse * n as f64;
            let (_, p_swap) = partial_f(sse_swap, sse, p, n, test_n_eff)?;
            if p_swap > config.alias_level {
                aliases.push(c);
            }
        }
        terms.push(SelectedTerm {
            candidate: k,
            coefficient: b,
            std_error: se,
            ci95: [b - tq * se, b + tq * se],
            p_value,
            partial_r2,
            share,
            aliases,
        });
    }
    let r2 = if sum_squares > 0.0 {
        1.0 - sse / sum_squares
    } else {
        0.0
    };
    Ok(Selection {
        terms,
        n,
        n_eff,
        n_eff_full: problem.n_eff_ref,
        sum_squares,
        sse,
        r2,
        usable,
        screened,
        steps,
    })
}

#[cfg(test)]
mod tests;
