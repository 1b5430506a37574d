//! Score screening for the free-run search: which candidate terms (or pairs) are worth a
//! full calibration.
//!
//! At the current calibrated model (coefficients `θ` of its terms and initial states
//! `x₀`), the free-run cost is `J = ‖r‖²` with `r = √(1/(R_c M))·(y − ŷ)`. Adding a term
//! `c·φ(x, u)` to one equation changes the outputs by `c·s + O(c²)` with the output
//! sensitivity `s = ∂ŷ/∂c` at `c = 0`. Re-fitting `θ` and `x₀` with the new coefficient
//! (Gauss–Newton, one step) lowers `J` by
//!
//! `ΔJ ≈ (s⊥ᵀ r)² / (s⊥ᵀ s⊥)`, `s⊥ = (I − Q Qᵀ) s`,
//!
//! where `Q` spans the sensitivities of the current parameters — the score (Lagrange
//! multiplier) statistic of the added coefficient. For a pair `[s₁ s₂]` the drop is the
//! projection of `r` on their span. The statistic is a linearisation at `c = 0`: it ranks
//! well but can misjudge a term whose right coefficient changes the trajectory a lot, so
//! the search calibrates the few best-ranked candidates fully and decides on those.
//!
//! Sensitivities are forward sensitivities integrated with the current free run (the
//! exact derivative of its RK4 map, see `augment::sensitivity`): one pass gives every
//! parameter's and every candidate's column. Where they are unavailable (adaptive
//! integrator, a term whose derivative does not build, a non-finite sensitivity) they
//! are central differences of whole free-run simulations, with steps scaled so that the
//! term moves its equation's right-hand side by about 1e-4 of its RMS along the current
//! trajectory.

use nalgebra::{DMatrix, DVector};
use sysid_core::{Dataset, Dynamics, Integrator, Term, TermModel};

use crate::augment::{measured_values, simulate_outputs};
use crate::error::{DiscoveryError, Result};
use crate::term_set::RefineCandidate;

mod columns;
use columns::{Columns, difference_columns, forward_columns};

/// Relative size of the finite-difference perturbations.
const REL_STEP: f64 = 1e-4;

/// Sensitivities at the current model.
pub(crate) struct Screen {
    /// Weighted residual `r` (length `M`).
    residual: DVector<f64>,
    /// Candidate sensitivities projected off the current parameters' span (`None` when
    /// the term is identically zero along the trajectory or its simulation diverged).
    projected: Vec<Option<DVector<f64>>>,
    /// Raw candidate sensitivities.
    raw: Vec<Option<DVector<f64>>>,
    /// Sensitivities of the free terms' coefficients (in `free_terms` order; `None` when
    /// not computable) and their current coefficients.
    term_columns: Vec<Option<(DVector<f64>, f64)>>,
    /// Sensitivities of the initial states.
    x0_columns: Vec<DVector<f64>>,
}

/// Stacked weighted outputs `√(1/(R_c M))·ŷ` over the measured values of every experiment.
fn stacked_outputs<D: Dynamics + ?Sized>(
    f: &D,
    c: &DMatrix<f64>,
    data: &Dataset,
    x0: &[Vec<f64>],
    scale: &[f64],
    integrator: &Integrator,
) -> Option<DVector<f64>> {
    let mut out = Vec::new();
    for (exp, x0e) in data.experiments().iter().zip(x0) {
        let y = simulate_outputs(f, c, x0e, exp, integrator).ok()?;
        push_measured(&mut out, exp.outputs(), &y, scale);
    }
    out.iter()
        .all(|v| v.is_finite())
        .then(|| DVector::from_vec(out))
}

/// Append `scale_c · values` at the measured entries of `measured`.
fn push_measured(out: &mut Vec<f64>, measured: &DMatrix<f64>, values: &DMatrix<f64>, s: &[f64]) {
    for k in 0..measured.ncols() {
        for (ch, w) in s.iter().enumerate() {
            if !measured[(ch, k)].is_nan() {
                out.push(w * values[(ch, k)]);
            }
        }
    }
}

/// The current model with its `k`-th term's coefficient replaced.
fn with_coefficient(model: &TermModel, k: usize, value: f64) -> Result<TermModel> {
    let terms: Vec<Term> = model
        .terms()
        .iter()
        .enumerate()
        .map(|(i, t)| Term {
            coefficient: if i == k { value } else { t.coefficient },
            ..t.clone()
        })
        .collect();
    Ok(TermModel::new(model.linear().clone(), terms)?)
}

/// The current model plus one candidate term with coefficient `value`.
fn with_candidate(model: &TermModel, cand: &RefineCandidate, value: f64) -> Result<TermModel> {
    let one = RefineCandidate {
        coefficient: value,
        ..cand.clone()
    };
    crate::term_set::build(model, std::slice::from_ref(&one), &[0])
}

/// RMS of each state's right-hand side and of a candidate's basis along a trajectory.
fn rms_along(values: impl Iterator<Item = f64>) -> f64 {
    let (mut s, mut n) = (0.0, 0usize);
    for v in values {
        if v.is_finite() {
            s += v * v;
            n += 1;
        }
    }
    if n == 0 { 0.0 } else { (s / n as f64).sqrt() }
}

impl Screen {
    /// Sensitivities of the calibrated `model` (its terms `free_terms` and every initial
    /// state are the current parameters) and of every candidate not in `exclude`.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn new(
        model: &TermModel,
        free_terms: &[usize],
        x0: &[Vec<f64>],
        candidates: &[RefineCandidate],
        exclude: &[usize],
        data: &Dataset,
        noise: &[f64],
        integrator: &Integrator,
    ) -> Result<Self> {
        let linear = model.linear();
        let c = linear.c();
        let m = measured_values(data).max(1) as f64;
        let scale: Vec<f64> = noise.iter().map(|r| 1.0 / (r * m).sqrt()).collect();
        let y0 = stacked_outputs(model, c, data, x0, &scale, integrator).ok_or(
            DiscoveryError::InvalidConfig {
                field: "current model",
                value: f64::NAN,
                reason: "its free-run simulation diverges",
            },
        )?;
        let mut y_meas = Vec::with_capacity(y0.len());
        for exp in data.experiments() {
            push_measured(&mut y_meas, exp.outputs(), exp.outputs(), &scale);
        }
        let residual = DVector::from_vec(y_meas) - &y0;

        // Trajectory statistics for the step sizes: RHS RMS per state, along the current
        // free run of every experiment.
        let n = linear.n_states();
        let mut trajectories = Vec::new();
        for (exp, x0e) in data.experiments().iter().zip(x0) {
            let xs = sysid_core::simulate_experiment(
                model,
                x0e,
                exp,
                0..exp.len(),
                integrator,
                sysid_core::integrate::DEFAULT_BLOW_UP,
            )?;
            trajectories.push((xs, exp.inputs().clone()));
        }
        let mut rhs_rms = vec![0.0; n];
        {
            let mut dx = vec![0.0; n];
            let mut sums = vec![0.0; n];
            let mut count = 0usize;
            for (xs, us) in &trajectories {
                for k in 0..xs.ncols() {
                    let (x, u) = at_sample(xs, us, k);
                    model.rhs(0.0, x, u, &mut dx);
                    for (s, d) in sums.iter_mut().zip(&dx) {
                        *s += d * d;
                    }
                    count += 1;
                }
            }
            for (r, s) in rhs_rms.iter_mut().zip(&sums) {
                *r = (s / count.max(1) as f64).sqrt();
            }
        }
        let basis_rms = |t: &Term| {
            rms_along(trajectories.iter().flat_map(|(xs, us)| {
                (0..xs.ncols()).map(move |k| {
                    let (x, u) = at_sample(xs, us, k);
                    t.eval(x, u)
                })
            }))
        };

        // Steps of the finite differences; a term whose step is degenerate (zero along
        // the trajectory with a zero coefficient, or not finite) gets no column either way.
        let term_steps: Vec<Option<f64>> = free_terms
            .iter()
            .map(|&k| {
                let t = &model.terms()[k];
                let h = REL_STEP
                    * t.coefficient
                        .abs()
                        .max(rhs_rms[t.state] / basis_rms(t).max(1e-300));
                (h.is_finite() && h > 0.0).then_some(h)
            })
            .collect();
        let mut probes: Vec<Option<(Term, f64)>> = Vec::with_capacity(candidates.len());
        for (i, cand) in candidates.iter().enumerate() {
            if exclude.contains(&i) {
                probes.push(None);
                continue;
            }
            let probe = with_candidate(model, cand, 1.0)?;
            let Some(term) = probe.terms().last() else {
                probes.push(None);
                continue;
            };
            let phi = basis_rms(term);
            let h = REL_STEP * rhs_rms[term.state].max(1e-12) / phi;
            probes.push((phi > 0.0 && h.is_finite()).then(|| (term.clone(), h)));
        }

        let columns = match forward_columns(
            model,
            free_terms,
            &term_steps,
            &probes,
            x0,
            data,
            &scale,
            integrator,
        ) {
            Some(columns) => columns,
            None => difference_columns(
                model,
                free_terms,
                &term_steps,
                candidates,
                &probes,
                x0,
                data,
                &scale,
                integrator,
                &trajectories,
            )?,
        };
        let Columns {
            terms: term_columns,
            x0: x0_columns,
            candidates: raw,
        } = columns;
        let term_columns: Vec<Option<(DVector<f64>, f64)>> = term_columns
            .into_iter()
            .zip(free_terms)
            .map(|(col, &k)| col.map(|c| (c, model.terms()[k].coefficient)))
            .collect();
        let current: Vec<DVector<f64>> = term_columns
            .iter()
            .flatten()
            .map(|(col, _)| col.clone())
            .chain(x0_columns.iter().cloned())
            .collect();
        let basis = orthonormal_basis(&current, y0.len());
        let projected = raw
            .iter()
            .map(|s| s.as_ref().map(|s| project_off(&basis, s.clone())))
            .collect();
        Ok(Self {
            residual,
            projected,
            raw,
            term_columns,
            x0_columns,
        })
    }

    /// Predicted cost after exchanging the current model's free term `k` (its position in
    /// `free_terms`) for candidate `i`, and the candidate's Gauss–Newton coefficient:
    /// with `z = r + c_k s_k` (the residual without term `k`) and everything projected off
    /// the other parameters, `J ≈ ‖z⊥‖² − (s_i⊥ᵀ z⊥)²/‖s_i⊥‖²`.
    pub(crate) fn swap(&self, k: usize, i: usize) -> Option<(f64, f64)> {
        let (sk, ck) = self.term_columns.get(k)?.as_ref()?;
        let si = self.raw.get(i)?.as_ref()?;
        let others: Vec<DVector<f64>> = self
            .term_columns
            .iter()
            .enumerate()
            .filter(|(j, _)| *j != k)
            .filter_map(|(_, c)| c.as_ref().map(|(col, _)| col.clone()))
            .chain(self.x0_columns.iter().cloned())
            .collect();
        let basis = orthonormal_basis(&others, self.residual.len());
        let z = project_off(&basis, &self.residual + sk * *ck);
        let s = project_off(&basis, si.clone());
        let ss = s.norm_squared();
        if ss <= 0.0 {
            return None;
        }
        let sz = s.dot(&z);
        Some((z.norm_squared() - sz * sz / ss, sz / ss))
    }

    /// The current cost `‖r‖²`.
    pub(crate) fn cost(&self) -> f64 {
        self.residual.norm_squared()
    }

    /// Predicted cost drop and Gauss–Newton coefficient of adding candidate `i`.
    pub(crate) fn single(&self, i: usize) -> Option<(f64, f64)> {
        let s = self.projected.get(i)?.as_ref()?;
        let ss = s.norm_squared();
        if ss <= 0.0 {
            return None;
        }
        let sr = s.dot(&self.residual);
        Some((sr * sr / ss, sr / ss))
    }

    /// Predicted cost drop and Gauss–Newton coefficients of adding candidates `i` and `j`.
    pub(crate) fn pair(&self, i: usize, j: usize) -> Option<(f64, [f64; 2])> {
        let a = self.projected.get(i)?.as_ref()?;
        let b = self.projected.get(j)?.as_ref()?;
        let (aa, ab, bb) = (a.norm_squared(), a.dot(b), b.norm_squared());
        let (ar, br) = (a.dot(&self.residual), b.dot(&self.residual));
        let det = aa * bb - ab * ab;
        // Nearly collinear pairs (|cos| > 0.9999) name nothing the single step could not.
        if det.is_nan() || det <= 1e-8 * aa * bb {
            return None;
        }
        let ci = (bb * ar - ab * br) / det;
        let cj = (aa * br - ab * ar) / det;
        Some((ci * ar + cj * br, [ci, cj]))
    }
}

/// State and input at sample `k` as slices of the column-major matrices (no copy).
fn at_sample<'a>(xs: &'a DMatrix<f64>, us: &'a DMatrix<f64>, k: usize) -> (&'a [f64], &'a [f64]) {
    let (n, m) = (xs.nrows(), us.nrows());
    (
        &xs.as_slice()[k * n..(k + 1) * n],
        &us.as_slice()[k * m..(k + 1) * m],
    )
}

/// `v` minus its projection on the orthonormal `basis`.
fn project_off(basis: &[DVector<f64>], mut v: DVector<f64>) -> DVector<f64> {
    for q in basis {
        let d = q.dot(&v);
        v.axpy(-d, q, 1.0);
    }
    v
}

/// Typical magnitude of state `j` along a trajectory (for the x₀ step size).
fn state_scale(xs: &DMatrix<f64>, j: usize) -> f64 {
    rms_along(xs.row(j).iter().copied()).max(1e-6)
}

/// Gram–Schmidt (twice) basis of the columns' span; dependent columns are dropped.
fn orthonormal_basis(columns: &[DVector<f64>], len: usize) -> Vec<DVector<f64>> {
    let mut basis: Vec<DVector<f64>> = Vec::new();
    for col in columns {
        if col.len() != len {
            continue;
        }
        let norm0 = col.norm();
        if norm0.is_nan() || norm0 <= 0.0 {
            continue;
        }
        let mut v = col.clone();
        for _ in 0..2 {
            for q in &basis {
                let d = q.dot(&v);
                v.axpy(-d, q, 1.0);
            }
        }
        let norm = v.norm();
        if norm > 1e-10 * norm0 {
            basis.push(v / norm);
        }
    }
    basis
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The pair drop is the squared norm of the residual's projection on the span of the
    /// two columns, checked against a least-squares solve by normal equations.
    #[test]
    fn pair_drop_is_the_projection_on_the_span() {
        let a = DVector::from_vec(vec![1.0, 0.0, 1.0, 2.0]);
        let b = DVector::from_vec(vec![0.0, 1.0, 1.0, -1.0]);
        let r = DVector::from_vec(vec![0.5, -0.2, 0.3, 0.9]);
        let screen = Screen {
            residual: r.clone(),
            projected: vec![Some(a.clone()), Some(b.clone())],
            raw: vec![Some(a.clone()), Some(b.clone())],
            term_columns: vec![],
            x0_columns: vec![],
        };
        let (drop, [ca, cb]) = screen.pair(0, 1).unwrap();
        let x = DMatrix::from_columns(&[a.clone(), b.clone()]);
        let coef = (x.transpose() * &x).try_inverse().unwrap() * x.transpose() * &r;
        let fitted = &x * &coef;
        assert!((ca - coef[0]).abs() < 1e-12 && (cb - coef[1]).abs() < 1e-12);
        assert!((drop - fitted.norm_squared()).abs() < 1e-12);
        // The single drop of `a` is its one-column projection.
        let (d1, c1) = screen.single(0).unwrap();
        assert!((c1 - a.dot(&r) / a.norm_squared()).abs() < 1e-12);
        assert!((d1 - (a.dot(&r)).powi(2) / a.norm_squared()).abs() < 1e-12);
        assert!(d1 <= drop + 1e-12);
    }

    /// The exchange prediction is the least-squares cost of the residual without term
    /// `k` (`r + c_k s_k`) regressed on the candidate and the other parameters.
    #[test]
    fn swap_prediction_matches_least_squares() {
        let col = |v: &[f64]| DVector::from_vec(v.to_vec());
        let sk = col(&[1.0, 0.5, -0.2, 0.3, 0.0, 1.0]);
        let other = col(&[0.0, 1.0, 1.0, 0.0, 2.0, -1.0]);
        let x0c = col(&[1.0, 1.0, 1.0, 1.0, 1.0, 1.0]);
        let si = col(&[0.3, -1.0, 0.4, 2.0, 0.1, 0.0]);
        let r = col(&[0.1, -0.3, 0.2, 0.05, -0.1, 0.2]);
        let ck = 0.7;
        let screen = Screen {
            residual: r.clone(),
            projected: vec![None],
            raw: vec![Some(si.clone())],
            term_columns: vec![Some((sk.clone(), ck)), Some((other.clone(), -0.4))],
            x0_columns: vec![x0c.clone()],
        };
        let (predicted, _) = screen.swap(0, 0).unwrap();
        let z = &r + &sk * ck;
        let x = DMatrix::from_columns(&[si, other, x0c]);
        let beta = (x.transpose() * &x).try_inverse().unwrap() * x.transpose() * &z;
        let want = (z - &x * beta).norm_squared();
        assert!((predicted - want).abs() < 1e-12, "{predicted} vs {want}");
    }

    #[test]
    fn basis_is_orthonormal_and_drops_dependent_columns() {
        let a = DVector::from_vec(vec![1.0, 2.0, 0.0]);
        let b = DVector::from_vec(vec![2.0, 4.0, 0.0]);
        let c = DVector::from_vec(vec![0.0, 1.0, 1.0]);
        let q = orthonormal_basis(&[a, b, c], 3);
        assert_eq!(q.len(), 2);
        for v in &q {
            assert!((v.norm() - 1.0).abs() < 1e-12);
        }
        assert!(q[0].dot(&q[1]).abs() < 1e-12);
    }
}
