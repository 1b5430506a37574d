//! Which unmeasured states the measurements leave without a scale, and which candidate
//! terms touch them: the structural ambiguity of partial observation.
//!
//! When a state `x_j` is not measured and every equation it enters is corrected, the
//! substitution `x_j → c·x_j` maps a model onto another one that produces the same
//! outputs, with the coefficients of `x_j`'s own equation and of its terms in other
//! equations rescaled. The catalogue's terms are (nearly all) homogeneous — `√(c·h) =
//! √c·√h`, `(c·x)³ = c³·x³`, `sign(c·v) = sign(v)` — so a rescaled model is again a
//! catalogue model, and a calibrated set of terms that touches such a state is only one
//! of a family the data cannot tell apart (in the two-tank example with only the lower
//! level measured, a halved input gain in the upper tank plus couplings and a `√h₂`
//! simulate the lower level as well as the true orifice laws). Conservation (a
//! transfer's one coefficient in both equations) or a known equation can break the
//! symmetry; whether it did is a question for the data, answered by searching again
//! without the terms in question ([`ban_touching`]).
//!
//! A state's scale is fixed ("pinned") when a measurement reads it alone, or when an
//! uncorrected equation (known exactly) ties it to pinned states: a measured position
//! pins the velocity of `ẋ = v`. The closure is taken to a fixed point.

use sysid_core::LinearModel;

use crate::refine::RefineCandidate;

/// Indices of the states whose scale no measurement or uncorrected equation fixes (see
/// the module documentation). Empty when every state is measured.
pub fn scale_free_states(linear: &LinearModel) -> Vec<usize> {
    let (a, c, e) = (linear.a(), linear.c(), linear.e());
    let n = linear.n_states();
    let nonzero = |x: f64| x.abs() > 0.0;
    let mut pinned = vec![false; n];
    // Each constraint is a set of states whose combination is known: a measured output's
    // row, or an uncorrected equation (its state, its derivative's known right-hand side).
    let mut constraints: Vec<Vec<usize>> = (0..c.nrows())
        .map(|r| (0..n).filter(|&j| nonzero(c[(r, j)])).collect())
        .collect();
    for i in 0..n {
        let corrected = (0..e.ncols()).any(|k| nonzero(e[(i, k)]));
        if !corrected {
            let mut set: Vec<usize> = (0..n).filter(|&j| nonzero(a[(i, j)])).collect();
            if !set.contains(&i) {
                set.push(i);
            }
            constraints.push(set);
        }
    }
    // A constraint with exactly one free state pins it.
    loop {
        let mut changed = false;
        for set in &constraints {
            let mut free = set.iter().filter(|&&j| !pinned[j]);
            if let (Some(&j), None) = (free.next(), free.next()) {
                pinned[j] = true;
                changed = true;
            }
        }
        if !changed {
            break;
        }
    }
    (0..n).filter(|&j| !pinned[j]).collect()
}

/// Whether `candidate` touches one of `states` (indices into `linear`'s states): it
/// enters or transfers into such a state's equation, or its term reads the state.
pub fn touches(candidate: &RefineCandidate, linear: &LinearModel, states: &[usize]) -> bool {
    let names = linear.state_names();
    let free = |name: &str| states.iter().any(|&j| names[j] == name);
    if free(&candidate.state) || candidate.into.as_deref().is_some_and(free) {
        return true;
    }
    if candidate.variables.is_empty() {
        candidate
            .term
            .split(|ch: char| !(ch.is_alphanumeric() || ch == '_'))
            .any(free)
    } else {
        candidate.variables.iter().any(|v| free(v))
    }
}

/// The candidate list without every candidate (ordinary or transfer) of an equation and
/// term that `banned` names, and the positions in the new list of `keep` (candidates of
/// the old list; those banned or missing are dropped): the starting point of a search
/// for an explanation that does without the banned terms.
pub fn ban_touching(
    candidates: &[RefineCandidate],
    banned: &[RefineCandidate],
    keep: &[RefineCandidate],
) -> (Vec<RefineCandidate>, Vec<usize>) {
    let same = |x: &RefineCandidate, y: &RefineCandidate| x.state == y.state && x.term == y.term;
    let list: Vec<RefineCandidate> = candidates
        .iter()
        .filter(|c| !banned.iter().any(|b| same(c, b)))
        .cloned()
        .collect();
    let start = keep
        .iter()
        .filter_map(|k| list.iter().position(|c| same(c, k)))
        .collect();
    (list, start)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::DMatrix;
    use sysid_core::ModelNames;

    fn model(a: &[f64], states: &[&str], measured: &[usize], corrected: &[usize]) -> LinearModel {
        let n = states.len();
        let mut c = DMatrix::zeros(measured.len(), n);
        for (r, &j) in measured.iter().enumerate() {
            c[(r, j)] = 1.0;
        }
        let mut e = DMatrix::zeros(n, corrected.len());
        for (k, &i) in corrected.iter().enumerate() {
            e[(i, k)] = 1.0;
        }
        let states: Vec<String> = states.iter().map(|s| s.to_string()).collect();
        let names = ModelNames {
            states: states.clone(),
            inputs: vec!["u".into()],
            outputs: measured.iter().map(|&j| states[j].clone()).collect(),
            corrections: corrected.iter().map(|&i| states[i].clone()).collect(),
        };
        LinearModel::with_names(
            DMatrix::from_row_slice(n, n, a),
            DMatrix::from_element(n, 1, 1.0),
            c,
            e,
            names,
        )
        .unwrap_or_else(|err| panic!("{err}"))
    }

    fn cand(state: &str, into: Option<&str>, term: &str) -> RefineCandidate {
        RefineCandidate {
            effect: "e".into(),
            state: state.into(),
            into: into.map(str::to_string),
            term: term.into(),
            coefficient: 0.0,
            variables: vec![],
            parameters: vec![],
        }
    }

    /// Two tanks: with the lower level measured alone the upper one is free (both its
    /// equations are corrected); with both measured nothing is. An oscillator measured
    /// in position pins its velocity through the known `ẋ = v`, unless that equation is
    /// corrected too.
    #[test]
    fn free_states_follow_measurements_and_known_equations() {
        let tanks = [-0.06, 0.0, 0.06, -0.08];
        let names = ["h1", "h2"];
        assert_eq!(
            scale_free_states(&model(&tanks, &names, &[1], &[0, 1])),
            vec![0]
        );
        assert!(scale_free_states(&model(&tanks, &names, &[0, 1], &[0, 1])).is_empty());
        let osc = [0.0, 1.0, -4.0, -0.2];
        let xv = ["x", "v"];
        assert!(scale_free_states(&model(&osc, &xv, &[0], &[1])).is_empty());
        assert_eq!(scale_free_states(&model(&osc, &xv, &[0], &[0, 1])), vec![1]);
        // A chain pins link by link: x1 measured, ẋ1 = x2, ẋ2 = x3 (known), x3 corrected.
        let chain = [0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, -1.0];
        assert!(scale_free_states(&model(&chain, &["a", "b", "c"], &[0], &[2])).is_empty());
    }

    #[test]
    fn touching_reads_equations_transfers_and_variables() {
        let lin = model(&[-0.06, 0.0, 0.06, -0.08], &["h1", "h2"], &[1], &[0, 1]);
        let free = [0];
        assert!(touches(&cand("h1", None, "u"), &lin, &free));
        assert!(touches(&cand("h2", None, "sqrt(abs(h1))"), &lin, &free));
        assert!(touches(&cand("h2", Some("h1"), "h2"), &lin, &free));
        assert!(!touches(&cand("h2", None, "sqrt(abs(h2))"), &lin, &free));
        // A name that only contains the state's name is not the state.
        assert!(!touches(&cand("h2", None, "h10"), &lin, &free));
        let mut with_vars = cand("h2", None, "tanh(h1/0.1)");
        with_vars.variables = vec!["h2".into()];
        assert!(
            !touches(&with_vars, &lin, &free),
            "variables decide when given"
        );
    }

    /// Banning removes both the ordinary and the transfer form of an equation's term and
    /// re-indexes the terms kept.
    #[test]
    fn ban_removes_both_forms_and_reindexes() {
        let cands = vec![
            cand("h1", None, "u"),
            cand("h1", Some("h2"), "sqrt(abs(h1))"),
            cand("h2", None, "sqrt(abs(h2))"),
            cand("h1", None, "sqrt(abs(h1))"),
        ];
        let (list, start) = ban_touching(
            &cands,
            &[cand("h1", None, "sqrt(abs(h1))")],
            &[cands[2].clone(), cands[3].clone()],
        );
        assert_eq!(list.len(), 2);
        assert_eq!(list[1].term, "sqrt(abs(h2))");
        assert_eq!(start, vec![1]);
    }
}
