//! The human side of `mmenn discover`: `report.md` (verdict, named effects with their
//! equations and intervals, the gap tables, the search's decisions) and the before/after
//! figures. Nothing here computes a result.

use std::path::Path;

use nalgebra::DMatrix;
use sysid_core::Dataset;

use super::{DiscoverSummary, GapPair};
use crate::error::Result;
use crate::model_file::ModelSpec;
use crate::plot::{Figure, Panels, Series};

/// The simulated outputs of the assumed and the discovered model on one record.
pub(super) struct GapRun<'a> {
    /// The records (the first experiment is drawn).
    pub data: &'a Dataset,
    /// Their fit % and RMSE before and after, pooled over every record.
    pub gap: &'a GapPair,
    /// Assumed model's free-run outputs (`p × N`).
    pub before: DMatrix<f64>,
    /// Discovered model's free-run outputs (`p × N`).
    pub after: DMatrix<f64>,
}

/// `gap_<output>.svg` (estimation record) and `gap_validation_<output>.svg`, each with
/// a residual panel, and `d̂` against every state and input of round 1.
pub(super) fn figures(
    s: &DiscoverSummary,
    spec: &ModelSpec,
    estimation: &GapRun<'_>,
    validation: Option<&GapRun<'_>>,
    out: &Path,
) -> Result<Vec<String>> {
    let mut files = gap_figures(spec, estimation, "", "estimation", out)?;
    if let Some(v) = validation {
        files.extend(gap_figures(spec, v, "validation_", "validation", out)?);
    }
    if let Some(round) = s.rounds.first() {
        for p in &round.localisation.profiles {
            let mut series = vec![Series::points(
                "MME d̂ (assumed model)",
                p.points.iter().map(|q| q[0]).collect::<Vec<f64>>(),
                p.points.iter().map(|q| q[1]).collect::<Vec<f64>>(),
            )];
            series.extend(term_curve(s, &p.equation, &p.variable, &p.points));
            Figure {
                title: format!("d̂ of {} against {} (round 1)", p.equation, p.variable),
                x_label: p.variable.clone(),
                y_label: format!("d_{}", p.equation),
                series,
                bands: round
                    .floor_rms
                    .iter()
                    .take(1)
                    .map(|f| ("d̂ noise floor (RMS)".to_string(), *f))
                    .collect(),
            }
            .write(&out.join(format!("d_{}_vs_{}.svg", p.equation, p.variable)))?;
            files.push(format!("d_{}_vs_{}.svg", p.equation, p.variable));
        }
    }
    Ok(files)
}

/// Points of the overlaid curve of named terms.
const CURVE_POINTS: usize = 400;

/// The named terms (claimed or unconfirmed) of equation `equation` that read only
/// `variable` (and constants), summed and drawn over the range of the profile's points:
/// what the discovered model adds to that equation along that variable. `None` when no
/// such term reads `variable`. Terms that also read other variables cannot be drawn
/// against one of them, and the legend says the curve holds only the others.
fn term_curve(
    s: &DiscoverSummary,
    equation: &str,
    variable: &str,
    points: &[[f64; 2]],
) -> Option<Series> {
    let (lo, hi) = points
        .iter()
        .map(|q| q[0])
        .filter(|x| x.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), x| {
            (lo.min(x), hi.max(x))
        });
    if hi.partial_cmp(&lo) != Some(std::cmp::Ordering::Greater) {
        return None;
    }
    // (sign, parsed term, coefficient) of every term entering `equation`.
    let mut parts = Vec::new();
    let mut reads_variable = false;
    let mut left_out = 0usize;
    for e in s.effects.iter().chain(&s.unconfirmed) {
        let sign = if e.state == equation {
            1.0
        } else if e.into.as_deref() == Some(equation) {
            -1.0
        } else {
            continue;
        };
        match sysid_core::Expr::parse(&e.term, &[variable]) {
            Ok(expr) => {
                reads_variable |= sysid_core::Expr::parse(&e.term, &[]).is_err();
                parts.push((sign * e.coefficient, expr));
            }
            Err(_) => left_out += 1,
        }
    }
    if !reads_variable {
        return None;
    }
    let x: Vec<f64> = (0..CURVE_POINTS)
        .map(|k| lo + (hi - lo) * k as f64 / (CURVE_POINTS - 1) as f64)
        .collect();
    let y: Vec<f64> = x
        .iter()
        .map(|&v| parts.iter().map(|(c, g)| c * g.eval(&[v])).sum())
        .collect();
    let label = if left_out == 0 {
        "discovered terms".to_string()
    } else {
        format!(
            "discovered terms in {variable} alone ({left_out} reading other variables not drawn)"
        )
    };
    Some(Series::line(label, x, y).coloured(2))
}

/// The before/after figures of one record, files `gap_<tag><output>.svg`.
fn gap_figures(
    spec: &ModelSpec,
    run: &GapRun<'_>,
    tag: &str,
    which: &str,
    out: &Path,
) -> Result<Vec<String>> {
    let mut files = Vec::new();
    let exp = &run.data.experiments()[0];
    let t = exp.times();
    // The fit % in the legends pools every record (the gap's rule); the first is drawn.
    let records = run.data.experiments().len();
    let which = if records > 1 {
        format!("{which} record 1 of {records}; fit % over all")
    } else {
        format!("{which} record")
    };
    for (i, name) in spec.linear.output_names().iter().enumerate() {
        let fit = |g: &super::Gap| g.fit_percent.get(name).copied().unwrap_or(f64::NAN);
        let (fit_b, fit_a) = (fit(&run.gap.before), fit(&run.gap.after));
        let measured: Vec<f64> = exp.outputs().row(i).iter().copied().collect();
        let residual = |y: &DMatrix<f64>| -> Vec<f64> {
            measured
                .iter()
                .zip(y.row(i).iter())
                .map(|(m, v)| m - v)
                .collect()
        };
        let y_label = match spec.unit_of(name) {
            Some(u) => format!("{name} ({u})"),
            None => name.clone(),
        };
        let file = format!("gap_{tag}{name}.svg");
        Panels::time_with_residuals(
            format!("{name}: free-run simulation before and after discovery ({which})"),
            y_label,
            vec![
                Series::points("measured", t.clone(), measured.clone()),
                Series::line(
                    format!("assumed model (fit {fit_b:.1} %)"),
                    t.clone(),
                    run.before.row(i).iter().copied().collect::<Vec<f64>>(),
                ),
                Series::line(
                    format!("discovered model (fit {fit_a:.1} %)"),
                    t.clone(),
                    run.after.row(i).iter().copied().collect::<Vec<f64>>(),
                ),
            ],
            vec![
                Series::line("assumed model", t.clone(), residual(&run.before)).coloured(1),
                Series::line("discovered model", t.clone(), residual(&run.after)).coloured(2),
            ],
        )
        .write(&out.join(&file))?;
        files.push(file);
    }
    Ok(files)
}

fn gap_table(g: &GapPair) -> String {
    let mut s = String::from("| quantity | channel | before | after |\n|---|---|---|---|\n");
    for (k, v) in &g.before.fit_percent {
        s.push_str(&format!(
            "| free-run fit % | {k} | {v:.2} | {:.2} |\n",
            g.after.fit_percent.get(k).copied().unwrap_or(f64::NAN)
        ));
    }
    for (k, v) in &g.before.rmse {
        s.push_str(&format!(
            "| free-run RMSE | {k} | {v:.4e} | {:.4e} |\n",
            g.after.rmse.get(k).copied().unwrap_or(f64::NAN)
        ));
    }
    for (k, v) in &g.before.d_rms {
        s.push_str(&format!(
            "| d̂ RMS | {k} | {v:.4e} | {:.4e} |\n",
            g.after.d_rms.get(k).copied().unwrap_or(f64::NAN)
        ));
    }
    s
}

pub(super) fn report(s: &DiscoverSummary) -> String {
    let mut r = format!(
        "# Discovery\n\nVerdict: **{}**.\n\n",
        crate::words::verdict(s.verdict)
    );
    for w in &s.warnings {
        r.push_str(&format!("**Warning.** {w}\n\n"));
    }
    if let Some(round) = s.rounds.first() {
        r.push_str(&roles_line(&round.discovery.roles));
    }
    if !s.effects.is_empty() {
        r.push_str("| effect | equation | term | coefficient (free-run calibrated) | its 95 % CI | regression 95 % CI | share of d̂ | named by |\n|---|---|---|---|---|---|---|---|\n");
        for e in &s.effects {
            let ci = e
                .ci95_regression
                .map_or("—".to_string(), |c| format!("[{:.6}, {:.6}]", c[0], c[1]));
            let share = e.share_of_d.map_or("—".to_string(), |v| format!("{v:.2}"));
            let cal = e
                .ci95
                .map_or("—".to_string(), |c| format!("[{:.6}, {:.6}]", c[0], c[1]));
            r.push_str(&format!(
                "| {} | {} | `{}` | {:.6} | {cal} | {ci} | {share} | {} |\n",
                e.name,
                e.equations(),
                e.term,
                e.coefficient,
                e.named_by
            ));
        }
        r.push_str("\nThe regression on d̂ is shrunk by W, so coefficients are recalibrated by free-run simulation error; their 95 % interval is the calibration's (Gauss–Newton, inflated for residual colour), the regression's is of its own shrunk coefficient.\n");
        let adjusted: Vec<_> = s
            .effects
            .iter()
            .filter_map(|e| e.adjusts.as_ref())
            .collect();
        if !adjusted.is_empty() {
            r.push_str("\nLinear terms recalibrate entries of the assumed model:\n\n");
            for a in adjusted {
                r.push_str(&format!(
                    "- {}[{}, {}]: {:.6} → {:.6}{}\n",
                    a.matrix,
                    a.row,
                    a.column,
                    a.assumed,
                    a.effective,
                    if a.cancelled {
                        " (cancelled within its 95 % interval: the assumed linear term is \
                         replaced by the named effects)"
                    } else {
                        ""
                    }
                ));
            }
        }
    }
    if !s.unconfirmed.is_empty() {
        let left_structure = s.stand_in.as_ref().is_some_and(|st| !st.accepts())
            && s.judgement.as_ref().is_some_and(|j| j.accepts());
        if left_structure {
            r.push_str("These terms improved the model (they are in `model.discovered.toml`) and bring its free-run cost within the reference, but MME's remaining correction is still predictable from the states and inputs (the flexible stand-in below), so they are **not claimed** as the missing physics — something outside the catalogue may be at work:\n\n");
        } else {
            r.push_str(&format!(
                "These terms improved the model (they are in `model.discovered.toml`) but left its free-run cost above {:.4} × the noise level, so they are **not claimed** as the missing physics — something outside the catalogue may be at work, or the data cannot tell where the effect acts:\n\n",
                s.claim_bound
            ));
        }
        for e in &s.unconfirmed {
            let support = match (e.ci95, e.interval_excludes_zero()) {
                (Some([lo, hi]), Some(true)) => {
                    format!(" — 95 % interval [{lo:.6}, {hi:.6}] excludes 0")
                }
                (Some([lo, hi]), _) => format!(
                    " — 95 % interval [{lo:.6}, {hi:.6}] **includes 0**: the data do not support this term"
                ),
                _ => String::new(),
            };
            r.push_str(&format!(
                "- {} in {}: `{}` × {:.6}{support}\n",
                e.name,
                e.equations(),
                e.term,
                e.coefficient
            ));
        }
        r.push_str("\nThe intervals are the free-run calibration's (Gauss–Newton, inflated for the colour of the residual). Far above the noise level every term that lowers the cost passes the search's step test; a term whose interval includes zero is one the data do not pin down, so read those as shape-fitting, not as physics.\n");
    }
    if let Some(a) = &s.ambiguity {
        r.push_str(&format!(
            "**Ambiguous.** The scale of {} is not fixed by any measurement or known equation, so several sets of terms can explain the measured outputs. Two sets reach the noise level (claim bound {:.4}), and neither is claimed:\n\n- the search's: {} (judged free-run cost {:.4});\n- without its terms touching {}: {} (judged free-run cost {:.4}).\n\nMeasuring {} (or fixing its equation) would decide between them.\n\n",
            a.free_states.join(", "),
            s.claim_bound,
            code_list(&a.named),
            a.named_cost,
            a.free_states.join(", "),
            code_list(&a.alternative),
            a.alternative_cost,
            a.free_states.join(", "),
        ));
    }
    r.push_str(&judgement_section(s));
    r.push_str("\n## Gap on the estimation data (free-run simulation; d̂ from MME)\n\n");
    r.push_str(&gap_table(&s.gap));
    if let Some(v) = &s.validation_gap {
        r.push_str("\n## Gap on the validation data (free-run simulation)\n\n");
        r.push_str(&gap_table(v));
    }
    for (i, round) in s.rounds.iter().enumerate() {
        r.push_str(&format!(
            "\n## Round {}\n\nThe regression on d̂ in this round: {} (a proposal; the verdict above is the workflow's, judged on the free run).\n\n",
            i + 1,
            match round.discovery.verdict {
                discovery::Verdict::Found => "named terms explain d̂ beyond its noise floor",
                discovery::Verdict::None => "d̂ within its noise floor",
                discovery::Verdict::Unexplained => "d̂ above its floor, not explained by the catalogue",
            }
        ));
        if let Some(why) = &round.rejected {
            r.push_str(&format!(
                "The terms this round proposed were **not accepted**: {why}.\n\n"
            ));
        }
        for st in &round.refinement {
            r.push_str(&format!(
                "- free-run search: {} {} (`{}`), cost {:.4} → {:.4}, statistic {:.2} vs {:.2}\n",
                st.action, st.effect, st.term, st.cost[0], st.cost[1], st.statistic, st.threshold
            ));
        }
        for w in &round.localisation.windows {
            r.push_str(&format!(
                "- disagreement in {} ({:?}) from {:.2} s to {:.2} s\n",
                w.channel, w.source, w.start, w.end
            ));
        }
        for reg in round.localisation.regions.iter().take(10) {
            r.push_str(&format!(
                "- d_{} is significant for {} in [{:.3}, {:.3}] (mean {:.3e})\n",
                reg.equation, reg.variable, reg.lo, reg.hi, reg.mean_d
            ));
        }
    }
    r.push_str(&format!("\nThe augmented model is `{}`.\n", s.model));
    r
}

/// The roles the catalogue was matched against: which laws may enter which equation.
fn roles_line(roles: &[(String, discovery::Role)]) -> String {
    format!(
        "Roles of the states (a friction law enters only a velocity's equation, an orifice or \
         overflow only a level's; inferred from `A`, the units and the names, or given in the \
         model file's `[roles]` table): {}.\n\n",
        crate::words::role_list(roles.iter().map(|(s, r)| (s, r)))
    )
}

/// `a, b` as inline code: `` `a`, `b` `` (`none` when empty).
fn code_list(items: &[String]) -> String {
    if items.is_empty() {
        return "none".into();
    }
    items
        .iter()
        .map(|t| format!("`{t}`"))
        .collect::<Vec<_>>()
        .join(", ")
}

/// How the verdict was judged: the statistic, its bootstrap reference and the passengers.
fn judgement_section(s: &DiscoverSummary) -> String {
    let mut r = String::new();
    match &s.judgement {
        Some(j) => {
            r.push_str(&format!(
                "\n## How the verdict was judged\n\nThe judged statistic is the free-run cost J = (1/M) Σ r²/R of the model on the records that judged the search (held-out or validation records; 1 = the noise level), with its initial states re-fitted there. A right model does not score exactly 1: the pipeline estimates initial states and calibrates coefficients. So J is compared with its **reference distribution under the same pipeline**: the model itself simulated (Dormand–Prince, rtol 1e-10) with noise of variance R, and the whole judging protocol rerun on each of B = {} draws ({} failed).\n\n| statistic J | reference mean | reference sd | threshold ({:.0} % quantile, scaled χ²) | p-value | accepted |\n|---|---|---|---|---|---|\n| {:.4} | {:.4} | {:.4} | {:.4} | {:.3} | {} |\n",
                j.draws,
                j.failed,
                100.0 * j.level,
                j.statistic,
                j.mean,
                j.sd,
                j.threshold,
                j.p_value,
                if j.statistic <= j.threshold { "yes" } else { "no" },
            ));
            if let Some(q) = &j.structure {
                r.push_str(&format!(
                    "
What remains must also look like noise: the **structure** of the judged free-run residual, the Ljung–Box statistic Q (squared autocorrelations at lags 1–{} per channel and record; about {} for white noise), compared with Q on the same draws (a right model's free-run residual is not exactly white either). An effect the catalogue terms only imitate leaves its shape in the residual even when J is small.

| statistic Q | reference mean | threshold ({:.0} % quantile, scaled χ²) | p-value | accepted |
|---|---|---|---|---|
| {:.2} | {:.2} | {:.2} | {:.3} | {} |
",
                    q.lags,
                    q.lags,
                    100.0 * q.level,
                    q.statistic,
                    q.reference.iter().sum::<f64>() / q.reference.len().max(1) as f64,
                    q.threshold,
                    q.p_value,
                    if q.statistic <= q.threshold { "yes" } else { "no" },
                ));
            }
            r.push_str(&format!(
                "
Verdict test: {}.
",
                if j.accepts() {
                    "both within their references"
                } else {
                    "not within the reference (what remains is more, or other, than noise)"
                }
            ));
        }
        None => {
            if let Some(note) = &s.judge_note {
                r.push_str(&format!(
                    "\n## How the verdict was judged\n\n{note}; the fixed bound {:.4} decided.\n",
                    s.claim_bound
                ));
            }
        }
    }
    r.push_str(&stand_in_section(s));
    if !s.passengers.is_empty() {
        r.push_str("\nTerms the search had kept but the same test showed unneeded (dropped; the rest recalibrated on the whole estimation records):\n\n");
        for p in &s.passengers {
            r.push_str(&format!("- {p}\n"));
        }
    }
    r
}

/// The flexible stand-in on `d̂` (see `discovery::standin`): statistic, reference, decision.
fn stand_in_section(s: &DiscoverSummary) -> String {
    match (&s.stand_in, &s.stand_in_note) {
        (Some(st), _) => format!(
            "
A verdict that nothing is left also needs MME's remaining correction d̂ (with the final model) to be **unpredictable**: a flexible stand-in (one-variable Gaussian bumps on every state and input, plus a joint radial layer, ridge-penalised) is compared with the model's own terms plus linear corrections by blocked 5-fold cross-validation, and the gain is the share of the held-out error the stand-in removes (per corrected equation: {}). A right model's gain is not exactly 0 — MME's states and d̂ share the noise — so it is compared with the gain on B = {} draws ({} failed) of the model simulated with noise and re-estimated by MME at the same W and R.

| statistic (largest gain) | reference mean | reference sd | threshold (max of the {:.1} % normal quantile and {:.2}) | accepted |
|---|---|---|---|---|
| {:.4} | {:.4} | {:.4} | {:.4} | {} |
",
            st.per_equation
                .iter()
                .map(|g| format!("{g:.4}"))
                .collect::<Vec<_>>()
                .join(", "),
            st.draws,
            st.failed,
            100.0 * st.level,
            st.min_gain,
            st.statistic,
            st.mean,
            st.sd,
            st.threshold,
            if st.accepts() {
                "yes"
            } else {
                "no: structure remains"
            },
        ),
        (None, Some(note)) => format!("\nThe flexible stand-in on d̂ did not decide: {note}.\n"),
        (None, None) => String::new(),
    }
}
