//! How often each μ schedule reaches the exact fit of a teacher network from random
//! starts: for 2-5-1, 3-4-1 and 2-8-1 teachers (`Mlp::new` seeds 11 and 12, inputs uniform
//! in [−1.5, 1.5)), 50 students of the same shape (`Mlp::for_data` seeds 100…149) are
//! trained without validation for up to 400 epochs; a student counts as exact when its
//! MSE is below 1e-10 of the target variance (the crate's teacher-test threshold).
//!
//! Run: `cargo run --release -p nn --example teacher_starts -- [SCHEDULE …]` with
//! [`nn::Damping`]'s snake_case names, each optionally followed by `+geodesic` for
//! [`nn::Acceleration::Geodesic`] (default: all six, without acceleration).

#![allow(clippy::print_stdout)]

use nalgebra::DMatrix;
use nn::{Acceleration, Architecture, Damping, LmConfig, Mlp, ValidationSplit, train_lm};
use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};

/// Students per teacher.
const STARTS: u64 = 50;
/// Exact fit: MSE below this fraction of the target variance.
const EXACT: f64 = 1e-10;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut schedules = Vec::new();
    for arg in std::env::args().skip(1) {
        let (name, acceleration) = match arg.split_once('+') {
            Some((name, "geodesic")) => (name, Acceleration::Geodesic),
            Some(_) => return Err(format!("unknown acceleration in {arg}").into()),
            None => (arg.as_str(), Acceleration::None),
        };
        let damping: Damping = serde_json::from_str(&format!("\"{}\"", name.replace('-', "_")))
            .map_err(|_| format!("unknown damping {name}"))?;
        schedules.push((damping, acceleration));
    }
    if schedules.is_empty() {
        schedules = Damping::ALL.map(|d| (d, Acceleration::None)).to_vec();
    }
    let mut totals = vec![0; schedules.len()];
    println!(
        "| teacher | samples | teacher seed | {} |",
        names(&schedules)
    );
    println!("|---|---:|---:|{}", "---:|".repeat(schedules.len()));
    for (inputs, hidden, samples) in [(2, 5, 300), (3, 4, 500), (2, 8, 400)] {
        for teacher_seed in [11u64, 12] {
            let teacher = Mlp::new(&Architecture::single(inputs, hidden, 1), teacher_seed)?;
            let mut rng = ChaCha8Rng::seed_from_u64(teacher_seed - 10);
            let x = DMatrix::<f64>::from_fn(inputs, samples, |_, _| rng.random_range(-1.5..1.5));
            let t = teacher.predict(&x)?;
            let mean = t.mean();
            let variance = t.map(|v| (v - mean).powi(2)).mean();
            let mut cells = Vec::new();
            for (k, &(damping, acceleration)) in schedules.iter().enumerate() {
                let config = LmConfig {
                    validation: ValidationSplit::None,
                    max_epochs: 400,
                    damping,
                    acceleration,
                    ..LmConfig::default()
                };
                let mut exact = 0;
                for seed in 100..100 + STARTS {
                    let mut student = Mlp::for_data(&x, &t, &[hidden], seed)?;
                    let report = train_lm(&mut student, &x, &t, &config, None)?;
                    if report.train_mse < EXACT * variance {
                        exact += 1;
                    }
                }
                totals[k] += exact;
                cells.push(format!("{exact}/{STARTS}"));
            }
            println!(
                "| {inputs}-{hidden}-1 | {samples} | {teacher_seed} | {} |",
                cells.join(" | ")
            );
        }
    }
    let totals: Vec<String> = totals.iter().map(|t| format!("**{t}**")).collect();
    println!("| all | | | {} |", totals.join(" | "));
    Ok(())
}

fn names(schedules: &[(Damping, Acceleration)]) -> String {
    let names: Vec<String> = schedules
        .iter()
        .map(|(d, a)| match a {
            Acceleration::None => format!("`{d:?}`"),
            _ => format!("`{d:?}` + `{a:?}`"),
        })
        .collect();
    names.join(" | ")
}
