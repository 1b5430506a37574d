//! The experiments of the reproduction, each an independent job producing parts of
//! result tables and figures; the run context they share (mode, folders, data sets).

pub mod ch2;
pub mod ch6;
pub mod discovery;
pub mod grey;
pub mod real;
pub mod systems;

use std::collections::BTreeMap;
use std::path::PathBuf;

use anyhow::{Context, Result};
use mmenn::benchmarks::DataDirSearch;
use mmenn::plot::{Figure, Series};

use crate::data::DataSet;
use crate::progress::Progress;
use crate::table::Table;

/// How much effort the run spends.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mode {
    /// Small sweeps and fewer seeds (< 2 min on 2 cores): the CI regression guard.
    Quick,
    /// The thesis's effort (1–10 hidden units × 10 initialisations).
    Full,
}

impl Mode {
    /// `quick` or `full`.
    pub fn name(self) -> &'static str {
        match self {
            Mode::Quick => "quick",
            Mode::Full => "full",
        }
    }

    /// Largest network and initialisations of the MME/NN sizing sweep.
    pub fn sweep(self) -> (usize, usize) {
        match self {
            Mode::Quick => (5, 3),
            Mode::Full => (10, 10),
        }
    }

    /// Noise seeds per damping class of the condition-monitoring study.
    pub fn class_seeds(self) -> u64 {
        match self {
            Mode::Quick => 6,
            Mode::Full => 12,
        }
    }
}

/// Seed of every network initialisation and validation split of MME/NN and NARX.
pub const FIT_SEED: u64 = 7;

/// What every job sees.
#[derive(Debug)]
pub struct Ctx {
    /// Effort.
    pub mode: Mode,
    /// `docs/results` (or `docs/results/quick`) under the output root.
    pub results: PathBuf,
    /// Scratch folder for the workflows' own outputs (`model.json`, sweeps…).
    pub work: PathBuf,
    /// Where the real benchmarks are looked for.
    pub bench: DataDirSearch,
    /// Progress lines.
    pub progress: Progress,
    /// The generated data sets.
    pub sets: Vec<DataSet>,
    /// Revision and host, appended to every figure's title.
    pub stamp: String,
}

impl Ctx {
    /// Write a figure into `results/figures/<name>.svg`; returns the path relative to
    /// `results`.
    pub fn figure(&self, name: &str, fig: &Figure) -> Result<String> {
        let rel = format!("figures/{name}.svg");
        let path = self.results.join(&rel);
        let mut fig = fig.clone();
        fig.title = format!("{} [{}]", fig.title, self.stamp);
        fig.write(&path)
            .with_context(|| format!("writing figure {}", path.display()))?;
        Ok(rel)
    }
}

/// What one job produced.
#[derive(Debug, Default)]
pub struct Outcome {
    /// Table parts (merged by id in job order).
    pub tables: Vec<Table>,
    /// Figures written (relative to the results folder).
    pub figures: Vec<String>,
    /// Tables the job could not produce, with the reason (e.g. data absent).
    pub skipped: BTreeMap<String, String>,
}

/// The work of a job.
pub type RunFn = Box<dyn Fn(&Ctx) -> Result<Outcome> + Send + Sync>;

/// One independent experiment.
pub struct Job {
    /// Name on the progress lines.
    pub name: String,
    /// Group selectable with `--only` (`ch2`, `ch4`, `ch6`, `real`, `discovery`).
    pub group: &'static str,
    /// Table ids it produces (to tell why a fixture table is missing when it is not run).
    pub tables: Vec<&'static str>,
    /// Expected cost (seconds of a full run measured on two cores): jobs start
    /// longest-first so that the parallel run ends as early as possible.
    pub cost: u32,
    /// The work.
    pub run: RunFn,
}

/// Every job, in table order.
pub fn jobs(mode: Mode) -> Vec<Job> {
    let mut v = vec![ch2::job()];
    v.extend(systems::jobs(mode));
    v.extend(ch6::jobs());
    v.extend(real::jobs());
    if mode == Mode::Full {
        v.extend(discovery::jobs());
    }
    v
}

/// At most `max` evenly spaced points of a series (figures stay small).
pub fn thin(x: &[f64], y: &[f64], max: usize) -> (Vec<f64>, Vec<f64>) {
    let step = x.len().div_ceil(max.max(1)).max(1);
    (
        x.iter().step_by(step).copied().collect(),
        y.iter().step_by(step).copied().collect(),
    )
}

/// A line series thinned to 1500 points.
pub fn line(label: impl Into<String>, x: &[f64], y: &[f64]) -> Series {
    let (a, b) = thin(x, y, 1500);
    Series::line(label, a, b)
}

/// The median of `v` (sorted in place; an even count's is the mean of the middle two; NaN
/// when empty).
pub fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n == 0 {
        return f64::NAN;
    }
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// A row of a matrix as a vector.
pub fn row(m: &nalgebra::DMatrix<f64>, i: usize) -> Vec<f64> {
    m.row(i).iter().copied().collect()
}
