//! Analytic weight and input Jacobians against central finite differences, over random
//! shapes, weights, scalers and inputs.

use nalgebra::DMatrix;
use nn::{Architecture, Mlp, Scaler};
use proptest::prelude::*;

/// Finite-difference step. Central differences have truncation error C·h² and round-off
/// error about ε·|y|/h; each comparison below estimates C·h² from the Richardson
/// difference |D(h) − D(2h)|/3 and adds the round-off bound, so the tolerance follows
/// from h rather than being hand-tuned.
const H: f64 = 1e-4;

/// Tolerance for one FD entry: 10× (Richardson truncation estimate + round-off bound).
fn tolerance(d_h: f64, d_2h: f64, y_scale: f64) -> f64 {
    10.0 * ((d_h - d_2h).abs() / 3.0 + 4.0 * f64::EPSILON * (1.0 + y_scale) / H)
}

#[derive(Debug, Clone)]
struct Case {
    net: Mlp,
    x: DMatrix<f64>,
}

fn case() -> impl Strategy<Value = Case> {
    (1usize..4, prop::collection::vec(1usize..5, 0..3), 1usize..4)
        .prop_flat_map(|(n, hidden, q)| {
            let arch = Architecture {
                inputs: n,
                hidden,
                outputs: q,
            };
            let nw = arch.n_weights();
            (
                Just(arch),
                prop::collection::vec(-1.5f64..1.5, nw),
                prop::collection::vec((-2.0f64..2.0, 0.5f64..3.0), n),
                prop::collection::vec((-2.0f64..2.0, 0.5f64..3.0), q),
                prop::collection::vec(-1.2f64..1.2, n * 3),
            )
        })
        .prop_map(|(arch, w, sin, sout, x01)| {
            let (ci, hi): (Vec<f64>, Vec<f64>) = sin.into_iter().unzip();
            let (co, ho): (Vec<f64>, Vec<f64>) = sout.into_iter().unzip();
            // Inputs within ±1.2 scaled units of the scaler centre.
            let x = DMatrix::from_fn(arch.inputs, 3, |j, k| {
                ci[j] + hi[j] * x01[k * arch.inputs + j]
            });
            let net = Mlp::from_parts(
                arch,
                w,
                Scaler::new(ci, hi).expect("valid scaler"),
                Scaler::new(co, ho).expect("valid scaler"),
            )
            .expect("valid parts");
            Case { net, x }
        })
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

    #[test]
    fn weight_jacobian_matches_central_differences(c in case()) {
        let jac = c.net.weight_jacobian(&c.x).unwrap();
        let q = c.net.n_outputs();
        prop_assert_eq!(jac.nrows(), c.x.ncols() * q);
        prop_assert_eq!(jac.ncols(), c.net.n_weights());
        let y = c.net.predict(&c.x).unwrap();
        let y_scale = y.amax();
        let w0 = c.net.weights().to_vec();
        let mut net = c.net.clone();
        let mut eval = |i: usize, step: f64| {
            let mut w = w0.clone();
            w[i] += step;
            net.set_weights(&w).unwrap();
            net.predict(&c.x).unwrap()
        };
        for i in 0..w0.len() {
            let d_h = (eval(i, H) - eval(i, -H)) / (2.0 * H);
            let d_2h = (eval(i, 2.0 * H) - eval(i, -2.0 * H)) / (4.0 * H);
            for k in 0..c.x.ncols() {
                for o in 0..q {
                    let (a, f, f2) = (jac[(k * q + o, i)], d_h[(o, k)], d_2h[(o, k)]);
                    let tol = tolerance(f, f2, y_scale);
                    prop_assert!((a - f).abs() <= tol, "w{} sample {} out {}: {} vs {} (tol {})", i, k, o, a, f, tol);
                }
            }
        }
    }

    #[test]
    fn input_jacobian_matches_central_differences(c in case()) {
        let n = c.net.n_inputs();
        for k in 0..c.x.ncols() {
            let x0: Vec<f64> = c.x.column(k).iter().copied().collect();
            let jac = c.net.input_jacobian(&x0).unwrap();
            let at = |j: usize, step: f64| {
                let mut x = x0.clone();
                x[j] += step;
                c.net.predict(&DMatrix::from_column_slice(n, 1, &x)).unwrap()
            };
            let y_scale = at(0, 0.0).amax();
            for j in 0..n {
                let d_h = (at(j, H) - at(j, -H)) / (2.0 * H);
                let d_2h = (at(j, 2.0 * H) - at(j, -2.0 * H)) / (4.0 * H);
                for o in 0..c.net.n_outputs() {
                    let tol = tolerance(d_h[o], d_2h[o], y_scale);
                    prop_assert!((jac[(o, j)] - d_h[o]).abs() <= tol, "x{} out {}: {} vs {} (tol {})", j, o, jac[(o, j)], d_h[o], tol);
                }
            }
        }
    }

    /// The one-sample gradients (for simulation-error training) are the two checked
    /// Jacobians above, sample by sample, through one reused workspace.
    #[test]
    fn one_sample_gradients_equal_the_checked_jacobians(c in case()) {
        let (q, n, nw) = (c.net.n_outputs(), c.net.n_inputs(), c.net.n_weights());
        let full = c.net.weight_jacobian(&c.x).unwrap();
        let y_all = c.net.predict(&c.x).unwrap();
        let mut ws = nn::Workspace::new();
        let (mut y, mut dw, mut dx) = (vec![0.0; q], DMatrix::zeros(q, nw), DMatrix::zeros(q, n));
        for k in 0..c.x.ncols() {
            let x: Vec<f64> = c.x.column(k).iter().copied().collect();
            c.net.gradients_into(&x, &mut y, &mut dw, &mut dx, &mut ws).unwrap();
            let dx_ref = c.net.input_jacobian(&x).unwrap();
            for o in 0..q {
                prop_assert!((y[o] - y_all[(o, k)]).abs() <= 1e-12 * (1.0 + y_all[(o, k)].abs()));
                for i in 0..nw {
                    let r = full[(k * q + o, i)];
                    prop_assert!((dw[(o, i)] - r).abs() <= 1e-12 * (1.0 + r.abs()), "w{} out {}: {} vs {}", i, o, dw[(o, i)], r);
                }
                for j in 0..n {
                    let r = dx_ref[(o, j)];
                    prop_assert!((dx[(o, j)] - r).abs() <= 1e-12 * (1.0 + r.abs()), "x{} out {}: {} vs {}", j, o, dx[(o, j)], r);
                }
            }
        }
        // Wrong sizes are errors, not panics.
        let mut short = DMatrix::zeros(q, nw + 1);
        prop_assert!(c.net.gradients_into(&c.x.column(0).iter().copied().collect::<Vec<_>>(), &mut y, &mut short, &mut dx, &mut ws).is_err());
    }
}
