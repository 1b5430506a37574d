//! Force-space discovery against hand-made answers: `τ̂ = M(q̂)·d̂` exactly, candidates
//! that read only their own joint, and a proposal that recovers known joint forces.

use nalgebra::DMatrix;
use sysid_core::{
    Channel, Dataset, Experiment, ExperimentEstimate, LinearModel, MechanicsSpec, MmeEstimate,
    ModelNames, Parameter, PhysicalModel, SolveReport,
};

use super::*;

const STATES: [&str; 4] = ["q1", "q2", "w1", "w2"];

fn strings(v: &[&str]) -> Vec<String> {
    v.iter().map(|s| (*s).to_owned()).collect()
}

/// Two coordinates with a configuration-dependent, coupled mass matrix; corrections on
/// both rate equations.
fn model() -> PhysicalModel {
    let names = ModelNames {
        states: strings(&STATES),
        inputs: strings(&["u"]),
        outputs: strings(&["q1", "q2"]),
        corrections: strings(&["w1", "w2"]),
    };
    let mut c = DMatrix::zeros(2, 4);
    c[(0, 0)] = 1.0;
    c[(1, 1)] = 1.0;
    let mut e = DMatrix::zeros(4, 2);
    e[(2, 0)] = 1.0;
    e[(3, 1)] = 1.0;
    let lin = LinearModel::with_names(DMatrix::zeros(4, 4), DMatrix::zeros(4, 1), c, e, names)
        .unwrap_or_else(|e| panic!("{e}"));
    let (q, qdot) = (strings(&["q1", "q2"]), strings(&["w1", "w2"]));
    let mass = vec![
        strings(&["a + cos(q2)", "0.5*cos(q2)"]),
        strings(&["0.5*cos(q2)", "1"]),
    ];
    let forces = strings(&["u - sin(q1)", "-sin(q1 + q2)"]);
    PhysicalModel::new(
        lin,
        vec![Parameter::new("a", 2.0)],
        &[],
        Some(MechanicsSpec {
            q: &q,
            qdot: &qdot,
            mass: &mass,
            forces: &forces,
        }),
    )
    .unwrap_or_else(|e| panic!("{e}"))
}

/// States along a smooth, non-periodic path; `τ(x)` the joint forces to hide in `d̂`.
fn estimate_with(n: usize, tau: impl Fn(&[f64]) -> [f64; 2]) -> (MmeEstimate, Dataset) {
    let states = DMatrix::from_fn(4, n, |i, k| {
        let t = k as f64 * 0.01;
        match i {
            0 => 0.6 * (1.3 * t).sin(),
            1 => 0.9 * (0.7 * t + 0.4).sin(),
            2 => 2.0 * (1.1 * t).cos() + 0.3 * (3.7 * t).sin(),
            _ => 1.5 * (0.9 * t + 1.0).cos() - 0.4 * (2.3 * t).sin(),
        }
    });
    let m = model();
    let mut d = DMatrix::zeros(2, n);
    for k in 0..n {
        let x: Vec<f64> = states.column(k).iter().copied().collect();
        let mut mm = [0.0; 4];
        m.mass_matrix(&x, &[0.0], &mut mm);
        let t = tau(&x);
        // d = M⁻¹ τ (2 × 2 by hand).
        let det = mm[0] * mm[3] - mm[1] * mm[2];
        d[(0, k)] = (mm[3] * t[0] - mm[1] * t[1]) / det;
        d[(1, k)] = (mm[0] * t[1] - mm[2] * t[0]) / det;
    }
    let est = MmeEstimate {
        state_names: strings(&STATES),
        correction_names: strings(&["w1", "w2"]),
        output_names: strings(&["q1", "q2"]),
        experiments: vec![ExperimentEstimate {
            t0: 0.0,
            dt: 0.01,
            substeps: 1,
            states: states.clone(),
            corrections: d.columns(0, n - 1).into_owned(),
        }],
        w: DMatrix::identity(2, 2),
        noise_variance: vec![1.0; 2],
        residual_variance: vec![1.0; 2],
        cost: 0.0,
        report: SolveReport::default(),
    };
    let exp = Experiment::new(
        0.0,
        0.01,
        DMatrix::zeros(1, n),
        states.rows(0, 2).into_owned(),
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let data = Dataset::new(
        vec![Channel::new("u")],
        vec![Channel::new("q1"), Channel::new("q2")],
        vec![exp],
    )
    .unwrap_or_else(|e| panic!("{e}"));
    (est, data)
}

/// Forces hidden as `d̂ = M⁻¹τ` come back as `τ` (to round-off), on both joints,
/// although each enters both corrections.
#[test]
fn joint_forces_undo_the_mass_matrix() {
    let tau = |x: &[f64]| [0.3 * x[2] + 0.1, -0.2 * x[3].powi(3)];
    let (est, data) = estimate_with(300, tau);
    let m = model();
    let taus = joint_forces(&m, m.linear().e(), &data, &est).unwrap_or_else(|e| panic!("{e}"));
    // Corrections are piecewise: the last sample takes the last piece.
    for k in 0..299 {
        let x: Vec<f64> = est.experiments[0]
            .states
            .column(k)
            .iter()
            .copied()
            .collect();
        let want = tau(&x);
        for j in 0..2 {
            let got = taus[0][(j, k)];
            assert!(
                (got - want[j]).abs() <= 1e-12,
                "{k} {j}: {got} vs {}",
                want[j]
            );
        }
        // The coupling is real: joint 1's force shows in both corrections.
        let d = est.experiments[0].corrections[(1, k)];
        assert!(d.abs() > 0.0 || x[3].abs() < 1e-9);
    }
}

/// Every candidate of joint `j` reads joint `j`'s rate (or angle) and nothing else.
#[test]
fn candidates_read_only_their_own_joint() {
    let (est, _) = estimate_with(50, |_| [0.0, 0.0]);
    let config = ForceConfig {
        effects: Effect::ALL.to_vec(),
        ..ForceConfig::default()
    };
    let cands = joint_candidates(&model(), &est, &config);
    assert!(cands.len() >= 2 * config.effects.len() / 3, "{cands:?}");
    let own = [["q1", "w1"], ["q2", "w2"]];
    let names: Vec<&str> = STATES.iter().copied().chain(["u"]).collect();
    for c in &cands {
        let e = Expr::parse(&c.term, &names).unwrap_or_else(|e| panic!("{e}"));
        for v in e.variables_used() {
            assert!(own[c.joint].contains(&names[v]), "{c:?}");
        }
        assert_eq!(c.state, own[c.joint][1]);
    }
    for j in 0..2 {
        assert!(
            cands
                .iter()
                .any(|c| c.joint == j && c.effect == Effect::ViscousDamping)
        );
    }
}

/// Viscous and smooth Coulomb friction hidden on each joint (with the candidates' own
/// width) are proposed on that joint, with their coefficients, and nothing else.
#[test]
fn the_proposal_recovers_per_joint_friction() {
    let (est0, _) = estimate_with(800, |_| [0.0, 0.0]);
    // Noise-free forces: any share above round-off is real.
    let config = ForceConfig {
        min_share: 1e-6,
        ..ForceConfig::default()
    };
    let cands = joint_candidates(&model(), &est0, &config);
    let eps: Vec<f64> = (0..2)
        .map(|j| {
            cands
                .iter()
                .find(|c| c.joint == j && c.effect == Effect::CoulombFrictionSmooth)
                .map(|c| c.parameters[0])
                .unwrap_or_else(|| panic!("no Coulomb candidate"))
        })
        .collect();
    let truth = [(-0.2, -0.5), (-0.1, -0.3)];
    let tau = |x: &[f64]| {
        std::array::from_fn(|j| {
            let w = x[2 + j];
            truth[j].0 * w + truth[j].1 * (w / eps[j]).tanh()
        })
    };
    let (est, data) = estimate_with(800, tau);
    let m = model();
    let taus = joint_forces(&m, m.linear().e(), &data, &est).unwrap_or_else(|e| panic!("{e}"));
    let (proposals, rms) =
        propose_forces(&m, &est, &data, &taus, &cands, &config).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(proposals.len(), 2);
    for (j, p) in proposals.iter().enumerate() {
        assert!(rms[j] > 0.0);
        assert_eq!(p.selected.len(), 2, "{p:?}");
        for s in &p.selected {
            let c = &cands[s.candidate];
            assert_eq!(c.joint, j);
            let want = match c.effect {
                Effect::ViscousDamping => truth[j].0,
                Effect::CoulombFrictionSmooth => truth[j].1,
                other => panic!("{other:?} proposed on joint {j}"),
            };
            assert!((s.coefficient - want).abs() <= 1e-9, "{s:?} vs {want}");
        }
        assert!(p.remaining_share < 1e-12);
    }
}

/// The width written as a name is the catalogue's law: with a number in its place both
/// parse to the same expression.
#[test]
fn a_named_width_is_the_catalogue_law() {
    for effect in [Effect::CoulombFrictionSmooth, Effect::CoulombFrictionAtan] {
        let named = with_width(effect, "w1", "0.37");
        let catalogue = effect.template(&["w1"], &[0.37]);
        let names = ["w1"];
        assert_eq!(
            Expr::parse(&named, &names).unwrap_or_else(|e| panic!("{e}")),
            Expr::parse(&catalogue, &names).unwrap_or_else(|e| panic!("{e}")),
            "{effect:?}"
        );
    }
}
