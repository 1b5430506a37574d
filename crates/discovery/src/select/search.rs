//! The search moves of stepwise selection (remove, exchange, add, add a pair) over a
//! precomputed scaled Gram matrix, and the partial F tests they use.

use std::collections::BTreeSet;

use nalgebra::{DMatrix, DVector};

use super::{Design, SelectionConfig, Step, StepAction};
use crate::error::Result;
use crate::stats::{effective_sample_size, f_upper_tail};

/// A fitted subset in scaled coordinates.
pub(super) struct Fit {
    pub(super) beta: DVector<f64>,
    /// Mean squared residual from the normal equations.
    pub(super) mse: f64,
    pub(super) max_vif: f64,
}

pub(super) struct Problem<'a> {
    pub(super) design: &'a Design,
    pub(super) scale: Vec<f64>,
    pub(super) gram: DMatrix<f64>,
    pub(super) b: Vec<f64>,
    pub(super) yy: f64,
    pub(super) n: usize,
    /// `N_eff` used by the tests during selection (full-model residual).
    pub(super) n_eff_ref: Option<f64>,
}

impl Problem<'_> {
    /// `N_eff` for a test whose larger model has residual `N_eff` `own`.
    pub(super) fn test_n_eff(&self, own: f64) -> f64 {
        self.n_eff_ref.unwrap_or(own)
    }

    /// Residual of the projection of `y` onto all `active` columns (pseudo-inverse of the
    /// scaled Gram matrix, eigenvalues below 1e-10 of the largest dropped).
    pub(super) fn full_residual(&self, active: &[usize]) -> Vec<f64> {
        let k = active.len();
        let g = DMatrix::from_fn(k, k, |i, j| self.gram[(active[i], active[j])]);
        let b = DVector::from_fn(k, |i, _| self.b[active[i]]);
        let eig = g.symmetric_eigen();
        let top = eig.eigenvalues.iter().copied().fold(0.0, f64::max);
        let mut beta = DVector::zeros(k);
        for (i, &lambda) in eig.eigenvalues.iter().enumerate() {
            if lambda > 1e-10 * top {
                let v = eig.eigenvectors.column(i);
                beta += v * (v.dot(&b) / lambda);
            }
        }
        let fit = Fit {
            beta,
            mse: 0.0,
            max_vif: 1.0,
        };
        self.residual(active, &fit)
    }

    pub(super) fn fit(&self, set: &[usize]) -> Option<Fit> {
        let p = set.len();
        if p == 0 {
            return Some(Fit {
                beta: DVector::zeros(0),
                mse: self.yy,
                max_vif: 1.0,
            });
        }
        let g = DMatrix::from_fn(p, p, |i, j| self.gram[(set[i], set[j])]);
        let rhs = DVector::from_fn(p, |i, _| self.b[set[i]]);
        let chol = g.cholesky()?;
        let beta = chol.solve(&rhs);
        let inv = chol.inverse();
        let max_vif = (0..p).map(|i| inv[(i, i)]).fold(0.0, f64::max);
        let mse = (self.yy - rhs.dot(&beta)).max(0.0);
        if !mse.is_finite() || !max_vif.is_finite() {
            return None;
        }
        Some(Fit { beta, mse, max_vif })
    }

    /// Residual of the fit of `set` (exact, from the columns).
    pub(super) fn residual(&self, set: &[usize], fit: &Fit) -> Vec<f64> {
        let mut r = self.design.y.clone();
        for (i, &k) in set.iter().enumerate() {
            let c = fit.beta[i] / self.scale[k];
            for (rv, xv) in r.iter_mut().zip(&self.design.columns[k]) {
                *rv -= c * xv;
            }
        }
        r
    }

    pub(super) fn n_eff(&self, r: &[f64]) -> f64 {
        let mut segs: Vec<&[f64]> = Vec::with_capacity(self.design.segments.len());
        let mut start = 0;
        for &len in &self.design.segments {
            segs.push(&r[start..start + len]);
            start += len;
        }
        effective_sample_size(&segs)
    }
}

/// The current model of the loop.
pub(super) struct State {
    pub(super) set: Vec<usize>,
    pub(super) sse: f64,
    pub(super) n_eff: f64,
}

/// Partial F (N_eff-scaled) of one term and its p-value, given the SSE without and with
/// it, the size `p` of the larger model, and the `N_eff` of the test.
pub(super) fn partial_f(
    sse_without: f64,
    sse_with: f64,
    p: usize,
    n: usize,
    n_eff: f64,
) -> Result<(f64, f64)> {
    joint_f(sse_without, sse_with, 1, p, n, n_eff)
}

/// Joint F of `q` terms (N_eff-scaled): `(ΔSSE/q)/(SSE/(N − p))·N_eff/N` against
/// `F(q, N_eff − p)`.
pub(super) fn joint_f(
    sse_without: f64,
    sse_with: f64,
    q: usize,
    p: usize,
    n: usize,
    n_eff: f64,
) -> Result<(f64, f64)> {
    let df2 = n_eff - p as f64;
    if df2 < 1.0 || n <= p {
        return Ok((f64::NAN, 1.0));
    }
    let f = if sse_with > 0.0 {
        (sse_without - sse_with).max(0.0) / q as f64 / (sse_with / (n - p) as f64)
            * (n_eff / n as f64)
    } else if sse_without > 0.0 {
        f64::INFINITY
    } else {
        f64::NAN
    };
    let p_value = if f.is_infinite() {
        0.0
    } else {
        f_upper_tail(f, q as f64, df2)?
    };
    Ok((f, p_value))
}

pub(super) fn sorted(set: &[usize]) -> Vec<usize> {
    let mut s = set.to_vec();
    s.sort_unstable();
    s
}

pub(super) fn refit(problem: &Problem<'_>, set: Vec<usize>) -> Option<State> {
    let fit = problem.fit(&set)?;
    let r = problem.residual(&set, &fit);
    let sse = r.iter().map(|v| v * v).sum();
    let n_eff = problem.n_eff(&r);
    Some(State { set, sse, n_eff })
}

pub(super) fn try_remove(
    problem: &Problem<'_>,
    state: &mut State,
    alpha_out: f64,
    visited: Option<&BTreeSet<Vec<usize>>>,
) -> Result<Option<Step>> {
    let p = state.set.len();
    if p == 0 {
        return Ok(None);
    }
    // The weakest member: the one whose removal raises SSE least.
    let mut weakest: Option<(usize, f64)> = None;
    for j in 0..p {
        let mut rest = state.set.clone();
        rest.remove(j);
        if visited.is_some_and(|v| v.contains(&sorted(&rest))) {
            continue;
        }
        let Some(fit) = problem.fit(&rest) else {
            continue;
        };
        let sse = fit.mse * problem.n as f64;
        if weakest.is_none_or(|(_, s)| sse < s) {
            weakest = Some((j, sse));
        }
    }
    let Some((j, sse_without)) = weakest else {
        return Ok(None);
    };
    let n_eff = problem.test_n_eff(state.n_eff);
    let (f, p_value) = partial_f(sse_without, state.sse, p, problem.n, n_eff)?;
    if p_value <= alpha_out {
        return Ok(None);
    }
    let mut rest = state.set.clone();
    let gone = rest.remove(j);
    let Some(next) = refit(problem, rest) else {
        return Ok(None);
    };
    *state = next;
    Ok(Some(Step {
        action: StepAction::Remove,
        candidate: gone,
        replaced: None,
        with: None,
        f,
        p_value,
        level: alpha_out,
        n_eff,
        sse: state.sse,
    }))
}

pub(super) fn try_add(
    problem: &Problem<'_>,
    state: &mut State,
    active: &[usize],
    alpha_in: f64,
    config: &SelectionConfig,
    visited: &BTreeSet<Vec<usize>>,
) -> Result<Option<Step>> {
    if state.set.len() >= config.max_terms {
        return Ok(None);
    }
    let mut best: Option<(usize, f64)> = None;
    for &k in active {
        if state.set.contains(&k) {
            continue;
        }
        let mut set = state.set.clone();
        set.push(k);
        if visited.contains(&sorted(&set)) {
            continue;
        }
        let Some(fit) = problem.fit(&set) else {
            continue;
        };
        if fit.max_vif > config.max_vif {
            continue;
        }
        if best.is_none_or(|(_, m)| fit.mse < m) {
            best = Some((k, fit.mse));
        }
    }
    let Some((k, _)) = best else {
        return Ok(None);
    };
    let mut set = state.set.clone();
    set.push(k);
    let Some(next) = refit(problem, set) else {
        return Ok(None);
    };
    let n_eff = problem.test_n_eff(next.n_eff);
    let (f, p_value) = partial_f(state.sse, next.sse, next.set.len(), problem.n, n_eff)?;
    if p_value >= alpha_in {
        return Ok(None);
    }
    *state = next;
    Ok(Some(Step {
        action: StepAction::Add,
        candidate: k,
        replaced: None,
        with: None,
        f,
        p_value,
        level: alpha_in,
        n_eff,
        sse: state.sse,
    }))
}

pub(super) fn try_exchange(
    problem: &Problem<'_>,
    state: &mut State,
    active: &[usize],
    config: &SelectionConfig,
    visited: &BTreeSet<Vec<usize>>,
) -> Result<Option<Step>> {
    if state.set.is_empty() {
        return Ok(None);
    }
    let current = problem.fit(&state.set).map_or(f64::INFINITY, |f| f.mse);
    let mut best: Option<(usize, usize, f64)> = None;
    for j in 0..state.set.len() {
        for &k in active {
            if state.set.contains(&k) {
                continue;
            }
            let mut set = state.set.clone();
            set[j] = k;
            if visited.contains(&sorted(&set)) {
                continue;
            }
            let Some(fit) = problem.fit(&set) else {
                continue;
            };
            if fit.max_vif > config.max_vif || fit.mse >= current * (1.0 - 1e-9) {
                continue;
            }
            if best.is_none_or(|(_, _, m)| fit.mse < m) {
                best = Some((j, k, fit.mse));
            }
        }
    }
    let Some((j, k, _)) = best else {
        return Ok(None);
    };
    let mut set = state.set.clone();
    let out = set[j];
    set[j] = k;
    let Some(next) = refit(problem, set) else {
        return Ok(None);
    };
    *state = next;
    Ok(Some(Step {
        action: StepAction::Exchange,
        candidate: k,
        replaced: Some(out),
        with: None,
        f: f64::NAN,
        p_value: f64::NAN,
        level: f64::NAN,
        n_eff: state.n_eff,
        sse: state.sse,
    }))
}

pub(super) fn try_add_pair(
    problem: &Problem<'_>,
    state: &mut State,
    active: &[usize],
    alpha_pair: f64,
    config: &SelectionConfig,
    visited: &BTreeSet<Vec<usize>>,
) -> Result<Option<Step>> {
    if state.set.len() + 2 > config.max_terms {
        return Ok(None);
    }
    let outside: Vec<usize> = active
        .iter()
        .copied()
        .filter(|k| !state.set.contains(k))
        .collect();
    let mut best: Option<(usize, usize, f64)> = None;
    for (a, &i) in outside.iter().enumerate() {
        for &j in &outside[a + 1..] {
            let mut set = state.set.clone();
            set.push(i);
            set.push(j);
            if visited.contains(&sorted(&set)) {
                continue;
            }
            let Some(fit) = problem.fit(&set) else {
                continue;
            };
            if fit.max_vif > config.max_vif {
                continue;
            }
            if best.is_none_or(|(_, _, m)| fit.mse < m) {
                best = Some((i, j, fit.mse));
            }
        }
    }
    let Some((i, j, _)) = best else {
        return Ok(None);
    };
    let mut set = state.set.clone();
    set.push(i);
    set.push(j);
    let Some(next) = refit(problem, set) else {
        return Ok(None);
    };
    let n_eff = problem.test_n_eff(next.n_eff);
    let (f, p_value) = joint_f(state.sse, next.sse, 2, next.set.len(), problem.n, n_eff)?;
    if p_value >= alpha_pair {
        return Ok(None);
    }
    *state = next;
    Ok(Some(Step {
        action: StepAction::AddPair,
        candidate: i,
        replaced: None,
        with: Some(j),
        f,
        p_value,
        level: alpha_pair,
        n_eff,
        sse: state.sse,
    }))
}
