//! Calibration by free-run simulation error recovers true coefficients from shrunk
//! starting values (as regression on MME's d̂ gives).

use discovery::{CalibrationConfig, InitialState, OutputWeights, calibrate};
use plants::{Recipe, SimulationRequest, simulate_system};
use sysid_core::TermModel;

/// msd_cubic training data with the default position noise (variance 0.09 m²) — the
/// assumed model plus the two discovered terms, started at 60 % of the truth
/// (−0.3·x³, −0.06·v), initial state estimated too. The calibrated coefficients must be
/// within 4 standard errors of the truth (−0.5, −0.1) and within 3 % of it, and the cost
/// with weights 1/R must end near 1 (χ² per value: 1 ± 3.3·√(2/1001) ≈ 1 ± 0.15).
#[test]
fn recovers_true_coefficients_from_shrunk_start() {
    let sim = simulate_system(&SimulationRequest {
        system: "msd_cubic".into(),
        recipe: Recipe::Train,
        noise_variance: None,
        seed: 5,
        ..SimulationRequest::default()
    })
    .unwrap_or_else(|e| panic!("{e}"));
    let start = TermModel::from_specs(
        sim.assumed.model.clone(),
        [
            ("v", "cubic_stiffness", "x^3", -0.3),
            ("v", "viscous_damping", "v", -0.06),
        ],
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let config = CalibrationConfig {
        initial_state: InitialState::Estimate,
        weights: OutputWeights::NoiseVariance(sim.assumed.noise_variance.clone()),
        ..CalibrationConfig::default()
    };
    let cal =
        calibrate(&start, &sim.data, &[vec![4.8, 0.2]], &config).unwrap_or_else(|e| panic!("{e}"));
    for (k, truth) in [(0, -0.5), (1, -0.1)] {
        let (c, s) = (cal.coefficients_after[k], cal.coefficient_std[k]);
        assert!(
            (c - truth).abs() < 4.0 * s,
            "term {k}: {c} ± {s} vs {truth}"
        );
        assert!(
            (c - truth).abs() < 0.03 * truth.abs(),
            "term {k}: {c} vs {truth}"
        );
    }
    assert!(
        (cal.cost_after - 1.0).abs() < 0.15,
        "cost {}",
        cal.cost_after
    );
    assert!(cal.cost_before > 10.0 * cal.cost_after);
    assert!((cal.x0[0][0] - 5.0).abs() < 0.1, "x0 {:?}", cal.x0);
}
