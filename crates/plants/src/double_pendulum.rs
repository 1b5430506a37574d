//! Double compound pendulum (two uniform rods) on a horizontally accelerated pivot, with
//! viscous damping at the pivot and at the joint and optional (smoothed) Coulomb friction
//! at the joint (thesis §4.3; the friction makes it a stand-in for the §5.6 rig).
//! Equations derived here from the Lagrangian; the thesis's ignorance model (§4.3.2) and
//! the linearised physics model about the hanging equilibrium.
//!
//! # Derivation
//!
//! Coordinates: pivot at `(x_p(t), 0)` with `ẍ_p = u`; `θ1`, `θ2` are the rods' angles from
//! the downward vertical (positive counter-clockwise, so positive θ swings the rod towards
//! +x). Rod `i` has length `l_i`, mass `m_i`, centre of mass at `a_i = l_i/2` from its upper
//! end and centroidal inertia `I_i = m_i l_i²/12`. Centre-of-mass positions
//!
//! ```text
//! r1 = (x_p + a1 sin θ1,            −a1 cos θ1)
//! r2 = (x_p + l1 sin θ1 + a2 sin θ2, −l1 cos θ1 − a2 cos θ2)
//! ```
//!
//! Kinetic energy `T = Σ ½ m_i |ṙ_i|² + ½ I_i ω_i²`, which expands to
//!
//! ```text
//! T = ½ (m1+m2) ẋ_p² + ½ J1 ω1² + ½ J2 ω2² + K cos(θ1−θ2) ω1 ω2
//!     + ẋ_p (P1 cos θ1 ω1 + P2 cos θ2 ω2)
//! J1 = I1 + m1 a1² + m2 l1²,  J2 = I2 + m2 a2²,  K = m2 l1 a2,
//! P1 = m1 a1 + m2 l1,         P2 = m2 a2
//! ```
//!
//! potential energy `V = −g (P1 cos θ1 + P2 cos θ2)` and Rayleigh dissipation
//! `R = ½ c1 ω1² + ½ c2 (ω2 − ω1)²` (pivot damping `c1`, joint damping `c2` on the relative
//! rate), plus the joint's Coulomb torque `τ_f = tau_c2·tanh((ω2 − ω1)/eps)` (a
//! generalised force on the relative angle, entering exactly where `c2 (ω2 − ω1)` does;
//! default `tau_c2 = 0`). Lagrange's equations `d/dt ∂T/∂ω_i − ∂T/∂θ_i + ∂V/∂θ_i + ∂R/∂ω_i = 0` give, with
//! `Δ = θ1 − θ2` (the `ẋ_p sin θ_i ω_i` terms cancel between the two derivatives):
//!
//! ```text
//! J1 ω̇1 + K cos Δ ω̇2 = −K sin Δ ω2² − g P1 sin θ1 − P1 cos θ1 u − c1 ω1 + c2 (ω2 − ω1) + τ_f =: r1
//! K cos Δ ω̇1 + J2 ω̇2 =  K sin Δ ω1² − g P2 sin θ2 − P2 cos θ2 u − c2 (ω2 − ω1) − τ_f         =: r2
//! ```
//!
//! and, solving the 2×2 system by Cramer's rule (`det = J1 J2 − K² cos² Δ > 0` because
//! `J1 > m2 l1²` and `J2 > m2 a2²`):
//!
//! ```text
//! ω̇1 = (J2 r1 − K cos Δ r2) / det,    ω̇2 = (J1 r2 − K cos Δ r1) / det
//! ```
//!
//! The state order is the thesis's: `[θ1, θ2, ω1, ω2]` (x1…x4 of Figs. 4.21–4.30).
//!
//! Linearised about the hanging equilibrium (`θ = ω = u = 0`): `M0 q̈ + D q̇ + G q = −P u`
//! with `M0 = [[J1, K], [K, J2]]`, `D = [[c1 + c2, −c2], [−c2, c2]]`,
//! `G = g·diag(P1, P2)`, `P = [P1, P2]ᵀ`. The Coulomb term has no linearisation at rest
//! and is left out of it (as a physics model that does not know the friction would).

use std::collections::BTreeMap;

use nalgebra::{DMatrix, Matrix2, Vector2};
use sysid_core::{Dynamics, LinearModel};

use crate::error::{PlantError, Result};
use crate::params::{ParamInfo, Parameters, non_negative, param_table, positive};
use crate::signals::{Excitation, Sine};
use crate::system::Recipe;
use crate::system::{RecipeSpec, TruthSystem, selection_model, unit_map};

/// Registry name.
pub const NAME: &str = "double_pendulum";

/// Joint damping values (N·m·s/rad) of the thesis's five condition-monitoring classes
/// (§6.3; printed ".24, .27, .3, .33, .36" with lost digits, read as 0.024…0.036: ±20 %
/// around the default `c2 = 0.03`). For the default rods this is a strongly damped joint:
/// the linearised fast (joint) mode has damping ratio 0.54…0.80, the slow mode 0.017.
pub const JOINT_DAMPING_CLASSES: [f64; 5] = [0.024, 0.027, 0.030, 0.033, 0.036];

/// State names in order.
pub const STATES: [&str; 4] = ["theta1", "theta2", "omega1", "omega2"];

/// Physical parameters of [`DoublePendulum`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DoublePendulumParams {
    /// Upper rod mass, kg.
    pub m1: f64,
    /// Upper rod length (pivot to joint), m.
    pub l1: f64,
    /// Lower rod mass, kg.
    pub m2: f64,
    /// Lower rod length, m.
    pub l2: f64,
    /// Viscous damping at the pivot, N·m·s/rad.
    pub c1: f64,
    /// Viscous damping at the joint (on the relative rate ω2 − ω1), N·m·s/rad; set from
    /// [`JOINT_DAMPING_CLASSES`] for condition monitoring.
    pub c2: f64,
    /// Coulomb friction torque at the joint, N·m (opposes the relative rate ω2 − ω1;
    /// default 0, i.e. none).
    pub tau_c2: f64,
    /// Velocity scale of the smoothed joint friction `tau_c2·tanh((ω2 − ω1)/eps)`, rad/s
    /// (default 1e-3: above ~3·eps it is Coulomb friction to 0.5 %).
    pub eps: f64,
    /// Gravitational acceleration, m/s².
    pub g: f64,
}

impl Default for DoublePendulumParams {
    /// m1 = 0.4 kg, l1 = 0.3 m, m2 = 0.3 kg, l2 = 0.25 m, c1 = 0.01, c2 = 0.03 N·m·s/rad
    /// (middle class), no joint Coulomb friction (tau_c2 = 0, eps = 1e-3 rad/s),
    /// g = 9.81 m/s². Linear modes at about 5.1 and 13.2 rad/s.
    fn default() -> Self {
        Self {
            m1: 0.4,
            l1: 0.3,
            m2: 0.3,
            l2: 0.25,
            c1: 0.01,
            c2: 0.03,
            tau_c2: 0.0,
            eps: 1e-3,
            g: 9.81,
        }
    }
}

param_table!(
    DoublePendulumParams,
    NAME,
    [
        (m1, "kg"),
        (l1, "m"),
        (m2, "kg"),
        (l2, "m"),
        (c1, "N*m*s/rad"),
        (c2, "N*m*s/rad"),
        (tau_c2, "N*m"),
        (eps, "rad/s"),
        (g, "m/s^2")
    ]
);

/// Lumped constants of the equations of motion (see the module derivation).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DoublePendulumConstants {
    /// `J1 = I1 + m1 a1² + m2 l1²`, kg·m².
    pub j1: f64,
    /// `J2 = I2 + m2 a2²`, kg·m².
    pub j2: f64,
    /// `K = m2 l1 a2`, kg·m².
    pub k: f64,
    /// `P1 = m1 a1 + m2 l1`, kg·m.
    pub p1: f64,
    /// `P2 = m2 a2`, kg·m.
    pub p2: f64,
}

/// The double pendulum truth system. See the module documentation for the equations.
///
/// Its assumed model ([`TruthSystem::assumed_model`]) is the thesis's ignorance model
/// (eq. 4.28): only the kinematic rows `θ̇_i = ω_i`, zero dynamics rows, both angles
/// measured, both velocity equations corrected, so the truth correction is the full
/// angular acceleration `[ω̇1, ω̇2]`. [`DoublePendulum::linearised_model`] gives the
/// physics model about the hanging equilibrium (use [`crate::model_error`] for its
/// correction).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct DoublePendulum {
    params: DoublePendulumParams,
}

impl DoublePendulum {
    /// Build from parameters: masses, lengths, `eps`, `g` positive, dampings and friction
    /// non-negative.
    pub fn new(params: DoublePendulumParams) -> Result<Self> {
        positive(NAME, "m1", params.m1)?;
        positive(NAME, "l1", params.l1)?;
        positive(NAME, "m2", params.m2)?;
        positive(NAME, "l2", params.l2)?;
        non_negative(NAME, "c1", params.c1)?;
        non_negative(NAME, "c2", params.c2)?;
        non_negative(NAME, "tau_c2", params.tau_c2)?;
        positive(NAME, "eps", params.eps)?;
        positive(NAME, "g", params.g)?;
        Ok(Self { params })
    }

    /// The parameters.
    pub fn params(&self) -> &DoublePendulumParams {
        &self.params
    }

    /// The lumped constants `J1, J2, K, P1, P2`.
    pub fn constants(&self) -> DoublePendulumConstants {
        let DoublePendulumParams { m1, l1, m2, l2, .. } = self.params;
        let (a1, a2) = (l1 / 2.0, l2 / 2.0);
        DoublePendulumConstants {
            j1: m1 * l1 * l1 / 12.0 + m1 * a1 * a1 + m2 * l1 * l1,
            j2: m2 * l2 * l2 / 12.0 + m2 * a2 * a2,
            k: m2 * l1 * a2,
            p1: m1 * a1 + m2 * l1,
            p2: m2 * a2,
        }
    }

    /// Mechanical energy in the pivot frame, `T + V` with the pivot at rest, J
    /// (conserved when `c1 = c2 = tau_c2 = 0` and `u = 0`).
    pub fn energy(&self, x: &[f64]) -> f64 {
        let DoublePendulumConstants { j1, j2, k, p1, p2 } = self.constants();
        let g = self.params.g;
        let (t1, t2, w1, w2) = (x[0], x[1], x[2], x[3]);
        0.5 * j1 * w1 * w1 + 0.5 * j2 * w2 * w2 + k * (t1 - t2).cos() * w1 * w2
            - g * (p1 * t1.cos() + p2 * t2.cos())
    }

    /// The thesis's ignorance model (eq. 4.28): `θ̇_i = ω_i`, `ω̇_i = 0` (+ corrections).
    pub fn ignorance_model(&self) -> Result<LinearModel> {
        let mut a = DMatrix::zeros(4, 4);
        a[(0, 2)] = 1.0;
        a[(1, 3)] = 1.0;
        let b = DMatrix::zeros(4, 1);
        selection_model(a, b, &STATES, &["u"], &STATES[..2], &STATES[2..])
    }

    /// The linearised physics model about the hanging equilibrium (module docs), with
    /// the same names, measurements and corrections as the ignorance model. It has no
    /// joint Coulomb friction (not linearisable at rest).
    pub fn linearised_model(&self) -> Result<LinearModel> {
        let DoublePendulumConstants { j1, j2, k, p1, p2 } = self.constants();
        let DoublePendulumParams { c1, c2, g, .. } = self.params;
        let m0 = Matrix2::new(j1, k, k, j2);
        let inv = m0.try_inverse().ok_or(PlantError::InvalidParameter {
            system: NAME,
            name: "m1".to_string(),
            value: self.params.m1,
            reason: "mass matrix is singular",
        })?;
        let stiff = -inv * Matrix2::new(g * p1, 0.0, 0.0, g * p2);
        let damp = -inv * Matrix2::new(c1 + c2, -c2, -c2, c2);
        let inp = -inv * Vector2::new(p1, p2);
        let mut a = DMatrix::zeros(4, 4);
        a[(0, 2)] = 1.0;
        a[(1, 3)] = 1.0;
        let mut b = DMatrix::zeros(4, 1);
        for i in 0..2 {
            for j in 0..2 {
                a[(2 + i, j)] = stiff[(i, j)];
                a[(2 + i, 2 + j)] = damp[(i, j)];
            }
            b[(2 + i, 0)] = inp[i];
        }
        selection_model(a, b, &STATES, &["u"], &STATES[..2], &STATES[2..])
    }

    /// Joint friction torque `c2 (ω2 − ω1) + tau_c2·tanh((ω2 − ω1)/eps)` at relative rate
    /// `rel = ω2 − ω1`, N·m (acts on the lower rod with a minus sign, on the upper with a
    /// plus sign).
    pub fn joint_torque(&self, rel: f64) -> f64 {
        let DoublePendulumParams {
            c2, tau_c2, eps, ..
        } = self.params;
        c2 * rel + tau_c2 * (rel / eps).tanh()
    }

    /// Angular accelerations `[ω̇1, ω̇2]` at state `x` and pivot acceleration `u`.
    pub fn accelerations(&self, x: &[f64], u: f64) -> [f64; 2] {
        let DoublePendulumConstants { j1, j2, k, p1, p2 } = self.constants();
        let DoublePendulumParams { c1, g, .. } = self.params;
        let (t1, t2, w1, w2) = (x[0], x[1], x[2], x[3]);
        let (s, c) = (t1 - t2).sin_cos();
        let joint = self.joint_torque(w2 - w1);
        let r1 = -k * s * w2 * w2 - g * p1 * t1.sin() - p1 * t1.cos() * u - c1 * w1 + joint;
        let r2 = k * s * w1 * w1 - g * p2 * t2.sin() - p2 * t2.cos() * u - joint;
        let det = j1 * j2 - k * k * c * c;
        [(j2 * r1 - k * c * r2) / det, (j1 * r2 - k * c * r1) / det]
    }
}

impl Dynamics for DoublePendulum {
    fn n_states(&self) -> usize {
        4
    }
    fn n_inputs(&self) -> usize {
        1
    }
    fn rhs(&self, _t: f64, x: &[f64], u: &[f64], dx: &mut [f64]) {
        let [a1, a2] = self.accelerations(x, u[0]);
        dx[0] = x[2];
        dx[1] = x[3];
        dx[2] = a1;
        dx[3] = a2;
    }
}

impl TruthSystem for DoublePendulum {
    fn name(&self) -> &'static str {
        NAME
    }
    fn description(&self) -> &'static str {
        "double compound pendulum (two uniform rods), pivot acceleration input, damping at \
         pivot and joint, optional joint Coulomb friction; both angles measured; ignorance \
         model assumed (thesis 4.3)"
    }
    fn parameters(&self) -> Vec<ParamInfo> {
        self.params.list()
    }
    /// 100 Hz.
    fn default_fs(&self) -> f64 {
        100.0
    }
    /// 1e-6 rad² per angle (σ = 1 mrad): the thesis's simulation is essentially clean.
    fn default_noise_variance(&self) -> Vec<f64> {
        vec![1e-6, 1e-6]
    }
    fn assumed_model(&self) -> Result<LinearModel> {
        self.ignorance_model()
    }
    fn truth_correction(&self, x: &[f64], u: &[f64], d: &mut [f64]) {
        let acc = self.accelerations(x, u[0]);
        d.copy_from_slice(&acc);
    }
    fn units(&self) -> BTreeMap<String, String> {
        unit_map(
            &[
                ("theta1", "rad", "rad/s"),
                ("theta2", "rad", "rad/s"),
                ("omega1", "rad/s", "rad/s^2"),
                ("omega2", "rad/s", "rad/s^2"),
            ],
            &[("u", "m/s^2")],
        )
    }
    /// The single pendulum's inputs (as the thesis does): train `u = 5 sin(2 t)` from
    /// `[0.5, 0.8, 0, 0]`, test `u = −4 sin(3.2 t)` from `[−0.3, 0.2, 0, 0]`, 20 s each.
    fn recipe(&self, recipe: Recipe) -> RecipeSpec {
        let (x0, amplitude, omega) = match recipe {
            Recipe::Train => (vec![0.5, 0.8, 0.0, 0.0], 5.0, 2.0),
            Recipe::Test => (vec![-0.3, 0.2, 0.0, 0.0], -4.0, 3.2),
        };
        RecipeSpec {
            x0,
            inputs: vec![Excitation::Sine(Sine {
                amplitude,
                omega,
                ..Sine::default()
            })],
            duration: 20.0,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testutil::random_point;
    use nalgebra::DVector;
    use rand::rngs::ChaCha8Rng;
    use rand::{RngExt, SeedableRng};
    use sysid_core::integrate::DEFAULT_BLOW_UP;
    use sysid_core::{DpOptions, Integrator, simulate};

    /// Accelerations by a different route: projected Newton–Euler (Kane's method). Each
    /// rod's centre-of-mass acceleration is `J_i q̈ + h_i + (u, 0)` with `J_i` the 2×2
    /// position Jacobian and `h_i` the velocity-product (centripetal) terms taken from the
    /// kinematics; projecting Newton's and Euler's laws with `J_iᵀ` gives
    /// `[Σ m_i J_iᵀ J_i + diag(I1, I2)] q̈ = −Σ m_i J_iᵀ (h_i + (u, g)) − ∂R/∂q̇`,
    /// solved here by LU.
    fn kane_accelerations(p: &DoublePendulumParams, x: &[f64], u: f64) -> DVector<f64> {
        let (t1, t2, w1, w2) = (x[0], x[1], x[2], x[3]);
        let (a1, a2) = (p.l1 / 2.0, p.l2 / 2.0);
        let (i1, i2) = (p.m1 * p.l1 * p.l1 / 12.0, p.m2 * p.l2 * p.l2 / 12.0);
        let jac1 = DMatrix::from_row_slice(2, 2, &[a1 * t1.cos(), 0.0, a1 * t1.sin(), 0.0]);
        let jac2 = DMatrix::from_row_slice(
            2,
            2,
            &[
                p.l1 * t1.cos(),
                a2 * t2.cos(),
                p.l1 * t1.sin(),
                a2 * t2.sin(),
            ],
        );
        let h1 = DVector::from_vec(vec![-a1 * t1.sin() * w1 * w1, a1 * t1.cos() * w1 * w1]);
        let h2 = DVector::from_vec(vec![
            -p.l1 * t1.sin() * w1 * w1 - a2 * t2.sin() * w2 * w2,
            p.l1 * t1.cos() * w1 * w1 + a2 * t2.cos() * w2 * w2,
        ]);
        let ext = DVector::from_vec(vec![u, p.g]);
        let mass = jac1.transpose() * &jac1 * p.m1
            + jac2.transpose() * &jac2 * p.m2
            + DMatrix::from_diagonal(&DVector::from_vec(vec![i1, i2]));
        // Joint friction as a torque pair: +τ on the upper rod, −τ on the lower.
        let tau = p.c2 * (w2 - w1) + p.tau_c2 * ((w2 - w1) / p.eps).tanh();
        let damping = DVector::from_vec(vec![p.c1 * w1 - tau, tau]);
        let rhs = -(jac1.transpose() * (h1 + &ext) * p.m1)
            - jac2.transpose() * (h2 + &ext) * p.m2
            - damping;
        mass.lu()
            .solve(&rhs)
            .expect("mass matrix is positive definite")
    }

    /// 500 random states/inputs over the full angle range: the closed form and Kane's
    /// method agree to 1e-10 relative to the acceleration scale (both are exact; the
    /// difference is round-off of O(10) flops on O(100) magnitudes).
    #[test]
    fn closed_form_matches_kanes_method() {
        let mut rng = ChaCha8Rng::seed_from_u64(2015);
        let pi = std::f64::consts::PI;
        for case in 0..500 {
            let params = DoublePendulumParams {
                m1: 0.1 + rng.random::<f64>(),
                l1: 0.1 + rng.random::<f64>(),
                m2: 0.1 + rng.random::<f64>(),
                l2: 0.1 + rng.random::<f64>(),
                c1: 0.05 * rng.random::<f64>(),
                c2: 0.05 * rng.random::<f64>(),
                tau_c2: 0.05 * rng.random::<f64>(),
                eps: 0.01 + rng.random::<f64>(),
                g: 9.81,
            };
            let p = DoublePendulum::new(params).unwrap();
            let x = random_point(
                &mut rng,
                &[(-pi, pi), (-pi, pi), (-10.0, 10.0), (-10.0, 10.0)],
            );
            let u = random_point(&mut rng, &[(-20.0, 20.0)])[0];
            let closed = p.accelerations(&x, u);
            let kane = kane_accelerations(&params, &x, u);
            let scale = kane.amax().max(1.0);
            for i in 0..2 {
                assert!(
                    (closed[i] - kane[i]).abs() < 1e-10 * scale,
                    "case {case}: {closed:?} vs {kane}"
                );
            }
        }
    }

    /// Undamped and unforced, `T + V` is conserved. Tolerance as for the single pendulum
    /// (DP at rtol 1e-10 over ~10⁴ steps), relative to the energy scale `g (P1 + P2)`,
    /// from a large-swing start (θ = 1.2, −0.8 rad) where the motion is irregular.
    #[test]
    fn undamped_unforced_conserves_energy() {
        let p = DoublePendulum::new(DoublePendulumParams {
            c1: 0.0,
            c2: 0.0,
            ..DoublePendulumParams::default()
        })
        .unwrap();
        let opts = DpOptions {
            rtol: 1e-10,
            atol: 1e-12,
            ..DpOptions::default()
        };
        let x0 = [1.2, -0.8, 0.0, 0.0];
        let u = DMatrix::zeros(1, 2001);
        let x = simulate(
            &p,
            &x0,
            0.0,
            0.01,
            &u,
            &Integrator::DormandPrince(opts),
            DEFAULT_BLOW_UP,
        )
        .unwrap();
        let c = p.constants();
        let scale = p.params.g * (c.p1 + c.p2);
        let e0 = p.energy(&x0);
        for k in 0..x.ncols() {
            let e = p.energy(x.column(k).as_slice());
            assert!(
                (e - e0).abs() < 1e-7 * scale,
                "sample {k}: drift {}",
                e - e0
            );
        }
        // The motion really is large: the lower rod swings beyond 1 rad.
        assert!(x.row(1).amax() > 1.0);
    }

    /// Joint Coulomb friction only (c1 = c2 = 0, u = 0): the energy lost up to each sample
    /// equals the work of the friction torque, `∫ tau_c2·Δω·tanh(Δω/eps) dt` with
    /// `Δω = ω2 − ω1` (power balance, independent of how the torque enters the equations
    /// of motion). The integral is the trapezoid rule on 1e-4 s samples; with the corner
    /// smoothed by eps = 0.05 rad/s the integrand's second derivative stays below ~1e4
    /// W/s², so the rule's error is below dt²/12·T·1e4 ≈ 2e-5 J over 2 s; the bound used
    /// is 1e-4 of the energy scale g (P1 + P2) ≈ 1.8 J. The friction must really act:
    /// at least 5 % of that scale is dissipated.
    #[test]
    fn joint_coulomb_friction_dissipates_its_work() {
        let (tau_c2, eps) = (0.02, 0.05);
        let p = DoublePendulum::new(DoublePendulumParams {
            c1: 0.0,
            c2: 0.0,
            tau_c2,
            eps,
            ..DoublePendulumParams::default()
        })
        .unwrap();
        let opts = DpOptions {
            rtol: 1e-11,
            atol: 1e-13,
            ..DpOptions::default()
        };
        let (dt, n) = (1e-4, 20_001);
        let x0 = [1.2, -0.8, 0.0, 0.0];
        let u = DMatrix::zeros(1, n);
        let x = simulate(
            &p,
            &x0,
            0.0,
            dt,
            &u,
            &Integrator::DormandPrince(opts),
            DEFAULT_BLOW_UP,
        )
        .unwrap();
        let c = p.constants();
        let scale = p.params.g * (c.p1 + c.p2);
        let power = |k: usize| {
            let rel = x[(3, k)] - x[(2, k)];
            tau_c2 * rel * (rel / eps).tanh()
        };
        let e0 = p.energy(&x0);
        let mut work = 0.0;
        for k in 1..n {
            work += 0.5 * dt * (power(k - 1) + power(k));
            let lost = e0 - p.energy(x.column(k).as_slice());
            assert!(
                (lost - work).abs() < 1e-4 * scale,
                "sample {k}: energy lost {lost}, friction work {work}"
            );
        }
        assert!(work > 0.05 * scale, "friction work {work} is too small");
    }

    /// With the default `tau_c2 = 0` the accelerations are exactly those of the viscous
    /// model: adding the parameter changed no existing result.
    #[test]
    fn zero_coulomb_friction_changes_nothing() {
        let p = DoublePendulum::default();
        let x = [0.3, -0.2, 1.5, -2.5];
        let [a1, a2] = p.accelerations(&x, 1.7);
        // The pre-friction closed form, written out.
        let DoublePendulumConstants { j1, j2, k, p1, p2 } = p.constants();
        let DoublePendulumParams { c1, c2, g, .. } = *p.params();
        let (s, cd) = (x[0] - x[1]).sin_cos();
        let r1 = -k * s * x[3] * x[3] - g * p1 * x[0].sin() - p1 * x[0].cos() * 1.7 - c1 * x[2]
            + c2 * (x[3] - x[2]);
        let r2 =
            k * s * x[2] * x[2] - g * p2 * x[1].sin() - p2 * x[1].cos() * 1.7 - c2 * (x[3] - x[2]);
        let det = j1 * j2 - k * k * cd * cd;
        assert_eq!(a1.to_bits(), ((j2 * r1 - k * cd * r2) / det).to_bits());
        assert_eq!(a2.to_bits(), ((j1 * r2 - k * cd * r1) / det).to_bits());
    }

    /// The linearised model's A and B equal the truth's Jacobian at the hanging
    /// equilibrium, taken by central differences of the closed form (step 1e-6, error
    /// ~1e-11 here); 1e-7 relative to the entry scale.
    #[test]
    fn linearised_model_is_the_jacobian_at_rest() {
        let p = DoublePendulum::default();
        let model = p.linearised_model().unwrap();
        let h = 1e-6;
        let mut fp = [0.0; 4];
        let mut fm = [0.0; 4];
        for j in 0..5 {
            let mut xp = [0.0; 4];
            let mut xm = [0.0; 4];
            let (mut up, mut um) = ([0.0], [0.0]);
            if j < 4 {
                xp[j] = h;
                xm[j] = -h;
            } else {
                up[0] = h;
                um[0] = -h;
            }
            p.rhs(0.0, &xp, &up, &mut fp);
            p.rhs(0.0, &xm, &um, &mut fm);
            for i in 0..4 {
                let fd = (fp[i] - fm[i]) / (2.0 * h);
                let an = if j < 4 {
                    model.a()[(i, j)]
                } else {
                    model.b()[(i, 0)]
                };
                assert!(
                    (fd - an).abs() < 1e-7 * an.abs().max(1.0),
                    "({i}, {j}): {an} vs {fd}"
                );
            }
        }
    }
}
