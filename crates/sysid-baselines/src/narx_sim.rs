//! Free run and k-step prediction of any one-step NARX map `y(k) = F(φ(k))` on the
//! tapped-delay regressor of [`crate::regressors`]: the network NARX and the polynomial
//! NARX share these loops, so both start, predict and report divergence the same way.

use nalgebra::{DMatrix, DVector};
use sysid_core::{Experiment, Horizon, Prediction};

use crate::error::{BaselineError, Result};
use crate::regressors::{NarxOrders, fill_regressor};

/// A one-step map on the tapped-delay regressor.
pub(crate) trait OneStep {
    /// Scratch space of one simulation (allocated once per run).
    type Scratch;
    fn orders(&self) -> NarxOrders;
    fn input_names(&self) -> &[String];
    fn output_names(&self) -> &[String];
    /// Divergence limits per output.
    fn limits(&self) -> &[(f64, f64)];
    /// Scratch space for [`OneStep::map`].
    fn scratch(&self) -> Self::Scratch;
    /// `out = F(reg)`; `reg` is the regressor laid out as [`fill_regressor`] writes it.
    fn map(&self, reg: &[f64], scratch: &mut Self::Scratch, out: &mut [f64]) -> Result<()>;
}

/// Scratch of one run: the regressor, the map's own space and the output.
struct Buffers<S> {
    reg: Vec<f64>,
    inner: S,
    out: Vec<f64>,
}

fn buffers<M: OneStep>(m: &M) -> Buffers<M::Scratch> {
    let (p, q) = (m.output_names().len(), m.input_names().len());
    Buffers {
        reg: vec![0.0; m.orders().regressor_len(p, q)],
        inner: m.scratch(),
        out: vec![0.0; p],
    }
}

/// Channel counts and record length against the model's.
pub(crate) fn check<M: OneStep>(m: &M, experiment: &Experiment) -> Result<()> {
    if experiment.n_inputs() != m.input_names().len() {
        return Err(BaselineError::Dimension {
            what: "input channels of the experiment vs the NARX model",
            found: experiment.n_inputs(),
            expected: m.input_names().len(),
        });
    }
    if experiment.n_outputs() != m.output_names().len() {
        return Err(BaselineError::Dimension {
            what: "output channels of the experiment vs the NARX model",
            found: experiment.n_outputs(),
            expected: m.output_names().len(),
        });
    }
    let lag = m.orders().max_lag();
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

/// First sample `s ≥ max_lag` whose `na` preceding outputs are all measured: the free
/// run starts there.
pub(crate) fn first_complete_window<M: OneStep>(m: &M, experiment: &Experiment) -> Result<usize> {
    let o = m.orders();
    let (lag, na) = (o.max_lag(), o.na);
    let y = experiment.outputs();
    (lag..experiment.len())
        .find(|&s| (s - na..s).all(|j| y.column(j).iter().all(|v| !v.is_nan())))
        .ok_or(BaselineError::NoInitialWindow {
            experiment: 0,
            window: na,
        })
}

/// One step at sample `k` reading outputs through `y`; checks the limits.
fn step<M: OneStep>(
    m: &M,
    y: impl Fn(usize, usize) -> f64,
    u: &DMatrix<f64>,
    k: usize,
    bufs: &mut Buffers<M::Scratch>,
) -> Result<()> {
    let dims = (m.output_names().len(), m.input_names().len());
    fill_regressor(y, |c, j| u[(c, j)], dims, k, &m.orders(), &mut bufs.reg);
    m.map(&bufs.reg, &mut bufs.inner, &mut bufs.out)?;
    for (i, v) in bufs.out.iter().enumerate() {
        let (lo, hi) = m.limits()[i];
        if !(v.is_finite() && *v >= lo && *v <= hi) {
            return Err(BaselineError::Diverged {
                sample: k,
                channel: m.output_names()[i].clone(),
                value: *v,
            });
        }
    }
    Ok(())
}

/// Outputs with samples `s..end` replaced by the free run from `s` (measured values
/// elsewhere).
fn free_run<M: OneStep>(
    m: &M,
    experiment: &Experiment,
    s: usize,
    end: usize,
) -> Result<DMatrix<f64>> {
    let mut buf = experiment.outputs().clone();
    let mut bufs = buffers(m);
    let u = experiment.inputs();
    for k in s..end {
        step(m, |c, j| buf[(c, j)], u, k, &mut bufs)?;
        buf.column_mut(k).copy_from_slice(&bufs.out);
    }
    Ok(buf)
}

/// Free-run simulation. The run starts at the first sample `s ≥ max_lag` whose `na`
/// preceding outputs are measured; those are the initial conditions, and
/// `initial_samples = s`. Columns before `s` are NaN (not predicted). Errors: channel
/// counts differing from the model's, a record no longer than the lag window, no
/// complete initial window, divergence (an output leaving its limits).
pub(crate) fn simulate<M: OneStep>(m: &M, experiment: &Experiment) -> Result<Prediction> {
    check(m, experiment)?;
    let s = first_complete_window(m, experiment)?;
    let mut outputs = free_run(m, experiment, s, experiment.len())?;
    outputs.columns_mut(0, s).fill(f64::NAN);
    Ok(Prediction {
        horizon: Horizon::FreeRun,
        outputs,
        initial_samples: s,
    })
}

/// k-step prediction: the output at `t` is the model iterated `k` times from the measured
/// outputs up to `t − k`. A missing measurement inside a window is replaced by the
/// model's own prediction of that sample (its k-step prediction, or within the first
/// `k − 1` samples after the start, its free run). `initial_samples = s + k − 1` with `s`
/// as in [`simulate`]; earlier columns are NaN.
pub(crate) fn predict<M: OneStep>(m: &M, experiment: &Experiment, k: usize) -> Result<Prediction> {
    crate::error::check_horizon(k)?;
    check(m, experiment)?;
    let s = first_complete_window(m, experiment)?;
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
    let p = m.output_names().len();
    // Best available value of each sample: the measurement, else a prediction.
    let mut best = free_run(m, experiment, s, skip)?;
    for j in s..len {
        for c in 0..p {
            if !measured[(c, j)].is_nan() {
                best[(c, j)] = measured[(c, j)];
            }
        }
    }
    let mut outputs = DMatrix::from_element(p, len, f64::NAN);
    let mut bufs = buffers(m);
    let mut temp = DMatrix::zeros(p, k);
    let u = experiment.inputs();
    for t in skip..len {
        let o = t + 1 - k;
        for st in 0..k {
            let read = |c: usize, j: usize| {
                if j >= o {
                    temp[(c, j - o)]
                } else {
                    best[(c, j)]
                }
            };
            step(m, read, u, o + st, &mut bufs)?;
            temp.column_mut(st).copy_from_slice(&bufs.out);
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

/// The free-run sensitivities `dŷ_c(k)/dθ` of a one-step map's simulation, for the
/// simulation-error refinements of both NARX kinds: the last `na + 1` samples' rows of
/// every output in a ring, and the weighted residuals with their Jacobian rows as they are
/// produced. `ŷ(k)` reads `ŷ(k−1…k−na)`, so the row of sample `k` is the map's own
/// derivative plus `Σ_v g_v·dŷ_{ch(v)}(k − lag(v))/dθ` over the regressor's output-lag
/// entries `v` (laid out channel by channel, lags 1…na).
pub(crate) struct Sensitivities {
    orders: NarxOrders,
    p: usize,
    n_par: usize,
    ring: Vec<f64>,
    residuals: Vec<f64>,
    jacobian: Option<Vec<f64>>,
}

impl Sensitivities {
    /// For `p` outputs and `n_par` parameters; `jacobian` false keeps residuals only.
    pub(crate) fn new(orders: NarxOrders, p: usize, n_par: usize, jacobian: bool) -> Self {
        Self {
            orders,
            p,
            n_par,
            ring: vec![
                0.0;
                if jacobian {
                    (orders.na + 1) * p * n_par
                } else {
                    0
                }
            ],
            residuals: Vec::new(),
            jacobian: jacobian.then(Vec::new),
        }
    }

    /// Whether Jacobian rows are kept.
    pub(crate) fn with_jacobian(&self) -> bool {
        self.jacobian.is_some()
    }

    /// A new record starts: the measured delay window has no sensitivity.
    pub(crate) fn start_record(&mut self) {
        self.ring.fill(0.0);
    }

    /// Store output `c`'s row at sample `k ≥ s` (after the start `s`): `row` holds the
    /// map's own derivative on entry and the chained row on return; `g(v)` is
    /// `∂ŷ_c(k)/∂φ_v` for output-lag entry `v` (0 skips it).
    pub(crate) fn chain(&mut self, k: usize, c: usize, row: &mut [f64], g: impl Fn(usize) -> f64) {
        let (na, n, p) = (self.orders.na, self.n_par, self.p);
        let ring_len = na + 1;
        for v in 0..p * na {
            let gv = g(v);
            if gv == 0.0 {
                continue;
            }
            let (ch, lag) = (v / na, v % na + 1);
            let from = ((k - lag) % ring_len) * p * n + ch * n;
            for (r, old) in row.iter_mut().zip(&self.ring[from..from + n]) {
                *r += gv * old;
            }
        }
        let slot = (k % ring_len) * p * n + c * n;
        self.ring[slot..slot + n].copy_from_slice(row);
    }

    /// Record `w·(ŷ − y)` of output `c` at sample `k` (and its Jacobian row, stored by
    /// [`Sensitivities::chain`]).
    pub(crate) fn push(&mut self, k: usize, c: usize, w: f64, yhat: f64, y: f64) {
        self.residuals.push(w * (yhat - y));
        if let Some(jac) = self.jacobian.as_mut() {
            let n = self.n_par;
            let slot = (k % (self.orders.na + 1)) * self.p * n + c * n;
            jac.extend(self.ring[slot..slot + n].iter().map(|v| w * v));
        }
    }

    /// The residual vector and, when kept, the Jacobian (`rows × n_par`).
    pub(crate) fn finish(self) -> (DVector<f64>, Option<DMatrix<f64>>) {
        let rows = self.residuals.len();
        let n = self.n_par;
        (
            DVector::from_vec(self.residuals),
            self.jacobian.map(|j| DMatrix::from_row_slice(rows, n, &j)),
        )
    }
}

/// Free-run RMSE per output (unweighted) from the weighted residuals a refinement's run
/// produced over `data` (every measured sample after each record's start, outputs
/// interleaved where measured).
pub(crate) fn rmse_per_output<M: OneStep>(
    m: &M,
    data: &sysid_core::Dataset,
    residuals: &DVector<f64>,
    weight: &[f64],
) -> Result<Vec<f64>> {
    let p = weight.len();
    let mut sse = vec![0.0; p];
    let mut n = vec![0usize; p];
    let mut idx = 0;
    for exp in data.experiments() {
        let s = first_complete_window(m, exp)?;
        for k in s..exp.len() {
            for c in 0..p {
                if !exp.outputs()[(c, k)].is_nan() {
                    let e = residuals[idx] / weight[c];
                    sse[c] += e * e;
                    n[c] += 1;
                    idx += 1;
                }
            }
        }
    }
    Ok((0..p)
        .map(|c| (sse[c] / n[c].max(1) as f64).sqrt())
        .collect())
}

/// 1 / standard deviation of each of the `p` outputs over every record of `data` (1 for
/// a constant output): the weights of the simulation-error residuals.
pub(crate) fn output_weights(data: &sysid_core::Dataset, p: usize) -> Vec<f64> {
    (0..p)
        .map(|c| {
            let vals: Vec<f64> = data
                .experiments()
                .iter()
                .flat_map(|e| e.outputs().row(c).iter().copied().collect::<Vec<_>>())
                .filter(|v| !v.is_nan())
                .collect();
            let mean = vals.iter().sum::<f64>() / vals.len().max(1) as f64;
            let var =
                vals.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / vals.len().max(1) as f64;
            if var > 0.0 { 1.0 / var.sqrt() } else { 1.0 }
        })
        .collect()
}
