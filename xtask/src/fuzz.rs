//! `cargo xtask fuzz`: bounded libFuzzer runs of the targets in `fuzz/` (issue 21). Each
//! target runs for a stated number of seconds from the seed corpus in `fuzz/corpus/<t>`
//! (read only) into a working corpus under the build folder, so the repository's seeds
//! never grow by themselves; executions and crashes are read from libFuzzer's final
//! statistics and printed as one line per target. Needs the nightly toolchain and
//! `cargo-fuzz` (`cargo install cargo-fuzz`).

use std::path::Path;
use std::process::Command;

use anyhow::{Context, Result, bail};

/// The targets of `fuzz/Cargo.toml`.
pub const TARGETS: [&str; 5] = ["csv", "model_toml", "expr", "model_json", "estimate"];

/// One target's run.
struct Run {
    target: String,
    seconds: u64,
    executions: Option<u64>,
    ok: bool,
}

/// Run `targets` (all when empty) for `seconds` each; fail when any target crashed.
/// Prints its table to the terminal (a development command, like `reproduce`'s progress).
#[allow(clippy::print_stdout, clippy::print_stderr)]
pub fn fuzz(root: &Path, targets: &[String], seconds: u64) -> Result<()> {
    let chosen: Vec<String> = if targets.is_empty() {
        TARGETS.iter().map(|t| t.to_string()).collect()
    } else {
        for t in targets {
            if !TARGETS.contains(&t.as_str()) {
                bail!(
                    "unknown fuzz target '{t}' (targets: {})",
                    TARGETS.join(", ")
                );
            }
        }
        targets.to_vec()
    };
    let fuzz_dir = root.join("fuzz");
    let mut runs = Vec::new();
    for t in &chosen {
        let work = root.join("target").join("fuzz-corpus").join(t);
        std::fs::create_dir_all(&work).with_context(|| format!("creating {}", work.display()))?;
        let seeds = fuzz_dir.join("corpus").join(t);
        eprintln!("fuzz: {t} for {seconds} s");
        let output = Command::new("cargo")
            .current_dir(&fuzz_dir)
            .args(["+nightly", "fuzz", "run", "-O", t])
            .arg(&work)
            .arg(&seeds)
            .arg("--")
            .arg(format!("-max_total_time={seconds}"))
            .args(["-print_final_stats=1", "-timeout=20", "-rss_limit_mb=3072"])
            .output()
            .context("running cargo +nightly fuzz (is cargo-fuzz installed?)")?;
        let log = String::from_utf8_lossy(&output.stderr);
        let executions = log
            .lines()
            .find_map(|l| l.strip_prefix("stat::number_of_executed_units:"))
            .and_then(|v| v.trim().parse().ok());
        if !output.status.success() {
            eprintln!("{log}");
        }
        runs.push(Run {
            target: t.clone(),
            seconds,
            executions,
            ok: output.status.success(),
        });
    }
    println!("| target | seconds | executions | result |\n|---|---|---|---|");
    for r in &runs {
        println!(
            "| {} | {} | {} | {} |",
            r.target,
            r.seconds,
            r.executions.map_or("?".into(), |e| e.to_string()),
            if r.ok {
                "no crash"
            } else {
                "CRASH (see above)"
            }
        );
    }
    if runs.iter().any(|r| !r.ok) {
        bail!("a fuzz target crashed; the input is under fuzz/artifacts/");
    }
    Ok(())
}
