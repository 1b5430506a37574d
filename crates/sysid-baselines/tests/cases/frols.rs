//! Sparse polynomial NARX (FROLS) against known truth: a noise-free sparse system of the
//! class (the true terms selected first and kept, coefficients exact), the independent
//! generator's Duffing records (`fixtures/discovery_suite`, scipy RK45), and bad input.

use nalgebra::DMatrix;
use sysid_baselines::{
    BaselineError, FrolsConfig, NarxOrders, PolyNarxModel, PrefixFailure, TermCount, fit_frols,
    frols::FrolsFit,
};
use sysid_core::{Channel, Dataset, Experiment, Model};

use crate::common::series as dataset;

/// A deterministic white-ish input in [−1, 1] (xorshift64*), so every candidate monomial
/// is excited.
fn input(n: usize, seed: u64) -> Vec<f64> {
    let mut s = seed.max(1);
    (0..n)
        .map(|_| {
            s ^= s >> 12;
            s ^= s << 25;
            s ^= s >> 27;
            let v = s.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 11;
            2.0 * (v as f64 / (1u64 << 53) as f64) - 1.0
        })
        .collect()
}

/// `y(k) = 0.02 + 0.5 y(k−1) + 0.3 u(k−1) + 0.1 y(k−1) u(k−1) − 0.05 u(k−2)³`.
fn truth(u: &[f64]) -> Vec<f64> {
    let mut y = vec![0.0; u.len()];
    for k in 2..u.len() {
        y[k] = 0.02 + 0.5 * y[k - 1] + 0.3 * u[k - 1] + 0.1 * y[k - 1] * u[k - 1]
            - 0.05 * u[k - 2].powi(3);
    }
    y
}

/// The true terms as the model names them, with their coefficients.
const TRUE_TERMS: [(&str, f64); 5] = [
    ("1", 0.02),
    ("y(k-1)", 0.5),
    ("u(k-1)", 0.3),
    ("y(k-1)*u(k-1)", 0.1),
    ("u(k-2)^3", -0.05),
];

fn exact_fit(count: TermCount) -> FrolsFit {
    let u = input(800, 7);
    let y = truth(&u);
    fit_frols(&dataset(&u, &y, 1.0), &cubic_config(count)).unwrap()
}

/// The dictionary of the sparse system's class: na = nb = 2, degree 3 in the newest two
/// lags and taps (35 candidates), at most 20 terms.
fn cubic_config(count: TermCount) -> FrolsConfig {
    FrolsConfig {
        orders: NarxOrders {
            na: 2,
            nb: 2,
            nk: 1,
        },
        degree: 3,
        nonlinear_lags: 2,
        max_terms: 20,
        count,
        ..FrolsConfig::default()
    }
}

/// From the 35 monomials of degree ≤ 3 in y(k−1), y(k−2), u(k−1), u(k−2), the first five
/// terms FROLS selects are exactly the true ones (in some order), the selection then stops
/// (nothing is left to explain), AIC and BIC keep all five and nothing else, and the
/// coefficients in the recorded units are the true ones to 1e-8.
#[test]
fn a_sparse_system_of_the_class_is_recovered_term_by_term() {
    for count in [TermCount::Aic, TermCount::Bic] {
        let fit = exact_fit(count);
        assert_eq!(fit.candidates, 35);
        let first: Vec<&str> = fit
            .ranking
            .iter()
            .take(5)
            .map(|r| r.name.as_str())
            .collect();
        let mut sorted = first.clone();
        sorted.sort_unstable();
        let mut want: Vec<&str> = TRUE_TERMS.iter().map(|t| t.0).collect();
        want.sort_unstable();
        assert_eq!(sorted, want, "first five selected: {first:?}");
        assert_eq!(fit.ranking.len(), 5, "{:?}", fit.ranking);
        assert_eq!(fit.n_terms, 5);
        let total: f64 = fit.ranking.iter().map(|r| r.err).sum();
        assert!((total - 1.0).abs() < 1e-12, "ΣERR = {total}");
        for (name, want) in TRUE_TERMS {
            let i = first.iter().position(|n| *n == name).unwrap();
            let got = fit.coefficients[i];
            assert!((got - want).abs() < 1e-8, "{name}: {got} against {want}");
        }
        assert!(fit.one_step_rmse < 1e-10, "{}", fit.one_step_rmse);
    }
    // A new input: the free run of the recovered model is the truth.
    let fit = exact_fit(TermCount::Aic);
    let u2 = input(500, 99);
    let y2 = truth(&u2);
    let sim = fit
        .model
        .simulate(&dataset(&u2, &y2, 1.0).experiments()[0])
        .unwrap();
    let worst = (2..500)
        .map(|k| (sim.outputs[(0, k)] - y2[k]).abs())
        .fold(0.0, f64::max);
    assert!(worst < 1e-8, "largest free-run error {worst:e}");
}

/// With the true structure known, a fixed count of three keeps the three terms FROLS
/// ranked first, and their coefficients are least squares on those columns (not the true
/// values): a prefix model is a refit, not a truncation.
#[test]
fn a_prefix_model_is_least_squares_on_its_terms() {
    let fit = exact_fit(TermCount::Fixed(3));
    assert_eq!(fit.n_terms, 3);
    assert_eq!(fit.model.n_terms(), 3);
    let u = input(800, 7);
    let y = truth(&u);
    let e = &dataset(&u, &y, 1.0).experiments()[0].clone();
    // One-step residual of the 3-term model = sqrt(SSE(3)/N) of the ranking.
    let pred = fit.model.predict(e, 1).unwrap();
    let s = pred.initial_samples;
    let sse: f64 = (s..800)
        .map(|k| (pred.outputs[(0, k)] - y[k]).powi(2))
        .sum();
    assert!(
        (sse - fit.ranking[2].sse).abs() <= 1e-9 * sse,
        "{sse} vs {}",
        fit.ranking[2].sse
    );
    assert!((fit.one_step_rmse - (sse / fit.rows as f64).sqrt()).abs() < 1e-12);
    let full = fit.model_with(5).unwrap();
    assert_eq!(full.n_terms(), 5);
    assert!(fit.model_with(0).is_err() && fit.model_with(6).is_err());
}

/// Scoring rule fixed before the first run (docs/decisions/frols-polynomial-narx.md, rule
/// 5b): on the independent generator's hardening Duffing oscillator (measured with noise),
/// the sparse degree-3 model's validation free-run RMSE is at most half the sparse linear
/// ARX model's of the same lags.
#[test]
fn on_an_independent_duffing_record_the_sparse_cubic_halves_the_free_run_error() {
    let (u, y, dt) = crate::common::read_case("duffing_hardening", "est.csv");
    let train = dataset(&u, &y, dt);
    let fit = |degree| fit_frols(&train, &duffing_config(degree)).unwrap();
    let (lin, cub) = (fit(1), fit(3));
    let (linear, cubic) = (duffing_val_rmse(&lin.model), duffing_val_rmse(&cub.model));
    // Measured 2026-11-28 (2-core VM): linear 1.50e-1 (5 of 7 terms), cubic 2.45e-3 (9 of
    // 37 terms; the dense degree-3 model of the same lags: 4.00e-3).
    assert!(cub.n_terms < cub.candidates, "not sparse");
    assert!(
        cubic <= 0.5 * linear,
        "linear {linear:e} ({} terms), cubic {cubic:e} ({} terms)",
        lin.n_terms,
        cub.n_terms
    );
}

/// The Duffing records' FROLS configuration: na = nb = 3, nk = 1, the given degree, the
/// newest 2 lags in the monomials, AIC count.
fn duffing_config(degree: usize) -> FrolsConfig {
    FrolsConfig {
        orders: NarxOrders {
            na: 3,
            nb: 3,
            nk: 1,
        },
        degree,
        nonlinear_lags: 2,
        ..FrolsConfig::default()
    }
}

/// A model's free-run RMSE over the hardening Duffing validation record after its delay
/// window.
fn duffing_val_rmse(model: &PolyNarxModel) -> f64 {
    case_val_rmse("duffing_hardening", model)
}

/// A model's free-run RMSE over the validation record of discovery-suite case `case` after
/// its delay window.
fn case_val_rmse(case: &str, model: &PolyNarxModel) -> f64 {
    let (uv, yv, dt) = crate::common::read_case(case, "val.csv");
    crate::common::free_run_rmse(model, &dataset(&uv, &yv, dt), &yv)
}

/// The term count by held-out free run on the scipy Duffing record (rule written before
/// the run: docs/decisions/frols-term-count-by-free-run.md, addendum 2). FROLS (AIC) on the
/// first 80 % of est.csv, every prefix run free over the last 20 %, both counts run free
/// over val.csv. The rule asked (a) no more terms than AIC, (b) at most 1.10 × AIC's
/// validation RMSE, (c) at most half the sparse linear model's. (a) and (c) hold; (b) does
/// not: the 400-sample held-out stretch ranks 7 terms best (4.08e-3 against 6.51e-3 for
/// AIC's 9), the 1250-sample validation record the other way (7.15e-3 against 2.66e-3).
/// The finding is asserted as measured, so a change that mends it fails here and must
/// update the decision record.
#[test]
fn the_free_run_count_on_an_independent_duffing_record_keeps_fewer_terms_but_loses_to_aic() {
    let (u, y, dt) = crate::common::read_case("duffing_hardening", "est.csv");
    let cut = u.len() * 4 / 5;
    let fit = fit_frols(&dataset(&u[..cut], &y[..cut], dt), &duffing_config(3)).unwrap();
    let held = dataset(&u[cut..], &y[cut..], dt);
    let scores: Vec<(usize, Option<f64>)> = fit
        .free_run_scores(held.experiments(), 3)
        .unwrap()
        .iter()
        .map(|s| (s.n, s.value()))
        .collect();
    let (n, _) = sysid_baselines::count_by_free_run(&scores, 0.02).expect("an eligible count");
    let by_free_run = duffing_val_rmse(&fit.model_with(n).unwrap());
    let by_aic = duffing_val_rmse(&fit.model);
    let linear = duffing_val_rmse(
        &fit_frols(&dataset(&u[..cut], &y[..cut], dt), &duffing_config(1))
            .unwrap()
            .model,
    );
    let said = format!(
        "free run: {n} terms, {by_free_run:e}; AIC: {} terms, {by_aic:e}; linear {linear:e}; \
         held-out scores {scores:?}",
        fit.n_terms
    );
    assert!(n <= fit.n_terms, "(a) {said}");
    assert!(by_free_run <= 0.5 * linear, "(c) {said}");
    // (b), the finding: the free-run count is more than 1.10 × AIC's on validation.
    assert!(by_free_run > 1.10 * by_aic, "(b) now holds: {said}");
}

/// The number of terms by held-out free run (docs/decisions/
/// frols-term-count-by-free-run.md), rule fixed before the run: on the sparse system
/// measured with output noise (σ = 0.01), FROLS on the first 1000 samples (cap 20), every
/// prefix run free over the last 500, the count chosen keeps every true term and no more
/// terms than AIC keeps, and a count whose free run diverges is never chosen.
#[test]
fn the_free_run_count_keeps_the_true_terms_and_no_more_than_aic() {
    let u = input(1500, 11);
    let clean = truth(&u);
    let noise = input(1500, 23);
    let y: Vec<f64> = clean
        .iter()
        .zip(&noise)
        .map(|(c, e)| c + 0.01 * 3f64.sqrt() * e)
        .collect();
    let fit = fit_frols(
        &dataset(&u[..1000], &y[..1000], 1.0),
        &cubic_config(TermCount::Aic),
    )
    .unwrap();
    let held = dataset(&u[1000..], &y[1000..], 1.0);
    let mut scores: Vec<(usize, Option<f64>)> = (1..=fit.ranking.len())
        .map(|n| {
            let rmse = fit
                .model_with(n)
                .and_then(|m| m.simulate(&held.experiments()[0]))
                .ok()
                .and_then(|sim| {
                    let s = sim.initial_samples;
                    let r = ((s..500)
                        .map(|k| (sim.outputs[(0, k)] - y[1000 + k]).powi(2))
                        .sum::<f64>()
                        / (500 - s) as f64)
                        .sqrt();
                    r.is_finite().then_some(r)
                });
            (n, rmse)
        })
        .collect();
    // The library's scoring is this hand computation.
    let lib = fit.free_run_scores(held.experiments(), 2).unwrap();
    assert_eq!(lib.len(), scores.len());
    for (s, (n, r)) in lib.iter().zip(&scores) {
        assert_eq!((s.n, s.value()), (*n, *r));
    }
    let (n, _) = sysid_baselines::count_by_free_run(&scores, 0.02).expect("an eligible count");
    let kept: Vec<&str> = fit.ranking[..n].iter().map(|r| r.name.as_str()).collect();
    for (name, _) in TRUE_TERMS {
        assert!(
            kept.contains(&name),
            "{name} not among the {n} kept: {kept:?}"
        );
    }
    assert!(n <= fit.n_terms, "free run keeps {n}, AIC {}", fit.n_terms);
    // A count whose free run failed is skipped even if it would be the smallest.
    scores[n - 1].1 = None;
    let (m, _) = sysid_baselines::count_by_free_run(&scores, 0.02).unwrap();
    assert_ne!(m, n);
}

/// `y(k) = 0.6 y(k−1) + 0.5 u(k−1) + 0.4 u(k−2)³`: exactly three terms.
fn three_term_truth(u: &[f64]) -> Vec<f64> {
    let mut y = vec![0.0; u.len()];
    for k in 2..u.len() {
        y[k] = 0.6 * y[k - 1] + 0.5 * u[k - 1] + 0.4 * u[k - 2].powi(3);
    }
    y
}

const THREE_TERMS: [&str; 3] = ["y(k-1)", "u(k-1)", "u(k-2)^3"];

/// `len` samples of the three-term system's input and its output measured with uniform
/// noise of standard deviation `noise`.
fn three_term_record(len: usize, noise: f64) -> (Vec<f64>, Vec<f64>) {
    let u = input(len, 5);
    let e = input(len, 29);
    let y: Vec<f64> = three_term_truth(&u)
        .iter()
        .zip(&e)
        .map(|(c, e)| c + noise * 3f64.sqrt() * e)
        .collect();
    (u, y)
}

/// FROLS (degree 3 in two lags, 35 candidates, cap 20) on the first 1500 samples of the
/// three-term system measured with output noise of σ = `noise`.
fn three_term_fit(noise: f64) -> (FrolsFit, Vec<f64>, Vec<f64>) {
    let (u, y) = three_term_record(2500, noise);
    let fit = fit_frols(
        &dataset(&u[..1500], &y[..1500], 1.0),
        &cubic_config(TermCount::Aic),
    )
    .unwrap();
    (fit, u, y)
}

/// docs/decisions/frols-term-count-by-free-run.md on data where the right count is known:
/// the three-term system measured with output noise (σ = 0.05), FROLS on the first 1500
/// samples, every prefix run free over the last 1000 (measured, noisy). The first three
/// terms ranked are the true ones, every count is eligible there, and the count chosen
/// is 3, while AIC on the one-step residual keeps more and the cap (20) is not chosen.
#[test]
fn held_out_free_run_keeps_the_three_true_terms_where_aic_keeps_more() {
    let (fit, u, y) = three_term_fit(0.05);
    assert_eq!(fit.ranking.len(), 20);
    let mut first: Vec<&str> = fit.ranking[..3].iter().map(|r| r.name.as_str()).collect();
    first.sort_unstable();
    let mut truth = THREE_TERMS.to_vec();
    truth.sort_unstable();
    assert_eq!(first, truth);
    let held = dataset(&u[1500..], &y[1500..], 1.0);
    let scores = fit.free_run_scores(held.experiments(), 10).unwrap();
    assert_eq!(scores.len(), 20);
    let pairs: Vec<(usize, Option<f64>)> = scores.iter().map(|s| (s.n, s.value())).collect();
    assert!(
        pairs
            .iter()
            .enumerate()
            .all(|(i, p)| p.0 == i + 1 && p.1.is_some()),
        "{pairs:?}"
    );
    let (n, rmse) = sysid_baselines::count_by_free_run(&pairs, 0.02).unwrap();
    assert_eq!(n, 3, "{pairs:?}");
    assert_eq!(Some(rmse), pairs[2].1);
    // About the noise level: the three-term model's free run is the truth's.
    assert!(rmse < 1.1 * 0.05, "{rmse}");
    assert!(fit.n_terms > 3, "AIC keeps {}", fit.n_terms);
    // The largest count explains the fitted rows best but is not chosen.
    assert!(fit.ranking[19].sse < fit.ranking[2].sse);
}

/// On a held-out record whose input is 4 times wider than the training input (its output
/// from the noise-free system), the counts with terms fitted to noise really diverge: each
/// such count has no score, its failure names the sample, and it is never chosen; the
/// count chosen is still the true 3.
#[test]
fn a_prefix_that_diverges_on_the_held_out_record_is_not_eligible() {
    let (fit, u, _) = three_term_fit(0.05);
    let wide: Vec<f64> = u[1500..].iter().map(|v| 4.0 * v).collect();
    let y = three_term_truth(&wide);
    let held = dataset(&wide, &y, 1.0);
    let scores = fit.free_run_scores(held.experiments(), 10).unwrap();
    let mut diverged = 0;
    for s in &scores {
        match &s.rmse {
            Ok(v) => assert!(v.is_finite() && s.value() == Some(*v)),
            Err(PrefixFailure::Run(BaselineError::Diverged { sample, .. })) => {
                assert!(*sample > 2 && *sample < 1000, "{sample}");
                assert_eq!(s.value(), None);
                diverged += 1;
            }
            Err(other) => panic!("count {}: {other}", s.n),
        }
    }
    // The over-large counts diverge, the small ones do not.
    assert!(scores[19].value().is_none() && scores[..3].iter().all(|s| s.value().is_some()));
    assert!(diverged >= 10, "{diverged} of 20 diverged");
    let pairs: Vec<(usize, Option<f64>)> = scores.iter().map(|s| (s.n, s.value())).collect();
    let (n, _) = sysid_baselines::count_by_free_run(&pairs, 0.02).unwrap();
    assert_eq!(n, 3, "{pairs:?}");
    // Pooled over two records, each count's score is the RMSE over both: the held-out
    // record twice scores as once, and a count failing on either has no score.
    let two = [held.experiments()[0].clone(), held.experiments()[0].clone()];
    let twice = fit.free_run_scores(&two, 10).unwrap();
    for (a, b) in scores.iter().zip(&twice) {
        match (a.value(), b.value()) {
            (Some(x), Some(y)) => assert!((x - y).abs() <= 1e-12 * x, "{x} vs {y}"),
            (None, None) => {}
            other => panic!("count {}: {other:?}", a.n),
        }
    }
    // A missing measured sample after the skipped ones is left out of the score, not
    // counted as zero error.
    let mut gap = y.clone();
    gap[500] = f64::NAN;
    let gapped = dataset(&wide, &gap, 1.0);
    let with_gap = fit.free_run_scores(gapped.experiments(), 10).unwrap();
    let sim = fit
        .model_with(3)
        .unwrap()
        .simulate(&held.experiments()[0])
        .unwrap();
    let kept: Vec<f64> = (10..1000)
        .filter(|&k| k != 500)
        .map(|k| (sim.outputs[(0, k)] - y[k]).powi(2))
        .collect();
    let by_hand = (kept.iter().sum::<f64>() / kept.len() as f64).sqrt();
    let lib = with_gap[2].value().unwrap();
    assert!(
        (lib - by_hand).abs() <= 1e-12 * by_hand,
        "{lib} vs {by_hand}"
    );
    // Nothing after the skipped samples, or no record: an error, not a score.
    assert!(fit.free_run_scores(&[], 10).is_err());
    let short = dataset(&wide[..10], &y[..10], 1.0);
    assert!(fit.free_run_scores(short.experiments(), 10).is_err());
}

/// Wrong shapes, short or missing records, a constant output, bad settings: typed errors,
/// never a panic; a missing output sample only skips the rows it touches; a free run
/// leaving the limits names its sample.
#[test]
fn bad_input_gives_typed_errors() {
    let u = input(300, 3);
    let y = truth(&u);
    let cfg = FrolsConfig::default();
    // Two outputs.
    let two = Dataset::new(
        vec![Channel::new("u")],
        vec![Channel::new("y"), Channel::new("z")],
        vec![
            Experiment::new(
                0.0,
                1.0,
                DMatrix::from_row_slice(1, 300, &u),
                DMatrix::from_fn(2, 300, |_, k| y[k]),
            )
            .unwrap(),
        ],
    )
    .unwrap();
    assert!(matches!(
        fit_frols(&two, &cfg),
        Err(BaselineError::Dimension { found: 2, .. })
    ));
    // A record no longer than the lag window, and one with fewer rows than the cap.
    assert!(matches!(
        fit_frols(&dataset(&u[..2], &y[..2], 1.0), &cfg),
        Err(BaselineError::LagsExceedData { .. })
    ));
    assert!(matches!(
        fit_frols(&dataset(&u[..20], &y[..20], 1.0), &cfg),
        Err(BaselineError::TooFewRows { .. })
    ));
    // No measured output, and a constant one.
    assert!(matches!(
        fit_frols(&dataset(&u, &[f64::NAN; 300], 1.0), &cfg),
        Err(BaselineError::TooFewRows { .. })
    ));
    let e = fit_frols(&dataset(&u, &[2.5; 300], 1.0), &cfg).unwrap_err();
    assert!(matches!(e, BaselineError::NoVariation { .. }), "{e}");
    // Settings.
    for (bad, field) in [
        (
            FrolsConfig {
                max_terms: 0,
                ..cfg.clone()
            },
            "max_terms",
        ),
        (
            FrolsConfig {
                count: TermCount::Fixed(41),
                ..cfg.clone()
            },
            "count",
        ),
        (
            FrolsConfig {
                degree: 0,
                ..cfg.clone()
            },
            "degree",
        ),
        (
            FrolsConfig {
                divergence_factor: f64::NAN,
                ..cfg.clone()
            },
            "divergence_factor",
        ),
    ] {
        let e = fit_frols(&dataset(&u, &y, 1.0), &bad)
            .unwrap_err()
            .to_string();
        assert!(e.contains(field), "{field}: {e}");
    }
    // A NaN input cannot even make a record.
    assert!(
        Experiment::new(
            0.0,
            1.0,
            DMatrix::from_element(1, 10, f64::NAN),
            DMatrix::zeros(1, 10)
        )
        .is_err()
    );
    // Missing output samples: rows touching them are skipped, the fit is still exact.
    let mut holes = y.clone();
    holes[100] = f64::NAN;
    holes[200] = f64::NAN;
    let fit = fit_frols(&dataset(&u, &holes, 1.0), &cfg).unwrap();
    assert_eq!(fit.skipped_rows, 6);
    assert!(fit.one_step_rmse < 1e-10);
    // Forty times the training amplitude: the cubic leaves the divergence limits.
    let big: Vec<f64> = input(300, 5).iter().map(|v| 40.0 * v).collect();
    let e = fit
        .model
        .simulate(&dataset(&big, &vec![0.0; 300], 1.0).experiments()[0])
        .unwrap_err()
        .to_string();
    assert!(e.contains("diverged at sample"), "{e}");
}

/// A term of the ranking written out (`1`, `y(k-1)`, `y(k-1)^2*u(k-2)`), evaluated at
/// sample `t` of the recorded signals `y` and `u`: the hand computation's own reading of
/// the names, independent of the library's scaled columns.
fn term_at(name: &str, y: &[f64], u: &[f64], t: usize) -> f64 {
    if name == "1" {
        return 1.0;
    }
    name.split('*')
        .map(|factor| {
            let (var, power) = match factor.split_once('^') {
                Some((v, p)) => (v, p.parse::<i32>().unwrap()),
                None => (factor, 1),
            };
            let signal = if var.starts_with('y') { y } else { u };
            let delay: usize = var
                .split_once("(k-")
                .map_or(0, |(_, d)| d.trim_end_matches(')').parse().unwrap());
            signal[t - delay].powi(power)
        })
        .product()
}

/// docs/decisions/frols-count-kfold.md, first test: on a small record (the three-term
/// system with output noise, 403 samples so that the last of the 5 folds takes the
/// remainder, FROLS capped at 8 terms), every count's pooled K-fold score equals a hand
/// computation: per fold, the first `n` terms evaluated from their names on the recorded
/// signals, coefficients by a direct least-squares solve (SVD) on the rows whose lag window
/// t − 2 ..= t misses the fold, a free run over the fold from its first two measured
/// samples, the squared errors after the first 5 samples of every fold pooled.
#[test]
fn kfold_scores_equal_a_hand_computation() {
    let len = 403;
    let u = input(len, 41);
    let e = input(len, 43);
    let y: Vec<f64> = three_term_truth(&u)
        .iter()
        .zip(&e)
        .map(|(c, e)| c + 0.05 * e)
        .collect();
    let data = dataset(&u, &y, 1.0);
    let fit = fit_frols(
        &data,
        &FrolsConfig {
            max_terms: 8,
            ..cubic_config(TermCount::Aic)
        },
    )
    .unwrap();
    assert_eq!(fit.ranking.len(), 8);
    let (folds, skip, lag) = (5, 5, 2);
    let lib = fit.kfold_scores(&data, folds, skip).unwrap();
    assert_eq!(lib.len(), 8);
    let bounds: Vec<(usize, usize)> = (0..folds)
        .map(|f| (f * 80, if f + 1 == folds { len } else { f * 80 + 80 }))
        .collect();
    for (n, score) in (1..=8).zip(&lib) {
        let names: Vec<&str> = fit.ranking[..n].iter().map(|r| r.name.as_str()).collect();
        let (mut sse, mut count) = (0.0, 0);
        for &(a, b) in &bounds {
            let rows: Vec<usize> = (lag..len).filter(|&t| t < a || t - lag >= b).collect();
            let p = DMatrix::from_fn(rows.len(), n, |i, j| term_at(names[j], &y, &u, rows[i]));
            let target = nalgebra::DVector::from_iterator(rows.len(), rows.iter().map(|&t| y[t]));
            let theta = p.svd(true, true).solve(&target, 1e-14).unwrap();
            let mut sim = y[a..b].to_vec();
            let uf = &u[a..b];
            for t in lag..b - a {
                sim[t] = (0..n)
                    .map(|j| theta[j] * term_at(names[j], &sim, uf, t))
                    .sum();
            }
            for t in skip..b - a {
                sse += (sim[t] - y[a + t]).powi(2);
                count += 1;
            }
        }
        let by_hand = (sse / count as f64).sqrt();
        let got = score
            .value()
            .unwrap_or_else(|| panic!("count {n}: {:?}", score.rmse));
        assert_eq!(score.n, n);
        assert!(
            (got - by_hand).abs() <= 1e-9 * by_hand,
            "count {n}: library {got:e}, by hand {by_hand:e}"
        );
    }
    // Bad settings and records: typed errors, not panics.
    let bad = |folds, skip, d: &Dataset| fit.kfold_scores(d, folds, skip).unwrap_err().to_string();
    assert!(bad(1, 5, &data).contains("folds"));
    assert!(bad(5, 1, &data).contains("skip"));
    assert!(bad(5, 80, &data).contains("per K-fold fold"));
    let shorter = dataset(&u[..400], &y[..400], 1.0);
    assert!(bad(5, 5, &shorter).contains("record FROLS ranked on"));
    let two = Dataset::new(
        vec![Channel::new("u")],
        vec![Channel::new("y")],
        vec![data.experiments()[0].clone(), data.experiments()[0].clone()],
    )
    .unwrap();
    assert!(bad(5, 5, &two).contains("experiments of a K-fold record"));
    assert!(bad(403, 2, &data).contains("per K-fold fold"));
}

/// The rule's Duffing test (docs/decisions/frols-count-kfold.md) on discovery-suite case
/// `case`: FROLS (na = nb = 3, nk = 1, degree 3, nl = 2, AIC) on all 2000 samples of
/// est.csv, the K-fold count (5 folds, skip 3, 2 % tolerance) and AIC's count run free over
/// val.csv, and the sparse linear model (degree 1, AIC) on the same samples. Returns
/// (K-fold count, its validation RMSE, AIC's count, AIC's RMSE, linear RMSE, what to say).
fn kfold_on_case(case: &str) -> (usize, f64, usize, f64, f64, String) {
    let (u, y, dt) = crate::common::read_case(case, "est.csv");
    assert_eq!(u.len(), 2000);
    let est = dataset(&u, &y, dt);
    let fit = fit_frols(&est, &duffing_config(3)).unwrap();
    let scores: Vec<(usize, Option<f64>)> = fit
        .kfold_scores(&est, sysid_baselines::KFOLD_FOLDS, 3)
        .unwrap()
        .iter()
        .map(|s| (s.n, s.value()))
        .collect();
    let (n, _) = sysid_baselines::count_by_free_run(&scores, 0.02).expect("an eligible count");
    let by_kfold = case_val_rmse(case, &fit.model_with(n).unwrap());
    let by_aic = case_val_rmse(case, &fit.model);
    let linear = case_val_rmse(case, &fit_frols(&est, &duffing_config(1)).unwrap().model);
    let said = format!(
        "{case}: K-fold {n} terms, {by_kfold:e}; AIC {} terms, {by_aic:e}; linear {linear:e}; \
         pooled scores {scores:?}",
        fit.n_terms
    );
    (n, by_kfold, fit.n_terms, by_aic, linear, said)
}

/// The K-fold count on the three scipy Duffing records of the discovery suite
/// (docs/decisions/frols-count-kfold.md, second test). The rule asked (a) no more terms
/// than AIC, (b) a validation free-run RMSE at most 1.10 × AIC's, (c) at most half the
/// sparse linear model's, on each record. Measured (2026-11-28, recorded in the decision
/// file's outcome): (b) holds on all three (the K-fold count is at or below AIC's error on
/// softening and amplitude damping, 4.5 % above it on hardening); (a) fails on hardening
/// (13 terms against AIC's 9) and on amplitude damping (16 against 10); (c) fails on
/// softening, where no cubic FROLS model of these orders halves the linear model's error
/// (K-fold 5.98e-2, AIC 9.28e-2, linear 6.06e-2). The findings are asserted as measured, so
/// a change that flips any of them fails here and must update the decision record.
#[test]
fn the_kfold_count_on_three_duffing_records_keeps_aics_error_but_not_always_fewer_terms() {
    // (case, (a) holds, (b) holds, (c) holds), as measured.
    for (case, a, b, c) in [
        ("duffing_hardening", false, true, true),
        ("duffing_softening", true, true, false),
        ("duffing_amplitude_damping", false, true, true),
    ] {
        let (n, by_kfold, aic_n, by_aic, linear, said) = kfold_on_case(case);
        let flipped = "flipped: update docs/decisions/frols-count-kfold.md";
        assert_eq!(n <= aic_n, a, "(a) {flipped}; {said}");
        assert_eq!(by_kfold <= 1.10 * by_aic, b, "(b) {flipped}; {said}");
        assert_eq!(by_kfold <= 0.5 * linear, c, "(c) {flipped}; {said}");
    }
}

/// docs/decisions/frols-count-kfold.md, third test: the three-term system (output noise
/// σ = 0.05) whose last fold's input is 4 times wider (its output from the same
/// recursion). Refitted on the other four folds, the counts with terms fitted to noise
/// diverge over the wide fold: each such count has no pooled score, its failure names a
/// sample of that fold, and it is never chosen; the count chosen is the three true terms.
#[test]
fn a_count_whose_free_run_diverges_on_one_fold_is_not_eligible() {
    let len = 2500;
    let u: Vec<f64> = input(len, 5)
        .iter()
        .enumerate()
        .map(|(k, v)| if k >= 2000 { 4.0 * v } else { *v })
        .collect();
    let e = input(len, 29);
    let y: Vec<f64> = three_term_truth(&u)
        .iter()
        .zip(&e)
        .map(|(c, e)| c + 0.05 * 3f64.sqrt() * e)
        .collect();
    let data = dataset(&u, &y, 1.0);
    let fit = fit_frols(&data, &cubic_config(TermCount::Aic)).unwrap();
    let scores = fit.kfold_scores(&data, 5, 10).unwrap();
    let mut diverged = 0;
    for s in &scores {
        match &s.rmse {
            Ok(v) => assert!(v.is_finite() && s.value() == Some(*v)),
            Err(PrefixFailure::Run(BaselineError::Diverged { sample, .. })) => {
                assert!((2000..2500).contains(sample), "count {}: {sample}", s.n);
                assert_eq!(s.value(), None);
                diverged += 1;
            }
            Err(other) => panic!("count {}: {other}", s.n),
        }
    }
    let pairs: Vec<(usize, Option<f64>)> = scores.iter().map(|s| (s.n, s.value())).collect();
    // Measured: counts 9–20 diverge over the wide fold, 1–8 run through every fold.
    assert!(diverged >= 10, "{diverged} of 20 diverged: {pairs:?}");
    assert!(pairs[19].1.is_none() && pairs[..3].iter().all(|p| p.1.is_some()));
    let (n, _) = sysid_baselines::count_by_free_run(&pairs, 0.02).unwrap();
    assert_eq!(n, 3, "{pairs:?}");
    let mut kept: Vec<&str> = fit.ranking[..n].iter().map(|r| r.name.as_str()).collect();
    kept.sort_unstable();
    let mut truth = THREE_TERMS.to_vec();
    truth.sort_unstable();
    assert_eq!(kept, truth, "{pairs:?}");
}

/// `fit_frols_kfold` on the three-term system with output noise (σ = 0.05; 1500
/// samples): the count is the one `count_by_free_run` takes from its own K-fold scores,
/// the model keeps exactly the three true terms (the rule of
/// docs/decisions/frols-count-kfold.md on data whose right count is known), and a bad
/// tolerance is a typed error.
#[test]
fn the_kfold_count_keeps_the_three_true_terms() {
    let (u, y) = three_term_record(1500, 0.05);
    let data = dataset(&u, &y, 1.0);
    let k = sysid_baselines::fit_frols_kfold(&data, &cubic_config(TermCount::Aic), 0.02).unwrap();
    let pairs: Vec<(usize, Option<f64>)> = k.scores.iter().map(|s| (s.n, s.value())).collect();
    let (n, best) = sysid_baselines::count_by_free_run(&pairs, 0.02).unwrap();
    assert_eq!((k.count, k.score), (n, best));
    assert_eq!(k.fit.n_terms, k.count);
    let names: Vec<String> = k.fit.ranking[..k.count]
        .iter()
        .map(|r| r.name.clone())
        .collect();
    let mut sorted = names.clone();
    sorted.sort();
    let mut truth: Vec<String> = THREE_TERMS.iter().map(|s| s.to_string()).collect();
    truth.sort();
    assert_eq!(sorted, truth, "{names:?}");
    let err =
        sysid_baselines::fit_frols_kfold(&data, &cubic_config(TermCount::Aic), -0.1).unwrap_err();
    assert!(
        matches!(
            err,
            BaselineError::InvalidConfig {
                field: "tolerance",
                ..
            }
        ),
        "{err}"
    );
}
