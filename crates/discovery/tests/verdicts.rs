//! Verdicts where nothing must be named: pure coloured noise (`none`) and a disturbance
//! that no catalogue term can produce (`unexplained`).

use discovery::{DiscoveryConfig, Verdict, propose};
use nalgebra::DMatrix;
use plants::Recipe;

use crate::common::{ar1, floor_of, simulate};

/// d̂ is AR(1) noise with the floor's own statistics (another realisation): within the
/// floor, so `none`, and no effect is named. Checked over several seeds.
#[test]
fn pure_coloured_noise_is_none() {
    let sim = simulate("pendulum", Recipe::Train);
    let len = sim.truth.states.ncols();
    let (rms, phi) = (0.1, 0.95);
    let floor = floor_of(1, len, rms, phi, 100);
    for seed in 101..106 {
        let samples = [discovery::Samples::new(
            sim.truth.states.clone(),
            sim.truth.inputs.clone(),
            ar1(1, len, rms, phi, seed),
        )
        .unwrap_or_else(|e| panic!("{e}"))];
        let d = propose(
            &sim.assumed.model,
            &sim.assumed.units,
            &samples,
            &floor,
            &DiscoveryConfig::default(),
        )
        .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(d.verdict, Verdict::None, "seed {seed}: {:#?}", d.equations);
        assert!(d.effects.is_empty());
        assert!(!d.equations[0].significant);
    }
}

/// d̂ = 2 sin(2π·0.13 t + 0.3) + noise: a time-varying disturbance independent of the
/// pendulum's states and input (0.13 Hz appears in neither). d̂ is far above the floor,
/// the library explains little of it, so `unexplained`, and no effect is named.
#[test]
fn disturbance_outside_the_library_is_unexplained() {
    let sim = simulate("pendulum", Recipe::Train);
    let len = sim.truth.states.ncols();
    let (rms, phi) = (0.1, 0.9);
    let floor = floor_of(1, len, rms, phi, 200);
    let dt = sim.truth.dt;
    let noise = ar1(1, len, rms, phi, 201);
    let d_hat = DMatrix::from_fn(1, len, |_, k| {
        2.0 * (2.0 * std::f64::consts::PI * 0.13 * k as f64 * dt + 0.3).sin() + noise[(0, k)]
    });
    let samples =
        [
            discovery::Samples::new(sim.truth.states.clone(), sim.truth.inputs.clone(), d_hat)
                .unwrap_or_else(|e| panic!("{e}")),
        ];
    let d = propose(
        &sim.assumed.model,
        &sim.assumed.units,
        &samples,
        &floor,
        &DiscoveryConfig::default(),
    )
    .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(d.verdict, Verdict::Unexplained, "{:#?}", d.equations);
    assert!(d.effects.is_empty());
    assert!(d.equations[0].significant);
    assert!(d.equations[0].share_above_floor < 0.75);
}
