//! `compare` as a library call, in memory: the assumed model, a linear output-error fit,
//! NARX, polynomial NARX and MME/NN on the cubic mass–spring–damper, judged free-run on a
//! test record.
//!
//! `cargo run --release -p mmenn --example compare`

#![allow(clippy::result_large_err)] // mmenn's errors carry paths and context

use mmenn::LoadedModel;
use mmenn::compare::{CompareOptions, compute_compare};
use mmenn::fit::{DomainPolicy, FitOptions, HiddenChoice, TrajectoryChoice};
use mmenn::plants::{Recipe, SimulationRequest, simulate_system};
use mmenn::simulate::assumed_model_spec;
use mmenn::sysid_baselines::EvaluationTable;

/// Simulate both records and compare; the validation table.
pub fn run() -> mmenn::Result<EvaluationTable> {
    let req = |recipe| SimulationRequest {
        system: "msd_cubic".into(),
        recipe,
        seed: 2,
        fs: Some(20.0),
        ..Default::default()
    };
    let train = simulate_system(&req(Recipe::Train))?;
    let test = simulate_system(&req(Recipe::Test))?;
    let model = LoadedModel::from_spec(
        std::path::Path::new("model.toml"),
        assumed_model_spec(&train),
    )?;
    let opts = CompareOptions {
        fit: FitOptions {
            hidden: HiddenChoice::Fixed(3),
            inits: 3,
            train_on_trajectories: TrajectoryChoice::None,
            x0_window: 50,
            // As `mmenn fit` and `mmenn compare` do: a network that fails the guard's stress
            // check holds its edge value beyond its training box.
            network_domain: DomainPolicy::Checked,
            ..FitOptions::default()
        },
        narx_lags: Some(2),
        ..CompareOptions::default()
    };
    let outcome = compute_compare(&train.data, &model, Some(&test.data), &opts)?;
    Ok(outcome
        .summary
        .validation
        .unwrap_or(outcome.summary.estimation))
}

#[allow(clippy::print_stdout)]
fn main() -> mmenn::Result<()> {
    let table = run()?;
    println!("{} ({})", table.title(), table.horizon());
    for row in table.rows() {
        for ch in &row.evaluation.channels {
            println!(
                "  {:<14} {}: fit {:.1} %",
                row.label, ch.name, ch.metrics.fit_percent
            );
        }
    }
    Ok(())
}
