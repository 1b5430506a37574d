//! The discrete map of the nonlinear assumed model over one sub-step — one step of
//! sysid-core's RK4 ([`sysid_core::tangent`]) of `ẋ = f(t, x, u) + E d` with `d` held and
//! `u` held or, for first-order-hold inputs, interpolated at each stage time
//! ([`StepInput`]) — and its Jacobians `Φ = ∂x⁺/∂x`, `Γ = ∂x⁺/∂d`: the step's tangents
//! from `S = [I | 0]` with the direct source `[0 | E]`, exact through the four stages.

use nalgebra::DMatrix;
use sysid_core::Dynamics;
use sysid_core::tangent::{self, StepInput, TangentSource};

/// `f + E d` with `E d` computed once per step.
struct Corrected<'a, F: ?Sized> {
    f: &'a F,
    ed: &'a [f64],
}

impl<F: Dynamics + ?Sized> Dynamics for Corrected<'_, F> {
    fn n_states(&self) -> usize {
        self.f.n_states()
    }
    fn n_inputs(&self) -> usize {
        self.f.n_inputs()
    }
    fn rhs(&self, t: f64, x: &[f64], u: &[f64], dx: &mut [f64]) {
        self.f.rhs(t, x, u, dx);
        dx.iter_mut().zip(self.ed).for_each(|(k, e)| *k += e);
    }
    fn jacobians(&self, t: f64, x: &[f64], u: &[f64], a: &mut DMatrix<f64>, b: &mut DMatrix<f64>) {
        self.f.jacobians(t, x, u, a, b);
    }
}

/// `∂(E d)/∂d = E` in the tangent columns after the `n` state ones.
struct HeldCorrection<'a>(&'a DMatrix<f64>);

impl TangentSource for HeldCorrection<'_> {
    fn add_to(&self, _: f64, _: &[f64], _: &[f64], out: &mut DMatrix<f64>) {
        let n = self.0.nrows();
        let mut block = out.columns_mut(n, self.0.ncols());
        block += self.0;
    }
}

/// Buffers for one step (no allocation per step).
pub(crate) struct Rk4 {
    n: usize,
    q: usize,
    ed: Vec<f64>,
    rk: tangent::Rk4,
    /// Tangents `[∂x/∂x | ∂x/∂d]`, `n × (n + q)`.
    s: DMatrix<f64>,
}

impl Rk4 {
    /// Buffers for `n` states, `m` inputs, `q` corrections.
    pub fn new(n: usize, m: usize, q: usize) -> Self {
        Self {
            n,
            q,
            ed: vec![0.0; n],
            rk: tangent::Rk4::new(n, m, n + q),
            s: DMatrix::zeros(n, n + q),
        }
    }

    fn set_correction(&mut self, e: &DMatrix<f64>, d: &[f64]) {
        for i in 0..self.n {
            self.ed[i] = (0..self.q).map(|c| e[(i, c)] * d[c]).sum();
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
        u: &StepInput,
        d: &[f64],
    ) {
        self.set_correction(e, d);
        let g = Corrected { f, ed: &self.ed };
        self.rk.step(&g, t, h, x, u);
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
        u: &StepInput,
        d: &[f64],
        x_next: &mut [f64],
        phi: &mut [f64],
        gamma: &mut [f64],
    ) {
        let n = self.n;
        self.set_correction(e, d);
        self.s.fill(0.0);
        self.s.fill_diagonal(1.0);
        x_next.copy_from_slice(x);
        let g = Corrected { f, ed: &self.ed };
        self.rk
            .step_with_tangents(&g, &HeldCorrection(e), t, h, x_next, &mut self.s, u);
        let s = self.s.as_slice();
        phi.copy_from_slice(&s[..n * n]);
        gamma.copy_from_slice(&s[n * n..]);
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
        let held = StepInput::Held(&ua);
        let ramp = StepInput::Ramp {
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

    /// With `d = 0`, `s` steps with [`StepInput::Ramp`] over one sample interval are
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
            let u = StepInput::Ramp {
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
            let u = StepInput::Held(&ua);
            rk.step(&Pendulum, &e, ta + i as f64 * h, h, &mut held, &u, &[0.0]);
        }
        assert!((held[1] - theirs[1]).abs() > 0.1);
    }
}
