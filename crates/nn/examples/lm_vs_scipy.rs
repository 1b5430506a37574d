//! Head-to-head with MINPACK's Levenberg–Marquardt (scipy), Rust side: for N = 2,000 and
//! 20,000 samples of the `lm_grid` bench data (3 inputs, 1 output) and H = 1…10 hidden units,
//! write the scaled data and the initial weights for `benches/scipy_lm.py`, train with
//! [`train_lm`] from those weights, and record the training MSE and the elapsed time after
//! every epoch (best of `REPEATS` runs per epoch). Time is the thread's CPU time, so other
//! processes on a shared machine do not inflate it (the Python side does the same).
//!
//! Run: `cargo run --release -p nn --example lm_vs_scipy -- OUT_DIR [N [H]]`, then
//! `python3 crates/nn/benches/scipy_lm.py OUT_DIR` (see the crate README).

#![allow(clippy::print_stderr)]

use std::fmt::Write as _;

use nalgebra::DMatrix;
use nn::{EpochInfo, LmConfig, Mlp, ValidationSplit, train_lm};
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

/// CPU time of the calling thread, s.
fn cpu_seconds() -> f64 {
    let t = rustix::time::clock_gettime(rustix::time::ClockId::ThreadCPUTime);
    t.tv_sec as f64 + 1e-9 * t.tv_nsec as f64
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
    // Optional filters (for profiling one case): N, then H.
    let only = |i: usize| {
        std::env::args()
            .nth(i)
            .and_then(|v| v.parse::<usize>().ok())
    };
    let (only_n, only_h) = (only(2), only(3));
    let mut cases = Vec::new();
    for n in [2_000usize, 20_000] {
        if only_n.is_some_and(|v| v != n) {
            continue;
        }
        let (x, t) = data(n);
        for h in 1..=10usize {
            if only_h.is_some_and(|v| v != h) {
                continue;
            }
            let net = Mlp::for_data(&x, &t, &[h], 11)?;
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
                ..LmConfig::default()
            };
            let mut best_times: Vec<f64> = Vec::new();
            let mut history = Vec::new();
            let mut termination = String::new();
            for _ in 0..REPEATS {
                let mut trained = net.clone();
                let mut times = vec![0.0];
                let start = cpu_seconds();
                let mut on_epoch = |_: EpochInfo| times.push(cpu_seconds() - start);
                let report = train_lm(&mut trained, &x, &t, &config, Some(&mut on_epoch))?;
                if best_times.is_empty() {
                    best_times = times;
                } else {
                    for (b, t) in best_times.iter_mut().zip(&times) {
                        *b = b.min(*t);
                    }
                }
                history = report.train_history.clone();
                termination = format!("{:?}", report.termination);
            }
            cases.push(format!(
                "{{\"n\":{n},\"h\":{h},\"rho\":{:e},\"w0\":{},\"rust_mse\":{},\"rust_time\":{},\"rust_stop\":\"{termination}\"}}",
                net.output_scaler().half_range()[0],
                list(net.weights()),
                list(&history),
                list(&best_times),
            ));
            eprintln!(
                "N {n} H {h}: {} epochs, MSE {:.4e}, {:.4} s",
                history.len() - 1,
                history.last().copied().unwrap_or(f64::NAN),
                best_times.last().copied().unwrap_or(f64::NAN)
            );
        }
    }
    std::fs::write(
        out.join("rust.json"),
        format!(
            "{{\"max_epochs\":{MAX_EPOCHS},\"cases\":[\n{}\n]}}\n",
            cases.join(",\n")
        ),
    )?;
    Ok(())
}
