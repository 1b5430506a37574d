//! The exact linear–quadratic sweep: backward cost-to-go (information-form Riccati)
//! recursion, minimisation over the free initial state, forward pass for `d̂` and `x̂`.
//!
//! Discrete problem (one experiment, `N` samples, `s` sub-steps, `h = dt/s`):
//!
//! `x_{j+1} = Φ_j x_j + Γ_j d_j + c_j`, `j = 0 … (N−1)s − 1`,
//!
//! `J = Σ_k Σ_{i observed} (ỹ_{k,i} − (C x_{ks})_i)² / R_i + Σ_j h d_jᵀ W d_j`,
//!
//! minimised over the free `x_0` and every `d_j`. The cost-to-go from sub-step `j` is
//! `V_j(x) = xᵀP_j x − 2q_jᵀx + const`. Eliminating `d_j` (a `q × q` Cholesky of
//! `S_j = hW + Γ_jᵀP_{j+1}Γ_j`) and then substituting the dynamics gives
//!
//! `P̃ = P − PΓS⁻¹ΓᵀP`, `q̃ = q − PΓS⁻¹Γᵀq`, `P_j = ΦᵀP̃Φ`, `q_j = Φᵀ(q̃ − P̃c)`,
//!
//! plus `CᵀR⁻¹C` and `CᵀR⁻¹ỹ` (observed channels only) at each sample. At `j = 0` the
//! free initial state minimises `V_0`; a Gaussian prior `x_0 ~ N(m, Π⁻¹)` adds
//! `(x_0 − m)ᵀΠ(x_0 − m)` to `J`, i.e. `P_0 ← P_0 + Π`, `q_0 ← q_0 + Πm` (the
//! information-form initial condition of the backward sweep; `Π = 0` is the diffuse case). The optimal
//! correction is the affine policy `d_j = f_j − F_j x_j` with `F_j = S⁻¹ΓᵀPΦ` and
//! `f_j = S⁻¹Γᵀ(q − Pc)`. The result is the exact least-squares optimum (a diffuse-prior
//! Rauch–Tung–Striebel smoother; e.g. Bryson & Ho, *Applied Optimal Control*, ch. 13).
//!
//! Because the elimination is block Gaussian elimination of the Hessian `2A` of `J`,
//! `log det A = Σ_j log det S_j + log det P_0`; [`crate::noise`] uses this for the exact
//! marginal likelihood.
//!
//! The kernel ([`crate::kernel`], which also runs the sweep) is generic over nalgebra dimensions and uses only in-place operations on
//! buffers allocated once per call, so it never allocates per step; small sizes
//! (`n = 2, 4`) run on fixed-size matrices.

use nalgebra::{DMatrix, Dim, Matrix, MatrixView, StorageMut};

use crate::config::Prior;

/// The measured side of one experiment's problem.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Problem<'a> {
    /// States `n`.
    pub n: usize,
    /// Corrections `q`.
    pub q: usize,
    /// Samples `N` (≥ 1).
    pub samples: usize,
    /// Sub-steps per sample interval `s` (≥ 1).
    pub substeps: usize,
    /// Sub-step length `h`, s.
    pub h: f64,
    /// Weight `W`, `q × q` (per unit time).
    pub w: &'a DMatrix<f64>,
    /// Output matrix `C`, `p × n`.
    pub c: &'a DMatrix<f64>,
    /// `1/R_i` per model output.
    pub inv_r: &'a [f64],
    /// The dataset's outputs of this experiment (`p_data × N`, NaN = missing).
    pub outputs: &'a DMatrix<f64>,
    /// Model output `i` is dataset output row `out_map[i]`.
    pub out_map: &'a [usize],
    /// Experiment index, for errors.
    pub experiment: usize,
    /// Time of the first sample, s (for errors).
    pub t0: f64,
    /// Whether the steady-state shortcut may be used (time-invariant steps only).
    pub steady: SteadyState,
    /// Gaussian prior on `x_0` (`None`: free, diffuse). It adds `Π = diag(info)` to
    /// `P_0` and `Π m` to `q_0` before the minimisation over `x_0`.
    pub prior: Option<&'a Prior>,
}

/// Whether the backward pass may switch to the steady-state gains once the Riccati
/// recursion has converged (see [`crate::kernel`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum SteadyState {
    /// Use it where valid (time-invariant steps, unchanged observation pattern).
    Allow,
    /// Always run the full recursion (reference for tests; time-varying steps).
    #[cfg_attr(not(test), allow(dead_code))]
    Never,
}

impl Problem<'_> {
    /// Number of correction pieces `(N−1)·s`.
    pub fn pieces(&self) -> usize {
        self.samples.saturating_sub(1) * self.substeps
    }
}

/// Where the step matrices come from.
#[derive(Debug, Clone, Copy)]
pub(crate) enum StepModel<'a> {
    /// Time-invariant `Φ = Ad`, `Γ = Ed`; offset `c_j = Bd u_k` with the input held per
    /// sample, or, with a ramp gain `Γ₂` (first-order hold), `c_j = Bd u(t_j) +
    /// Γ₂ (u(t_j + h) − u(t_j))` with `u` linear between samples.
    Lti {
        /// `Ad`, `n × n`.
        ad: &'a DMatrix<f64>,
        /// `Ed`, `n × q`.
        ed: &'a DMatrix<f64>,
        /// `Bd`, `n × m`.
        bd: &'a DMatrix<f64>,
        /// The dataset's inputs of this experiment (`m_data × N`).
        inputs: &'a DMatrix<f64>,
        /// Model input `l` is dataset input row `in_map[l]`.
        in_map: &'a [usize],
        /// `Γ₂`, `n × m`, when the inputs are interpolated linearly between samples
        /// (`None`: held).
        ramp: Option<&'a DMatrix<f64>>,
    },
    /// Time-varying: column-major `Φ_j` (`n²` each), `Γ_j` (`n·q` each), `c_j` (`n` each).
    Tv {
        /// All `Φ_j`.
        phi: &'a [f64],
        /// All `Γ_j`.
        gamma: &'a [f64],
        /// All `c_j`.
        offset: &'a [f64],
    },
}

/// Whether the backward pass accumulates `log det S_j` (needed by the likelihood only).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum LogDet {
    /// Skip the logarithms.
    Skip,
    /// Accumulate `Σ log det S_j` and `log det P_0`.
    Accumulate,
}

/// Buffers reused across sweeps. Both are stacks: the backward pass pushes in descending
/// step order and the forward pass reads them back from the end.
#[derive(Debug, Clone, Default)]
pub(crate) struct Workspace {
    /// `F_j` (`q × n`, column-major) of every step not covered by a steady-state table.
    pub(crate) gains: Vec<f64>,
    /// `f_j` (`q`) of every step.
    pub(crate) feed: Vec<f64>,
}

/// What a sweep returns besides the trajectories it writes.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct SweepOut {
    /// Sum of squared residuals per model output (observed samples only).
    pub sse: Vec<f64>,
    /// Observed samples per model output.
    pub count: Vec<usize>,
    /// `Σ_j h d_jᵀ W d_j`.
    pub correction_cost: f64,
    /// `Σ_j log det S_j` (0 unless [`LogDet::Accumulate`]).
    pub logdet_s: f64,
    /// `log det P_0` (0 unless [`LogDet::Accumulate`]); with a prior, of `P_0 + Π`.
    pub logdet_p0: f64,
    /// The prior's share of `J`, `(x_0 − m)ᵀΠ(x_0 − m)` (0 without a prior).
    pub prior_cost: f64,
    /// Steps run on steady-state gains.
    pub steady_steps: usize,
}

impl SweepOut {
    /// `J` = weighted misfit + correction cost (+ the prior's share, if any).
    pub fn cost(&self, inv_r: &[f64]) -> f64 {
        let j = self.sse.iter().zip(inv_r).map(|(s, w)| s * w).sum::<f64>() + self.correction_cost;
        if self.prior_cost == 0.0 {
            j
        } else {
            j + self.prior_cost
        }
    }
}

/// The gains `(F_j, f_j)` of step `j` from the last sweep of a time-varying problem with
/// `steps` steps (no steady-state tables), for the nonlinear closed-loop rollout: the
/// optimal correction of the linearised problem is `d = f_j − F_j x` (`F_j` is `q × n`,
/// column-major).
pub(crate) fn gains(
    ws: &Workspace,
    steps: usize,
    n: usize,
    q: usize,
    j: usize,
) -> (&[f64], &[f64]) {
    let slot = steps - 1 - j;
    (
        &ws.gains[slot * q * n..(slot + 1) * q * n],
        &ws.feed[slot * q..(slot + 1) * q],
    )
}

/// Step matrices of a problem, by sub-step index.
pub(crate) trait Steps<D: Dim, Q: Dim> {
    /// Whether `Φ_j`, `Γ_j` are the same for every step.
    const TIME_INVARIANT: bool;
    /// `Φ_j`.
    fn phi(&self, j: usize) -> MatrixView<'_, f64, D, D>;
    /// `Γ_j`.
    fn gamma(&self, j: usize) -> MatrixView<'_, f64, D, Q>;
    /// `c_j`, written into `out` (`n` long).
    fn offset(&self, j: usize, out: &mut [f64]);
}

/// In-place lower Cholesky factor of a symmetric matrix (upper triangle left as is).
/// Returns `Σ log L_ii²` or the failing pivot and its value relative to `max_i |m_ii|`.
pub(crate) fn cholesky_in_place<R: Dim, S: StorageMut<f64, R, R>>(
    m: &mut Matrix<f64, R, R, S>,
    relative_floor: f64,
) -> std::result::Result<f64, (usize, f64)> {
    let n = m.nrows();
    let mut scale = 0.0_f64;
    for i in 0..n {
        scale = scale.max(m[(i, i)].abs());
    }
    let mut logdet = 0.0;
    for j in 0..n {
        let mut djj = m[(j, j)];
        for k in 0..j {
            djj -= m[(j, k)] * m[(j, k)];
        }
        let positive = djj > relative_floor * scale;
        if !positive || !djj.is_finite() {
            return Err((j, if scale > 0.0 { djj / scale } else { djj }));
        }
        let ljj = djj.sqrt();
        m[(j, j)] = ljj;
        logdet += djj.ln();
        for i in j + 1..n {
            let mut v = m[(i, j)];
            for k in 0..j {
                v -= m[(i, k)] * m[(j, k)];
            }
            m[(i, j)] = v / ljj;
        }
    }
    Ok(logdet)
}

/// `B ← L⁻¹ B` for lower-triangular `L` (stored in the lower triangle of `l`).
pub(crate) fn forward_sub<R: Dim, C: Dim, S1, S2>(
    l: &Matrix<f64, R, R, S1>,
    b: &mut Matrix<f64, R, C, S2>,
) where
    S1: nalgebra::Storage<f64, R, R>,
    S2: StorageMut<f64, R, C>,
{
    let n = l.nrows();
    for c in 0..b.ncols() {
        for i in 0..n {
            let mut v = b[(i, c)];
            for k in 0..i {
                v -= l[(i, k)] * b[(k, c)];
            }
            b[(i, c)] = v / l[(i, i)];
        }
    }
}

/// `B ← L⁻ᵀ B` for lower-triangular `L`.
pub(crate) fn backward_sub<R: Dim, C: Dim, S1, S2>(
    l: &Matrix<f64, R, R, S1>,
    b: &mut Matrix<f64, R, C, S2>,
) where
    S1: nalgebra::Storage<f64, R, R>,
    S2: StorageMut<f64, R, C>,
{
    let n = l.nrows();
    for c in 0..b.ncols() {
        for i in (0..n).rev() {
            let mut v = b[(i, c)];
            for k in i + 1..n {
                v -= l[(k, i)] * b[(k, c)];
            }
            b[(i, c)] = v / l[(i, i)];
        }
    }
}

pub(crate) fn symmetrize<D: Dim, S: StorageMut<f64, D, D>>(m: &mut Matrix<f64, D, D, S>) {
    let n = m.nrows();
    for i in 0..n {
        for j in 0..i {
            let v = 0.5 * (m[(i, j)] + m[(j, i)]);
            m[(i, j)] = v;
            m[(j, i)] = v;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kernel::sweep;
    use sysid_core::LinearModel;

    /// A damped oscillator, position measured, velocity corrected, 4000 samples with two
    /// gaps; returns states, corrections and the sweep summary.
    fn solve(steady: SteadyState, s: usize) -> (Vec<f64>, Vec<f64>, SweepOut) {
        let model = LinearModel::new(
            DMatrix::from_row_slice(2, 2, &[0.0, 1.0, -4.0, -0.2]),
            DMatrix::from_row_slice(2, 1, &[0.0, 1.0]),
            DMatrix::from_row_slice(1, 2, &[1.0, 0.0]),
            DMatrix::from_row_slice(2, 1, &[0.0, 1.0]),
        )
        .unwrap();
        let len = 4000;
        let dt = 0.02;
        let h = dt / s as f64;
        let z = model.discretize(h).unwrap();
        let mut y = DMatrix::from_fn(1, len, |_, k| {
            let t = k as f64 * dt;
            (1.3 * t).sin() + 0.05 * ((k * 7919 % 101) as f64 / 50.0 - 1.0)
        });
        for k in (1000..1010).chain([2500, 2502, len - 1]) {
            y[(0, k)] = f64::NAN;
        }
        let u = DMatrix::from_fn(1, len, |_, k| (0.37 * k as f64 * dt).cos());
        let w = DMatrix::from_element(1, 1, 5.0);
        let pr = Problem {
            n: 2,
            q: 1,
            samples: len,
            substeps: s,
            h,
            w: &w,
            c: model.c(),
            inv_r: &[400.0],
            outputs: &y,
            out_map: &[0],
            experiment: 0,
            t0: 0.0,
            steady,
            prior: None,
        };
        let steps = StepModel::Lti {
            ad: &z.ad,
            ed: &z.ed,
            bd: &z.bd,
            inputs: &u,
            in_map: &[0],
            ramp: None,
        };
        let mut states = vec![0.0; 2 * len];
        let mut corr = vec![0.0; (len - 1) * s];
        let mut ws = Workspace::default();
        let out = sweep(
            &pr,
            &steps,
            &mut ws,
            &mut states,
            &mut corr,
            LogDet::Accumulate,
        )
        .unwrap();
        (states, corr, out)
    }

    fn rel(a: &[f64], b: &[f64]) -> f64 {
        let num: f64 = a.iter().zip(b).map(|(x, y)| (x - y).powi(2)).sum();
        let den: f64 = b.iter().map(|y| y * y).sum();
        (num / den).sqrt()
    }

    #[test]
    fn steady_state_shortcut_matches_full_recursion_across_gaps() {
        for s in [1, 3] {
            let (xa, da, oa) = solve(SteadyState::Allow, s);
            let (xn, dn, on) = solve(SteadyState::Never, s);
            // Most steps must actually run on frozen gains, in several episodes.
            assert!(
                oa.steady_steps > 3000 * s,
                "steady steps {}",
                oa.steady_steps
            );
            assert_eq!(on.steady_steps, 0);
            // Gains frozen at 1e-12 relative change: results agree far below 1e-8.
            assert!(rel(&xa, &xn) < 1e-9, "states {}", rel(&xa, &xn));
            assert!(rel(&da, &dn) < 1e-9, "d {}", rel(&da, &dn));
            assert!((oa.logdet_s - on.logdet_s).abs() < 1e-9 * on.logdet_s.abs());
            assert!((oa.cost(&[400.0]) - on.cost(&[400.0])).abs() < 1e-9 * on.cost(&[400.0]));
        }
    }
}
