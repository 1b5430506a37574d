//! The files of an estimate: `estimate.csv`, the figures and `report.md` (with
//! `report.html`), from one set of columns per experiment.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use mme_core::MmeOutput;
use sysid_core::{Dataset, MmeEstimate};

use super::{EstimateSummary, OUTLIER_SCREEN_SIGMA};
use crate::data_file::write_csv;
use crate::error::Result;
use crate::model_file::ModelSpec;
use crate::plot::{Figure, Series};

/// Row `i` of a matrix as a shared column, written straight into its one allocation
/// (a mapped range has a known length, so nothing is collected twice).
fn shared_row(m: &nalgebra::DMatrix<f64>, i: usize) -> Arc<[f64]> {
    let (rows, data) = (m.nrows(), m.as_slice());
    (0..m.ncols()).map(|k| data[i + k * rows]).collect()
}

/// One experiment's estimate as columns, made once and shared by `estimate.csv` and the
/// figures: sample times, every state, and `d̂` per corrected state at the samples (the
/// piece that starts at the sample, as [`sysid_core::ExperimentEstimate::corrections_at_samples`]).
pub(super) struct EstimateColumns {
    t: Arc<[f64]>,
    states: Vec<Arc<[f64]>>,
    corrections: Vec<Arc<[f64]>>,
}

impl EstimateColumns {
    pub(super) fn of(e: &sysid_core::ExperimentEstimate) -> Self {
        let n = e.len();
        let pieces = e.corrections.ncols();
        let (q, c) = (e.corrections.nrows(), e.corrections.as_slice());
        let correction = |i: usize| -> Arc<[f64]> {
            (0..n)
                .map(|k| {
                    if pieces == 0 {
                        0.0
                    } else {
                        c[i + (k * e.substeps).min(pieces - 1) * q]
                    }
                })
                .collect()
        };
        Self {
            t: (0..n).map(|k| e.t0 + k as f64 * e.dt).collect(),
            states: (0..e.states.nrows())
                .map(|i| shared_row(&e.states, i))
                .collect(),
            corrections: (0..q).map(correction).collect(),
        }
    }
}

/// Write one experiment's estimate as CSV: `t`, every state, `d_<state>` per corrected state.
pub fn write_estimate_csv(path: &Path, est: &MmeEstimate, experiment: usize) -> Result<()> {
    write_columns_csv(
        path,
        est,
        &EstimateColumns::of(&est.experiments[experiment]),
    )
}

pub(super) fn write_columns_csv(
    path: &Path,
    est: &MmeEstimate,
    cols: &EstimateColumns,
) -> Result<()> {
    let mut header = vec!["t".to_string()];
    header.extend(est.state_names.iter().cloned());
    header.extend(est.correction_names.iter().map(|c| format!("d_{c}")));
    let mut refs: Vec<&[f64]> = vec![&cols.t];
    refs.extend(cols.states.iter().map(|c| &c[..]));
    refs.extend(cols.corrections.iter().map(|c| &c[..]));
    write_csv(path, &header, &refs)
}

/// Figures of an estimate (first experiment): measurement vs estimate per measured
/// channel, every state, `d̂` vs time, `d̂` against each state and input, and the W curve
/// (with the covariance constraint's target ratio 1).
pub fn estimate_figures(
    out: &MmeOutput,
    data: &Dataset,
    spec: &ModelSpec,
    dir: &Path,
) -> Result<Vec<PathBuf>> {
    estimate_figures_with_target(out, data, spec, dir, 1.0)
}

/// [`estimate_figures`] with the W search's target ratio (a robust estimate aims at
/// `κ(c)`, see [`mme_core::robust::huber_variance`]).
pub fn estimate_figures_with_target(
    out: &MmeOutput,
    data: &Dataset,
    spec: &ModelSpec,
    dir: &Path,
    target_ratio: f64,
) -> Result<Vec<PathBuf>> {
    let cols = EstimateColumns::of(&out.estimate.experiments[0]);
    figures_of(out, data, spec, dir, target_ratio, &cols)
}

/// [`estimate_figures_with_target`] with the first experiment's columns made already.
pub(super) fn figures_of(
    out: &MmeOutput,
    data: &Dataset,
    spec: &ModelSpec,
    dir: &Path,
    target_ratio: f64,
    cols: &EstimateColumns,
) -> Result<Vec<PathBuf>> {
    let est = &out.estimate;
    let (e, exp) = (&est.experiments[0], &data.experiments()[0]);
    // Every column is copied out of its matrix once and shared by the figures.
    let t = cols.t.clone();
    let shared = shared_row;
    let unit = |n: &str| {
        spec.unit_of(n)
            .map(|u| format!("{n} ({u})"))
            .unwrap_or_else(|| n.to_string())
    };
    let mut figures: Vec<(String, Figure)> = Vec::new();
    let mut save = |name: String, fig: Figure| -> Result<()> {
        figures.push((name, fig));
        Ok(())
    };
    let states = &cols.states;
    let y_hat = spec.linear.c() * &e.states;
    for (i, name) in est.output_names.iter().enumerate() {
        let Ok(j) = data.output_index(name) else {
            continue;
        };
        let measured = shared(exp.outputs(), j);
        let smoothed = shared(&y_hat, i);
        let label = match sysid_core::channel_metrics(&measured, &smoothed) {
            Ok(m) if m.fit_percent.is_finite() => {
                format!(
                    "MME estimate (fit {:.1} % to the measurement)",
                    m.fit_percent
                )
            }
            _ => "MME estimate".to_string(),
        };
        let fig = Figure {
            title: format!("{name}: measurement and MME estimate (smoother, not a prediction)"),
            x_label: "t (s)".into(),
            y_label: unit(name),
            series: vec![
                Series::points("measured", t.clone(), measured),
                Series::line(label, t.clone(), smoothed),
            ],
            bands: vec![],
        };
        save(format!("measured_{name}.svg"), fig)?;
    }
    drop(y_hat);
    let fig = Figure {
        title: "estimated states".into(),
        x_label: "t (s)".into(),
        y_label: "state (units in the legend)".into(),
        series: est
            .state_names
            .iter()
            .zip(states)
            .map(|(n, x)| Series::line(unit(n), t.clone(), x.clone()))
            .collect(),
        bands: vec![],
    };
    save("states.svg".into(), fig)?;
    let corrections = &cols.corrections;
    let fig = Figure {
        title: "model correction d̂(t)".into(),
        x_label: "t (s)".into(),
        y_label: "d̂ (units in the legend)".into(),
        series: est
            .correction_names
            .iter()
            .zip(corrections)
            .map(|(n, dv)| Series::line(unit(&format!("d_{n}")), t.clone(), dv.clone()))
            .collect(),
        bands: vec![],
    };
    save("d_vs_time.svg".into(), fig)?;
    let inputs: Vec<(String, Arc<[f64]>)> = spec
        .linear
        .input_names()
        .iter()
        .filter_map(|n| {
            data.input_index(n)
                .ok()
                .map(|j| (n.clone(), shared(exp.inputs(), j)))
        })
        .collect();
    for (cname, dv) in est.correction_names.iter().zip(corrections) {
        let against = est
            .state_names
            .iter()
            .cloned()
            .zip(states.iter().cloned())
            .chain(inputs.iter().cloned());
        for (vname, v) in against {
            let fig = Figure {
                title: format!("d_{cname} against {vname}"),
                x_label: unit(&vname),
                y_label: unit(&format!("d_{cname}")),
                series: vec![Series::points("MME estimate", v, dv.clone())],
                bands: vec![],
            };
            save(format!("d_{cname}_vs_{vname}.svg"), fig)?;
        }
    }
    if !out.w_curve.is_empty() {
        let x: Vec<f64> = out.w_curve.iter().map(|p| p.alpha.log10()).collect();
        let mut series: Vec<Series> = est
            .output_names
            .iter()
            .enumerate()
            .map(|(i, n)| {
                Series::line(
                    format!("{n}: residual / noise variance"),
                    x.clone(),
                    out.w_curve
                        .iter()
                        .map(|p| p.residual_variance[i] / out.noise.variance[i])
                        .collect::<Vec<f64>>(),
                )
            })
            .collect();
        series.push(Series::points(
            "constraint ratio ρ (sweeps of the search)",
            x.clone(),
            out.w_curve.iter().map(|p| p.ratio).collect::<Vec<f64>>(),
        ));
        let (xa, xb) = x
            .iter()
            .filter(|v| v.is_finite())
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
                (a.min(*v), b.max(*v))
            });
        if xa.is_finite() {
            series.push(Series::dashed(
                format!("target ρ = {target_ratio:.3}"),
                vec![xa, xb],
                vec![target_ratio, target_ratio],
            ));
        }
        if let Some(w) = &out.w_search
            && w.alpha > 0.0
        {
            series.push(Series::highlight(
                format!("chosen α = {:.4e}", w.alpha),
                vec![w.alpha.log10()],
                vec![w.ratio],
            ));
        }
        let fig = Figure {
            title: "covariance constraint: residual variance against W".into(),
            x_label: "log10 α  (W = α·shape)".into(),
            y_label: "residual variance / noise variance".into(),
            series,
            bands: vec![],
        };
        save("w_curve.svg".into(), fig)?;
    }
    write_figures(dir, figures)
}

/// Render and write figures (each atomically) on the available cores; returns their
/// paths in the order given. The files do not depend on the order they are drawn in; the
/// first error in the given order is returned.
pub fn write_figures(dir: &Path, figures: Vec<(String, Figure)>) -> Result<Vec<PathBuf>> {
    use rayon::prelude::*;
    let written: Vec<Result<PathBuf>> = figures
        .into_par_iter()
        .map(|(name, fig)| {
            let p = dir.join(name);
            fig.write(&p)?;
            Ok(p)
        })
        .collect();
    written.into_iter().collect()
}

pub(super) fn estimate_report(s: &EstimateSummary, spec: &ModelSpec) -> String {
    let mut r = String::from("# MME estimate\n\n");
    r.push_str(&format!(
        "Assumed model: {} states ({}), corrected equations: {}; {} named terms. {} samples, sub-steps per sample interval: {}.\n\n",
        spec.linear.n_states(),
        spec.linear.state_names().join(", "),
        spec.linear.correction_names().join(", "),
        spec.terms.len(),
        s.samples,
        s.substeps
    ));
    if !s.x0_prior.is_empty() {
        let list: Vec<String> = s
            .x0_prior
            .iter()
            .map(|(name, p)| format!("{name}(t0) ~ N({}, {}²)", p.mean, p.std))
            .collect();
        r.push_str(&format!(
            "Initial-state prior (the model file's `[x0_prior]`, added to J at the first \
             sample of every record): {}; the other states start free.\n\n",
            list.join(", ")
        ));
    }
    r.push_str("| channel | noise variance R | residual variance | ratio |\n|---|---|---|---|\n");
    for (name, nv) in &s.noise_variance {
        r.push_str(&format!(
            "| {name} | {nv:.4e} | {:.4e} | {:.3} |\n",
            s.residual_variance[name], s.residual_to_noise[name]
        ));
    }
    r.push_str(
        "\n*Noise variance R*: the measurement noise assumed per channel. *Residual \
         variance*: mean square of measurement minus estimate. *Ratio*: residual / noise \
         variance; the covariance constraint chooses W so that it is about 1 (well below 1: \
         the estimate follows the noise; well above 1: W holds the correction back).\n\n",
    );
    r.push_str(&format!(
        "Noise variance: {}.\n\n",
        crate::words::noise_method(s.noise_method)
    ));
    // The model-free references the estimate was judged against (auto only).
    if !s.noise_references.is_empty() {
        let refs: Vec<String> = s
            .noise_references
            .iter()
            .map(|(name, (d, f))| {
                let floor = f.map_or("—".to_string(), |v| format!("{v:.4e}"));
                format!("{name}: second differences {d:.4e}, spectral floor {floor}")
            })
            .collect();
        r.push_str(&format!(
            "Model-free references (upper bounds of white noise; a likelihood estimate below \
             1 % of the lower is taken as the likelihood running to R → 0): {}.\n\n",
            refs.join("; ")
        ));
    }
    for w in &s.warnings {
        r.push_str(&format!("**Warning.** {w}\n\n"));
    }
    match &s.w_search {
        Some(w) => r.push_str(&format!(
            "W (weight of the model correction d̂, per unit time) chosen by the covariance \
             constraint: α = {:.4e}, ratio reached {:.4}; search {} after {} sweeps.\n",
            w.alpha,
            w.ratio,
            crate::words::termination(Some(w.termination)),
            w.evaluations
        )),
        None => r.push_str("W (weight of the model correction d̂) given by the user.\n"),
    }
    r.push_str(&format!(
        "\nW diagonal by corrected state: {}. MME cost J = {:.6e} (weighted misfit to the \
         data plus weighted size of d̂, at the optimum). Solve: {}.\n",
        crate::words::named_values(&s.w_by_correction),
        s.cost,
        crate::words::termination(s.report.termination)
    ));
    if !s.report.iterations.is_empty() {
        r.push_str(&format!(
            "Gauss–Newton iterations: {}.\n",
            s.report.iterations.len()
        ));
    }
    if let Some(p) = s.robust_passes {
        r.push_str(&format!(
            "\nRobust (Huber) estimate: {p} passes; residual variances are those of the \
             pseudo-observations.\n"
        ));
    }
    if !s.outliers.is_empty() {
        let screen = if s.robust_passes.is_some() {
            format!(
                "{} noise standard deviations (σ) from the robust estimate",
                mme_core::RobustConfig::default().report_sigma
            )
        } else {
            format!(
                "{OUTLIER_SCREEN_SIGMA} σ from the cubic through their neighbours (σ: the \
                 noise standard deviation, or the record's robust spread about those cubics \
                 when larger, as on signals with content near the Nyquist frequency)"
            )
        };
        r.push_str(&format!("\nOutliers: samples more than {screen}.\n\n"));
        r.push_str("| experiment | channel | sample | t (s) | value | σ out |\n|---|---|---|---|---|---|\n");
        for o in s.outliers.iter().take(50) {
            r.push_str(&format!(
                "| {} | {} | {} | {} | {} | {:.1} |\n",
                o.experiment, o.channel, o.sample, o.time, o.value, o.sigmas
            ));
        }
    }
    r.push_str(
        "\nFigures: `measured_*.svg` (measurement vs estimate), `states.svg`, \
         `d_vs_time.svg`, `d_*_vs_*.svg` (d̂ against each state and input), `w_curve.svg` \
         (residual-to-noise ratio against W; the chosen W where it crosses the target).\n",
    );
    r.push_str(&crate::html::figures_section(&s.files));
    r
}
