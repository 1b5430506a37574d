//! `cargo xtask reproduce [--quick] [--check] [--bless]`: regenerate the simulated benchmark
//! data, rerun the thesis experiments, write `docs/results/`, and compare the tables with
//! `fixtures/tables/<mode>/`. `cargo xtask cycles`: import cycles between a crate's files.
#![doc = include_str!("../README.md")]

mod baselines;
mod check;
mod cycles;
mod data;
mod experiments;
mod fuzz;
mod progress;
mod report;
mod stamp;
mod summary;
mod table;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result, bail};
use clap::{Args, Parser, Subcommand};
use mmenn::benchmarks::DataDirSearch;

use crate::check::{TABLE_FORMAT, TableFile};
use crate::experiments::{Ctx, FIT_SEED, Mode, Outcome};
use crate::progress::Progress;
use crate::stamp::Stamp;
use crate::summary::DataSummary;
use crate::table::Table;

/// Development tasks of the mmenn workspace.
#[derive(Debug, Parser)]
#[command(name = "xtask")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Regenerate the simulated data, rerun every experiment, write docs/results.
    Reproduce(ReproduceArgs),
    /// Bounded libFuzzer runs of the targets in fuzz/ (nightly toolchain and cargo-fuzz).
    Fuzz(FuzzArgs),
    /// Import cycles between the files of each crate (fails when there is one).
    Cycles,
}

#[derive(Debug, Args)]
struct FuzzArgs {
    /// Seconds per target.
    #[arg(long, default_value_t = 60)]
    seconds: u64,
    /// Only these targets (csv, model_toml, expr, model_json, estimate), comma-separated.
    #[arg(long, value_delimiter = ',')]
    targets: Vec<String>,
}

#[derive(Debug, Args)]
struct ReproduceArgs {
    /// Small sweeps and fewer seeds (the CI regression guard); results go to
    /// docs/results/quick.
    #[arg(long)]
    quick: bool,
    /// Compare the tables with fixtures/tables/<mode>/ and the data files' summary
    /// statistics with fixtures/data_summary.json; fail with a diff when anything drifts
    /// beyond the stated tolerances.
    #[arg(long, conflicts_with = "bless")]
    check: bool,
    /// Write this run's tables as the new fixtures (fixtures/tables/<mode>/) and its data
    /// summaries into fixtures/data_summary.json.
    #[arg(long)]
    bless: bool,
    /// Folder holding the real benchmarks (cascaded_tanks/, silverbox/, emps/); default
    /// $MMENN_DATA_DIR, then ../shared/data beside the workspace.
    #[arg(long)]
    data_dir: Option<PathBuf>,
    /// Root for fixtures/data and docs/results (default: the workspace).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Fixture folder holding tables/<mode>/ and data_summary.json (default: the
    /// workspace's fixtures/).
    #[arg(long)]
    fixtures: Option<PathBuf>,
    /// Only these experiment groups (ch2, ch4, ch6, real, discovery) or jobs (by the name
    /// on their progress lines, e.g. "real Cascaded Tanks"), comma-separated.
    #[arg(long, value_delimiter = ',')]
    only: Vec<String>,
    /// Worker threads (default: all cores).
    #[arg(long)]
    jobs: Option<usize>,
    /// Print no progress (a bar on a terminal, a line per experiment otherwise).
    #[arg(long, short)]
    quiet: bool,
}

/// The workspace this binary was compiled from, or an error when the command is run from
/// inside another mmenn workspace: two checkouts sharing one `CARGO_TARGET_DIR` overwrite
/// each other's `target/release/xtask`, and cargo, seeing its own package fresh, runs
/// the other checkout's binary. Its code would then write into, and stamp results for, a
/// tree it was not built from.
fn workspace_root() -> Result<PathBuf> {
    let here = Path::new(env!("CARGO_MANIFEST_DIR"));
    let built = here
        .parent()
        .map(Path::to_path_buf)
        .unwrap_or_else(|| here.to_path_buf());
    let cwd = std::env::current_dir().context("reading the current directory")?;
    root_for(&built, &cwd)
}

/// [`workspace_root`]'s check: `built` unless `cwd` lies inside another workspace with an
/// `xtask` package.
fn root_for(built: &Path, cwd: &Path) -> Result<PathBuf> {
    let invoked = cwd
        .ancestors()
        .find(|d| d.join("xtask").join("Cargo.toml").is_file() && d.join("Cargo.toml").is_file());
    if let Some(invoked) = invoked {
        let same = match (invoked.canonicalize(), built.canonicalize()) {
            (Ok(a), Ok(b)) => a == b,
            _ => invoked == built,
        };
        if !same {
            anyhow::bail!(
                "this xtask binary was built from {} but is run in {}: another checkout \
                 sharing the target directory overwrote it. Rebuild it here (touch \
                 xtask/src/main.rs, then cargo xtask …) or give each checkout its own \
                 CARGO_TARGET_DIR",
                built.display(),
                invoked.display()
            );
        }
    }
    Ok(built.to_path_buf())
}

#[cfg(test)]
mod root_tests {
    use super::root_for;

    /// A binary built from one checkout and run inside another is refused, naming both;
    /// run inside its own checkout (any sub-folder) or outside any, it uses its own.
    #[test]
    fn a_binary_from_another_checkout_is_refused() {
        let base = std::env::temp_dir().join(format!("mmenn-root-{}", std::process::id()));
        let (a, b) = (base.join("a"), base.join("b"));
        for w in [&a, &b] {
            std::fs::create_dir_all(w.join("xtask").join("src")).unwrap();
            std::fs::write(w.join("Cargo.toml"), "[workspace]\n").unwrap();
            std::fs::write(w.join("xtask").join("Cargo.toml"), "[package]\n").unwrap();
        }
        assert_eq!(root_for(&a, &a.join("xtask").join("src")).unwrap(), a);
        assert_eq!(root_for(&a, &base).unwrap(), a);
        let e = root_for(&a, &b).unwrap_err().to_string();
        assert!(
            e.contains("built from") && e.contains(&*b.to_string_lossy()),
            "{e}"
        );
        std::fs::remove_dir_all(&base).unwrap();
    }
}

/// Timing of one job.
#[derive(Debug, Clone, serde::Serialize)]
pub struct JobTime {
    /// Job name.
    pub name: String,
    /// Wall time, s.
    pub seconds: f64,
    /// Whether it succeeded.
    pub ok: bool,
}

fn reproduce(args: ReproduceArgs) -> Result<()> {
    let mode = if args.quick { Mode::Quick } else { Mode::Full };
    if let Some(n) = args.jobs {
        rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build_global()
            .context("setting the worker threads")?;
    }
    let root = workspace_root()?;
    let out_root = args.out.clone().unwrap_or_else(|| root.clone());
    let results = match mode {
        Mode::Full => out_root.join("docs").join("results"),
        Mode::Quick => out_root.join("docs").join("results").join("quick"),
    };
    let data_dir = out_root.join("fixtures").join("data");
    let work = out_root
        .join("target")
        .join("xtask-reproduce")
        .join(mode.name());
    let fixture_root = args
        .fixtures
        .clone()
        .unwrap_or_else(|| root.join("fixtures"));
    let fixture_tables = fixture_root.join("tables").join(mode.name());
    for d in [
        results.join("figures"),
        results.join("tables"),
        data_dir.clone(),
        work.clone(),
    ] {
        std::fs::create_dir_all(&d).with_context(|| format!("creating {}", d.display()))?;
    }
    let progress = Progress::start(args.quiet);
    let mut seeds = BTreeMap::new();
    seeds.insert("measurement noise".to_string(), data::NOISE_SEED);
    seeds.insert("network initialisations and splits".to_string(), FIT_SEED);
    seeds.insert("ch6 noise seeds per class".to_string(), mode.class_seeds());
    let stamp = Stamp::now(&root, mode.name(), seeds);
    progress.line(
        "reproduce",
        &format!(
            "mode {}, revision {}, host {} ({} cores), output {}",
            mode.name(),
            stamp.git_revision,
            stamp.host,
            stamp.nproc,
            results.display()
        ),
    );

    let clock = Instant::now();
    let summary_path = fixture_root.join("data_summary.json");
    let committed = if args.check {
        Some(DataSummary::read(&summary_path)?)
    } else {
        None
    };
    let (sets, data_problems, data_summary) = data::generate(
        &data::specs(mode.class_seeds()),
        &data_dir,
        committed.as_ref(),
    )?;
    let data_seconds = clock.elapsed().as_secs_f64();
    progress.line(
        "data",
        &format!(
            "{} data sets written to {} in {data_seconds:.1} s",
            sets.len(),
            data_dir.display()
        ),
    );

    let ctx = Ctx {
        mode,
        results: results.clone(),
        work,
        bench: DataDirSearch::from_env(args.data_dir.clone(), Some(root.clone())),
        progress,
        sets,
        stamp: format!("rev {}, {}", stamp.git_revision, stamp.host),
    };
    let all = experiments::jobs(mode);
    let mut not_run: BTreeMap<String, String> = BTreeMap::new();
    let mut selected = Vec::new();
    for job in all {
        if args.only.is_empty() || args.only.iter().any(|g| g == job.group || *g == job.name) {
            selected.push(job);
        } else {
            for t in &job.tables {
                not_run.insert(
                    t.to_string(),
                    format!("group {} not selected (--only)", job.group),
                );
            }
        }
    }
    let workers = args
        .jobs
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()))
        .max(1);
    let outcomes = run_jobs(&ctx, &selected, workers);

    let mut tables: Vec<Table> = Vec::new();
    let mut figures = Vec::new();
    let mut failures = Vec::new();
    let mut times = Vec::new();
    for ((time, r), job) in outcomes.into_iter().zip(&selected) {
        times.push(time);
        match r {
            Ok(o) => {
                for t in o.tables {
                    match tables.iter_mut().find(|x| x.id == t.id) {
                        Some(x) => x.merge(t),
                        None => tables.push(t),
                    }
                }
                figures.extend(o.figures);
                not_run.extend(o.skipped);
            }
            Err(e) => {
                failures.push(format!("{}: {e:#}", job.name));
                for t in &job.tables {
                    not_run.insert(t.to_string(), format!("job {} failed", job.name));
                }
            }
        }
    }
    let total = ctx.progress.elapsed();

    for t in &tables {
        let file = TableFile {
            format: TABLE_FORMAT.into(),
            mode: mode.name().into(),
            stamp: stamp.clone(),
            table: t.clone(),
        };
        let dir = results.join("tables");
        mmenn::atomic::write_atomic(
            &dir.join(format!("{}.json", t.id)),
            serde_json::to_string_pretty(&file)?.as_bytes(),
        )?;
        let md = format!("{}\n{}\n", t.markdown(), stamp.markdown());
        mmenn::atomic::write_atomic(&dir.join(format!("{}.md", t.id)), md.as_bytes())?;
    }
    let run = report::RunInfo {
        stamp: stamp.clone(),
        total_seconds: total,
        data_seconds,
        jobs: times,
        skipped: not_run.clone(),
        failures: failures.clone(),
        figures,
    };
    let quick_run: Option<serde_json::Value> = match mode {
        Mode::Full => std::fs::read_to_string(results.join("quick").join("run.json"))
            .ok()
            .and_then(|t| serde_json::from_str(&t).ok()),
        Mode::Quick => None,
    };
    mmenn::atomic::write_atomic(
        &results.join("run.json"),
        serde_json::to_string_pretty(&run)?.as_bytes(),
    )?;
    mmenn::atomic::write_atomic(
        &results.join("README.md"),
        report::readme(&run, &tables, mode, quick_run.as_ref()).as_bytes(),
    )?;
    ctx.progress.line(
        "reproduce",
        &format!(
            "{} tables written to {} in {total:.1} s",
            tables.len(),
            results.display()
        ),
    );

    if args.bless {
        std::fs::create_dir_all(&fixture_tables)?;
        for t in &tables {
            let file = TableFile {
                format: TABLE_FORMAT.into(),
                mode: mode.name().into(),
                stamp: stamp.clone(),
                table: t.clone(),
            };
            mmenn::atomic::write_atomic(
                &fixture_tables.join(format!("{}.json", t.id)),
                serde_json::to_string_pretty(&file)?.as_bytes(),
            )?;
        }
        // The quick and full runs generate different sets (ch6 noise seeds): keep the
        // other mode's entries, replace this run's.
        let mut summary = DataSummary::read(&summary_path)?;
        let n_files = data_summary.files.len();
        summary.files.extend(data_summary.files);
        summary.write(&summary_path)?;
        ctx.progress.line(
            "bless",
            &format!(
                "{} fixture tables written to {}; summaries of {n_files} data files to {}",
                tables.len(),
                fixture_tables.display(),
                summary_path.display()
            ),
        );
    }
    if !failures.is_empty() {
        bail!(
            "{} experiment(s) failed:\n  {}",
            failures.len(),
            failures.join("\n  ")
        );
    }
    if args.check {
        let fixtures = check::read_fixtures(&fixture_tables)?;
        let rep = check::compare(&tables, &fixtures, &not_run);
        for s in &rep.skipped {
            ctx.progress.line("check", &format!("skipped {s}"));
        }
        let mut problems = data_problems;
        problems.extend(rep.failures.iter().cloned());
        if !problems.is_empty() {
            bail!(
                "reproduction drifted from the fixtures ({} of {} values compared; {} problems):\n  {}",
                rep.failures.len(),
                rep.compared,
                problems.len(),
                problems.join("\n  ")
            );
        }
        ctx.progress.line(
            "check",
            &format!(
                "{} values in {} tables and every data file agree with the fixtures",
                rep.compared,
                fixtures.len()
            ),
        );
    }
    Ok(())
}

/// A job's timing and result.
type Finished = (JobTime, Result<Outcome>);

/// Run the jobs on `workers` threads, longest expected first (each worker takes the next
/// job when it is free); results in the jobs' order.
fn run_jobs(
    ctx: &Ctx,
    jobs: &[experiments::Job],
    workers: usize,
) -> Vec<(JobTime, Result<Outcome>)> {
    use std::sync::Mutex;
    use std::sync::atomic::{AtomicUsize, Ordering};
    let mut order: Vec<usize> = (0..jobs.len()).collect();
    order.sort_by_key(|&i| std::cmp::Reverse(jobs[i].cost));
    let next = AtomicUsize::new(0);
    ctx.progress
        .begin_jobs(&jobs.iter().map(|j| f64::from(j.cost)).collect::<Vec<_>>());
    let slots: Vec<Mutex<Option<Finished>>> = jobs.iter().map(|_| Mutex::new(None)).collect();
    std::thread::scope(|scope| {
        for _ in 0..workers.min(jobs.len()) {
            scope.spawn(|| {
                loop {
                    let k = next.fetch_add(1, Ordering::SeqCst);
                    let Some(&i) = order.get(k) else { break };
                    let job = &jobs[i];
                    ctx.progress.job_started(&job.name);
                    let clock = Instant::now();
                    let r = (job.run)(ctx);
                    let seconds = clock.elapsed().as_secs_f64();
                    let failure = r.as_ref().err().map(|e| format!("{e:#}"));
                    ctx.progress.job_finished(
                        &job.name,
                        f64::from(job.cost),
                        seconds,
                        failure.as_deref(),
                    );
                    let time = JobTime {
                        name: job.name.clone(),
                        seconds,
                        ok: r.is_ok(),
                    };
                    if let Ok(mut slot) = slots[i].lock() {
                        *slot = Some((time, r));
                    }
                }
            });
        }
    });
    ctx.progress.end_jobs();
    slots
        .into_iter()
        .zip(jobs)
        .map(|(slot, job)| {
            slot.into_inner().ok().flatten().unwrap_or_else(|| {
                (
                    JobTime {
                        name: job.name.clone(),
                        seconds: 0.0,
                        ok: false,
                    },
                    Err(anyhow::anyhow!(
                        "job {} did not report (a worker panicked)",
                        job.name
                    )),
                )
            })
        })
        .collect()
}

fn main() -> Result<()> {
    match Cli::parse().command {
        Command::Reproduce(args) => reproduce(args),
        Command::Fuzz(args) => fuzz::fuzz(&workspace_root()?, &args.targets, args.seconds),
        Command::Cycles => cycles::cycles(&workspace_root()?),
    }
}
