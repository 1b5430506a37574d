//! The RK4 step's tangents against central differences of the step itself, for random
//! nonlinear models `ẋ = A x + B u + p ⊙ tanh(W x)` (`n ≤ 3`), random initial states and
//! parameters, inputs held or linear: `S = ∂x_N/∂[x0, p]` after several steps must equal
//! the central difference of `x_N` (an independent computation: only `rhs` is used).

// Index loops over the states read like the equations.
#![allow(clippy::needless_range_loop)]

use nalgebra::DMatrix;
use proptest::prelude::*;
use sysid_core::tangent::{Rk4, TangentSource};
use sysid_core::{Dynamics, InterSample};

use crate::config;

#[derive(Debug, Clone)]
struct Random {
    n: usize,
    a: DMatrix<f64>,
    b: DMatrix<f64>,
    w: DMatrix<f64>,
    p: Vec<f64>,
}

impl Random {
    fn wx(&self, x: &[f64], i: usize) -> f64 {
        (0..self.n).map(|j| self.w[(i, j)] * x[j]).sum()
    }
}

impl Dynamics for Random {
    fn n_states(&self) -> usize {
        self.n
    }
    fn n_inputs(&self) -> usize {
        1
    }
    fn rhs(&self, _: f64, x: &[f64], u: &[f64], dx: &mut [f64]) {
        for i in 0..self.n {
            dx[i] = (0..self.n).map(|j| self.a[(i, j)] * x[j]).sum::<f64>()
                + self.b[(i, 0)] * u[0]
                + self.p[i] * self.wx(x, i).tanh();
        }
    }
    fn jacobians(&self, _: f64, x: &[f64], _: &[f64], a: &mut DMatrix<f64>, b: &mut DMatrix<f64>) {
        for i in 0..self.n {
            let sech2 = 1.0 - self.wx(x, i).tanh().powi(2);
            for j in 0..self.n {
                a[(i, j)] = self.a[(i, j)] + self.p[i] * sech2 * self.w[(i, j)];
            }
            b[(i, 0)] = self.b[(i, 0)];
        }
    }
}

/// `∂f/∂p_i = tanh((W x)_i) e_i`, in the columns after the `n` initial-state ones.
impl TangentSource for Random {
    fn add_to(&self, _: f64, x: &[f64], _: &[f64], out: &mut DMatrix<f64>) {
        for i in 0..self.n {
            out[(i, self.n + i)] += self.wx(x, i).tanh();
        }
    }
}

const SAMPLES: usize = 6;
const SUBSTEPS: usize = 3;
const DT: f64 = 0.1;

fn input(k: usize) -> [f64; 1] {
    [(0.9 * k as f64).sin()]
}

/// Simulate `SAMPLES` intervals from `x0`, with tangents when `s` is given.
fn run(f: &Random, x0: &[f64], hold: InterSample, mut s: Option<&mut DMatrix<f64>>) -> Vec<f64> {
    let n = f.n;
    let mut rk = Rk4::new(n, 1, 2 * n);
    let mut x = x0.to_vec();
    let h = DT / SUBSTEPS as f64;
    for k in 0..SAMPLES {
        let (ua, ub) = (input(k), input(k + 1));
        for j in 0..SUBSTEPS {
            let t = k as f64 * DT + j as f64 * h;
            let step = hold.step_input(&ua, &ub, j, SUBSTEPS);
            match s.as_deref_mut() {
                Some(s) => rk.step_with_tangents(f, f, t, h, &mut x, s, &step),
                None => rk.step(f, t, h, &mut x, &step),
            }
        }
    }
    x
}

fn matrix(n: usize, scale: f64) -> impl Strategy<Value = DMatrix<f64>> {
    prop::collection::vec(-scale..scale, n * n).prop_map(move |v| DMatrix::from_vec(n, n, v))
}

fn case() -> impl Strategy<Value = (Random, Vec<f64>, bool)> {
    (1usize..=3).prop_flat_map(|n| {
        (
            matrix(n, 2.0),
            prop::collection::vec(-1.0..1.0f64, n),
            matrix(n, 1.5),
            prop::collection::vec(-2.0..2.0f64, n),
            prop::collection::vec(-1.5..1.5f64, n),
            any::<bool>(),
        )
            .prop_map(move |(a, b, w, p, x0, foh)| {
                let f = Random {
                    n,
                    a,
                    b: DMatrix::from_vec(n, 1, b),
                    w,
                    p,
                };
                (f, x0, foh)
            })
    })
}

proptest! {
    #![proptest_config(config(64))]

    /// Central differences with step 1e-5 have truncation error ~1e-10 times the third
    /// derivative of `x_N` (of order 1 here: 0.6 s of a model with rates ≲ 5/s) and
    /// round-off ~1e-16/1e-5 = 1e-11; 1e-7 absolute plus 1e-6 relative leaves a margin
    /// of 100 while a wrong stage term (an error of order h = 0.03) fails by far.
    #[test]
    fn tangents_match_central_differences((f, x0, foh) in case()) {
        let n = f.n;
        let hold = if foh { InterSample::Foh } else { InterSample::Zoh };
        let mut s = DMatrix::zeros(n, 2 * n);
        for i in 0..n {
            s[(i, i)] = 1.0;
        }
        let x_end = run(&f, &x0, hold, Some(&mut s));
        prop_assert_eq!(&x_end, &run(&f, &x0, hold, None), "the tangent step moves x as the plain step");
        let h = 1e-5;
        for col in 0..2 * n {
            let shifted = |sign: f64| {
                let mut x = x0.clone();
let mut g = f.clone();
                if col < n { x[col] += sign * h } else { g.p[col - n] += sign * h }
                run(&g, &x, hold, None)
            };
            let (plus, minus) = (shifted(1.0), shifted(-1.0));
            for i in 0..n {
                let fd = (plus[i] - minus[i]) / (2.0 * h);
                prop_assert!(
                    (s[(i, col)] - fd).abs() <= 1e-7 + 1e-6 * fd.abs(),
                    "S[{i},{col}] = {} vs central difference {fd}", s[(i, col)]
                );
            }
        }
    }
}
