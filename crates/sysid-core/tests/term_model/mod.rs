//! `TermModel` against hand-written dynamics: its right-hand side equals the linear model's
//! plus the nonlinear terms coded in Rust, and its analytic Jacobians equal the trait's
//! default finite differences.

use nalgebra::DMatrix;
use proptest::prelude::*;
use sysid_core::{Dynamics, LinearModel, ModelNames, TermModel};

use crate::config;

/// States (theta, omega, h1), inputs (u, v).
fn linear() -> LinearModel {
    let names = ModelNames {
        states: vec!["theta".into(), "omega".into(), "h1".into()],
        inputs: vec!["u".into(), "v".into()],
        outputs: vec!["theta".into()],
        corrections: vec!["d".into()],
    };
    let a = DMatrix::from_row_slice(3, 3, &[0.0, 1.0, 0.0, -9.81, -0.2, 0.1, 0.3, 0.0, -0.5]);
    let b = DMatrix::from_row_slice(3, 2, &[0.0, 0.0, 1.0, -0.4, 0.0, 0.8]);
    let c = DMatrix::from_row_slice(1, 3, &[1.0, 0.0, 0.0]);
    let e = DMatrix::from_row_slice(3, 1, &[0.0, 1.0, 0.0]);
    LinearModel::with_names(a, b, c, e, names).unwrap_or_else(|e| panic!("{e}"))
}

/// One term of every SPEC kind, on all three equations, two of them reading inputs.
const SPECS: [(&str, &str, &str, f64); 8] = [
    ("omega", "coulomb_friction", "sign(omega)", -0.3),
    ("omega", "quadratic_drag", "omega*abs(omega)", -0.05),
    ("omega", "gravity_nonlinearity", "sin(theta) - theta", -9.81),
    ("omega", "input_coupling", "u*cos(theta)", 1.5),
    ("h1", "orifice_outflow", "sqrt(h1)", -0.7),
    ("theta", "cubic_stiffening", "theta^3", 0.1),
    ("h1", "bilinear", "v*h1/(1 + theta^2)", 0.2),
    ("theta", "bias", "1e-3", 2.0),
];

fn model() -> TermModel {
    TermModel::from_specs(linear(), SPECS).unwrap_or_else(|e| panic!("{e}"))
}

/// The same terms written in Rust, as (contribution to each state, magnitude scale).
fn hand_terms(x: &[f64], u: &[f64]) -> [f64; 3] {
    let (theta, omega, h1) = (x[0], x[1], x[2]);
    let sign = if omega > 0.0 {
        1.0
    } else if omega < 0.0 {
        -1.0
    } else {
        0.0
    };
    [
        0.1 * theta.powi(3) + 2.0 * 1e-3,
        -0.3 * sign - 0.05 * omega * omega.abs() - 9.81 * (theta.sin() - theta)
            + 1.5 * u[0] * theta.cos(),
        -0.7 * h1.sqrt() + 0.2 * u[1] * h1 / (1.0 + theta * theta),
    ]
}

/// Delegates the right-hand side only, so `jacobians` is the trait's finite-difference
/// default.
struct FiniteDifferences<'a>(&'a TermModel);

impl Dynamics for FiniteDifferences<'_> {
    fn n_states(&self) -> usize {
        self.0.n_states()
    }
    fn n_inputs(&self) -> usize {
        self.0.n_inputs()
    }
    fn rhs(&self, t: f64, x: &[f64], u: &[f64], dx: &mut [f64]) {
        self.0.rhs(t, x, u, dx)
    }
}

fn state() -> impl Strategy<Value = (Vec<f64>, Vec<f64>)> {
    (
        -1.5..1.5_f64,
        -3.0..3.0_f64,
        0.2..2.0_f64,
        -2.0..2.0_f64,
        -2.0..2.0_f64,
    )
        .prop_map(|(theta, omega, h1, u, v)| (vec![theta, omega, h1], vec![u, v]))
}

proptest! {
    #![proptest_config(config(256))]

    /// `rhs = A x + B u + hand-coded terms`. Both sides add about ten rounded terms of
    /// magnitude ≤ `scale` in different orders, so they agree to ~10·ε·scale; the
    /// tolerance is 100·ε·scale.
    #[test]
    fn rhs_is_linear_part_plus_terms((x, u) in state()) {
        let m = model();
        let mut lin = [0.0; 3];
        m.linear().rhs(0.0, &x, &u, &mut lin);
        let hand = hand_terms(&x, &u);
        let mut got = [0.0; 3];
        m.rhs(0.0, &x, &u, &mut got);
        let mut nonlinear = [0.0; 3];
        m.nonlinear_rhs(&x, &u, &mut nonlinear);
        for i in 0..3 {
            let scale = 1.0 + lin[i].abs() + 30.0;
            let tol = 100.0 * f64::EPSILON * scale;
            prop_assert!((got[i] - (lin[i] + hand[i])).abs() <= tol, "state {i}: {} vs {}", got[i], lin[i] + hand[i]);
            prop_assert!((nonlinear[i] - hand[i]).abs() <= tol, "state {i}");
        }
    }

    /// Analytic Jacobians match the default central differences. Difference error:
    /// `h²·|f'''|/6 + ε·|f|/h` with `h ≈ 6e-6·max(1, |x|)`, i.e. ≈ 4e-11·(|f'''| + |f|) ≲
    /// 4e-9 here (|f| ≲ 40, |f'''| ≲ 60 with h1 ≥ 0.2); ω stays 1e-3 away from the jump
    /// of sign(ω), far more than the step. Tolerance 1e-6·(1 + |J|).
    #[test]
    fn analytic_jacobians_match_finite_differences((x, u) in state()) {
        prop_assume!(x[1].abs() > 1e-3);
        let m = model();
        let (mut a, mut b) = (DMatrix::zeros(3, 3), DMatrix::zeros(3, 2));
        let (mut fa, mut fb) = (DMatrix::zeros(3, 3), DMatrix::zeros(3, 2));
        m.jacobians(0.0, &x, &u, &mut a, &mut b);
        FiniteDifferences(&m).jacobians(0.0, &x, &u, &mut fa, &mut fb);
        for (name, analytic, numeric) in [("A", &a, &fa), ("B", &b, &fb)] {
            for j in 0..analytic.ncols() {
                for i in 0..analytic.nrows() {
                    let (an, nu) = (analytic[(i, j)], numeric[(i, j)]);
                    prop_assert!((an - nu).abs() <= 1e-6 * (1.0 + an.abs()),
                        "{name}[{i},{j}] at x={x:?}, u={u:?}: {an} vs {nu}");
                }
            }
        }
    }
}

/// Without terms the model is exactly its linear part.
#[test]
fn no_terms_is_the_linear_model() {
    let m = TermModel::from_specs(linear(), Vec::<(&str, &str, &str, f64)>::new())
        .unwrap_or_else(|e| panic!("{e}"));
    let (x, u) = ([0.3, -0.7, 1.1], [0.5, -2.0]);
    let (mut got, mut want) = ([0.0; 3], [0.0; 3]);
    m.rhs(0.0, &x, &u, &mut got);
    linear().rhs(0.0, &x, &u, &mut want);
    assert_eq!(got.map(f64::to_bits), want.map(f64::to_bits));
    let (mut a, mut b) = (DMatrix::zeros(3, 3), DMatrix::zeros(3, 2));
    m.jacobians(0.0, &x, &u, &mut a, &mut b);
    assert_eq!(&a, linear().a());
    assert_eq!(&b, linear().b());
}

/// Terms printed back (as `model.discovered.toml` would hold them) rebuild the same model.
#[test]
fn printed_terms_rebuild_the_same_model() {
    let m = model();
    let printed: Vec<(String, String, String, f64)> = m
        .terms()
        .iter()
        .map(|t| {
            let state = m.linear().state_names()[t.state].clone();
            (state, t.effect.clone(), t.expr.to_string(), t.coefficient)
        })
        .collect();
    let specs = printed
        .iter()
        .map(|(s, e, t, c)| (s.as_str(), e.as_str(), t.as_str(), *c));
    let again = TermModel::from_specs(linear(), specs).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(again.terms(), m.terms());
}
