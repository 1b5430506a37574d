//! The free-run search on plants whose truth is known.

use super::*;
use plants::{Recipe, SimulationRequest, simulate_system};

/// The truth of the cubic mass–spring–damper is known (correction −0.5·x³ − 0.1·v on
/// the velocity equation). Started from a wrong set (a linear stiffness), the search
/// must drop it and end with exactly the cubic spring and the damper, with calibrated
/// coefficients near the truth (noise variance 0.09 m² on 1001 samples).
#[test]
fn free_run_search_finds_the_true_terms_from_a_wrong_start() {
    let sim = simulate_system(&SimulationRequest {
        system: "msd_cubic".into(),
        recipe: Recipe::Train,
        seed: 9,
        ..Default::default()
    })
    .unwrap();
    let base = TermModel::new(sim.assumed.model.clone(), vec![]).unwrap();
    let cand = |effect: &str, term: &str| RefineCandidate {
        effect: effect.into(),
        state: "v".into(),
        into: None,
        term: term.into(),
        coefficient: 0.0,
        variables: vec![],
        parameters: vec![],
    };
    let candidates = vec![
        cand("linear_stiffness", "x"),
        cand("cubic_stiffness", "x^3"),
        cand("viscous_damping", "v"),
        cand("quadratic_drag", "v*abs(v)"),
    ];
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
        &candidates,
        &[0],
        &sim.data,
        &x0,
        &sim.assumed.noise_variance,
        &RefineConfig::default(),
    )
    .unwrap();
    let mut names: Vec<&str> = r
        .selected
        .iter()
        .map(|&i| candidates[i].effect.as_str())
        .collect();
    names.sort_unstable();
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
    let sim = simulate_system(&SimulationRequest {
        system: "van_der_pol".into(),
        recipe: Recipe::Train,
        seed: 3,
        ..Default::default()
    })
    .unwrap();
    let base = TermModel::new(sim.assumed.model.clone(), vec![]).unwrap();
    let state = sim.assumed.model.correction_names()[0].clone();
    let (x, v) = (
        sim.assumed.model.state_names()[0].clone(),
        sim.assumed.model.state_names()[1].clone(),
    );
    let cand = |effect: &str, term: String| RefineCandidate {
        effect: effect.into(),
        state: state.clone(),
        into: None,
        term,
        coefficient: 0.0,
        variables: vec![],
        parameters: vec![],
    };
    let candidates = vec![
        cand("cubic_stiffness", format!("{x}^3")),
        cand("viscous_damping", v.clone()),
        cand("amplitude_dependent_damping", format!("{x}^2*{v}")),
        cand("quadratic_drag", format!("{v}*abs({v})")),
    ];
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
        &candidates,
        &[],
        &sim.data,
        &x0,
        &sim.assumed.noise_variance,
        &RefineConfig::default(),
    )
    .unwrap();
    let mut names: Vec<&str> = r
        .selected
        .iter()
        .map(|&i| candidates[i].effect.as_str())
        .collect();
    names.sort_unstable();
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
