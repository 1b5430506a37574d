//! Closed-form kernels for networks with one hidden layer (the thesis networks), a block
//! of samples at a time: the forward pass, the residuals and the Jacobian rows, each
//! quantity contiguous over the block's samples so that the loops vectorise.

use nalgebra::DMatrix;

use super::normal::Part;
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
