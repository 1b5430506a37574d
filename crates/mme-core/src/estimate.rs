//! The public entry points of the linear estimator and the assembly of its result.

use std::time::Instant;

use nalgebra::DMatrix;
use sysid_core::{
    Dataset, ExperimentEstimate, InterSample, LinearModel, MmeEstimate, ModelNames, SolveReport,
    Termination,
};

use crate::config::{
    MmeConfig, NoiseSpec, ResolvedWeight, check_noise, resolve_prior, resolve_weight,
};
use crate::error::Result;
use crate::evaluate::{Solve, Summary};
use crate::linear::LinearRun;
use crate::noise::estimate_noise;
use crate::nonlinear::NonlinearModel;
use crate::observe::{MmeEvent, MmeObserver, MmePhase, NoObserver};
use crate::result::{MmeOutput, NoiseMethod, NoiseReport};
use crate::sweep::LogDet;
use crate::tune_w::tune;

/// MME estimate of a linear assumed model on a dataset; see [`estimate_with_report`] for
/// the `W` curve and the noise report.
///
/// The dataset's output channels are matched to `model.output_names()` and its inputs to
/// `model.input_names()` by name (extra dataset channels are ignored). NaN outputs are
/// missing samples and are skipped per channel.
pub fn estimate(model: &LinearModel, data: &Dataset, config: &MmeConfig) -> Result<MmeEstimate> {
    estimate_with_report(model, data, config).map(|o| o.estimate)
}

/// MME estimate of a linear assumed model, with the residual-variance-versus-`W` curve of
/// the automatic search and the noise-variance report.
///
/// Steps: validate the configuration and bind channels; discretise (exact, once per
/// sample period, with the ramp term for first-order-hold experiments); estimate `R` if asked ([`crate::noise`]); find `W` if asked
/// ([`crate::tune_w`]); run the exact sweep (private module `sweep`) at the final `(W, R)`.
/// `report.termination` is `Exact` for a fixed `W`, otherwise the `W` search's ending.
///
/// A record read band-limited between samples ([`InterSample::Bl`]) has no exact
/// discretisation per sample interval: such a dataset goes to the nonlinear estimator
/// ([`crate::estimate_nonlinear_with_report`], RK4 sub-steps reading the record's grid)
/// with the linear model as its dynamics.
pub fn estimate_with_report(
    model: &LinearModel,
    data: &Dataset,
    config: &MmeConfig,
) -> Result<MmeOutput> {
    estimate_with_observer(model, data, config, &NoObserver)
}

/// [`estimate_with_report`], telling `observer` each step as it runs (see
/// [`crate::observe`]: the noise-variance search's evaluations, the `W` trials, the
/// final sweep). The result is the same, bit for bit, whatever the observer.
pub fn estimate_with_observer(
    model: &LinearModel,
    data: &Dataset,
    config: &MmeConfig,
    observer: &dyn MmeObserver,
) -> Result<MmeOutput> {
    if data
        .experiments()
        .iter()
        .any(|e| e.intersample() == InterSample::Bl)
    {
        let names = ModelNames {
            states: model.state_names().to_vec(),
            inputs: model.input_names().to_vec(),
            outputs: model.output_names().to_vec(),
            corrections: model.correction_names().to_vec(),
        };
        let nl = NonlinearModel::new(model.clone(), model.c().clone(), model.e().clone(), names)?;
        return crate::estimate_nonlinear_with_observer(&nl, data, config, observer);
    }
    let mut clock = Phases::new();
    let weight = resolve_weight(&config.w, model.n_corrections())?;
    if let NoiseSpec::Given(v) = &config.noise_variance {
        check_noise(v, model.output_names())?;
    }
    let prior = resolve_prior(&config.x0_prior, model.state_names())?;
    let mut run = LinearRun::new(model, data, config.substeps)?.with_prior(prior);
    clock.mark("validate_and_discretize");

    let noise = resolve_noise(
        &mut run,
        &weight,
        config,
        data,
        model.output_names(),
        observer,
    )?;
    clock.mark("noise");

    let inv_r: Vec<f64> = noise.variance.iter().map(|v| 1.0 / v).collect();
    let mut w_curve = Vec::new();
    let (w, w_search) = match &weight {
        ResolvedWeight::Fixed(w) => (w.clone(), None),
        ResolvedWeight::Auto { shape, opts } => {
            observer.event(&MmeEvent::Phase(MmePhase::WeightSearch));
            let search = tune(&mut run, shape, &inv_r, opts, &mut w_curve, observer)?;
            (shape * search.alpha, Some(search))
        }
    };
    clock.mark("tune_w");

    observer.event(&MmeEvent::Phase(MmePhase::FinalSolve));
    let summary = run.solve(&w, &inv_r, LogDet::Skip)?;
    clock.mark("sweep");

    // Move the estimates out of the run (no copy of N-long matrices).
    let states = std::mem::take(&mut run.states);
    let corrections = std::mem::take(&mut run.corrections);
    let experiments = data
        .experiments()
        .iter()
        .zip(&run.discrete)
        .zip(states.into_iter().zip(corrections))
        .map(|((exp, disc), (x, d))| ExperimentEstimate {
            t0: exp.t0(),
            dt: exp.dt(),
            substeps: disc.substeps,
            states: x,
            corrections: d,
        })
        .collect();
    let termination = w_search
        .as_ref()
        .map_or(Termination::Exact, |s| s.termination);
    let estimate = assemble(
        model.state_names(),
        model.correction_names(),
        model.output_names(),
        experiments,
        w,
        &noise,
        &summary,
        SolveReport {
            termination: Some(termination),
            iterations: Vec::new(),
            phase_seconds: clock.done(),
        },
    );
    Ok(MmeOutput {
        estimate,
        w_curve,
        w_search,
        noise,
    })
}

/// `R` as given, or estimated with the `W` shape of the configuration (announced to
/// `observer` as [`MmePhase::NoiseVariance`]).
pub(crate) fn resolve_noise<S: Solve>(
    solver: &mut S,
    weight: &ResolvedWeight,
    config: &MmeConfig,
    data: &Dataset,
    outputs: &[String],
    observer: &dyn MmeObserver,
) -> Result<NoiseReport> {
    match &config.noise_variance {
        NoiseSpec::Given(v) => Ok(NoiseReport {
            method: NoiseMethod::Given,
            variance: v.clone(),
            difference_based: Vec::new(),
            spectral_floor: Vec::new(),
            likelihood_alpha: None,
            neg2_log_likelihood: None,
            evaluations: 0,
        }),
        NoiseSpec::Auto => {
            let shape = match weight {
                ResolvedWeight::Fixed(w) => w.clone(),
                ResolvedWeight::Auto { shape, .. } => shape.clone(),
            };
            let binding = crate::binding::bind(&[], outputs, data)?;
            // The restricted likelihood integrates over a diffuse initial state; a prior
            // in absolute units would break the concentration over the common scale.
            solver.use_prior(false);
            observer.event(&MmeEvent::Phase(MmePhase::NoiseVariance));
            let report = estimate_noise(solver, &shape, data, &binding, outputs, observer);
            solver.use_prior(true);
            report
        }
    }
}

/// Build the shared result type.
#[allow(clippy::too_many_arguments)]
pub(crate) fn assemble(
    states: &[String],
    corrections: &[String],
    outputs: &[String],
    experiments: Vec<ExperimentEstimate>,
    w: DMatrix<f64>,
    noise: &NoiseReport,
    summary: &Summary,
    report: SolveReport,
) -> MmeEstimate {
    MmeEstimate {
        state_names: states.to_vec(),
        correction_names: corrections.to_vec(),
        output_names: outputs.to_vec(),
        experiments,
        w,
        noise_variance: noise.variance.clone(),
        residual_variance: summary.residual_variance(),
        cost: summary.cost,
        report,
    }
}

/// Wall time per phase.
pub(crate) struct Phases {
    last: Instant,
    phases: Vec<(String, f64)>,
}

impl Phases {
    pub fn new() -> Self {
        Self {
            last: Instant::now(),
            phases: Vec::new(),
        }
    }
    pub fn mark(&mut self, name: &str) {
        let now = Instant::now();
        self.phases
            .push((name.to_string(), (now - self.last).as_secs_f64()));
        self.last = now;
    }
    pub fn done(self) -> Vec<(String, f64)> {
        self.phases
    }
}
