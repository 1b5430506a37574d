//! The discovery workflow on the `oscillator` test bench: one known linear oscillator,
//! one hidden effect at a time (or two, or none, or one outside the catalogue), at 2 %
//! and 5 % measurement noise (σ = 1 cm and 2.5 cm on a response of RMS ≈ 0.48 m). The
//! truth is known, so every verdict, name and calibrated coefficient is checked against
//! it, and the validation record (a different input) must be simulated better.

use mmenn::discover::{DiscoverOptions, DiscoverSummary, run_discover};
use mmenn::plants::{Recipe, SimulationRequest};
use mmenn::simulate::run_simulate;
/// σ = 1 cm (2 % of the response RMS) and σ = 2.5 cm (5 %).
const LOW: f64 = 1e-4;
const HIGH: f64 = 6.25e-4;

fn run(label: &str, params: &[(&str, f64)], noise: f64) -> DiscoverSummary {
    let dir = std::env::temp_dir().join(format!(
        "mmenn-hidden-{}-{label}-{noise}",
        std::process::id()
    ));
    let _ = std::fs::remove_dir_all(&dir);
    let req = |recipe, seed| SimulationRequest {
        system: "oscillator".into(),
        recipe,
        seed,
        noise_variance: Some(noise),
        params: params.iter().map(|(n, v)| (n.to_string(), *v)).collect(),
        ..Default::default()
    };
    let train = run_simulate(&req(Recipe::Train, 5), &dir.join("train")).unwrap();
    let test = run_simulate(&req(Recipe::Test, 6), &dir.join("test")).unwrap();
    let s = run_discover(
        std::slice::from_ref(&train.data),
        &train.model,
        std::slice::from_ref(&test.data),
        &DiscoverOptions::default(),
        &dir.join("out"),
    )
    .unwrap();
    std::fs::remove_dir_all(&dir).unwrap();
    s
}

/// The verdict is `found`, exactly the expected effects are named (catalogue name and
/// truth coefficient of the correction `d` on `v̇`, i.e. force / m with m = 1), each
/// calibrated coefficient within 3 % of the truth (measured errors are below 1 %) with
/// its 95 % interval covering the truth, and
/// the validation free-run RMSE falls at least threefold.
fn expect_found(s: &DiscoverSummary, expected: &[(&str, f64)]) {
    assert_eq!(format!("{:?}", s.verdict), "Found", "{:?}", s.unconfirmed);
    let mut names: Vec<&str> = s.effects.iter().map(|e| e.name.as_str()).collect();
    names.sort_unstable();
    let mut want: Vec<&str> = expected.iter().map(|(n, _)| *n).collect();
    want.sort_unstable();
    assert_eq!(names, want, "{:?}", s.effects);
    for (name, truth) in expected {
        let e = s.effects.iter().find(|e| e.name == *name).unwrap();
        assert_eq!(e.state, "v");
        assert!(
            (e.coefficient - truth).abs() < 0.03 * truth.abs(),
            "{name}: {} vs truth {truth}",
            e.coefficient
        );
        let [lo, hi] = e.ci95_calibrated.expect("calibrated interval");
        assert!(
            lo <= *truth && *truth <= hi,
            "{name}: 95 % interval [{lo}, {hi}] misses the truth {truth}"
        );
    }
    let v = s.validation_gap.as_ref().unwrap();
    assert!(
        v.after.rmse["x"] < v.before.rmse["x"] / 3.0,
        "validation RMSE {} → {}",
        v.before.rmse["x"],
        v.after.rmse["x"]
    );
}

#[test]
fn cubic_hardening_low_noise() {
    expect_found(
        &run("hard", &[("k3", 1.0)], LOW),
        &[("cubic_stiffness", -1.0)],
    );
}

#[test]
fn cubic_softening_high_noise() {
    expect_found(
        &run("soft", &[("k3", -0.4)], HIGH),
        &[("cubic_stiffness", 0.4)],
    );
}

#[test]
fn quadratic_drag_high_noise() {
    expect_found(
        &run("drag", &[("cq", 0.5)], HIGH),
        &[("quadratic_drag", -0.5)],
    );
}

#[test]
fn coulomb_friction_low_noise() {
    // Truth −0.2·tanh(v/0.001); the catalogue's smooth Coulomb term uses its own
    // velocity scale, which is equivalent away from v = 0.
    expect_found(
        &run("coulomb", &[("fc", 0.2)], LOW),
        &[("coulomb_friction_smooth", -0.2)],
    );
}

#[test]
fn two_effects_at_once_high_noise() {
    expect_found(
        &run("two", &[("k3", 1.0), ("fc", 0.2)], HIGH),
        &[("cubic_stiffness", -1.0), ("coulomb_friction_smooth", -0.2)],
    );
}

#[test]
fn correct_model_gives_none() {
    for noise in [LOW, HIGH] {
        let s = run("none", &[], noise);
        assert_eq!(format!("{:?}", s.verdict), "None", "noise {noise}");
        assert!(s.effects.is_empty() && s.unconfirmed.is_empty());
    }
}

#[test]
fn contact_spring_outside_the_catalogue_is_unexplained_without_a_name() {
    // A one-sided spring kc·max(0, x − 0.3): no catalogue term has this shape.
    let s = run("contact", &[("kc", 20.0)], LOW);
    assert_eq!(format!("{:?}", s.verdict), "Unexplained");
    assert!(s.effects.is_empty(), "wrongly named: {:?}", s.effects);
}
