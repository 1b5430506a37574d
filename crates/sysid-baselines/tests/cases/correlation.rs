//! Correlation analysis against closed forms and simulated processes.

use nalgebra::DMatrix;
use sysid_baselines::{
    CorrelationKind, SuggestionConfig, autocorrelation, cross_correlation, pacf_from_acf,
    partial_autocorrelation, suggest_lags,
};
use sysid_core::{Channel, Confidence, Dataset, Experiment};

use crate::common::white;

/// AR(2) `y_k = 0.75 y_{k−1} − 0.5 y_{k−2} + e_k` (poles of modulus √0.5, stationary):
/// its PACF is `φ11 = a1/(1 − a2) = 0.5`, `φ22 = a2 = −0.5` and 0 beyond (Box & Jenkins).
#[test]
fn pacf_of_ar2_is_significant_at_lags_1_and_2_and_white_beyond() {
    let n = 20_000;
    let burn = 500;
    let e = white(n + burn, 7);
    let mut y = vec![0.0; n + burn];
    for k in 2..n + burn {
        y[k] = 0.75 * y[k - 1] - 0.5 * y[k - 2] + e[k];
    }
    let y = &y[burn..];
    let max_lag = 40;
    let pacf = partial_autocorrelation(&[y], max_lag).unwrap();
    assert_eq!(pacf.kind, CorrelationKind::Partial);
    assert_eq!(pacf.samples, n);
    // Sampling s.d. of a PACF estimate is about 1/√N = 0.007; allow 4 s.d.
    let tol = 4.0 / (n as f64).sqrt();
    assert!((pacf.values[1] - 0.5).abs() < tol, "{}", pacf.values[1]);
    assert!((pacf.values[2] + 0.5).abs() < tol, "{}", pacf.values[2]);
    let outside = pacf.outside(Confidence::P95);
    assert!(outside.contains(&1) && outside.contains(&2));
    // Beyond the true order the 38 estimates at lags 3..=40 are asymptotically
    // independent N(0, 1/N) (Quenouille), so the number outside the 95 % band is
    // Binomial(38, 0.05): mean 1.9, P(X > 6) ≈ 0.3 %. Allow at most 6.
    let beyond = outside.iter().filter(|&&l| l > 2).count();
    assert!(
        beyond <= 6,
        "{beyond} lags beyond 2 outside the 95 % band: {outside:?}"
    );
}

/// On any series, Durbin–Levinson gives `φ11 = r1` and `φ22 = (r2 − r1²)/(1 − r1²)`.
#[test]
fn pacf_lags_1_and_2_match_closed_forms_on_a_short_series() {
    let x = [
        0.3, -1.2, 2.5, 0.7, -0.4, 1.9, -2.2, 0.1, 1.4, -0.8, 0.6, -1.5,
    ];
    let r = sysid_core::acf(&x, 4).unwrap();
    let pacf = partial_autocorrelation(&[&x], 4).unwrap();
    let acf = autocorrelation(&[&x], 4).unwrap();
    assert!((acf.values[1] - r[1]).abs() < 1e-15);
    assert!((pacf.values[1] - r[1]).abs() < 1e-15);
    let closed = (r[2] - r[1] * r[1]) / (1.0 - r[1] * r[1]);
    assert!(
        (pacf.values[2] - closed).abs() < 1e-14,
        "{} vs {closed}",
        pacf.values[2]
    );
    assert_eq!(pacf_from_acf(&r)[2].to_bits(), pacf.values[2].to_bits());
}

/// `y_k = u_{k−4}`: the cross-correlation peaks at lag +4 with value ≈ 1 (exactly 1 up
/// to the 4 samples lost at the ends), also when samples are missing.
#[test]
fn xcf_of_a_delayed_copy_peaks_at_the_delay() {
    let n = 3000;
    let u = white(n, 11);
    let mut y: Vec<f64> = (0..n)
        .map(|k| if k >= 4 { u[k - 4] } else { 0.0 })
        .collect();
    for k in [100, 101, 777, 2500] {
        y[k] = f64::NAN;
    }
    let c = cross_correlation(&[&u], &[&y], 10).unwrap();
    let (imax, vmax) =
        c.values.iter().enumerate().fold(
            (0, f64::MIN),
            |a, (i, v)| if *v > a.1 { (i, *v) } else { a },
        );
    assert_eq!(c.lags[imax], 4);
    // Missing samples and the 4 zero-filled ones cost at most ~10/3000 of the sum.
    assert!(vmax > 0.99, "{vmax}");
    assert_eq!(c.samples, n - 4);
}

/// Pure delay `y_k = u_{k−3} + 0.1 e_k` with white `u`: the only significant positive
/// cross-correlation is at lag 3, so `nb = 3` with `nk = 1` taps `u(k−1..k−3)`.
#[test]
fn lag_suggestion_finds_a_pure_delay() {
    let n = 5000;
    let u = white(n, 21);
    let e = white(n, 22);
    let y: Vec<f64> = (0..n)
        .map(|k| if k >= 3 { u[k - 3] } else { 0.0 } + 0.1 * e[k])
        .collect();
    let data = Dataset::new(
        vec![Channel::new("u")],
        vec![Channel::new("y")],
        vec![
            Experiment::new(
                0.0,
                1.0,
                DMatrix::from_row_slice(1, n, &u),
                DMatrix::from_row_slice(1, n, &y),
            )
            .unwrap(),
        ],
    )
    .unwrap();
    let config = SuggestionConfig {
        confidence: Confidence::P99,
        ..SuggestionConfig::default()
    };
    let s = suggest_lags(&data, &config).unwrap();
    let xcf = &s.xcf[0];
    // r(3) = 1/√(1 + 0.01) = 0.995; every other lag is O(1/√N) = 0.014, below the
    // 99 % band 0.036 except by chance; the seed is fixed.
    assert!((xcf.correlogram.at(3).unwrap() - 1.0 / 1.01_f64.sqrt()).abs() < 0.01);
    assert_eq!(xcf.largest_significant, Some(3));
    assert_eq!(s.orders.nb, 3);
    assert_eq!(s.orders.nk, 1);
    assert_eq!(
        s.orders.na,
        s.pacf[0].largest_significant.unwrap_or(1).max(1)
    );
}
