//! `calibrate`'s coefficient standard errors against their Monte-Carlo distribution on an
//! independently generated Cascaded Tanks record (`fixtures/calibration_se`, written by
//! its `generate.py` with numpy/scipy only). The rule — plant, noise, realisations,
//! statistics and pass criteria — is that directory's README, committed before the data.

use std::path::PathBuf;

use discovery::{
    Calibration, CalibrationConfig, InitialState, OutputWeights, RefineCandidate, RefineConfig,
    calibrate, refine_by_free_run, simulate_outputs,
};
use nalgebra::DMatrix;
use sysid_core::{Channel, Dataset, Experiment, LinearModel, ModelNames, TermModel, Termination};

/// True `k1, k2, k3, k4` (truth.json; checked against it on loading).
const K: [f64; 4] = [0.05, 0.06, 0.05, 0.035];
/// Calibrated term indices (`k1`, `k4`, `k3`); term 0 (`k2`) is held at the truth (gauge).
const FREE: [usize; 3] = [1, 2, 3];
/// Names of the calibrated coefficients, in `FREE` order.
const NAMES: [&str; 3] = ["k1", "k4", "k3"];
/// Realisations used per case (README: all 100 within the runtime budget).
const REALISATIONS: usize = 100;
/// Factor on every reported SE in the comparison (1; the mutation check set it to 0.8).
const SE_SCALE: f64 = 1.0;

fn dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/calibration_se")
}

fn read(name: &str) -> String {
    std::fs::read_to_string(dir().join(name)).unwrap_or_else(|e| panic!("{name}: {e}"))
}

/// The record: input, noise-free output, σ.
struct Record {
    u: Vec<f64>,
    y: Vec<f64>,
    sigma: f64,
}

fn record() -> Record {
    let (mut u, mut y) = (Vec::new(), Vec::new());
    for line in read("record.csv").lines().skip(1) {
        let v: Vec<f64> = line
            .split(',')
            .map(|s| s.parse().unwrap_or_else(|e| panic!("{s}: {e}")))
            .collect();
        assert!((v[0] - 4.0 * u.len() as f64).abs() < 1e-9, "time {line}");
        u.push(v[1]);
        y.push(v[2]);
    }
    let truth: serde_json::Value =
        serde_json::from_str(&read("truth.json")).unwrap_or_else(|e| panic!("{e}"));
    for (name, k) in ["k1", "k2", "k3", "k4"].iter().zip(K) {
        assert_eq!(truth["coefficients"][name].as_f64(), Some(k), "{name}");
    }
    let sigma = truth["sigma"].as_f64().unwrap_or(f64::NAN);
    assert!(
        sigma > 0.0 && u.len() == 1024,
        "sigma {sigma}, {} samples",
        u.len()
    );
    Record { u, y, sigma }
}

/// Noise realisations in units of σ, one per line.
fn noise(name: &str) -> Vec<Vec<f64>> {
    read(name)
        .lines()
        .take(REALISATIONS)
        .map(|l| {
            l.split(',')
                .map(|s| s.parse().unwrap_or_else(|e| panic!("{s}: {e}")))
                .collect()
        })
        .collect()
}

fn dataset(u: &[f64], y: &[f64]) -> Dataset {
    let n = u.len();
    let exp = Experiment::new(
        0.0,
        4.0,
        DMatrix::from_row_slice(1, n, u),
        DMatrix::from_row_slice(1, n, y),
    )
    .unwrap_or_else(|e| panic!("{e}"));
    Dataset::new(vec![Channel::new("u")], vec![Channel::new("h2")], vec![exp])
        .unwrap_or_else(|e| panic!("{e}"))
}

fn linear() -> LinearModel {
    LinearModel::with_names(
        DMatrix::zeros(2, 2),
        DMatrix::zeros(2, 1),
        DMatrix::from_row_slice(1, 2, &[0.0, 1.0]),
        DMatrix::from_row_slice(2, 1, &[0.0, 1.0]),
        ModelNames {
            states: vec!["h1".into(), "h2".into()],
            inputs: vec!["u".into()],
            outputs: vec!["h2".into()],
            corrections: vec!["h2".into()],
        },
    )
    .unwrap_or_else(|e| panic!("{e}"))
}

const SQRT_H1: &str = "sqrt((h1 + abs(h1))/2)";
const SQRT_H2: &str = "sqrt((h2 + abs(h2))/2)";

/// The tanks as terms: `0: h2 += k2·√h1⁺` (fixed), `1: h1 += −k1·√h1⁺`, `2: h1 += k4·u`,
/// `3: h2 += −k3·√h2⁺`, with the free coefficients `(k1, k4, k3)` given.
fn model(free: [f64; 3]) -> TermModel {
    TermModel::from_specs(
        linear(),
        [
            ("h2", "inflow", SQRT_H1, K[1]),
            ("h1", "outflow", SQRT_H1, -free[0]),
            ("h1", "pump", "u", free[1]),
            ("h2", "outflow", SQRT_H2, -free[2]),
        ],
    )
    .unwrap_or_else(|e| panic!("{e}"))
}

/// True `(k1, k4, k3)`.
const TRUE_FREE: [f64; 3] = [K[0], K[3], K[2]];

fn config(sigma: f64) -> CalibrationConfig {
    CalibrationConfig {
        initial_state: InitialState::Estimate,
        weights: OutputWeights::NoiseVariance(vec![sigma * sigma]),
        terms: Some(FREE.to_vec()),
        ..CalibrationConfig::default()
    }
}

/// One calibrated realisation: `(k1, k4, k3)` (positive), their reported SEs, the
/// refine.rs effective-sample-size ratio `q` of its free-run residual, the cost.
struct Fit {
    theta: [f64; 3],
    se: [f64; 3],
    q: f64,
    cost: f64,
    termination: Termination,
}

/// Free coefficients as positive rates (terms 1 and 3 carry a minus sign).
fn rates(cal: &Calibration) -> [f64; 3] {
    let c = &cal.coefficients_after;
    [-c[1], c[2], -c[3]]
}

/// `q = (1 − ρ₁)/(1 + ρ₁)` of the free-run residual, ρ₁ of the mean-removed residual,
/// clamped as `crates/discovery/src/refine.rs` `residual_neff_ratio` (private) does; the
/// formula is reproduced here, and `refine_matches_reproduced_correction` ties it to the
/// public `refine_by_free_run`.
fn neff_ratio(cal: &Calibration, data: &Dataset, config: &CalibrationConfig) -> f64 {
    let exp = &data.experiments()[0];
    let y = simulate_outputs(
        &cal.model,
        cal.model.linear().c(),
        &cal.x0[0],
        exp,
        &config.integrator,
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let r: Vec<f64> = (0..exp.len())
        .map(|k| exp.outputs()[(0, k)] - y[(0, k)])
        .collect();
    let mean = r.iter().sum::<f64>() / r.len() as f64;
    let den: f64 = r.iter().map(|v| (v - mean).powi(2)).sum();
    let num: f64 = r.windows(2).map(|w| (w[0] - mean) * (w[1] - mean)).sum();
    let rho = (num / den).clamp(-0.99, 0.99);
    ((1.0 - rho) / (1.0 + rho)).clamp(1e-3, 1.0)
}

fn fit(rec: &Record, y: &[f64]) -> (Fit, Calibration, Dataset) {
    let data = dataset(&rec.u, y);
    let start = model(TRUE_FREE.map(|k| 0.7 * k));
    let cfg = config(rec.sigma);
    let cal = calibrate(&start, &data, &[vec![y[0], y[0]]], &cfg)
        .unwrap_or_else(|e| panic!("calibrate: {e}"));
    let se = [
        cal.coefficient_std[1],
        cal.coefficient_std[2],
        cal.coefficient_std[3],
    ];
    let f = Fit {
        theta: rates(&cal),
        se,
        q: neff_ratio(&cal, &data, &cfg),
        cost: cal.cost_after,
        termination: cal.termination,
    };
    (f, cal, data)
}

fn run_case(rec: &Record, file: &str) -> Vec<Fit> {
    noise(file)
        .iter()
        .map(|z| {
            let y: Vec<f64> = rec
                .y
                .iter()
                .zip(z)
                .map(|(y, z)| y + rec.sigma * z)
                .collect();
            fit(rec, &y).0
        })
        .collect()
}

/// Per-coefficient Monte-Carlo comparison of one case.
#[derive(Debug)]
struct Summary {
    mc_sd: [f64; 3],
    median_se: [f64; 3],
    ratio: [f64; 3],
    bias: [f64; 3],
    bias_over_sd: [f64; 3],
    coverage: f64,
}

/// Statistics of the README over `fits`, with each realisation's SE divided by
/// `√q^power` (power 0: as reported; 1: refine.rs's correction).
fn summarise(fits: &[Fit], power: i32) -> Summary {
    let n = fits.len() as f64;
    let mut s = Summary {
        mc_sd: [0.0; 3],
        median_se: [0.0; 3],
        ratio: [0.0; 3],
        bias: [0.0; 3],
        bias_over_sd: [0.0; 3],
        coverage: 0.0,
    };
    let se = |f: &Fit, j: usize| SE_SCALE * f.se[j] / f.q.powi(power).sqrt();
    let mut covered = 0usize;
    for (j, &truth) in TRUE_FREE.iter().enumerate() {
        let mean = fits.iter().map(|f| f.theta[j]).sum::<f64>() / n;
        let var = fits
            .iter()
            .map(|f| (f.theta[j] - mean).powi(2))
            .sum::<f64>()
            / (n - 1.0);
        let mut ses: Vec<f64> = fits.iter().map(|f| se(f, j)).collect();
        ses.sort_by(f64::total_cmp);
        let m = ses.len();
        s.median_se[j] = if m % 2 == 1 {
            ses[m / 2]
        } else {
            0.5 * (ses[m / 2 - 1] + ses[m / 2])
        };
        s.mc_sd[j] = var.sqrt();
        s.ratio[j] = s.median_se[j] / s.mc_sd[j];
        s.bias[j] = mean - truth;
        s.bias_over_sd[j] = s.bias[j] / s.mc_sd[j];
        covered += fits
            .iter()
            .filter(|f| (f.theta[j] - truth).abs() < 2.0 * se(f, j))
            .count();
    }
    s.coverage = covered as f64 / (3.0 * n);
    s
}

/// The README's criteria; the failures, named.
fn failures(s: &Summary) -> Vec<String> {
    let mut out = Vec::new();
    for (j, &name) in NAMES.iter().enumerate() {
        if !(0.8..=1.25).contains(&s.ratio[j]) {
            out.push(format!("{}: median SE / MC sd {:.3}", name, s.ratio[j]));
        }
        if s.bias_over_sd[j].abs() > 0.3 {
            out.push(format!("{}: bias/sd {:.3}", name, s.bias_over_sd[j]));
        }
    }
    if !(0.90..=0.99).contains(&s.coverage) {
        out.push(format!("coverage {:.3}", s.coverage));
    }
    out
}

/// Sanity checks of every realisation: a stationary point, and (white noise) χ²/M near 1.
fn check_fits(fits: &[Fit], cost_band: Option<(f64, f64)>) {
    assert_eq!(fits.len(), REALISATIONS);
    for (r, f) in fits.iter().enumerate() {
        assert!(
            matches!(
                f.termination,
                Termination::Converged | Termination::NoDescent
            ),
            "realisation {r}: {:?}",
            f.termination
        );
        assert!(
            f.se.iter().all(|s| s.is_finite() && *s > 0.0) && f.cost.is_finite(),
            "realisation {r}: se {:?} cost {}",
            f.se,
            f.cost
        );
        if let Some((lo, hi)) = cost_band {
            assert!(
                (lo..=hi).contains(&f.cost),
                "realisation {r}: cost {}",
                f.cost
            );
        }
    }
}

/// The Rust RK4 model reproduces the scipy record: calibrating the noise-free output
/// recovers the truth.
#[test]
fn noise_free_record_recovers_truth() {
    let rec = record();
    let (f, cal, _) = fit(&rec, &rec.y);
    for j in 0..3 {
        assert!(
            (f.theta[j] / TRUE_FREE[j] - 1.0).abs() < 1e-4,
            "{}: {} vs {} (x0 {:?})",
            NAMES[j],
            f.theta[j],
            TRUE_FREE[j],
            cal.x0
        );
    }
    assert!((cal.x0[0][0] - 2.0).abs() < 1e-3 && (cal.x0[0][1] - 3.5).abs() < 1e-3);
}

/// The second valley (post-hoc, README outcome): `k4` and `k3` both ~20 % high, the
/// two linearised time constants swapped. The midpoint between the truth 0.035 and the
/// valley's ~0.042 separates the modes.
fn in_second_valley(f: &Fit) -> bool {
    f.theta[1] > 0.0385
}

fn primary(fits: Vec<Fit>) -> Vec<Fit> {
    fits.into_iter().filter(|f| !in_second_valley(f)).collect()
}

/// `lo ≤ x ≤ hi`, or a message naming `what`.
fn within(what: &str, x: f64, lo: f64, hi: f64, s: &Summary) {
    assert!(
        (lo..=hi).contains(&x),
        "{what} {x:.4} outside [{lo}, {hi}]\n{s:?}"
    );
}

/// Case (a), white noise. Pre-registered criteria on all 100 realisations FAIL (README
/// outcome): 8 realisations settle in the second valley (also from a start at the truth),
/// which inflates the Monte-Carlo spread of `k4` and `k3` ~7-fold; the pinned failure is
/// exactly that. Within the main valley (post-hoc) the reported SEs meet the criteria.
#[test]
fn white_noise_standard_errors_match_monte_carlo() {
    let rec = record();
    let fits = run_case(&rec, "noise_white.csv");
    check_fits(&fits, Some((0.8, 1.2)));
    let second: Vec<usize> = (0..fits.len())
        .filter(|&r| in_second_valley(&fits[r]))
        .collect();
    assert_eq!(second, [25, 35, 37, 65, 79, 80, 89, 97]);
    // Pre-registered, all realisations: observed failures pinned.
    let s = summarise(&fits, 0);
    assert_eq!(
        failures(&s).len(),
        3,
        "k4 ratio, k3 ratio, coverage: {:?}",
        failures(&s)
    );
    within("k1 ratio", s.ratio[0], 0.8, 1.25, &s);
    within("k4 ratio", s.ratio[1], 0.12, 0.16, &s);
    within("k3 ratio", s.ratio[2], 0.13, 0.17, &s);
    within("coverage", s.coverage, 0.86, 0.90, &s);
    // Post-hoc: the main valley alone meets every criterion.
    let p = summarise(&primary(fits), 0);
    let bad = failures(&p);
    assert!(bad.is_empty(), "main valley: {bad:?}\n{p:?}");
}

/// Case (b), AR(1) 0.8 noise. The reported (white-noise) SEs under-cover badly; with
/// refine.rs's correction `SE/√q` the pre-registered criteria on all 100 realisations
/// still FAIL, for the same reason as case (a) (15 realisations in the second valley);
/// within the main valley (post-hoc) the corrected SEs meet them and the raw ones do not.
#[test]
fn ar1_noise_standard_errors_need_the_neff_correction() {
    let rec = record();
    let fits = run_case(&rec, "noise_ar1.csv");
    check_fits(&fits, None);
    let second: Vec<usize> = (0..fits.len())
        .filter(|&r| in_second_valley(&fits[r]))
        .collect();
    assert_eq!(
        second,
        [6, 8, 10, 14, 21, 27, 37, 52, 53, 56, 68, 71, 72, 82, 84]
    );
    for f in &fits {
        assert!((0.08..=0.16).contains(&f.q), "q {} (AR(1) 0.8: 1/9)", f.q);
    }
    // Pre-registered, all realisations: observed behaviour pinned.
    let raw = summarise(&fits, 0);
    within("raw k1 ratio", raw.ratio[0], 0.33, 0.40, &raw);
    within("raw k4 ratio", raw.ratio[1], 0.08, 0.11, &raw);
    within("raw k3 ratio", raw.ratio[2], 0.09, 0.12, &raw);
    within("raw coverage", raw.coverage, 0.33, 0.42, &raw);
    let cor = summarise(&fits, 1);
    within("corrected k1 ratio", cor.ratio[0], 0.8, 1.25, &cor);
    within("corrected k4 ratio", cor.ratio[1], 0.24, 0.31, &cor);
    within("corrected k3 ratio", cor.ratio[2], 0.26, 0.33, &cor);
    within("corrected coverage", cor.coverage, 0.83, 0.88, &cor);
    // Post-hoc, main valley: raw under-covers, corrected meets every criterion.
    let fits = primary(fits);
    let praw = summarise(&fits, 0);
    assert!(
        praw.coverage < 0.5 && praw.ratio.iter().all(|r| *r < 0.45),
        "main valley, raw: {praw:?}"
    );
    let pcor = summarise(&fits, 1);
    let bad = failures(&pcor);
    assert!(bad.is_empty(), "main valley, corrected: {bad:?}\n{pcor:?}");
}

/// The reproduced correction is the one `refine_by_free_run` applies: its
/// `Refinement::coefficient_std` for the three terms matches `SE/√q` within 2 %.
#[test]
fn refine_matches_reproduced_correction() {
    let rec = record();
    let z = noise("noise_ar1.csv");
    for r in [0, 1] {
        let y: Vec<f64> = rec
            .y
            .iter()
            .zip(&z[r])
            .map(|(y, z)| y + rec.sigma * z)
            .collect();
        let (f, cal, data) = fit(&rec, &y);
        let full = model(f.theta);
        let base = TermModel::from_specs(linear(), [("h2", "inflow", SQRT_H1, K[1])])
            .unwrap_or_else(|e| panic!("{e}"));
        let candidates: Vec<RefineCandidate> = FREE
            .iter()
            .map(|&k| {
                let t = &full.terms()[k];
                RefineCandidate {
                    effect: t.effect.clone(),
                    state: if k == 3 { "h2" } else { "h1" }.into(),
                    into: None,
                    term: [SQRT_H1, "u", SQRT_H2][k - 1].into(),
                    coefficient: cal.coefficients_after[k],
                    variables: vec![],
                    parameters: vec![],
                }
            })
            .collect();
        let refined = refine_by_free_run(
            &base,
            &candidates,
            &[0, 1, 2],
            &data,
            &cal.x0,
            &[rec.sigma * rec.sigma],
            &RefineConfig::default(),
        )
        .unwrap_or_else(|e| panic!("refine: {e}"));
        assert_eq!(refined.selected, vec![0, 1, 2], "{:?}", refined.steps);
        for (j, &name) in NAMES.iter().enumerate() {
            let mine = f.se[j] / f.q.sqrt();
            let theirs = refined.coefficient_std[j];
            assert!(
                (theirs / mine - 1.0).abs() < 0.02,
                "realisation {r}, {}: refine {theirs} vs SE/√q {mine} (q {})",
                name,
                f.q
            );
        }
    }
}
