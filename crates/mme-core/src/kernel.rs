//! The generic sweep kernel (see [`crate::sweep`] for the recursion and its vocabulary),
//! with the steady-state shortcut for time-invariant steps, and [`sweep`], which runs it
//! on fixed-size matrices for small problems.
//!
//! **Steady state.** With time-invariant `Φ, Γ` and the same set of observed channels at
//! every sample, the backward Riccati recursion for `P` converges to a fixed point (the
//! steady-state smoother). Once `P` after the measurement at sample `k` agrees with `P`
//! at sample `k+1` to [`STEADY_TOL`] (relative, max-norm) and both samples have the same
//! observation pattern, one interval's worth of gains is frozen in a table and the
//! backward pass only runs the linear recursion for `q`
//! (`q_j = Φᵀ(I − XᵀΓᵀ)q_{j+1} − ΦᵀP̃c_j`, `f_j = S⁻¹Γᵀq_{j+1} − Xc_j`), an `O(n²)`
//! step instead of `O(n³)`. The first sample with another observation pattern (a
//! missing value) ends the shortcut: `P` is restored from the table's pre-measurement
//! value and the full recursion resumes (and may converge again). The inputs and data
//! enter only `q`, so they never invalidate the table.

use nalgebra::allocator::Allocator;
use nalgebra::{
    DMatrix, DefaultAllocator, Dim, Dyn, MatrixView, MatrixViewMut, OMatrix, OVector, U1, U2, U4,
};

use crate::error::{MmeError, Result};
use crate::sweep::{
    LogDet, Problem, SteadyState, StepModel, Steps, SweepOut, Workspace, backward_sub,
    cholesky_in_place, forward_sub, symmetrize,
};

/// Relative max-norm change of `P` between consecutive samples below which the recursion
/// counts as converged. The frozen gains then differ from the exact ones by about this
/// much relative, far below the 1e-8 agreement the brute-force tests demand, while a
/// recursion stagnating at round-off (~1e-15) still qualifies.
pub(crate) const STEADY_TOL: f64 = 1e-12;

/// Smallest pivot of `S_j`, relative to its largest diagonal, accepted as positive. `S_j`
/// is at least `hW` (positive definite), so only gross round-off can trip this.
const S_PIVOT_FLOOR: f64 = 1e-300;

/// Smallest pivot of `P_0`, relative to its largest diagonal, accepted as observable. An
/// unobservable direction leaves a pivot at round-off level (~1e-16); 1e-12 leaves four
/// orders of margin while still accepting a badly excited but observable state.
const P0_PIVOT_FLOOR: f64 = 1e-12;

/// Frozen gains of one sub-step phase of a steady-state interval.
struct Phase<D: Dim, Q: Dim>
where
    DefaultAllocator: Allocator<D, D> + Allocator<Q, D>,
{
    /// `F = S⁻¹ΓᵀPΦ`.
    f: OMatrix<f64, Q, D>,
    /// `Ψ = S⁻¹Γᵀ`.
    psi: OMatrix<f64, Q, D>,
    /// `X = S⁻¹ΓᵀP`.
    x: OMatrix<f64, Q, D>,
    /// `M = Φᵀ(I − XᵀΓᵀ)`.
    m: OMatrix<f64, D, D>,
    /// `N = −ΦᵀP̃`.
    nm: OMatrix<f64, D, D>,
    /// `log det S`.
    logdet: f64,
}

/// A steady-state table: one interval of phases, plus `P` before the next measurement.
struct Table<D: Dim, Q: Dim>
where
    DefaultAllocator: Allocator<D, D> + Allocator<Q, D>,
{
    phases: Vec<Phase<D, Q>>,
    p_pre: OMatrix<f64, D, D>,
}

/// Steps `lo..hi` run on table `table`.
#[derive(Debug, Clone, Copy)]
struct Episode {
    lo: usize,
    hi: usize,
    table: usize,
}

/// Run one sweep; see [`sweep`].
#[allow(clippy::too_many_arguments)]
pub(crate) fn run<D: Dim, Q: Dim, S: Steps<D, Q>>(
    d: D,
    qd: Q,
    pr: &Problem,
    src: &S,
    ws: &mut Workspace,
    states: &mut [f64],
    corrections: &mut [f64],
    logdet: LogDet,
) -> Result<SweepOut>
where
    DefaultAllocator: Allocator<D, D>
        + Allocator<D, Q>
        + Allocator<Q, D>
        + Allocator<Q, Q>
        + Allocator<D>
        + Allocator<Q>,
{
    let (n, q, s) = (pr.n, pr.q, pr.substeps);
    let samples = pr.samples;
    let steps = pr.pieces();
    let p = pr.c.nrows();
    let breakdown = |step, what| MmeError::Breakdown {
        experiment: pr.experiment,
        step,
        time: pr.t0 + step as f64 * pr.h,
        what,
    };
    let allow_steady = S::TIME_INVARIANT && pr.steady == SteadyState::Allow && p <= 64;

    ws.gains.clear();
    ws.feed.clear();
    ws.feed.reserve(steps * q);

    // Per-channel information: H_i = c_iᵀc_i / R_i, g_i = c_iᵀ / R_i.
    let h_info: Vec<OMatrix<f64, D, D>> = (0..p)
        .map(|i| OMatrix::from_fn_generic(d, d, |a, b| pr.c[(i, a)] * pr.c[(i, b)] * pr.inv_r[i]))
        .collect();
    let g_info: Vec<OVector<f64, D>> = (0..p)
        .map(|i| OVector::from_fn_generic(d, U1, |a, _| pr.c[(i, a)] * pr.inv_r[i]))
        .collect();
    let c_rows: Vec<OVector<f64, D>> = (0..p)
        .map(|i| OVector::from_fn_generic(d, U1, |a, _| pr.c[(i, a)]))
        .collect();
    let hw = OMatrix::<f64, Q, Q>::from_fn_generic(qd, qd, |a, b| pr.h * pr.w[(a, b)]);
    let w = OMatrix::<f64, Q, Q>::from_fn_generic(qd, qd, |a, b| pr.w[(a, b)]);
    let y_at = |k: usize, i: usize| pr.outputs[(pr.out_map[i], k)];
    let mask = |k: usize| -> u64 {
        (0..p)
            .filter(|&i| !y_at(k, i).is_nan())
            .fold(0u64, |m, i| m | (1u64 << i))
    };
    let measure_q = |k: usize, qv: &mut OVector<f64, D>| {
        for (i, g) in g_info.iter().enumerate() {
            let y = y_at(k, i);
            if !y.is_nan() {
                qv.axpy(y, g, 1.0);
            }
        }
    };
    let measure_p = |k: usize, pm: &mut OMatrix<f64, D, D>| {
        for (i, h) in h_info.iter().enumerate() {
            if !y_at(k, i).is_nan() {
                *pm += h;
            }
        }
    };

    // ---- Backward pass ----
    let mut pm = OMatrix::<f64, D, D>::zeros_generic(d, d);
    let mut qv = OVector::<f64, D>::zeros_generic(d, U1);
    let mut g = OMatrix::<f64, Q, D>::zeros_generic(qd, d);
    let mut sm = OMatrix::<f64, Q, Q>::zeros_generic(qd, qd);
    let mut w1 = OMatrix::<f64, D, D>::zeros_generic(d, d);
    let mut cv = OVector::<f64, D>::zeros_generic(d, U1);
    let mut tmp = OVector::<f64, D>::zeros_generic(d, U1);
    let mut gq = OVector::<f64, Q>::zeros_generic(qd, U1);
    let mut av = OVector::<f64, Q>::zeros_generic(qd, U1);
    let mut logdet_s = 0.0;

    let mut tables: Vec<Table<D, Q>> = Vec::new();
    let mut episodes: Vec<Episode> = Vec::new();
    let mut steady: Option<(usize, u64)> = None;
    let mut prev_post = pm.clone();
    let mut prev_mask: Option<u64> = None;
    let mut steady_steps = 0usize;

    measure_p(samples - 1, &mut pm);
    measure_q(samples - 1, &mut qv);
    if allow_steady {
        prev_post.copy_from(&pm);
        prev_mask = Some(mask(samples - 1));
    }
    for k in (0..samples - 1).rev() {
        if let Some((t, _)) = steady {
            // Linear recursion for q on frozen gains.
            for r in (0..s).rev() {
                let j = k * s + r;
                let ph = &tables[t].phases[r];
                src.offset(j, cv.as_mut_slice());
                av.gemv(1.0, &ph.psi, &qv, 0.0);
                av.gemv(-1.0, &ph.x, &cv, 1.0);
                ws.feed.extend_from_slice(av.as_slice());
                tmp.gemv(1.0, &ph.m, &qv, 0.0);
                tmp.gemv(1.0, &ph.nm, &cv, 1.0);
                std::mem::swap(&mut qv, &mut tmp);
                if logdet == LogDet::Accumulate {
                    logdet_s += ph.logdet;
                }
            }
            steady_steps += s;
            if let Some(ep) = episodes.last_mut() {
                ep.lo = k * s;
            }
        } else {
            for r in (0..s).rev() {
                let j = k * s + r;
                let phi = src.phi(j);
                let gam = src.gamma(j);
                src.offset(j, cv.as_mut_slice());
                // G = ΓᵀP, S = hW + GΓ, a = Γᵀq − Gc.
                g.gemm_tr(1.0, &gam, &pm, 0.0);
                sm.copy_from(&hw);
                sm.gemm(1.0, &g, &gam, 1.0);
                gq.gemv_tr(1.0, &gam, &qv, 0.0);
                av.copy_from(&gq);
                av.gemv(-1.0, &g, &cv, 1.0);
                let ld = cholesky_in_place(&mut sm, S_PIVOT_FLOOR)
                    .map_err(|_| breakdown(j, "correction Hessian S lost positive definiteness"))?;
                if logdet == LogDet::Accumulate {
                    logdet_s += ld;
                }
                // Y = L⁻¹G; P̃ = P − YᵀY (exactly symmetric); X = L⁻ᵀY = S⁻¹ΓᵀP; f = S⁻¹a.
                forward_sub(&sm, &mut g);
                pm.gemm_tr(-1.0, &g, &g, 1.0);
                backward_sub(&sm, &mut g);
                forward_sub(&sm, &mut av);
                backward_sub(&sm, &mut av);
                let start = ws.gains.len();
                ws.gains.resize(start + q * n, 0.0);
                MatrixViewMut::from_slice_generic(&mut ws.gains[start..], qd, d)
                    .gemm(1.0, &g, &phi, 0.0);
                ws.feed.extend_from_slice(av.as_slice());
                // q̃ = q − Xᵀ(Γᵀq); q_j = Φᵀ(q̃ − P̃c); P_j = ΦᵀP̃Φ.
                qv.gemv_tr(-1.0, &g, &gq, 1.0);
                tmp.copy_from(&qv);
                tmp.gemv(-1.0, &pm, &cv, 1.0);
                qv.gemv_tr(1.0, &phi, &tmp, 0.0);
                w1.gemm(1.0, &pm, &phi, 0.0);
                pm.gemm_tr(1.0, &phi, &w1, 0.0);
                symmetrize(&mut pm);
            }
        }
        // Measurement at sample k.
        measure_q(k, &mut qv);
        if let Some((t, m_ss)) = steady {
            let mk = mask(k);
            if mk != m_ss {
                pm.copy_from(&tables[t].p_pre);
                measure_p(k, &mut pm);
                steady = None;
                prev_post.copy_from(&pm);
                prev_mask = Some(mk);
            }
        } else {
            measure_p(k, &mut pm);
            if allow_steady {
                let mk = mask(k);
                let scale = pm.amax();
                if prev_mask == Some(mk) && k > 0 && (&pm - &prev_post).amax() <= STEADY_TOL * scale
                {
                    let table = build_table(&pm, src, &hw, s)
                        .ok_or_else(|| breakdown(k * s, "steady-state table"))?;
                    tables.push(table);
                    episodes.push(Episode {
                        lo: k * s,
                        hi: k * s,
                        table: tables.len() - 1,
                    });
                    steady = Some((tables.len() - 1, mk));
                }
                prev_post.copy_from(&pm);
                prev_mask = Some(mk);
            }
        }
    }

    // ---- Free initial state: minimise xᵀP_0x − 2q_0ᵀx ----
    let not_observable = |(pivot, value)| MmeError::NotObservable {
        experiment: pr.experiment,
        pivot,
        value,
    };
    let (x, ld0, prior_cost) = match pr.prior {
        None => {
            let ld0 = cholesky_in_place(&mut pm, P0_PIVOT_FLOOR).map_err(not_observable)?;
            let mut x = qv.clone();
            forward_sub(&pm, &mut x);
            backward_sub(&pm, &mut x);
            (x, ld0, 0.0)
        }
        Some(prior) => {
            // Prior `x_0 ~ N(m, Π⁻¹)`: minimise xᵀ(P_0 + Π)x − 2(q_0 + Πm)ᵀx. A tight
            // prior makes the diagonal of `P_0 + Π` span many decades, so the pivot test
            // runs on the Jacobi-scaled matrix `D(P_0 + Π)D`, `D = diag(1/√(P_0 + Π)_ii)`.
            for i in 0..n {
                pm[(i, i)] += prior.info[i];
                qv[i] += prior.info[i] * prior.mean[i];
            }
            let mut scale = OVector::<f64, D>::zeros_generic(d, U1);
            for i in 0..n {
                let dii = pm[(i, i)];
                if !(dii.is_finite() && dii > 0.0) {
                    return Err(not_observable((i, dii)));
                }
                scale[i] = 1.0 / dii.sqrt();
            }
            for a in 0..n {
                for b in 0..n {
                    pm[(a, b)] *= scale[a] * scale[b];
                }
            }
            let ld_scaled = cholesky_in_place(&mut pm, P0_PIVOT_FLOOR).map_err(not_observable)?;
            let mut x = qv.component_mul(&scale);
            forward_sub(&pm, &mut x);
            backward_sub(&pm, &mut x);
            x.component_mul_assign(&scale);
            let ld0 = ld_scaled - 2.0 * scale.iter().map(|v| v.ln()).sum::<f64>();
            let cost = prior.cost(x.as_slice());
            (x, ld0, cost)
        }
    };
    let mut x = x;

    // ---- Forward pass ----
    let mut sse = vec![0.0; p];
    let mut count = vec![0usize; p];
    let mut residuals = |k: usize, x: &OVector<f64, D>, states: &mut [f64]| {
        states[k * n..(k + 1) * n].copy_from_slice(x.as_slice());
        for i in 0..p {
            let y = y_at(k, i);
            if !y.is_nan() {
                let r = y - c_rows[i].dot(x);
                sse[i] += r * r;
                count[i] += 1;
            }
        }
    };
    residuals(0, &x, states);
    let mut xn = OVector::<f64, D>::zeros_generic(d, U1);
    let mut dv = OVector::<f64, Q>::zeros_generic(qd, U1);
    let mut wd = OVector::<f64, Q>::zeros_generic(qd, U1);
    let mut correction_cost = 0.0;
    let mut g_ptr = ws.gains.len();
    let mut f_ptr = ws.feed.len();
    // Episodes were recorded backwards in time; walk them forwards.
    let mut ep = episodes.len();
    for j in 0..steps {
        while ep > 0 && episodes[ep - 1].hi <= j {
            ep -= 1;
        }
        let in_table = ep > 0 && episodes[ep - 1].lo <= j;
        let phi = src.phi(j);
        let gam = src.gamma(j);
        src.offset(j, cv.as_mut_slice());
        f_ptr -= q;
        dv.as_mut_slice()
            .copy_from_slice(&ws.feed[f_ptr..f_ptr + q]);
        if in_table {
            let fj = &tables[episodes[ep - 1].table].phases[j % s].f;
            dv.gemv(-1.0, fj, &x, 1.0);
        } else {
            g_ptr -= q * n;
            let fj = MatrixView::from_slice_generic(&ws.gains[g_ptr..g_ptr + q * n], qd, d);
            dv.gemv(-1.0, &fj, &x, 1.0);
        }
        wd.gemv(1.0, &w, &dv, 0.0);
        correction_cost += pr.h * wd.dot(&dv);
        corrections[j * q..(j + 1) * q].copy_from_slice(dv.as_slice());
        xn.copy_from(&cv);
        xn.gemv(1.0, &phi, &x, 1.0);
        xn.gemv(1.0, &gam, &dv, 1.0);
        std::mem::swap(&mut x, &mut xn);
        if (j + 1) % s == 0 {
            residuals((j + 1) / s, &x, states);
        }
    }
    if !correction_cost.is_finite() || !prior_cost.is_finite() || sse.iter().any(|v| !v.is_finite())
    {
        return Err(breakdown(steps, "non-finite trajectory"));
    }
    Ok(SweepOut {
        sse,
        count,
        correction_cost,
        logdet_s,
        logdet_p0: if logdet == LogDet::Accumulate {
            ld0
        } else {
            0.0
        },
        prior_cost,
        steady_steps,
    })
}

/// Freeze one interval of gains starting from the post-measurement `P` (time-invariant
/// steps only, so phase `r` uses `Φ_r = Φ`, `Γ_r = Γ`). Runs once per steady episode, so
/// it may allocate.
fn build_table<D: Dim, Q: Dim, S: Steps<D, Q>>(
    p_post: &OMatrix<f64, D, D>,
    src: &S,
    hw: &OMatrix<f64, Q, Q>,
    s: usize,
) -> Option<Table<D, Q>>
where
    DefaultAllocator: Allocator<D, D>
        + Allocator<D, Q>
        + Allocator<Q, D>
        + Allocator<Q, Q>
        + Allocator<D>
        + Allocator<Q>,
{
    let mut pm = p_post.clone();
    let mut phases: Vec<Phase<D, Q>> = Vec::with_capacity(s);
    for r in (0..s).rev() {
        let phi = src.phi(r).clone_owned();
        let gam = src.gamma(r).clone_owned();
        let gt = gam.transpose();
        let g = &gt * &pm;
        let sm = hw + &g * &gam;
        let chol = nalgebra::Cholesky::new(sm)?;
        let logdet = 2.0
            * chol
                .l_dirty()
                .diagonal()
                .iter()
                .map(|v| v.ln())
                .sum::<f64>();
        let x = chol.solve(&g);
        let psi = chol.solve(&gt);
        let mut pt = &pm - g.transpose() * &x;
        symmetrize(&mut pt);
        let f = &x * &phi;
        let phit = phi.transpose();
        let ident =
            OMatrix::<f64, D, D>::identity_generic(phi.shape_generic().0, phi.shape_generic().1);
        let m = &phit * (ident - x.transpose() * &gt);
        let nm = -(&phit * &pt);
        pm = &phit * &pt * &phi;
        symmetrize(&mut pm);
        phases.push(Phase {
            f,
            psi,
            x,
            m,
            nm,
            logdet,
        });
    }
    phases.reverse();
    Some(Table { phases, p_pre: pm })
}

/// Run the sweep; write states at samples (`n × N`, column-major) into `states` and the
/// correction pieces (`q × (N−1)s`) into `corrections`.
pub(crate) fn sweep(
    pr: &Problem,
    model: &StepModel,
    ws: &mut Workspace,
    states: &mut [f64],
    corrections: &mut [f64],
    logdet: LogDet,
) -> Result<SweepOut> {
    debug_assert_eq!(states.len(), pr.n * pr.samples);
    debug_assert_eq!(corrections.len(), pr.q * pr.pieces());
    macro_rules! go {
        ($d:expr, $q:expr) => {
            match model {
                StepModel::Lti {
                    ad,
                    ed,
                    bd,
                    inputs,
                    in_map,
                    ramp,
                } => {
                    let src = LtiSteps {
                        phi: ad.as_slice(),
                        gamma: ed.as_slice(),
                        bd,
                        inputs,
                        in_map,
                        ramp: *ramp,
                        s: pr.substeps,
                        d: $d,
                        qd: $q,
                    };
                    run($d, $q, pr, &src, ws, states, corrections, logdet)
                }
                StepModel::Tv { phi, gamma, offset } => {
                    let src = TvSteps {
                        phi,
                        gamma,
                        offset,
                        n: pr.n,
                        q: pr.q,
                        d: $d,
                        qd: $q,
                    };
                    run($d, $q, pr, &src, ws, states, corrections, logdet)
                }
            }
        };
    }
    match (pr.n, pr.q) {
        (2, 1) => go!(U2, U1),
        (2, 2) => go!(U2, U2),
        (4, 1) => go!(U4, U1),
        (4, 2) => go!(U4, U2),
        (n, q) => go!(Dyn(n), Dyn(q)),
    }
}

struct LtiSteps<'a, D, Q> {
    phi: &'a [f64],
    gamma: &'a [f64],
    bd: &'a DMatrix<f64>,
    inputs: &'a DMatrix<f64>,
    in_map: &'a [usize],
    ramp: Option<&'a DMatrix<f64>>,
    s: usize,
    d: D,
    qd: Q,
}

impl<D: Dim, Q: Dim> Steps<D, Q> for LtiSteps<'_, D, Q> {
    const TIME_INVARIANT: bool = true;
    #[inline]
    fn phi(&self, _j: usize) -> MatrixView<'_, f64, D, D> {
        MatrixView::from_slice_generic(self.phi, self.d, self.d)
    }
    #[inline]
    fn gamma(&self, _j: usize) -> MatrixView<'_, f64, D, Q> {
        MatrixView::from_slice_generic(self.gamma, self.d, self.qd)
    }
    #[inline]
    fn offset(&self, j: usize, out: &mut [f64]) {
        let k = j / self.s;
        out.iter_mut().for_each(|o| *o = 0.0);
        let Some(ramp) = self.ramp else {
            for (l, &row) in self.in_map.iter().enumerate() {
                let u = self.inputs[(row, k)];
                for (i, o) in out.iter_mut().enumerate() {
                    *o += self.bd[(i, l)] * u;
                }
            }
            return;
        };
        // First-order hold: sub-step `i` of interval `k` spans the fractions
        // `[i/s, (i+1)/s]` of the ramp from `u_k` to `u_{k+1}` (`k + 1 < N` because
        // `j < (N−1)s`).
        let i = j - k * self.s;
        let (f0, f1) = (i as f64 / self.s as f64, (i + 1) as f64 / self.s as f64);
        for (l, &row) in self.in_map.iter().enumerate() {
            let (ua, ub) = (self.inputs[(row, k)], self.inputs[(row, k + 1)]);
            let u0 = ua + f0 * (ub - ua);
            let du = (f1 - f0) * (ub - ua);
            for (r, o) in out.iter_mut().enumerate() {
                *o += self.bd[(r, l)] * u0 + ramp[(r, l)] * du;
            }
        }
    }
}

struct TvSteps<'a, D, Q> {
    phi: &'a [f64],
    gamma: &'a [f64],
    offset: &'a [f64],
    n: usize,
    q: usize,
    d: D,
    qd: Q,
}

impl<D: Dim, Q: Dim> Steps<D, Q> for TvSteps<'_, D, Q> {
    const TIME_INVARIANT: bool = false;
    #[inline]
    fn phi(&self, j: usize) -> MatrixView<'_, f64, D, D> {
        let nn = self.n * self.n;
        MatrixView::from_slice_generic(&self.phi[j * nn..(j + 1) * nn], self.d, self.d)
    }
    #[inline]
    fn gamma(&self, j: usize) -> MatrixView<'_, f64, D, Q> {
        let nq = self.n * self.q;
        MatrixView::from_slice_generic(&self.gamma[j * nq..(j + 1) * nq], self.d, self.qd)
    }
    #[inline]
    fn offset(&self, j: usize, out: &mut [f64]) {
        out.copy_from_slice(&self.offset[j * self.n..(j + 1) * self.n]);
    }
}
