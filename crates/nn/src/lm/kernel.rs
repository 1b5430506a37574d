//! Closed-form kernels for networks with one hidden layer (the thesis networks), a block
//! of samples at a time: the forward pass, the residuals and the Jacobian rows, each
//! quantity contiguous over the block's samples so that the loops vectorise.

use nalgebra::DMatrix;

use super::part::{BLOCK, Part};
use crate::mlp::{Mlp, tanh};

/// Forward pass of samples `k0..k0 + kb` of `part` through a one-hidden-layer network into
/// `acts` (`H + q` rows of `kb`: hidden outputs, then scaled outputs), with each unit's
/// sum in the order [`Mlp::forward_scaled`] uses, so the values are the same bits.
pub(super) fn forward_block(net: &Mlp, part: &Part, k0: usize, kb: usize, acts: &mut [f64]) {
    let n = net.n_inputs();
    let h = net.hidden()[0];
    let q = net.n_outputs();
    let w = net.weights();
    let (hidden, outputs) = acts[..(h + q) * kb].split_at_mut(h * kb);
    for (a, unit) in hidden.chunks_exact_mut(kb).zip(w.chunks_exact(n + 1)) {
        a.fill(0.0);
        for (j, &wj) in unit[..n].iter().enumerate() {
            let s = part.input(j, k0, kb);
            for (ak, &sk) in a.iter_mut().zip(s) {
                *ak += wj * sk;
            }
        }
        let b = unit[n];
        for ak in a.iter_mut() {
            *ak = tanh(b + *ak);
        }
    }
    let out_w = &w[h * (n + 1)..];
    for (y, unit) in outputs.chunks_exact_mut(kb).zip(out_w.chunks_exact(h + 1)) {
        y.fill(0.0);
        for (a, &v) in hidden.chunks_exact(kb).zip(&unit[..h]) {
            for (yk, &ak) in y.iter_mut().zip(a) {
                *yk += v * ak;
            }
        }
        let c = unit[h];
        for yk in y.iter_mut() {
            *yk += c;
        }
    }
}

/// Residuals `e = ρ_o·(t̂ − ŷ)` of a block from its activations (layout of
/// [`forward_block`]) into `e` (row `o·kb + k`), adding their squares to `sse` one by one
/// (the order the per-sample path adds them in when there is one output).
pub(super) fn block_residuals(
    part: &Part,
    rho: &[f64],
    k0: usize,
    kb: usize,
    outputs: &[f64],
    e: &mut [f64],
    sse: &mut f64,
) {
    for (o, (&r, y)) in rho.iter().zip(outputs.chunks_exact(kb)).enumerate() {
        let t = part.target(o, k0, kb);
        for ((ek, &tk), &yk) in e[o * kb..(o + 1) * kb].iter_mut().zip(t).zip(y) {
            *ek = r * (tk - yk);
            *sse += *ek * *ek;
        }
    }
}

/// The Jacobian rows `ρ_o·∂ŷ_o/∂w` of a block of `kb` samples of a one-hidden-layer
/// network, from its activations (layout of [`forward_block`]), into the column-major `j`
/// (row `o·kb + k`; `J`'s row order does not change `JᵀJ` or `Jᵀe`). For hidden unit `i`,
/// `g = ρ_o·v_{o,i}·(1 − a_i²)` gives `g·s_j` and `g` (bias); output unit `o` gets `ρ_o·a_i`
/// and `ρ_o`, the other output units 0. The same numbers back-propagation gives.
pub(super) fn single_layer_jacobian(
    net: &Mlp,
    part: &Part,
    rho: &[f64],
    k0: usize,
    kb: usize,
    acts: &[f64],
    j: &mut DMatrix<f64>,
) {
    let n = net.n_inputs();
    let h = net.hidden()[0];
    let ld = j.nrows();
    let w = net.weights();
    let out_offset = h * (n + 1);
    let js = j.as_mut_slice();
    for (o, &r) in rho.iter().enumerate() {
        let rows = o * kb..(o + 1) * kb;
        let v = &w[out_offset + o * (h + 1)..out_offset + o * (h + 1) + h];
        for (i, (&vi, a)) in v.iter().zip(acts.chunks_exact(kb)).enumerate() {
            let base = i * (n + 1);
            let (inputs, rest) = js.split_at_mut((base + n) * ld);
            let g = &mut rest[rows.clone()];
            for (gk, &ak) in g.iter_mut().zip(a) {
                *gk = r * vi * (1.0 - ak * ak);
            }
            for jn in 0..n {
                let s = part.input(jn, k0, kb);
                let col = &mut inputs[(base + jn) * ld..][rows.clone()];
                for ((ck, &gk), &sk) in col.iter_mut().zip(g.iter()).zip(s) {
                    *ck = gk * sk;
                }
            }
        }
        for u in 0..rho.len() {
            for i in 0..=h {
                let col = &mut js[(out_offset + u * (h + 1) + i) * ld..][rows.clone()];
                if u != o {
                    col.fill(0.0);
                } else if i < h {
                    for (ck, &ak) in col.iter_mut().zip(&acts[i * kb..(i + 1) * kb]) {
                        *ck = r * ak;
                    }
                } else {
                    col.fill(r);
                }
            }
        }
    }
}

/// A block of ones (the bias columns' entries).
const ONES: [f64; BLOCK] = [1.0; BLOCK];

/// `Σ a_k b_k` with eight running sums (lane `k mod 8`) added at the end in a fixed order:
/// independent additions that pipeline and vectorise where one running sum would wait on
/// each addition; the same bits every time.
fn dot(a: &[f64], b: &[f64]) -> f64 {
    let mut lanes = [0.0; 8];
    let (ac, bc) = (a.chunks_exact(8), b.chunks_exact(8));
    let tail: f64 = ac
        .remainder()
        .iter()
        .zip(bc.remainder())
        .map(|(x, y)| x * y)
        .sum();
    for (x, y) in ac.zip(bc) {
        for l in 0..8 {
            lanes[l] += x[l] * y[l];
        }
    }
    let [l0, l1, l2, l3, l4, l5, l6, l7] = lanes;
    (((l0 + l4) + (l1 + l5)) + ((l2 + l6) + (l3 + l7))) + tail
}

/// Adds `Jᵀ r_vv` of a block of `kb` samples to `out` (one entry per weight), where
/// `r_vv = ρ_o·∂²ŷ_o/∂w²[v, v]` is the second derivative of the residuals along the
/// direction `v` (flat weight layout) at the weights whose activations are `acts` (layout
/// of [`forward_block`]) and `J` the Jacobian rows of [`single_layer_jacobian`].
///
/// With `z_i = tanh(a_i)`, `a_i = Σ_j W_ij s_j + b_i`, `ŷ_o = Σ_i V_oi z_i + c_o` and the
/// direction's `δa_i = Σ_j v(W_ij) s_j + v(b_i)`:
/// `∂²ŷ_o[v, v] = Σ_i (1 − z_i²)·δa_i·(2 v(V_oi) − 2 V_oi z_i δa_i)`
/// (from `z′ = 1 − z²`, `z″ = −2z(1 − z²)`; the output layer is linear). `scratch` holds
/// `H + q` rows of `kb`.
#[allow(clippy::too_many_arguments)]
pub(super) fn block_curvature(
    net: &Mlp,
    v: &[f64],
    part: &Part,
    rho: &[f64],
    k0: usize,
    kb: usize,
    acts: &[f64],
    scratch: &mut [f64],
    out: &mut [f64],
) {
    let n = net.n_inputs();
    let h = net.hidden()[0];
    let w = net.weights();
    let out_offset = h * (n + 1);
    let (da, g) = scratch[..(h + rho.len()) * kb].split_at_mut(h * kb);
    // δa_i over the block.
    for (d, dir) in da.chunks_exact_mut(kb).zip(v.chunks_exact(n + 1)) {
        d.fill(dir[n]);
        for (j, &vj) in dir[..n].iter().enumerate() {
            for (dk, &sk) in d.iter_mut().zip(part.input(j, k0, kb)) {
                *dk += vj * sk;
            }
        }
    }
    // g_o = ρ_o²·∂²ŷ_o[v, v] (the factor ρ_o of r_vv and the one of J's rows).
    for (o, (go, &r)) in g.chunks_exact_mut(kb).zip(rho).enumerate() {
        let unit = out_offset + o * (h + 1);
        go.fill(0.0);
        for (i, (z, d)) in acts.chunks_exact(kb).zip(da.chunks_exact(kb)).enumerate() {
            let (vo, wo) = (2.0 * v[unit + i], 2.0 * w[unit + i]);
            for ((gk, &zk), &dk) in go.iter_mut().zip(z).zip(d) {
                *gk += (1.0 - zk * zk) * dk * (vo - wo * zk * dk);
            }
        }
        let r2 = r * r;
        for gk in go.iter_mut() {
            *gk *= r2;
        }
        // Output weights: ∂ŷ_o/∂V_oi = z_i, ∂ŷ_o/∂c_o = 1.
        for (i, z) in acts.chunks_exact(kb).take(h).enumerate() {
            out[unit + i] += dot(go, z);
        }
        out[unit + h] += dot(go, &ONES[..kb]);
    }
    // Hidden weights: ∂ŷ_o/∂W_ij = V_oi (1 − z_i²) s_j, ∂ŷ_o/∂b_i = V_oi (1 − z_i²).
    for (i, (z, back)) in acts
        .chunks_exact(kb)
        .zip(da.chunks_exact_mut(kb))
        .enumerate()
    {
        back.fill(0.0);
        for (o, go) in g.chunks_exact(kb).enumerate() {
            let voi = w[out_offset + o * (h + 1) + i];
            for (bk, &gk) in back.iter_mut().zip(go) {
                *bk += voi * gk;
            }
        }
        for (bk, &zk) in back.iter_mut().zip(z) {
            *bk *= 1.0 - zk * zk;
        }
        let base = i * (n + 1);
        for j in 0..n {
            out[base + j] += dot(back, part.input(j, k0, kb));
        }
        out[base + n] += dot(back, &ONES[..kb]);
    }
}
