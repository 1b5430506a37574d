//! The linearised problem of one Levenberg–Marquardt epoch: over the samples in scaled
//! units ([`Part`]), their sum of squared errors, and the normal equations `JᵀJ`, `Jᵀe`
//! ([`Linearisation`]), accumulated over fixed chunks of samples in parallel with the same
//! bits for any number of threads.

use std::ops::Range;

use nalgebra::{DMatrix, DMatrixView, DVector, DVectorView};
use rayon::prelude::*;

use super::kernel::{block_curvature, block_residuals, forward_block, single_layer_jacobian};
use super::part::{BLOCK, Part};
use crate::mlp::{Mlp, Workspace};

/// Column panel width of the upper-triangular `JᵀJ` accumulation: for 51 weights two
/// panels do 77 % of the full product's flops while each stays large enough for the
/// blocked kernel (16 and 32 measured equally fast).
const PANEL: usize = 32;

/// nalgebra hands a product to `matrixmultiply` only when every dimension exceeds this
/// (its `SMALL_DIM`).
const GEMM_MIN_DIM: usize = 5;

/// Least work (samples × weights) of a call for which chunks are handed to rayon: below
/// it (e.g. 2,000 samples of a 6-weight network) waking the pool costs about as much as
/// it saves.
const PARALLEL_MIN_WORK: usize = 1 << 15;

/// Samples per chunk, the unit of parallel work (8 blocks), unless that would make more
/// than [`MAX_CHUNKS`] chunks.
const CHUNK: usize = 8 * BLOCK;

/// At most this many chunks (each holds its own partial `JᵀJ`), so memory stays bounded
/// for very long records.
const MAX_CHUNKS: usize = 64;

/// Chunk length for `n` samples: a function of `n` alone (never of the thread count), a
/// multiple of [`BLOCK`], at least [`CHUNK`].
fn chunk_len(n: usize) -> usize {
    (n.div_ceil(MAX_CHUNKS).div_ceil(BLOCK) * BLOCK).max(CHUNK)
}

/// How the Jacobian rows are computed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kernel {
    /// One hidden layer (the thesis networks): whole blocks of samples at a time, one
    /// weight's derivatives over the block contiguous, in closed form.
    SingleLayer,
    /// Any depth: one sample at a time by back-propagation.
    Backprop,
}

impl Kernel {
    fn of(net: &Mlp) -> Self {
        if net.hidden().len() == 1 {
            Self::SingleLayer
        } else {
            Self::Backprop
        }
    }

    /// Activations kept per sample: hidden outputs and scaled outputs with one hidden
    /// layer (kept block by block, each activation contiguous over the block's samples),
    /// every activation (sample by sample) otherwise.
    fn keep_width(self, net: &Mlp) -> usize {
        match self {
            Self::SingleLayer => net.hidden()[0] + net.n_outputs(),
            Self::Backprop => net.output_range().end,
        }
    }
}

/// What a chunk is evaluated on.
#[derive(Clone, Copy)]
struct Problem<'a> {
    kernel: Kernel,
    part: &'a Part,
    net: &'a Mlp,
    rho: &'a [f64],
}

/// Buffers of one chunk: its block of Jacobian rows and residuals, and its partial sums.
struct Slot {
    ws: Workspace,
    /// One block's Jacobian `J` (column-major, `BLOCK·q × n_w`; the first `kb·q` rows used).
    j: DMatrix<f64>,
    /// One block's residuals.
    e: DVector<f64>,
    /// One block's activations when they are not kept (one hidden layer only).
    acts: Vec<f64>,
    /// This chunk's `JᵀJ` (upper triangle) and `Jᵀe`.
    jtj: DMatrix<f64>,
    jte: DVector<f64>,
    /// One block's scratch rows for [`Linearisation::curvature`] (one hidden layer only).
    curv: Vec<f64>,
    /// This chunk's `Jᵀ r_vv`.
    jtr: DVector<f64>,
    /// This chunk's SSE (`None`: evaluation cut off).
    sse: Option<f64>,
}

/// When [`Linearisation::sse`] may stop early: once `SSE + offset ≥ limit` is certain.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Cutoff {
    /// Added to the SSE before the comparison (the weight-decay term).
    pub(super) offset: f64,
    /// The objective to beat.
    pub(super) limit: f64,
}

impl Cutoff {
    /// Whether a partial SSE `partial`, after chunks summing to `floor`, already reaches
    /// the limit (the same additions as the full objective, so exact).
    fn reached(self, floor: f64, partial: f64) -> bool {
        (floor + partial) + self.offset >= self.limit
    }
}

/// What a [`Linearisation`] is for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Use {
    /// SSE and normal equations (the training part).
    NormalEquations,
    /// SSE only (the validation part): no `JᵀJ` buffers.
    SseOnly,
}

/// The normal equations of the linearised problem, `jtj = JᵀJ` and `jte = Jᵀe` (with
/// `J = ∂y/∂w` scaled by `ρ_o` and `e = t − y`), accumulated without forming the full
/// Jacobian: samples are cut into chunks (fixed by the sample count alone), each chunk
/// sums its blocks of [`BLOCK`] samples in order into its own partial sums, chunks run in
/// parallel with rayon, and the partial sums are added in chunk order. So the result is
/// the same, bit for bit, for any number of threads.
pub(super) struct Linearisation {
    kernel: Kernel,
    chunk: usize,
    n_samples: usize,
    /// Weights of the network (the work per sample, for [`PARALLEL_MIN_WORK`]).
    work_per_sample: usize,
    slots: Vec<Slot>,
    /// `JᵀJ` (full, symmetric) after [`Linearisation::build`].
    pub(super) jtj: DMatrix<f64>,
    /// `Jᵀe` after [`Linearisation::build`].
    pub(super) jte: DVector<f64>,
}

impl Linearisation {
    /// Buffers for `net` and a part of `n_samples` samples.
    pub(super) fn new(net: &Mlp, n_samples: usize, usage: Use) -> Self {
        Self::with_kernel(net, n_samples, usage, Kernel::of(net))
    }

    fn with_kernel(net: &Mlp, n_samples: usize, usage: Use, kernel: Kernel) -> Self {
        let chunk = chunk_len(n_samples);
        let q = net.n_outputs();
        let nw = match usage {
            Use::NormalEquations => net.n_weights(),
            Use::SseOnly => 0,
        };
        let acts = match kernel {
            Kernel::SingleLayer => BLOCK * kernel.keep_width(net),
            Kernel::Backprop => 0,
        };
        let slots = (0..n_samples.div_ceil(chunk))
            .map(|_| {
                let mut ws = Workspace::new();
                ws.prepare(net.architecture());
                Slot {
                    ws,
                    j: DMatrix::zeros(BLOCK * q, nw),
                    e: DVector::zeros(BLOCK * q),
                    acts: vec![0.0; acts],
                    jtj: DMatrix::zeros(nw, nw),
                    jte: DVector::zeros(nw),
                    curv: vec![0.0; acts],
                    jtr: DVector::zeros(nw),
                    sse: None,
                }
            })
            .collect();
        Self {
            kernel,
            chunk,
            n_samples,
            work_per_sample: net.n_weights(),
            slots,
            jtj: DMatrix::zeros(nw, nw),
            jte: DVector::zeros(nw),
        }
    }

    /// Length of the buffer [`Linearisation::sse`] keeps activations in.
    pub(super) fn keep_len(&self, net: &Mlp) -> usize {
        self.n_samples * self.kernel.keep_width(net)
    }

    fn range(&self, c: usize) -> Range<usize> {
        c * self.chunk..((c + 1) * self.chunk).min(self.n_samples)
    }

    /// Run `f(samples, slot, the chunk's part of the kept activations)` over the chunks
    /// `chunks`: in parallel when there are several, rayon has more than one thread and
    /// the work is worth handing over, in order on the calling thread otherwise. Each
    /// chunk's result is the same either way. `keep` is the whole buffer.
    fn for_each_chunk<F>(
        &mut self,
        chunks: Range<usize>,
        keep: Option<&mut [f64]>,
        width: usize,
        f: F,
    ) where
        F: Fn(Range<usize>, &mut Slot, Option<&mut [f64]>) + Sync,
    {
        let per = (self.chunk * width).max(1);
        let mut keeps: Vec<Option<&mut [f64]>> = match keep {
            Some(k) => {
                let end = (chunks.end * per).min(k.len());
                k[chunks.start * per..end]
                    .chunks_mut(per)
                    .map(Some)
                    .collect()
            }
            None => Vec::new(),
        };
        keeps.resize_with(chunks.len(), || None);
        let ranges: Vec<Range<usize>> = chunks.clone().map(|c| self.range(c)).collect();
        let samples: usize = ranges.iter().map(Range::len).sum();
        let parallel = ranges.len() > 1
            && rayon::current_num_threads() > 1
            && samples * self.work_per_sample >= PARALLEL_MIN_WORK;
        let slots = &mut self.slots[chunks];
        if !parallel {
            for ((r, s), k) in ranges.into_iter().zip(slots).zip(keeps) {
                f(r, s, k);
            }
        } else {
            ranges
                .into_par_iter()
                .zip(slots.par_iter_mut())
                .zip(keeps.into_par_iter())
                .for_each(|((r, s), k)| f(r, s, k));
        }
    }

    /// The problem over `part` at `net`'s weights and the row width kept per sample.
    fn problem<'a>(&self, part: &'a Part, net: &'a Mlp, rho: &'a [f64]) -> (Problem<'a>, usize) {
        let problem = Problem {
            kernel: self.kernel,
            part,
            net,
            rho,
        };
        (problem, self.kernel.keep_width(net))
    }

    /// SSE of `part` at `net`'s weights; with `keep` (length [`Linearisation::keep_len`])
    /// also keeps the activations, so that [`Linearisation::build`] at the same weights
    /// can skip the forward pass.
    ///
    /// With a [`Cutoff`] the evaluation stops, returning `None`, as soon as a partial sum
    /// `S` of the squared errors has `S + offset ≥ limit`: the terms are non-negative and
    /// rounded addition is monotone, so the full sum would satisfy it too. Chunks are then
    /// evaluated in order, one at a time (each knowing the exact sum before it) or, when
    /// the work is worth running in parallel, as many at a time as rayon has threads (each
    /// knowing the sum before its group). When no cutoff happens the result is the same
    /// bits as without one.
    pub(super) fn sse(
        &mut self,
        part: &Part,
        net: &Mlp,
        rho: &[f64],
        mut keep: Option<&mut [f64]>,
        cutoff: Option<Cutoff>,
    ) -> Option<f64> {
        let (problem, width) = self.problem(part, net, rho);
        let n_chunks = self.slots.len();
        let threads = rayon::current_num_threads();
        let group = match cutoff {
            None => n_chunks.max(1),
            // Worth running in parallel: one chunk per thread at a time.
            Some(_)
                if threads > 1 && self.n_samples * self.work_per_sample >= PARALLEL_MIN_WORK =>
            {
                threads
            }
            // In order, each chunk knowing the exact sum before it.
            Some(_) => 1,
        };
        let mut total = 0.0;
        let mut c0 = 0;
        while c0 < n_chunks {
            let c1 = (c0 + group).min(n_chunks);
            let floor = total;
            self.for_each_chunk(c0..c1, keep.as_deref_mut(), width, |range, slot, keep| {
                let stop = cutoff.map(|c| (floor, c));
                slot.sse = chunk_sse(problem, range, slot, keep, stop);
            });
            for slot in &self.slots[c0..c1] {
                let sse = slot.sse?;
                total += sse;
            }
            c0 = c1;
        }
        Some(total)
    }

    /// Normal equations of `part` at `net`'s weights into [`Linearisation::jtj`] and
    /// [`Linearisation::jte`]; returns the SSE (the same bits [`Linearisation::sse`]
    /// gives). With `kept` (from [`Linearisation::sse`] at the same weights) the forward
    /// pass is skipped; the numbers are identical either way.
    pub(super) fn build(
        &mut self,
        part: &Part,
        net: &Mlp,
        rho: &[f64],
        kept: Option<&[f64]>,
    ) -> f64 {
        let (problem, width) = self.problem(part, net, rho);
        self.for_each_chunk(0..self.slots.len(), None, width, |range, slot, _| {
            let kept = kept.map(|k| &k[range.start * width..range.end * width]);
            chunk_normal_equations(problem, range, slot, kept);
        });
        self.jtj.fill(0.0);
        self.jte.fill(0.0);
        let mut sse = 0.0;
        for slot in &self.slots {
            self.jtj += &slot.jtj;
            self.jte += &slot.jte;
            sse += slot.sse.unwrap_or(f64::NAN);
        }
        self.jtj.fill_lower_triangle_with_upper_triangle();
        sse
    }

    /// `Jᵀ r_vv` of `part` into `out`: the Jacobian's transpose times the residuals' second
    /// directional derivative along `v` (for geodesic acceleration), at `net`'s weights
    /// whose activations `kept` are (from [`Linearisation::sse`]); chunks summed in order,
    /// so the same bits for any thread count. Returns `false`, leaving `out` alone, when
    /// the network has more than one hidden layer (no closed form here).
    pub(super) fn curvature(
        &mut self,
        part: &Part,
        net: &Mlp,
        rho: &[f64],
        kept: &[f64],
        v: &[f64],
        out: &mut DVector<f64>,
    ) -> bool {
        if self.kernel != Kernel::SingleLayer {
            return false;
        }
        let width = self.kernel.keep_width(net);
        self.for_each_chunk(0..self.slots.len(), None, width, |range, slot, _| {
            slot.jtr.fill(0.0);
            let acts = &kept[range.start * width..range.end * width];
            let mut k0 = range.start;
            while k0 < range.end {
                let kb = BLOCK.min(range.end - k0);
                let local = (k0 - range.start) * width..(k0 - range.start + kb) * width;
                block_curvature(
                    net,
                    v,
                    part,
                    rho,
                    k0,
                    kb,
                    &acts[local],
                    &mut slot.curv,
                    slot.jtr.as_mut_slice(),
                );
                k0 += kb;
            }
        });
        out.fill(0.0);
        for slot in &self.slots {
            *out += &slot.jtr;
        }
        true
    }
}

/// SSE of the samples `range` of `part` (one chunk), block by block; keeps the activations
/// in `keep` when given.
fn chunk_sse(
    Problem {
        kernel,
        part,
        net,
        rho,
    }: Problem<'_>,
    range: Range<usize>,
    slot: &mut Slot,
    mut keep: Option<&mut [f64]>,
    stop: Option<(f64, Cutoff)>,
) -> Option<f64> {
    let width = kernel.keep_width(net);
    let cut = |sse: f64| stop.is_some_and(|(floor, c)| c.reached(floor, sse));
    let mut sse = 0.0;
    match kernel {
        Kernel::SingleLayer => {
            let h = net.hidden()[0];
            let mut k0 = range.start;
            while k0 < range.end {
                let kb = BLOCK.min(range.end - k0);
                let acts = match keep.as_mut() {
                    Some(k) => &mut k[(k0 - range.start) * width..(k0 - range.start + kb) * width],
                    None => &mut slot.acts[..kb * width],
                };
                forward_block(net, part, k0, kb, acts);
                block_residuals(
                    part,
                    rho,
                    k0,
                    kb,
                    &acts[h * kb..],
                    slot.e.as_mut_slice(),
                    &mut sse,
                );
                if cut(sse) {
                    return None;
                }
                k0 += kb;
            }
        }
        Kernel::Backprop => {
            let n = net.n_inputs();
            let out = net.output_range();
            let ws = &mut slot.ws;
            for k in range.clone() {
                ws.acts[..n].copy_from_slice(part.x.column(k).as_slice());
                net.forward_scaled(ws);
                for ((&y, &t), &r) in ws.acts[out.clone()]
                    .iter()
                    .zip(part.t.column(k).iter())
                    .zip(rho)
                {
                    let e = r * (t - y);
                    sse += e * e;
                }
                if let Some(keep) = keep.as_mut() {
                    let kk = k - range.start;
                    keep[kk * width..(kk + 1) * width].copy_from_slice(&ws.acts[..width]);
                }
                if (k + 1 - range.start).is_multiple_of(BLOCK) && cut(sse) {
                    return None;
                }
            }
        }
    }
    (!cut(sse)).then_some(sse)
}

/// Normal equations of the samples `range` of `part` (one chunk) into the slot's partial
/// sums, block by block in order.
fn chunk_normal_equations(
    Problem {
        kernel,
        part,
        net,
        rho,
    }: Problem<'_>,
    range: Range<usize>,
    slot: &mut Slot,
    kept: Option<&[f64]>,
) {
    let q = net.n_outputs();
    let width = kernel.keep_width(net);
    slot.jtj.fill(0.0);
    slot.jte.fill(0.0);
    let mut sse = 0.0;
    let mut k0 = range.start;
    while k0 < range.end {
        let kb = BLOCK.min(range.end - k0);
        let local = (k0 - range.start) * width..(k0 - range.start + kb) * width;
        match kernel {
            Kernel::SingleLayer => {
                let h = net.hidden()[0];
                let acts: &[f64] = match kept {
                    Some(k) => &k[local],
                    None => {
                        forward_block(net, part, k0, kb, &mut slot.acts[..kb * width]);
                        &slot.acts[..kb * width]
                    }
                };
                block_residuals(
                    part,
                    rho,
                    k0,
                    kb,
                    &acts[h * kb..],
                    slot.e.as_mut_slice(),
                    &mut sse,
                );
                single_layer_jacobian(net, part, rho, k0, kb, acts, &mut slot.j);
            }
            Kernel::Backprop => {
                let n = net.n_inputs();
                let out = net.output_range();
                for k in 0..kb {
                    let ws = &mut slot.ws;
                    match kept {
                        Some(acts) => ws.acts[..width].copy_from_slice(
                            &acts[local.start + k * width..local.start + (k + 1) * width],
                        ),
                        None => {
                            ws.acts[..n].copy_from_slice(part.x.column(k0 + k).as_slice());
                            net.forward_scaled(ws);
                        }
                    }
                    for (o, ((&y, &t), &r)) in ws.acts[out.clone()]
                        .iter()
                        .zip(part.t.column(k0 + k).iter())
                        .zip(rho)
                        .enumerate()
                    {
                        let ek = r * (t - y);
                        slot.e[k * q + o] = ek;
                        sse += ek * ek;
                    }
                    net.weight_rows_scaled(ws, rho, &mut slot.j, k * q);
                }
            }
        }
        let rows = kb * q;
        accumulate(
            &mut slot.jtj,
            &mut slot.jte,
            &slot.j,
            rows,
            &slot.e.rows(0, rows),
        );
        k0 += kb;
    }
    slot.sse = Some(sse);
}

/// `jtj += JᵀJ` (upper triangle only, by column panels:
/// `JᵀJ[0..c1, c0..c1] += Jᵀ[0..c1, :]·J[:, c0..c1]`) and `jte += Jᵀe` for the first `rows`
/// rows of the column-major block `j`. `Jᵀ` is a strided view of the same buffer; plain
/// `gemm` (not `gemm_tr`, which nalgebra evaluates as one matrix–vector product per
/// column) so that `matrixmultiply`'s blocked kernel runs.
fn accumulate(
    jtj: &mut DMatrix<f64>,
    jte: &mut DVector<f64>,
    j: &DMatrix<f64>,
    rows: usize,
    e: &DVectorView<'_, f64>,
) {
    let (ld, nw) = j.shape();
    let jv = j.rows(0, rows);
    let jt = DMatrixView::from_slice_with_strides(j.as_slice(), nw, rows, ld, 1);
    let mut c0 = 0;
    while c0 < nw {
        let c1 = (c0 + PANEL).min(nw);
        let mut panel = jtj.view_mut((0, c0), (c1, c1 - c0));
        if c1 > GEMM_MIN_DIM && c1 - c0 > GEMM_MIN_DIM && rows > GEMM_MIN_DIM {
            panel.gemm(1.0, &jt.rows(0, c1), &jv.columns(c0, c1 - c0), 1.0);
        } else {
            // nalgebra's own small-matrix loop would run instead of `matrixmultiply`, and
            // it mishandles the strided `Jᵀ` view: take dot products of `J`'s columns.
            panel.gemm_tr(1.0, &jv.columns(0, c1), &jv.columns(c0, c1 - c0), 1.0);
        }
        c0 = c1;
    }
    jte.gemv_tr(1.0, &jv, e, 1.0);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mlp::Architecture;
    use crate::scaling::Scaler;

    /// A network with `hidden` layers, 3 inputs and 2 outputs (output scales `rho`), and
    /// `n` deterministic samples, as a [`Part`].
    fn setup(hidden: Vec<usize>, outputs: usize, n: usize) -> (Mlp, Part, Vec<f64>) {
        let arch = Architecture {
            inputs: 3,
            hidden,
            outputs,
        };
        let x = DMatrix::from_fn(3, n, |i, k| ((i * 7 + k * 13) % 17) as f64 / 8.0 - 1.0);
        let t = DMatrix::from_fn(outputs, n, |o, k| (x[(0, k)] + o as f64 * x[(2, k)]).sin());
        let rho: Vec<f64> = [1.5, 0.5][..outputs].to_vec();
        let net = Mlp::new(&arch, 3)
            .unwrap()
            .with_scalers(
                Scaler::identity(3),
                Scaler::new(vec![0.0; outputs], rho.clone()).unwrap(),
            )
            .unwrap();
        let idx: Vec<usize> = (0..n).collect();
        let part = Part::gather(&net, &x, &t, &idx);
        (net, part, rho)
    }

    fn bits(v: &[f64]) -> Vec<u64> {
        v.iter().map(|x| x.to_bits()).collect()
    }

    /// Sample counts: inside one block; one chunk with a partial block; several chunks
    /// with a partial last chunk and block.
    const SIZES: [usize; 3] = [37, 2 * BLOCK + 37, 2 * CHUNK + 3 * BLOCK + 37];

    #[test]
    fn blocked_normal_equations_match_the_full_jacobian() {
        // One hidden layer (closed-form rows) and two (back-propagation), one and two
        // outputs: JᵀJ and Jᵀe against the products of the full Jacobian from
        // `weight_jacobian` (independent code), to round-off of sums of up to ~2,500 terms
        // of size ≤ max|JᵀJ| (ε·N relative, with margin).
        for hidden in [vec![5], vec![4, 3]] {
            for outputs in [1, 2] {
                for n in SIZES {
                    let (net, part, rho) = setup(hidden.clone(), outputs, n);
                    let mut lin = Linearisation::new(&net, n, Use::NormalEquations);
                    let sse = lin.build(&part, &net, &rho, None);
                    let x = part.x.clone();
                    let t = DMatrix::from_fn(outputs, n, |o, k| part.t[(o, k)] * rho[o]);
                    let jac = net.weight_jacobian(&x).unwrap();
                    let y = net.predict(&x).unwrap();
                    let e = DVector::from_iterator(n * outputs, (&t - &y).iter().copied());
                    let jtj = jac.transpose() * &jac;
                    let jte = jac.transpose() * &e;
                    let scale = jtj.amax();
                    let tol = 1e-15 * n as f64 * 10.0;
                    assert!(
                        (&lin.jtj - &jtj).amax() < tol * scale,
                        "{hidden:?} {outputs} {n}"
                    );
                    assert!((&lin.jte - &jte).amax() < tol * scale.max(jte.amax()));
                    assert!((sse - e.norm_squared()).abs() < tol * sse);
                }
            }
        }
    }

    #[test]
    fn curvature_matches_second_differences_of_the_outputs() {
        // Jᵀ r_vv from the closed-form kernel against the full Jacobian (independent code)
        // times the central second difference (y(w + hv) − 2y(w) + y(w − hv))/h² of the
        // network's outputs (the setup's output scaler is ρ, so `predict` gives ρ·ŷ, the
        // residuals up to sign and the target). Truncation O(h²·|y⁗|) ≈ 1e-8 and round-off
        // ε·|y|/h² ≈ 1e-8 at h = 1e-4: agreement to 1e-5 of the largest entry.
        for outputs in [1, 2] {
            for n in SIZES {
                let (mut net, part, rho) = setup(vec![5], outputs, n);
                let mut lin = Linearisation::new(&net, n, Use::NormalEquations);
                let mut kept = vec![0.0; lin.keep_len(&net)];
                lin.sse(&part, &net, &rho, Some(&mut kept), None).unwrap();
                let nw = net.n_weights();
                let v: Vec<f64> = (0..nw).map(|i| ((i * 5 % 11) as f64 - 5.0) / 7.0).collect();
                let mut got = DVector::zeros(nw);
                assert!(lin.curvature(&part, &net, &rho, &kept, &v, &mut got));

                let x = part.x.clone();
                let w0 = net.weights().to_vec();
                let jac = net.weight_jacobian(&x).unwrap();
                let y0 = net.predict(&x).unwrap();
                let h = 1e-4;
                let mut at = |sign: f64| {
                    let shifted: Vec<f64> =
                        w0.iter().zip(&v).map(|(w, d)| w + sign * h * d).collect();
                    net.weights_mut().copy_from_slice(&shifted);
                    net.predict(&x).unwrap()
                };
                let (yp, ym) = (at(1.0), at(-1.0));
                let rvv = (yp - &y0 * 2.0 + ym) / (h * h);
                let rvv = DVector::from_iterator(n * outputs, rvv.iter().copied());
                let want = jac.transpose() * rvv;
                let err = (&got - &want).amax();
                assert!(
                    err < 1e-5 * want.amax(),
                    "{outputs} {n}: {err:e} of {:e}",
                    want.amax()
                );
            }
        }
        // More than one hidden layer: no closed form, `out` left alone.
        let (net, part, rho) = setup(vec![4, 3], 1, 37);
        let mut lin = Linearisation::new(&net, 37, Use::NormalEquations);
        let mut out = DVector::from_element(net.n_weights(), 7.0);
        let v = vec![1.0; net.n_weights()];
        assert!(!lin.curvature(&part, &net, &rho, &[], &v, &mut out));
        assert!(out.iter().all(|&o| o.to_bits() == 7.0f64.to_bits()));
    }

    #[test]
    fn closed_form_kernel_gives_back_propagation_bits() {
        // One hidden layer and one output: the block kernel computes every activation,
        // residual and Jacobian entry with the same operations as back-propagation, rows in
        // the same order, so JᵀJ, Jᵀe and the SSE are the same bits.
        for n in SIZES {
            let (net, part, rho) = setup(vec![6], 1, n);
            let mut fast = Linearisation::new(&net, n, Use::NormalEquations);
            let mut slow =
                Linearisation::with_kernel(&net, n, Use::NormalEquations, Kernel::Backprop);
            let a = fast.build(&part, &net, &rho, None);
            let b = slow.build(&part, &net, &rho, None);
            assert_eq!(a.to_bits(), b.to_bits());
            assert_eq!(bits(fast.jtj.as_slice()), bits(slow.jtj.as_slice()));
            assert_eq!(bits(fast.jte.as_slice()), bits(slow.jte.as_slice()));
        }
    }

    #[test]
    fn same_bits_for_any_thread_count_and_with_kept_activations() {
        // The chunks are fixed by N alone and reduced in order: pools of 1 and 2 threads
        // give the same bits. Building from the activations kept by `sse` gives the same
        // bits as building with its own forward pass, and `sse` agrees with `build`.
        for hidden in [vec![5], vec![4, 3]] {
            let n = SIZES[2];
            let (net, part, rho) = setup(hidden, 2, n);
            // Large enough that two threads really split the chunks.
            assert!(n * net.n_weights() >= PARALLEL_MIN_WORK);
            let run = |threads: usize| {
                let pool = rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()
                    .unwrap();
                pool.install(|| {
                    let mut lin = Linearisation::new(&net, n, Use::NormalEquations);
                    let mut kept = vec![0.0; lin.keep_len(&net)];
                    let sse = lin.sse(&part, &net, &rho, Some(&mut kept), None).unwrap();
                    let built = lin.build(&part, &net, &rho, Some(&kept));
                    let (jtj, jte) = (lin.jtj.clone(), lin.jte.clone());
                    let fresh = lin.build(&part, &net, &rho, None);
                    assert_eq!(built.to_bits(), fresh.to_bits());
                    assert_eq!(sse.to_bits(), fresh.to_bits());
                    assert_eq!(bits(jtj.as_slice()), bits(lin.jtj.as_slice()));
                    assert_eq!(bits(jte.as_slice()), bits(lin.jte.as_slice()));
                    (bits(&[sse]), bits(jtj.as_slice()), bits(jte.as_slice()))
                })
            };
            assert_eq!(run(1), run(2));
        }
    }

    #[test]
    fn cutoff_stops_only_when_the_full_sum_reaches_the_limit() {
        // Below the true objective the evaluation is cut off (None); at or above the limit
        // it is not, and the SSE is the same bits as without a cutoff — for any thread
        // count (the groups of chunks depend on it, the answer must not).
        for hidden in [vec![5], vec![4, 3]] {
            for n in SIZES {
                let (net, part, rho) = setup(hidden.clone(), 1, n);
                for threads in [1, 2] {
                    let pool = rayon::ThreadPoolBuilder::new()
                        .num_threads(threads)
                        .build()
                        .unwrap();
                    pool.install(|| {
                        let mut lin = Linearisation::new(&net, n, Use::SseOnly);
                        let sse = lin.sse(&part, &net, &rho, None, None).unwrap();
                        let offset = 0.25;
                        let objective = sse + offset;
                        let mut at = |limit: f64| {
                            lin.sse(&part, &net, &rho, None, Some(Cutoff { offset, limit }))
                        };
                        // Just above: the full sum stays below, never cut.
                        let above = at(objective * (1.0 + 1e-12)).unwrap();
                        assert_eq!(above.to_bits(), sse.to_bits());
                        // At the objective itself "≥ limit" holds only at the very end.
                        assert_eq!(at(objective), None);
                        assert_eq!(at(objective * 0.5), None);
                        assert_eq!(at(0.0), None);
                    });
                }
            }
        }
    }
}
