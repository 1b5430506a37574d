//! Analytic limits of the MME problem: W → ∞ gives the best-fitting free response of the
//! assumed model (d̂ → 0); W → 0 interpolates the measurements (residuals → 0).

use mme_core::{MmeConfig, NoiseSpec, WeightSpec, estimate};
use nalgebra::{DMatrix, DVector};
use sysid_core::{Dataset, Experiment, LinearModel, MmeEstimate};

use super::common::{dataset, gaussian, linear};

fn model() -> LinearModel {
    linear(
        &[0.0, 1.0, -2.0, -0.3],
        &[0.0, 1.0],
        &[1.0, 0.0],
        &[0.0, 1.0],
        2,
        (&["x", "v"], &["u"], &["x"], &["d"]),
    )
}

/// 300 samples at 0.05 s of a signal the model cannot follow exactly, with gaps.
fn data() -> Dataset {
    let len = 300;
    let noise = gaussian(11, len, 0.05);
    let mut y = DMatrix::from_fn(1, len, |_, k| {
        let t = k as f64 * 0.05;
        (1.1 * t).sin() * (-0.05 * t).exp() + 0.2 * (3.0 * t).cos() + noise[k]
    });
    for k in [5, 6, 100, 299] {
        y[(0, k)] = f64::NAN;
    }
    let u = DMatrix::from_fn(1, len, |_, k| (0.4 * k as f64 * 0.05).sin());
    dataset(
        &["u"],
        &["x"],
        vec![Experiment::new(0.0, 0.05, u, y).unwrap()],
    )
}

fn run(w: f64) -> MmeEstimate {
    let config = MmeConfig {
        w: WeightSpec::Scalar(w),
        noise_variance: NoiseSpec::Given(vec![0.0025]),
        substeps: Some(2),
        ..MmeConfig::default()
    };
    estimate(&model(), &data(), &config).unwrap()
}

/// The free response with the least squared output error: `x_k = M_k x0 + m_k`
/// (exact ZOH over two sub-steps, `d = 0`), `x0` by least squares on observed samples.
fn free_response_fit(model: &LinearModel, data: &Dataset) -> DMatrix<f64> {
    let exp = &data.experiments()[0];
    let z = model.discretize(exp.dt() / 2.0).unwrap();
    let len = exp.len();
    let mut mk = DMatrix::<f64>::identity(2, 2);
    let mut vk = DVector::<f64>::zeros(2);
    let mut basis = Vec::with_capacity(len);
    for k in 0..len {
        basis.push((mk.clone(), vk.clone()));
        let u = DVector::from_element(1, exp.inputs()[(0, k)]);
        for _ in 0..2 {
            mk = &z.ad * &mk;
            vk = &z.ad * &vk + &z.bd * &u;
        }
    }
    let obs: Vec<usize> = (0..len)
        .filter(|&k| !exp.outputs()[(0, k)].is_nan())
        .collect();
    let a = DMatrix::from_fn(obs.len(), 2, |r, c| (model.c() * &basis[obs[r]].0)[(0, c)]);
    let b = DVector::from_iterator(
        obs.len(),
        obs.iter()
            .map(|&k| exp.outputs()[(0, k)] - (model.c() * &basis[k].1)[0]),
    );
    let x0 = a.svd(true, true).solve(&b, 1e-14).unwrap();
    DMatrix::from_fn(2, len, |i, k| (&basis[k].0 * &x0 + &basis[k].1)[i])
}

#[test]
fn large_w_gives_the_best_fitting_free_response() {
    let fit = free_response_fit(&model(), &data());
    let dev = |w: f64| {
        let est = run(w);
        let e = &est.experiments[0];
        ((&e.states - &fit).norm() / fit.norm(), e.corrections.amax())
    };
    let (dev_a, d_a) = dev(1e8);
    let (dev_b, d_b) = dev(1e10);
    // First-order perturbation in 1/W: both the state deviation and d̂ shrink 100× when W
    // grows 100× (ratio 100 ± 10 % allows the second-order term), and at W = 1e10 the
    // estimate is the free response to 1e-5.
    assert!(
        (90.0..110.0).contains(&(dev_a / dev_b)),
        "state deviation ratio {}",
        dev_a / dev_b
    );
    assert!(
        (90.0..110.0).contains(&(d_a / d_b)),
        "d ratio {}",
        d_a / d_b
    );
    assert!(dev_b < 1e-5, "deviation from the free-response fit {dev_b}");
}

#[test]
fn small_w_interpolates_the_measurements() {
    let data = data();
    let ratio = |w: f64| {
        let est = run(w);
        est.residual_variance[0]
            / data.experiments()[0]
                .outputs()
                .iter()
                .filter(|v| !v.is_nan())
                .map(|v| v * v)
                .sum::<f64>()
    };
    let (r6, r8) = (ratio(1e-6), ratio(1e-8));
    // Residuals are O(W) as W → 0, so their mean square falls ~10⁴× per 100× in W.
    assert!(
        r8 < 1e-10,
        "residual mean square relative to the signal {r8}"
    );
    assert!(r6 / r8 > 1e3, "residuals do not vanish with W: {r6} → {r8}");
}
