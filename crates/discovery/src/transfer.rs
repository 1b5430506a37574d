//! Transfer candidates: a flow that leaves one state and enters another under one
//! coefficient. When the assumed linear model already routes state `j`'s flow from
//! equation `i` to equation `k` — `A[k][j] = −A[i][j] ≠ 0`, the signature of conservation
//! (an upper tank's outflow is the lower tank's inflow; heat leaving one body enters the
//! next) — a missing effect in that flow law (orifice `√h` instead of a linear outflow)
//! must appear in both equations with opposite signs. Offering the pair as one
//! candidate halves its parameters and keeps the free-run search from fitting the second
//! equation's share with unrelated terms. The ordinary one-equation candidate stays in
//! the list; the search decides between them.
//!
//! What this module does not do: it never assumes conservation the assumed model does
//! not already state.

use sysid_core::{Expr, LinearModel, term_variables};

use crate::augment::measured_values;
use crate::error::Result;
use crate::refine::{RefineCandidate, Refinement, Search, refine_with_holdout};
use crate::stats::chi2_quantile;

/// Relative tolerance of `A[k][j] = −A[i][j]` (model files carry ~16 digits; a
/// hand-written model with rounded entries still matches to 1e-6).
const MATCH_RTOL: f64 = 1e-6;

/// Every routing `(i, j, k)` of the assumed model: state `j`'s linear flow leaves
/// equation `i` and enters equation `k` (`A[k][j] = −A[i][j] ≠ 0`, `k ≠ i`, and
/// `A[i][j] < 0` so that `i` is the source).
pub fn routings(linear: &LinearModel) -> Vec<(usize, usize, usize)> {
    let a = linear.a();
    let n = a.nrows();
    let mut out = Vec::new();
    for j in 0..n {
        for i in 0..n {
            let aij = a[(i, j)];
            if aij >= 0.0 || aij.is_nan() {
                continue;
            }
            for k in (0..n).filter(|&k| k != i) {
                if (a[(k, j)] + aij).abs() <= MATCH_RTOL * aij.abs() {
                    out.push((i, j, k));
                }
            }
        }
    }
    out
}

/// For every candidate of equation `i` whose expression reads a state `j` routed from
/// `i` to some `k` ([`routings`]), a transfer copy into `k` (starting coefficient 0).
/// Candidates that are already transfers, or whose expression does not parse over the
/// model's names, get none. The copies are returned in candidate order, without
/// duplicates.
pub fn transfer_candidates(
    linear: &LinearModel,
    candidates: &[RefineCandidate],
) -> Vec<RefineCandidate> {
    let routes = routings(linear);
    if routes.is_empty() {
        return Vec::new();
    }
    let names = linear.state_names();
    let variables = term_variables(linear);
    let n = linear.n_states();
    let mut out: Vec<RefineCandidate> = Vec::new();
    for cand in candidates.iter().filter(|c| c.into.is_none()) {
        let Some(i) = names.iter().position(|s| *s == cand.state) else {
            continue;
        };
        let Ok(expr) = Expr::parse(&cand.term, &variables) else {
            continue;
        };
        let used = expr.variables_used();
        for &(_, _, k) in routes
            .iter()
            .filter(|(ri, j, _)| *ri == i && *j < n && used.contains(j))
        {
            let copy = RefineCandidate {
                into: Some(names[k].clone()),
                coefficient: 0.0,
                ..cand.clone()
            };
            if !out.contains(&copy) {
                out.push(copy);
            }
        }
    }
    out
}

/// The conserved variant of a candidate list: every candidate that has a transfer copy
/// in `transfers` is replaced by it in place (the first copy, keeping the starting
/// coefficient), the rest kept — so indices into the list (a starting set) stay valid.
pub fn conserved_variant(
    candidates: &[RefineCandidate],
    transfers: &[RefineCandidate],
) -> Vec<RefineCandidate> {
    candidates
        .iter()
        .map(|c| {
            transfers
                .iter()
                .find(|t| c.into.is_none() && t.state == c.state && t.term == c.term)
                .map_or_else(
                    || c.clone(),
                    |t| RefineCandidate {
                        coefficient: c.coefficient,
                        ..t.clone()
                    },
                )
        })
        .collect()
}

/// [`refine_with_holdout`] twice when the assumed model routes flows ([`routings`]): once
/// over `candidates` as given (every term in one equation) and once over their
/// [`conserved_variant`] (terms of routed states as transfers), and the better of the two
/// on the judged records, scored by `M·J + p·χ²₁(1 − α)` (`M` judged values, `J` the
/// judged free-run cost, `p` kept terms: the search's own price per term). Conservation
/// is the hypothesis the assumed model already makes, so the burden of proof is on
/// breaking it: the plain search wins only when its score is lower by more than one
/// more χ²₁(1 − α) — the same test as for adding a term. (When both reach the noise
/// level the data cannot tell them apart, and the routed explanation is kept.) Returns
/// the refinement and the candidate list its `selected` indices refer to (the search's
/// own `candidates`, as it left them). Without routings this is one plain search.
pub fn refine_with_transfers(
    search: &Search<'_>,
    candidates: &[RefineCandidate],
    initial: &[usize],
) -> Result<(Refinement, Vec<RefineCandidate>)> {
    let plain = refine_with_holdout(search, candidates, initial)?;
    let transfers = transfer_candidates(search.base.linear(), candidates);
    if transfers.is_empty() {
        let list = plain.candidates.clone();
        return Ok((plain, list));
    }
    let conserved = conserved_variant(candidates, &transfers);
    let routed = refine_with_holdout(search, &conserved, initial)?;
    let m = measured_values(search.holdout.map_or(search.data, |h| h.data)) as f64;
    let price = chi2_quantile(1.0 - search.config.alpha, 1.0)?;
    let score = |r: &Refinement| {
        let j = r.cost[1];
        if j.is_finite() {
            m * j + r.selected.len() as f64 * price
        } else {
            f64::INFINITY
        }
    };
    let best = if score(&routed) <= score(&plain) + price {
        routed
    } else {
        plain
    };
    let list = best.candidates.clone();
    Ok((best, list))
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::DMatrix;
    use sysid_core::ModelNames;

    fn model(a: &[f64], n: usize) -> LinearModel {
        let states: Vec<String> = (1..=n).map(|i| format!("h{i}")).collect();
        let names = ModelNames {
            states: states.clone(),
            inputs: vec!["u".into()],
            outputs: states.clone(),
            corrections: states,
        };
        LinearModel::with_names(
            DMatrix::from_row_slice(n, n, a),
            DMatrix::from_element(n, 1, 0.0),
            DMatrix::identity(n, n),
            DMatrix::identity(n, n),
            names,
        )
        .unwrap_or_else(|e| panic!("{e}"))
    }

    fn cand(state: &str, term: &str) -> RefineCandidate {
        RefineCandidate {
            effect: "orifice_outflow".into(),
            state: state.into(),
            into: None,
            term: term.into(),
            coefficient: 0.1,
            variables: vec![],
            parameters: vec![],
        }
    }

    /// Three cascaded tanks route h1 → h2 → h3; a mass–spring–damper routes nothing
    /// (its `A[v][x] = −k/m` has no matching positive entry).
    #[test]
    fn routings_follow_conserved_columns() {
        let tanks = model(&[-0.06, 0.0, 0.0, 0.06, -0.08, 0.0, 0.0, 0.08, -0.1], 3);
        assert_eq!(routings(&tanks), vec![(0, 0, 1), (1, 1, 2)]);
        let msd = model(&[0.0, 1.0, -4.0, -0.2], 2);
        assert!(routings(&msd).is_empty());
    }

    /// Only terms reading the routed state get a transfer copy, into the routed equation,
    /// with coefficient 0.
    #[test]
    fn copies_only_terms_of_the_routed_state() {
        let tanks = model(&[-0.06, 0.0, 0.06, -0.08], 2);
        let cands = vec![
            cand("h1", "sqrt(abs(h1))"),
            cand("h1", "1"),
            cand("h1", "u"),
            cand("h2", "sqrt(abs(h2))"),
            cand("h2", "sqrt(abs(h1))"),
        ];
        let copies = transfer_candidates(&tanks, &cands);
        assert_eq!(copies.len(), 1, "{copies:?}");
        assert_eq!(copies[0].state, "h1");
        assert_eq!(copies[0].into.as_deref(), Some("h2"));
        assert_eq!(copies[0].term, "sqrt(abs(h1))");
        assert!(copies[0].coefficient.abs() < f64::MIN_POSITIVE);
    }

    /// The conserved variant replaces routed candidates in place (indices of a starting
    /// set stay valid) and keeps their starting coefficients; the rest are unchanged.
    #[test]
    fn conserved_variant_replaces_in_place() {
        let tanks = model(&[-0.06, 0.0, 0.06, -0.08], 2);
        let cands = vec![cand("h2", "sqrt(abs(h2))"), cand("h1", "sqrt(abs(h1))")];
        let transfers = transfer_candidates(&tanks, &cands);
        let conserved = conserved_variant(&cands, &transfers);
        assert_eq!(conserved.len(), 2);
        assert_eq!(conserved[0], cands[0]);
        assert_eq!(conserved[1].into.as_deref(), Some("h2"));
        assert_eq!(conserved[1].term, "sqrt(abs(h1))");
        assert!((conserved[1].coefficient - 0.1).abs() < 1e-15);
    }
}
