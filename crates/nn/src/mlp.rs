//! The feed-forward network [`Mlp`]: architecture, flat weight vector and its layout,
//! Nguyen–Widrow initialisation, scaling, and the forward pass (one sample or a batch).

use nalgebra::DMatrix;
use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};
use serde::{Deserialize, Serialize};

use crate::error::{NnError, Result, check_finite, check_shape};
use crate::scaling::Scaler;

/// Layer sizes of a network: `inputs → hidden[0] → … → hidden[L−1] → outputs`.
///
/// Hidden layers use `tanh`; the output layer is linear. `hidden` may be empty (a purely
/// affine map), though the thesis networks have one hidden layer.
#[derive(Debug, Clone, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct Architecture {
    /// Number of network inputs.
    pub inputs: usize,
    /// Units in each hidden layer, first to last.
    pub hidden: Vec<usize>,
    /// Number of network outputs.
    pub outputs: usize,
}

impl Architecture {
    /// One hidden layer of `hidden` units.
    pub fn single(inputs: usize, hidden: usize, outputs: usize) -> Self {
        Self {
            inputs,
            hidden: vec![hidden],
            outputs,
        }
    }

    /// Check every dimension is at least 1.
    pub fn validate(&self) -> Result<()> {
        if self.inputs == 0 {
            return Err(NnError::ZeroDimension {
                what: "inputs",
                layer: 0,
            });
        }
        if let Some(layer) = self.hidden.iter().position(|&h| h == 0) {
            return Err(NnError::ZeroDimension {
                what: "hidden units",
                layer,
            });
        }
        if self.outputs == 0 {
            return Err(NnError::ZeroDimension {
                what: "outputs",
                layer: self.hidden.len(),
            });
        }
        Ok(())
    }

    /// Number of weight layers (hidden layers plus the output layer).
    pub fn n_layers(&self) -> usize {
        self.hidden.len() + 1
    }

    /// `(fan_in, units)` of weight layer `layer` (`0..n_layers()`; the last is the output
    /// layer).
    pub fn layer_shape(&self, layer: usize) -> (usize, usize) {
        let fan_in = if layer == 0 {
            self.inputs
        } else {
            self.hidden[layer - 1]
        };
        let units = if layer < self.hidden.len() {
            self.hidden[layer]
        } else {
            self.outputs
        };
        (fan_in, units)
    }

    /// Index of the first weight of layer `layer` in the flat weight vector.
    pub fn layer_offset(&self, layer: usize) -> usize {
        (0..layer)
            .map(|l| {
                let (fan_in, units) = self.layer_shape(l);
                units * (fan_in + 1)
            })
            .sum()
    }

    /// Total number of weights and biases.
    pub fn n_weights(&self) -> usize {
        self.layer_offset(self.n_layers())
    }
}

/// Reusable buffers for allocation-free forward passes and Jacobians.
///
/// Any workspace works with any network: it grows on first use with a larger network
/// and is never shrunk.
#[derive(Debug, Clone, Default)]
pub struct Workspace {
    /// Activations: scaled input, each hidden layer's output, scaled output (flat).
    pub(crate) acts: Vec<f64>,
    /// Back-propagated sensitivities (two buffers of the widest layer).
    pub(crate) delta: [Vec<f64>; 2],
}

impl Workspace {
    /// An empty workspace.
    pub fn new() -> Self {
        Self::default()
    }

    /// Make the buffers large enough for `arch`.
    /// An empty workspace, as a constant (for a `thread_local!` without lazy set-up).
    pub(crate) const fn empty() -> Self {
        Self {
            acts: Vec::new(),
            delta: [Vec::new(), Vec::new()],
        }
    }

    /// Room for the activations of a forward pass through `arch` (the back-propagation
    /// buffers are left as they are).
    pub(crate) fn prepare_forward(&mut self, arch: &Architecture) {
        let total = arch.inputs + arch.hidden.iter().sum::<usize>() + arch.outputs;
        if self.acts.len() < total {
            self.acts.resize(total, 0.0);
        }
    }

    pub(crate) fn prepare(&mut self, arch: &Architecture) {
        let total = arch.inputs + arch.hidden.iter().sum::<usize>() + arch.outputs;
        if self.acts.len() < total {
            self.acts.resize(total, 0.0);
        }
        let widest = arch
            .hidden
            .iter()
            .copied()
            .chain([arch.inputs, arch.outputs])
            .max()
            .unwrap_or(0);
        for d in &mut self.delta {
            if d.len() < widest {
                d.resize(widest, 0.0);
            }
        }
    }
}

/// A feed-forward network with `tanh` hidden layers, a linear output layer, and input
/// and output scaling stored in the network.
///
/// The weights act on *scaled* data: inputs are mapped by the input [`Scaler`] before the
/// first layer, and the last layer's output is mapped back by the output [`Scaler`].
///
/// # Weight layout
///
/// The flat weight vector ([`Mlp::weights`], [`Mlp::set_weights`]) lists the weight
/// layers in order (hidden layer 0, 1, …, then the output layer). Within a layer of
/// `units` units with `fan_in` inputs, unit `i` occupies the `fan_in + 1` entries
/// starting at `layer_offset + i·(fan_in + 1)`: its `fan_in` input weights, then its
/// bias. For a single hidden layer of `H` units, `n` inputs and `q` outputs that is
/// `[w₁₁ … w₁ₙ b₁, …, w_H1 … w_Hn b_H, v₁₁ … v₁H c₁, …, v_q1 … v_qH c_q]`, length
/// `H(n + 1) + q(H + 1)`. This layout is stable: condition monitoring reads weights as
/// features.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "MlpRaw")]
pub struct Mlp {
    arch: Architecture,
    weights: Vec<f64>,
    input_scaler: Scaler,
    output_scaler: Scaler,
}

#[derive(Deserialize)]
struct MlpRaw {
    arch: Architecture,
    weights: Vec<f64>,
    input_scaler: Scaler,
    output_scaler: Scaler,
}

impl TryFrom<MlpRaw> for Mlp {
    type Error = NnError;
    fn try_from(raw: MlpRaw) -> Result<Self> {
        Mlp::from_parts(raw.arch, raw.weights, raw.input_scaler, raw.output_scaler)
    }
}

impl Mlp {
    /// A network with identity scaling and Nguyen–Widrow initial weights drawn from
    /// `ChaCha8Rng::seed_from_u64(seed)` (see [`Mlp::initialise`]).
    pub fn new(arch: &Architecture, seed: u64) -> Result<Self> {
        arch.validate()?;
        let mut net = Self {
            arch: arch.clone(),
            weights: vec![0.0; arch.n_weights()],
            input_scaler: Scaler::identity(arch.inputs),
            output_scaler: Scaler::identity(arch.outputs),
        };
        net.initialise(seed);
        Ok(net)
    }

    /// A network sized for `inputs` (`n × N`) and `targets` (`q × N`), with scalers fitted
    /// to that data and Nguyen–Widrow initial weights from `seed`.
    ///
    /// Errors: a zero-size hidden layer, zero channels or samples, different sample counts,
    /// a non-finite entry.
    pub fn for_data(
        inputs: &DMatrix<f64>,
        targets: &DMatrix<f64>,
        hidden: &[usize],
        seed: u64,
    ) -> Result<Self> {
        let arch = Architecture {
            inputs: inputs.nrows(),
            hidden: hidden.to_vec(),
            outputs: targets.nrows(),
        };
        arch.validate()?;
        check_training_data(&arch, inputs, targets)?;
        let input_scaler = Scaler::fit(inputs)?;
        let output_scaler = Scaler::fit(targets)?;
        let mut net = Self {
            arch: arch.clone(),
            weights: vec![0.0; arch.n_weights()],
            input_scaler,
            output_scaler,
        };
        net.initialise(seed);
        Ok(net)
    }

    /// Assemble a network from its parts (this is also how deserialisation validates).
    ///
    /// Errors: invalid architecture, wrong weight count, non-finite weight, scaler sizes
    /// not matching the inputs/outputs.
    pub fn from_parts(
        arch: Architecture,
        weights: Vec<f64>,
        input_scaler: Scaler,
        output_scaler: Scaler,
    ) -> Result<Self> {
        arch.validate()?;
        check_weights(&arch, &weights)?;
        if input_scaler.len() != arch.inputs {
            return Err(NnError::Length {
                what: "input scaler channels",
                found: input_scaler.len(),
                expected: arch.inputs,
            });
        }
        if output_scaler.len() != arch.outputs {
            return Err(NnError::Length {
                what: "output scaler channels",
                found: output_scaler.len(),
                expected: arch.outputs,
            });
        }
        Ok(Self {
            arch,
            weights,
            input_scaler,
            output_scaler,
        })
    }

    /// Replace the scalers (weights are kept, so the map changes).
    ///
    /// Errors: scaler sizes not matching the inputs/outputs.
    pub fn with_scalers(self, input_scaler: Scaler, output_scaler: Scaler) -> Result<Self> {
        Self::from_parts(self.arch, self.weights, input_scaler, output_scaler)
    }

    /// Re-draw every weight from `ChaCha8Rng::seed_from_u64(seed)`.
    ///
    /// Hidden layers use Nguyen–Widrow (Nguyen & Widrow, IJCNN 1990): for a layer of `S`
    /// units with `R` inputs assumed in [−1, 1], each unit's weight vector is drawn
    /// uniformly in [−1, 1]ᴿ and rescaled to norm `β = 0.7·S^(1/R)`, and its bias is
    /// uniform in [−β, β], so the units' active regions tile the input box. The scaled
    /// inputs and every `tanh` output lie in [−1, 1], as the rule assumes. The linear
    /// output layer's weights and biases are uniform in ±1/√(fan_in + 1), which keeps the
    /// initial scaled output of order 1 for any hidden width.
    pub fn initialise(&mut self, seed: u64) {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let n_layers = self.arch.n_layers();
        for layer in 0..n_layers {
            let (fan_in, units) = self.arch.layer_shape(layer);
            let offset = self.arch.layer_offset(layer);
            let block = &mut self.weights[offset..offset + units * (fan_in + 1)];
            if layer + 1 < n_layers {
                let beta = 0.7 * (units as f64).powf(1.0 / fan_in as f64);
                for unit in block.chunks_exact_mut(fan_in + 1) {
                    let (w, b) = unit.split_at_mut(fan_in);
                    // Redraw the (probability-zero) near-null direction so the norm is usable.
                    let norm = loop {
                        for v in w.iter_mut() {
                            *v = rng.random_range(-1.0..1.0);
                        }
                        let norm = w.iter().map(|v| v * v).sum::<f64>().sqrt();
                        if norm > 1e-8 {
                            break norm;
                        }
                    };
                    for v in w.iter_mut() {
                        *v *= beta / norm;
                    }
                    b[0] = rng.random_range(-beta..beta);
                }
            } else {
                let r = 1.0 / ((fan_in + 1) as f64).sqrt();
                for v in block.iter_mut() {
                    *v = rng.random_range(-r..r);
                }
            }
        }
    }

    /// The architecture.
    pub fn architecture(&self) -> &Architecture {
        &self.arch
    }

    /// Number of inputs.
    pub fn n_inputs(&self) -> usize {
        self.arch.inputs
    }

    /// Number of outputs.
    pub fn n_outputs(&self) -> usize {
        self.arch.outputs
    }

    /// Units per hidden layer.
    pub fn hidden(&self) -> &[usize] {
        &self.arch.hidden
    }

    /// Number of weights and biases.
    pub fn n_weights(&self) -> usize {
        self.weights.len()
    }

    /// The flat weight vector (layout in the [type docs](Mlp#weight-layout)).
    pub fn weights(&self) -> &[f64] {
        &self.weights
    }

    /// Replace the flat weight vector (layout in the [type docs](Mlp#weight-layout)).
    ///
    /// Errors: wrong length, non-finite entry (the network is left unchanged).
    pub fn set_weights(&mut self, weights: &[f64]) -> Result<()> {
        check_weights(&self.arch, weights)?;
        self.weights.copy_from_slice(weights);
        Ok(())
    }

    /// Set weights without checks (trainer's trial steps; length is guaranteed there).
    pub(crate) fn weights_mut(&mut self) -> &mut [f64] {
        &mut self.weights
    }

    /// The `fan_in + 1` entries of one unit: its input weights, then its bias.
    /// `None` if `layer` or `unit` is out of range.
    pub fn unit_weights(&self, layer: usize, unit: usize) -> Option<&[f64]> {
        if layer >= self.arch.n_layers() {
            return None;
        }
        let (fan_in, units) = self.arch.layer_shape(layer);
        if unit >= units {
            return None;
        }
        let start = self.arch.layer_offset(layer) + unit * (fan_in + 1);
        self.weights.get(start..start + fan_in + 1)
    }

    /// The input scaler.
    pub fn input_scaler(&self) -> &Scaler {
        &self.input_scaler
    }

    /// The output scaler.
    pub fn output_scaler(&self) -> &Scaler {
        &self.output_scaler
    }

    /// Evaluate one sample: `y = net(x)`, allocation-free once `ws` has grown.
    ///
    /// Errors: `x` or `y` of the wrong length. Non-finite inputs propagate to `y`.
    pub fn forward(&self, x: &[f64], y: &mut [f64], ws: &mut Workspace) -> Result<()> {
        self.check_io(x.len(), y.len())?;
        ws.prepare(&self.arch);
        self.input_scaler
            .scale_into(x, &mut ws.acts[..self.arch.inputs]);
        self.forward_scaled(ws);
        let out = self.output_range();
        self.output_scaler.unscale_into(&ws.acts[out], y);
        Ok(())
    }

    /// Evaluate a batch: `inputs` is `n × N` (one sample per column); returns `q × N`.
    ///
    /// Errors: wrong number of input rows, a non-finite input.
    pub fn predict(&self, inputs: &DMatrix<f64>) -> Result<DMatrix<f64>> {
        check_shape("inputs", inputs, self.arch.inputs, inputs.ncols())?;
        check_finite("inputs", inputs)?;
        let mut out = DMatrix::zeros(self.arch.outputs, inputs.ncols());
        let mut ws = Workspace::new();
        for (x, mut y) in inputs.column_iter().zip(out.column_iter_mut()) {
            // Columns of a DMatrix are contiguous.
            self.forward(x.as_slice(), y.as_mut_slice(), &mut ws)?;
        }
        Ok(out)
    }

    /// Forward pass in scaled units: reads `ws.acts[..n_inputs]` (already scaled) and
    /// fills every later activation. `ws` must be prepared.
    pub(crate) fn forward_scaled(&self, ws: &mut Workspace) {
        let n_layers = self.arch.n_layers();
        let mut in_start = 0;
        for layer in 0..n_layers {
            let (fan_in, units) = self.arch.layer_shape(layer);
            let offset = self.arch.layer_offset(layer);
            let (before, after) = ws.acts.split_at_mut(in_start + fan_in);
            let a_in = &before[in_start..];
            let a_out = &mut after[..units];
            let block = &self.weights[offset..offset + units * (fan_in + 1)];
            for (o, unit) in a_out.iter_mut().zip(block.chunks_exact(fan_in + 1)) {
                let s = unit[fan_in]
                    + unit[..fan_in]
                        .iter()
                        .zip(a_in)
                        .map(|(w, a)| w * a)
                        .sum::<f64>();
                *o = if layer + 1 < n_layers { tanh(s) } else { s };
            }
            in_start += fan_in;
        }
    }

    /// Range of `ws.acts` holding the first activation of layer input `layer`
    /// (`0` = scaled input, `n_layers()` = scaled output).
    pub(crate) fn acts_start(&self, layer: usize) -> usize {
        (0..layer).map(|l| self.arch.layer_shape(l).0).sum()
    }

    /// Range of `ws.acts` holding the scaled output.
    pub(crate) fn output_range(&self) -> std::ops::Range<usize> {
        let start = self.acts_start(self.arch.n_layers());
        start..start + self.arch.outputs
    }

    pub(crate) fn check_io(&self, x_len: usize, y_len: usize) -> Result<()> {
        if x_len != self.arch.inputs {
            return Err(NnError::Length {
                what: "input sample",
                found: x_len,
                expected: self.arch.inputs,
            });
        }
        if y_len != self.arch.outputs {
            return Err(NnError::Length {
                what: "output sample",
                found: y_len,
                expected: self.arch.outputs,
            });
        }
        Ok(())
    }
}

/// `tanh` through one `exp`: `tanh(s) = sign(s)·(1 − 2/(e^{2|s|} + 1))`.
///
/// About three times faster than `f64::tanh` (which goes through `expm1`), and training
/// spends most of its time here. Odd by construction, exactly ±1 once `e^{2|s|}` overflows,
/// NaN in → NaN out. The absolute error is a few ulps of 1 (≤ 1e-15); the relative error
/// grows as `|s|` → 0 (about ε/|s|), which no network output or derivative notices because
/// every activation enters a sum with O(1) terms.
#[inline]
pub(crate) fn tanh(s: f64) -> f64 {
    let e = (2.0 * s.abs()).exp();
    (1.0 - 2.0 / (e + 1.0)).copysign(s)
}

/// Validate a weight vector against an architecture.
fn check_weights(arch: &Architecture, weights: &[f64]) -> Result<()> {
    let expected = arch.n_weights();
    if weights.len() != expected {
        return Err(NnError::Length {
            what: "weight vector",
            found: weights.len(),
            expected,
        });
    }
    if let Some(k) = weights.iter().position(|w| !w.is_finite()) {
        return Err(NnError::NonFinite {
            matrix: "weight vector",
            channel: 0,
            sample: k,
        });
    }
    Ok(())
}

/// Validate training data against an architecture: shapes, at least one sample, finite.
pub(crate) fn check_training_data(
    arch: &Architecture,
    inputs: &DMatrix<f64>,
    targets: &DMatrix<f64>,
) -> Result<()> {
    check_shape("inputs", inputs, arch.inputs, inputs.ncols())?;
    check_shape("targets", targets, arch.outputs, inputs.ncols())?;
    if inputs.ncols() == 0 {
        return Err(NnError::TooFewSamples {
            what: "training data",
            found: 0,
            needed: 1,
        });
    }
    check_finite("inputs", inputs)?;
    check_finite("targets", targets)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fast_tanh_matches_std_to_a_few_ulps_of_one() {
        // Absolute error bound 1e-15 (a few ulps of 1) over a fine grid, both tails and 0.
        let mut worst = 0.0f64;
        for k in -200_000..=200_000 {
            let s = k as f64 * 1e-4;
            worst = worst.max((tanh(s) - s.tanh()).abs());
        }
        assert!(worst < 1e-15, "worst {worst}");
        assert_eq!(tanh(0.0).to_bits(), 0.0f64.to_bits());
        // Saturation is exact: the bits of ±1.
        assert_eq!(tanh(800.0).to_bits(), 1.0f64.to_bits());
        assert_eq!(tanh(-800.0).to_bits(), (-1.0f64).to_bits());
        assert!(tanh(f64::NAN).is_nan());
    }

    #[test]
    fn layout_matches_hand_count() {
        // 3 inputs, hidden [4, 2], 2 outputs: 4·4 + 2·5 + 2·3 = 32 weights.
        let arch = Architecture {
            inputs: 3,
            hidden: vec![4, 2],
            outputs: 2,
        };
        assert_eq!(arch.n_weights(), 32);
        assert_eq!(arch.layer_offset(1), 16);
        assert_eq!(arch.layer_offset(2), 26);
    }

    #[test]
    fn forward_matches_hand_computation() {
        // 1 input, 2 hidden, 1 output, identity scaling:
        // y = 0.5·tanh(2x + 0.1) − 1.5·tanh(−x + 0.3) + 0.25.
        let arch = Architecture::single(1, 2, 1);
        let mut net = Mlp::new(&arch, 0).unwrap();
        net.set_weights(&[2.0, 0.1, -1.0, 0.3, 0.5, -1.5, 0.25])
            .unwrap();
        let x = 0.7_f64;
        let expected = 0.5 * (2.0 * x + 0.1).tanh() - 1.5 * (-x + 0.3).tanh() + 0.25;
        let mut y = [0.0];
        net.forward(&[x], &mut y, &mut Workspace::new()).unwrap();
        // Same operations in a different order: a few ulps of an O(1) value.
        assert!((y[0] - expected).abs() < 1e-15);
        assert_eq!(net.unit_weights(0, 1), Some(&[-1.0, 0.3][..]));
        assert_eq!(net.unit_weights(1, 0), Some(&[0.5, -1.5, 0.25][..]));
        assert_eq!(net.unit_weights(1, 1), None);
    }

    #[test]
    fn nguyen_widrow_norms() {
        // Hidden-unit weight vectors have norm β = 0.7·S^(1/R) and |bias| ≤ β.
        let arch = Architecture::single(2, 9, 1);
        let net = Mlp::new(&arch, 3).unwrap();
        let beta = 0.7 * 9f64.powf(0.5);
        for unit in 0..9 {
            let w = net.unit_weights(0, unit).unwrap();
            let norm = (w[0] * w[0] + w[1] * w[1]).sqrt();
            assert!((norm - beta).abs() < 1e-12 * beta);
            assert!(w[2].abs() <= beta);
        }
    }

    #[test]
    fn zero_dimensions_are_typed_errors() {
        let bad = Architecture {
            inputs: 2,
            hidden: vec![3, 0],
            outputs: 1,
        };
        assert_eq!(
            Mlp::new(&bad, 0).unwrap_err(),
            NnError::ZeroDimension {
                what: "hidden units",
                layer: 1
            }
        );
        let bad = Architecture::single(0, 3, 1);
        assert!(matches!(
            Mlp::new(&bad, 0),
            Err(NnError::ZeroDimension { what: "inputs", .. })
        ));
    }
}
