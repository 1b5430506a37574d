//! The acquisition-filter estimate against an independent record, `fixtures/acquisition`:
//! a Duffing oscillator integrated by scipy's DOP853 on a closed-form multisine and recorded
//! through a known filter `H = e^{−i2πfD/fs}·G(f)` by exact circular FFT filtering (no code
//! of this crate made it). `Ã` should be `G`; the scoring rule is the fixture README's,
//! written before this test first ran.

mod noise;

use std::path::PathBuf;

use nalgebra::Complex;
use sysid_core::acquisition::{AcquisitionFilter, AcquisitionOptions, FIR_HALF};

fn fixture(name: &str) -> String {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures/acquisition")
        .join(name);
    std::fs::read_to_string(&path).unwrap_or_else(|e| {
        panic!(
            "cannot read fixture {} ({e}); it is committed, regenerate it with \
             `python3 fixtures/acquisition/generate.py`",
            path.display()
        )
    })
}

/// The record's columns `t,u,y_true_model,y`.
struct Record {
    t: Vec<f64>,
    simulated: Vec<f64>,
    measured: Vec<f64>,
}

/// A committed CSV fixture's rows after its header (which must be `header`), each with
/// `columns` numbers; a bad header, row or number names the file and row.
fn csv_rows(name: &str, header: &str, columns: usize) -> Vec<Vec<f64>> {
    let text = fixture(name);
    let mut lines = text.lines();
    assert_eq!(lines.next().map(str::trim), Some(header), "{name} header");
    lines
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty())
        .map(|(i, line)| {
            let v: Vec<f64> = line
                .split(',')
                .map(|s| {
                    s.trim()
                        .parse()
                        .unwrap_or_else(|e| panic!("{name} row {}: {s:?}: {e}", i + 2))
                })
                .collect();
            assert_eq!(
                v.len(),
                columns,
                "{name} row {}: {} columns",
                i + 2,
                v.len()
            );
            v
        })
        .collect()
}

fn record() -> Record {
    let (mut t, mut simulated, mut measured) = (Vec::new(), Vec::new(), Vec::new());
    for v in csv_rows("record.csv", "t,u,y_true_model,y", 4) {
        t.push(v[0]);
        simulated.push(v[2]);
        measured.push(v[3]);
    }
    Record {
        t,
        simulated,
        measured,
    }
}

/// `truth.json`'s values, read with serde_json; a missing key or a wrong type names it.
trait Truth {
    fn key(&self, key: &str) -> &serde_json::Value;
    fn num(&self) -> f64;
    fn arr(&self) -> &[serde_json::Value];
    fn complex(&self) -> Complex<f64>;
}

impl Truth for serde_json::Value {
    fn key(&self, key: &str) -> &serde_json::Value {
        self.as_object()
            .and_then(|m| m.get(key))
            .unwrap_or_else(|| panic!("truth.json: no key {key:?}"))
    }
    fn num(&self) -> f64 {
        self.as_f64()
            .unwrap_or_else(|| panic!("truth.json: expected a number, found {self}"))
    }
    fn arr(&self) -> &[serde_json::Value] {
        self.as_array()
            .unwrap_or_else(|| panic!("truth.json: expected an array, found {self}"))
    }
    fn complex(&self) -> Complex<f64> {
        let v = self.arr();
        Complex::new(v[0].num(), v[1].num())
    }
}

fn rms(x: impl Iterator<Item = f64>) -> f64 {
    let (mut sum, mut n) = (0.0, 0usize);
    for v in x {
        sum += v * v;
        n += 1;
    }
    (sum / n as f64).sqrt()
}

#[test]
#[allow(clippy::print_stderr)]
fn the_estimate_recovers_a_known_acquisition_filter_from_a_scipy_duffing_record() {
    let truth: serde_json::Value =
        serde_json::from_str(&fixture("truth.json")).expect("truth.json is JSON");
    let rec = record();
    let fs = truth.key("fs_hz").num();
    let n = truth.key("samples").num() as usize;
    assert_eq!(rec.t.len(), n, "record.csv rows");
    let dt = 1.0 / fs;
    assert!((rec.t[1] - rec.t[0] - dt).abs() < 1e-12, "sample interval");

    let o = truth.key("options");
    let options = AcquisitionOptions {
        pass_below_hz: o.key("pass_below_hz").num(),
        first_band_hz: o.key("first_band_hz").num(),
        band_hz: o.key("band_hz").num(),
    };
    let tol = truth.key("tolerance_abs").num();
    let filter = AcquisitionFilter::estimate(&rec.measured, &rec.simulated, dt, &options)
        .expect("estimate on the independent record");

    // Rule 1: every band centred below 180 Hz is estimated; every estimated band is one of
    // the fixture's.
    let expected: Vec<(f64, Complex<f64>)> = truth
        .key("bands")
        .arr()
        .iter()
        .map(|b| (b.key("centre_hz").num(), b.key("mean_g").complex()))
        .collect();
    let mean_at = |c: f64| {
        expected
            .iter()
            .find(|(e, _)| (e - c).abs() < 1e-9)
            .map(|&(_, g)| g)
    };
    for &(c, _) in expected.iter().filter(|(c, _)| *c < 180.0) {
        assert!(
            filter.bands().iter().any(|(e, _)| (e - c).abs() < 1e-9),
            "band centred at {c} Hz left out"
        );
    }

    // Rule 2: every estimated band within `tol` of G's mean over the band's bins.
    let mut worst = (0.0f64, 0.0f64);
    let mut failures = Vec::new();
    for &(c, g) in filter.bands() {
        let mean = mean_at(c).unwrap_or_else(|| panic!("estimated band at {c} Hz not in truth"));
        let err = (g - mean).norm();
        if err > worst.0 {
            worst = (err, c);
        }
        if err > tol {
            failures.push(format!("{c} Hz: {g:.5} vs {mean:.5} (|err| {err:.4})"));
        }
    }
    let below_180 = filter
        .bands()
        .iter()
        .filter(|(c, _)| *c < 180.0)
        .map(|&(c, g)| (g - mean_at(c).unwrap()).norm())
        .fold(0.0, f64::max);
    eprintln!(
        "acquisition: {} bands estimated (last centre {} Hz); largest |Ã − mean G| {:.3e} at \
         {} Hz; below 180 Hz {:.3e}",
        filter.bands().len(),
        filter.bands().last().unwrap().0,
        worst.0,
        worst.1,
        below_180
    );
    assert!(
        failures.is_empty(),
        "bands off by more than {tol}:\n{}",
        failures.join("\n")
    );

    // Rule 3: end to end, away from the ends the FIR holds.
    let ratio_max = truth.key("inverse_residual_ratio_max").num();
    let inner = FIR_HALF..n - FIR_HALF;
    let before = rms(inner.clone().map(|i| rec.measured[i] - rec.simulated[i]));
    let inv = filter.apply_inverse(&rec.measured, dt).unwrap();
    let fwd = filter.apply(&rec.simulated, dt).unwrap();
    let after_inv = rms(inner.clone().map(|i| inv[i] - rec.simulated[i]));
    let after_fwd = rms(inner.map(|i| fwd[i] - rec.measured[i]));
    eprintln!(
        "acquisition: rms(y − S) {before:.4e}; rms(Ã⁻¹y − S) {after_inv:.4e} (ratio {:.4}); \
         rms(ÃS − y) {after_fwd:.4e} (ratio {:.4})",
        after_inv / before,
        after_fwd / before
    );
    assert!(
        after_inv <= ratio_max * before,
        "inverse: ratio {}",
        after_inv / before
    );
    assert!(
        after_fwd <= ratio_max * before,
        "forward: ratio {}",
        after_fwd / before
    );
}
