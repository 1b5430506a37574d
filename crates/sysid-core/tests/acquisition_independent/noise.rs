//! The estimate's standard errors against the Monte-Carlo spread of the estimate itself, on
//! the independent record with coloured measurement noise added by numpy
//! (`fixtures/acquisition/generate.py --noise`): one committed realisation of the noisy
//! output, and per band the spread of Ã over 200 realisations. The rule (N1–N4) is the
//! fixture README's "Standard errors on a noisy record", written before the data existed.

use nalgebra::Complex;
use sysid_core::acquisition::{AcquisitionFilter, AcquisitionOptions};

use super::{Truth, csv_rows, fixture, record};

/// N1: Rust's gain and standard error against numpy's on the same committed record.
const TIE_REL: f64 = 1e-6;
/// N2: the median over bands of `se / sd_mc` (one realisation).
const MEDIAN_RATIO: (f64, f64) = (0.90, 1.10);
/// N3: every band's `se / sd_mc` within this factor of one.
const BAND_FACTOR: f64 = 1.5;
/// N4(a): pooled coverage of `|Ã_r − Ã₀| ≤ 2·se_r` over the numpy realisations.
const COVERAGE: (f64, f64) = (0.93, 0.99);
/// N4(b): the median over bands of `mean_r se_r / sd_mc`.
const MEDIAN_MEAN_SE_RATIO: (f64, f64) = (0.95, 1.05);

/// The committed noisy realisation's `y` column (`t,y`), checked against the record's `t`.
fn noisy_output(t: &[f64]) -> Vec<f64> {
    let mut y = Vec::new();
    for (i, v) in csv_rows("record_noisy.csv", "t,y", 2)
        .into_iter()
        .enumerate()
    {
        assert!(
            t.get(i).is_some_and(|&ti| (ti - v[0]).abs() < 1e-12),
            "record_noisy.csv row {}: t = {} is not record.csv's",
            i + 2,
            v[0]
        );
        y.push(v[1]);
    }
    assert_eq!(y.len(), t.len(), "record_noisy.csv rows");
    y
}

fn median(mut v: Vec<f64>) -> f64 {
    assert!(!v.is_empty(), "median of no values");
    v.sort_by(f64::total_cmp);
    let m = v.len() / 2;
    if v.len() % 2 == 1 {
        v[m]
    } else {
        0.5 * (v[m - 1] + v[m])
    }
}

#[test]
fn standard_errors_match_the_monte_carlo_spread_on_a_noisy_scipy_record() {
    let truth: serde_json::Value =
        serde_json::from_str(&fixture("noise_truth.json")).expect("noise_truth.json is JSON");
    let rec = record();
    let y_noisy = noisy_output(&rec.t);
    let n = truth.key("samples").num() as usize;
    assert_eq!(y_noisy.len(), n, "samples");
    let dt = 1.0 / truth.key("fs_hz").num();
    let o = truth.key("options");
    let options = AcquisitionOptions {
        pass_below_hz: o.key("pass_below_hz").num(),
        first_band_hz: o.key("first_band_hz").num(),
        band_hz: o.key("band_hz").num(),
    };
    let realisations = truth.key("noise").key("realisations").num();
    assert!(realisations >= 200.0, "{realisations} realisations");

    let filter = AcquisitionFilter::estimate(&y_noisy, &rec.simulated, dt, &options)
        .expect("estimate on the noisy independent record");
    let reference = truth.key("bands").arr();

    // N1: the same bands, and Rust's gain and se equal numpy's on the committed record.
    let centres: Vec<f64> = filter.bands().iter().map(|b| b.0).collect();
    let expected: Vec<f64> = reference.iter().map(|b| b.key("centre_hz").num()).collect();
    assert_eq!(centres, expected, "kept band centres (Hz)");
    assert_eq!(
        filter.standard_errors().len(),
        reference.len(),
        "standard errors"
    );

    let mut ratios = Vec::new();
    let mut mean_se_ratios = Vec::new();
    let mut covered = 0.0;
    for ((&(c, g), se), b) in filter
        .bands()
        .iter()
        .zip(filter.standard_errors())
        .zip(reference)
    {
        let se = se.unwrap_or_else(|| panic!("band at {c} Hz: no standard error"));
        let g_np: Complex<f64> = b.key("gain_committed").complex();
        let se_np = b.key("se_committed").num();
        assert!(
            (g - g_np).norm() <= TIE_REL * g_np.norm(),
            "band at {c} Hz: Ã {g} against numpy's {g_np} on the same record"
        );
        assert!(
            (se - se_np).abs() <= TIE_REL * se_np,
            "band at {c} Hz: se {se} against numpy's {se_np} on the same record"
        );

        // N3: every band's se against the Monte-Carlo spread of Ã.
        let sd_mc = b.key("sd_mc").num();
        let ratio = se / sd_mc;
        assert!(
            (1.0 / BAND_FACTOR..=BAND_FACTOR).contains(&ratio),
            "band at {c} Hz: se {se:.4e} against the Monte-Carlo sd {sd_mc:.4e} (ratio {ratio:.3}, \
             allowed within a factor {BAND_FACTOR})"
        );
        ratios.push(ratio);
        mean_se_ratios.push(b.key("mean_se").num() / sd_mc);
        let count = b.key("covered").num();
        assert!(
            (0.0..=realisations).contains(&count),
            "band at {c} Hz: covered in {count} of {realisations} realisations"
        );
        covered += count;
    }

    // N2: median calibration on the one committed realisation.
    let m = median(ratios);
    assert!(
        (MEDIAN_RATIO.0..=MEDIAN_RATIO.1).contains(&m),
        "median over {} bands of se / sd_mc = {m:.4}, outside {MEDIAN_RATIO:?}",
        centres.len()
    );

    // N4: the numpy Monte-Carlo facts, which N1 makes facts about this estimator,
    // recomputed from the per-band numbers.
    let coverage = covered / (realisations * centres.len() as f64);
    assert!(
        (coverage - truth.key("coverage").num()).abs() < 1e-12,
        "pooled coverage {coverage} against the recorded {}",
        truth.key("coverage").num()
    );
    assert!(
        (COVERAGE.0..=COVERAGE.1).contains(&coverage),
        "|Ã_r − Ã₀| ≤ 2·se_r in {coverage:.4} of {realisations} realisations × {} bands, \
         outside {COVERAGE:?}",
        centres.len()
    );
    let mm = median(mean_se_ratios);
    assert!(
        (MEDIAN_MEAN_SE_RATIO.0..=MEDIAN_MEAN_SE_RATIO.1).contains(&mm),
        "median over bands of mean se / sd_mc = {mm:.4}, outside {MEDIAN_MEAN_SE_RATIO:?}"
    );
}
