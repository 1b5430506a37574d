//! `discover` as a library call: simulate the cubic mass–spring–damper, and let the
//! discovery workflow name the effect the linear assumed model is missing. `discover`
//! writes its model file, so this example works in a scratch directory.
//!
//! `cargo run --release -p mmenn --example discover`

#![allow(clippy::result_large_err)] // mmenn's errors carry paths and context

use std::path::Path;

use mmenn::discover::{DiscoverOptions, WorkflowConfig, run_discover};
use mmenn::plants::{Recipe, SimulationRequest, simulate_system};
use mmenn::simulate::write_simulation;
use mmenn::{LoadedModel, ModelKind};

/// What the example found.
pub struct DiscoverExample {
    /// The discovered model, loaded.
    pub model: LoadedModel,
    /// Names of the effects it claims.
    pub effects: Vec<String>,
    /// The discovered model as equations.
    pub equations: String,
}

/// Simulate into `dir`, discover, load the discovered model.
pub fn run(dir: &Path) -> mmenn::Result<DiscoverExample> {
    let sim = simulate_system(&SimulationRequest {
        system: "msd_cubic".into(),
        recipe: Recipe::Train,
        seed: 2,
        fs: Some(20.0),
        ..Default::default()
    })?;
    let files = write_simulation(&sim, &dir.join("train"))?;
    let out = dir.join("discover");
    let summary = run_discover(
        std::slice::from_ref(&files.data),
        &files.model,
        &[],
        &DiscoverOptions {
            workflow: WorkflowConfig {
                max_rounds: 1,
                ..WorkflowConfig::default()
            },
            ..DiscoverOptions::default()
        },
        &out,
    )?;
    let path = out.join(&summary.model);
    Ok(DiscoverExample {
        model: LoadedModel::read(&path)?,
        effects: summary.effects.iter().map(|e| e.name.clone()).collect(),
        equations: mmenn::show::show_model(&path)?,
    })
}

#[allow(clippy::print_stdout)]
fn main() -> mmenn::Result<()> {
    let dir = std::env::temp_dir().join(format!("mmenn-example-discover-{}", std::process::id()));
    let r = run(&dir)?;
    println!("named effects: {:?}", r.effects);
    if r.model.kind == ModelKind::WithTerms {
        println!("{}", r.equations);
    }
    println!("files in {}", dir.display());
    Ok(())
}
