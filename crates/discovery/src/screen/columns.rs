//! Output sensitivities of the screen: of the current model's parameters (free
//! coefficients, initial states) and of candidate terms at coefficient 0, by forward
//! sensitivities or, where those are unavailable, by central differences.

use nalgebra::{DMatrix, DVector};
use sysid_core::{Dataset, Integrator, Term, TermModel};

use super::{
    REL_STEP, push_measured, stacked_outputs, state_scale, with_candidate, with_coefficient,
};
use crate::augment::sensitivity::{Forcing, Partials, Propagator};
use crate::augment::{measured_values, simulate_outputs};
use crate::error::Result;
use crate::term_set::RefineCandidate;

/// Output sensitivities `∂(√(1/(R_c M))·ŷ)/∂θ` of the current parameters and of the
/// candidates at coefficient 0, one entry per measured value.
pub(super) struct Columns {
    /// Per free term (`None`: degenerate step or not computable).
    pub(super) terms: Vec<Option<DVector<f64>>>,
    /// The computable initial-state columns, experiment by experiment.
    pub(super) x0: Vec<DVector<f64>>,
    /// Per candidate (`None`: excluded, identically zero or not computable).
    pub(super) candidates: Vec<Option<DVector<f64>>>,
}

/// [`Columns`] by forward sensitivities integrated with the current free run (module
/// `augment::sensitivity`): a candidate at coefficient 0 only adds its `F_θ` column.
/// `None` when they are not available (adaptive integrator, a derivative that does not
/// build, a diverging run, a non-finite sensitivity such as `sqrt` at 0, which would
/// spread to every column): the caller then differences.
#[allow(clippy::too_many_arguments)]
pub(super) fn forward_columns(
    model: &TermModel,
    free_terms: &[usize],
    term_steps: &[Option<f64>],
    probes: &[Option<(Term, f64)>],
    x0: &[Vec<f64>],
    data: &Dataset,
    scale: &[f64],
    integrator: &Integrator,
) -> Option<Columns> {
    let Integrator::Rk4 { substeps } = *integrator else {
        return None;
    };
    let linear = model.linear();
    let n = linear.n_states();
    let partials = Partials::new(n, model.terms())?;
    let coefficients: Vec<f64> = model.terms().iter().map(|t| t.coefficient).collect();
    let nf = free_terms.len();
    let mut forcing: Vec<(usize, Forcing<'_>)> = free_terms
        .iter()
        .enumerate()
        .map(|(j, &k)| (j, Forcing::Model(k)))
        .collect();
    // Shared columns: the free terms, then the live candidates.
    let mut candidate_column = vec![None; probes.len()];
    for (i, probe) in probes.iter().enumerate() {
        if let Some((term, _)) = probe {
            candidate_column[i] = Some(forcing.len());
            forcing.push((forcing.len() + n, Forcing::Extra(term)));
        }
    }
    let shared_count = forcing.len();
    let propagator = Propagator {
        linear,
        terms: model.terms(),
        coefficients: &coefficients,
        partials: &partials,
        forcing,
        x0_block: Some(nf),
        q: shared_count + n,
        substeps,
        blow_up: sysid_core::integrate::DEFAULT_BLOW_UP,
    };
    let rows = measured_values(data);
    let c = linear.c();
    let mut shared = DMatrix::zeros(rows, shared_count);
    let mut x0_columns = Vec::with_capacity(n * data.experiments().len());
    let mut row = 0;
    for (exp, x0e) in data.experiments().iter().zip(x0) {
        let mut block = vec![DVector::zeros(rows); n];
        let first = row;
        row += propagator
            .run_outputs(exp, x0e, exp.len(), c, scale, |r, j, v| match j {
                j if j < nf => shared[(first + r, j)] = v,
                j if j < nf + n => block[j - nf][first + r] = v,
                j => shared[(first + r, j - n)] = v,
            })
            .ok()?;
        if !block.iter().all(|b| b.iter().all(|v| v.is_finite())) {
            return None;
        }
        x0_columns.extend(block);
    }
    if !shared.iter().all(|v| v.is_finite()) {
        return None;
    }
    let column = |j: usize| shared.column(j).into_owned();
    Some(Columns {
        terms: term_steps
            .iter()
            .enumerate()
            .map(|(j, h)| h.map(|_| column(j)))
            .collect(),
        x0: x0_columns,
        candidates: candidate_column.iter().map(|j| j.map(column)).collect(),
    })
}

/// [`Columns`] by central differences of whole free runs, with the steps `term_steps`,
/// the probes' steps, and `REL_STEP` of each initial state (or of its typical size).
#[allow(clippy::too_many_arguments)]
pub(super) fn difference_columns(
    model: &TermModel,
    free_terms: &[usize],
    term_steps: &[Option<f64>],
    candidates: &[RefineCandidate],
    probes: &[Option<(Term, f64)>],
    x0: &[Vec<f64>],
    data: &Dataset,
    scale: &[f64],
    integrator: &Integrator,
    trajectories: &[(DMatrix<f64>, DMatrix<f64>)],
) -> Result<Columns> {
    let c = model.linear().c();
    let n = model.linear().n_states();
    let rows = measured_values(data);
    let mut terms = Vec::with_capacity(free_terms.len());
    for (&k, h) in free_terms.iter().zip(term_steps) {
        let Some(h) = *h else {
            terms.push(None);
            continue;
        };
        let coefficient = model.terms()[k].coefficient;
        let plus = with_coefficient(model, k, coefficient + h)?;
        let minus = with_coefficient(model, k, coefficient - h)?;
        terms.push(
            match (
                stacked_outputs(&plus, c, data, x0, scale, integrator),
                stacked_outputs(&minus, c, data, x0, scale, integrator),
            ) {
                (Some(a), Some(b)) => Some((a - b) / (2.0 * h)),
                _ => None,
            },
        );
    }
    let mut x0_columns: Vec<DVector<f64>> = Vec::new();
    let mut offset = 0;
    for (e, (exp, x0e)) in data.experiments().iter().zip(x0).enumerate() {
        let len: usize = exp.outputs().iter().filter(|v| !v.is_nan()).count();
        for j in 0..n {
            let h = REL_STEP * x0e[j].abs().max(1e-3 * state_scale(&trajectories[e].0, j));
            let mut xp = x0e.clone();
            xp[j] += h;
            let mut xm = x0e.clone();
            xm[j] -= h;
            let (Ok(a), Ok(b)) = (
                simulate_outputs(model, c, &xp, exp, integrator),
                simulate_outputs(model, c, &xm, exp, integrator),
            ) else {
                continue;
            };
            let mut pa = Vec::with_capacity(len);
            let mut pb = Vec::with_capacity(len);
            push_measured(&mut pa, exp.outputs(), &a, scale);
            push_measured(&mut pb, exp.outputs(), &b, scale);
            let mut col = DVector::zeros(rows);
            for i in 0..len {
                col[offset + i] = (pa[i] - pb[i]) / (2.0 * h);
            }
            if col.iter().all(|v| v.is_finite()) {
                x0_columns.push(col);
            }
        }
        offset += len;
    }
    let mut columns = Vec::with_capacity(candidates.len());
    for (cand, probe) in candidates.iter().zip(probes) {
        let Some((_, h)) = probe else {
            columns.push(None);
            continue;
        };
        let plus = with_candidate(model, cand, *h)?;
        let minus = with_candidate(model, cand, -*h)?;
        columns.push(
            match (
                stacked_outputs(&plus, c, data, x0, scale, integrator),
                stacked_outputs(&minus, c, data, x0, scale, integrator),
            ) {
                (Some(a), Some(b)) => Some((a - b) / (2.0 * h)),
                _ => None,
            },
        );
    }
    Ok(Columns {
        terms,
        x0: x0_columns,
        candidates: columns,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Forward-sensitivity columns equal the central-difference ones: a damped pendulum
    /// with a calibrated `sin θ` term, two records (one with a gap), candidates with an
    /// input, a transfer and a polynomial, one left out. The differences use steps of
    /// 1e-4 of the scale, so they err by ~1e-8 relative (truncation `h²·s‴/6`), the
    /// sensitivities by rounding only: 1e-5 of each column's norm separates a right
    /// column from a wrong sign, weight or row by orders of magnitude.
    #[test]
    fn forward_columns_match_differences() {
        use sysid_core::{Channel, Experiment, LinearModel, ModelNames};
        let own = |v: &[&str]| v.iter().map(|s| s.to_string()).collect::<Vec<_>>();
        let linear = LinearModel::with_names(
            DMatrix::from_row_slice(2, 2, &[0.0, 1.0, 0.0, -0.2]),
            DMatrix::from_row_slice(2, 1, &[0.0, 1.0]),
            DMatrix::from_row_slice(1, 2, &[1.0, 0.0]),
            DMatrix::identity(2, 2),
            ModelNames {
                states: own(&["theta", "omega"]),
                inputs: own(&["u"]),
                outputs: own(&["theta"]),
                corrections: own(&["theta", "omega"]),
            },
        )
        .unwrap_or_else(|e| panic!("{e}"));
        let model =
            TermModel::from_specs(linear.clone(), [("omega", "gravity", "sin(theta)", -4.0)])
                .unwrap_or_else(|e| panic!("{e}"));
        let integrator = Integrator::Rk4 { substeps: 4 };
        let x0 = vec![vec![0.6, 0.0], vec![-0.3, 0.5]];
        let experiments: Vec<Experiment> = x0
            .iter()
            .enumerate()
            .map(|(e, x)| {
                let len = 150 + 50 * e;
                let u = DMatrix::from_fn(1, len, |_, k| (0.05 * (e + 2) as f64 * k as f64).sin());
                let blank = Experiment::new(0.0, 0.05, u.clone(), DMatrix::zeros(1, len))
                    .unwrap_or_else(|e| panic!("{e}"));
                let mut y = simulate_outputs(&model, linear.c(), x, &blank, &integrator)
                    .unwrap_or_else(|e| panic!("{e}"));
                y.iter_mut()
                    .enumerate()
                    .for_each(|(k, v)| *v += 0.01 * (k as f64).cos());
                if e == 1 {
                    y[(0, 20)] = f64::NAN;
                }
                Experiment::new(0.0, 0.05, u, y).unwrap_or_else(|e| panic!("{e}"))
            })
            .collect();
        let data = Dataset::new(
            vec![Channel::new("u")],
            vec![Channel::new("theta")],
            experiments,
        )
        .unwrap_or_else(|e| panic!("{e}"));
        let cand = |state: &str, into: Option<&str>, term: &str| RefineCandidate {
            effect: "probe".into(),
            state: state.into(),
            into: into.map(Into::into),
            term: term.into(),
            coefficient: 0.0,
            variables: vec![],
            parameters: vec![],
        };
        let candidates = [
            cand("omega", None, "u*cos(theta)"),
            cand("theta", Some("omega"), "theta^3"),
            cand("omega", None, "omega*abs(omega)"),
            cand("omega", None, "theta"),
        ];
        // The last candidate is left out (as an excluded one is).
        let probes: Vec<Option<(Term, f64)>> = candidates
            .iter()
            .enumerate()
            .map(|(i, c)| {
                let probe = with_candidate(&model, c, 1.0).unwrap_or_else(|e| panic!("{e}"));
                let term = probe.terms().last().cloned();
                term.filter(|_| i != 3).map(|t| (t, 1e-4))
            })
            .collect();
        let scale = [0.7];
        let steps = [Some(4e-4)];
        let forward = forward_columns(
            &model,
            &[0],
            &steps,
            &probes,
            &x0,
            &data,
            &scale,
            &integrator,
        )
        .unwrap_or_else(|| panic!("forward sensitivities unavailable"));
        let trajectories: Vec<(DMatrix<f64>, DMatrix<f64>)> = data
            .experiments()
            .iter()
            .zip(&x0)
            .map(|(exp, x)| {
                let xs =
                    sysid_core::simulate(&model, x, 0.0, exp.dt(), exp.inputs(), &integrator, 1e12)
                        .unwrap_or_else(|e| panic!("{e}"));
                (xs, exp.inputs().clone())
            })
            .collect();
        let fd = difference_columns(
            &model,
            &[0],
            &steps,
            &candidates,
            &probes,
            &x0,
            &data,
            &scale,
            &integrator,
            &trajectories,
        )
        .unwrap_or_else(|e| panic!("{e}"));
        let close = |a: &DVector<f64>, b: &DVector<f64>, what: &str| {
            assert_eq!(a.len(), b.len(), "{what}");
            let norm = b.norm();
            assert!(norm > 0.0, "{what}: a zero column proves nothing");
            let err = (a - b).norm();
            assert!(
                err <= 1e-5 * norm,
                "{what}: |fwd − fd| = {err:e}, |fd| = {norm:e}"
            );
        };
        let pairs = |a: &[Option<DVector<f64>>], b: &[Option<DVector<f64>>], what: &str| {
            assert_eq!(a.len(), b.len());
            for (i, (x, y)) in a.iter().zip(b).enumerate() {
                match (x, y) {
                    (Some(x), Some(y)) => close(x, y, &format!("{what} {i}")),
                    (None, None) => {}
                    _ => panic!("{what} {i}: one method has a column, the other none"),
                }
            }
        };
        pairs(&forward.terms, &fd.terms, "term");
        pairs(&forward.candidates, &fd.candidates, "candidate");
        assert!(forward.candidates[3].is_none() && forward.candidates[0].is_some());
        assert_eq!((forward.x0.len(), fd.x0.len()), (4, 4));
        for (i, (a, b)) in forward.x0.iter().zip(&fd.x0).enumerate() {
            close(a, b, &format!("x0 {i}"));
        }
    }
}
