//! A trained network used as the model-error term of a hybrid model: [`NetCorrection`]
//! implements `sysid_core::Correction` with network inputs `[x, u]` (or `x` alone, for a
//! network trained on the states only: it ignores the model's inputs) and outputs `d`,
//! and gives the Jacobians `∂d/∂x`, `∂d/∂u` for linearisation.
//!
//! Outside the box its training pairs spanned (the input scaler's `[−1, 1]` per input),
//! a network extrapolates however its weights happen to: [`Domain::Hold`] clamps every
//! scaled input to `[−1, 1]` first, so the correction keeps its value at the nearest
//! point of the box (the physics carries the model beyond the data, the network does
//! not). [`Domain::Extrapolate`], the thesis method, evaluates the network anywhere.

use std::cell::RefCell;

use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};
use sysid_core::Correction;

use crate::error::{NnError, Result};
use crate::mlp::{Mlp, Workspace};

/// A network `d = NN([x; u])` read as a correction of a model with `n_states` states and
/// `n_model_inputs` inputs: network inputs `0..n_states` are the states, the rest (if the
/// network has any) are the model inputs; a network with exactly `n_states` inputs sees
/// the states alone and ignores the model's inputs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "NetCorrectionRaw")]
pub struct NetCorrection {
    net: Mlp,
    n_states: usize,
    #[serde(default)]
    domain: Domain,
    n_model_inputs: usize,
}

/// What a [`NetCorrection`] does with inputs outside the box its training data spanned
/// (module doc).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Domain {
    /// Evaluate the network wherever it is asked (the thesis method).
    #[default]
    Extrapolate,
    /// Clamp each scaled input to `[−1, 1]`: the correction holds its value at the box's
    /// nearest point, and its derivative along a clamped input is zero.
    Hold,
}

#[derive(Deserialize)]
struct NetCorrectionRaw {
    net: Mlp,
    n_states: usize,
    #[serde(default)]
    domain: Domain,
    /// Absent in files written before states-only networks: the network saw every input.
    #[serde(default)]
    n_model_inputs: Option<usize>,
}

impl TryFrom<NetCorrectionRaw> for NetCorrection {
    type Error = NnError;
    fn try_from(raw: NetCorrectionRaw) -> Result<Self> {
        let corr = match raw.n_model_inputs {
            Some(m) => NetCorrection::for_model(raw.net, raw.n_states, m)?,
            None => NetCorrection::new(raw.net, raw.n_states)?,
        };
        Ok(corr.with_domain(raw.domain))
    }
}

thread_local! {
    /// Per-thread scratch for [`Correction::eval`], which takes `&self` and cannot carry a
    /// caller workspace; it lets integrators call the network without allocating.
    /// Initialised as a constant, so an access checks no lazy initialisation.
    static SCRATCH: RefCell<Workspace> = const { RefCell::new(Workspace::empty()) };
}

impl NetCorrection {
    /// Wrap `net`, whose first `n_states` inputs are states and the remaining ones model
    /// inputs.
    ///
    /// Errors: `n_states` larger than the network's input count.
    pub fn new(net: Mlp, n_states: usize) -> Result<Self> {
        let Some(n_model_inputs) = net.n_inputs().checked_sub(n_states) else {
            return Err(NnError::CorrectionSplit {
                n_states,
                n_inputs: net.n_inputs(),
            });
        };
        Self::for_model(net, n_states, n_model_inputs)
    }

    /// Wrap `net` as the correction of a model with `n_states` states and `n_model_inputs`
    /// inputs: a network with `n_states + n_model_inputs` inputs sees `[x; u]` (as
    /// [`NetCorrection::new`]), one with `n_states` inputs sees the states alone.
    ///
    /// Errors: any other input count.
    pub fn for_model(net: Mlp, n_states: usize, n_model_inputs: usize) -> Result<Self> {
        let n = net.n_inputs();
        if n != n_states && n != n_states + n_model_inputs {
            return Err(NnError::CorrectionInputs {
                n_states,
                n_model_inputs,
                n_inputs: n,
            });
        }
        Ok(Self {
            net,
            n_states,
            domain: Domain::Extrapolate,
            n_model_inputs,
        })
    }

    /// Whether the network sees the model's inputs (false: the states alone).
    pub fn sees_inputs(&self) -> bool {
        self.net.n_inputs() == self.n_states + self.n_model_inputs
    }

    /// The same correction with the given behaviour outside the training box.
    pub fn with_domain(mut self, domain: Domain) -> Self {
        self.domain = domain;
        self
    }

    /// What the correction does outside the training box.
    pub fn domain(&self) -> Domain {
        self.domain
    }

    /// Whether the network's inputs at `(x, u)` lie inside the box the network's input
    /// scaler maps onto `[−1, 1]` (its training data's range per input; for a constant
    /// channel its value ± 1, the scaler's unit half-range). A states-only network looks
    /// at `x` alone. Slices of the wrong length are outside.
    pub fn in_domain(&self, x: &[f64], u: &[f64]) -> bool {
        let seen = if self.sees_inputs() { u } else { &[] };
        x.len() == self.n_states
            && u.len() == self.n_model_inputs
            && x.iter()
                .chain(seen)
                .enumerate()
                .all(|(j, &v)| !self.outside(j, v))
    }

    /// Whether value `v` of network input `j` lies outside its training range.
    fn outside(&self, j: usize, v: f64) -> bool {
        let s = self.net.input_scaler();
        ((v - s.centre()[j]) / s.half_range()[j]).abs() > 1.0
    }

    /// The network.
    pub fn network(&self) -> &Mlp {
        &self.net
    }

    /// The network's flat weight vector, mutable (training in place; the architecture,
    /// and so the split into states and inputs, cannot change through it).
    pub fn weights_mut(&mut self) -> &mut [f64] {
        self.net.weights_mut()
    }

    /// Give back the network.
    pub fn into_network(self) -> Mlp {
        self.net
    }

    /// Evaluate `d = NN([x; u])` with a caller workspace (allocation-free once it has
    /// grown).
    ///
    /// Errors: `x`, `u` or `d` of the wrong length.
    pub fn eval_into(&self, x: &[f64], u: &[f64], d: &mut [f64], ws: &mut Workspace) -> Result<()> {
        self.view().eval_into(x, u, d, ws)
    }

    /// The network borrowed as a correction.
    pub(crate) fn view(&self) -> NetView<'_> {
        NetView {
            net: &self.net,
            n_states: self.n_states,
            n_model_inputs: self.n_model_inputs,
            domain: self.domain,
        }
    }

    /// Evaluate `d` and the Jacobians `∂d/∂x` (`q × n`) and `∂d/∂u` (`q × m`) at `(x, u)`.
    ///
    /// Errors: any slice or matrix of the wrong size.
    pub fn jacobians(
        &self,
        x: &[f64],
        u: &[f64],
        d: &mut [f64],
        dx: &mut DMatrix<f64>,
        du: &mut DMatrix<f64>,
        ws: &mut Workspace,
    ) -> Result<()> {
        let q = self.net.n_outputs();
        let m = self.n_inputs();
        for (matrix, mat, cols) in [("dd/dx", &*dx, self.n_states), ("dd/du", &*du, m)] {
            if mat.nrows() != q || mat.ncols() != cols {
                return Err(NnError::Shape {
                    matrix,
                    rows: mat.nrows(),
                    cols: mat.ncols(),
                    expected_rows: q,
                    expected_cols: cols,
                });
            }
        }
        self.eval_into(x, u, d, ws)?;
        // The forward pass sized only the activations; back-propagation needs the rest.
        ws.prepare(self.net.architecture());
        let n = self.n_states;
        // Along a clamped input the correction does not change.
        let hold = self.domain == Domain::Hold;
        let clamped = |j: usize| hold && self.outside(j, if j < n { x[j] } else { u[j - n] });
        // A states-only network does not depend on the inputs.
        du.fill(0.0);
        self.net.input_gradients(ws, |o, j, v| {
            let v = if clamped(j) { 0.0 } else { v };
            if j < n {
                dx[(o, j)] = v;
            } else {
                du[(o, j - n)] = v;
            }
        });
        Ok(())
    }
}

/// A borrowed network read as a correction of a model with `n_states` states: what
/// [`NetCorrection`] evaluates through, and what nn's shooting windows simulate with (one
/// per trial weight vector, without copying the network).
#[derive(Debug, Clone, Copy)]
pub(crate) struct NetView<'a> {
    pub(crate) net: &'a Mlp,
    pub(crate) n_states: usize,
    pub(crate) n_model_inputs: usize,
    pub(crate) domain: Domain,
}

impl NetView<'_> {
    /// [`NetCorrection::eval_into`].
    pub(crate) fn eval_into(
        &self,
        x: &[f64],
        u: &[f64],
        d: &mut [f64],
        ws: &mut Workspace,
    ) -> Result<()> {
        self.load(x, u, d.len(), ws)?;
        self.net.forward_scaled(ws);
        let out = self.net.output_range();
        self.net.output_scaler().unscale_into(&ws.acts[out], d);
        Ok(())
    }

    /// Check lengths, prepare `ws` and write the scaled `[x; u]` into it.
    fn load(&self, x: &[f64], u: &[f64], d_len: usize, ws: &mut Workspace) -> Result<()> {
        if x.len() != self.n_states {
            return Err(NnError::Length {
                what: "correction states",
                found: x.len(),
                expected: self.n_states,
            });
        }
        if u.len() != self.n_model_inputs {
            return Err(NnError::Length {
                what: "correction inputs",
                found: u.len(),
                expected: self.n_model_inputs,
            });
        }
        if d_len != self.net.n_outputs() {
            return Err(NnError::Length {
                what: "correction outputs",
                found: d_len,
                expected: self.net.n_outputs(),
            });
        }
        ws.prepare_forward(self.net.architecture());
        let s = self.net.input_scaler();
        let n = self.n_states;
        // The network's own inputs: the states, then the model inputs if it sees them (a
        // states-only network's scaler has no entries for them).
        let ni = self.net.n_inputs();
        let (centre, half) = (s.centre(), s.half_range());
        let (xs, us) = ws.acts[..ni].split_at_mut(n);
        for (((a, v), c), h) in xs.iter_mut().zip(x).zip(&centre[..n]).zip(&half[..n]) {
            *a = (v - c) / h;
        }
        for (((a, v), c), h) in us.iter_mut().zip(u).zip(&centre[n..]).zip(&half[n..]) {
            *a = (v - c) / h;
        }
        if self.domain == Domain::Hold {
            for a in &mut ws.acts[..ni] {
                *a = a.clamp(-1.0, 1.0);
            }
        }
        Ok(())
    }
}

impl Correction for NetView<'_> {
    fn n_states(&self) -> usize {
        self.n_states
    }

    fn n_inputs(&self) -> usize {
        self.n_model_inputs
    }

    fn n_outputs(&self) -> usize {
        self.net.n_outputs()
    }

    /// Evaluate `d = NN([x; u])` in a per-thread workspace; slices of the wrong length
    /// fill `d` with NaN, which the hybrid simulation reports as divergence.
    fn eval(&self, x: &[f64], u: &[f64], d: &mut [f64]) {
        let ok = SCRATCH.with(|cell| match cell.try_borrow_mut() {
            Ok(mut ws) => self.eval_into(x, u, d, &mut ws),
            // Re-entrant call on this thread (not expected): use a fresh workspace.
            Err(_) => self.eval_into(x, u, d, &mut Workspace::new()),
        });
        if ok.is_err() {
            d.fill(f64::NAN);
        }
    }
}

impl Correction for NetCorrection {
    fn n_states(&self) -> usize {
        self.view().n_states()
    }

    fn n_inputs(&self) -> usize {
        self.view().n_inputs()
    }

    fn n_outputs(&self) -> usize {
        self.view().n_outputs()
    }

    /// Evaluate `d = NN([x; u])`. The trait cannot return an error: slices of the wrong
    /// length fill `d` with NaN, which the hybrid simulation reports as divergence.
    fn eval(&self, x: &[f64], u: &[f64], d: &mut [f64]) {
        self.view().eval(x, u, d);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mlp::Architecture;

    #[test]
    #[allow(
        clippy::float_cmp,
        reason = "same operations in the same order give identical bits"
    )]
    fn eval_matches_forward_on_concatenated_input() {
        let net = Mlp::new(&Architecture::single(3, 4, 2), 5).unwrap();
        let corr = NetCorrection::new(net.clone(), 2).unwrap();
        assert_eq!(
            (corr.n_states(), corr.n_inputs(), corr.n_outputs()),
            (2, 1, 2)
        );
        let mut d = [0.0; 2];
        corr.eval(&[0.3, -0.2], &[0.9], &mut d);
        let mut y = [0.0; 2];
        net.forward(&[0.3, -0.2, 0.9], &mut y, &mut Workspace::new())
            .unwrap();
        // Same arithmetic in the same order: identical bits.
        assert_eq!(d, y);
        let full = net.input_jacobian(&[0.3, -0.2, 0.9]).unwrap();
        let (mut dx, mut du) = (DMatrix::zeros(2, 2), DMatrix::zeros(2, 1));
        corr.jacobians(
            &[0.3, -0.2],
            &[0.9],
            &mut d,
            &mut dx,
            &mut du,
            &mut Workspace::new(),
        )
        .unwrap();
        assert_eq!(dx, full.columns(0, 2).into_owned());
        assert_eq!(du, full.columns(2, 1).into_owned());
        corr.eval(&[0.3], &[0.9], &mut d);
        assert!(d.iter().all(|v| v.is_nan()));
        assert!(matches!(
            NetCorrection::new(net, 4),
            Err(NnError::CorrectionSplit {
                n_states: 4,
                n_inputs: 3
            })
        ));
    }

    /// Held: outside the training box the correction equals its value at the box's
    /// nearest point (each input clamped in original units, `centre ± half-range`), its
    /// derivative along a clamped input is zero and along the others that of the network
    /// at the clamped point; inside the box it is the network itself. Old JSON without
    /// the field reads as extrapolating.
    #[test]
    #[allow(
        clippy::float_cmp,
        reason = "clamping in original units and in scaled units give the same scaled input"
    )]
    fn held_correction_keeps_its_edge_value() {
        use crate::scaling::Scaler;
        let s_in = Scaler::fit(&DMatrix::from_row_slice(
            3,
            2,
            &[-1.0, 1.0, 0.0, 2.0, -0.5, 0.5],
        ))
        .unwrap();
        let net = Mlp::new(&Architecture::single(3, 4, 2), 5)
            .unwrap()
            .with_scalers(s_in, Scaler::identity(2))
            .unwrap();
        let free = NetCorrection::new(net.clone(), 2).unwrap();
        let held = free.clone().with_domain(Domain::Hold);
        assert_eq!(held.domain(), Domain::Hold);
        let (mut a, mut b) = ([0.0; 2], [0.0; 2]);
        // Inside: identical.
        free.eval(&[0.3, 1.2], &[0.1], &mut a);
        held.eval(&[0.3, 1.2], &[0.1], &mut b);
        assert_eq!(a, b);
        assert!(held.in_domain(&[0.3, 1.2], &[0.1]));
        // Outside in x0 (above) and u (below): the value at (1.0, 1.2, −0.5).
        assert!(!held.in_domain(&[3.0, 1.2], &[-4.0]));
        held.eval(&[3.0, 1.2], &[-4.0], &mut b);
        free.eval(&[1.0, 1.2], &[-0.5], &mut a);
        assert_eq!(a, b);
        free.eval(&[3.0, 1.2], &[-4.0], &mut a);
        assert!(a.iter().zip(&b).any(|(p, q)| (p - q).abs() > 1e-6));
        let mut ws = Workspace::new();
        let (mut dx, mut du) = (DMatrix::zeros(2, 2), DMatrix::zeros(2, 1));
        held.jacobians(&[3.0, 1.2], &[-4.0], &mut b, &mut dx, &mut du, &mut ws)
            .unwrap();
        let edge = net.input_jacobian(&[1.0, 1.2, -0.5]).unwrap();
        for o in 0..2 {
            assert_eq!(dx[(o, 0)], 0.0);
            assert_eq!(du[(o, 0)], 0.0);
            assert!((dx[(o, 1)] - edge[(o, 1)]).abs() <= 1e-12 * edge[(o, 1)].abs().max(1.0));
            assert!(edge[(o, 1)].abs() > 0.0);
        }
        // Serde: the field round-trips and old text without it extrapolates.
        let text = serde_json::to_string(&held).unwrap();
        assert!(text.contains("\"domain\":\"hold\""), "{text}");
        let back: NetCorrection = serde_json::from_str(&text).unwrap();
        assert_eq!(back, held);
        let old = text.replace(",\"domain\":\"hold\"", "");
        let old: NetCorrection = serde_json::from_str(&old).unwrap();
        assert_eq!(old.domain(), Domain::Extrapolate);
    }

    /// A network with as many inputs as the model has states sees the states alone: its
    /// value is the network's on `x` whatever `u` is, `∂d/∂u` is zero and `∂d/∂x` the
    /// network's; it reports the model's input count; other input counts are refused;
    /// held, only the states are clamped; the model's input count round-trips through
    /// JSON, and text without it reads as a network on `[x; u]`.
    #[test]
    #[allow(
        clippy::float_cmp,
        reason = "same operations in the same order give identical bits"
    )]
    fn states_only_network_ignores_the_inputs() {
        let net = Mlp::new(&Architecture::single(2, 4, 1), 3).unwrap();
        let corr = NetCorrection::for_model(net.clone(), 2, 3).unwrap();
        assert!(!corr.sees_inputs());
        assert_eq!(
            (corr.n_states(), corr.n_inputs(), corr.n_outputs()),
            (2, 3, 1)
        );
        let mut y = [0.0];
        net.forward(&[0.3, -0.2], &mut y, &mut Workspace::new())
            .unwrap();
        for u in [[0.0, 0.0, 0.0], [9.0, -4.0, 1e3]] {
            let mut d = [f64::NAN];
            corr.eval(&[0.3, -0.2], &u, &mut d);
            assert_eq!(d, y);
        }
        let mut d = [0.0];
        corr.eval(&[0.3, -0.2], &[1.0], &mut d);
        assert!(d[0].is_nan(), "wrong input length must not evaluate");
        let full = net.input_jacobian(&[0.3, -0.2]).unwrap();
        let (mut dx, mut du) = (DMatrix::zeros(1, 2), DMatrix::from_element(1, 3, 7.0));
        corr.jacobians(
            &[0.3, -0.2],
            &[5.0, 5.0, 5.0],
            &mut d,
            &mut dx,
            &mut du,
            &mut Workspace::new(),
        )
        .unwrap();
        assert_eq!(dx, full);
        assert!(du.iter().all(|&v| v == 0.0));
        // The states and inputs variant of the same model is accepted too; others are not.
        let both = Mlp::new(&Architecture::single(5, 4, 1), 3).unwrap();
        assert!(NetCorrection::for_model(both, 2, 3).unwrap().sees_inputs());
        let odd = Mlp::new(&Architecture::single(4, 4, 1), 3).unwrap();
        assert!(matches!(
            NetCorrection::for_model(odd, 2, 3),
            Err(NnError::CorrectionInputs {
                n_states: 2,
                n_model_inputs: 3,
                n_inputs: 4
            })
        ));
        // In the box whatever u is (scaler of a fresh network: ±1 around 0).
        let held = corr.clone().with_domain(Domain::Hold);
        assert!(held.in_domain(&[0.3, -0.2], &[1e3, -1e3, 0.0]));
        assert!(!held.in_domain(&[3.0, -0.2], &[0.0, 0.0, 0.0]));
        assert!(!held.in_domain(&[0.3, -0.2], &[0.0]));
        let text = serde_json::to_string(&corr).unwrap();
        assert!(text.contains("\"n_model_inputs\":3"), "{text}");
        let back: NetCorrection = serde_json::from_str(&text).unwrap();
        assert_eq!(back, corr);
        let both = NetCorrection::new(net, 1).unwrap();
        let old = serde_json::to_string(&both)
            .unwrap()
            .replace(",\"n_model_inputs\":1", "");
        assert!(!old.contains("n_model_inputs"));
        let old: NetCorrection = serde_json::from_str(&old).unwrap();
        assert_eq!(old, both);
        assert!(old.sees_inputs());
    }
}
