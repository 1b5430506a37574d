//! The samples of one part of the data (training or validation) in scaled units, laid out
//! both ways: one sample per column for back-propagation, one channel contiguous over the
//! samples for the block kernels.

use nalgebra::DMatrix;

use crate::mlp::{Mlp, Workspace};

/// Samples per block of Jacobian rows: 128 rows of up to ~100 weights stay in L2 cache.
pub(super) const BLOCK: usize = 128;

/// Samples of one part (training or validation), in scaled units.
pub(super) struct Part {
    /// Inputs, `n × N` (one sample per column).
    pub(super) x: DMatrix<f64>,
    /// Targets, `q × N`.
    pub(super) t: DMatrix<f64>,
    /// Inputs transposed, `N × n`: each input channel contiguous over the samples.
    xt: DMatrix<f64>,
    /// Targets transposed, `N × q`.
    tt: DMatrix<f64>,
}

impl Part {
    pub(super) fn gather(
        net: &Mlp,
        inputs: &DMatrix<f64>,
        targets: &DMatrix<f64>,
        idx: &[usize],
    ) -> Self {
        let mut x = DMatrix::zeros(inputs.nrows(), idx.len());
        let mut t = DMatrix::zeros(targets.nrows(), idx.len());
        for (c, &k) in idx.iter().enumerate() {
            net.input_scaler()
                .scale_into(inputs.column(k).as_slice(), x.column_mut(c).as_mut_slice());
            net.output_scaler()
                .scale_into(targets.column(k).as_slice(), t.column_mut(c).as_mut_slice());
        }
        let (xt, tt) = (x.transpose(), t.transpose());
        Self { x, t, xt, tt }
    }

    pub(super) fn len(&self) -> usize {
        self.x.ncols()
    }

    /// Input channel `j` of samples `k0..k0 + kb`, contiguous.
    pub(super) fn input(&self, j: usize, k0: usize, kb: usize) -> &[f64] {
        let n = self.len();
        &self.xt.as_slice()[j * n + k0..j * n + k0 + kb]
    }

    /// Target channel `o` of samples `k0..k0 + kb`, contiguous.
    pub(super) fn target(&self, o: usize, k0: usize, kb: usize) -> &[f64] {
        let n = self.len();
        &self.tt.as_slice()[o * n + k0..o * n + k0 + kb]
    }

    /// Sum of squared errors `Σ (ρ_o·(t̂ − ŷ))²` over the part, one sample at a time in
    /// order (for [`Mlp::mse`]; training sums its errors with the linearisation).
    pub(super) fn sse(&self, net: &Mlp, rho: &[f64], ws: &mut Workspace) -> f64 {
        let n = net.n_inputs();
        let out = net.output_range();
        let mut sse = 0.0;
        for (x, t) in self.x.column_iter().zip(self.t.column_iter()) {
            ws.acts[..n].copy_from_slice(x.as_slice());
            net.forward_scaled(ws);
            for ((&y, &t), &r) in ws.acts[out.clone()].iter().zip(t.iter()).zip(rho) {
                let e = r * (t - y);
                sse += e * e;
            }
        }
        sse
    }
}
