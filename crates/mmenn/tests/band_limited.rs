//! Shared fixture of the first-order-hold tests: a damped oscillator driven by a
//! band-limited input (four sines, 10–36 samples per period at `DT`), simulated with the
//! input linear between samples by RK4 (20 sub-steps), position measured with noise;
//! written as a data file and a truth file (every state) for `predict`.

use std::path::{Path, PathBuf};

use mmenn::sysid_core::{
    Integrator, InterSample, LinearModel, ModelNames, TermModel, simulate_with,
};
use nalgebra::DMatrix;

/// Sample period, s.
pub const DT: f64 = 0.25;

/// Measurement noise variance of the position.
pub const NOISE_VARIANCE: f64 = 1e-4;

/// `ẍ = −4x − 0.4ẋ + u` (+ what the truth adds on `v`), position measured, `v` corrected.
pub fn oscillator() -> LinearModel {
    let names = ModelNames {
        states: vec!["x".into(), "v".into()],
        inputs: vec!["u".into()],
        outputs: vec!["x".into()],
        corrections: vec!["v".into()],
    };
    LinearModel::with_names(
        DMatrix::from_row_slice(2, 2, &[0.0, 1.0, -4.0, -0.4]),
        DMatrix::from_row_slice(2, 1, &[0.0, 1.0]),
        DMatrix::from_row_slice(1, 2, &[1.0, 0.0]),
        DMatrix::from_row_slice(2, 1, &[0.0, 1.0]),
        names,
    )
    .unwrap()
}

/// A record of `truth` from rest: `dir/name.csv` (t, u, noisy x) and
/// `dir/name_truth.csv` (t, u, x, v without noise). `phase` shifts the input's sines.
pub fn record(
    dir: &Path,
    truth: &TermModel,
    name: &str,
    len: usize,
    phase: f64,
    seed: u64,
) -> (PathBuf, PathBuf) {
    let u = DMatrix::from_fn(1, len, |_, k| {
        let t = k as f64 * DT;
        [(0.7, 0.0), (1.3, 1.1), (1.9, 2.3), (2.6, 0.4)]
            .iter()
            .map(|(w, p)| 0.9 * (w * t + p + phase).sin())
            .sum::<f64>()
    });
    let xs = simulate_with(
        truth,
        &[0.0, 0.0],
        0.0,
        DT,
        &u,
        InterSample::Foh,
        &Integrator::Rk4 { substeps: 20 },
        1e12,
    )
    .unwrap();
    let noise = mmenn::plants::noise::gaussian_noise(&[NOISE_VARIANCE], len, seed, 0).unwrap();
    let y: Vec<f64> = xs
        .row(0)
        .iter()
        .zip(noise.iter())
        .map(|(x, e)| x + e)
        .collect();
    let t: Vec<f64> = (0..len).map(|k| k as f64 * DT).collect();
    let data = dir.join(format!("{name}.csv"));
    let header = ["t", "u", "x"].map(String::from);
    mmenn::data_file::write_csv(&data, &header, &[&t, u.as_slice(), &y]).unwrap();
    let clean = dir.join(format!("{name}_truth.csv"));
    let header = ["t", "u", "x", "v"].map(String::from);
    let (x, v): (Vec<f64>, Vec<f64>) = (
        xs.row(0).iter().copied().collect(),
        xs.row(1).iter().copied().collect(),
    );
    mmenn::data_file::write_csv(&clean, &header, &[&t, u.as_slice(), &x, &v]).unwrap();
    (data, clean)
}

/// The model file of `linear` with inputs `hold` between samples, written to `path`.
pub fn write_spec(path: &Path, linear: &LinearModel, hold: InterSample) {
    use mmenn::model_file::{ModelSpec, NoiseVariance, write_model};
    let spec = ModelSpec {
        linear: linear.clone(),
        noise_variance: NoiseVariance::Given(vec![NOISE_VARIANCE]),
        units: Default::default(),
        terms: vec![],
        intersample: hold,
        parameters: Vec::new(),
        mechanics: None,
        acquisition: None,
        roles: Default::default(),
    };
    write_model(path, &spec).unwrap();
}
