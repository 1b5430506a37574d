//! Sensitivity Jacobians against central differences of the simulated residuals.

use nalgebra::DMatrix;
use sysid_core::{
    Channel, Dataset, Experiment, Integrator, InterSample, LinearModel, ModelNames, TermModel,
    TermSpec,
};

use super::super::{
    DEFAULT_BLOW_UP, InitialState, OutputWeights, Problem, jacobian_fd, sensitivity_partials,
    simulate_outputs, weights_for,
};
use super::{Outcome, jacobian};

fn names(states: &[&str], inputs: &[&str], outputs: &[&str]) -> ModelNames {
    let own = |v: &[&str]| v.iter().map(|s| s.to_string()).collect::<Vec<_>>();
    ModelNames {
        states: own(states),
        inputs: own(inputs),
        outputs: own(outputs),
        corrections: own(states),
    }
}

fn matrix(rows: usize, cols: usize, v: &[f64]) -> DMatrix<f64> {
    DMatrix::from_row_slice(rows, cols, v)
}

/// One record of `model` from `x0` under input `u` (`m × len`), outputs simulated with
/// `RK4`; samples listed in `missing` (channel, sample) are set to NaN.
fn record(
    model: &TermModel,
    x0: &[f64],
    u: DMatrix<f64>,
    dt: f64,
    missing: &[(usize, usize)],
) -> Experiment {
    let len = u.ncols();
    let p = model.linear().n_outputs();
    let blank = Experiment::new(0.0, dt, u.clone(), DMatrix::zeros(p, len))
        .unwrap_or_else(|e| panic!("{e}"));
    let mut y = simulate_outputs(
        model,
        model.linear().c(),
        x0,
        &blank,
        &Integrator::Rk4 { substeps: 4 },
    )
    .unwrap_or_else(|e| panic!("{e}"));
    for &(ch, k) in missing {
        y[(ch, k)] = f64::NAN;
    }
    Experiment::new(0.0, dt, u, y).unwrap_or_else(|e| panic!("{e}"))
}

/// The calibration problem of `calibrate` for `model` on `data`, at horizon `fraction`.
#[allow(clippy::too_many_arguments)]
fn problem<'a>(
    model: &'a TermModel,
    data: &'a Dataset,
    x0: &'a [Vec<f64>],
    noise: &[f64],
    free: Vec<usize>,
    initial: InitialState,
    fraction: f64,
) -> Problem<'a> {
    let linear = model.linear();
    let (weights, valid) = weights_for(linear, data, &OutputWeights::NoiseVariance(noise.to_vec()))
        .unwrap_or_else(|e| panic!("{e}"));
    let mut pr = Problem {
        linear,
        terms: model.terms(),
        data,
        weights,
        free,
        estimate_x0: initial == InitialState::Estimate,
        base_coefficients: model.terms().iter().map(|t| t.coefficient).collect(),
        base_x0: x0,
        integrator: Integrator::Rk4 { substeps: 4 },
        blow_up: DEFAULT_BLOW_UP,
        lengths: vec![],
        valid,
        evaluations: 0,
        partials: None,
    };
    pr.partials = sensitivity_partials(&pr);
    pr.set_horizon(fraction);
    pr
}

/// θ of the problem: its calibrated coefficients, then the initial states if estimated.
fn theta(pr: &Problem<'_>) -> Vec<f64> {
    let mut t: Vec<f64> = pr.free.iter().map(|&k| pr.base_coefficients[k]).collect();
    if pr.estimate_x0 {
        t.extend(pr.base_x0.iter().flatten());
    }
    t
}

/// Every column of the sensitivity Jacobian equals the central-difference one to 1e-6
/// of its norm. Central differences with `h = 1e-5·max(|θ|, 0.01)` err by
/// `h²/6·|r'''|` (≈ 1e-10 relative for these smooth, O(1)-scaled problems) plus
/// rounding `ε‖r‖/h` ≤ 2.2e-16/1e-7 ≈ 2e-9 relative; the sensitivities are the exact
/// derivative of the same RK4 map, so the two agree far inside 1e-6, while a wrong sign,
/// weight, column or missing term in `F_x` would be off by O(1).
fn assert_matches_central_differences(pr: &mut Problem<'_>) {
    let t = theta(pr);
    let Some(partials) = pr.partials.clone() else {
        panic!("sensitivities unavailable");
    };
    let sens = match jacobian(pr, &partials, &t, 4) {
        Ok(Outcome::Jacobian(j)) => j,
        Ok(Outcome::NonFinite) => panic!("non-finite sensitivity"),
        Err((e, err)) => panic!("experiment {e}: {err}"),
    };
    let fd = jacobian_fd(pr, &t, None).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(sens.shape(), fd.shape());
    assert_eq!(sens.nrows(), pr.valid);
    for j in 0..fd.ncols() {
        let norm = fd.column(j).norm();
        let err = (sens.column(j) - fd.column(j)).norm();
        assert!(
            norm > 0.0,
            "column {j} is zero: the test would prove nothing"
        );
        assert!(
            err <= 1e-6 * norm,
            "column {j}: |sens − fd| = {err:e}, |fd| = {norm:e}"
        );
    }
}

/// Duffing oscillator `ẍ = −x − 0.2ẋ + u + c₁x³ + c₂x²ẋ`, only `x` measured (with gaps),
/// coefficients and the initial state calibrated, full and half horizon.
#[test]
fn cubic_terms_with_estimated_initial_state() {
    let linear = LinearModel::with_names(
        matrix(2, 2, &[0.0, 1.0, -1.0, -0.2]),
        matrix(2, 1, &[0.0, 1.0]),
        matrix(1, 2, &[1.0, 0.0]),
        DMatrix::identity(2, 2),
        names(&["x", "v"], &["u"], &["x"]),
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let truth = TermModel::from_specs(
        linear.clone(),
        [
            ("v", "cubic_stiffness", "x^3", -0.5),
            ("v", "van_der_pol", "x^2*v", -0.3),
        ],
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let u = DMatrix::from_fn(1, 200, |_, k| 0.8 * (0.3 * k as f64 * 0.05).sin());
    let exp = record(&truth, &[1.2, -0.3], u, 0.05, &[(0, 3), (0, 77), (0, 150)]);
    let data = Dataset::new(vec![Channel::new("u")], vec![Channel::new("x")], vec![exp])
        .unwrap_or_else(|e| panic!("{e}"));
    let start = TermModel::from_specs(
        linear,
        [
            ("v", "cubic_stiffness", "x^3", -0.3),
            ("v", "van_der_pol", "x^2*v", -0.1),
        ],
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let x0 = [vec![1.0, -0.1]];
    for fraction in [1.0, 0.5] {
        let mut pr = problem(
            &start,
            &data,
            &x0,
            &[0.01],
            vec![0, 1],
            InitialState::Estimate,
            fraction,
        );
        assert_matches_central_differences(&mut pr);
    }
}

/// Two tanks: a transfer `c₁√h₁` from `h₁` into `h₂` plus an outflow `c₂√h₂`, both
/// levels measured with different noise variances, three records of different lengths
/// (each with its own estimated initial state), at the half horizon.
#[test]
fn transfer_term_over_several_experiments() {
    let linear = LinearModel::with_names(
        matrix(2, 2, &[0.0, 0.0, 0.0, -0.05]),
        matrix(2, 1, &[1.0, 0.0]),
        DMatrix::identity(2, 2),
        DMatrix::identity(2, 2),
        names(&["h1", "h2"], &["q"], &["h1", "h2"]),
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let specs = |c1: f64, c2: f64| {
        [
            TermSpec {
                state: "h1",
                into: Some("h2"),
                effect: "orifice",
                term: "sqrt(h1)",
                coefficient: c1,
            },
            TermSpec {
                state: "h2",
                into: None,
                effect: "orifice",
                term: "sqrt(h2)",
                coefficient: c2,
            },
        ]
    };
    let truth =
        TermModel::from_specs(linear.clone(), specs(-0.5, -0.4)).unwrap_or_else(|e| panic!("{e}"));
    let starts = [[1.0, 0.5], [0.6, 1.1], [1.4, 0.9]];
    let experiments: Vec<Experiment> = starts
        .iter()
        .enumerate()
        .map(|(i, x0)| {
            let len = 120 + 40 * i;
            let w = 0.05 * (i + 1) as f64;
            let u = DMatrix::from_fn(1, len, |_, k| 0.5 + 0.2 * (w * k as f64).sin());
            record(&truth, x0, u, 0.1, &[(1, 10 + i)])
        })
        .collect();
    let data = Dataset::new(
        vec![Channel::new("q")],
        vec![Channel::new("h1"), Channel::new("h2")],
        experiments,
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let start = TermModel::from_specs(linear, specs(-0.4, -0.3)).unwrap_or_else(|e| panic!("{e}"));
    let x0: Vec<Vec<f64>> = starts
        .iter()
        .map(|s| vec![s[0] + 0.05, s[1] - 0.05])
        .collect();
    let mut pr = problem(
        &start,
        &data,
        &x0,
        &[1e-4, 4e-4],
        vec![0, 1],
        InitialState::Estimate,
        0.5,
    );
    assert_matches_central_differences(&mut pr);
}

/// Pendulum `θ̈ = −0.3θ̇ + c₁ sin θ + c₂ u cos θ` (a trigonometric term and one in the
/// input), fixed initial state; all terms free, and only the input term free (the other
/// still enters `F_x`, in the calibrated column order reversed).
#[test]
fn trigonometric_term_with_input() {
    let linear = LinearModel::with_names(
        matrix(2, 2, &[0.0, 1.0, 0.0, -0.3]),
        matrix(2, 1, &[0.0, 0.0]),
        matrix(1, 2, &[1.0, 0.0]),
        DMatrix::identity(2, 2),
        names(&["theta", "omega"], &["u"], &["theta"]),
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let model = |c1: f64, c2: f64| {
        TermModel::from_specs(
            linear.clone(),
            [
                ("omega", "gravity", "sin(theta)", c1),
                ("omega", "actuator", "u*cos(theta)", c2),
            ],
        )
        .unwrap_or_else(|e| panic!("{e}"))
    };
    let u = DMatrix::from_fn(1, 250, |_, k| {
        1.5 * (0.11 * k as f64).sin() + 0.5 * (0.37 * k as f64).cos()
    });
    let exp = record(&model(-9.0, 2.0), &[0.8, 0.0], u, 0.02, &[]);
    let data = Dataset::new(
        vec![Channel::new("u")],
        vec![Channel::new("theta")],
        vec![exp],
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let start = model(-7.0, 1.5);
    let x0 = [vec![0.8, 0.0]];
    // Held and interpolated inputs: the residuals follow the record's hold, so a pass
    // that held the input of an `foh` record would miss the input term's column.
    for hold in [InterSample::Zoh, InterSample::Foh] {
        let data = data.clone().with_intersample(hold);
        for free in [vec![0, 1], vec![1], vec![1, 0]] {
            let mut pr = problem(&start, &data, &x0, &[1e-3], free, InitialState::Fixed, 1.0);
            assert_matches_central_differences(&mut pr);
        }
    }
}

/// Where sensitivities cannot serve, calibration falls back to finite differences and
/// still recovers a known coefficient: `ẋ = −0.3x + u + c·sqrt(x)` from `x(0) = 0`,
/// where `∂φ/∂x = 1/(2√x)` is infinite (so `S` turns non-finite at the first stage;
/// without the fallback no step is ever taken), and the same model under the adaptive
/// integrator (no sensitivities at all). Noise-free data from `c = −0.4`, start `−0.2`.
/// The same law written `sqrt(abs(x))` has the strong-zero slope 0 at `x = 0`
/// (`sign(0) = 0` times an infinite outer slope; sysid-core's derivative rule), so its
/// sensitivities stay finite there; it must recover the coefficient all the same.
#[test]
fn falls_back_to_differences_and_still_recovers() {
    let one = |v: f64| DMatrix::from_element(1, 1, v);
    let linear = LinearModel::with_names(
        one(-0.3),
        one(1.0),
        one(1.0),
        one(1.0),
        names(&["x"], &["u"], &["x"]),
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let law = |term: &'static str| {
        let linear = linear.clone();
        move |c: f64| {
            TermModel::from_specs(linear.clone(), [("x", "orifice", term, c)])
                .unwrap_or_else(|e| panic!("{e}"))
        }
    };
    let model = law("sqrt(x)");
    let u = DMatrix::from_fn(1, 200, |_, k| 0.5 + 0.3 * (0.1 * k as f64).sin());
    let exp = record(&model(-0.4), &[0.0], u, 0.1, &[]);
    let data = Dataset::new(vec![Channel::new("u")], vec![Channel::new("x")], vec![exp])
        .unwrap_or_else(|e| panic!("{e}"));
    let start = model(-0.2);
    let x0 = [vec![0.0]];
    let partials =
        super::Partials::new(1, start.terms()).unwrap_or_else(|| panic!("the derivative builds"));
    let pr = problem(
        &start,
        &data,
        &x0,
        &[1e-4],
        vec![0],
        InitialState::Fixed,
        1.0,
    );
    assert!(
        matches!(jacobian(&pr, &partials, &[-0.2], 4), Ok(Outcome::NonFinite)),
        "the sensitivity at x = 0 must be non-finite for this test to mean anything"
    );
    let abs_start = law("sqrt(abs(x))")(-0.2);
    for (start, integrator) in [
        (&start, Integrator::Rk4 { substeps: 4 }),
        (
            &start,
            Integrator::DormandPrince(sysid_core::DpOptions::default()),
        ),
        (&abs_start, Integrator::Rk4 { substeps: 4 }),
    ] {
        let config = super::super::CalibrationConfig {
            integrator,
            ..Default::default()
        };
        let cal =
            super::super::calibrate(start, &data, &x0, &config).unwrap_or_else(|e| panic!("{e}"));
        // Noise-free: the data's own model (RK4; the adaptive integrator differs from it
        // by ~1e-8), so the coefficient comes back to well within 1e-4.
        assert!(
            (cal.coefficients_after[0] + 0.4).abs() < 1e-4,
            "{integrator:?}: {:?}",
            cal.coefficients_after
        );
    }
}
