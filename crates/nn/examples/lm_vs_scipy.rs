//! Head-to-head with MINPACK's Levenberg–Marquardt (scipy), Rust side: for N = 2,000 and
//! 20,000 samples of the `lm_grid` bench data (3 inputs, 1 output), H = 1…10 hidden units
//! and one or more initial-weight seeds, write the scaled data and the initial weights for
//! `benches/scipy_lm.py`, train with [`train_lm`] from those weights, and record the
//! training MSE and the elapsed time after every epoch (best of `REPEATS` runs per epoch).
//! Two clocks: the process's CPU time (all threads; other processes on a shared machine do
//! not inflate it, and the Python side measures the same for single-threaded scipy) and
//! wall-clock time.
//!
//! Run: `cargo run --release -p nn --example lm_vs_scipy -- OUT_DIR [N [H]] [--threads K]
//! [--damping NAME] [--acceleration NAME] [--seeds S1,S2,…] [--mu-decrease F]
//! [--mu-increase F]`, then
//! `python3 crates/nn/benches/scipy_lm.py OUT_DIR` (see the crate README). `--threads`
//! sizes rayon's pool (default 1); `--damping` picks [`nn::Damping`] by its snake_case name
//! (default `trainlm`); `--seeds` lists the seeds of [`Mlp::for_data`]'s initial weights
//! (default 11, the single start of the first comparison); `--mu-decrease` and
//! `--mu-increase` set [`LmConfig`]'s factors; `--acceleration geodesic` turns on
//! [`nn::Acceleration::Geodesic`] (default `none`).

#![allow(clippy::print_stderr)]

use std::fmt::Write as _;

use nalgebra::DMatrix;
use nn::{Acceleration, Damping, EpochInfo, LmConfig, Mlp, ValidationSplit, train_lm};
use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};

/// Runs per case; the per-epoch elapsed time is the minimum over runs.
const REPEATS: usize = 3;
/// Epoch budget (both optimisers get a budget large enough to level off).
const MAX_EPOCHS: usize = 200;

/// The `lm_grid` bench data: inputs uniform in [−2, 2)³ from `ChaCha8Rng` seed 7, target
/// `sin(x₁)·cos(x₂/2) + 0.3·tanh(x₃)`.
fn data(n: usize) -> (DMatrix<f64>, DMatrix<f64>) {
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let x = DMatrix::<f64>::from_fn(3, n, |_, _| rng.random_range(-2.0..2.0));
    let t = DMatrix::from_fn(1, n, |_, k| {
        (x[(0, k)]).sin() * (0.5 * x[(1, k)]).cos() + 0.3 * x[(2, k)].tanh()
    });
    (x, t)
}

/// CPU time of the process (all threads), s.
fn cpu_seconds() -> f64 {
    let t = rustix::time::clock_gettime(rustix::time::ClockId::ProcessCPUTime);
    t.tv_sec as f64 + 1e-9 * t.tv_nsec as f64
}

/// Value following the flag `name` on the command line.
fn flag(name: &str) -> Option<String> {
    let args: Vec<String> = std::env::args().collect();
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1).cloned())
}

fn list(v: &[f64]) -> String {
    let items: Vec<String> = v.iter().map(|x| format!("{x:e}")).collect();
    format!("[{}]", items.join(","))
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let out = std::path::PathBuf::from(
        std::env::args()
            .nth(1)
            .ok_or("usage: lm_vs_scipy OUT_DIR")?,
    );
    std::fs::create_dir_all(&out)?;
    let threads: usize = flag("--threads").map_or(Ok(1), |v| v.parse())?;
    // The schedule's serde name (snake_case; `-` accepted for `_`).
    let damping: Damping = match flag("--damping") {
        None => Damping::Trainlm,
        Some(name) => serde_json::from_str(&format!("\"{}\"", name.replace('-', "_")))
            .map_err(|_| format!("unknown damping {name}"))?,
    };
    let acceleration: Acceleration = match flag("--acceleration") {
        None => Acceleration::None,
        Some(name) => serde_json::from_str(&format!("\"{name}\""))
            .map_err(|_| format!("unknown acceleration {name}"))?,
    };
    let defaults = LmConfig::default();
    let mu_decrease: f64 = flag("--mu-decrease").map_or(Ok(defaults.mu_decrease), |v| v.parse())?;
    let mu_increase: f64 = flag("--mu-increase").map_or(Ok(defaults.mu_increase), |v| v.parse())?;
    let seeds: Vec<u64> = flag("--seeds").map_or(Ok(vec![11]), |v| {
        v.split(',').map(str::parse).collect::<Result<_, _>>()
    })?;
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build_global()?;
    // Optional filters (for profiling one case): N, then H (positional, after OUT_DIR).
    let mut positional = Vec::new();
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        if a.starts_with("--") {
            args.next();
        } else {
            positional.push(a);
        }
    }
    let only = |i: usize| positional.get(i).and_then(|v| v.parse::<usize>().ok());
    let (only_n, only_h) = (only(1), only(2));
    let mut cases = Vec::new();
    for n in [2_000usize, 20_000] {
        if only_n.is_some_and(|v| v != n) {
            continue;
        }
        let (x, t) = data(n);
        for (h, &seed) in (1..=10usize).flat_map(|h| seeds.iter().map(move |s| (h, s))) {
            if only_h.is_some_and(|v| v != h) {
                continue;
            }
            let net = Mlp::for_data(&x, &t, &[h], seed)?;
            if !out.join(format!("data_N{n}.csv")).exists() {
                // Scaled data: the weights act on these (Mlp::for_data's mapminmax scalers).
                let (si, so) = (net.input_scaler(), net.output_scaler());
                let mut csv = String::from("s1,s2,s3,target\n");
                for k in 0..n {
                    for j in 0..3 {
                        let v = (x[(j, k)] - si.centre()[j]) / si.half_range()[j];
                        write!(csv, "{v:e},")?;
                    }
                    let v = (t[(0, k)] - so.centre()[0]) / so.half_range()[0];
                    writeln!(csv, "{v:e}")?;
                }
                std::fs::write(out.join(format!("data_N{n}.csv")), csv)?;
            }
            let config = LmConfig {
                max_epochs: MAX_EPOCHS,
                validation: ValidationSplit::None,
                damping,
                acceleration,
                mu_decrease,
                mu_increase,
                ..LmConfig::default()
            };
            let mut best_times: Vec<f64> = Vec::new();
            let mut best_walls: Vec<f64> = Vec::new();
            let mut history = Vec::new();
            let mut termination = String::new();
            for _ in 0..REPEATS {
                let mut trained = net.clone();
                let (mut times, mut walls) = (vec![0.0], vec![0.0]);
                let (start, wall) = (cpu_seconds(), std::time::Instant::now());
                let mut on_epoch = |_: EpochInfo| {
                    times.push(cpu_seconds() - start);
                    walls.push(wall.elapsed().as_secs_f64());
                };
                let report = train_lm(&mut trained, &x, &t, &config, Some(&mut on_epoch))?;
                for (best, new) in [(&mut best_times, times), (&mut best_walls, walls)] {
                    if best.is_empty() {
                        *best = new;
                    } else {
                        for (b, t) in best.iter_mut().zip(&new) {
                            *b = b.min(*t);
                        }
                    }
                }
                history = report.train_history.clone();
                termination = format!("{:?}", report.termination);
            }
            cases.push(format!(
                "{{\"n\":{n},\"h\":{h},\"seed\":{seed},\"rho\":{:e},\"w0\":{},\"rust_mse\":{},\"rust_time\":{},\"rust_wall\":{},\"rust_stop\":\"{termination}\"}}",
                net.output_scaler().half_range()[0],
                list(net.weights()),
                list(&history),
                list(&best_times),
                list(&best_walls),
            ));
            eprintln!(
                "N {n} H {h} seed {seed}: {} epochs, MSE {:.4e}, {:.4} s",
                history.len() - 1,
                history.last().copied().unwrap_or(f64::NAN),
                best_times.last().copied().unwrap_or(f64::NAN)
            );
        }
    }
    std::fs::write(
        out.join("rust.json"),
        format!(
            "{{\"max_epochs\":{MAX_EPOCHS},\"threads\":{threads},\"damping\":\"{damping:?}\",\"acceleration\":\"{acceleration:?}\",\"mu_decrease\":{mu_decrease:e},\"mu_increase\":{mu_increase:e},\"seeds\":{seeds:?},\"cases\":[\n{}\n]}}\n",
            cases.join(",\n")
        ),
    )?;
    Ok(())
}
