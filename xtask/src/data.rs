//! The simulated data sets of the reproduction: which systems, recipes, noise levels,
//! sample rates and seeds; their generation into `fixtures/data/<name>/<recipe>/`
//! (`data.csv`, `truth.csv`, `model.toml`); and, under `--check`, the comparison of their
//! summary statistics with the committed `fixtures/data_summary.json` (see
//! [`crate::summary`]).

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use mmenn::data_file::read_table;
use mmenn::plants::{Recipe, SimulatedData, SimulationRequest, simulate_system};
use mmenn::simulate::{SimulateOutput, write_simulation};

use crate::summary::{DataSummary, FileSummary};

/// Seed of the measurement noise of every data set (the recipes' inputs are fixed).
pub const NOISE_SEED: u64 = 1;

/// Damping classes of the condition-monitoring study (thesis ch. 6), N·s/m.
pub const MSD_CLASSES: [f64; 3] = [0.1, 0.15, 0.2];

/// The simulated double-pendulum rig (stand-in for the thesis's §5.6 experiment): the
/// nominal rods with joint Coulomb friction 0.01 N·m (≈ 3 % of the lower rod's largest
/// gravity torque) and 20 % / 50 % more viscous damping at the joint / pivot than the
/// nominal physics model (c2 = 0.03, c1 = 0.01) knows.
pub const RIG_PARAMS: [(&str, f64); 3] = [("tau_c2", 0.01), ("c2", 0.036), ("c1", 0.015)];

/// Angle noise of the rig, rad² (σ ≈ 3.2 mrad ≈ 0.18°, an encoder-class sensor; the
/// simulation study uses 1e-6).
pub const RIG_NOISE: f64 = 1e-5;

/// One data set to generate.
#[derive(Debug, Clone, PartialEq)]
pub struct DataSpec {
    /// Folder name under `fixtures/data`.
    pub name: String,
    /// Registered system.
    pub system: &'static str,
    /// Noise variance (`None`: the system's default; `Some(0)`: clean).
    pub noise: Option<f64>,
    /// Sample rate, Hz (`None`: the system's default).
    pub fs: Option<f64>,
    /// Parameter overrides.
    pub params: Vec<(String, f64)>,
    /// Noise seed.
    pub seed: u64,
    /// Whether a test recipe is generated too.
    pub with_test: bool,
}

impl DataSpec {
    fn new(name: &str, system: &'static str) -> Self {
        Self {
            name: name.into(),
            system,
            noise: None,
            fs: None,
            params: Vec::new(),
            seed: NOISE_SEED,
            with_test: true,
        }
    }

    fn request(&self, recipe: Recipe) -> SimulationRequest {
        SimulationRequest {
            system: self.system.into(),
            recipe,
            noise_variance: self.noise,
            fs: self.fs,
            seed: self.seed,
            params: self.params.clone(),
            duration: None,
        }
    }
}

/// Name of the condition-monitoring data set of damping `c` and noise seed `seed`.
pub fn msd_class_name(c: f64, seed: u64) -> String {
    format!("msd_c{:03}_s{seed}", (c * 100.0).round() as i64)
}

/// Every data set: ch. 2 (cubic MSD), ch. 4/5 (pendulums, double pendulum, two tanks at
/// four rates) and ch. 6 (cubic MSD at three dampings, `class_seeds` noise seeds each).
pub fn specs(class_seeds: u64) -> Vec<DataSpec> {
    let mut v = vec![
        DataSpec::new("msd_cubic", "msd_cubic"),
        DataSpec {
            noise: Some(0.0),
            ..DataSpec::new("pendulum_clean", "pendulum")
        },
        DataSpec {
            noise: Some(0.01),
            ..DataSpec::new("pendulum_noisy", "pendulum")
        },
        DataSpec::new("compound_pendulum", "compound_pendulum"),
        DataSpec::new("double_pendulum", "double_pendulum"),
        DataSpec {
            noise: Some(RIG_NOISE),
            params: RIG_PARAMS
                .iter()
                .map(|(n, v)| (n.to_string(), *v))
                .collect(),
            ..DataSpec::new("double_pendulum_rig", "double_pendulum")
        },
    ];
    for (name, fs) in [
        ("two_tank_10hz", 10.0),
        ("two_tank_5hz", 5.0),
        ("two_tank_1hz", 1.0),
        ("two_tank_0.5hz", 0.5),
    ] {
        v.push(DataSpec {
            fs: Some(fs),
            ..DataSpec::new(name, "two_tank")
        });
    }
    for c in MSD_CLASSES {
        for seed in 1..=class_seeds {
            v.push(DataSpec {
                params: vec![("c".into(), c)],
                seed,
                with_test: false,
                ..DataSpec::new(&msd_class_name(c, seed), "msd_cubic")
            });
        }
    }
    v
}

/// One generated recipe: the files and the simulation (with its truth) in memory.
#[derive(Debug, Clone)]
pub struct Record {
    /// Paths of `data.csv`, `truth.csv`, `model.toml`.
    pub files: SimulateOutput,
    /// The simulation.
    pub sim: SimulatedData,
}

impl Record {
    /// The true initial state.
    pub fn x0(&self) -> Vec<f64> {
        self.sim.truth.states.column(0).iter().copied().collect()
    }
}

/// A generated data set.
#[derive(Debug, Clone)]
pub struct DataSet {
    /// Its specification.
    pub spec: DataSpec,
    /// Training recipe.
    pub train: Record,
    /// Test recipe.
    pub test: Option<Record>,
}

impl DataSet {
    /// The test record, or an error naming the data set.
    pub fn test(&self) -> Result<&Record> {
        self.test
            .as_ref()
            .with_context(|| format!("data set {} has no test recipe", self.spec.name))
    }
}

/// One generated data set, its problems under `--check` and its files' summaries.
type Generated = (DataSet, Vec<String>, Vec<(String, FileSummary)>);

/// Data files whose regenerated summary statistics differ from the committed ones by more
/// than this (relative to the column's largest magnitude) fail `--check`. The truth is
/// integrated to rtol 1e-10, so round-off differences between machines (libm, instruction
/// choice) stay orders of magnitude below it except on a chaotic record.
pub const DATA_TOLERANCE: f64 = 1e-6;

/// Generate every data set into `dir` and summarise every written CSV (keys
/// `<name>/<recipe>/<file>`). With `committed`, compare each summary with the committed
/// one and return one line per difference beyond [`DATA_TOLERANCE`].
pub fn generate(
    specs: &[DataSpec],
    dir: &Path,
    committed: Option<&DataSummary>,
) -> Result<(Vec<DataSet>, Vec<String>, DataSummary)> {
    use rayon::prelude::*;
    let results: Vec<Result<Generated>> = specs
        .par_iter()
        .map(|spec| {
            let mut problems = Vec::new();
            let mut summaries = Vec::new();
            let mut make = |recipe: Recipe| -> Result<Record> {
                let sim = simulate_system(&spec.request(recipe))
                    .with_context(|| format!("simulating {} ({recipe})", spec.name))?;
                let sub: PathBuf = dir.join(&spec.name).join(recipe.to_string());
                let files = write_simulation(&sim, &sub)
                    .with_context(|| format!("writing {}", sub.display()))?;
                for f in ["data.csv", "truth.csv"] {
                    let label = format!("{}/{recipe}/{f}", spec.name);
                    let new = FileSummary::of(&read_table(&sub.join(f))?);
                    if let Some(c) = committed {
                        match c.files.get(&label) {
                            None => problems.push(format!("{label}: no committed summary to compare")),
                            Some(old) => match new.difference(old) {
                                Ok((d, _)) if d <= DATA_TOLERANCE => {}
                                Ok((d, what)) => problems.push(format!(
                                    "{label}: {what} differs from the committed summary by {d:.3e} of the column's largest magnitude (> {DATA_TOLERANCE:e})"
                                )),
                                Err(e) => problems.push(format!("{label}: {e}")),
                            },
                        }
                    }
                    summaries.push((label, new));
                }
                Ok(Record { files, sim })
            };
            let train = make(Recipe::Train)?;
            let test = if spec.with_test {
                Some(make(Recipe::Test)?)
            } else {
                None
            };
            Ok((
                DataSet {
                    spec: spec.clone(),
                    train,
                    test,
                },
                problems,
                summaries,
            ))
        })
        .collect();
    let mut sets = Vec::new();
    let mut problems = Vec::new();
    let mut summary = DataSummary::default();
    for r in results {
        let (s, p, f) = r?;
        sets.push(s);
        problems.extend(p);
        summary.files.extend(f);
    }
    Ok((sets, problems, summary))
}

/// The data set named `name`.
pub fn find<'a>(sets: &'a [DataSet], name: &str) -> Result<&'a DataSet> {
    sets.iter()
        .find(|s| s.spec.name == name)
        .with_context(|| format!("data set {name} was not generated"))
}
