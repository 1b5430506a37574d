//! Analytic derivatives of an [`Mlp`] by back-propagation: the Jacobian of the outputs
//! with respect to every weight (for Levenberg–Marquardt and sensitivity studies) and the
//! input–output Jacobian `∂y/∂x` (for linearising a hybrid model).

use nalgebra::DMatrix;

use crate::error::{NnError, Result, check_finite, check_shape};
use crate::mlp::{Mlp, Workspace};

impl Mlp {
    /// Jacobian of the outputs with respect to all weights, in original output units.
    ///
    /// `inputs` is `n × N`. The result has `N·q` rows and [`Mlp::n_weights`] columns; row
    /// `k·q + o` is `∂y_o(x_k)/∂w`, with columns in the [weight layout](Mlp#weight-layout).
    ///
    /// Errors: wrong number of input rows, a non-finite input.
    pub fn weight_jacobian(&self, inputs: &DMatrix<f64>) -> Result<DMatrix<f64>> {
        check_shape("inputs", inputs, self.n_inputs(), inputs.ncols())?;
        check_finite("inputs", inputs)?;
        let q = self.n_outputs();
        let mut jac = DMatrix::zeros(inputs.ncols() * q, self.n_weights());
        let mut ws = Workspace::new();
        ws.prepare(self.architecture());
        let n_in = self.n_inputs();
        let rho = self.output_scaler().half_range().to_vec();
        for (k, x) in inputs.column_iter().enumerate() {
            self.input_scaler()
                .scale_into(x.as_slice(), &mut ws.acts[..n_in]);
            self.forward_scaled(&mut ws);
            self.weight_rows_scaled(&mut ws, &rho, &mut jac, k * q);
        }
        Ok(jac)
    }

    /// Input–output Jacobian `∂y/∂x` (`q × n`, original units) at one input sample.
    ///
    /// Errors: `x` of the wrong length.
    pub fn input_jacobian(&self, x: &[f64]) -> Result<DMatrix<f64>> {
        let mut y = vec![0.0; self.n_outputs()];
        let mut jac = DMatrix::zeros(self.n_outputs(), self.n_inputs());
        self.input_jacobian_into(x, &mut y, &mut jac, &mut Workspace::new())?;
        Ok(jac)
    }

    /// Output `y` and input–output Jacobian `∂y/∂x` (`q × n`) at `x`, written into
    /// caller-owned buffers; allocation-free once `ws` has grown.
    ///
    /// Errors: `x`, `y` or `jac` of the wrong size.
    pub fn input_jacobian_into(
        &self,
        x: &[f64],
        y: &mut [f64],
        jac: &mut DMatrix<f64>,
        ws: &mut Workspace,
    ) -> Result<()> {
        self.check_io(x.len(), y.len())?;
        let (q, n) = (self.n_outputs(), self.n_inputs());
        if jac.nrows() != q || jac.ncols() != n {
            return Err(NnError::Shape {
                matrix: "input Jacobian",
                rows: jac.nrows(),
                cols: jac.ncols(),
                expected_rows: q,
                expected_cols: n,
            });
        }
        ws.prepare(self.architecture());
        self.input_scaler().scale_into(x, &mut ws.acts[..n]);
        self.forward_scaled(ws);
        let out = self.output_range();
        self.output_scaler().unscale_into(&ws.acts[out], y);
        self.input_gradients(ws, |o, j, v| jac[(o, j)] = v);
        Ok(())
    }

    /// Output `y`, its weight Jacobian `∂y/∂w` (`q × n_w`, columns in the
    /// [weight layout](Mlp#weight-layout)) and its input Jacobian `∂y/∂x` (`q × n`), all in
    /// original units, at one input sample, from one forward and `q` backward passes;
    /// allocation-free once `ws` has grown. For simulation-error training of a model that
    /// feeds the network's outputs back into its inputs, where both derivatives enter the
    /// chain rule at every sample.
    ///
    /// Errors: `x`, `y`, `dw` or `dx` of the wrong size.
    pub fn gradients_into(
        &self,
        x: &[f64],
        y: &mut [f64],
        dw: &mut DMatrix<f64>,
        dx: &mut DMatrix<f64>,
        ws: &mut Workspace,
    ) -> Result<()> {
        self.check_io(x.len(), y.len())?;
        let (q, n, nw) = (self.n_outputs(), self.n_inputs(), self.n_weights());
        for (matrix, m, cols) in [("weight Jacobian", &*dw, nw), ("input Jacobian", &*dx, n)] {
            if m.nrows() != q || m.ncols() != cols {
                return Err(NnError::Shape {
                    matrix,
                    rows: m.nrows(),
                    cols: m.ncols(),
                    expected_rows: q,
                    expected_cols: cols,
                });
            }
        }
        ws.prepare(self.architecture());
        self.input_scaler().scale_into(x, &mut ws.acts[..n]);
        self.forward_scaled(ws);
        let out = self.output_range();
        self.output_scaler().unscale_into(&ws.acts[out], y);
        let h_out = self.output_scaler().half_range();
        let h_in = self.input_scaler().half_range();
        for (o, &h) in h_out.iter().enumerate() {
            // Seeded with the output's half-range, the pass writes ∂y_o/∂w in original
            // units and leaves ∂y_o/∂s (scaled input) in the first delta buffer.
            self.backward(ws, o, h, Some((dw, o)));
            for (j, &hj) in h_in.iter().enumerate() {
                dx[(o, j)] = ws.delta[0][j] / hj;
            }
        }
        Ok(())
    }

    /// Call `put(o, j, ∂y_o/∂x_j)` for every output and input (original units). `ws` must
    /// hold a forward pass of the sample.
    pub(crate) fn input_gradients(
        &self,
        ws: &mut Workspace,
        mut put: impl FnMut(usize, usize, f64),
    ) {
        let h_out = self.output_scaler().half_range();
        let h_in = self.input_scaler().half_range();
        for (o, &h) in h_out.iter().enumerate() {
            self.backward(ws, o, h, None);
            // After the full pass the first delta buffer holds ∂(h_o·ŷ_o)/∂s (scaled input);
            // s_j = (x_j − c_j)/h_j adds the factor 1/h_j.
            for (j, &hj) in h_in.iter().enumerate() {
                put(o, j, ws.delta[0][j] / hj);
            }
        }
    }

    /// Write `ρ_o·∂ŷ_o/∂w` for every output `o` into rows `row0 + o` of `jac`, where `ŷ` is
    /// the scaled output. `ws` must hold a forward pass of the sample.
    pub(crate) fn weight_rows_scaled(
        &self,
        ws: &mut Workspace,
        rho: &[f64],
        jac: &mut DMatrix<f64>,
        row0: usize,
    ) {
        for (o, &r) in rho.iter().enumerate() {
            self.backward(ws, o, r, Some((jac, row0 + o)));
        }
    }

    /// Back-propagate the sensitivity of scaled output `o` (times `seed`) through every
    /// layer. Writes weight derivatives into `rows` when given; on return `ws.delta[0]`
    /// holds the derivative with respect to the scaled input.
    ///
    /// For weight layer `l` with input activations `a` and sensitivities `δ` of its
    /// units, `∂/∂W[i,j] = δ_i·a_j` and `∂/∂b_i = δ_i`; the next sensitivities are
    /// `δ'_j = (Σ_i W[i,j]·δ_i)·(1 − a_j²)` (tanh′ = 1 − tanh²), without the tanh factor at
    /// the network input.
    fn backward(
        &self,
        ws: &mut Workspace,
        o: usize,
        seed: f64,
        mut rows: Option<(&mut DMatrix<f64>, usize)>,
    ) {
        let arch = self.architecture();
        let n_layers = arch.n_layers();
        let [cur, next] = &mut ws.delta;
        let (_, q) = arch.layer_shape(n_layers - 1);
        cur[..q].fill(0.0);
        cur[o] = seed;
        let w = self.weights();
        for layer in (0..n_layers).rev() {
            let (fan_in, units) = arch.layer_shape(layer);
            let offset = arch.layer_offset(layer);
            let a_start = self.acts_start(layer);
            let a_in = &ws.acts[a_start..a_start + fan_in];
            if let Some((jac, row)) = rows.as_mut() {
                for (i, &d) in cur[..units].iter().enumerate() {
                    let base = offset + i * (fan_in + 1);
                    for (j, &a) in a_in.iter().enumerate() {
                        jac[(*row, base + j)] = d * a;
                    }
                    jac[(*row, base + fan_in)] = d;
                }
            }
            next[..fan_in].fill(0.0);
            for (i, &d) in cur[..units].iter().enumerate() {
                let base = offset + i * (fan_in + 1);
                for (nj, &wij) in next[..fan_in].iter_mut().zip(&w[base..base + fan_in]) {
                    *nj += wij * d;
                }
            }
            if layer > 0 {
                for (nj, &a) in next[..fan_in].iter_mut().zip(a_in) {
                    *nj *= 1.0 - a * a;
                }
            }
            std::mem::swap(cur, next);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mlp::Architecture;

    #[test]
    fn single_unit_derivatives_match_closed_form() {
        // y = v·tanh(w·x + b) + c with identity scaling:
        // ∂y/∂w = v·x·sech², ∂y/∂b = v·sech², ∂y/∂v = tanh, ∂y/∂c = 1, ∂y/∂x = v·w·sech².
        let mut net = Mlp::new(&Architecture::single(1, 1, 1), 0).unwrap();
        let (w, b, v, c) = (0.8, -0.2, 1.7, 0.4);
        net.set_weights(&[w, b, v, c]).unwrap();
        let x = 0.6;
        let t = (w * x + b).tanh();
        let s2 = 1.0 - t * t;
        let jac = net
            .weight_jacobian(&DMatrix::from_element(1, 1, x))
            .unwrap();
        let expected = [v * x * s2, v * s2, t, 1.0];
        for (k, e) in expected.iter().enumerate() {
            assert!((jac[(0, k)] - e).abs() < 1e-15, "weight {k}");
        }
        let dx = net.input_jacobian(&[x]).unwrap();
        assert!((dx[(0, 0)] - v * w * s2).abs() < 1e-15);
    }
}
