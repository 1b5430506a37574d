//! The discrete map of the nonlinear assumed model over one sub-step — one classical RK4
//! step of `ẋ = f(t, x, u) + E d` with `d` held and `u` held or, for first-order-hold
//! inputs, interpolated at each stage time ([`StageInput`]) — and its Jacobians
//! `Φ = ∂x⁺/∂x`, `Γ = ∂x⁺/∂d`, chained exactly through the four stages.
//!
//! With `k_i = g(ξ_i)`, `ξ_1 = x`, `ξ_2 = x + ½h k_1`, `ξ_3 = x + ½h k_2`,
//! `ξ_4 = x + h k_3` and `A_i = ∂f/∂x(ξ_i)`:
//! `∂k_1/∂x = A_1`, `∂k_i/∂x = A_i (I + c_i h ∂k_{i−1}/∂x)`,
//! `∂k_1/∂d = E`, `∂k_i/∂d = A_i c_i h ∂k_{i−1}/∂d + E` (`c = ½, ½, 1`), and
//! `Φ = I + h/6 Σ w_i ∂k_i/∂x`, `Γ = h/6 Σ w_i ∂k_i/∂d` (`w = 1, 2, 2, 1`).

use nalgebra::DMatrix;
use sysid_core::Dynamics;

/// The input over one sub-step.
#[derive(Debug, Clone, Copy)]
pub(crate) enum StageInput<'u> {
    /// Held at `u` for every stage (zero-order hold).
    Held(&'u [f64]),
    /// Linear between two samples (first-order hold): at a stage `c·h` into the step,
    /// `u = ua + (from + c·per)·(ub − ua)`, where `from` is the fraction of the sample
    /// interval at the step's start and `per = h/dt` the fraction one step spans (so the
    /// stage times are `t, t + h/2, t + h`, as in `sysid_core`'s RK4).
    Ramp {
        /// Input at the interval's first sample.
        ua: &'u [f64],
        /// Input at the interval's last sample.
        ub: &'u [f64],
        /// Interval fraction at the step's start.
        from: f64,
        /// Interval fraction per step.
        per: f64,
    },
}

impl StageInput<'_> {
    /// The input at stage offset `c` (fraction of the step), computed into `buf` if needed.
    fn at<'a>(&'a self, c: f64, buf: &'a mut [f64]) -> &'a [f64] {
        match *self {
            StageInput::Held(u) => u,
            StageInput::Ramp { ua, ub, from, per } => {
                let f = from + c * per;
                for ((b, a), z) in buf.iter_mut().zip(ua).zip(ub) {
                    *b = a + f * (z - a);
                }
                &buf[..ua.len()]
            }
        }
    }
}

/// Buffers for one step (no allocation per step).
pub(crate) struct Rk4 {
    n: usize,
    q: usize,
    /// Interpolated input (first-order hold).
    u: Vec<f64>,
    ed: Vec<f64>,
    k: [Vec<f64>; 4],
    xi: Vec<f64>,
    a: DMatrix<f64>,
    b: DMatrix<f64>,
    dk_dx: [DMatrix<f64>; 4],
    dk_dd: [DMatrix<f64>; 4],
    tmp_x: DMatrix<f64>,
    tmp_d: DMatrix<f64>,
}

const STAGE_C: [f64; 4] = [0.0, 0.5, 0.5, 1.0];
const WEIGHT: [f64; 4] = [1.0, 2.0, 2.0, 1.0];

impl Rk4 {
    /// Buffers for `n` states, `m` inputs, `q` corrections.
    pub fn new(n: usize, m: usize, q: usize) -> Self {
        Self {
            n,
            q,
            u: vec![0.0; m],
            ed: vec![0.0; n],
            k: std::array::from_fn(|_| vec![0.0; n]),
            xi: vec![0.0; n],
            a: DMatrix::zeros(n, n),
            b: DMatrix::zeros(n, m),
            dk_dx: std::array::from_fn(|_| DMatrix::zeros(n, n)),
            dk_dd: std::array::from_fn(|_| DMatrix::zeros(n, q)),
            tmp_x: DMatrix::zeros(n, n),
            tmp_d: DMatrix::zeros(n, q),
        }
    }

    fn set_correction(&mut self, e: &DMatrix<f64>, d: &[f64]) {
        for i in 0..self.n {
            self.ed[i] = (0..self.q).map(|c| e[(i, c)] * d[c]).sum();
        }
    }

    /// `ξ_s = x + c·k_{s−1}` (`ξ_1 = x`).
    fn stage_point(&mut self, s: usize, c: f64, x: &[f64]) {
        if s == 0 {
            self.xi.copy_from_slice(x);
        } else {
            for ((xi, xv), kv) in self.xi.iter_mut().zip(x).zip(&self.k[s - 1]) {
                *xi = xv + c * kv;
            }
        }
    }

    fn stages<F: Dynamics + ?Sized>(&mut self, f: &F, t: f64, h: f64, x: &[f64], u: &StageInput) {
        for (s, &cs) in STAGE_C.iter().enumerate() {
            self.stage_point(s, cs * h, x);
            let ks = &mut self.k[s];
            f.rhs(t + cs * h, &self.xi, u.at(cs, &mut self.u), ks);
            ks.iter_mut().zip(&self.ed).for_each(|(k, e)| *k += e);
        }
    }

    /// `x ← x⁺` for one step of length `h` from time `t`.
    #[allow(clippy::too_many_arguments)]
    pub fn step<F: Dynamics + ?Sized>(
        &mut self,
        f: &F,
        e: &DMatrix<f64>,
        t: f64,
        h: f64,
        x: &mut [f64],
        u: &StageInput,
        d: &[f64],
    ) {
        self.set_correction(e, d);
        self.stages(f, t, h, x, u);
        for (i, xi) in x.iter_mut().enumerate() {
            *xi += h / 6.0 * (0..4).map(|s| WEIGHT[s] * self.k[s][i]).sum::<f64>();
        }
    }

    /// `x⁺`, `Φ` and `Γ` of one step (written into `x_next`, `phi` `n × n`, `gamma`
    /// `n × q`, column-major slices).
    #[allow(clippy::too_many_arguments)]
    pub fn step_jacobians<F: Dynamics + ?Sized>(
        &mut self,
        f: &F,
        e: &DMatrix<f64>,
        t: f64,
        h: f64,
        x: &[f64],
        u: &StageInput,
        d: &[f64],
        x_next: &mut [f64],
        phi: &mut [f64],
        gamma: &mut [f64],
    ) {
        let n = self.n;
        self.set_correction(e, d);
        for (s, &cs) in STAGE_C.iter().enumerate() {
            self.stage_point(s, cs * h, x);
            let ts = t + cs * h;
            let us = u.at(cs, &mut self.u);
            f.rhs(ts, &self.xi, us, &mut self.k[s]);
            self.k[s]
                .iter_mut()
                .zip(&self.ed)
                .for_each(|(k, e)| *k += e);
            f.jacobians(ts, &self.xi, us, &mut self.a, &mut self.b);
            if s == 0 {
                self.dk_dx[0].copy_from(&self.a);
                self.dk_dd[0].copy_from(e);
            } else {
                let c = cs * h;
                // ∂ξ/∂x = I + c ∂k_{s−1}/∂x ; ∂ξ/∂d = c ∂k_{s−1}/∂d.
                self.tmp_x.copy_from(&self.dk_dx[s - 1]);
                self.tmp_x.scale_mut(c);
                for i in 0..n {
                    self.tmp_x[(i, i)] += 1.0;
                }
                self.tmp_d.copy_from(&self.dk_dd[s - 1]);
                self.tmp_d.scale_mut(c);
                let (a, tx, td) = (&self.a, &self.tmp_x, &self.tmp_d);
                self.dk_dx[s].gemm(1.0, a, tx, 0.0);
                self.dk_dd[s].copy_from(e);
                self.dk_dd[s].gemm(1.0, a, td, 1.0);
            }
        }
        for i in 0..n {
            x_next[i] = x[i] + h / 6.0 * (0..4).map(|s| WEIGHT[s] * self.k[s][i]).sum::<f64>();
        }
        for c in 0..n {
            for r in 0..n {
                let v: f64 = (0..4).map(|s| WEIGHT[s] * self.dk_dx[s][(r, c)]).sum();
                phi[c * n + r] = if r == c { 1.0 } else { 0.0 } + h / 6.0 * v;
            }
        }
        for c in 0..self.q {
            for r in 0..n {
                let v: f64 = (0..4).map(|s| WEIGHT[s] * self.dk_dd[s][(r, c)]).sum();
                gamma[c * n + r] = h / 6.0 * v;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Damped pendulum with pivot input and analytic Jacobians.
    struct Pendulum;
    impl Dynamics for Pendulum {
        fn n_states(&self) -> usize {
            2
        }
        fn n_inputs(&self) -> usize {
            1
        }
        fn rhs(&self, t: f64, x: &[f64], u: &[f64], dx: &mut [f64]) {
            dx[0] = x[1];
            dx[1] = -9.81 * x[0].sin() - 0.3 * x[1] - x[0].cos() * u[0] + 0.1 * t;
        }
        fn jacobians(
            &self,
            _t: f64,
            x: &[f64],
            u: &[f64],
            a: &mut DMatrix<f64>,
            b: &mut DMatrix<f64>,
        ) {
            a[(0, 0)] = 0.0;
            a[(0, 1)] = 1.0;
            a[(1, 0)] = -9.81 * x[0].cos() + x[0].sin() * u[0];
            a[(1, 1)] = -0.3;
            b[(0, 0)] = 0.0;
            b[(1, 0)] = -x[0].cos();
        }
    }

    #[test]
    fn chained_jacobians_match_central_differences() {
        let e = DMatrix::from_row_slice(2, 2, &[0.3, 0.0, 1.0, 0.5]);
        let mut rk = Rk4::new(2, 1, 2);
        let (t, h) = (0.4, 0.05);
        let (ua, ub) = ([0.7], [-1.9]);
        let held = StageInput::Held(&ua);
        let ramp = StageInput::Ramp {
            ua: &ua,
            ub: &ub,
            from: 0.25,
            per: 0.25,
        };
        let x = [0.9, -1.2];
        let d = [0.2, -0.4];
        for u in [held, ramp] {
            let (mut xn, mut phi, mut gam) = ([0.0; 2], [0.0; 4], [0.0; 4]);
            rk.step_jacobians(&Pendulum, &e, t, h, &x, &u, &d, &mut xn, &mut phi, &mut gam);
            let mut plain = x;
            rk.step(&Pendulum, &e, t, h, &mut plain, &u, &d);
            // Same arithmetic in both paths: equal to round-off.
            assert!(plain.iter().zip(&xn).all(|(a, b)| (a - b).abs() <= 1e-14));
            // Central differences: error ~ε^(2/3) relative for this smooth map.
            let eps = 1e-6;
            for c in 0..2 {
                let (mut xp, mut xm) = (x, x);
                xp[c] += eps;
                xm[c] -= eps;
                rk.step(&Pendulum, &e, t, h, &mut xp, &u, &d);
                rk.step(&Pendulum, &e, t, h, &mut xm, &u, &d);
                for r in 0..2 {
                    let fd = (xp[r] - xm[r]) / (2.0 * eps);
                    assert!(
                        (fd - phi[c * 2 + r]).abs() < 1e-8,
                        "Φ[{r},{c}] {fd} vs {}",
                        phi[c * 2 + r]
                    );
                }
                let (mut dp, mut dm) = (d, d);
                dp[c] += eps;
                dm[c] -= eps;
                let (mut xp, mut xm) = (x, x);
                rk.step(&Pendulum, &e, t, h, &mut xp, &u, &dp);
                rk.step(&Pendulum, &e, t, h, &mut xm, &u, &dm);
                for r in 0..2 {
                    let fd = (xp[r] - xm[r]) / (2.0 * eps);
                    assert!(
                        (fd - gam[c * 2 + r]).abs() < 1e-8,
                        "Γ[{r},{c}] {fd} vs {}",
                        gam[c * 2 + r]
                    );
                }
            }
        }
    }

    /// With `d = 0`, `s` steps with [`StageInput::Ramp`] over one sample interval are
    /// `sysid_core`'s first-order-hold RK4 with `s` sub-steps: the same stage times and
    /// inputs, so equal to round-off (a few ulps of the O(1) state).
    #[test]
    fn ramp_steps_match_sysid_core_first_order_hold() {
        let e = DMatrix::from_row_slice(2, 1, &[0.0, 1.0]);
        let mut rk = Rk4::new(2, 1, 1);
        let (ta, dt, s) = (0.3, 0.2, 4);
        let (ua, ub) = ([1.5], [-2.5]);
        let x0 = [0.9, -1.2];
        let mut ours = x0;
        let h = dt / s as f64;
        for i in 0..s {
            let u = StageInput::Ramp {
                ua: &ua,
                ub: &ub,
                from: i as f64 / s as f64,
                per: 1.0 / s as f64,
            };
            rk.step(&Pendulum, &e, ta + i as f64 * h, h, &mut ours, &u, &[0.0]);
        }
        let mut theirs = x0;
        let mut ws = sysid_core::integrate::Workspace::new(2);
        sysid_core::integrate::integrate_sample(
            &Pendulum,
            ta,
            ta + dt,
            &mut theirs,
            &ua,
            &ub,
            sysid_core::InterSample::Foh,
            &sysid_core::Integrator::Rk4 { substeps: s },
            &mut ws,
        )
        .unwrap();
        for (a, b) in ours.iter().zip(&theirs) {
            assert!((a - b).abs() < 1e-13, "{a} vs {b}");
        }
        // The held input differs visibly (ub − ua = −4 over 0.2 s).
        let mut held = x0;
        for i in 0..s {
            let u = StageInput::Held(&ua);
            rk.step(&Pendulum, &e, ta + i as f64 * h, h, &mut held, &u, &[0.0]);
        }
        assert!((held[1] - theirs[1]).abs() > 0.1);
    }
}
