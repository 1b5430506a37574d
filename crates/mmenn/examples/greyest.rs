//! `greyest` as a library call: the two-link pendulum of `fixtures/two_link` (records
//! written by an independent scipy generator), its model file with the masses fixed as
//! weighed and every other free parameter started 30 % high, calibrated on `est.csv`.
//!
//! `cargo run --release -p mmenn --example greyest`

#![allow(clippy::result_large_err)] // mmenn's errors carry paths and context

use std::path::Path;

use mmenn::LoadedModel;
use mmenn::data_file::{read_table, table_to_experiment};
use mmenn::greyest::{GreyestOptions, compute_greyest_quietly};
use mmenn::sysid_core::Estimation;

/// What the example found: (name, start, estimate, σ) per free parameter.
pub struct GreyestExample {
    /// The free parameters.
    pub estimates: Vec<(String, f64, f64, Option<f64>)>,
    /// Free-run fit % of each angle on the record.
    pub fit_percent: Vec<(String, f64)>,
}

/// Read the model and record, start off the truth, estimate (all in memory).
pub fn run() -> mmenn::Result<GreyestExample> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/two_link");
    let mut spec = LoadedModel::read(&dir.join("model.toml"))?.spec;
    for p in &mut spec.parameters {
        if p.name == "m1" || p.name == "m2" {
            p.estimation = Estimation::Fixed;
        } else if p.estimation == Estimation::Free {
            p.value *= 1.3;
        }
    }
    let model = LoadedModel::from_spec(&dir.join("model.toml"), spec)?;
    let lin = &model.spec.linear;
    let table = read_table(&dir.join("est.csv"))?;
    let record = table_to_experiment(&table, lin.input_names(), lin.output_names())?;
    let outcome = compute_greyest_quietly(
        &model,
        &[record],
        &["est.csv".into()],
        &GreyestOptions::default(),
    )?;
    let s = &outcome.summary;
    Ok(GreyestExample {
        estimates: s
            .parameters
            .iter()
            .map(|p| (p.name.clone(), p.start, p.value, p.sigma))
            .collect(),
        fit_percent: s.records[0].fit_percent.clone().into_iter().collect(),
    })
}

#[allow(clippy::print_stdout)]
fn main() -> mmenn::Result<()> {
    let r = run()?;
    for (name, start, value, sigma) in &r.estimates {
        let sigma = sigma.map_or("—".into(), |s| format!("± {s:.2e}"));
        println!("{name}: {start:.4e} → {value:.6e} {sigma}");
    }
    for (name, fit) in &r.fit_percent {
        println!("free-run fit of {name}: {fit:.2} %");
    }
    Ok(())
}
