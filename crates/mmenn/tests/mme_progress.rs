//! MME's steps reach the progress sink of the commands that run it: `estimate` (noise
//! search, W trials, final solve as the "MME estimate" task's stage and note) and `fit`'s
//! training estimate (W trials and Gauss–Newton iterations of a model with named terms).
//! The notes are one to one with what the estimate returns, and reporting changes
//! nothing it computes.

use std::path::Path;
use std::sync::Mutex;

use mmenn::estimate::{
    EstimateOptions, WeightChoice, compute_estimate, compute_estimate_with_progress, estimate_spec,
    mme_config,
};
use mmenn::fit::{FitOptions, HiddenChoice, TrajectoryChoice, UnconvergedMme, compute_fit};
use mmenn::mme_core::IterationOptions;
use mmenn::progress::{MME_TASK, Progress};
use mmenn::sysid_core::{Channel, Dataset, Experiment};
use mmenn::{MmennError, ModelSpec};

/// A damped oscillator assumed linear, the noise variance estimated.
const OSCILLATOR: &str = r#"
states = ["x", "v"]
inputs = ["u"]
A = [[0.0, 1.0], [-4.0, -0.4]]
B = [[0.0], [1.0]]
measured = ["x"]
corrected = ["v"]
noise_variance = "auto"
"#;

/// 500 samples at 0.05 s of the oscillator with a cubic spring the model lacks, the
/// position with a deterministic ±0.02 pseudo-noise.
fn oscillator_record() -> Dataset {
    const DT: f64 = 0.05;
    const LEN: usize = 500;
    let u = |t: f64| (0.7 * t).sin() + 0.5 * (1.9 * t).sin();
    let f = |t: f64, x: [f64; 2]| [x[1], -4.0 * x[0] - 0.4 * x[1] - 2.0 * x[0].powi(3) + u(t)];
    let states = crate::truth::rk4_samples(f, [0.5, 0.0], DT, LEN, 10);
    let mut lcg = 777u64;
    let mut outputs = Vec::with_capacity(LEN);
    for x in &states {
        lcg = lcg
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        outputs.push(x[0] + ((lcg >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 0.04);
    }
    let inputs: Vec<f64> = (0..LEN).map(|k| u(k as f64 * DT)).collect();
    let exp = Experiment::new(
        0.0,
        DT,
        nalgebra::DMatrix::from_row_slice(1, LEN, &inputs),
        nalgebra::DMatrix::from_row_slice(1, LEN, &outputs),
    )
    .unwrap();
    Dataset::new(vec![Channel::new("u")], vec![Channel::new("x")], vec![exp]).unwrap()
}

/// Every report's `(task, stage, note)`, in order.
#[derive(Default)]
struct Seen(Mutex<Vec<(String, String, String)>>);

impl Seen {
    fn sink(&self) -> impl Fn(&Progress) + Sync + '_ {
        |p: &Progress| {
            self.0
                .lock()
                .unwrap()
                .push((p.task.clone(), p.stage.clone(), p.note.clone()))
        }
    }
    /// The notes of the MME task in `stage` that start with `prefix`.
    fn notes(reports: &[(String, String, String)], stage: &str, prefix: &str) -> Vec<String> {
        reports
            .iter()
            .filter(|(t, s, n)| t == MME_TASK && s == stage && n.starts_with(prefix))
            .map(|r| r.2.clone())
            .collect()
    }
    /// The W-trial notes of the MME task in `stage` (not the iterations within a trial).
    fn trials(reports: &[(String, String, String)], stage: &str) -> Vec<String> {
        Self::notes(reports, stage, "W trial ")
            .into_iter()
            .filter(|n| n.contains(" of at most 80: ratio "))
            .collect()
    }
}

#[test]
fn estimate_reports_the_noise_search_each_w_trial_and_the_final_solve() {
    let spec = mmenn::model_file::parse_model(Path::new("oscillator.toml"), OSCILLATOR).unwrap();
    let data = oscillator_record();
    let opts = EstimateOptions::default();
    let seen = Seen::default();
    let reported = compute_estimate_with_progress(&data, &spec, &opts, None, &seen.sink()).unwrap();
    let plain = compute_estimate(&data, &spec, &opts, None).unwrap();
    let mut a = reported.output.clone();
    let mut b = plain.output.clone();
    a.estimate.report.phase_seconds.clear();
    b.estimate.report.phase_seconds.clear();
    assert_eq!(format!("{a:?}"), format!("{b:?}"));

    let reports = seen.0.into_inner().unwrap();
    assert!(reports.iter().all(|r| r.0 == MME_TASK), "{reports:?}");
    // The phases in the order they ran, each first seen with an empty note.
    let mut stages: Vec<&str> = reports.iter().map(|r| r.1.as_str()).collect();
    stages.dedup();
    assert_eq!(stages, ["noise-variance search", "W search", "final solve"]);

    // The likelihood search: its evaluations counted up to the report's count.
    let evaluations = Seen::notes(&reports, "noise-variance search", "likelihood evaluation ");
    assert!(!evaluations.is_empty());
    let last = evaluations.last().unwrap();
    let count = plain.output.noise.evaluations;
    assert!(
        last.starts_with(&format!("likelihood evaluation {count}, −2 log L ")),
        "{last} ({count} evaluations)"
    );
    assert!(last.ends_with("(the search has no fixed count)"), "{last}");
    let start = Seen::notes(
        &reports,
        "noise-variance search",
        "covariance-constraint start, W trial 1 of at most 80: ratio ",
    );
    assert_eq!(start.len(), 1, "{reports:?}");

    // One note per W trial of the returned curve, numbered in order, the last one with
    // the ratio the search ended at.
    let trials = Seen::trials(&reports, "W search");
    assert_eq!(trials.len(), plain.output.w_curve.len());
    for (k, note) in trials.iter().enumerate() {
        assert!(
            note.starts_with(&format!("W trial {} of at most 80: ratio ", k + 1))
                && note.ends_with(" (target 1)"),
            "{note}"
        );
    }
    // The ratios told, to the three decimals of a note, are the curve's, the last one
    // where the search ended.
    let ratio_of = |note: &str| -> f64 {
        let after = note.split("ratio ").nth(1).unwrap_or_default();
        after.split(' ').next().unwrap_or_default().parse().unwrap()
    };
    let mut told: Vec<f64> = trials.iter().map(|n| ratio_of(n)).collect();
    let search = plain.output.w_search.as_ref().unwrap();
    assert!(
        (told.last().unwrap() - search.ratio).abs() <= 5e-4,
        "{trials:?} vs {search:?}"
    );
    let mut curve: Vec<f64> = plain.output.w_curve.iter().map(|p| p.ratio).collect();
    told.sort_by(f64::total_cmp);
    curve.sort_by(f64::total_cmp);
    for (t, c) in told.iter().zip(&curve) {
        assert!(
            (t - c).abs() <= 5e-4 * c.abs().max(1.0),
            "{told:?} vs {curve:?}"
        );
    }
    // A linear final solve is one sweep: nothing but its start is reported.
    assert_eq!(reports.last().unwrap().1, "final solve");
    assert_eq!(reports.last().unwrap().2, "");
}

#[test]
fn fits_training_estimate_reports_w_trials_and_gauss_newton_iterations() {
    let spec: ModelSpec = crate::fit_mme_convergence::spec();
    let data = crate::fit_mme_convergence::record();
    // Automatic W, one Gauss–Newton iteration per solve (warm-started, the final solve
    // still converges here).
    let estimate = EstimateOptions {
        w: WeightChoice::Auto,
        iterations: IterationOptions {
            max_iterations: 1,
            ..IterationOptions::default()
        },
        ..EstimateOptions::default()
    };
    let opts = FitOptions {
        estimate: estimate.clone(),
        hidden: HiddenChoice::Fixed(2),
        inits: 1,
        train_on_trajectories: TrajectoryChoice::None,
        on_unconverged_mme: UnconvergedMme::Refuse,
        ..FitOptions::default()
    };
    let seen = Seen::default();
    let out = compute_fit(&data, &spec, None, &opts, &seen.sink());
    assert!(
        !matches!(out, Err(MmennError::MmeNotConverged { .. })),
        "{:?}",
        out.map(|o| o.summary)
    );
    let reports = seen.0.into_inner().unwrap();
    // The same estimate without a sink: as many W-trial notes as its curve has points.
    let direct = estimate_spec(
        &spec,
        &data.clone().with_intersample(spec.intersample),
        &mme_config(&spec, &estimate),
    )
    .unwrap();
    let trials = Seen::trials(&reports, "W search");
    assert_eq!(trials.len(), direct.w_curve.len(), "{trials:?}");
    assert!(trials.len() >= 2, "{trials:?}");
    // Each trial's Gauss–Newton iteration is reported, under the trial it belongs to,
    // with the bound as a fraction.
    for k in 1..=trials.len() {
        let prefix = format!("W trial {k}, Gauss–Newton iteration 1 of at most 1: J ");
        let iterations = Seen::notes(&reports, "W search", &prefix);
        assert_eq!(iterations.len(), 1, "{prefix}: {reports:?}");
    }
    let last = Seen::notes(
        &reports,
        "final solve",
        "Gauss–Newton iteration 1 of at most 1: J ",
    );
    assert_eq!(last.len(), 1, "{reports:?}");
    assert!(last[0].contains("(converged below 1e-10)"), "{last:?}");
}
