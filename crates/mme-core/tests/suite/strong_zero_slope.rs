//! MME through an empty tank: a Torricelli model of two cascaded tanks written with the
//! plain `sqrt(max(h, 0))` flows a model file would hold (no regularising offset). The
//! tanks start empty and stay so until the pump starts, so the measured levels, and the
//! estimate near them, go below 0, where the flow is constant (0). The symbolic slope
//! there is the chain rule's strong zero (`sysid_core::Expr` derivative docs); with the
//! plain rule `da/(2·sqrt(a))` it was 0/0 = NaN and the estimate stopped with an error. The truth
//! comes from a hand-written explicit Euler integrator that shares no code with
//! `sysid-core` or `mme-core`.

use mme_core::{MmeConfig, NoiseSpec, NonlinearModel, WeightSpec, estimate_nonlinear_with_report};
use nalgebra::DMatrix;
use rand::SeedableRng;
use rand::rngs::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use sysid_core::{Dataset, Experiment, Expr, LinearModel, ModelNames, TermModel, Termination};

use super::common::dataset;

/// Upper tank outflow, pump gain, transfer to and outflow of the lower tank (V^½/s,
/// 1/s), about the values fitted to the Cascaded Tanks benchmark.
const K1: f64 = 0.0399;
const K4: f64 = 0.0409;
const K2: f64 = 0.0728;
const K3: f64 = 0.0897;
/// Sample period, s.
const TS: f64 = 4.0;
/// Samples.
const LEN: usize = 200;
/// Samples with the pump off at the start (both tanks empty).
const OFF: usize = 25;
/// Noise on both measured levels, V.
const SIGMA: f64 = 0.02;

/// The flow term, as written in a model file.
const FLOW: &str = "sqrt(max(h, 0))";

/// Pump off for [`OFF`] samples, then levels held for 25 samples from a fixed list.
fn input() -> Vec<f64> {
    let levels = [3.2, 2.6, 3.9, 3.0, 3.6, 2.8, 4.0];
    (0..LEN)
        .map(|k| {
            if k < OFF {
                0.0
            } else {
                levels[((k - OFF) / 25) % levels.len()]
            }
        })
        .collect()
}

/// The true levels by explicit Euler, 400 steps per sample (0.01 s; the slowest time
/// constant is ~100 s), the input held over each sample, from empty tanks. The levels
/// never go below 0 (flows out of an empty tank are 0).
fn truth(u: &[f64]) -> (Vec<f64>, Vec<f64>) {
    let steps = 400;
    let h = TS / steps as f64;
    let (mut h1, mut h2) = (0.0_f64, 0.0_f64);
    let (mut x1, mut x2) = (Vec::with_capacity(LEN), Vec::with_capacity(LEN));
    for &uk in u {
        x1.push(h1);
        x2.push(h2);
        for _ in 0..steps {
            let q1 = h1.max(0.0).sqrt();
            let d1 = -K1 * q1 + K4 * uk;
            let d2 = K2 * q1 - K3 * h2.max(0.0).sqrt();
            h1 += h * d1;
            h2 += h * d2;
        }
    }
    (x1, x2)
}

/// Both levels with N(0, σ²) noise from a seeded stream, and the true levels.
fn data() -> (Dataset, [Vec<f64>; 2]) {
    let u = input();
    let (h1, h2) = truth(&u);
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let normal = Normal::new(0.0, SIGMA).unwrap();
    let y = DMatrix::from_fn(2, LEN, |i, k| [&h1, &h2][i][k] + normal.sample(&mut rng));
    let exp = Experiment::new(0.0, TS, DMatrix::from_row_slice(1, LEN, &u), y).unwrap();
    (dataset(&["u"], &["y1", "y2"], vec![exp]), [h1, h2])
}

/// The assumed model (the truth's structure and coefficients): zero linear part, the
/// flows as terms, both levels measured, corrections on both.
fn model() -> NonlinearModel<TermModel> {
    let names = ModelNames {
        states: vec!["h1".into(), "h2".into()],
        inputs: vec!["u".into()],
        outputs: vec!["y1".into(), "y2".into()],
        corrections: vec!["h1".into(), "h2".into()],
    };
    let linear = LinearModel::with_names(
        DMatrix::zeros(2, 2),
        DMatrix::zeros(2, 1),
        DMatrix::identity(2, 2),
        DMatrix::identity(2, 2),
        names.clone(),
    )
    .unwrap();
    let (f1, f2) = (FLOW.replace('h', "h1"), FLOW.replace('h', "h2"));
    let terms = TermModel::from_specs(
        linear,
        [
            ("h1", "outflow", f1.as_str(), -K1),
            ("h1", "pump", "u", K4),
            ("h2", "inflow", f1.as_str(), K2),
            ("h2", "outflow", f2.as_str(), -K3),
        ],
    )
    .unwrap();
    NonlinearModel::new(
        terms,
        DMatrix::identity(2, 2),
        DMatrix::identity(2, 2),
        names,
    )
    .unwrap()
}

/// The flow's slope below an empty tank is exactly 0, not NaN (what the estimate needs).
#[test]
fn flow_slope_below_empty_is_zero() {
    let e = Expr::parse(FLOW, &["h"]).unwrap();
    let d = e.derivative(0).unwrap();
    for h in [-1.0, -0.03, -1e-9] {
        assert!(d.eval(&[h]) == 0.0, "{d} at {h}: {}", d.eval(&[h]));
    }
    assert!((d.eval(&[4.0]) - 0.25).abs() <= 1e-15, "{d}");
}

/// With the plain chain rule this stopped at once: `NonFiniteModel { time: 0.0, what:
/// "∂f/∂h1", value: NaN }` at the data-based start, whose levels (the first measurements of
/// the empty tanks) are negative.
#[test]
fn estimate_converges_through_empty_tanks() {
    let (data, truth) = data();
    // The records do go below empty: the data-based start and the linearisation meet it.
    let y = data.experiments()[0].outputs();
    assert!(
        y[(0, 0)] < 0.0 || y[(1, 0)] < 0.0,
        "first sample {:?}",
        y.column(0)
    );
    assert!((0..OFF).filter(|&k| y[(1, k)] < 0.0).count() >= 5);
    let config = MmeConfig {
        w: WeightSpec::Scalar(1e3),
        noise_variance: NoiseSpec::Given(vec![SIGMA * SIGMA; 2]),
        ..MmeConfig::default()
    };
    let out = estimate_nonlinear_with_report(&model(), &data, &config).unwrap();
    let est = &out.estimate;
    assert_eq!(
        est.report.termination,
        Some(Termination::Converged),
        "{:?}",
        est.report.iterations
    );
    assert!(est.cost.is_finite(), "cost {}", est.cost);
    // Bound fixed before the first run: the estimated levels within 0.05 V RMS of the
    // truth (2.5 σ; both levels are measured with σ = 0.02 V and the model is exact).
    let states = &est.experiments[0].states;
    for (i, t) in truth.iter().enumerate() {
        let rmse = (states
            .row(i)
            .iter()
            .zip(t)
            .map(|(a, b)| (a - b).powi(2))
            .sum::<f64>()
            / LEN as f64)
            .sqrt();
        assert!(rmse < 0.05, "RMSE of h{} {rmse} V", i + 1);
    }
}
