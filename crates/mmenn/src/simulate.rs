//! `mmenn simulate`: generate a built-in system's data set and write `data.csv` (t,
//! inputs, measured states with noise), `truth.csv` (t, inputs, every true state,
//! `d_<state>` truth corrections) and `model.toml` (the system's assumed model).

use std::path::{Path, PathBuf};

use plants::{SimulatedData, SimulationRequest};

use crate::atomic::ensure_dir;
use crate::data_file::{write_csv, write_experiment};
use crate::error::Result;
use crate::model_file::{ModelSpec, NoiseVariance, write_model};

/// Paths of the files [`run_simulate`] wrote.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SimulateOutput {
    /// Measured data (inputs + noisy measured states).
    pub data: PathBuf,
    /// Noise-free truth (all states and truth corrections).
    pub truth: PathBuf,
    /// The assumed model.
    pub model: PathBuf,
}

/// The model file describing a simulated system's assumed model.
pub fn assumed_model_spec(sim: &SimulatedData) -> ModelSpec {
    ModelSpec {
        linear: sim.assumed.model.clone(),
        noise_variance: NoiseVariance::Given(sim.assumed.noise_variance.clone()),
        units: sim.assumed.units.clone(),
        terms: Vec::new(),
        // The plants hold their inputs between samples.
        intersample: sysid_core::InterSample::Zoh,
        parameters: Vec::new(),
        mechanics: None,
        acquisition: None,
        roles: Default::default(),
    }
}

/// Simulate `request` and write its three files into `out` (created if needed).
pub fn run_simulate(request: &SimulationRequest, out: &Path) -> Result<SimulateOutput> {
    let sim = plants::simulate_system(request)?;
    write_simulation(&sim, out)
}

/// Write an already simulated data set into `out`.
pub fn write_simulation(sim: &SimulatedData, out: &Path) -> Result<SimulateOutput> {
    ensure_dir(out)?;
    let paths = SimulateOutput {
        data: out.join("data.csv"),
        truth: out.join("truth.csv"),
        model: out.join("model.toml"),
    };
    write_experiment(&paths.data, &sim.data, 0)?;
    let truth = &sim.truth;
    let n = truth.states.ncols();
    let t: Vec<f64> = (0..n).map(|k| truth.t0 + k as f64 * truth.dt).collect();
    let mut header = vec!["t".to_string()];
    header.extend(sim.data.input_names());
    header.extend(truth.state_names.iter().cloned());
    header.extend(truth.correction_names.iter().cloned());
    let rows: Vec<Vec<f64>> = (0..truth.inputs.nrows())
        .map(|i| truth.inputs.row(i).iter().copied().collect())
        .chain((0..truth.states.nrows()).map(|i| truth.states.row(i).iter().copied().collect()))
        .chain(
            (0..truth.corrections.nrows())
                .map(|i| truth.corrections.row(i).iter().copied().collect()),
        )
        .collect();
    let mut cols: Vec<&[f64]> = vec![&t];
    cols.extend(rows.iter().map(Vec::as_slice));
    write_csv(&paths.truth, &header, &cols)?;
    write_model(&paths.model, &assumed_model_spec(sim))?;
    Ok(paths)
}
