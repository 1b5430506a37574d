//! The nonlinear estimator (iterated linearisation): exactness on a linear model,
//! stationarity of the true cost, an exact pendulum model, and the automatic W.

use mme_core::{
    MmeConfig, NoiseSpec, NonlinearModel, StartTrajectory, WeightSpec, estimate,
    estimate_nonlinear_with_report, estimate_with_report,
};
use nalgebra::DMatrix;
use sysid_core::{Dataset, Dynamics, Experiment, Integrator, ModelNames, Termination, simulate};

use super::common::{assert_hold_margins, dataset, gaussian, linear, row};

/// Point-mass pendulum with pivot acceleration input (SPEC §3):
/// `θ̈ = −(g/l) sin θ − b θ̇ − (1/l) cos θ · u`, g = 9.81, l = 1, b = `damping`.
#[derive(Clone, Copy)]
struct Pendulum {
    damping: f64,
}

impl Dynamics for Pendulum {
    fn n_states(&self) -> usize {
        2
    }
    fn n_inputs(&self) -> usize {
        1
    }
    fn rhs(&self, _t: f64, x: &[f64], u: &[f64], dx: &mut [f64]) {
        dx[0] = x[1];
        dx[1] = -9.81 * x[0].sin() - self.damping * x[1] - x[0].cos() * u[0];
    }
    fn jacobians(&self, _t: f64, x: &[f64], u: &[f64], a: &mut DMatrix<f64>, b: &mut DMatrix<f64>) {
        a.copy_from_slice(&[
            0.0,
            -9.81 * x[0].cos() + x[0].sin() * u[0],
            1.0,
            -self.damping,
        ]);
        b.copy_from_slice(&[0.0, -x[0].cos()]);
    }
}

fn names() -> ModelNames {
    let v = |s: &[&str]| s.iter().map(|x| x.to_string()).collect();
    ModelNames {
        states: v(&["theta", "omega"]),
        inputs: v(&["u"]),
        outputs: v(&["theta"]),
        corrections: v(&["d"]),
    }
}

fn pendulum_model(damping: f64) -> NonlinearModel<Pendulum> {
    NonlinearModel::new(
        Pendulum { damping },
        DMatrix::from_row_slice(1, 2, &[1.0, 0.0]),
        DMatrix::from_row_slice(2, 1, &[0.0, 1.0]),
        names(),
    )
    .unwrap()
}

/// Pendulum data: θ(0) = 0.8 rad, u = 2 sin(1.5 t), θ measured with N(0, σ²).
fn pendulum_data(len: usize, dt: f64, sigma: f64, seed: u64) -> (Dataset, DMatrix<f64>) {
    let u = DMatrix::from_fn(1, len, |_, k| 2.0 * (1.5 * k as f64 * dt).sin());
    let truth = simulate(
        &Pendulum { damping: 0.3 },
        &[0.8, 0.0],
        0.0,
        dt,
        &u,
        &Integrator::Rk4 { substeps: 10 },
        1e9,
    )
    .unwrap();
    let v = gaussian(seed, len, sigma);
    let y = DMatrix::from_fn(1, len, |_, k| truth[(0, k)] + v[k]);
    (
        dataset(
            &["u"],
            &["theta"],
            vec![Experiment::new(0.0, dt, u, y).unwrap()],
        ),
        truth,
    )
}

fn rms(v: &[f64]) -> f64 {
    (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt()
}

#[test]
fn linear_dynamics_reproduce_the_linear_estimator() {
    let lin = linear(
        &[0.0, 1.0, -2.0, -0.3],
        &[0.0, 1.0],
        &[1.0, 0.0],
        &[0.0, 1.0],
        2,
        (&["theta", "omega"], &["u"], &["theta"], &["d"]),
    );
    let (data, _) = pendulum_data(300, 0.05, 0.02, 3);
    let config = MmeConfig {
        w: WeightSpec::Scalar(2.0),
        noise_variance: NoiseSpec::Given(vec![4e-4]),
        substeps: Some(2),
        ..MmeConfig::default()
    };
    let exact = estimate(&lin, &data, &config).unwrap();
    let model =
        NonlinearModel::new(lin.clone(), lin.c().clone(), lin.e().clone(), names()).unwrap();
    let out = estimate_nonlinear_with_report(&model, &data, &config).unwrap();
    let got = &out.estimate;
    // One Gauss–Newton step solves a linear problem; the second only confirms it.
    assert_eq!(got.report.termination, Some(Termination::Converged));
    assert!(
        got.report.iterations.len() <= 2,
        "{:?}",
        got.report.iterations
    );
    // RK4 over h = 0.025 s differs from the exact ZOH map by ~(ωh)⁵/120 ≈ 1e-10 per step.
    let rel = |a: &DMatrix<f64>, b: &DMatrix<f64>| (a - b).norm() / b.norm();
    let (ge, ee) = (&got.experiments[0], &exact.experiments[0]);
    assert!(
        rel(&ge.states, &ee.states) < 1e-6,
        "states {}",
        rel(&ge.states, &ee.states)
    );
    assert!(
        rel(&ge.corrections, &ee.corrections) < 1e-6,
        "d {}",
        rel(&ge.corrections, &ee.corrections)
    );
    assert!((got.cost - exact.cost).abs() < 1e-6 * exact.cost);
}

/// The true MME cost of `(x0, d)` for the pendulum, with an RK4 written here.
fn true_cost(theta: &[f64], y: &[f64], u: &[f64], dt: f64, w: f64, r: f64) -> f64 {
    let f =
        |x: [f64; 2], u: f64, d: f64| [x[1], -9.81 * x[0].sin() - 0.3 * x[1] - x[0].cos() * u + d];
    let mut x = [theta[0], theta[1]];
    let mut cost = (y[0] - x[0]).powi(2) / r;
    for k in 0..y.len() - 1 {
        let d = theta[2 + k];
        let add = |x: [f64; 2], k: [f64; 2], c: f64| [x[0] + c * k[0], x[1] + c * k[1]];
        let k1 = f(x, u[k], d);
        let k2 = f(add(x, k1, dt / 2.0), u[k], d);
        let k3 = f(add(x, k2, dt / 2.0), u[k], d);
        let k4 = f(add(x, k3, dt), u[k], d);
        for i in 0..2 {
            x[i] += dt / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
        }
        cost += dt * w * d * d + (y[k + 1] - x[0]).powi(2) / r;
    }
    cost
}

fn gradient(theta: &[f64], cost: &dyn Fn(&[f64]) -> f64) -> Vec<f64> {
    (0..theta.len())
        .map(|i| {
            let eps = 1e-6 * theta[i].abs().max(1.0);
            let (mut p, mut m) = (theta.to_vec(), theta.to_vec());
            p[i] += eps;
            m[i] -= eps;
            (cost(&p) - cost(&m)) / (2.0 * eps)
        })
        .collect()
}

#[test]
fn gauss_newton_solution_is_a_stationary_point_of_the_true_cost() {
    let (dt, len, w, r) = (0.05, 40, 0.5, 1e-3_f64);
    let (data, _) = pendulum_data(len, dt, r.sqrt(), 8);
    let config = MmeConfig {
        w: WeightSpec::Scalar(w),
        noise_variance: NoiseSpec::Given(vec![r]),
        substeps: Some(1),
        ..MmeConfig::default()
    };
    let out = estimate_nonlinear_with_report(&pendulum_model(0.3), &data, &config).unwrap();
    assert_eq!(
        out.estimate.report.termination,
        Some(Termination::Converged)
    );
    let est = &out.estimate.experiments[0];
    let y = row(data.experiments()[0].outputs(), 0);
    let u = row(data.experiments()[0].inputs(), 0);
    let cost = |t: &[f64]| true_cost(t, &y, &u, dt, w, r);
    let solution: Vec<f64> = [est.states[(0, 0)], est.states[(1, 0)]]
        .into_iter()
        .chain(row(&est.corrections, 0))
        .collect();
    assert!((cost(&solution) - out.estimate.cost).abs() < 1e-9 * out.estimate.cost);
    let start: Vec<f64> = [y[0], 0.0].into_iter().chain(vec![0.0; len - 1]).collect();
    let norm = |g: Vec<f64>| g.iter().map(|v| v * v).sum::<f64>().sqrt();
    let (g_sol, g_start) = (
        norm(gradient(&solution, &cost)),
        norm(gradient(&start, &cost)),
    );
    // Central differences with ε = 1e-6 on J ≈ 20 carry round-off of ~1e-9 per component
    // (~1e-8 over 41 components): the solution's gradient must sit near that floor, eight
    // orders of magnitude below the start's (~1e3).
    assert!(
        g_sol < 1e-8 * g_start + 1e-6,
        "gradient {g_sol} vs start {g_start}"
    );
}

#[test]
fn exact_pendulum_model_leaves_only_noise_in_d() {
    let (dt, len, sigma) = (0.01, 1001, 0.01);
    let (data, truth) = pendulum_data(len, dt, sigma, 21);
    let r = sigma * sigma;
    // W from the covariance constraint on the small-angle (linearised) model, which needs
    // a real correction: (g/l)(θ − sin θ), the damping, and (1 − cos θ)u.
    let small_angle = linear(
        &[0.0, 1.0, -9.81, 0.0],
        &[0.0, -1.0],
        &[1.0, 0.0],
        &[0.0, 1.0],
        2,
        (&["theta", "omega"], &["u"], &["theta"], &["d"]),
    );
    let auto = MmeConfig {
        noise_variance: NoiseSpec::Given(vec![r]),
        substeps: Some(1),
        ..MmeConfig::default()
    };
    let lin = estimate_with_report(&small_angle, &data, &auto).unwrap();
    let w = lin.estimate.w[(0, 0)];
    let fixed = MmeConfig {
        w: WeightSpec::Scalar(w),
        ..auto.clone()
    };
    // Noise floor: what this W makes of pure measurement noise (y = v, u = 0).
    let v = gaussian(21, len, sigma);
    let noise_only = dataset(
        &["u"],
        &["theta"],
        vec![
            Experiment::new(
                0.0,
                dt,
                DMatrix::zeros(1, len),
                DMatrix::from_row_slice(1, len, &v),
            )
            .unwrap(),
        ],
    );
    let floor = rms(&row(
        &estimate(&small_angle, &noise_only, &fixed)
            .unwrap()
            .experiments[0]
            .corrections,
        0,
    ));
    let out = estimate_nonlinear_with_report(&pendulum_model(0.3), &data, &fixed).unwrap();
    let est = &out.estimate;
    assert_eq!(est.report.termination, Some(Termination::Converged));
    let history = &est.report.iterations;
    assert!(history.len() <= 15, "{} iterations", history.len());
    for pair in history.windows(2) {
        assert!(pair[1].cost <= pair[0].cost);
    }
    let d_exact = rms(&row(&est.experiments[0].corrections, 0));
    let d_lin = rms(&row(&lin.estimate.experiments[0].corrections, 0));
    // Exact model: d̂ is the filtered noise alone (the linearisations differ from the
    // small-angle one by cos θ ≥ 0.7, hence the factor 1.5 allowance); the wrong model's
    // d̂ stands well above that floor, so the comparison can tell them apart.
    assert!(
        d_exact <= 1.5 * floor,
        "exact-model d̂ RMS {d_exact} vs floor {floor}"
    );
    assert!(
        d_lin >= 3.0 * floor,
        "small-angle d̂ RMS {d_lin} vs floor {floor}"
    );
    // And the unmeasured rate is recovered.
    let err = rms(&row(&truth, 1)
        .iter()
        .zip(row(&est.experiments[0].states, 1))
        .map(|(a, b)| a - b)
        .collect::<Vec<_>>());
    assert!(err < 0.05 * rms(&row(&truth, 1)), "rate RMS error {err}");
}

#[test]
fn automatic_w_with_a_nonlinear_model_missing_its_damping() {
    let (dt, len, sigma) = (0.01, 801, 0.01);
    let (data, truth) = pendulum_data(len, dt, sigma, 33);
    let config = MmeConfig {
        noise_variance: NoiseSpec::Given(vec![sigma * sigma]),
        substeps: Some(1),
        start: StartTrajectory::Given(vec![vec![0.8, 0.0]]),
        ..MmeConfig::default()
    };
    let out = estimate_nonlinear_with_report(&pendulum_model(0.0), &data, &config).unwrap();
    let search = out.w_search.as_ref().unwrap();
    assert_eq!(search.termination, Termination::Converged);
    assert!((search.ratio - 1.0).abs() < 1e-3 + 1e-9);
    // The missing term is −b θ̇ (b = 0.3): d̂ must carry it.
    let est = &out.estimate.experiments[0];
    let d_true: Vec<f64> = (0..len - 1)
        .map(|k| -0.3 * 0.5 * (truth[(1, k)] + truth[(1, k + 1)]))
        .collect();
    let fit = super::common::r2(&d_true, &row(&est.corrections, 0));
    assert!(fit > 0.8, "R² of d̂ against the missing damping {fit}");
}

#[test]
fn noise_variance_with_a_nonlinear_model() {
    // Laplace (linearised) likelihood at the converged trajectory, exact pendulum model.
    let (dt, len, sigma) = (0.01, 801, 0.02);
    let (data, _) = pendulum_data(len, dt, sigma, 44);
    let config = MmeConfig {
        noise_variance: NoiseSpec::Auto,
        substeps: Some(1),
        ..MmeConfig::default()
    };
    let out = estimate_nonlinear_with_report(&pendulum_model(0.3), &data, &config).unwrap();
    let r = out.noise.variance[0];
    assert!(
        (r / (sigma * sigma) - 1.0).abs() < 0.2,
        "estimated {r} vs {}",
        sigma * sigma
    );
}

#[test]
fn first_order_hold_pendulum_record_needs_no_correction() {
    // Pendulum (θ up to ≈ 1 rad, so sin θ is far from θ) driven by a multisine of tones
    // up to 2 Hz sampled at 10 Hz; noise-free θ simulated with the input interpolated.
    let (dt, len) = (0.1, 301);
    let u = DMatrix::from_fn(1, len, |_, k| {
        let t = k as f64 * dt;
        (1..=6)
            .map(|i| {
                let phase = -std::f64::consts::PI * (i * (i - 1)) as f64 / 6.0;
                0.8 * (2.0 * std::f64::consts::PI * (i as f64 / 3.0) * t + phase).sin()
            })
            .sum::<f64>()
    });
    let truth = sysid_core::simulate_with(
        &Pendulum { damping: 0.3 },
        &[0.8, 0.0],
        0.0,
        dt,
        &u,
        sysid_core::InterSample::Foh,
        &Integrator::Rk4 { substeps: 200 },
        1e9,
    )
    .unwrap();
    let y = DMatrix::from_fn(1, len, |_, k| truth[(0, k)]);
    let config = MmeConfig {
        w: WeightSpec::Scalar(1e-2),
        noise_variance: NoiseSpec::Given(vec![1e-8]),
        substeps: Some(20),
        ..MmeConfig::default()
    };
    let run = |hold| {
        let data = dataset(
            &["u"],
            &["theta"],
            vec![
                Experiment::new(0.0, dt, u.clone(), y.clone())
                    .unwrap()
                    .with_intersample(hold),
            ],
        );
        estimate_nonlinear_with_report(&pendulum_model(0.3), &data, &config)
            .unwrap()
            .estimate
    };
    let foh = run(sysid_core::InterSample::Foh);
    let zoh = run(sysid_core::InterSample::Zoh);
    let d_foh = rms(&row(&foh.experiments[0].corrections, 0));
    let d_zoh = rms(&row(&zoh.experiments[0].corrections, 0));
    let states = &foh.experiments[0].states;
    let err = |i: usize| {
        rms(&(0..len)
            .map(|k| states[(i, k)] - truth[(i, k)])
            .collect::<Vec<_>>())
    };
    let (sx, sv) = (rms(&row(&truth, 0)), rms(&row(&truth, 1)));
    let theta_max = row(&truth, 0).iter().fold(0.0_f64, |a, b| a.max(b.abs()));
    assert!(theta_max > 0.8, "θ reaches only {theta_max} rad");
    assert_eq!(foh.report.termination, Some(Termination::Converged));
    // Measured: d̂ RMS 7.1e-9 with Foh (RK4 with 20 sub-steps against the 200-sub-step
    // truth) against 0.51 with Zoh (the held input lags by half a sample; the forcing
    // cos θ·u has RMS ≈ rms(u) = 1.4). Margins: Foh d̂ below 1e-6 of the forcing and
    // at least 1e4 below the held-input d̂.
    let forcing = rms(&row(&u, 0));
    assert_hold_margins(d_foh, d_zoh, forcing);
    // States: measured RMS errors 8e-17 (θ, scale 0.25) and 7.1e-10 (θ̇, scale 0.73).
    assert!(err(0) < 1e-9 * sx, "θ RMS error {} vs {sx}", err(0));
    assert!(err(1) < 1e-7 * sv, "θ̇ RMS error {} vs {sv}", err(1));
}
