//! The simulated data sets of the reproduction: which systems, recipes, noise levels,
//! sample rates and seeds; their generation into `fixtures/data/<name>/<recipe>/`
//! (`data.csv`, `truth.csv`, `model.toml`); and, under `--check`, their comparison with the
//! committed files.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use mmenn::data_file::{Table as CsvTable, read_table};
use mmenn::plants::{Recipe, SimulatedData, SimulationRequest, simulate_system};
use mmenn::simulate::{SimulateOutput, write_simulation};

/// Seed of the measurement noise of every data set (the recipes' inputs are fixed).
pub const NOISE_SEED: u64 = 1;

/// Damping classes of the condition-monitoring study (thesis ch. 6), N·s/m.
pub const MSD_CLASSES: [f64; 3] = [0.1, 0.15, 0.2];

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

/// Largest difference between a regenerated and a committed CSV, relative to each
/// column's largest magnitude (so it reads the same for metres and radians).
fn relative_difference(new: &CsvTable, old: &CsvTable) -> Result<f64> {
    if new.header != old.header {
        bail!(
            "header {:?} differs from the committed {:?}",
            new.header,
            old.header
        );
    }
    let mut worst = 0.0_f64;
    for (a, b) in new.columns.iter().zip(&old.columns) {
        if a.len() != b.len() {
            bail!("{} rows, the committed file has {}", a.len(), b.len());
        }
        let scale = b.iter().fold(0.0_f64, |m, v| m.max(v.abs())).max(1e-300);
        for (x, y) in a.iter().zip(b) {
            worst = worst.max((x - y).abs() / scale);
        }
    }
    Ok(worst)
}

/// Data files whose regenerated numbers differ from the committed ones by more than this
/// (relative to the column's range) fail `--check`. The truth is integrated to rtol 1e-10,
/// so round-off differences between machines (libm, instruction choice) stay orders of
/// magnitude below it except on a chaotic record.
pub const DATA_TOLERANCE: f64 = 1e-6;

/// Generate every data set into `dir`. With `committed`, compare each regenerated file with
/// the committed one of the same name first (read before anything is overwritten) and
/// return one line per difference beyond [`DATA_TOLERANCE`].
pub fn generate(
    specs: &[DataSpec],
    dir: &Path,
    committed: Option<&Path>,
) -> Result<(Vec<DataSet>, Vec<String>)> {
    use rayon::prelude::*;
    let results: Vec<Result<(DataSet, Vec<String>)>> = specs
        .par_iter()
        .map(|spec| {
            let mut problems = Vec::new();
            let mut make = |recipe: Recipe| -> Result<Record> {
                let sim = simulate_system(&spec.request(recipe))
                    .with_context(|| format!("simulating {} ({recipe})", spec.name))?;
                let sub: PathBuf = dir.join(&spec.name).join(recipe.to_string());
                let old: Vec<(String, Option<CsvTable>)> = match committed {
                    Some(c) => ["data.csv", "truth.csv"]
                        .iter()
                        .map(|f| {
                            let p = c.join(&spec.name).join(recipe.to_string()).join(f);
                            (f.to_string(), read_table(&p).ok())
                        })
                        .collect(),
                    None => Vec::new(),
                };
                let files = write_simulation(&sim, &sub)
                    .with_context(|| format!("writing {}", sub.display()))?;
                for (f, old) in old {
                    let label = format!("{}/{recipe}/{f}", spec.name);
                    match old {
                        None => problems.push(format!("{label}: no committed file to compare")),
                        Some(old) => {
                            let new = read_table(&sub.join(&f))?;
                            match relative_difference(&new, &old) {
                                Ok(d) if d <= DATA_TOLERANCE => {}
                                Ok(d) => problems.push(format!(
                                    "{label}: differs from the committed file by {d:.3e} of the column range (> {DATA_TOLERANCE:e})"
                                )),
                                Err(e) => problems.push(format!("{label}: {e}")),
                            }
                        }
                    }
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
            ))
        })
        .collect();
    let mut sets = Vec::new();
    let mut problems = Vec::new();
    for r in results {
        let (s, p) = r?;
        sets.push(s);
        problems.extend(p);
    }
    Ok((sets, problems))
}

/// The data set named `name`.
pub fn find<'a>(sets: &'a [DataSet], name: &str) -> Result<&'a DataSet> {
    sets.iter()
        .find(|s| s.spec.name == name)
        .with_context(|| format!("data set {name} was not generated"))
}
