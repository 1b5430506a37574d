//! Stiff terms in bounded time (issue 20, item 5): a mass with a steep friction law
//! `v̇ = u − c·tanh(k·v)` is stiff near `v = 0` (`∂v̇/∂v = −c·k`). The nonlinear
//! estimator's sub-steps then follow stability, not accuracy, on that relaxation mode, and
//! the RK4 trajectory at that step still matches a fine-step reference; and a stated
//! budget stops the estimate with a typed error that names the stage and how far it got.

use mme_core::discretize::{MAX_DEFAULT_SUBSTEPS, default_substeps, nonlinear_substeps};
use mme_core::{MmeConfig, MmeError, NoiseSpec, NonlinearModel, WeightSpec, estimate_nonlinear};
use nalgebra::DMatrix;
use sysid_core::{
    Budget, BudgetExhausted, BudgetLimit, CoreError, Dynamics, Experiment, Integrator, ModelNames,
    simulate,
};

use super::common::{dataset, gaussian};

/// Friction level `c` and steepness `k` (slope at rest `c·k` = 1000 /s).
const C: f64 = 1.0;
const K: f64 = 1000.0;
/// Sample period, s: `dt·c·k = 10`, far past RK4's stability limit of 2.785 for one step.
const DT: f64 = 0.01;

/// `ṗ = v`, `v̇ = u − c·tanh(k·v)`.
struct SteepFriction;

impl Dynamics for SteepFriction {
    fn n_states(&self) -> usize {
        2
    }
    fn n_inputs(&self) -> usize {
        1
    }
    fn rhs(&self, _t: f64, x: &[f64], u: &[f64], dx: &mut [f64]) {
        dx[0] = x[1];
        dx[1] = u[0] - C * (K * x[1]).tanh();
    }
    fn jacobians(
        &self,
        _t: f64,
        x: &[f64],
        _u: &[f64],
        a: &mut DMatrix<f64>,
        b: &mut DMatrix<f64>,
    ) {
        let th = (K * x[1]).tanh();
        a.copy_from_slice(&[0.0, 0.0, 1.0, -C * K * (1.0 - th * th)]);
        b.copy_from_slice(&[0.0, 1.0]);
    }
}

/// A sine force that alternately sticks (|u| < c) and slides: `u = 2 sin(1.3 t)`.
fn force(len: usize) -> DMatrix<f64> {
    DMatrix::from_fn(1, len, |_, k| 2.0 * (1.3 * k as f64 * DT).sin())
}

fn jacobian_at_rest() -> DMatrix<f64> {
    let (mut a, mut b) = (DMatrix::zeros(2, 2), DMatrix::zeros(2, 1));
    SteepFriction.jacobians(0.0, &[0.0, 0.0], &[0.0], &mut a, &mut b);
    a
}

fn model() -> NonlinearModel<SteepFriction> {
    let v = |s: &[&str]| s.iter().map(|x| x.to_string()).collect();
    NonlinearModel::new(
        SteepFriction,
        DMatrix::from_row_slice(1, 2, &[1.0, 0.0]),
        DMatrix::from_row_slice(2, 1, &[0.0, 1.0]),
        ModelNames {
            states: v(&["p", "v"]),
            inputs: v(&["u"]),
            outputs: v(&["p"]),
            corrections: v(&["d"]),
        },
    )
    .unwrap()
}

/// The accuracy rule asks for `dt·ck/0.1 = 100` sub-steps (capped at 64); the stiff rule
/// asks only stability of the relaxation mode, `⌈dt·ck/2⌉ = 5` (the other eigenvalue is
/// 0). RK4 at that step, over 10 s of stick and slip, stays within 2e-3 of the position
/// and velocity of a reference with 400 times as many steps (`h·ck = 0.005`); the
/// relaxation mode confines RK4's error at `h·ck = 2` to the boundary layer `|v| ≲ 1/k`,
/// so the bound is 2/k (measured: 3.1e-4). One step per sample (`|h·ck| = 10`, unstable
/// on that mode) leaves the layer: its error is more than 10 times larger (measured:
/// 1.9e-2).
#[test]
fn stiff_relaxation_needs_only_stable_sub_steps_and_matches_a_fine_reference() {
    let a = jacobian_at_rest();
    assert_eq!(default_substeps(&a, DT), MAX_DEFAULT_SUBSTEPS);
    let s = nonlinear_substeps(&a, DT);
    assert_eq!(s, 5);
    let len = 1001;
    let u = force(len);
    let run = |substeps| {
        simulate(
            &SteepFriction,
            &[0.0, 0.0],
            0.0,
            DT,
            &u,
            &Integrator::Rk4 { substeps },
            1e9,
        )
        .unwrap()
    };
    let reference = run(2000);
    let err = |x: &DMatrix<f64>| (x - &reference).abs().max();
    let (at_rule, one_step) = (err(&run(s)), err(&run(1)));
    assert!(at_rule < 2.0 / K, "error at {s} sub-steps {at_rule:e}");
    assert!(one_step > 10.0 * at_rule, "{one_step:e} vs {at_rule:e}");
    // A model that is not stiff at this period keeps the accuracy rule exactly.
    let slow = DMatrix::from_row_slice(2, 2, &[0.0, 1.0, -4.0, -0.4]);
    assert_eq!(nonlinear_substeps(&slow, DT), default_substeps(&slow, DT));
}

fn steep_data(len: usize) -> sysid_core::Dataset {
    let u = force(len);
    let truth = simulate(
        &SteepFriction,
        &[0.0, 0.0],
        0.0,
        DT,
        &u,
        &Integrator::Rk4 { substeps: 200 },
        1e9,
    )
    .unwrap();
    let noise = gaussian(5, len, 1e-3);
    let y = DMatrix::from_fn(1, len, |_, k| truth[(0, k)] + noise[k]);
    dataset(
        &["u"],
        &["p"],
        vec![Experiment::new(0.0, DT, u, y).unwrap()],
    )
}

fn config(budget: Budget) -> MmeConfig {
    MmeConfig {
        w: WeightSpec::Scalar(1.0),
        noise_variance: NoiseSpec::Given(vec![1e-6]),
        budget,
        ..MmeConfig::default()
    }
}

/// Every iteration charges its sub-steps (`(N − 1)·s` = 300·5): an unlimited run charges
/// exactly iterations × 1500; a budget of 0 units stops before the first iteration, one of
/// 1500 before the second, each with the stage and the iterations done; the estimate is
/// not returned.
#[test]
fn a_work_unit_budget_stops_the_nonlinear_estimate_with_a_typed_error() {
    let data = steep_data(301);
    let steps = 300 * 5;
    let unlimited = Budget::work_units(u64::MAX);
    let out = estimate_nonlinear(&model(), &data, &config(unlimited.clone())).unwrap();
    let iterations = out.report.iterations.len() as u64;
    assert!(iterations >= 2, "{:?}", out.report.iterations);
    assert_eq!(unlimited.used(), iterations * steps);

    for (units, done) in [(0, 0), (steps, 1)] {
        let err =
            estimate_nonlinear(&model(), &data, &config(Budget::work_units(units))).unwrap_err();
        let MmeError::Core(CoreError::BudgetExhausted(spent)) = &err else {
            panic!("expected a spent budget, got {err:?}");
        };
        assert_eq!(
            spent,
            &BudgetExhausted {
                limit: BudgetLimit::WorkUnits(units),
                stage: "nonlinear MME iteration",
                done,
                total: Some(50),
                used: units + steps,
            }
        );
        let text = err.to_string();
        assert!(text.contains("nonlinear MME iteration"), "{text}");
    }
}
