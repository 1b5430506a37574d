//! A trained NARX network as a [`sysid_core::Model`]: free-run simulation (the network's
//! own outputs fed back after an initial window of measured samples) and k-step
//! prediction (measured outputs up to `k` steps back), with divergence detection.

use nn::{Mlp, Workspace};
use serde::{Deserialize, Serialize};
use sysid_core::{Experiment, Model, Prediction};

use crate::error::{BaselineError, Result};
use crate::narx_sim::{self, OneStep};
use crate::projection::RegressorProjection;
use crate::regressors::NarxOrders;

/// A NARX model `y(k) = F(y(k−1…k−na), u(k−nk…k−nk−nb+1))` with `F` an [`Mlp`]
/// (reading the regressor's principal components when a projection is set).
/// Deserialisation re-checks every dimension through [`NarxModel::new`].
///
/// A discrete-time model of the samples themselves: how the inputs moved between samples
/// ([`Experiment::intersample`]) means nothing to it and is ignored.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "NarxModelRaw")]
pub struct NarxModel {
    net: Mlp,
    projection: Option<RegressorProjection>,
    orders: NarxOrders,
    input_names: Vec<String>,
    output_names: Vec<String>,
    /// Per output: `(low, high)` outside which a simulation counts as diverged.
    limits: Vec<(f64, f64)>,
}

#[derive(Deserialize)]
struct NarxModelRaw {
    net: Mlp,
    projection: Option<RegressorProjection>,
    orders: NarxOrders,
    input_names: Vec<String>,
    output_names: Vec<String>,
    limits: Vec<(f64, f64)>,
}

impl TryFrom<NarxModelRaw> for NarxModel {
    type Error = BaselineError;
    fn try_from(r: NarxModelRaw) -> Result<Self> {
        NarxModel::new(
            r.net,
            r.projection,
            r.orders,
            r.input_names,
            r.output_names,
            r.limits,
        )
    }
}

impl NarxModel {
    /// Assemble a model. The network reads the regressor, or its projection when one is
    /// given. `limits[i] = (low, high)` bounds output `i` in simulation.
    ///
    /// Errors: orders with no taps, network inputs/outputs not matching the orders,
    /// projection and channel counts, a limit that is not an increasing finite pair.
    pub fn new(
        net: Mlp,
        projection: Option<RegressorProjection>,
        orders: NarxOrders,
        input_names: Vec<String>,
        output_names: Vec<String>,
        limits: Vec<(f64, f64)>,
    ) -> Result<Self> {
        orders.validate()?;
        let (p, m) = (output_names.len(), input_names.len());
        let reg_len = orders.regressor_len(p, m);
        let expected = match &projection {
            Some(proj) => {
                if proj.input_len() != reg_len {
                    return Err(BaselineError::Dimension {
                        what: "projection inputs vs NARX regressor length",
                        found: proj.input_len(),
                        expected: reg_len,
                    });
                }
                proj.dim()
            }
            None => reg_len,
        };
        if net.n_inputs() != expected {
            return Err(BaselineError::Dimension {
                what: "network inputs vs NARX regressor length",
                found: net.n_inputs(),
                expected,
            });
        }
        if net.n_outputs() != p {
            return Err(BaselineError::Dimension {
                what: "network outputs vs NARX output channels",
                found: net.n_outputs(),
                expected: p,
            });
        }
        if limits.len() != p {
            return Err(BaselineError::Dimension {
                what: "divergence limits vs NARX output channels",
                found: limits.len(),
                expected: p,
            });
        }
        if let Some((lo, hi)) = limits
            .iter()
            .find(|(lo, hi)| !(lo.is_finite() && hi.is_finite() && lo < hi))
        {
            return Err(BaselineError::InvalidConfig {
                field: "limits",
                value: hi - lo,
                reason: "each divergence limit must be a finite increasing pair",
            });
        }
        Ok(Self {
            net,
            projection,
            orders,
            input_names,
            output_names,
            limits,
        })
    }

    /// The network.
    pub fn network(&self) -> &Mlp {
        &self.net
    }

    /// Replace the network's weights (same architecture).
    ///
    /// Errors: a vector of the wrong length or with a non-finite entry.
    pub(crate) fn set_network_weights(&mut self, weights: &[f64]) -> Result<()> {
        self.net.set_weights(weights)?;
        Ok(())
    }

    /// The regressor projection, if any.
    pub fn projection(&self) -> Option<&RegressorProjection> {
        self.projection.as_ref()
    }

    /// The tapped delays.
    pub fn orders(&self) -> NarxOrders {
        self.orders
    }

    /// Input channel names, in regressor order.
    pub fn input_names(&self) -> &[String] {
        &self.input_names
    }

    /// Divergence limits per output.
    pub fn limits(&self) -> &[(f64, f64)] {
        &self.limits
    }
}

/// The network's scratch: the projected regressor and the forward pass's workspace.
pub(crate) struct NetScratch {
    tmp: Vec<f64>,
    z: Vec<f64>,
    ws: Workspace,
}

impl OneStep for NarxModel {
    type Scratch = NetScratch;

    fn orders(&self) -> NarxOrders {
        self.orders
    }

    fn input_names(&self) -> &[String] {
        &self.input_names
    }

    fn output_names(&self) -> &[String] {
        &self.output_names
    }

    fn limits(&self) -> &[(f64, f64)] {
        &self.limits
    }

    fn scratch(&self) -> NetScratch {
        let len = self
            .orders
            .regressor_len(self.output_names.len(), self.input_names.len());
        NetScratch {
            tmp: vec![0.0; len],
            z: vec![0.0; self.net.n_inputs()],
            ws: Workspace::new(),
        }
    }

    fn map(&self, reg: &[f64], s: &mut NetScratch, out: &mut [f64]) -> Result<()> {
        match &self.projection {
            Some(proj) => {
                proj.apply(reg, &mut s.tmp, &mut s.z);
                self.net.forward(&s.z, out, &mut s.ws)?;
            }
            None => self.net.forward(reg, out, &mut s.ws)?,
        }
        Ok(())
    }
}

impl Model for NarxModel {
    type Error = BaselineError;

    fn output_names(&self) -> Vec<String> {
        self.output_names.clone()
    }

    /// Free-run simulation. The run starts at the first sample `s ≥ max_lag` whose `na`
    /// preceding outputs are measured; those are the initial conditions, and
    /// `initial_samples = s`. Columns before `s` are NaN (not predicted). Errors: channel
    /// counts differing from the model's, a record no longer than the lag window, no
    /// complete initial window, divergence (an output leaving its limits).
    fn simulate(&self, experiment: &Experiment) -> Result<Prediction> {
        narx_sim::simulate(self, experiment)
    }

    /// k-step prediction: the output at `t` is the model iterated `k` times from the
    /// measured outputs up to `t − k`. A missing measurement inside a window is replaced
    /// by the model's own prediction of that sample (its k-step prediction, or within the
    /// first `k − 1` samples after the start, its free run). `initial_samples = s + k − 1`
    /// with `s` as in [`Model::simulate`]; earlier columns are NaN.
    fn predict(&self, experiment: &Experiment, k: usize) -> Result<Prediction> {
        narx_sim::predict(self, experiment, k)
    }
}
