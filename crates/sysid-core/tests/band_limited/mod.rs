//! The band-limited input reading ([`InterSample::Bl`]) against a truth integrated from
//! the continuous input itself: a lightly damped oscillator driven by a multisine whose
//! components reach 0.3 of the sampling rate, as the Silverbox's excitation does. The truth
//! is a hand-written RK4 at 64 steps per sample on the analytic input (no code of the
//! crate's integrators); the models see only the samples.

use nalgebra::DMatrix;
use sysid_core::{Experiment, Integrator, InterSample, LinearModel, simulate_with};

const FS: f64 = 100.0;
const N: usize = 1200;
/// (frequency as a share of the sampling rate, phase)
const TONES: [(f64, f64); 5] = [
    (0.02, 0.3),
    (0.07, 1.9),
    (0.13, 4.1),
    (0.21, 2.2),
    (0.3, 0.7),
];

fn u(t: f64) -> f64 {
    TONES
        .iter()
        .map(|(nu, ph)| (2.0 * std::f64::consts::PI * nu * FS * t + ph).sin())
        .sum()
}

/// ẋ1 = x2, ẋ2 = −ω²x1 − 2ζω x2 + u, resonance at 0.1 of the sampling rate.
fn abcd() -> (DMatrix<f64>, DMatrix<f64>) {
    let w = 2.0 * std::f64::consts::PI * 0.1 * FS;
    let z = 0.05;
    (
        DMatrix::from_row_slice(2, 2, &[0.0, 1.0, -w * w, -2.0 * z * w]),
        DMatrix::from_row_slice(2, 1, &[0.0, 1.0]),
    )
}

fn truth() -> Vec<f64> {
    let (a, b) = abcd();
    let f = |t: f64, x: [f64; 2]| {
        [
            a[(0, 0)] * x[0] + a[(0, 1)] * x[1] + b[(0, 0)] * u(t),
            a[(1, 0)] * x[0] + a[(1, 1)] * x[1] + b[(1, 0)] * u(t),
        ]
    };
    let sub = 64;
    let h = 1.0 / FS / sub as f64;
    let mut x = [0.0, 0.0];
    let mut out = vec![x[0]];
    for k in 0..N - 1 {
        for j in 0..sub {
            let t = k as f64 / FS + j as f64 * h;
            let k1 = f(t, x);
            let k2 = f(
                t + h / 2.0,
                [x[0] + h / 2.0 * k1[0], x[1] + h / 2.0 * k1[1]],
            );
            let k3 = f(
                t + h / 2.0,
                [x[0] + h / 2.0 * k2[0], x[1] + h / 2.0 * k2[1]],
            );
            let k4 = f(t + h, [x[0] + h * k3[0], x[1] + h * k3[1]]);
            for i in 0..2 {
                x[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
            }
        }
        out.push(x[0]);
    }
    out
}

fn rms(v: impl Iterator<Item = f64>) -> f64 {
    let (s, n) = v.fold((0.0, 0usize), |(s, n), x| (s + x * x, n + 1));
    (s / n as f64).sqrt()
}

/// Decided before the first run: away from the record's ends (the kernel holds the end
/// samples, so the first and last 40 samples are not scored), the band-limited free run
/// is within 1 % of the response's RMS of the truth and at most a tenth of the linear
/// reading's error.
#[test]
fn band_limited_reading_follows_a_multisine_near_a_third_of_the_sampling_rate() {
    let (a, b) = abcd();
    let model = LinearModel::new(
        a,
        b,
        DMatrix::from_row_slice(1, 2, &[1.0, 0.0]),
        DMatrix::zeros(2, 0),
    )
    .unwrap();
    let inputs = DMatrix::from_fn(1, N, |_, k| u(k as f64 / FS));
    let y = truth();
    let run = |hold| {
        let xs = simulate_with(
            &model,
            &[0.0, 0.0],
            0.0,
            1.0 / FS,
            &inputs,
            hold,
            &Integrator::Rk4 { substeps: 8 },
            1e12,
        )
        .unwrap();
        let err = rms((40..N - 40).map(|k| xs[(0, k)] - y[k]));
        (xs, err)
    };
    let (_, bl) = run(InterSample::Bl);
    let (_, foh) = run(InterSample::Foh);
    let size = rms((40..N - 40).map(|k| y[k]));
    assert!(
        bl < 0.01 * size,
        "band-limited error {bl:.3e} of response RMS {size:.3e}"
    );
    assert!(
        bl < 0.1 * foh,
        "band-limited {bl:.3e} against linear {foh:.3e}"
    );
}

/// The record's own path ([`Experiment::step_input`]) reads the same grid the free run
/// uses, and a window reads its parent's grid (not one held at the window's edges).
#[test]
fn windows_read_their_parent_grid() {
    let inputs = DMatrix::from_fn(1, 300, |_, k| u(k as f64 / FS));
    let outputs = DMatrix::zeros(1, 300);
    let exp = Experiment::new(0.0, 1.0 / FS, inputs, outputs)
        .unwrap()
        .with_intersample(InterSample::Bl);
    let win = exp.window(100, 200).unwrap();
    let mut a = [0.0];
    let mut b = [0.0];
    for j in 0..4 {
        for c in [0.0, 0.5, 1.0] {
            let pa = exp.step_input(100, j, 4);
            let pb = win.step_input(0, j, 4);
            assert_eq!(pa.at(c, &mut a), pb.at(c, &mut b));
            // And it is the band-limited value, not the linear one, at mid-interval.
            let t = (100.0 + (j as f64 + c) / 4.0) / FS;
            assert!((a[0] - u(t)).abs() < 5e-3, "{} against {}", a[0], u(t));
        }
    }
    // The first window sample's start differs from a window cut and read on its own.
    let alone = Experiment::new(0.0, 1.0 / FS, win.inputs().clone(), win.outputs().clone())
        .unwrap()
        .with_intersample(InterSample::Bl);
    let (mut c, mut d) = ([0.0], [0.0]);
    let x = alone.step_input(0, 1, 2).at(0.0, &mut c)[0];
    let yv = win.step_input(0, 1, 2).at(0.0, &mut d)[0];
    assert!(
        (x - yv).abs() > 1e-6,
        "a cut record holds its edge: {x} vs {yv}"
    );
}
