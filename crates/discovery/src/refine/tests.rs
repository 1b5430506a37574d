//! The free-run search on plants whose truth is known.

use super::*;
use plants::{Recipe, SimulatedData, SimulationRequest, simulate_system};

/// A training record of `system` (seed `seed`, default noise).
fn record(system: &str, seed: u64) -> SimulatedData {
    simulate_system(&SimulationRequest {
        system: system.into(),
        recipe: Recipe::Train,
        seed,
        ..Default::default()
    })
    .unwrap()
}

/// A candidate of the equation `state` with no starting coefficient.
fn candidate(effect: &str, state: &str, term: String) -> RefineCandidate {
    RefineCandidate {
        effect: effect.into(),
        state: state.into(),
        into: None,
        term,
        coefficient: 0.0,
        variables: vec![],
        parameters: vec![],
    }
}

/// The search over `candidates` from `initial` on `sim`'s record (initial state from the
/// truth, default settings), and the kept effects' names, sorted.
fn search(
    sim: &SimulatedData,
    candidates: &[RefineCandidate],
    initial: &[usize],
) -> (Refinement, Vec<String>) {
    let base = TermModel::new(sim.assumed.model.clone(), vec![]).unwrap();
    let x0 = vec![
        sim.truth
            .states
            .column(0)
            .iter()
            .copied()
            .collect::<Vec<f64>>(),
    ];
    let r = refine_by_free_run(
        &base,
        candidates,
        initial,
        &sim.data,
        &x0,
        &sim.assumed.noise_variance,
        &RefineConfig::default(),
    )
    .unwrap();
    let mut names: Vec<String> = r
        .selected
        .iter()
        .map(|&i| candidates[i].effect.clone())
        .collect();
    names.sort_unstable();
    (r, names)
}

/// The truth of the cubic mass–spring–damper is known (correction −0.5·x³ − 0.1·v on
/// the velocity equation). Started from a wrong set (a linear stiffness), the search
/// must drop it and end with exactly the cubic spring and the damper, with calibrated
/// coefficients near the truth (noise variance 0.09 m² on 1001 samples).
#[test]
fn free_run_search_finds_the_true_terms_from_a_wrong_start() {
    let sim = record("msd_cubic", 9);
    let candidates = vec![
        candidate("linear_stiffness", "v", "x".into()),
        candidate("cubic_stiffness", "v", "x^3".into()),
        candidate("viscous_damping", "v", "v".into()),
        candidate("quadratic_drag", "v", "v*abs(v)".into()),
    ];
    let (r, names) = search(&sim, &candidates, &[0]);
    assert_eq!(
        names,
        ["cubic_stiffness", "viscous_damping"],
        "steps: {:?}",
        r.steps
    );
    for t in r.model.terms() {
        let want = if t.expr.to_string() == "x^3" {
            -0.5
        } else {
            -0.1
        };
        assert!(
            (t.coefficient - want).abs() < 0.05 * want.abs() + 0.005,
            "{}: {} vs {want}",
            t.expr,
            t.coefficient
        );
    }
    // The final cost is the noise level: J ≈ 1 (±5σ of a χ² mean over ~1000 values).
    assert!(
        (r.cost[1] - 1.0).abs() < 5.0 * (2.0_f64 / 1001.0).sqrt(),
        "final cost {}",
        r.cost[1]
    );
}

/// Van der Pol: the correction `μ(1 − x²)v` needs `v` and `x²v` together — either
/// alone destabilises or kills the limit cycle, so no single term helps and only the
/// pair step can name them (truth coefficients +1 and −1 for μ = 1).
#[test]
fn pair_step_names_terms_that_only_work_together() {
    let sim = record("van_der_pol", 3);
    let state = sim.assumed.model.correction_names()[0].clone();
    let names_of = sim.assumed.model.state_names();
    let (x, v) = (&names_of[0], &names_of[1]);
    let candidates = vec![
        candidate("cubic_stiffness", &state, format!("{x}^3")),
        candidate("viscous_damping", &state, v.clone()),
        candidate("amplitude_dependent_damping", &state, format!("{x}^2*{v}")),
        candidate("quadratic_drag", &state, format!("{v}*abs({v})")),
    ];
    let (r, names) = search(&sim, &candidates, &[]);
    assert_eq!(
        names,
        ["amplitude_dependent_damping", "viscous_damping"],
        "steps: {:?}",
        r.steps
    );
    assert!(r.steps.iter().any(|s| s.action == "add (pair)"));
    for t in r.model.terms() {
        let want = if t.expr.to_string().contains('^') {
            -1.0
        } else {
            1.0
        };
        assert!(
            (t.coefficient - want).abs() < 0.05,
            "{}: {}",
            t.expr,
            t.coefficient
        );
    }
}
