//! Localisation of an injected disturbance in time, of a free-run drift, and the plot
//! data of d̂ against states and inputs.

use discovery::{FreeRun, LocaliseConfig, Samples, WindowLength, WindowSource, localise};
use nalgebra::DMatrix;
use plants::Recipe;

use crate::common::{ar1, floor_of, simulate};

/// d̂ = AR(1) noise (σ = 0.1, φ = 0.9) plus a step disturbance of 1 on t ∈ [6, 12) s, on
/// the pendulum's 100 Hz grid, with a 0.5 s window. Tolerance of the edges: the moving
/// mean square ramps by A²/L = 0.02 per sample across an edge, and the noise moves it by
/// about 2Aσ/√(L_eff/2) ≈ 2·0.1/√1.3 ≈ 0.18 at most, i.e. ≲ 9 samples; 0.15 s (15
/// samples) is allowed.
#[test]
fn finds_an_injected_disturbance_window() {
    let sim = simulate("pendulum", Recipe::Train);
    let len = sim.truth.states.ncols();
    let dt = sim.truth.dt;
    let (rms, phi) = (0.1, 0.9);
    let noise = ar1(1, len, rms, phi, 301);
    let d_hat = DMatrix::from_fn(1, len, |_, k| {
        let t = k as f64 * dt;
        noise[(0, k)] + if (6.0..12.0).contains(&t) { 1.0 } else { 0.0 }
    });
    let samples = Samples::new(sim.truth.states.clone(), sim.truth.inputs.clone(), d_hat)
        .unwrap_or_else(|e| panic!("{e}"));
    let floor = floor_of(1, len, rms, phi, 302);
    // A free-run error that is noise except an offset of 5σ on t ∈ [14, 16) s.
    let sigma = 0.01;
    let y_noise = ar1(1, len, sigma, 0.0, 303);
    let simulated = DMatrix::from_fn(1, len, |_, k| sim.truth.states[(0, k)]);
    let measured = DMatrix::from_fn(1, len, |_, k| {
        let t = k as f64 * dt;
        simulated[(0, k)]
            + y_noise[(0, k)]
            + if (14.0..16.0).contains(&t) {
                5.0 * sigma
            } else {
                0.0
            }
    });
    let variance = [sigma * sigma];
    let free_run = FreeRun {
        measured: &measured,
        simulated: &simulated,
        noise_variance: &variance,
    };
    let config = LocaliseConfig {
        window: WindowLength::Seconds(0.5),
        ..LocaliseConfig::default()
    };
    let loc = localise(
        &sim.assumed.model,
        &samples,
        0.0,
        dt,
        &floor,
        Some(&free_run),
        &config,
    )
    .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(loc.window_samples, 50);
    let d_windows: Vec<_> = loc
        .windows
        .iter()
        .filter(|w| w.source == WindowSource::Correction)
        .collect();
    assert_eq!(d_windows.len(), 1, "{d_windows:?}");
    let w = d_windows[0];
    assert_eq!(w.channel, "omega");
    assert!(
        (w.start - 6.0).abs() < 0.15 && (w.end - 12.0).abs() < 0.15,
        "{w:?}"
    );
    assert!(w.peak_ratio.is_some_and(|r| r > 5.0));
    let y_windows: Vec<_> = loc
        .windows
        .iter()
        .filter(|w| w.source == WindowSource::FreeRun)
        .collect();
    assert_eq!(y_windows.len(), 1, "{y_windows:?}");
    assert!((y_windows[0].start - 14.0).abs() < 0.15 && (y_windows[0].end - 16.0).abs() < 0.15);
    // Plot data: one profile per (equation, state or input), bins covering every sample.
    assert_eq!(loc.profiles.len(), 3);
    for p in &loc.profiles {
        assert_eq!(p.bins.iter().map(|b| b.count).sum::<usize>(), len);
        assert!(p.points.len() <= 2000);
    }
    assert_eq!(loc.moving_rms.len(), 2);
}
