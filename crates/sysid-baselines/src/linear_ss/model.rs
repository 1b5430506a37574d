//! The model of the linear state-space baseline: second- and first-order [`Section`]s in
//! parallel with feedthrough and offsets ([`LinearSsModel`]), its simulation from a state
//! fitted to the first outputs of a record, and one record's signals ([`Record`]).

use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};
use sysid_core::{Experiment, Horizon, Model, Prediction};

use crate::error::{BaselineError, Result};

/// One block of the parallel realisation.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Section {
    /// `(b1 z + b2)/(z² + a1 z + a2)`.
    Second {
        /// Denominator coefficient of `z`.
        a1: f64,
        /// Constant denominator coefficient.
        a2: f64,
        /// Numerator coefficient of `z`.
        b1: f64,
        /// Constant numerator coefficient.
        b2: f64,
    },
    /// `(b1 z + b2)/((z − 1)(z − p))`: a second-order block with one pole held at 1 (a
    /// known integrator, e.g. position from force).
    Integrating {
        /// The free pole.
        p: f64,
        /// Numerator coefficient of `z`.
        b1: f64,
        /// Constant numerator coefficient.
        b2: f64,
    },
    /// `b/(z − λ)`.
    First {
        /// The pole.
        lambda: f64,
        /// The gain.
        b: f64,
    },
}

impl Section {
    pub(super) fn states(&self) -> usize {
        match self {
            Section::Second { .. } | Section::Integrating { .. } => 2,
            Section::First { .. } => 1,
        }
    }

    /// `(a1, a2, b1, b2)` of a two-state block.
    pub(super) fn coefficients(&self) -> Option<(f64, f64, f64, f64)> {
        match *self {
            Section::Second { a1, a2, b1, b2 } => Some((a1, a2, b1, b2)),
            Section::Integrating { p, b1, b2 } => Some((-(1.0 + p), p, b1, b2)),
            Section::First { .. } => None,
        }
    }

    pub(super) fn params(&self) -> Vec<f64> {
        match *self {
            Section::Second { a1, a2, b1, b2 } => vec![a1, a2, b1, b2],
            Section::Integrating { p, b1, b2 } => vec![p, b1, b2],
            Section::First { lambda, b } => vec![lambda, b],
        }
    }

    pub(super) fn with_params(&self, t: &[f64]) -> Self {
        match self {
            Section::Second { .. } => Section::Second {
                a1: t[0],
                a2: t[1],
                b1: t[2],
                b2: t[3],
            },
            Section::Integrating { .. } => Section::Integrating {
                p: t[0],
                b1: t[1],
                b2: t[2],
            },
            Section::First { .. } => Section::First {
                lambda: t[0],
                b: t[1],
            },
        }
    }

    /// Poles as `(re, im)`.
    pub fn poles(&self) -> Vec<(f64, f64)> {
        match *self {
            Section::First { lambda, .. } => vec![(lambda, 0.0)],
            Section::Integrating { p, .. } => vec![(1.0, 0.0), (p, 0.0)],
            Section::Second { a1, a2, .. } => {
                let disc = a1 * a1 / 4.0 - a2;
                if disc >= 0.0 {
                    let r = disc.sqrt();
                    vec![(-a1 / 2.0 + r, 0.0), (-a1 / 2.0 - r, 0.0)]
                } else {
                    let i = (-disc).sqrt();
                    vec![(-a1 / 2.0, i), (-a1 / 2.0, -i)]
                }
            }
        }
    }

    /// One step of the block's state from `x` with input `v`.
    #[inline]
    pub(super) fn step(&self, x: &mut [f64], v: f64) {
        match *self {
            Section::First { lambda, b } => x[0] = lambda * x[0] + b * v,
            _ => {
                let (a1, a2, b1, b2) = self.coefficients().unwrap_or_default();
                let x1 = -a1 * x[0] + x[1] + b1 * v;
                let x2 = -a2 * x[0] + b2 * v;
                x[0] = x1;
                x[1] = x2;
            }
        }
    }
}

/// The fitted model: parallel sections, feedthrough and offsets, simulated from a state
/// estimated on the first `window` outputs of each record.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LinearSsModel {
    /// The blocks.
    pub sections: Vec<Section>,
    /// Direct feedthrough `d`.
    pub d: f64,
    /// Input offset `u_off` (the record mean plus the fitted bias when it is fitted).
    pub input_offset: f64,
    /// Output offset `y_off` (the record mean).
    pub output_offset: f64,
    /// Samples whose outputs initialise the state (least squares) before a free run.
    pub window: usize,
    /// Output channel name.
    pub output: String,
}

/// Response pieces over a window: forced outputs (zero state) and free responses of each
/// state (unit initial state, zero input).
pub(super) struct WindowBasis {
    pub(super) forced: Vec<f64>,
    pub(super) free: DMatrix<f64>,
}

impl LinearSsModel {
    /// Number of states.
    pub fn order(&self) -> usize {
        self.sections.iter().map(Section::states).sum()
    }

    /// Every pole, `(re, im)`.
    pub fn poles(&self) -> Vec<(f64, f64)> {
        self.sections.iter().flat_map(Section::poles).collect()
    }

    /// Largest pole modulus (≤ 1: no growing mode; 1: integrator).
    pub fn spectral_radius(&self) -> f64 {
        self.poles()
            .iter()
            .map(|(r, i)| r.hypot(*i))
            .fold(0.0, f64::max)
    }

    /// The block-diagonal `(A, B, C, D)` (inputs and outputs as deviations from the
    /// offsets).
    pub fn state_space(&self) -> crate::subspace::DiscreteStateSpace {
        let n = self.order();
        let (mut a, mut b, mut c) = (
            DMatrix::zeros(n, n),
            DMatrix::zeros(n, 1),
            DMatrix::zeros(1, n),
        );
        let mut o = 0;
        for s in &self.sections {
            match *s {
                Section::Second { .. } | Section::Integrating { .. } => {
                    let (a1, a2, b1, b2) = s.coefficients().unwrap_or_default();
                    a[(o, o)] = -a1;
                    a[(o, o + 1)] = 1.0;
                    a[(o + 1, o)] = -a2;
                    b[(o, 0)] = b1;
                    b[(o + 1, 0)] = b2;
                    c[(0, o)] = 1.0;
                }
                Section::First { lambda, b: g } => {
                    a[(o, o)] = lambda;
                    b[(o, 0)] = g;
                    c[(0, o)] = 1.0;
                }
            }
            o += s.states();
        }
        crate::subspace::DiscreteStateSpace {
            a,
            b,
            c,
            d: DMatrix::from_element(1, 1, self.d),
        }
    }

    /// Outputs from state `x0` at sample `start` over `u[start..end]`; `None` if they
    /// leave the finite range.
    pub(super) fn run(&self, u: &[f64], x0: &[f64], start: usize, end: usize) -> Option<Vec<f64>> {
        let mut x = x0.to_vec();
        let mut y = Vec::with_capacity(end - start);
        for &uk in &u[start..end] {
            let v = uk - self.input_offset;
            let mut out = self.output_offset + self.d * v;
            let mut o = 0;
            for s in &self.sections {
                out += x[o];
                s.step(&mut x[o..o + s.states()], v);
                o += s.states();
            }
            if !out.is_finite() || out.abs() > 1e100 {
                return None;
            }
            y.push(out);
        }
        Some(y)
    }

    pub(super) fn window_basis(
        &self,
        u: &[f64],
        start: usize,
        window: usize,
    ) -> Option<WindowBasis> {
        let n = self.order();
        let forced = self.run(u, &vec![0.0; n], start, start + window)?;
        let mut free = DMatrix::zeros(window, n);
        let mut o = 0;
        for s in &self.sections {
            for i in 0..s.states() {
                let mut x = vec![0.0; s.states()];
                x[i] = 1.0;
                for k in 0..window {
                    free[(k, o + i)] = x[0];
                    s.step(&mut x, 0.0);
                }
            }
            o += s.states();
        }
        Some(WindowBasis { forced, free })
    }

    /// Least-squares state at sample `start` from outputs `y[start..start + window]`
    /// (minimum-norm when the window does not determine every state). `None` when the
    /// model diverges over the window.
    pub(super) fn state_at(
        &self,
        u: &[f64],
        y: &[f64],
        start: usize,
        window: usize,
    ) -> Option<Vec<f64>> {
        let basis = self.window_basis(u, start, window)?;
        let rhs = DVector::from_fn(window, |k, _| y[start + k] - basis.forced[k]);
        let svd = basis.free.svd(true, true);
        let smax = svd.singular_values.max();
        if !(smax > 0.0 && smax.is_finite()) {
            return None;
        }
        let z = svd.solve(&rhs, 1e-10 * smax).ok()?;
        Some(z.iter().copied().collect())
    }

    /// Free-run outputs over the whole record from the state fitted to its first
    /// `window` outputs. `None` if the model diverges.
    pub fn simulate_signal(&self, u: &[f64], y: &[f64]) -> Option<Vec<f64>> {
        if u.len() != y.len() || self.window == 0 || self.window > u.len() {
            return None;
        }
        let x0 = self.state_at(u, y, 0, self.window)?;
        self.run(u, &x0, 0, u.len())
    }

    pub(super) fn signals(&self, experiment: &Experiment) -> Result<(Vec<f64>, Vec<f64>)> {
        if experiment.n_inputs() != 1 || experiment.n_outputs() != 1 {
            return Err(BaselineError::Dimension {
                what: "channels of the experiment (the linear state-space baseline is SISO)",
                found: experiment.n_inputs() + experiment.n_outputs(),
                expected: 2,
            });
        }
        if self.window == 0 || self.window > experiment.len() {
            return Err(BaselineError::LagsExceedData {
                what: "state-initialisation window",
                experiment: 0,
                needed: self.window.max(1),
                available: experiment.len(),
            });
        }
        let u: Vec<f64> = experiment.inputs().row(0).iter().copied().collect();
        let y: Vec<f64> = experiment.outputs().row(0).iter().copied().collect();
        if let Some(k) = u.iter().position(|v| !v.is_finite()) {
            return Err(BaselineError::NoInitialWindow {
                experiment: 0,
                window: k,
            });
        }
        Ok((u, y))
    }
}

pub(super) fn diverged(sample: usize) -> BaselineError {
    BaselineError::Diverged {
        sample,
        channel: "linear state-space output".into(),
        value: f64::INFINITY,
    }
}

impl Model for LinearSsModel {
    type Error = BaselineError;

    fn output_names(&self) -> Vec<String> {
        vec![self.output.clone()]
    }

    /// Free run from the state fitted to the first `window` outputs (reported as
    /// `initial_samples`). Errors: not SISO, too short, missing window outputs, divergence.
    fn simulate(&self, experiment: &Experiment) -> Result<Prediction> {
        let (u, y) = self.signals(experiment)?;
        if y[..self.window].iter().any(|v| !v.is_finite()) {
            return Err(BaselineError::NoInitialWindow {
                experiment: 0,
                window: self.window,
            });
        }
        let sim = self.simulate_signal(&u, &y).ok_or_else(|| diverged(0))?;
        Ok(Prediction {
            horizon: Horizon::FreeRun,
            outputs: DMatrix::from_row_slice(1, sim.len(), &sim),
            initial_samples: self.window,
        })
    }

    /// k-step prediction: the state at `t − k − window + 1` fitted to the `window` outputs
    /// that end at `t − k`, then run to `t`.
    fn predict(&self, experiment: &Experiment, k: usize) -> Result<Prediction> {
        crate::error::check_horizon(k)?;
        let (u, y) = self.signals(experiment)?;
        let (w, len) = (self.window, u.len());
        let skip = w + k - 1;
        if skip >= len {
            return Err(BaselineError::LagsExceedData {
                what: "state-initialisation window plus prediction horizon",
                experiment: 0,
                needed: skip + 1,
                available: len,
            });
        }
        let mut out = vec![f64::NAN; len];
        for (t, slot) in out.iter_mut().enumerate().skip(skip) {
            let start = t + 1 - k - w;
            if y[start..start + w].iter().any(|v| !v.is_finite()) {
                continue;
            }
            let x = self.state_at(&u, &y, start, w).ok_or_else(|| diverged(t))?;
            let run = self.run(&u, &x, start, t + 1).ok_or_else(|| diverged(t))?;
            *slot = run[run.len() - 1];
        }
        Ok(Prediction {
            horizon: Horizon::Steps(k),
            outputs: DMatrix::from_row_slice(1, len, &out),
            initial_samples: skip,
        })
    }
}

/// Offsets and signals of one record.
pub(super) struct Record<'a> {
    pub(super) u: &'a [f64],
    pub(super) y: &'a [f64],
}
