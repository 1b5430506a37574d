//! The trajectory-training step of `mmenn fit` (thesis §7.1): after the network has
//! learned MME's `d̂`, its weights are trained further by multiple shooting on the training
//! records' free-run output error ([`nn::train_on_trajectories`], the network inside the
//! hybrid model `sysid_core::CorrectedModel`), and the validation free-run is reported
//! before and after. ("Refine" is kept for discovery's model refinement.)

use std::collections::BTreeMap;

use nn::{Mlp, ShootingRecord, TrajectoryConfig, TrajectoryReport};
use serde::Serialize;
use sysid_core::{Dataset, MmeEstimate};

use super::FitOptions;
use crate::error::Result;
use crate::model_file::ModelSpec;

/// Whether `fit` trains the network on trajectories after training it on `d̂`
/// (`--train-on-trajectories yes|no`; the old spelling `--refine trajectory|none` is still
/// read).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum TrajectoryChoice {
    /// Keep the network trained on `d̂`.
    None,
    /// Multiple-shooting Levenberg–Marquardt on the training records' free-run output
    /// error, windows started from MME's `x̂`, early stopping on the validation records'
    /// windows when given (the default: on the test suite's systems it
    /// never made the validation free-run worse and helped most where `d̂` is biased).
    #[default]
    Trajectory,
}

impl std::str::FromStr for TrajectoryChoice {
    type Err = String;
    /// `yes` / `no`, or the old values `trajectory` / `none`.
    fn from_str(s: &str) -> std::result::Result<Self, Self::Err> {
        match s {
            "no" | "none" => Ok(Self::None),
            "yes" | "trajectory" => Ok(Self::Trajectory),
            _ => Err(format!(
                "'{s}' is neither \"yes\" nor \"no\" (the old \"trajectory\" and \"none\" also work)"
            )),
        }
    }
}

/// What the trajectory training did, and whether it helped on validation data.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TrajectorySummary {
    /// The optimiser's report (objective = mean squared output error over the shooting
    /// windows, in units of each channel's standard deviation).
    pub report: TrajectoryReport,
    /// Free-run fit % per output channel on the validation record with the network
    /// trained on `d̂` only (when validation data are given and its free run did not
    /// fail), judged as the kept model is: the one free-run judge, the network's domain
    /// [`TrajectorySummary::validation_domain`].
    pub validation_fit_before: Option<BTreeMap<String, f64>>,
    /// The same with the network trained on trajectories (the validation report's numbers
    /// when it was kept).
    pub validation_fit_after: Option<BTreeMap<String, f64>>,
    /// What both networks did outside their training box in those validation free runs:
    /// the kept model's domain (`None` without validation data). Under
    /// `DomainPolicy::Checked` the guard judges each candidate with the domain its stress
    /// check gave it, which may differ; these two numbers are judged one way.
    pub validation_domain: Option<nn::Domain>,
}

impl TrajectorySummary {
    /// Markdown section for `report.md`.
    pub fn markdown(&self) -> String {
        let r = &self.report;
        let mut s = format!(
            "\n## Trajectory training (thesis §7.1)\n\nMultiple shooting over {} training \
             windows ({} held out for early stopping), started from MME's x̂: {} LM steps, \
             returned step {} (stopped: {}); training objective (mean squared residual in \
             units of each channel's standard deviation) {:.4e} → {:.4e}.\n",
            r.train_windows,
            r.val_windows,
            r.iterations,
            r.best_iteration,
            crate::words::termination(Some(r.termination)),
            r.initial_train_objective(),
            r.final_train_objective(),
        );
        if let (Some(b), Some(a)) = (&self.validation_fit_before, &self.validation_fit_after) {
            if let Some(d) = self.validation_domain {
                s.push_str(&format!(
                    "\nBoth validation free runs with the kept model's domain ({}).\n",
                    crate::words::network_domain(d)
                ));
            }
            s.push_str(
                "\n| channel | validation fit % before | after | helped |\n|---|---|---|---|\n",
            );
            for (name, before) in b {
                let after = a.get(name).copied().unwrap_or(f64::NAN);
                let verdict = if after > *before { "yes" } else { "no" };
                s.push_str(&format!(
                    "| {name} | {before:.2} | {after:.2} | {verdict} |\n"
                ));
            }
        } else if self.validation_domain.is_some() {
            s.push_str(&format!("\n{}\n", self.validation_failure()));
        } else {
            s.push_str("\nNo validation data given: whether it helped is not judged.\n");
        }
        s
    }

    /// Which validation free run failed, in words (when validation data were given and
    /// one of the two has no numbers).
    pub(crate) fn validation_failure(&self) -> String {
        let which = match (&self.validation_fit_before, &self.validation_fit_after) {
            (None, None) => "of the network before and after it",
            (None, Some(_)) => "of the network before it",
            _ => "of the network after it",
        };
        format!("The validation free run {which} failed: whether it helped is not judged.")
    }
}

/// Shooting records: each experiment (with its `intersample`, which the windows follow)
/// with MME's `x̂` of it.
pub(super) fn shooting<'a>(data: &'a Dataset, est: &'a MmeEstimate) -> Vec<ShootingRecord<'a>> {
    data.experiments()
        .iter()
        .zip(&est.experiments)
        .map(|(experiment, e)| ShootingRecord {
            experiment,
            states: &e.states,
        })
        .collect()
}

/// Train `network` on the training records' trajectories (`train`, from [`shooting`] or
/// pieces of it), windows starting from MME's `x̂`; windows of the validation records (with MME's `x̂` of them) decide when to stop,
/// when given. Whether it helped on the validation record is judged after the guard,
/// with the kept model's domain (`compute_fit`).
pub(super) fn train_network_on_trajectories(
    spec: &ModelSpec,
    network: &mut Mlp,
    train: &[ShootingRecord<'_>],
    val: Option<(&MmeEstimate, &Dataset)>,
    x0: &[f64],
    opts: &FitOptions,
    progress: &dyn crate::progress::ProgressSink,
) -> Result<TrajectorySummary> {
    let config = TrajectoryConfig {
        substeps: opts.substeps,
        ..opts.trajectory
    };
    let mut model = crate::hybrid::hybrid_model(
        spec,
        network.clone(),
        x0,
        opts.substeps,
        opts.network_domain.initial(),
    )?;
    let val = val.map_or_else(Vec::new, |(e, d)| shooting(d, e));
    const TASK: &str = "trajectory training";
    let most = config.max_iterations;
    let mut on_step = |p: nn::TrajectoryProgress| {
        let note = match p.val_objective {
            Some(v) => format!("objective {:.4e}, held out {v:.4e}", p.train_objective),
            None => format!("objective {:.4e}", p.train_objective),
        };
        progress
            .report(&crate::progress::Progress::new(TASK, p.iteration, Some(most)).with_note(note));
    };
    progress.report(&crate::progress::Progress::new(TASK, 0, Some(most)));
    let report = nn::train_on_trajectories(&mut model, train, &val, &config, Some(&mut on_step));
    progress.finish(TASK);
    let report = report?;
    network.clone_from(model.correction().network());
    Ok(TrajectorySummary {
        report,
        validation_fit_before: None,
        validation_fit_after: None,
        validation_domain: None,
    })
}
