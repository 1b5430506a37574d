//! `estimate` as a library call: simulate the cubic mass–spring–damper (a built-in
//! system), run MME with its linear assumed model, and see how much of the missing
//! spring force MME's correction `d̂` recovers against the simulation's truth.
//!
//! `cargo run --release -p mmenn --example estimate`

#![allow(clippy::result_large_err)] // mmenn's errors carry paths and context

use mmenn::estimate::{EstimateOptions, compute_estimate};
use mmenn::plants::{Recipe, SimulationRequest, simulate_system};
use mmenn::simulate::assumed_model_spec;
use mmenn::sysid_core::channel_metrics;

/// What the example found.
pub struct EstimateExample {
    /// MME's `W` per corrected equation.
    pub w: Vec<(String, f64)>,
    /// Fit % of MME's `d̂` to the true correction, per corrected equation.
    pub d_fit_percent: Vec<(String, f64)>,
}

/// Simulate, estimate, compare `d̂` with the truth (all in memory).
pub fn run() -> mmenn::Result<EstimateExample> {
    let sim = simulate_system(&SimulationRequest {
        system: "msd_cubic".into(),
        recipe: Recipe::Train,
        seed: 2,
        fs: Some(20.0),
        ..Default::default()
    })?;
    let spec = assumed_model_spec(&sim);
    let outcome = compute_estimate(&sim.data, &spec, &EstimateOptions::default(), None)?;
    let est = &outcome.output.estimate;
    let d = est.experiments[0].corrections_at_samples();
    let mut d_fit_percent = Vec::new();
    for (i, name) in est.correction_names.iter().enumerate() {
        let truth: Vec<f64> = sim.truth.corrections.row(i).iter().copied().collect();
        let estimate: Vec<f64> = d.row(i).iter().copied().collect();
        let m = channel_metrics(&truth, &estimate).map_err(|source| mmenn::MmennError::Core {
            context: "d̂ against the true correction",
            source,
        })?;
        d_fit_percent.push((name.clone(), m.fit_percent));
    }
    Ok(EstimateExample {
        w: outcome.summary.w_by_correction.into_iter().collect(),
        d_fit_percent,
    })
}

#[allow(clippy::print_stdout)]
fn main() -> mmenn::Result<()> {
    let r = run()?;
    for ((name, w), (_, fit)) in r.w.iter().zip(&r.d_fit_percent) {
        println!("d_{name}: W = {w:.4e}, fit of d̂ to the true correction {fit:.1} %");
    }
    Ok(())
}
