//! A trained NARX network as a [`sysid_core::Model`]: free-run simulation (the network's
//! own outputs fed back after an initial window of measured samples) and k-step
//! prediction (measured outputs up to `k` steps back), with divergence detection.

use nalgebra::DMatrix;
use nn::{Mlp, Workspace};
use serde::{Deserialize, Serialize};
use sysid_core::{Experiment, Horizon, Model, Prediction};

use crate::error::{BaselineError, Result};
use crate::projection::RegressorProjection;
use crate::regressors::{NarxOrders, fill_regressor};

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

    fn check(&self, experiment: &Experiment) -> Result<()> {
        if experiment.n_inputs() != self.input_names.len() {
            return Err(BaselineError::Dimension {
                what: "input channels of the experiment vs the NARX model",
                found: experiment.n_inputs(),
                expected: self.input_names.len(),
            });
        }
        if experiment.n_outputs() != self.output_names.len() {
            return Err(BaselineError::Dimension {
                what: "output channels of the experiment vs the NARX model",
                found: experiment.n_outputs(),
                expected: self.output_names.len(),
            });
        }
        let lag = self.orders.max_lag();
        if experiment.len() <= lag {
            return Err(BaselineError::LagsExceedData {
                what: "NARX regressor window",
                experiment: 0,
                needed: lag + 1,
                available: experiment.len(),
            });
        }
        Ok(())
    }

    /// First sample `s ≥ max_lag` whose `na` preceding outputs are all measured: the
    /// free run starts there.
    fn first_complete_window(&self, experiment: &Experiment) -> Result<usize> {
        let lag = self.orders.max_lag();
        let na = self.orders.na;
        let y = experiment.outputs();
        (lag..experiment.len())
            .find(|&s| (s - na..s).all(|j| y.column(j).iter().all(|v| !v.is_nan())))
            .ok_or(BaselineError::NoInitialWindow {
                experiment: 0,
                window: na,
            })
    }

    /// One network step at sample `k` reading outputs through `y`; checks the limits.
    fn step(
        &self,
        y: impl Fn(usize, usize) -> f64,
        u: &DMatrix<f64>,
        k: usize,
        bufs: &mut Buffers,
    ) -> Result<()> {
        let dims = (self.output_names.len(), self.input_names.len());
        fill_regressor(y, |c, j| u[(c, j)], dims, k, &self.orders, &mut bufs.reg);
        match &self.projection {
            Some(proj) => {
                proj.apply(&bufs.reg, &mut bufs.tmp, &mut bufs.z);
                self.net.forward(&bufs.z, &mut bufs.out, &mut bufs.ws)?;
            }
            None => self.net.forward(&bufs.reg, &mut bufs.out, &mut bufs.ws)?,
        }
        let out = &bufs.out;
        for (i, v) in out.iter().enumerate() {
            let (lo, hi) = self.limits[i];
            if !(v.is_finite() && *v >= lo && *v <= hi) {
                return Err(BaselineError::Diverged {
                    sample: k,
                    channel: self.output_names[i].clone(),
                    value: *v,
                });
            }
        }
        Ok(())
    }

    fn buffers(&self) -> Buffers {
        let p = self.output_names.len();
        let len = self.orders.regressor_len(p, self.input_names.len());
        Buffers {
            reg: vec![0.0; len],
            tmp: vec![0.0; len],
            z: vec![0.0; self.net.n_inputs()],
            out: vec![0.0; p],
            ws: Workspace::new(),
        }
    }

    /// Outputs with samples `s..end` replaced by the free run from `s` (measured values
    /// elsewhere).
    fn free_run(&self, experiment: &Experiment, s: usize, end: usize) -> Result<DMatrix<f64>> {
        let mut buf = experiment.outputs().clone();
        let mut bufs = self.buffers();
        let u = experiment.inputs();
        for k in s..end {
            self.step(|c, j| buf[(c, j)], u, k, &mut bufs)?;
            buf.column_mut(k).copy_from_slice(&bufs.out);
        }
        Ok(buf)
    }
}

/// Scratch space of one simulation.
struct Buffers {
    reg: Vec<f64>,
    tmp: Vec<f64>,
    z: Vec<f64>,
    out: Vec<f64>,
    ws: Workspace,
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
        self.check(experiment)?;
        let s = self.first_complete_window(experiment)?;
        let mut outputs = self.free_run(experiment, s, experiment.len())?;
        outputs.columns_mut(0, s).fill(f64::NAN);
        Ok(Prediction {
            horizon: Horizon::FreeRun,
            outputs,
            initial_samples: s,
        })
    }

    /// k-step prediction: the output at `t` is the model iterated `k` times from the
    /// measured outputs up to `t − k`. A missing measurement inside a window is replaced
    /// by the model's own prediction of that sample (its k-step prediction, or within the
    /// first `k − 1` samples after the start, its free run). `initial_samples = s + k − 1`
    /// with `s` as in [`Model::simulate`]; earlier columns are NaN.
    fn predict(&self, experiment: &Experiment, k: usize) -> Result<Prediction> {
        crate::error::check_horizon(k)?;
        self.check(experiment)?;
        let s = self.first_complete_window(experiment)?;
        let len = experiment.len();
        let skip = s + k - 1;
        if skip >= len {
            return Err(BaselineError::LagsExceedData {
                what: "NARX initial window plus prediction horizon",
                experiment: 0,
                needed: skip + 1,
                available: len,
            });
        }
        let measured = experiment.outputs();
        let p = self.output_names.len();
        // Best available value of each sample: the measurement, else a prediction.
        let mut best = self.free_run(experiment, s, skip)?;
        for j in s..len {
            for c in 0..p {
                if !measured[(c, j)].is_nan() {
                    best[(c, j)] = measured[(c, j)];
                }
            }
        }
        let mut outputs = DMatrix::from_element(p, len, f64::NAN);
        let mut bufs = self.buffers();
        let mut temp = DMatrix::zeros(p, k);
        let u = experiment.inputs();
        for t in skip..len {
            let o = t + 1 - k;
            for step in 0..k {
                let read = |c: usize, j: usize| {
                    if j >= o {
                        temp[(c, j - o)]
                    } else {
                        best[(c, j)]
                    }
                };
                self.step(read, u, o + step, &mut bufs)?;
                temp.column_mut(step).copy_from_slice(&bufs.out);
            }
            outputs.column_mut(t).copy_from(&temp.column(k - 1));
            for c in 0..p {
                if best[(c, t)].is_nan() {
                    best[(c, t)] = temp[(c, k - 1)];
                }
            }
        }
        Ok(Prediction {
            horizon: Horizon::Steps(k),
            outputs,
            initial_samples: skip,
        })
    }
}
