//! Inputs interpolated between samples (first-order hold): on noise-free data simulated
//! from the assumed model itself with a band-limited input, MME marked `Foh` finds
//! `d̂ ≈ 0` and the true states, while the same record marked `Zoh` (input held, half a
//! sample late) needs a clearly non-zero `d̂`.

use mme_core::{MmeConfig, NoiseSpec, WeightSpec, estimate};
use nalgebra::DMatrix;
use sysid_core::{Experiment, Integrator, InterSample, simulate_with};

use super::common::{assert_hold_margins, dataset, linear, row};

fn rms(v: &[f64]) -> f64 {
    (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt()
}

/// A multisine of 12 tones from 0.5 to 11 Hz (Schroeder phases), unit amplitude each.
pub fn multisine(len: usize, dt: f64) -> DMatrix<f64> {
    DMatrix::from_fn(1, len, |_, k| {
        let t = k as f64 * dt;
        (1..=12)
            .map(|i| {
                let f = 0.5 + (i - 1) as f64 * (10.5 / 11.0);
                let phase = -std::f64::consts::PI * (i * (i - 1)) as f64 / 12.0;
                (2.0 * std::f64::consts::PI * f * t + phase).sin()
            })
            .sum()
    })
}

#[test]
fn first_order_hold_record_of_the_assumed_linear_model_needs_no_correction() {
    // Lightly damped resonance at 6 Hz sampled at 50 Hz (≈ 8 samples per period, the
    // Silverbox ratio), forced by tones up to 11 Hz.
    let (dt, len) = (0.02, 1001);
    let w0 = 2.0 * std::f64::consts::PI * 6.0;
    let model = linear(
        &[0.0, 1.0, -w0 * w0, -2.0 * 0.05 * w0],
        &[0.0, 50.0],
        &[1.0, 0.0],
        &[0.0, 1.0],
        2,
        (&["x", "v"], &["u"], &["x"], &["d"]),
    );
    let u = multisine(len, dt);
    let x0 = [0.01, 0.0];
    let truth = simulate_with(
        &model,
        &x0,
        0.0,
        dt,
        &u,
        InterSample::Foh,
        &Integrator::Rk4 { substeps: 40 },
        1e9,
    )
    .unwrap();
    let y = DMatrix::from_fn(1, len, |_, k| truth[(0, k)]);
    let run = |hold: InterSample| {
        let data = dataset(
            &["u"],
            &["x"],
            vec![
                Experiment::new(0.0, dt, u.clone(), y.clone())
                    .unwrap()
                    .with_intersample(hold),
            ],
        );
        let config = MmeConfig {
            w: WeightSpec::Scalar(1e-2),
            noise_variance: NoiseSpec::Given(vec![1e-8]),
            ..MmeConfig::default()
        };
        estimate(&model, &data, &config).unwrap()
    };
    let foh = run(InterSample::Foh);
    let zoh = run(InterSample::Zoh);
    let d_foh = rms(&row(&foh.experiments[0].corrections, 0));
    let d_zoh = rms(&row(&zoh.experiments[0].corrections, 0));
    assert_eq!(foh.experiments[0].substeps, 8);
    let states = &foh.experiments[0].states;
    let ex = rms(&(0..len)
        .map(|k| states[(0, k)] - truth[(0, k)])
        .collect::<Vec<_>>());
    let ev = rms(&(0..len)
        .map(|k| states[(1, k)] - truth[(1, k)])
        .collect::<Vec<_>>());
    let sx = rms(&row(&truth, 0));
    let sv = rms(&row(&truth, 1));
    // Measured: d̂ RMS 8.1e-7 (Foh; what is left is the RK4 error of the truth, 40
    // sub-steps) against 46.6 (Zoh: the held input lags the multisine by half a sample,
    // and the correction has to supply B·(u(t) − u_k), of the order of the forcing
    // 50·rms(u) ≈ 120 times a phase error of ω·dt/2). Margins: d̂ below 1e-6 of the
    // forcing, and at least 1e4 below the held-input d̂.
    let forcing = 50.0 * rms(&row(&u, 0));
    assert_hold_margins(d_foh, d_zoh, forcing);
    // States: measured RMS errors 3.4e-15 (x, scale 0.23) and 1.0e-8 (v, scale 8.6).
    assert!(ex < 1e-9 * sx, "x RMS error {ex} vs {sx}");
    assert!(ev < 1e-7 * sv, "v RMS error {ev} vs {sv}");
}
