//! The system registry and the public entry point: [`systems`] lists every plant,
//! [`simulate_system`] turns a [`SimulationRequest`] (system, recipe, noise, rate, seed,
//! parameter overrides) into noisy data, the noise-free truth and the assumed model.

use std::collections::BTreeMap;

use nalgebra::DMatrix;
use sysid_core::integrate::DEFAULT_BLOW_UP;
use sysid_core::{Channel, Dataset, DpOptions, Experiment, Integrator, LinearModel, simulate};

use crate::compound_pendulum::{self, CompoundPendulum, CompoundPendulumParams};
use crate::double_pendulum::{self, DoublePendulum, DoublePendulumParams};
use crate::error::{PlantError, Result};
use crate::msd::{self, MsdCubic, MsdCubicParams};
use crate::noise::add_noise;
use crate::oscillator::{self, Oscillator, OscillatorParams};
use crate::params::{ParamInfo, Parameters};
use crate::pendulum::{self, Pendulum, PendulumParams};
use crate::signals::SampleGrid;
pub use crate::system::Recipe;
use crate::system::TruthSystem;
use crate::two_tank::{self, TwoTank, TwoTankParams};
use crate::van_der_pol::{self, VanDerPol, VanDerPolParams};

/// What [`systems`] tells about one registered system.
#[derive(Debug, Clone, PartialEq)]
pub struct SystemInfo {
    /// Registry name, used in [`SimulationRequest::system`].
    pub name: &'static str,
    /// One line with the equation.
    pub description: &'static str,
    /// Default sample rate, Hz.
    pub default_fs: f64,
    /// Default measurement-noise variance per measured channel (units²).
    pub default_noise_variance: Vec<f64>,
    /// Physical parameters `(name, default value, unit)`; the names accepted by
    /// [`SimulationRequest::params`].
    pub parameters: Vec<(&'static str, f64, &'static str)>,
}

/// Registered systems, in listing order.
const NAMES: [&str; 7] = [
    msd::NAME,
    pendulum::NAME,
    compound_pendulum::NAME,
    double_pendulum::NAME,
    two_tank::NAME,
    van_der_pol::NAME,
    oscillator::NAME,
];

/// Every registered system with its defaults.
pub fn systems() -> Vec<SystemInfo> {
    NAMES
        .iter()
        .filter_map(|name| build_system(name, &[]).ok())
        .map(|s| SystemInfo {
            name: s.name(),
            description: s.description(),
            default_fs: s.default_fs(),
            default_noise_variance: s.default_noise_variance(),
            parameters: s.parameters(),
        })
        .collect()
}

fn with_overrides<P, S>(
    overrides: &[(String, f64)],
    build: fn(P) -> Result<S>,
) -> Result<Box<dyn TruthSystem>>
where
    P: Parameters + Default,
    S: TruthSystem + 'static,
{
    let mut params = P::default();
    for (name, value) in overrides {
        params.set(name, *value)?;
    }
    Ok(Box::new(build(params)?))
}

/// Build a registered system by name with parameter overrides (unknown system or
/// parameter names and out-of-range values are typed errors).
pub fn build_system(name: &str, overrides: &[(String, f64)]) -> Result<Box<dyn TruthSystem>> {
    match name {
        msd::NAME => with_overrides::<MsdCubicParams, _>(overrides, MsdCubic::new),
        pendulum::NAME => with_overrides::<PendulumParams, _>(overrides, Pendulum::new),
        compound_pendulum::NAME => {
            with_overrides::<CompoundPendulumParams, _>(overrides, CompoundPendulum::new)
        }
        double_pendulum::NAME => {
            with_overrides::<DoublePendulumParams, _>(overrides, DoublePendulum::new)
        }
        two_tank::NAME => with_overrides::<TwoTankParams, _>(overrides, TwoTank::new),
        van_der_pol::NAME => with_overrides::<VanDerPolParams, _>(overrides, VanDerPol::new),
        oscillator::NAME => with_overrides::<OscillatorParams, _>(overrides, Oscillator::new),
        other => Err(PlantError::UnknownSystem {
            name: other.to_string(),
        }),
    }
}

/// What to simulate.
#[derive(Debug, Clone, PartialEq)]
pub struct SimulationRequest {
    /// Registry name (see [`systems`]).
    pub system: String,
    /// Training or test experiment.
    pub recipe: Recipe,
    /// Measurement-noise variance applied to every measured channel (units²; ≥ 0);
    /// `None` uses the system's default. A variance below [`MIN_NOISE_VARIANCE`]
    /// (including 0, the "clean" case) is raised to it.
    pub noise_variance: Option<f64>,
    /// Sample rate, Hz (> 0); `None` uses the system's default.
    pub fs: Option<f64>,
    /// Seed of the measurement noise (ChaCha8). The recipe's inputs are fixed per
    /// recipe and do not depend on it.
    pub seed: u64,
    /// Parameter overrides by name (see [`SystemInfo::parameters`]).
    pub params: Vec<(String, f64)>,
    /// Record length, s (> 0); `None` uses the recipe's default. Samples run from
    /// t = 0 to the last grid time ≤ `duration`.
    pub duration: Option<f64>,
}

impl Default for SimulationRequest {
    /// The thesis's first example: `msd_cubic`, training recipe, default noise and rate,
    /// seed 0, no overrides, default duration.
    fn default() -> Self {
        Self {
            system: msd::NAME.to_string(),
            recipe: Recipe::Train,
            noise_variance: None,
            fs: None,
            seed: 0,
            params: Vec::new(),
            duration: None,
        }
    }
}

/// Noise variance floor (units²): a request for clean data (variance 0) is served with
/// this much noise (σ = 1e-5), so that [`AssumedSpec::noise_variance`] is the variance
/// truly used *and* positive, as MME's `R` must be.
pub const MIN_NOISE_VARIANCE: f64 = 1e-10;

/// Most samples one request may produce.
pub const MAX_SAMPLES: usize = 10_000_000;
// The request check's message quotes the value.
const _: () = assert!(MAX_SAMPLES == 10_000_000);

/// The noise-free truth of a simulated experiment, on the data's sample grid.
#[derive(Debug, Clone, PartialEq)]
pub struct Truth {
    /// Time of the first sample, s.
    pub t0: f64,
    /// Sample period, s.
    pub dt: f64,
    /// State names, in order.
    pub state_names: Vec<String>,
    /// States, `n × N`.
    pub states: DMatrix<f64>,
    /// `d_<state>` for each corrected state.
    pub correction_names: Vec<String>,
    /// Truth corrections `f_truth − f_assumed` on the corrected rows at each sample
    /// (states and the input held on that sample), `q × N`.
    pub corrections: DMatrix<f64>,
    /// Inputs, `m × N` (the same as in the dataset).
    pub inputs: DMatrix<f64>,
}

/// The assumed model and the noise level of the data.
#[derive(Debug, Clone, PartialEq)]
pub struct AssumedSpec {
    /// The assumed linear model (names: states, inputs, outputs = measured states,
    /// corrections = corrected states).
    pub model: LinearModel,
    /// Noise variance per measured channel actually used to generate the data (> 0,
    /// see [`MIN_NOISE_VARIANCE`]).
    pub noise_variance: Vec<f64>,
    /// Units of states, inputs and corrections (`d_<state>`).
    pub units: BTreeMap<String, String>,
}

/// One simulated experiment.
#[derive(Debug, Clone, PartialEq)]
pub struct SimulatedData {
    /// One experiment: input channels and the measured states with noise, units set.
    pub data: Dataset,
    /// The noise-free truth.
    pub truth: Truth,
    /// The assumed model and noise level.
    pub assumed: AssumedSpec,
}

/// Tolerances of the truth simulation: Dormand–Prince 5(4), relative 1e-10 and
/// absolute 1e-12 per step, inputs held between samples.
pub fn truth_integrator() -> Integrator {
    Integrator::DormandPrince(DpOptions {
        rtol: 1e-10,
        atol: 1e-12,
        h_min: 1e-14,
        max_steps: 1_000_000,
    })
}

fn check_request_value(
    field: &'static str,
    value: f64,
    reason: &'static str,
    ok: bool,
) -> Result<()> {
    if ok {
        Ok(())
    } else {
        Err(PlantError::InvalidRequest {
            field,
            value,
            reason,
        })
    }
}

/// Simulate one experiment. Validates the request (system and parameter names, finite
/// and in-range parameters, `fs > 0`, `noise_variance ≥ 0`, `duration > 0`, sample count)
/// before integrating.
///
/// The noise stream is `ChaCha8Rng::seed_from_u64(seed)` on stream 0 for `Train` and 1
/// for `Test`, so the same seed gives independent noise on the two recipes.
pub fn simulate_system(req: &SimulationRequest) -> Result<SimulatedData> {
    let plant = build_system(&req.system, &req.params)?;
    let fs = req.fs.unwrap_or_else(|| plant.default_fs());
    check_request_value(
        "fs",
        fs,
        "sample rate must be positive and finite",
        fs.is_finite() && fs > 0.0,
    )?;
    let model = plant.assumed_model()?;
    let p = model.n_outputs();
    let requested = match req.noise_variance {
        Some(v) => vec![v; p],
        None => plant.default_noise_variance(),
    };
    for &v in &requested {
        check_request_value(
            "noise_variance",
            v,
            "must be non-negative and finite",
            v.is_finite() && v >= 0.0,
        )?;
    }
    let spec = plant.recipe(req.recipe);
    let duration = req.duration.unwrap_or(spec.duration);
    check_request_value(
        "duration",
        duration,
        "must be positive and finite",
        duration.is_finite() && duration > 0.0,
    )?;
    let dt = 1.0 / fs;
    // Samples at k·dt ≤ duration (tolerating round-off of duration·fs).
    let steps = (duration * fs * (1.0 + 1e-12)).floor();
    check_request_value(
        "duration",
        duration,
        "gives fewer than 2 samples at this fs",
        steps >= 1.0,
    )?;
    check_request_value(
        "duration",
        duration,
        "gives more than MAX_SAMPLES = 10,000,000 samples at this fs",
        steps < MAX_SAMPLES as f64,
    )?;
    let len = steps as usize + 1;
    let grid = SampleGrid { t0: 0.0, dt, len };

    let m = plant.n_inputs();
    let mut inputs = DMatrix::zeros(m, len);
    for (i, exc) in spec.inputs.iter().enumerate().take(m) {
        let values = exc.sample(&grid)?;
        inputs.row_mut(i).copy_from_slice(&values);
    }
    let states = simulate(
        &plant,
        &spec.x0,
        0.0,
        dt,
        &inputs,
        &truth_integrator(),
        DEFAULT_BLOW_UP,
    )
    .map_err(|source| PlantError::Simulation {
        system: plant.name(),
        source,
    })?;

    let q = model.n_corrections();
    let mut corrections = DMatrix::zeros(q, len);
    let mut d = vec![0.0; q];
    for k in 0..len {
        plant.truth_correction(
            states.column(k).as_slice(),
            inputs.column(k).as_slice(),
            &mut d,
        );
        corrections.column_mut(k).copy_from_slice(&d);
    }

    let used: Vec<f64> = requested
        .iter()
        .map(|v| v.max(MIN_NOISE_VARIANCE))
        .collect();
    let mut measured = model.c() * &states;
    let stream = match req.recipe {
        Recipe::Train => 0,
        Recipe::Test => 1,
    };
    add_noise(&mut measured, &used, req.seed, stream)?;

    let units = plant.units();
    let channel = |name: &String| match units.get(name) {
        Some(u) => Channel::with_unit(name.clone(), u.clone()),
        None => Channel::new(name.clone()),
    };
    let data = Dataset::new(
        model.input_names().iter().map(channel).collect(),
        model.output_names().iter().map(channel).collect(),
        vec![Experiment::new(0.0, dt, inputs.clone(), measured)?],
    )?;
    let truth = Truth {
        t0: 0.0,
        dt,
        state_names: model.state_names().to_vec(),
        states,
        correction_names: model
            .correction_names()
            .iter()
            .map(|s| format!("d_{s}"))
            .collect(),
        corrections,
        inputs,
    };
    Ok(SimulatedData {
        data,
        truth,
        assumed: AssumedSpec {
            model,
            noise_variance: used,
            units,
        },
    })
}

/// Parameters of a registered system after overrides (convenience for reports).
pub fn system_parameters(name: &str, overrides: &[(String, f64)]) -> Result<Vec<ParamInfo>> {
    Ok(build_system(name, overrides)?.parameters())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recipe_round_trips_through_text() {
        for r in [Recipe::Train, Recipe::Test] {
            assert_eq!(r.to_string().parse::<Recipe>().unwrap(), r);
        }
        assert!(matches!(
            "validate".parse::<Recipe>(),
            Err(PlantError::UnknownRecipe { .. })
        ));
    }

    #[test]
    fn every_system_is_listed_once() {
        let s = systems();
        assert_eq!(s.len(), NAMES.len());
        let names: Vec<&str> = s.iter().map(|i| i.name).collect();
        assert_eq!(names, NAMES.to_vec());
        for info in &s {
            assert!(info.default_fs > 0.0 && !info.parameters.is_empty());
            let model = build_system(info.name, &[])
                .unwrap()
                .assumed_model()
                .unwrap();
            assert_eq!(
                info.default_noise_variance.len(),
                model.n_outputs(),
                "{}",
                info.name
            );
        }
    }
}
