//! The linear estimator: a model bound to a dataset, discretised once, solved by the
//! exact sweep for any `(W, R)`.

use nalgebra::DMatrix;
use sysid_core::{Dataset, LinearModel};

use crate::binding::{Binding, bind};
use crate::config::Prior;
use crate::discretize::{Discrete, discretize_all};
use crate::error::Result;
use crate::evaluate::{Solve, Summary};
use crate::kernel::sweep;
use crate::sweep::{LogDet, Problem, SteadyState, StepModel, Workspace};

/// A linear assumed model bound to a dataset, with buffers for the estimates.
#[derive(Debug, Clone)]
pub(crate) struct LinearRun<'a> {
    model: &'a LinearModel,
    data: &'a Dataset,
    pub binding: Binding,
    pub discrete: Vec<Discrete>,
    ws: Workspace,
    /// Estimated states per experiment (`n × N`) from the last solve.
    pub states: Vec<DMatrix<f64>>,
    /// Correction pieces per experiment (`q × (N−1)s`) from the last solve.
    pub corrections: Vec<DMatrix<f64>>,
    /// Prior on every experiment's initial state (`None`: free).
    prior: Option<Prior>,
    /// Whether the solves use [`Self::prior`].
    prior_on: bool,
}

impl<'a> LinearRun<'a> {
    /// Bind and discretise (validates channels and sub-steps).
    pub fn new(model: &'a LinearModel, data: &'a Dataset, substeps: Option<usize>) -> Result<Self> {
        if model.n_states() == 0 {
            return Err(crate::error::MmeError::NoStates);
        }
        let binding = bind(model.input_names(), model.output_names(), data)?;
        let periods: Vec<(f64, sysid_core::InterSample, usize)> = data
            .experiments()
            .iter()
            .map(|e| (e.dt(), e.intersample(), e.len()))
            .collect();
        let discrete = discretize_all(model, &periods, substeps)?;
        let (n, q) = (model.n_states(), model.n_corrections());
        let states = data
            .experiments()
            .iter()
            .map(|e| DMatrix::zeros(n, e.len()))
            .collect();
        let corrections = data
            .experiments()
            .iter()
            .zip(&discrete)
            .map(|(e, d)| DMatrix::zeros(q, (e.len() - 1) * d.substeps))
            .collect();
        Ok(Self {
            model,
            data,
            binding,
            discrete,
            ws: Workspace::default(),
            states,
            corrections,
            prior: None,
            prior_on: true,
        })
    }

    /// Put a prior on every experiment's initial state.
    pub fn with_prior(mut self, prior: Option<Prior>) -> Self {
        self.prior = prior;
        self
    }
}

impl Solve for LinearRun<'_> {
    fn n_states(&self) -> usize {
        self.model.n_states()
    }

    fn n_corrections(&self) -> usize {
        self.model.n_corrections()
    }

    fn pieces(&self) -> Vec<(usize, f64)> {
        self.corrections
            .iter()
            .zip(&self.discrete)
            .map(|(c, d)| (c.ncols(), d.h))
            .collect()
    }

    fn use_prior(&mut self, on: bool) {
        self.prior_on = on;
    }

    fn solve(&mut self, w: &DMatrix<f64>, inv_r: &[f64], logdet: LogDet) -> Result<Summary> {
        let p = self.model.n_outputs();
        let prior = self.prior.as_ref().filter(|_| self.prior_on);
        let mut total = Summary {
            sse: vec![0.0; p],
            count: vec![0; p],
            correction_cost: 0.0,
            cost: 0.0,
            logdet_s: 0.0,
            logdet_p0: 0.0,
        };
        for (e, exp) in self.data.experiments().iter().enumerate() {
            let disc = &self.discrete[e];
            let pr = Problem {
                n: self.model.n_states(),
                q: self.model.n_corrections(),
                samples: exp.len(),
                substeps: disc.substeps,
                h: disc.h,
                w,
                c: self.model.c(),
                inv_r,
                outputs: exp.outputs(),
                out_map: &self.binding.outputs,
                experiment: e,
                t0: exp.t0(),
                steady: SteadyState::Allow,
                prior,
            };
            let steps = StepModel::Lti {
                ad: &disc.ad,
                ed: &disc.ed,
                bd: &disc.bd,
                inputs: exp.inputs(),
                in_map: &self.binding.inputs,
                ramp: disc.ramp.as_ref(),
            };
            let out = sweep(
                &pr,
                &steps,
                &mut self.ws,
                self.states[e].as_mut_slice(),
                self.corrections[e].as_mut_slice(),
                logdet,
            )?;
            for i in 0..p {
                total.sse[i] += out.sse[i];
                total.count[i] += out.count[i];
            }
            total.cost += out.cost(inv_r);
            total.correction_cost += out.correction_cost;
            total.logdet_s += out.logdet_s;
            total.logdet_p0 += out.logdet_p0;
        }
        Ok(total)
    }
}
