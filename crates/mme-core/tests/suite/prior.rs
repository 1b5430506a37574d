//! The Gaussian prior on the initial state ([`MmeConfig::x0_prior`]).
//!
//! * With every state under a prior, MME is the MAP estimate of a linear-Gaussian
//!   state-space model with `x_0 ~ N(m, P0)`, `d_j ~ N(0, (hW)⁻¹)` per sub-step and
//!   `v_k ~ N(0, R)`, so its states equal the Rauch–Tung–Striebel smoothed means. The
//!   filter, the smoother and the exact discretisation (matrix exponential of the
//!   augmented `[A B E; 0 0 0]`) are written here, sharing no code with `mme-core`.
//! * Limits: a very wide prior is no prior; a very narrow one pins `x̂(t0)` to the mean.
//! * The nonlinear path (iterated linearisation) agrees with the linear one on a linear
//!   model, prior included.
//! * A Torricelli cascade with only the lower level measured: a correct prior on the
//!   upper level improves its estimate over the first part of the record.
//! * Invalid priors are typed errors naming the state.

use mme_core::{
    MmeConfig, MmeError, NoiseSpec, NonlinearModel, StatePrior, WeightSpec, estimate,
    estimate_nonlinear, estimate_with_report,
};
use nalgebra::{DMatrix, DVector};
use sysid_core::{Dataset, Experiment, LinearModel, ModelNames, TermModel};

use super::common::{dataset, gaussian, linear};

const DT: f64 = 0.05;
const LEN: usize = 400;
const SUBSTEPS: usize = 2;
const R: f64 = 0.01;
const W: [f64; 2] = [4.0, 0.5];

/// Damped oscillator, position measured, both states corrected (`W` diagonal, unequal).
fn oscillator() -> LinearModel {
    linear(
        &[0.0, 1.0, -2.0, -0.3],
        &[0.0, 1.0],
        &[1.0, 0.0],
        &[1.0, 0.0, 0.0, 1.0],
        2,
        (&["x", "v"], &["u"], &["y"], &["x", "v"]),
    )
}

/// A record of the oscillator with a different (stiffer) truth, a varying input, noise and
/// three missing samples; the truth starts at (1.5, −0.4).
fn oscillator_data() -> Dataset {
    let u: Vec<f64> = (0..LEN)
        .map(|k| (0.7 * k as f64 * DT).sin() + 0.3)
        .collect();
    let v = gaussian(7, LEN, R.sqrt());
    let (mut x, mut xd) = (1.5_f64, -0.4_f64);
    let fine = 50;
    let h = DT / fine as f64;
    let mut y = Vec::with_capacity(LEN);
    for k in 0..LEN {
        y.push(x + v[k]);
        for _ in 0..fine {
            let a = -2.5 * x - 0.2 * xd + u[k];
            x += h * xd;
            xd += h * a;
        }
    }
    for k in [5, 200, 201] {
        y[k] = f64::NAN;
    }
    let exp = Experiment::new(
        0.0,
        DT,
        DMatrix::from_row_slice(1, LEN, &u),
        DMatrix::from_row_slice(1, LEN, &y),
    )
    .unwrap();
    dataset(&["u"], &["y"], vec![exp])
}

fn config(prior: Vec<StatePrior>) -> MmeConfig {
    MmeConfig {
        w: WeightSpec::Diagonal(W.to_vec()),
        noise_variance: NoiseSpec::Given(vec![R]),
        substeps: Some(SUBSTEPS),
        x0_prior: prior,
        ..MmeConfig::default()
    }
}

/// `(Ad, Bd, Ed)` for a sub-step `h`, from `exp(h·[A B E; 0 0 0])`.
fn discretise(model: &LinearModel, h: f64) -> (DMatrix<f64>, DMatrix<f64>, DMatrix<f64>) {
    let (n, m, q) = (model.n_states(), model.n_inputs(), model.n_corrections());
    let size = n + m + q;
    let mut big = DMatrix::zeros(size, size);
    big.view_mut((0, 0), (n, n)).copy_from(model.a());
    big.view_mut((0, n), (n, m)).copy_from(model.b());
    big.view_mut((0, n + m), (n, q)).copy_from(model.e());
    let ex = (big * h).exp();
    (
        ex.view((0, 0), (n, n)).into_owned(),
        ex.view((0, n), (n, m)).into_owned(),
        ex.view((0, n + m), (n, q)).into_owned(),
    )
}

/// Kalman filter from `x_0 ~ N(m, P0)` on the sub-step grid (measurement updates at the
/// samples, observed ones only), then the RTS smoother; smoothed means at the samples.
fn rts(model: &LinearModel, data: &Dataset, m: &[f64], p0_diag: &[f64]) -> Vec<DVector<f64>> {
    let exp = &data.experiments()[0];
    let h = DT / SUBSTEPS as f64;
    let (ad, bd, ed) = discretise(model, h);
    let w = DMatrix::from_diagonal(&DVector::from_column_slice(&W));
    let q = &ed * (w * h).try_inverse().unwrap() * ed.transpose();
    let c = model.c().clone();
    let steps = (LEN - 1) * SUBSTEPS;
    let mut x = DVector::from_column_slice(m);
    let mut p = DMatrix::from_diagonal(&DVector::from_column_slice(p0_diag));
    let (mut xf, mut pf, mut xp, mut pp) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for j in 0..=steps {
        if j > 0 {
            let k = (j - 1) / SUBSTEPS;
            let u = DVector::from_element(1, exp.inputs()[(0, k)]);
            x = &ad * &x + &bd * u;
            p = &ad * &p * ad.transpose() + &q;
        }
        xp.push(x.clone());
        pp.push(p.clone());
        if j % SUBSTEPS == 0 {
            let y = exp.outputs()[(0, j / SUBSTEPS)];
            if !y.is_nan() {
                let s = (&c * &p * c.transpose())[(0, 0)] + R;
                let gain = &p * c.transpose() / s;
                let innov = y - (&c * &x)[0];
                x += &gain * innov;
                p = &p - &gain * &c * &p;
            }
        }
        xf.push(x.clone());
        pf.push(p.clone());
    }
    let mut xs = xf[steps].clone();
    let mut out = vec![DVector::zeros(2); LEN];
    out[LEN - 1] = xs.clone();
    for j in (0..steps).rev() {
        let g = &pf[j] * ad.transpose() * pp[j + 1].clone().try_inverse().unwrap();
        xs = &xf[j] + g * (&xs - &xp[j + 1]);
        if j % SUBSTEPS == 0 {
            out[j / SUBSTEPS] = xs.clone();
        }
    }
    out
}

fn states_at(est: &sysid_core::MmeEstimate, k: usize) -> DVector<f64> {
    est.experiments[0].states.column(k).into_owned()
}

/// MME with a prior on both states equals the RTS smoother from that prior, at every
/// sample (the prior's mean is far from the truth, so the mean term matters at the start).
#[test]
fn prior_mme_equals_rts_smoother() {
    let model = oscillator();
    let data = oscillator_data();
    let (m, std) = ([0.4, 0.9], [0.3, 0.5]);
    let prior = vec![
        StatePrior::new("x", m[0], std[0]),
        StatePrior::new("v", m[1], std[1]),
    ];
    let est = estimate(&model, &data, &config(prior)).unwrap();
    let smooth = rts(&model, &data, &m, &[std[0] * std[0], std[1] * std[1]]);
    let mut worst = 0.0_f64;
    for (k, s) in smooth.iter().enumerate() {
        worst = worst.max((states_at(&est, k) - s).amax());
    }
    // Both solve the same linear least-squares problem exactly (7e-10 when written: the
    // covariance-form smoother inverts 800 predicted covariances; states are O(1)). 1e-8
    // as for the brute-force comparisons.
    assert!(worst < 1e-8, "largest |MME − RTS| = {worst:e}");
    // The comparison has teeth: without the prior, x̂(t0) differs from the smoother's.
    let free = estimate(&model, &data, &config(Vec::new())).unwrap();
    let gap = (states_at(&free, 0) - &smooth[0]).amax();
    assert!(gap > 1e-2, "prior and no prior agree at t0 to {gap:e}");
    // J includes the prior's share: J(prior) − J(no prior) ≥ 0, and J(prior) is the
    // data misfit + correction cost + (x̂0 − m)ᵀP0⁻¹(x̂0 − m).
    let x0 = states_at(&est, 0);
    let prior_cost: f64 = (0..2).map(|i| ((x0[i] - m[i]) / std[i]).powi(2)).sum();
    assert!(prior_cost > 0.0);
    assert!(est.cost >= free.cost);
}

/// With a prior on one state only, a very wide prior is the diffuse (no-prior) estimate
/// and a very narrow one pins that state's `x̂(t0)` to its mean.
#[test]
fn wide_prior_is_no_prior_and_narrow_prior_pins_the_start() {
    let model = oscillator();
    let data = oscillator_data();
    let free = estimate(&model, &data, &config(Vec::new())).unwrap();
    let wide = estimate(&model, &data, &config(vec![StatePrior::new("v", 3.0, 1e5)])).unwrap();
    let diff = (&wide.experiments[0].states - &free.experiments[0].states).amax();
    // The prior's pull is (m − x̂0)/std² ~ 1e-10 against an information of order 1e2.
    assert!(diff < 1e-8, "wide prior moved the states by {diff:e}");
    let narrow = estimate(
        &model,
        &data,
        &config(vec![StatePrior::new("v", 3.0, 1e-6)]),
    )
    .unwrap();
    let v0 = narrow.experiments[0].states[(1, 0)];
    assert!((v0 - 3.0).abs() < 1e-6, "v̂(t0) = {v0}");
    // …while the free estimate is nowhere near 3 (the truth starts at −0.4).
    assert!((free.experiments[0].states[(1, 0)] - 3.0).abs() > 1.0);
    // The other state stays free: it is not pinned to anything.
    assert!(narrow.experiments[0].states[(0, 0)].is_finite());
}

/// The nonlinear estimator (RK4 sub-steps, iterated linearisation) on the linear model
/// agrees with the exact linear estimator, prior included, to the RK4 discretisation
/// error; and both differ from their no-prior results by far more than that.
#[test]
fn nonlinear_path_applies_the_prior_like_the_linear_path() {
    let model = oscillator();
    let data = oscillator_data();
    let prior = vec![
        StatePrior::new("x", 0.4, 0.3),
        StatePrior::new("v", 0.9, 0.5),
    ];
    let names = ModelNames {
        states: vec!["x".into(), "v".into()],
        inputs: vec!["u".into()],
        outputs: vec!["y".into()],
        corrections: vec!["x".into(), "v".into()],
    };
    let nl =
        NonlinearModel::new(model.clone(), model.c().clone(), model.e().clone(), names).unwrap();
    let lin = estimate(&model, &data, &config(prior.clone())).unwrap();
    let non = estimate_nonlinear(&nl, &data, &config(prior)).unwrap();
    let lin_free = estimate(&model, &data, &config(Vec::new())).unwrap();
    let diff = (&lin.experiments[0].states - &non.experiments[0].states).amax();
    let effect = (&lin.experiments[0].states - &lin_free.experiments[0].states).amax();
    // RK4 with h = 0.025 s on eigenvalues of modulus √2: local error ~ (λh)⁵/120 ~ 1e-10.
    assert!(diff < 1e-6, "nonlinear vs linear with prior: {diff:e}");
    assert!(
        effect > 1e-2,
        "the prior moved the estimate by only {effect:e}"
    );
    assert!(
        (lin.cost - non.cost).abs() < 1e-6 * lin.cost,
        "J {} vs {}",
        lin.cost,
        non.cost
    );
}

// ---- Two cascaded tanks, only the lower level measured ----

use super::start::{K1, K2, K3, K4, model_with as tank_model_with};

const TS: f64 = 4.0;
const TANK_LEN: usize = 250;
const SIGMA: f64 = 0.02;
const H1_0: f64 = 9.0;
const H2_0: f64 = 3.0;

fn tank_rhs(h1: f64, h2: f64, u: f64) -> (f64, f64) {
    let q1 = h1.abs().sqrt();
    (-K1 * q1 + K4 * u, K2 * q1 - K3 * h2.abs().sqrt())
}

/// True levels at every sample: classical RK4 with 200 steps per sample (0.02 s), input
/// held per sample, from (9, 3) V (off equilibrium).
fn tank_truth(u: &[f64]) -> (Vec<f64>, Vec<f64>) {
    let steps = 200;
    let h = TS / steps as f64;
    let (mut a, mut b) = (H1_0, H2_0);
    let (mut x1, mut x2) = (Vec::new(), Vec::new());
    for &uk in u {
        x1.push(a);
        x2.push(b);
        for _ in 0..steps {
            let k1 = tank_rhs(a, b, uk);
            let k2 = tank_rhs(a + 0.5 * h * k1.0, b + 0.5 * h * k1.1, uk);
            let k3 = tank_rhs(a + 0.5 * h * k2.0, b + 0.5 * h * k2.1, uk);
            let k4 = tank_rhs(a + h * k3.0, b + h * k3.1, uk);
            a += h / 6.0 * (k1.0 + 2.0 * k2.0 + 2.0 * k3.0 + k4.0);
            b += h / 6.0 * (k1.1 + 2.0 * k2.1 + 2.0 * k3.1 + k4.1);
        }
    }
    (x1, x2)
}

fn tank_model() -> NonlinearModel<TermModel> {
    tank_model_with(K2)
}

/// The assumed model's transfer coefficient is 20 % low (the model error MME is for) and
/// corrections on both levels are cheap (`W = 1`), so the lower level's data say little
/// about where the upper level started: a correction on `h2` can stand in for the inflow
/// `k2√h1`, and without a prior `ĥ1(0)` lands where the biased model's fit puts it (about
/// 9 V off when written). A prior `h1(0) ~ N(9.3, 0.5²)` (truth 9) must make the upper
/// level's estimate over the first 40 samples (160 s, about one upper-tank time constant)
/// clearly better. The truth is integrated by a hand-written RK4 at 0.02 s, not MME's own
/// sub-steps.
#[test]
fn prior_on_the_unmeasured_tank_level_improves_its_start() {
    let levels = [3.2, 2.6, 3.9, 3.0, 3.6, 2.8, 4.0, 3.3, 2.5, 3.7];
    let u: Vec<f64> = (0..TANK_LEN)
        .map(|k| levels[(k / 25) % levels.len()])
        .collect();
    let (h1, h2) = tank_truth(&u);
    let v = gaussian(43, TANK_LEN, SIGMA);
    let y = DMatrix::from_fn(1, TANK_LEN, |_, k| h2[k] + v[k]);
    let exp = Experiment::new(0.0, TS, DMatrix::from_row_slice(1, TANK_LEN, &u), y).unwrap();
    let data = dataset(&["u"], &["y"], vec![exp]);
    let config = |prior: Vec<StatePrior>| MmeConfig {
        w: WeightSpec::Scalar(1.0),
        noise_variance: NoiseSpec::Given(vec![SIGMA * SIGMA]),
        x0_prior: prior,
        ..MmeConfig::default()
    };
    let model = tank_model_with(0.8 * K2);
    let rms_first = |est: &sysid_core::MmeEstimate| {
        let x1 = est.experiments[0].states.row(0);
        let window = 40;
        ((0..window).map(|k| (x1[k] - h1[k]).powi(2)).sum::<f64>() / window as f64).sqrt()
    };
    let free = estimate_nonlinear(&model, &data, &config(Vec::new())).unwrap();
    let with = estimate_nonlinear(
        &model,
        &data,
        &config(vec![StatePrior::new("h1", 9.3, 0.5)]),
    )
    .unwrap();
    let (e_free, e_with) = (rms_first(&free), rms_first(&with));
    let start_free = (free.experiments[0].states[(0, 0)] - H1_0).abs();
    let start_with = (with.experiments[0].states[(0, 0)] - H1_0).abs();
    assert!(
        e_with < 0.5 * e_free,
        "RMS of ĥ1 over the first 40 samples: with prior {e_with}, without {e_free}"
    );
    // Without the prior the start is several volts off (≈ 8.9 V when written); with it,
    // within the prior's std of the truth.
    assert!(
        start_with < 0.5 && start_free > 2.0,
        "|ĥ1(0) − 9|: with prior {start_with}, without {start_free}"
    );
}

/// Invalid priors are typed errors naming the state, from both estimators.
#[test]
fn invalid_priors_are_typed_errors() {
    let model = oscillator();
    let data = oscillator_data();
    let err = |p: StatePrior| estimate_with_report(&model, &data, &config(vec![p])).unwrap_err();
    assert!(matches!(
        err(StatePrior::new("v", 0.0, -1.0)),
        MmeError::InvalidPrior { ref state, field: "std", .. } if state == "v"
    ));
    assert!(matches!(
        err(StatePrior::new("x", f64::NAN, 1.0)),
        MmeError::InvalidPrior { ref state, field: "mean", .. } if state == "x"
    ));
    let unknown = err(StatePrior::new("h9", 0.0, 1.0));
    assert!(matches!(unknown, MmeError::UnknownState { ref name, .. } if name == "h9"));
    assert!(unknown.to_string().contains("'h9'"), "{unknown}");
    let nl = tank_model();
    let tank_data = {
        let exp = Experiment::new(
            0.0,
            TS,
            DMatrix::from_element(1, 10, 3.0),
            DMatrix::from_element(1, 10, 3.0),
        )
        .unwrap();
        dataset(&["u"], &["y"], vec![exp])
    };
    let bad = MmeConfig {
        x0_prior: vec![StatePrior::new("h1", 5.0, f64::NAN)],
        ..config(Vec::new())
    };
    assert!(matches!(
        estimate_nonlinear(&nl, &tank_data, &bad),
        Err(MmeError::InvalidPrior { ref state, field: "std", .. }) if state == "h1"
    ));
}
