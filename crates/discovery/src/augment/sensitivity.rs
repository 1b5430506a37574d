//! Forward sensitivities: the Jacobian of the free-run residuals for
//! [`calibrate`](super::calibrate) (and the screen's output sensitivities) by integrating
//! `S = ∂x/∂θ` with the state instead of re-simulating once or twice per parameter.
//!
//! For `ẋ = F(x, u; θ) = A x + B u + Σ_k c_k φ_k(x, u) (e_{s_k} − e_{r_k})` (the second
//! unit vector only for a transfer into `r_k`), the sensitivities obey the variational
//! equation `Ṡ = F_x S + F_θ` with `F_x = A + Σ_k c_k (e_{s_k} − e_{r_k}) ∇_x φ_kᵀ`, the
//! column of `F_θ` for coefficient `c_k` equal to `φ_k (e_{s_k} − e_{r_k})`, and zero
//! columns for initial states; `S(0)` has the unit columns of the initial-state
//! parameters and zeros elsewhere (Hairer, Nørsett & Wanner, *Solving ODEs I*, §I.14).
//!
//! `x` and `S` are advanced together by sysid-core's RK4 step with tangents
//! ([`sysid_core::tangent`]), the same steps and sub-steps as the state simulation, every
//! stage's `F_x` taken at that stage's state. The result is then the exact derivative of
//! the discrete RK4 map ("internal differentiation", Bock 1981), not an approximation of
//! the continuous sensitivity, so it matches central differences of the simulated
//! residuals to their truncation error. The right-hand side repeats the arithmetic of
//! [`Trial`](super::Trial) operation for operation and the step is the one `simulate`
//! takes, so the trajectory is the very one the residuals were computed on.
//!
//! `∂φ_k/∂x_v` are symbolic derivatives ([`Expr::derivative`]) built once per calibration
//! for the states each term reads; inputs need none. Only RK4 is handled here: the
//! caller falls back to finite differences for the adaptive integrator, for a term whose
//! derivative does not build, and when a sensitivity turns non-finite.

// Index loops over small state and parameter blocks read like the equations.
#![allow(clippy::needless_range_loop)]

use nalgebra::DMatrix;
use sysid_core::tangent::{Rk4, StageTangents};
use sysid_core::{CoreError, Dynamics, Experiment, Expr, LinearModel, Term};

use super::Problem;

/// `∂φ/∂x_v` of one term, folded when constant.
#[derive(Debug, Clone)]
enum Partial {
    Constant(f64),
    Expression(Expr),
}

impl Partial {
    fn eval(&self, x: &[f64], u: &[f64]) -> f64 {
        match self {
            Partial::Constant(c) => *c,
            Partial::Expression(e) => e.eval_parts(x, u),
        }
    }
}

/// State derivatives of every term, built once per calibration.
#[derive(Debug, Clone)]
pub(crate) struct Partials {
    /// Per term: `(v, ∂φ/∂x_v)` for each state `v` the term reads (zero ones dropped).
    terms: Vec<Vec<(usize, Partial)>>,
}

impl Partials {
    /// Derivatives of the terms over `n` states; `None` when one does not build.
    pub(crate) fn new(n: usize, terms: &[Term]) -> Option<Self> {
        let mut all = Vec::with_capacity(terms.len());
        for term in terms {
            let mut list = Vec::new();
            for v in term.expr.variables_used().into_iter().filter(|&v| v < n) {
                let d = term.expr.derivative(v).ok()?;
                match d.constant() {
                    Some(0.0) => {}
                    Some(c) => list.push((v, Partial::Constant(c))),
                    None => list.push((v, Partial::Expression(d))),
                }
            }
            all.push(list);
        }
        Some(Self { terms: all })
    }
}

/// What a sensitivity pass gives.
pub(super) enum Outcome {
    /// The residual Jacobian.
    Jacobian(DMatrix<f64>),
    /// A sensitivity became non-finite (e.g. `sqrt` at 0): use finite differences.
    NonFinite,
}

/// What drives one coefficient column of `F_θ`: a term of the model (its value is
/// already computed for the right-hand side) or a term outside it (a screened candidate
/// at coefficient 0, which adds nothing to `F` or `F_x`).
#[derive(Debug, Clone, Copy)]
pub(crate) enum Forcing<'a> {
    /// Term `k` of the model.
    Model(usize),
    /// A term not in the model.
    Extra(&'a Term),
}

/// Forward-sensitivity integration of one model over records: `S` has `q` columns, the
/// coefficient columns `forcing` and, when `x0_block` is set, `n` initial-state columns
/// from that column on.
pub(crate) struct Propagator<'a> {
    /// Linear part.
    pub(crate) linear: &'a LinearModel,
    /// Terms of the model.
    pub(crate) terms: &'a [Term],
    /// Their coefficients (may differ from the terms' own).
    pub(crate) coefficients: &'a [f64],
    /// Their state derivatives.
    pub(crate) partials: &'a Partials,
    /// `(column, forcing)` of every coefficient column.
    pub(crate) forcing: Vec<(usize, Forcing<'a>)>,
    /// First column of the initial-state block, if the initial state is a parameter.
    pub(crate) x0_block: Option<usize>,
    /// Columns of `S`.
    pub(crate) q: usize,
    /// RK4 sub-steps per sample interval.
    pub(crate) substeps: usize,
    /// States beyond this magnitude count as a diverged simulation.
    pub(crate) blow_up: f64,
}

/// One calibration's right-hand side as the RK4 step with tangents reads it: `F`, `F_x` and
/// the coefficient columns of `F_θ` at a stage point from one evaluation of every term
/// (each value serves `F` and its own column), the arithmetic of
/// [`Trial`](super::Trial) and of the partials unchanged.
struct StageEval<'p, 'a> {
    propagator: &'p Propagator<'a>,
    /// `(term, column)` of every coefficient column driven by a model term, by term.
    model_columns: Vec<(usize, usize)>,
    /// `(column, term)` of every coefficient column driven by a term outside the model.
    extra_columns: Vec<(usize, &'a Term)>,
}

impl<'p, 'a> StageEval<'p, 'a> {
    fn new(propagator: &'p Propagator<'a>) -> Self {
        let mut model_columns = Vec::new();
        let mut extra_columns = Vec::new();
        for &(j, forcing) in &propagator.forcing {
            match forcing {
                Forcing::Model(k) => model_columns.push((k, j)),
                Forcing::Extra(term) => extra_columns.push((j, term)),
            }
        }
        model_columns.sort_unstable();
        Self {
            propagator,
            model_columns,
            extra_columns,
        }
    }
}

impl StageTangents for StageEval<'_, '_> {
    /// `F = A x + B u + Σ_k c_k φ_k (e_{s_k} − e_{r_k})` exactly as `Trial::rhs` computes
    /// it, `F_x = A + Σ_k c_k (e_{s_k} − e_{r_k}) ∇_x φ_kᵀ` from the symbolic partials, and
    /// the coefficient columns `φ_k (e_{s_k} − e_{r_k})` of `F_θ` (initial-state columns
    /// have none).
    fn stage(
        &self,
        t: f64,
        x: &[f64],
        u: &[f64],
        k: &mut [f64],
        a: &mut DMatrix<f64>,
        fp: &mut DMatrix<f64>,
    ) {
        let p = self.propagator;
        p.linear.rhs(t, x, u, k);
        a.as_mut_slice().copy_from_slice(p.linear.a().as_slice());
        let mut columns = self.model_columns.iter().peekable();
        for (i, ((term, c), partials)) in p
            .terms
            .iter()
            .zip(p.coefficients)
            .zip(&p.partials.terms)
            .enumerate()
        {
            let value = term.expr.eval_parts(x, u);
            let v = c * value;
            k[term.state] += v;
            if let Some(r) = term.into {
                k[r] -= v;
            }
            while let Some(&(_, j)) = columns.next_if(|(owner, _)| *owner == i) {
                fp[(term.state, j)] += value;
                if let Some(r) = term.into {
                    fp[(r, j)] -= value;
                }
            }
            for (var, partial) in partials {
                let g = c * partial.eval(x, u);
                a[(term.state, *var)] += g;
                if let Some(r) = term.into {
                    a[(r, *var)] -= g;
                }
            }
        }
        for &(j, term) in &self.extra_columns {
            let value = term.expr.eval_parts(x, u);
            fp[(term.state, j)] += value;
            if let Some(r) = term.into {
                fp[(r, j)] -= value;
            }
        }
    }
}

impl Propagator<'_> {
    /// Simulate the first `len` samples of `exp` from `x0` with the sensitivities (by
    /// sysid-core's RK4 step with tangents), calling `at_sample(k, x, S)` at every sample
    /// (`S` is `n × q`). Errors with [`CoreError::Diverged`] as `simulate` does.
    pub(crate) fn run(
        &self,
        exp: &Experiment,
        x0: &[f64],
        len: usize,
        mut at_sample: impl FnMut(usize, &[f64], &DMatrix<f64>),
    ) -> Result<(), CoreError> {
        let n = self.linear.n_states();
        let m = self.linear.n_inputs();
        let q = self.q;
        let stage = StageEval::new(self);
        let mut rk = Rk4::new(n, m, q);
        let mut x = x0.to_vec();
        let mut s = DMatrix::zeros(n, q);
        if let Some(first) = self.x0_block {
            for i in 0..n {
                s[(i, first + i)] = 1.0;
            }
        }
        let substeps = self.substeps.max(1);
        for k in 0..len.min(exp.len()) {
            if k > 0 {
                // The record's own reading between samples k − 1 and k (held, linear or
                // band-limited).
                let ta = exp.t0() + (k - 1) as f64 * exp.dt();
                let tb = exp.t0() + k as f64 * exp.dt();
                let h = (tb - ta) / substeps as f64;
                for j in 0..substeps {
                    let t = ta + j as f64 * h;
                    let input = exp.step_input(k - 1, j, substeps);
                    rk.step_with_stage_tangents(&stage, t, h, &mut x, &mut s, &input);
                }
                if let Some((state, value)) = x
                    .iter()
                    .enumerate()
                    .find(|(_, v)| !v.is_finite() || v.abs() > self.blow_up)
                {
                    return Err(CoreError::Diverged {
                        t: tb,
                        state,
                        value: *value,
                    });
                }
            }
            at_sample(k, &x, &s);
        }
        Ok(())
    }
}

impl Propagator<'_> {
    /// [`Propagator::run`] reduced to weighted output sensitivities: at every measured
    /// (non-NaN) value of the first `len` samples of `exp`, in row order (sample, then
    /// channel), calls `put(row, j, w_ch·(C S)[ch, j])` for every column `j`, with `row`
    /// counted from 0. Returns the number of rows.
    pub(crate) fn run_outputs(
        &self,
        exp: &Experiment,
        x0: &[f64],
        len: usize,
        c: &DMatrix<f64>,
        weights: &[f64],
        mut put: impl FnMut(usize, usize, f64),
    ) -> Result<usize, CoreError> {
        let (n, q) = (self.linear.n_states(), self.q);
        let y = exp.outputs();
        let mut row = 0;
        self.run(exp, x0, len, |k, _, s| {
            for (ch, &w) in weights.iter().enumerate() {
                if y[(ch, k)].is_nan() {
                    continue;
                }
                for j in 0..q {
                    let mut cs = 0.0;
                    for i in 0..n {
                        cs += c[(ch, i)] * s[(i, j)];
                    }
                    put(row, j, w * cs);
                }
                row += 1;
            }
        })?;
        Ok(row)
    }
}

/// The residual Jacobian at `theta` by forward sensitivities, in the row order and with
/// the weighting of `Problem::residuals` (`∂r/∂θ = −√(w_c/M)·C S` at every measured
/// sample within the horizon). `substeps` is the RK4 sub-step count. A diverging
/// simulation is an error naming the experiment, as in `residuals`.
pub(super) fn jacobian(
    problem: &Problem<'_>,
    partials: &Partials,
    theta: &[f64],
    substeps: usize,
) -> Result<Outcome, (usize, CoreError)> {
    let (coefficients, x0) = problem.unpack(theta);
    let n = problem.linear.n_states();
    let nf = problem.free.len();
    let propagator = Propagator {
        linear: problem.linear,
        terms: problem.terms,
        coefficients: &coefficients,
        partials,
        forcing: problem
            .free
            .iter()
            .enumerate()
            .map(|(j, &k)| (j, Forcing::Model(k)))
            .collect(),
        x0_block: problem.estimate_x0.then_some(nf),
        q: nf + if problem.estimate_x0 { n } else { 0 },
        substeps,
        blow_up: problem.blow_up,
    };
    let c = problem.linear.c();
    let scale = 1.0 / (problem.valid as f64).sqrt();
    let row_scale: Vec<f64> = problem.weights.iter().map(|w| -scale * w.sqrt()).collect();
    let mut jac = DMatrix::zeros(problem.valid, theta.len());
    let mut row = 0;
    for (e, exp) in problem.data.experiments().iter().enumerate() {
        // Global column of local column j: this experiment's initial state sits at
        // `nf + e·n` in θ.
        let column = |j: usize| if j < nf { j } else { nf + e * n + (j - nf) };
        let first = row;
        row += propagator
            .run_outputs(exp, &x0[e], problem.lengths[e], c, &row_scale, |r, j, v| {
                jac[(first + r, column(j))] = v;
            })
            .map_err(|err| (e, err))?;
    }
    debug_assert_eq!(row, problem.valid, "rows must match the residuals");
    if jac.iter().all(|v| v.is_finite()) {
        Ok(Outcome::Jacobian(jac))
    } else {
        Ok(Outcome::NonFinite)
    }
}

#[cfg(test)]
mod tests;
