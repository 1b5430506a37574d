//! Shared helpers: seeded coloured noise and samples from a plant's truth.

use discovery::{NoiseFloor, Samples};
use nalgebra::DMatrix;
use plants::{Recipe, SimulatedData, SimulationRequest, simulate_system};
use rand::SeedableRng;
use rand::rngs::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

/// AR(1) noise `e_k = φ e_{k−1} + √(1−φ²)·σ·w_k` (stationary RMS σ, lag-1 correlation φ),
/// `rows × len`, from `ChaCha8Rng::seed_from_u64(seed)`.
pub fn ar1(rows: usize, len: usize, rms: f64, phi: f64, seed: u64) -> DMatrix<f64> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut out = DMatrix::zeros(rows, len);
    let gain = (1.0 - phi * phi).sqrt() * rms;
    for i in 0..rows {
        let mut e: f64 = StandardNormal.sample(&mut rng);
        e *= rms;
        for k in 0..len {
            let w: f64 = StandardNormal.sample(&mut rng);
            e = phi * e + gain * w;
            out[(i, k)] = e;
        }
    }
    out
}

/// Simulate a plant experiment (noise-free measurements are not needed here).
pub fn simulate(system: &str, recipe: Recipe) -> SimulatedData {
    simulate_system(&SimulationRequest {
        system: system.into(),
        recipe,
        noise_variance: Some(0.0),
        seed: 1,
        ..SimulationRequest::default()
    })
    .unwrap_or_else(|e| panic!("{system}: {e}"))
}

/// Samples of the truth states and inputs with `d̂ = truth correction + noise`.
pub fn truth_samples(sim: &SimulatedData, noise: &DMatrix<f64>) -> Samples {
    Samples::new(
        sim.truth.states.clone(),
        sim.truth.inputs.clone(),
        &sim.truth.corrections + noise,
    )
    .unwrap_or_else(|e| panic!("{e}"))
}

/// The floor measured on an independent realisation of the same noise process (what a
/// model-consistent MME run would give).
pub fn floor_of(rows: usize, len: usize, rms: f64, phi: f64, seed: u64) -> NoiseFloor {
    let run = ar1(rows, len, rms, phi, seed);
    NoiseFloor::from_corrections(&[&run]).unwrap_or_else(|e| panic!("{e}"))
}
