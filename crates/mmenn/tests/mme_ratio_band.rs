//! The sampling band of the `W` search's ratio (docs/decisions/mme-ratio-tolerance.md): with
//! the assumed model exactly right and the noise variance stated correctly, MME's `W` search
//! often ends `not_bracketed` a little below 1, and at least 99 % of such runs must count as
//! converged; with the noise variance stated twice the true one (ratio ≈ 0.5) the run must
//! still be refused, by the estimate's record and by `compute_fit`.
//!
//! The records are made here, not by the workspace: the models' own equations integrated by
//! the hand-written RK4 of `tests/truth.rs` with the input held over each sample (MME's
//! `zoh`), plus seeded Gaussian noise of the stated variance (splitmix64, Box–Muller).

use std::path::Path;

use mmenn::estimate::{EstimateOptions, estimate_spec, mme_config};
use mmenn::fit::{
    FitOptions, HiddenChoice, MmeConvergence, MmeStage, TrajectoryChoice, compute_fit,
    sampling_band,
};
use mmenn::sysid_core::{Channel, Dataset, Experiment, Termination};
use mmenn::{MmennError, ModelSpec};

/// Damped oscillator `x'' = −4x − 0.4x' + u`, `x` measured, correction on `v`.
const OSCILLATOR: &str = r#"
states = ["x", "v"]
inputs = ["u"]
A = [[0.0, 1.0], [-4.0, -0.4]]
B = [[0.0], [1.0]]
measured = ["x"]
corrected = ["v"]
noise_variance = [1e-4]
"#;

// The pendulum of `tests/fit_mme_convergence.rs` (gravity a named term: Gauss–Newton).
use crate::fit_mme_convergence::PENDULUM;

/// The true noise variance of every record (σ = 0.01).
const NOISE_VARIANCE: f64 = 1e-4;

/// Samples per record.
const LEN: usize = 400;

/// `text` with its noise variance set to `variance`.
fn spec(text: &str, variance: f64) -> ModelSpec {
    let text = text.replace(
        "noise_variance = [1e-4]",
        &format!("noise_variance = [{variance:e}]"),
    );
    mmenn::model_file::parse_model(Path::new("model.toml"), &text).unwrap()
}

/// A truth: right-hand side `f(x, u)`, start, sample time, input, the measured state's name.
struct Truth {
    f: fn([f64; 2], f64) -> [f64; 2],
    output: &'static str,
    x0: [f64; 2],
    dt: f64,
    u: fn(f64) -> f64,
}

const OSCILLATOR_TRUTH: Truth = Truth {
    f: |x, u| [x[1], -4.0 * x[0] - 0.4 * x[1] + u],
    output: "x",
    x0: [0.5, 0.0],
    dt: 0.05,
    u: |t| (0.7 * t).sin() + 0.5 * (2.3 * t + 0.4).sin(),
};

const PENDULUM_TRUTH: Truth = Truth {
    f: |x, u| [x[1], -19.62 * x[0].sin() - 0.2 * x[1] - 2.0 * u],
    output: "theta",
    x0: [1.0, 0.0],
    dt: 0.02,
    u: |t| 0.5 * (0.9 * t).sin() + 0.3 * (2.3 * t).sin(),
};

/// splitmix64: the next 64 random bits.
fn splitmix(state: &mut u64) -> u64 {
    *state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
    let mut z = *state;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// `n` independent standard normal numbers (Box–Muller) from `seed`.
fn gaussian(seed: u64, n: usize) -> Vec<f64> {
    let mut state = seed.wrapping_mul(0x2545_F491_4F6C_DD1D) ^ 0x5DEE_CE66;
    let mut uniform = || ((splitmix(&mut state) >> 11) as f64 + 0.5) / (1u64 << 53) as f64;
    let mut out = Vec::with_capacity(n + 1);
    while out.len() < n {
        let (a, b) = (uniform(), uniform());
        let r = (-2.0 * a.ln()).sqrt();
        let phi = std::f64::consts::TAU * b;
        out.push(r * phi.cos());
        out.push(r * phi.sin());
    }
    out.truncate(n);
    out
}

/// The noise-free first state of the truth at every sample, the input held over each
/// sample interval (16 RK4 steps per interval).
fn clean(truth: &Truth) -> (Vec<f64>, Vec<f64>) {
    let mut x = truth.x0;
    let (mut inputs, mut outputs) = (Vec::with_capacity(LEN), Vec::with_capacity(LEN));
    for k in 0..LEN {
        let u = (truth.u)(k as f64 * truth.dt);
        inputs.push(u);
        outputs.push(x[0]);
        x = crate::truth::rk4_samples(|_, x| (truth.f)(x, u), x, truth.dt, 2, 16)[1];
    }
    (inputs, outputs)
}

/// The record: the clean outputs plus noise of variance [`NOISE_VARIANCE`] from `seed`.
fn record(truth: &Truth, clean: &(Vec<f64>, Vec<f64>), seed: u64) -> Dataset {
    let sigma = NOISE_VARIANCE.sqrt();
    let noisy: Vec<f64> = clean
        .1
        .iter()
        .zip(gaussian(seed, LEN))
        .map(|(y, e)| y + sigma * e)
        .collect();
    let exp = Experiment::new(
        0.0,
        truth.dt,
        nalgebra::DMatrix::from_row_slice(1, LEN, &clean.0),
        nalgebra::DMatrix::from_row_slice(1, LEN, &noisy),
    )
    .unwrap();
    Dataset::new(
        vec![Channel::new("u")],
        vec![Channel::new(truth.output)],
        vec![exp],
    )
    .unwrap()
}

/// MME with the automatic `W` on `data`, recorded as `compute_fit` records its training
/// estimate.
fn convergence(spec: &ModelSpec, data: &Dataset) -> MmeConvergence {
    let out = estimate_spec(spec, data, &mme_config(spec, &EstimateOptions::default())).unwrap();
    MmeConvergence::of(MmeStage::Training, &out, data)
}

/// What the correct-model runs of one model gave.
struct Runs {
    refused: Vec<(u64, MmeConvergence)>,
    /// The ratio of every run that ended `not_bracketed` (below 1 and, refused or not),
    /// sorted.
    not_bracketed: Vec<f64>,
    runs: usize,
}

impl std::fmt::Display for Runs {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let r = &self.not_bracketed;
        let q = |p: f64| r[((r.len() - 1) as f64 * p).round() as usize];
        write!(
            f,
            "{} runs, {} refused, {} not bracketed",
            self.runs,
            self.refused.len(),
            r.len()
        )?;
        if !r.is_empty() {
            write!(
                f,
                " (ratio min {:.4}, 1 % {:.4}, 5 % {:.4}, 50 % {:.4}, max {:.4})",
                r[0],
                q(0.01),
                q(0.05),
                q(0.5),
                r[r.len() - 1]
            )?;
        }
        write!(f, "; refused: {:?}", self.refused)
    }
}

/// `seeds` correct-model runs of `text` on records of `truth`.
fn correct_model_runs(text: &str, truth: &Truth, seeds: u64) -> Runs {
    let spec = spec(text, NOISE_VARIANCE);
    let clean = clean(truth);
    let mut runs = Runs {
        refused: Vec::new(),
        not_bracketed: Vec::new(),
        runs: 0,
    };
    for seed in 0..seeds {
        let c = convergence(&spec, &record(truth, &clean, seed));
        runs.runs += 1;
        if c.termination == Some(Termination::NotBracketed) {
            runs.not_bracketed.push(c.w_search_ratio.unwrap());
        }
        if !c.converged() {
            runs.refused.push((seed, c));
        }
    }
    runs.not_bracketed.sort_by(f64::total_cmp);
    runs
}

/// A noise variance stated twice the true one: ratio ≈ 0.5, below the band, refused.
fn assert_overstated_noise_refused(text: &str, truth: &Truth) {
    let spec = spec(text, 2.0 * NOISE_VARIANCE);
    let data = record(truth, &clean(truth), 7);
    let c = convergence(&spec, &data);
    let band = sampling_band(LEN, 2);
    assert_eq!(c.sampling_band, Some(band), "{c}");
    assert_eq!(c.termination, Some(Termination::NotBracketed), "{c}");
    let ratio = c.w_search_ratio.unwrap();
    assert!((0.4..band).contains(&ratio), "{c}");
    assert!(!c.within_sampling_band() && !c.converged(), "{c}");
    assert!(c.ending().contains("below the sampling band"), "{c}");
}

/// The band for these records: `1 − 2/400 − 4·√(2/400)`.
#[test]
fn the_band_is_the_decisions_formula() {
    let band = sampling_band(LEN, 2);
    assert!((band - (1.0 - 0.005 - 4.0 * 0.005f64.sqrt())).abs() < 1e-15);
}

#[test]
fn a_correct_linear_model_is_accepted_in_99_percent_of_runs() {
    let runs = correct_model_runs(OSCILLATOR, &OSCILLATOR_TRUTH, 300);
    // The band is exercised: runs that end not bracketed below 1 are among those accepted.
    assert!(runs.not_bracketed.len() >= 30, "{runs}");
    assert!(runs.refused.len() <= 3, "{runs}");
    assert_overstated_noise_refused(OSCILLATOR, &OSCILLATOR_TRUTH);
}

#[test]
fn a_correct_pendulum_is_accepted_in_99_percent_of_runs() {
    let runs = correct_model_runs(PENDULUM, &PENDULUM_TRUTH, 100);
    assert!(runs.not_bracketed.len() >= 10, "{runs}");
    assert!(runs.refused.len() <= 1, "{runs}");
    assert_overstated_noise_refused(PENDULUM, &PENDULUM_TRUTH);
}

/// `compute_fit` under its default policy: a correct-model run that ended not bracketed
/// within the band is fitted, and its record says why it was accepted; the same record with
/// the noise variance stated twice too high is refused before any network is trained.
#[test]
fn compute_fit_accepts_within_the_band_and_refuses_below_it() {
    let opts = FitOptions {
        hidden: HiddenChoice::Fixed(2),
        inits: 1,
        train_on_trajectories: TrajectoryChoice::None,
        x0_window: 50,
        ..FitOptions::default()
    };
    let right = spec(OSCILLATOR, NOISE_VARIANCE);
    let clean = clean(&OSCILLATOR_TRUTH);
    // The first seed whose run ends not bracketed (below 1, within the band).
    let (data, c) = (0..40)
        .map(|seed| {
            let data = record(&OSCILLATOR_TRUTH, &clean, seed);
            let c = convergence(&right, &data);
            (data, c)
        })
        .find(|(_, c)| c.termination == Some(Termination::NotBracketed))
        .expect("no run ended not bracketed in 40 seeds");
    assert!(c.within_sampling_band(), "{c}");
    let outcome = compute_fit(&data, &right, None, &opts, &mmenn::progress::NoProgress).unwrap();
    assert!(outcome.mme_converged());
    let m = &outcome.summary.mme_estimates[0];
    assert_eq!(m.termination, Some(Termination::NotBracketed), "{m}");
    let words = m.to_string();
    for part in [
        "training estimate converged",
        "W search (covariance constraint)",
        "within the sampling band (ratio 0.",
        " ≥ 0.71",
    ] {
        assert!(words.contains(part), "{part:?} not in {words}");
    }
    let json = serde_json::to_value(&outcome.summary).unwrap();
    assert!(
        json["mme_estimates"][0]["sampling_band"].is_number(),
        "{json}"
    );

    let high = spec(OSCILLATOR, 2.0 * NOISE_VARIANCE);
    let Err(MmennError::MmeNotConverged { report }) =
        compute_fit(&data, &high, None, &opts, &mmenn::progress::NoProgress)
    else {
        panic!("a noise variance stated twice too high was not refused");
    };
    assert_eq!(report.stage, MmeStage::Training);
    assert!(!report.converged(), "{report}");
    assert!(
        report.to_string().contains("below the sampling band"),
        "{report}"
    );
}

/// `mmenn estimate` judges its estimate as `fit` does: a correct-model record whose `W`
/// search ends `not_bracketed` within the band exits 0 and says so; the same record with
/// the noise variance stated twice the true one exits 3.
#[test]
fn mmenn_estimate_exits_0_within_the_band_and_3_below_it() {
    let truth = &OSCILLATOR_TRUTH;
    let clean = clean(truth);
    let good = spec(OSCILLATOR, NOISE_VARIANCE);
    let seed = (0..40)
        .find(|&s| {
            let c = convergence(&good, &record(truth, &clean, s));
            c.termination == Some(Termination::NotBracketed) && c.converged()
        })
        .expect("a correct-model run that ends not bracketed within the band");
    let dir = std::env::temp_dir().join(format!("mmenn-band-cli-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let data = record(truth, &clean, seed);
    let e = &data.experiments()[0];
    let mut csv = String::from("t,u,x\n");
    for k in 0..LEN {
        csv += &format!(
            "{},{},{}\n",
            k as f64 * truth.dt,
            e.inputs()[(0, k)],
            e.outputs()[(0, k)]
        );
    }
    std::fs::write(dir.join("data.csv"), csv).unwrap();
    let run = |variance: f64, out: &str| {
        let text = OSCILLATOR.replace(
            "noise_variance = [1e-4]",
            &format!("noise_variance = [{variance:e}]"),
        );
        std::fs::write(dir.join("model.toml"), text).unwrap();
        std::process::Command::new(env!("CARGO_BIN_EXE_mmenn"))
            .current_dir(&dir)
            .args([
                "estimate",
                "--data",
                "data.csv",
                "--model",
                "model.toml",
                "--out",
                out,
            ])
            .output()
            .unwrap()
    };
    let within = run(NOISE_VARIANCE, "within");
    let text = String::from_utf8_lossy(&within.stdout);
    assert_eq!(
        within.status.code(),
        Some(0),
        "{text}{}",
        String::from_utf8_lossy(&within.stderr)
    );
    assert!(text.contains("within the sampling band"), "{text}");
    let below = run(2.0 * NOISE_VARIANCE, "below");
    assert_eq!(
        below.status.code(),
        Some(3),
        "{}",
        String::from_utf8_lossy(&below.stderr)
    );
    let _ = std::fs::remove_dir_all(&dir);
}
