//! `compute_fit` on an MME estimate that did not converge: by default it refuses before
//! training any network, naming the estimate, its ending and its residual/noise variance
//! ratio; under `UnconvergedMme::Warn` it builds the hybrid and the outcome says the
//! estimate did not converge; a converged estimate gives no warning.

use std::path::Path;
use std::sync::Mutex;

use mmenn::estimate::{EstimateOptions, WeightChoice};
use mmenn::fit::{
    FitOptions, HiddenChoice, MmeStage, TrajectoryChoice, UnconvergedMme, compute_fit,
};
use mmenn::mme_core::IterationOptions;
use mmenn::progress::Progress;
use mmenn::sysid_core::{Channel, Dataset, Experiment, Termination};
use mmenn::{MmennError, ModelSpec};

/// A pendulum whose gravity is a named term (so MME iterates: Gauss–Newton on the
/// linearisation); the data carry a quadratic drag the model lacks (`mme_ratio_band` uses it
/// on data without the drag).
pub(crate) const PENDULUM: &str = r#"
states = ["theta", "omega"]
inputs = ["u"]
A = [[0.0, 1.0], [0.0, -0.2]]
B = [[0.0], [-2.0]]
measured = ["theta"]
corrected = ["omega"]
noise_variance = [1e-4]

[[terms]]
state = "omega"
effect = "gravity"
term = "sin(theta)"
coefficient = -19.62
"#;

pub(crate) fn spec() -> ModelSpec {
    mmenn::model_file::parse_model(Path::new("pendulum.toml"), PENDULUM).unwrap()
}

/// 400 samples at 0.02 s of the pendulum with quadratic drag (RK4, 16 sub-steps), from
/// θ = 1 rad, the angle with a deterministic ±0.01 rad pseudo-noise.
pub(crate) fn record() -> Dataset {
    const DT: f64 = 0.02;
    const LEN: usize = 400;
    const SUB: usize = 16;
    let u = |t: f64| 0.5 * (0.9 * t).sin() + 0.3 * (2.3 * t).sin();
    let f = |t: f64, x: [f64; 2]| {
        [
            x[1],
            -19.62 * x[0].sin() - 0.2 * x[1] - 2.0 * u(t) - 1.5 * x[1] * x[1].abs(),
        ]
    };
    let states = crate::truth::rk4_samples(f, [1.0, 0.0], DT, LEN, SUB);
    let mut lcg = 12345u64;
    let (mut inputs, mut outputs) = (Vec::new(), Vec::new());
    for (k, x) in states.iter().enumerate() {
        lcg = lcg
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        let e = ((lcg >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 0.02;
        inputs.push(u(k as f64 * DT));
        outputs.push(x[0] + e);
    }
    let exp = Experiment::new(
        0.0,
        DT,
        nalgebra::DMatrix::from_row_slice(1, LEN, &inputs),
        nalgebra::DMatrix::from_row_slice(1, LEN, &outputs),
    )
    .unwrap();
    Dataset::new(
        vec![Channel::new("u")],
        vec![Channel::new("theta")],
        vec![exp],
    )
    .unwrap()
}

/// A small fit at a given `W`, MME's Gauss–Newton limited to `max_iterations`.
fn options(max_iterations: usize, policy: UnconvergedMme) -> FitOptions {
    FitOptions {
        estimate: EstimateOptions {
            w: WeightChoice::Value(1e3),
            iterations: IterationOptions {
                max_iterations,
                ..IterationOptions::default()
            },
            ..EstimateOptions::default()
        },
        hidden: HiddenChoice::Fixed(2),
        inits: 1,
        train_on_trajectories: TrajectoryChoice::None,
        x0_window: 50,
        on_unconverged_mme: policy,
        ..FitOptions::default()
    }
}

/// The tasks `compute_fit` reported to its progress sink.
fn fit_tasks(
    data: &Dataset,
    opts: &FitOptions,
) -> (mmenn::Result<mmenn::fit::FitOutcome>, Vec<String>) {
    let tasks = Mutex::new(Vec::new());
    let sink = |p: &Progress| tasks.lock().unwrap().push(p.task.clone());
    let out = compute_fit(data, &spec(), None, opts, &sink);
    (out, tasks.into_inner().unwrap())
}

#[test]
fn an_unconverged_estimate_is_refused_before_any_network_is_trained() {
    let data = record();
    let opts = options(1, UnconvergedMme::default());
    assert_eq!(
        FitOptions::default().on_unconverged_mme,
        UnconvergedMme::Refuse
    );
    let (out, tasks) = fit_tasks(&data, &opts);
    let Err(MmennError::MmeNotConverged { report }) = out else {
        panic!("expected MmeNotConverged, got {:?}", out.map(|o| o.summary));
    };
    assert_eq!(report.stage, MmeStage::Training);
    assert_eq!(report.termination, Some(Termination::MaxIterations));
    assert_eq!(report.w_search, None);
    assert!(!report.converged());
    let ratio = report.variance_ratio["theta"];
    assert!(ratio.is_finite() && ratio > 0.0, "{ratio}");
    let message = MmennError::MmeNotConverged {
        report: report.clone(),
    }
    .to_string();
    for part in [
        "training estimate did not converge",
        "iteration limit",
        "theta = ",
        "No network was trained",
        "EstimateOptions::iterations",
    ] {
        assert!(message.contains(part), "{part:?} not in {message}");
    }
    // Fail fast: MME ran, the network sizing sweep never started.
    assert!(tasks.iter().any(|t| t == "MME estimate"), "{tasks:?}");
    assert!(
        !tasks.iter().any(|t| t.contains("network")),
        "a network was trained: {tasks:?}"
    );
}

#[test]
fn the_warn_policy_builds_the_hybrid_and_says_mme_did_not_converge() {
    let data = record();
    let (out, tasks) = fit_tasks(&data, &options(1, UnconvergedMme::Warn));
    let outcome = out.unwrap();
    assert!(tasks.iter().any(|t| t.contains("network")), "{tasks:?}");
    assert!(!outcome.mme_converged());
    let s = &outcome.summary;
    assert_eq!(s.mme_termination, Some(Termination::MaxIterations));
    assert_eq!(s.mme_estimates.len(), 1);
    assert_eq!(s.mme_estimates[0].stage, MmeStage::Training);
    assert_eq!(
        s.mme_estimates[0].termination,
        Some(Termination::MaxIterations)
    );
    assert_eq!(s.unconverged_mme().len(), 1);
    // `summary.json` carries it, typed.
    let json = serde_json::to_value(s).unwrap();
    assert_eq!(
        json["mme_estimates"][0]["termination"],
        serde_json::json!("max_iterations")
    );
    assert_eq!(
        json["mme_estimates"][0]["stage"],
        serde_json::json!("training")
    );
}

#[test]
fn a_converged_estimate_gives_no_warning() {
    let data = record();
    // Validation data that choose too (`ValidationUse::Select`, so MME runs on them):
    // their estimate is checked and recorded as well.
    let opts = FitOptions {
        validation_use: mmenn::fit::ValidationUse::Select,
        ..options(
            IterationOptions::default().max_iterations,
            UnconvergedMme::Refuse,
        )
    };
    let outcome = compute_fit(
        &data,
        &spec(),
        Some(&data),
        &opts,
        &mmenn::progress::NoProgress,
    )
    .unwrap();
    assert!(outcome.mme_converged());
    let s = &outcome.summary;
    assert!(s.unconverged_mme().is_empty());
    let stages: Vec<MmeStage> = s.mme_estimates.iter().map(|m| m.stage).collect();
    assert_eq!(stages, [MmeStage::Training, MmeStage::Validation]);
    for m in &s.mme_estimates {
        assert_eq!(m.termination, Some(Termination::Converged), "{m}");
        assert!(m.variance_ratio["theta"].is_finite(), "{m}");
    }
}

/// Under `Warn` with the K-fold guard, every fold's MME estimate that stopped at the
/// iteration limit reaches the summary (and `summary.json`) beside the training estimate,
/// each naming its fold and the piece of the record it ran on: the copy from the guard's
/// fold scores into `FitSummary::mme_estimates` loses none and invents none.
#[test]
fn the_warn_policy_records_every_unconverged_fold_estimate_of_the_k_fold_guard() {
    let data = record();
    let opts = FitOptions {
        guard: mmenn::fit::GuardHeldOut::Folds(4),
        ..options(1, UnconvergedMme::Warn)
    };
    let (out, _) = fit_tasks(&data, &opts);
    let outcome = out.unwrap();
    let s = &outcome.summary;
    assert!(!outcome.mme_converged());
    // The guard ran four folds of 100 samples; the pieces left when a stretch is held out
    // are one for the first and last fold and two for the inner ones.
    let folds = &s.guard.folds;
    assert_eq!(folds.len(), 4);
    let in_folds: Vec<_> = folds
        .iter()
        .flat_map(|f| f.unconverged_mme.iter().cloned())
        .collect();
    assert_eq!(in_folds.len(), 6, "{in_folds:?}");
    let copied: Vec<_> = s
        .mme_estimates
        .iter()
        .filter(|m| m.stage == MmeStage::GuardFold)
        .cloned()
        .collect();
    assert_eq!(copied, in_folds);
    let mut seen = Vec::new();
    for m in &copied {
        assert_eq!(m.termination, Some(Termination::MaxIterations), "{m}");
        let f = m.fold.as_ref().unwrap();
        assert_eq!(f.folds, 4);
        assert_eq!(f.stretch, ((f.index - 1) * 100, f.index * 100));
        seen.push((f.index, f.record.clone()));
    }
    assert_eq!(
        seen,
        [
            (1, "samples 100..400".to_owned()),
            (2, "samples 0..100".to_owned()),
            (2, "samples 200..400".to_owned()),
            (3, "samples 0..200".to_owned()),
            (3, "samples 300..400".to_owned()),
            (4, "samples 0..300".to_owned()),
        ]
    );
    // The training estimate is still the first, and everything unconverged is listed.
    assert_eq!(s.mme_estimates[0].stage, MmeStage::Training);
    assert_eq!(s.unconverged_mme().len(), 7);
    let json = serde_json::to_value(s).unwrap();
    let stages: Vec<&str> = json["mme_estimates"]
        .as_array()
        .unwrap()
        .iter()
        .map(|m| m["stage"].as_str().unwrap())
        .collect();
    assert_eq!(stages.iter().filter(|s| **s == "guard_fold").count(), 6);
}
