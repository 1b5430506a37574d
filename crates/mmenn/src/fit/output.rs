//! What `mmenn fit` writes: the model, the sweep, the summary, the report and the
//! figures.

use std::path::Path;

use nn::SweepRow;
use sysid_core::Experiment;

use super::{
    FitOutcome, FitSummary, GuardCandidate, NetworkInputs, NetworkSelection, Training, d_figures,
    network_variables, row,
};
use crate::atomic::{ensure_dir, write_atomic};
use crate::data_file::write_csv;
use crate::error::Result;
use crate::model::{FreeRunReport, Judgement};
use crate::model_file::ModelSpec;
use crate::plot::{Figure, Series};

/// Write what [`compute_fit`](super::compute_fit) computed into `out`: `model.json`, `sweep.csv`,
/// `summary.json`, `report.md` and the figures (atomically, each file).
pub fn write_fit(o: &FitOutcome, out: &Path) -> Result<()> {
    ensure_dir(out)?;
    let spec = &o.spec;
    compare_figure(spec, &o.train_record, &o.train, "training")?
        .write(&out.join("compare_train.svg"))?;
    if let (Some(j), Some(exp)) = (&o.validation, &o.validation_record) {
        compare_figure(spec, exp, j, "validation")?.write(&out.join("compare_validation.svg"))?;
    }
    // d̂ and the network's fit of it on the training record.
    let net = match o.summary.network_inputs {
        NetworkInputs::StatesAndInputs => "NN(x̂, u)",
        NetworkInputs::States => "NN(x̂)",
    };
    for (i, name) in spec.linear.correction_names().iter().enumerate() {
        let idx: Vec<f64> = (0..o.d_train.ncols()).map(|k| k as f64).collect();
        let fig = Figure {
            title: format!("d_{name}: MME estimate and network"),
            x_label: "training pair".into(),
            y_label: match spec.unit_of(&format!("d_{name}")) {
                Some(u) => format!("d_{name} ({u})"),
                None => format!("d_{name}"),
            },
            series: vec![
                Series::points("MME d̂", idx.clone(), row(&o.d_train, i)),
                Series::line(
                    match sysid_core::channel_metrics(&row(&o.d_train, i), &row(&o.d_network, i)) {
                        Ok(m) if m.fit_percent.is_finite() => {
                            format!("{net} (fit {:.1} % to d̂)", m.fit_percent)
                        }
                        _ => net.to_string(),
                    },
                    idx,
                    row(&o.d_network, i),
                ),
            ],
            bands: vec![],
        };
        fig.write(&out.join(format!("nn_d_{name}.svg")))?;
        d_figures::d_against_variables(
            name,
            &row(&o.d_train, i),
            &row(&o.d_network, i),
            &o.x_train,
            &network_variables(spec, o.summary.network_inputs),
            spec,
            out,
        )?;
    }
    write_sweep(&out.join("sweep.csv"), &o.sweep)?;
    sweep_figure(&o.sweep, o.chosen).write(&out.join("sweep.svg"))?;
    write_atomic(
        &out.join("model.json"),
        serde_json::to_string_pretty(&o.model)?.as_bytes(),
    )?;
    write_atomic(
        &out.join("summary.json"),
        serde_json::to_string_pretty(&o.summary)?.as_bytes(),
    )?;
    crate::html::write_report(out, &fit_report(&o.summary))?;
    Ok(())
}

impl FitSummary {
    /// What the trajectory training, the guard and the stress check decided, one line
    /// each, as the terminal shows them (`mmenn fit` and `mmenn compare` print the same
    /// lines): the trajectory training and, with validation data, the validation free-run
    /// fit before and after it, both with the kept model's domain (the rule stated); the
    /// kept model and its domain, and why; the network-domain decision (a stress-check
    /// line per network candidate under `DomainPolicy::Checked`).
    pub fn decision_lines(&self) -> Vec<String> {
        let mut lines = Vec::new();
        if let Some(r) = &self.refinement {
            lines.push(format!(
                "trajectory training: {} steps, objective {:.4e} -> {:.4e}",
                r.report.iterations,
                r.report.initial_train_objective(),
                r.report.final_train_objective()
            ));
            match (
                &r.validation_fit_before,
                &r.validation_fit_after,
                r.validation_domain,
            ) {
                (Some(b), Some(a), Some(d)) => {
                    for (name, before) in b {
                        lines.push(format!(
                            "  validation free-run fit of {name}: {before:.2} % -> {:.2} % \
                             ({}, the kept model's domain)",
                            a.get(name).copied().unwrap_or(f64::NAN),
                            crate::words::network_domain(d)
                        ));
                    }
                }
                (_, _, Some(_)) => lines.push(format!("  {}", r.validation_failure())),
                _ => {}
            }
        }
        let kept_domain = match self.guard.chosen {
            GuardCandidate::PhysicsAlone => String::new(),
            _ => format!(" ({})", crate::words::network_domain(self.network_domain)),
        };
        lines.push(format!(
            "kept: {}{kept_domain} — {} (judged free-run on {})",
            self.guard.chosen.describe(),
            self.guard.reason,
            self.guard.held_out
        ));
        // The guard's errors judge each network with its own domain: say where that is
        // not the kept model's.
        let own: Vec<String> = self
            .guard
            .candidates
            .iter()
            .filter_map(|c| {
                c.domain.filter(|d| *d != self.network_domain).map(|d| {
                    format!(
                        "{}: {}",
                        c.candidate.describe(),
                        crate::words::network_domain(d)
                    )
                })
            })
            .collect();
        if !own.is_empty() {
            lines.push(format!(
                "  (the guard's errors judge each network with the domain its stress check \
                 gave it; {})",
                own.join("; ")
            ));
        }
        lines.extend(self.guard.domain.lines());
        lines
    }
}

/// The training or validation record's outputs measured and simulated free-run by the
/// hybrid model (fit % in the legend), over the residual.
fn compare_figure(
    spec: &ModelSpec,
    exp: &Experiment,
    rep: &Judgement,
    which: &str,
) -> Result<crate::plot::Panels> {
    let outputs = spec.linear.output_names();
    let labels: Vec<String> = outputs
        .iter()
        .map(|name| {
            let fit = rep.channels.get(name).map_or(f64::NAN, |m| m.fit_percent);
            format!("{name} MME/NN free-run (fit {fit:.1} %)")
        })
        .collect();
    crate::plot::Panels::outputs_with_residuals(
        format!("MME/NN hybrid model, free-run simulation ({which} data)"),
        outputs,
        &spec.units,
        exp,
        &rep.outputs,
        &labels,
    )
}

fn sweep_figure(rows: &[SweepRow], chosen: usize) -> Figure {
    let h: Vec<f64> = rows.iter().map(|r| r.hidden as f64).collect();
    let marked: Vec<&SweepRow> = rows.get(chosen).into_iter().collect();
    Figure {
        title: "network sizing sweep (thesis Figs. 4.5, 4.9)".into(),
        x_label: "hidden units".into(),
        y_label: "log10 MSE of d".into(),
        series: vec![
            Series::points(
                "training",
                h.clone(),
                rows.iter()
                    .map(|r| r.train_mse.log10())
                    .collect::<Vec<f64>>(),
            ),
            Series::points(
                "test",
                h,
                rows.iter()
                    .map(|r| r.test_mse.log10())
                    .collect::<Vec<f64>>(),
            ),
            Series::highlight(
                marked
                    .first()
                    .map(|r| format!("chosen: {} hidden, init {} (test)", r.hidden, r.init))
                    .unwrap_or_default(),
                marked.iter().map(|r| r.hidden as f64).collect::<Vec<f64>>(),
                marked
                    .iter()
                    .map(|r| r.test_mse.log10())
                    .collect::<Vec<f64>>(),
            ),
        ],
        bands: vec![],
    }
}

fn write_sweep(path: &Path, rows: &[SweepRow]) -> Result<()> {
    let header: Vec<String> = [
        "hidden",
        "init",
        "seed",
        "train_mse",
        "val_mse",
        "test_mse",
        "epochs",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    let cols: Vec<Vec<f64>> = vec![
        rows.iter().map(|r| r.hidden as f64).collect(),
        rows.iter().map(|r| r.init as f64).collect(),
        rows.iter().map(|r| r.seed as f64).collect(),
        rows.iter().map(|r| r.train_mse).collect(),
        rows.iter().map(|r| r.val_mse.unwrap_or(f64::NAN)).collect(),
        rows.iter().map(|r| r.test_mse).collect(),
        rows.iter().map(|r| r.epochs as f64).collect(),
    ];
    let refs: Vec<&[f64]> = cols.iter().map(Vec::as_slice).collect();
    write_csv(path, &header, &refs)
}

fn metrics_table(rep: &FreeRunReport) -> String {
    let mut s =
        String::from("| channel | fit % | R² | RMSE | error variance |\n|---|---|---|---|---|\n");
    for (n, m) in &rep.channels {
        s.push_str(&format!(
            "| {n} | {:.2} | {:.5} | {:.4e} | {:.4e} |\n",
            m.fit_percent, m.r2, m.rmse, m.error_variance
        ));
    }
    s
}

fn fit_report(s: &FitSummary) -> String {
    let mut r = String::from("# MME/NN hybrid model\n\n");
    for m in s.unconverged_mme() {
        r.push_str(&format!(
            "**Not to be trusted:** MME's {m}. The network learnt a d̂ that is not MME's \
             estimate ({}).\n\n",
            m.remedy()
        ));
    }
    let training = match s.training {
        Training::Trainlm => "Levenberg–Marquardt with MATLAB trainlm's damping schedule",
        Training::Accelerated => {
            "Levenberg–Marquardt, trainlm's schedule for 10 steps, then gain-ratio damping \
             with geodesic acceleration"
        }
    };
    let selection = match s.selection {
        NetworkSelection::CorrectionMse => "the thesis rule on the test MSE of d̂",
        NetworkSelection::FreeRun => "smallest free-run output error on the training data",
    };
    r.push_str(&format!(
        "Network: {} hidden tanh units, picked from the sizing sweep by {selection}; trained \
         by {training}. Train MSE of d̂ {:.3e}, test MSE {:.3e} (test set: {}). {} training \
         pairs {} → d̂. MME W by corrected state: {}.\n\n",
        s.hidden,
        s.chosen.train_mse,
        s.chosen.test_mse,
        s.test_source,
        s.training_pairs,
        match s.network_inputs {
            NetworkInputs::StatesAndInputs => "(x̂, u)",
            NetworkInputs::States => "x̂ (the states alone: `--network-inputs states`)",
        },
        crate::words::named_values(&s.w_by_correction)
    ));
    let estimates: Vec<String> = s.mme_estimates.iter().map(|m| m.to_string()).collect();
    r.push_str(&format!("MME: {}.\n\n", estimates.join("; ")));
    let bounds: Vec<String> = s
        .network_box
        .iter()
        .map(|(n, lo, hi)| format!("{n} ∈ [{lo:.4e}, {hi:.4e}]"))
        .collect();
    r.push_str(&format!(
        "The network learnt the correction on {}; outside that box it {}.\n\n",
        bounds.join(", "),
        match (s.network_domain, s.guard.domain.policy) {
            (nn::Domain::Hold, crate::fit::DomainPolicy::Checked) => {
                "keeps its value at the box's nearest point (held: it failed the stress check, \
                 see *Which model was kept*)"
            }
            (nn::Domain::Hold, _) => "keeps its value at the box's nearest point (held)",
            (nn::Domain::Extrapolate, _) => {
                "extrapolates (`--network-domain hold` holds it at the box's edge instead; \
                 `predict` says how often a free run leaves the box)"
            }
        }
    ));
    r.push_str(
        "*Fit %* = 100·(1 − ‖y − ŷ‖ / ‖y − mean(y)‖): 100 is perfect, 0 is no better than \
         the mean. *R²* = 1 − Σ(y − ŷ)² / Σ(y − mean y)². *RMSE*: root mean square of \
         y − ŷ, in the channel's unit. *Error variance*: variance of y − ŷ. ŷ is the \
         free-run simulation (no measurement used after the initial state).\n\n",
    );
    r.push_str(&format!(
        "## Training data — {}, {} scored\n\nInitial state: {}.\n\n",
        s.train.horizon, s.train.scored, s.train.x0_source
    ));
    r.push_str(&metrics_table(&s.train));
    if let Some(v) = &s.validation {
        r.push_str(&format!(
            "\n## Validation data — {}, {} scored\n\nInitial state: {}.\n\n",
            v.horizon, v.scored, v.x0_source
        ));
        if let Some(line) = s.validation_use_line() {
            r.push_str(&format!("{line}\n\n"));
        }
        r.push_str(&metrics_table(v));
    }
    if let Some(refine) = &s.refinement {
        r.push_str(&refine.markdown());
    }
    r.push_str(&s.guard.markdown());
    r.push_str(
        "\nFigures: `compare_*.svg` (measured output and the hybrid model's free run), \
         `nn_d_*.svg` (MME's d̂ and the network's fit of it, over the training pairs and \
         against each state and input), `sweep.svg` (MSE of d̂ per \
         network size, the chosen network ringed); the sweep table is `sweep.csv`.\n",
    );
    r.push_str(&crate::html::figures_section(&s.files));
    r
}
