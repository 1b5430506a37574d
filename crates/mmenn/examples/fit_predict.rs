//! `fit` then `predict` as library calls, in memory: MME/NN on the cubic
//! mass–spring–damper's training record (the test record as validation data, judged only,
//! as `mmenn fit --val`), then the hybrid model and the
//! linear assumed model predicted free-run on the test record by the one judge (initial
//! state fitted to the first 50 samples, every sample scored). `mmenn compare` with the
//! same options gets the same two numbers (see `examples/compare.rs`).
//!
//! `cargo run --release -p mmenn --example fit_predict`

#![allow(clippy::result_large_err)] // mmenn's errors carry paths and context

use std::path::Path;

use mmenn::LoadedModel;
use mmenn::fit::{DomainPolicy, FitOptions, HiddenChoice, TrajectoryChoice, compute_fit};
use mmenn::plants::{Recipe, SimulationRequest, simulate_system};
use mmenn::predict::{PredictOptions, compute_predict_on};
use mmenn::progress::NoProgress;
use mmenn::simulate::assumed_model_spec;

/// What the example found: free-run fit % of `x` on the test record.
pub struct FitPredictExample {
    /// The MME/NN hybrid model's.
    pub hybrid: f64,
    /// The linear assumed model's.
    pub assumed: f64,
}

/// Simulate both records, fit, predict.
pub fn run() -> mmenn::Result<FitPredictExample> {
    let req = |recipe| SimulationRequest {
        system: "msd_cubic".into(),
        recipe,
        seed: 2,
        fs: Some(20.0),
        ..Default::default()
    };
    let train = simulate_system(&req(Recipe::Train))?;
    let test = simulate_system(&req(Recipe::Test))?;
    let spec = assumed_model_spec(&train);
    let opts = FitOptions {
        hidden: HiddenChoice::Fixed(3),
        inits: 3,
        train_on_trajectories: TrajectoryChoice::None,
        x0_window: 50,
        // As `mmenn fit` and `mmenn compare` do: a network that fails the guard's stress
        // check holds its edge value beyond its training box.
        network_domain: DomainPolicy::Checked,
        ..FitOptions::default()
    };
    let fit = compute_fit(&train.data, &spec, Some(&test.data), &opts, &NoProgress)?;
    let hybrid = LoadedModel::from_hybrid(Path::new("model.json"), fit.model)?;
    let assumed = LoadedModel::from_spec(Path::new("model.toml"), spec)?;
    let popts = PredictOptions {
        x0_window: Some(50),
        ..PredictOptions::default()
    };
    let fit_of = |m: &LoadedModel| -> mmenn::Result<f64> {
        let p = compute_predict_on(m, &test.data, &popts)?;
        Ok(p.free.fit_percent("x"))
    };
    Ok(FitPredictExample {
        hybrid: fit_of(&hybrid)?,
        assumed: fit_of(&assumed)?,
    })
}

#[allow(clippy::print_stdout)]
fn main() -> mmenn::Result<()> {
    let r = run()?;
    println!(
        "free-run fit of x on the test record: MME/NN {:.1} %, assumed model {:.1} %",
        r.hybrid, r.assumed
    );
    Ok(())
}
