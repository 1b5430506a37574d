//! The grey-box estimator against a closed form (a model linear in its parameter and
//! start state, whose least-squares answer and covariance are ordinary least squares),
//! an active bound, multiple shooting reaching the same optimum, and typed errors.

use nalgebra::{DMatrix, DVector};

use super::*;
use crate::dynamics::Dynamics;
use crate::linear::{LinearModel, ModelNames};
use crate::physical::{Parameter, PhysicalError, PhysicalModel, PhysicalTerm};

/// A model whose reported parameters are tampered with (a start outside its bounds,
/// which `PhysicalModel` itself refuses to hold).
#[derive(Debug, Clone)]
struct Tampered {
    inner: PhysicalModel,
    params: Vec<Parameter>,
}

impl Dynamics for Tampered {
    fn n_states(&self) -> usize {
        self.inner.n_states()
    }
    fn n_inputs(&self) -> usize {
        self.inner.n_inputs()
    }
    fn rhs(&self, t: f64, x: &[f64], u: &[f64], dx: &mut [f64]) {
        self.inner.rhs(t, x, u, dx);
    }
}

impl ParametricDynamics for Tampered {
    fn parameters(&self) -> &[Parameter] {
        &self.params
    }
    fn with_parameters(&self, values: &[f64]) -> std::result::Result<Self, PhysicalError> {
        Ok(self.clone()).and_then(|t| {
            Ok(Tampered {
                inner: t.inner.with_parameters(values)?,
                params: t.params,
            })
        })
    }
    fn parameter_jacobian(&self, t: f64, x: &[f64], u: &[f64], out: &mut DMatrix<f64>) {
        self.inner.parameter_jacobian(t, x, u, out);
    }
}

/// `ẋ = b·u`, `y = x`: with the input held between samples RK4 is exact, so
/// `x_k = x0 + b·dt·Σ_{j<k} u_j`, linear in `(x0, b)`.
fn integrator(lower: f64, upper: f64, start: f64) -> PhysicalModel {
    integrator_with(lower, upper, start, Estimation::Free)
}

fn integrator_with(lower: f64, upper: f64, start: f64, estimation: Estimation) -> PhysicalModel {
    let names = ModelNames {
        states: vec!["x".into()],
        inputs: vec!["u".into()],
        outputs: vec!["x".into()],
        corrections: Vec::new(),
    };
    let linear = LinearModel::with_names(
        DMatrix::zeros(1, 1),
        DMatrix::zeros(1, 1),
        DMatrix::from_element(1, 1, 1.0),
        DMatrix::zeros(1, 0),
        names,
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let mut b = Parameter::new("b", start);
    b.lower = lower;
    b.upper = upper;
    b.estimation = estimation;
    let term = PhysicalTerm {
        state: 0,
        into: None,
        effect: "gain",
        term: "b*u",
        coefficient: 1.0,
    };
    PhysicalModel::new(linear, vec![b], &[term], None).unwrap_or_else(|e| panic!("{e}"))
}

const DT: f64 = 0.1;
const N: usize = 200;
const B_TRUE: f64 = 1.7;
const X0_TRUE: f64 = 0.4;
const NOISE: f64 = 0.05;

/// Uniform noise in `[−NOISE, NOISE]` from a fixed-seed 64-bit LCG (Knuth's MMIX
/// constants), so the record is the same on every platform.
fn record() -> Experiment {
    let mut state: u64 = 0x2545_F491_4F6C_DD1D;
    let mut noise = || {
        state = state
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        NOISE * (2.0 * ((state >> 11) as f64 / (1u64 << 53) as f64) - 1.0)
    };
    let u = DMatrix::from_fn(1, N, |_, k| {
        let k = k as f64;
        (0.3 * k).sin() + 0.5 * (1.1 * k).cos()
    });
    let mut x = X0_TRUE;
    let mut y = DMatrix::zeros(1, N);
    for k in 0..N {
        y[(0, k)] = x + noise();
        x += B_TRUE * DT * u[(0, k)];
    }
    Experiment::new(0.0, DT, u, y).unwrap_or_else(|e| panic!("{e}"))
}

/// Ordinary least squares of `y = x0 + b·s_k`: estimates `(x0, b)`, their covariance
/// `SSE/(N − 2)·(XᵀX)⁻¹`.
fn closed_form(exp: &Experiment) -> (DVector<f64>, DMatrix<f64>) {
    let mut x = DMatrix::zeros(N, 2);
    let mut s = 0.0;
    for k in 0..N {
        x[(k, 0)] = 1.0;
        x[(k, 1)] = s;
        s += DT * exp.input(k)[0];
    }
    let y = DVector::from_iterator(N, exp.outputs().row(0).iter().copied());
    let xtx = x.transpose() * &x;
    let inv = xtx.try_inverse().unwrap_or_else(|| panic!("singular"));
    let beta = &inv * x.transpose() * &y;
    let sse = (&y - &x * &beta).norm_squared();
    (beta, inv * (sse / (N - 2) as f64))
}

fn data<'a>(c: &'a DMatrix<f64>, records: &'a [Experiment], nv: &'a [f64]) -> GreyboxData<'a> {
    GreyboxData {
        c,
        noise_variance: nv,
        records,
        x0: &[],
    }
}

#[test]
fn linear_in_parameters_matches_ordinary_least_squares() {
    let records = [record()];
    let (beta, cov) = closed_form(&records[0]);
    let c = DMatrix::from_element(1, 1, 1.0);
    // The weight 1/σ² scales out of the estimate and, through s², of the covariance.
    let nv = [NOISE * NOISE / 3.0];
    for (lower, upper) in [
        (f64::NEG_INFINITY, f64::INFINITY),
        (0.0, 10.0),
        (0.0, f64::INFINITY),
    ] {
        let model = integrator(lower, upper, 1.0);
        let fit = estimate_parameters(&model, &data(&c, &records, &nv), &GreyboxOptions::default())
            .unwrap_or_else(|e| panic!("{e}"));
        let p = &fit.parameters[0];
        // A linear problem: the solve lands on the normal equations' answer to the
        // solver's precision (relative cost decrease 1e-10 ⇒ ~1e-6 relative in θ at worst;
        // 1e-6 of the value, well inside 1e-3 σ).
        assert!(
            (p.value - beta[1]).abs() < 1e-6 * beta[1].abs(),
            "{p:?} vs {beta}"
        );
        assert!(
            (fit.x0[0][0] - beta[0]).abs() < 1e-6,
            "{:?} vs {beta}",
            fit.x0
        );
        let sigma = p.sigma.unwrap_or(f64::NAN);
        // Same Jacobian at the same point: σ agrees to the relative 1e-6 of the point.
        assert!(
            (sigma - cov[(1, 1)].sqrt()).abs() < 1e-4 * cov[(1, 1)].sqrt(),
            "σ {sigma} vs {}",
            cov[(1, 1)].sqrt()
        );
        assert!((fit.x0_sigma[0][0] - cov[(0, 0)].sqrt()).abs() < 1e-4 * cov[(0, 0)].sqrt());
        assert!(p.active_bound.is_none());
        assert_eq!(fit.rank, (2, 2));
        assert!((fit.correlation[(0, 0)] - 1.0).abs() < 1e-12);
        // And it is the truth within a few σ (the closed form is an unbiased estimator).
        assert!((p.value - B_TRUE).abs() < 4.0 * sigma, "{p:?}");
        assert!(fit.fit_percent[0][0] > 90.0, "{:?}", fit.fit_percent);
        // A calibration that moves is converged, and no rank test ran on it.
        assert_eq!(fit.report().termination, crate::Termination::Converged);
        assert!(fit.report().moved());
        assert_eq!(fit.report().rank, None);
    }
}

/// The start state's least squares with `b` held at `b_held`: `x0 = mean(y_k − b·s_k)`,
/// its σ `√(SSE/(N − 1)/N)` (one estimated quantity).
fn x0_with_b_held(exp: &Experiment, b_held: f64) -> (f64, f64) {
    let mut s = 0.0;
    let mut rest = Vec::with_capacity(N);
    for k in 0..N {
        rest.push(exp.outputs()[(0, k)] - b_held * s);
        s += DT * exp.input(k)[0];
    }
    let mean = rest.iter().sum::<f64>() / N as f64;
    let sse: f64 = rest.iter().map(|v| (v - mean).powi(2)).sum();
    (mean, (sse / (N - 1) as f64 / N as f64).sqrt())
}

/// `b` in `[0, 1]` while the unconstrained optimum is 1.69 (the closed form): `b` ends on
/// its upper bound without σ, the rank counts the start state only, and the start state
/// and its σ are the closed form's with `b` held at 1 (one estimated quantity in `s²`).
#[test]
fn an_optimum_beyond_a_bound_is_reported_on_it() {
    let records = [record()];
    let (beta, _) = closed_form(&records[0]);
    assert!(beta[1] > 1.5, "{beta}");
    let c = DMatrix::from_element(1, 1, 1.0);
    let nv = [NOISE * NOISE / 3.0];
    let model = integrator(0.0, 1.0, 0.5);
    let fit = estimate_parameters(&model, &data(&c, &records, &nv), &GreyboxOptions::default())
        .unwrap_or_else(|e| panic!("{e}"));
    let p = &fit.parameters[0];
    assert_eq!(p.active_bound, Some(ActiveBound::Upper), "{p:?}");
    assert!((p.value - 1.0).abs() < 1e-5, "{p:?}");
    assert!(p.sigma.is_none());
    assert_eq!(fit.rank, (1, 1));
    assert!(fit.correlation[(0, 0)].is_nan());
    let (x0, sigma) = x0_with_b_held(&records[0], 1.0);
    // b is 1 to ~1e-13 here (cos z below 1e-3 and the solve converged on it), so x0 is
    // the closed form's to the solver's precision; σ to the relative 1e-6 of the point.
    assert!((fit.x0[0][0] - x0).abs() < 1e-6, "{:?} vs {x0}", fit.x0);
    assert!(
        (fit.x0_sigma[0][0] - sigma).abs() < 1e-4 * sigma,
        "σ {:?} vs {sigma}",
        fit.x0_sigma
    );
}

/// `ẋ = a·b·u` with `a` free but held by equal bounds `[0.5, 0.5]` and `b` unbounded:
/// only the product is in the data, and an unbounded `a` would make the estimate a valley.
/// `a` is held at 0.5, reported on its bound without σ and outside the rank; `b` is the
/// closed form's slope over 0.5 with its σ over 0.5 (`a` used to be moved by the solver
/// past its bounds: an error).
#[test]
fn a_parameter_with_equal_bounds_is_held_on_them() {
    let records = [record()];
    let (beta, cov) = closed_form(&records[0]);
    let c = DMatrix::from_element(1, 1, 1.0);
    let nv = [NOISE * NOISE / 3.0];
    let names = ModelNames {
        states: vec!["x".into()],
        inputs: vec!["u".into()],
        outputs: vec!["x".into()],
        corrections: Vec::new(),
    };
    let linear = LinearModel::with_names(
        DMatrix::zeros(1, 1),
        DMatrix::zeros(1, 1),
        DMatrix::from_element(1, 1, 1.0),
        DMatrix::zeros(1, 0),
        names,
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let mut a = Parameter::new("a", 0.5);
    a.lower = 0.5;
    a.upper = 0.5;
    let term = PhysicalTerm {
        state: 0,
        into: None,
        effect: "gain",
        term: "a*b*u",
        coefficient: 1.0,
    };
    let model = PhysicalModel::new(linear, vec![a, Parameter::new("b", 1.0)], &[term], None)
        .unwrap_or_else(|e| panic!("{e}"));
    let fit = estimate_parameters(&model, &data(&c, &records, &nv), &GreyboxOptions::default())
        .unwrap_or_else(|e| panic!("{e}"));
    let [a, b] = &fit.parameters[..] else {
        panic!("{:?}", fit.parameters)
    };
    assert_eq!((a.name.as_str(), b.name.as_str()), ("a", "b"));
    assert_eq!(a.value.to_bits(), 0.5f64.to_bits(), "{a:?}");
    assert_eq!(a.active_bound, Some(ActiveBound::Fixed), "{a:?}");
    assert!(a.sigma.is_none(), "{a:?}");
    // b and the start state: the two estimated quantities, both determined.
    assert_eq!(fit.rank, (2, 2));
    assert_eq!(fit.stages[0].estimated, 2);
    assert!(b.active_bound.is_none());
    assert!(
        (b.value - beta[1] / 0.5).abs() < 1e-6 * beta[1].abs(),
        "{b:?} vs {beta}"
    );
    let sigma = b.sigma.unwrap_or(f64::NAN);
    let want = cov[(1, 1)].sqrt() / 0.5;
    assert!((sigma - want).abs() < 1e-4 * want, "σ {sigma} vs {want}");
    assert!(
        (fit.x0[0][0] - beta[0]).abs() < 1e-6,
        "{:?} vs {beta}",
        fit.x0
    );
    assert!(fit.correlation[(0, 0)].is_nan() && fit.correlation[(0, 1)].is_nan());
    assert!((fit.correlation[(1, 1)] - 1.0).abs() < 1e-12);
}

#[test]
fn multiple_shooting_ends_at_the_free_run_optimum() {
    let records = [record()];
    let (beta, _) = closed_form(&records[0]);
    let c = DMatrix::from_element(1, 1, 1.0);
    let nv = [NOISE * NOISE / 3.0];
    let model = integrator(f64::NEG_INFINITY, f64::INFINITY, 0.2);
    let opts = GreyboxOptions {
        shooting: Shooting::Multiple { segment: 30 },
        ..GreyboxOptions::default()
    };
    let fit = estimate_parameters(&model, &data(&c, &records, &nv), &opts)
        .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(fit.stages.len(), 2);
    // 200 samples in segments of 30: 7 segments, 6 links of one state each.
    assert_eq!(fit.stages[0].estimated, 1 + 7);
    assert_eq!(fit.stages[0].residuals, 200 + 6);
    assert!((fit.parameters[0].value - beta[1]).abs() < 1e-6 * beta[1].abs());
}

#[test]
fn bad_input_is_a_typed_error() {
    let records = [record()];
    let c = DMatrix::from_element(1, 1, 1.0);
    let nv = [1e-3];
    let opts = GreyboxOptions::default();

    let fixed = integrator_with(0.0, 10.0, 1.0, Estimation::Fixed);
    let e = estimate_parameters(&fixed, &data(&c, &records, &nv), &opts).err();
    assert!(
        matches!(e, Some(CoreError::NoFreeParameters { parameters: 1 })),
        "{e:?}"
    );

    let inner = integrator(0.0, 10.0, 1.0);
    let mut params = inner.parameters().to_vec();
    params[0].value = 11.0;
    let outside = Tampered { inner, params };
    let e = estimate_parameters(&outside, &data(&c, &records, &nv), &opts).err();
    assert!(
        matches!(&e, Some(CoreError::ParameterOutsideBounds { name, .. }) if name == "b"),
        "{e:?}"
    );

    let model = integrator(0.0, 10.0, 1.0);
    let e = estimate_parameters(&model, &data(&c, &records, &[1e-3, 1e-3]), &opts).err();
    assert!(matches!(e, Some(CoreError::Length { .. })), "{e:?}");
    let e = estimate_parameters(&model, &data(&c, &records, &[0.0]), &opts).err();
    assert!(
        matches!(e, Some(CoreError::NonPositiveVariance { .. })),
        "{e:?}"
    );
    let c2 = DMatrix::from_element(2, 1, 1.0);
    let e = estimate_parameters(&model, &data(&c2, &records, &[1e-3, 1e-3]), &opts).err();
    assert!(matches!(e, Some(CoreError::Length { .. })), "{e:?}");
    let wide = DMatrix::from_element(1, 2, 1.0);
    let e = estimate_parameters(&model, &data(&wide, &records, &nv), &opts).err();
    assert!(matches!(e, Some(CoreError::Shape { .. })), "{e:?}");
    let two_inputs = [
        Experiment::new(0.0, DT, DMatrix::zeros(2, N), records[0].outputs().clone())
            .unwrap_or_else(|e| panic!("{e}")),
    ];
    let e = estimate_parameters(&model, &data(&c, &two_inputs, &nv), &opts).err();
    assert!(matches!(e, Some(CoreError::Length { .. })), "{e:?}");
    let bad_x0 = GreyboxData {
        x0: &[vec![0.0, 0.0]],
        ..data(&c, &records, &nv)
    };
    let e = estimate_parameters(&model, &bad_x0, &opts).err();
    assert!(matches!(e, Some(CoreError::Length { .. })), "{e:?}");
    // NaN outputs are missing samples; a record with none measured is an error.
    let unmeasured = [Experiment::new(
        0.0,
        DT,
        records[0].inputs().clone(),
        DMatrix::from_element(1, N, f64::NAN),
    )
    .unwrap_or_else(|e| panic!("{e}"))];
    let e = estimate_parameters(&model, &data(&c, &unmeasured, &nv), &opts).err();
    assert!(matches!(e, Some(CoreError::TooFewSamples { .. })), "{e:?}");
    let short = GreyboxOptions {
        shooting: Shooting::Multiple { segment: 1 },
        ..opts
    };
    let e = estimate_parameters(&model, &data(&c, &records, &nv), &short).err();
    assert!(
        matches!(e, Some(CoreError::InvalidArgument { .. })),
        "{e:?}"
    );
}

#[test]
fn missing_samples_are_skipped() {
    // Every third output missing: the same closed form on the remaining samples.
    let full = record();
    let mut y = full.outputs().clone();
    for k in (0..N).step_by(3) {
        y[(0, k)] = f64::NAN;
    }
    let records =
        [Experiment::new(0.0, DT, full.inputs().clone(), y).unwrap_or_else(|e| panic!("{e}"))];
    let c = DMatrix::from_element(1, 1, 1.0);
    let nv = [1e-3];
    // Start state given (the first sample is missing).
    let given = [vec![0.0]];
    let d = GreyboxData {
        x0: &given,
        ..data(&c, &records, &nv)
    };
    let fit = estimate_parameters(
        &integrator(f64::NEG_INFINITY, f64::INFINITY, 1.0),
        &d,
        &GreyboxOptions::default(),
    )
    .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(fit.stages[0].residuals, N - N.div_ceil(3));
    assert!(
        (fit.parameters[0].value - B_TRUE).abs() < 0.05,
        "{:?}",
        fit.parameters
    );
}

/// A pendulum with a gravity gain, viscous and smooth Coulomb friction as parameters:
/// `k` bounded on both sides, `c` below only, `fc` unbounded.
fn pendulum() -> PhysicalModel {
    let names = ModelNames {
        states: vec!["theta".into(), "omega".into()],
        inputs: vec!["u".into()],
        outputs: vec!["theta".into()],
        corrections: Vec::new(),
    };
    let linear = LinearModel::with_names(
        DMatrix::from_row_slice(2, 2, &[0.0, 1.0, 0.0, 0.0]),
        DMatrix::from_row_slice(2, 1, &[0.0, 1.0]),
        DMatrix::from_row_slice(1, 2, &[1.0, 0.0]),
        DMatrix::zeros(2, 0),
        names,
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let mut k = Parameter::new("k", 9.0);
    k.lower = 1.0;
    k.upper = 30.0;
    let mut c = Parameter::new("c", 0.3);
    c.lower = 0.0;
    let fc = Parameter::new("fc", 0.2);
    let term = |term| PhysicalTerm {
        state: 1,
        into: None,
        effect: "force",
        term,
        coefficient: -1.0,
    };
    PhysicalModel::new(
        linear,
        vec![k, c, fc],
        &[
            term("k*sin(theta)"),
            term("c*omega"),
            term("fc*atan(omega/0.1)"),
        ],
        None,
    )
    .unwrap_or_else(|e| panic!("{e}"))
}

#[test]
fn the_shooting_jacobian_is_the_derivative_of_the_residuals() {
    // Every column (transformed parameters, segment start states) and every row (output
    // errors, continuity defects) of the exact Jacobian against central differences of
    // the residuals, on a nonlinear model cut into three linked segments.
    let model = pendulum();
    let n_samples = 60;
    let u = DMatrix::from_fn(1, n_samples, |_, k| (0.7 * k as f64 * 0.05).sin());
    let xs = crate::integrate::simulate(
        &model,
        &[0.4, 0.0],
        0.0,
        0.05,
        &u,
        &crate::integrate::Integrator::Rk4 { substeps: 2 },
        1e6,
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let y = DMatrix::from_fn(1, n_samples, |_, k| xs[(0, k)] + 0.01 * (k as f64).sin());
    let records = [Experiment::new(0.0, 0.05, u, y).unwrap_or_else(|e| panic!("{e}"))];
    let c = DMatrix::from_row_slice(1, 2, &[1.0, 0.0]);
    let Free {
        free,
        transforms,
        z,
        ..
    } = free_parameters(&model).unwrap_or_else(|e| panic!("{e}"));
    let segments = shooting_segments(&records, 20);
    assert_eq!(segments.len(), 3);
    let mut problem = Calibration::new(
        &model,
        &c,
        vec![10.0],
        &records,
        free,
        transforms,
        segments,
        3.0,
        vec![2],
        1e6,
    );
    let mut theta = z;
    // Start states off the trajectory, so the defects are not zero.
    theta.extend_from_slice(&[0.35, 0.1, -0.2, 0.5, 0.1, -0.3]);
    let rows = problem.rows;
    assert_eq!(rows, 60 + 2 * 2);
    let mut jac = DMatrix::zeros(rows, theta.len());
    crate::least_squares::LeastSquaresProblem::jacobian(&mut problem, &theta, &[], &mut jac)
        .unwrap_or_else(|e| panic!("{e}"));
    let mut plus = vec![0.0; rows];
    let mut minus = vec![0.0; rows];
    for j in 0..theta.len() {
        let h = 1e-6 * theta[j].abs().max(1.0);
        let mut t = theta.clone();
        t[j] += h;
        assert!(problem.residuals_checked(&t, &mut plus).unwrap_or(false));
        t[j] -= 2.0 * h;
        assert!(problem.residuals_checked(&t, &mut minus).unwrap_or(false));
        let scale = jac.column(j).amax().max(1e-3);
        for i in 0..rows {
            let fd = (plus[i] - minus[i]) / (2.0 * h);
            // Central differences: truncation O(h²·r''') and rounding O(ε·r/h) ≈ 1e-9
            // relative; 1e-6 of the column's largest entry leaves room for both.
            assert!(
                (fd - jac[(i, j)]).abs() <= 1e-6 * scale,
                "row {i}, column {j}: exact {} vs difference {fd}",
                jac[(i, j)]
            );
        }
    }
}

/// A stated budget stops the calibration with a typed error naming the stage: a
/// work-unit budget of 0 before the first free-run iteration, one of exactly one
/// Jacobian's RK4 steps (199 intervals × 2 sub-steps) before the second; an unlimited
/// budget charges exactly that much per iteration.
#[test]
fn a_spent_budget_stops_the_calibration_with_a_typed_error() {
    let records = [record()];
    let c = DMatrix::from_element(1, 1, 1.0);
    let nv = [NOISE * NOISE / 3.0];
    let model = integrator(f64::NEG_INFINITY, f64::INFINITY, 1.0);
    let per_iteration = ((records[0].len() - 1) * 2) as u64;
    let unlimited = crate::Budget::work_units(u64::MAX);
    let opts = GreyboxOptions {
        budget: unlimited.clone(),
        ..GreyboxOptions::default()
    };
    let fit = estimate_parameters(&model, &data(&c, &records, &nv), &opts)
        .unwrap_or_else(|e| panic!("{e}"));
    assert!(unlimited.used() > 0);
    assert_eq!(unlimited.used() % per_iteration, 0);
    assert_eq!(fit.stages.len(), 1);
    for (units, done) in [(0, 0), (per_iteration, 1)] {
        let opts = GreyboxOptions {
            budget: crate::Budget::work_units(units),
            ..GreyboxOptions::default()
        };
        let e = estimate_parameters(&model, &data(&c, &records, &nv), &opts).err();
        assert_eq!(
            e,
            Some(CoreError::BudgetExhausted(crate::BudgetExhausted {
                limit: crate::BudgetLimit::WorkUnits(units),
                stage: "grey-box free-run iteration",
                done,
                total: None,
                used: units + per_iteration,
            }))
        );
    }
}

/// `ẋ = a·z²`, `ż = 0`, `y = x`: with the unmeasured `z` started at 0 (the minimum-norm
/// start) the sensitivities of `a` and of `z(0)` are zero all along, and on a record
/// whose mean is its first sample (`1, then 1.5, 0.5, …`, exact in binary) the gradient
/// of the start is exactly zero too: the solver stops at once, where it started.
fn flat_through_a_square() -> (PhysicalModel, Experiment) {
    let names = ModelNames {
        states: vec!["x".into(), "z".into()],
        inputs: vec!["u".into()],
        outputs: vec!["x".into()],
        corrections: Vec::new(),
    };
    let linear = LinearModel::with_names(
        DMatrix::zeros(2, 2),
        DMatrix::zeros(2, 1),
        DMatrix::from_row_slice(1, 2, &[1.0, 0.0]),
        DMatrix::zeros(2, 0),
        names,
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let term = PhysicalTerm {
        state: 0,
        into: None,
        effect: "square",
        term: "a*z^2",
        coefficient: 1.0,
    };
    let model = PhysicalModel::new(linear, vec![Parameter::new("a", 1.0)], &[term], None)
        .unwrap_or_else(|e| panic!("{e}"));
    let y = DMatrix::from_fn(1, 21, |_, k| match k {
        0 => 1.0,
        k if k % 2 == 1 => 1.5,
        _ => 0.5,
    });
    let exp = Experiment::new(0.0, DT, DMatrix::zeros(1, 21), y).unwrap_or_else(|e| panic!("{e}"));
    (model, exp)
}

#[test]
fn a_start_with_a_zero_sensitivity_that_does_not_move_is_no_progress() {
    let (model, exp) = flat_through_a_square();
    let records = [exp];
    let c = DMatrix::from_row_slice(1, 2, &[1.0, 0.0]);
    let nv = [0.25];
    let fit = estimate_parameters(&model, &data(&c, &records, &nv), &GreyboxOptions::default())
        .unwrap_or_else(|e| panic!("{e}"));
    let report = fit.report();
    assert_eq!(
        report.termination,
        crate::Termination::NoProgress,
        "{report:?}"
    );
    assert!(!report.moved());
    // Only the start of x is determined: a and z(0) have zero columns.
    assert_eq!(report.rank, Some((1, 3)));
    assert_eq!(fit.rank, (1, 3));
    assert_eq!(fit.x0, vec![vec![1.0, 0.0]]);
    assert_eq!(fit.parameters[0].value.to_bits(), 1.0f64.to_bits());

    // Started elsewhere (z = 1, so x moves with a) the same data calibrate: the cost
    // falls. (Only the product a·z(0)² is determined, so the solve ends at a stationary
    // valley, `NoDescent` — a moved solve is never `NoProgress`.)
    let starts = [vec![1.0, 1.0]];
    let elsewhere = GreyboxData {
        x0: &starts,
        ..data(&c, &records, &nv)
    };
    let fit = estimate_parameters(&model, &elsewhere, &GreyboxOptions::default())
        .unwrap_or_else(|e| panic!("{e}"));
    assert!(fit.report().moved());
    assert_eq!(fit.report().termination, crate::Termination::NoDescent);
    assert_eq!(fit.report().rank, None);
}

/// [`free_run_residuals`] at a fit's model, start states and sub-steps is the fit's final
/// cost (the same simulation code), and against the closed form: `r_k = (y_k − x0 − b·s_k)/σ`
/// at a moved `b`. A record whose simulation diverges is `None`; mismatched start states are
/// a typed error.
#[test]
fn free_run_residuals_are_the_estimators() {
    let records = [record()];
    let c = DMatrix::from_element(1, 1, 1.0);
    let nv = [NOISE * NOISE];
    let model = integrator(f64::NEG_INFINITY, f64::INFINITY, 1.0);
    let d = data(&c, &records, &nv);
    let fit = estimate_parameters(&model, &d, &GreyboxOptions::default())
        .unwrap_or_else(|e| panic!("{e}"));
    let r = free_run_residuals(&fit.model, &d, &fit.x0, &fit.substeps, 1e6)
        .unwrap_or_else(|e| panic!("{e}"))
        .unwrap_or_else(|| panic!("diverged"));
    let cost: f64 = r.iter().map(|v| v * v).sum();
    let reported = fit.report().final_cost();
    assert!(
        (cost - reported).abs() <= 1e-12 * reported,
        "{cost} vs {reported}"
    );
    let moved = model
        .with_parameters(&[2.5])
        .unwrap_or_else(|e| panic!("{e}"));
    let x0 = 0.1;
    let r = free_run_residuals(&moved, &d, &[vec![x0]], &[3], 1e6)
        .unwrap_or_else(|e| panic!("{e}"))
        .unwrap_or_else(|| panic!("diverged"));
    let exp = &records[0];
    let mut s = 0.0;
    for (k, rk) in r.iter().enumerate() {
        let expected = (exp.outputs()[(0, k)] - x0 - 2.5 * s) / NOISE;
        assert!((rk - expected).abs() < 1e-9, "{k}: {rk} vs {expected}");
        s += DT * exp.input(k)[0];
    }
    assert_eq!(
        free_run_residuals(&moved, &d, &[vec![x0]], &[1], 1e-3).unwrap_or_default(),
        None
    );
    assert!(free_run_residuals(&moved, &d, &[], &[1], 1e6).is_err());
}
