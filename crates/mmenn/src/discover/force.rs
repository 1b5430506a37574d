//! `mmenn discover` on a model file with a `[mechanics]` (mass-matrix) part: missing
//! effects are named per joint as generalized forces ([`discovery::force`]); MME (mme-core
//! on the physical model) gives `d̂`, the force terms are calibrated by free-run output
//! error, and the discovered model is the input file plus generalized-force `[[terms]]`.

use std::collections::BTreeMap;
use std::path::Path;

use discovery::Verdict;
use discovery::force::{
    ForceConfig, ForceEffect, ForceOutcome, ForceProblem, ForceTerm, WIDTH_RANGE,
};
use sysid_core::{Dataset, Estimation, PhysicalModel};

use super::{
    DISCOVER_TASK, DiscoverOptions, DiscoverSummary, GapPair, NamedEffect, free_run_gap_of,
    write_outputs,
};
use crate::error::{MmennError, Result};
use crate::estimate::mme_config;
use crate::model_file::{ModelSpec, NoiseVariance, ParameterEntry, TermEntry, write_model};
use crate::progress::{Progress, ProgressSink};

/// Steps reported: MME, the force-space search, the free runs of the report.
const STEPS: usize = 3;

/// The unit of joint `q`'s generalized force from the coordinate's unit: a torque for an
/// angle, a force for a length.
fn force_unit(spec: &ModelSpec, q: &str) -> Option<String> {
    match spec.units.get(q)?.as_str() {
        "rad" | "deg" => Some("N*m".into()),
        "m" | "mm" | "cm" => Some("N".into()),
        _ => None,
    }
}

/// The model file's physical model, errors naming the step.
fn physical(spec: &ModelSpec) -> Result<PhysicalModel> {
    spec.physical_model().map_err(|problem| MmennError::Model {
        path: "<model>".into(),
        line: None,
        column: None,
        problem,
    })
}

/// The spec plus force terms: with `free`, each term is `parameter·(term)` with its
/// coefficient a free parameter and every other parameter fixed (the calibration's
/// model); without, the term with its coefficient (the written model).
fn with_forces(spec: &ModelSpec, terms: &[ForceTerm], free: bool) -> ModelSpec {
    let mut out = spec.clone();
    if free {
        for p in &mut out.parameters {
            p.estimation = Estimation::Fixed;
        }
    }
    for t in terms {
        if free {
            out.parameters.push(ParameterEntry {
                name: t.parameter.clone(),
                value: t.coefficient,
                unit: None,
                bounds: None,
                estimation: Estimation::Free,
                sigma: None,
            });
            if let Some((name, start)) = &t.width {
                out.parameters.push(ParameterEntry {
                    name: name.clone(),
                    value: *start,
                    unit: None,
                    bounds: Some((start / WIDTH_RANGE, start * WIDTH_RANGE)),
                    estimation: Estimation::Free,
                    sigma: None,
                });
            }
        }
        out.terms.push(TermEntry {
            state: t.state.clone(),
            into: None,
            effect: t.effect.clone(),
            term: if free {
                format!("{}*({})", t.parameter, t.term)
            } else {
                t.term.clone()
            },
            coefficient: if free { 1.0 } else { t.coefficient },
        });
    }
    out
}

/// A force effect as `discovery.json` reports it.
fn named(spec: &ModelSpec, coords: &[String], e: &ForceEffect) -> NamedEffect {
    let unit = coords
        .get(e.joint)
        .and_then(|q| force_unit(spec, q))
        .and_then(|force| {
            let vars: Vec<Option<&str>> = if e.term.contains(&e.state) {
                vec![spec.units.get(&e.state).map(String::as_str)]
            } else {
                vec![spec.units.get(&coords[e.joint]).map(String::as_str)]
            };
            let term = e.effect.term_unit(&vars)?;
            Some(discovery::coefficient_unit(&force, &term))
        });
    NamedEffect {
        name: e.effect.name().to_string(),
        state: e.state.clone(),
        into: None,
        term: e.term.clone(),
        coefficient: e.coefficient,
        ci95: e.ci95(),
        ci95_regression: None,
        share_of_d: Some(e.share_of_force),
        named_by: "regression on the generalized force M(q̂)·d̂, kept by free-run calibration".into(),
        parameters: e.parameters.iter().cloned().collect::<BTreeMap<_, _>>(),
        adjusts: None,
        unit,
        reading: Some(format!(
            "{} (a force on joint {})",
            e.reading(),
            e.joint + 1
        )),
    }
}

/// Run force-space discovery and write `discovery.json`, `model.discovered.toml`,
/// `report.md` and the free-run figures into `out`.
pub(super) fn run_force_discover(
    original: &ModelSpec,
    data: &Dataset,
    val: Option<&Dataset>,
    opts: &DiscoverOptions,
    out: &Path,
    progress: &dyn ProgressSink,
) -> Result<DiscoverSummary> {
    original.refuse_acquisition("discover", Path::new("<model>"))?;
    original.refuse_uncorrected("discover", Path::new("<model>"))?;
    let step = |done: usize, stage: &str| {
        progress.report(&Progress::new(DISCOVER_TASK, done, Some(STEPS)).with_stage(stage));
    };
    step(0, "MME with the assumed model");
    let outcome = search(original, data, val, opts, &step, progress);
    progress.finish(DISCOVER_TASK);
    let (outcome, first, first_mme) = outcome?;

    let coords = original
        .mechanics
        .as_ref()
        .map(|m| m.q.clone())
        .unwrap_or_default();
    let kept: Vec<ForceTerm> = outcome
        .effects
        .iter()
        .map(|e| ForceTerm {
            state: e.state.clone(),
            effect: e.effect.name().to_string(),
            term: e.term.clone(),
            parameter: String::new(),
            coefficient: e.coefficient,
            width: None,
        })
        .collect();
    let spec = with_forces(original, &kept, false);
    let assumed = physical(original)?;
    let discovered = physical(&spec)?;
    let window = opts.workflow.x0_window;
    let lin = &original.linear;
    let (before, y_before) = free_run_gap_of(&assumed, lin, data, window, true)?;
    let (after, y_after) = free_run_gap_of(&discovered, lin, data, window, true)?;
    let validation_runs = match val {
        Some(v) => {
            let (b, yb) = free_run_gap_of(&assumed, lin, v, window, true)?;
            let (a, ya) = free_run_gap_of(&discovered, lin, v, window, true)?;
            Some((
                GapPair {
                    before: b,
                    after: a,
                },
                yb,
                ya,
            ))
        }
        None => None,
    };
    write_model(&out.join("model.discovered.toml"), &spec)?;

    let effects = outcome
        .effects
        .iter()
        .map(|e| named(original, &coords, e))
        .collect();
    let unconfirmed = outcome
        .unconfirmed
        .iter()
        .map(|e| named(original, &coords, e))
        .collect();
    let mut warnings = outcome.notes.clone();
    if let Some([b, a]) = outcome.validation_cost {
        warnings.push(format!(
            "validation free-run cost (1/M) Σ r²/R: {b:.4e} with the assumed model, {a:.4e} \
             with the discovered forces"
        ));
    }
    let summary = DiscoverSummary {
        verdict: outcome.verdict,
        effects,
        unconfirmed,
        // The noise-level bound the verdict was judged by: the assumed model's when
        // nothing was kept, the final model's when forces were kept.
        claim_bound: outcome
            .assumed_cost
            .or(outcome.found_cost)
            .map_or(f64::NAN, |c| c[1]),
        judgement: None,
        passengers: outcome
            .eliminated
            .iter()
            .map(|(e, why)| {
                format!(
                    "{} on joint {} ({}): {} × {:.4e}: {why}",
                    e.effect.name(),
                    e.joint + 1,
                    e.state,
                    e.term,
                    e.coefficient
                )
            })
            .collect(),
        judge_note: Some(format!(
            "force-space discovery (mass-matrix model): a force is kept when its 95 % interval \
             excludes zero and, with validation records, the kept forces lower the validation \
             free-run cost; they are claimed when they bring the free-run cost on the \
             estimation records to the fixed noise-level bound (no bootstrap judge){}",
            match (outcome.found_cost, outcome.assumed_cost) {
                (Some([c, _]), _) => format!(
                    ". With the kept forces that cost (the calibration's s², noise-weighted) \
                     is {c:.4} × the noise level"
                ),
                (None, Some([c, _])) => format!(
                    ". With no force kept, the assumed model's cost is {c:.4} × the noise level"
                ),
                (None, None) => String::new(),
            }
        )),
        gap: GapPair { before, after },
        validation_gap: validation_runs.as_ref().map(|(g, _, _)| g.clone()),
        ambiguity: None,
        stand_in: None,
        stand_in_note: None,
        warnings,
        degradation: None,
        model: "model.discovered.toml".into(),
        rounds: Vec::new(),
        mme_termination: first.report.termination,
        mme_estimate: Some(first_mme),
        generalized_forces: true,
    };
    let val_outputs = match (val, validation_runs) {
        (Some(v), Some((_, b, a))) => Some((v, b, a)),
        _ => None,
    };
    let text = report(&summary, &outcome);
    write_outputs(
        &summary,
        &spec,
        (data, y_before, y_after),
        val_outputs,
        &text,
        out,
    )?;
    Ok(summary)
}

/// MME with the assumed model, then the force-space search.
fn search(
    original: &ModelSpec,
    data: &Dataset,
    val: Option<&Dataset>,
    opts: &DiscoverOptions,
    step: &dyn Fn(usize, &str),
    progress: &dyn ProgressSink,
) -> Result<(
    ForceOutcome,
    sysid_core::MmeEstimate,
    crate::fit::MmeConvergence,
)> {
    let model = physical(original)?;
    // MME's own steps (W trials, iterations) as the note of step 1's report.
    let frame =
        || Progress::new(DISCOVER_TASK, 0, Some(STEPS)).with_stage("MME with the assumed model");
    let steps = crate::progress::MmeProgress::within(progress, &frame);
    let first_out = crate::estimate::estimate_spec_observed(
        original,
        data,
        &mme_config(original, &opts.estimate),
        &steps,
    )?;
    let first_mme =
        crate::fit::MmeConvergence::of(crate::fit::MmeStage::Training, &first_out, data);
    let first = first_out.estimate;
    step(1, "generalized forces: proposal and free-run calibration");
    let noise = match &original.noise_variance {
        NoiseVariance::Given(v) => v.clone(),
        NoiseVariance::Auto => first.noise_variance.clone(),
    };
    let build = |terms: &[ForceTerm]| physical(&with_forces(original, terms, true));
    let problem = ForceProblem {
        model: &model,
        estimate: &first,
        data,
        validation: val,
        noise_variance: &noise,
        noise_given: matches!(original.noise_variance, NoiseVariance::Given(_)),
        build: &build,
    };
    let config = ForceConfig {
        x0_window: opts.workflow.x0_window,
        trim_fraction: opts.workflow.trim_fraction,
        // One account for the whole job: MME above and every calibration draw on it.
        calibration: sysid_core::GreyboxOptions {
            budget: opts.estimate.budget.clone(),
            ..ForceConfig::default().calibration
        },
        ..ForceConfig::default()
    };
    let outcome = discovery::force::run_forces(&problem, &config)?;
    step(2, "free runs of the assumed and discovered models");
    Ok((outcome, first, first_mme))
}

/// `report.md` of a force-space run.
fn report(s: &DiscoverSummary, o: &ForceOutcome) -> String {
    let mut r = format!(
        "# Discovery (generalized forces)\n\nVerdict: **{}**.\n\nThe model has a mass \
         matrix, so MME's acceleration correction was mapped to joint forces, `τ̂ = M(q̂)·d̂`, \
         and each joint was explained by catalogue forces of its own rate only.\n\n",
        crate::words::discover_verdict(s)
    );
    for w in &s.warnings {
        r.push_str(&format!("**Note.** {w}\n\n"));
    }
    let rms: Vec<String> = o
        .proposals
        .iter()
        .zip(&o.force_rms)
        .map(|(p, v)| format!("{} {v:.4e}", p.state))
        .collect();
    r.push_str(&format!("RMS of τ̂ per joint: {}.\n\n", rms.join(", ")));
    let table = |title: &str, list: &[NamedEffect], r: &mut String| {
        if list.is_empty() {
            return;
        }
        r.push_str(&format!(
            "{title}\n\n| effect | joint equation | term | coefficient | 95 % CI | unit | reading |\n|---|---|---|---|---|---|---|\n"
        ));
        for e in list {
            let ci = e.ci95.map_or("—".to_string(), |c| {
                format!("[{:.4e}, {:.4e}]", c[0], c[1])
            });
            r.push_str(&format!(
                "| {} | {} | `{}` | {:.4e} | {ci} | {} | {} |\n",
                e.name,
                e.state,
                e.term,
                e.coefficient,
                e.unit.as_deref().unwrap_or("—"),
                e.reading.as_deref().unwrap_or("")
            ));
        }
        r.push('\n');
    };
    table("Named forces:", &s.effects, &mut r);
    if !o.shapes.is_empty() {
        r.push_str(
            "Shape of each smooth Coulomb law (free-run cost on the estimation records):\n\n",
        );
        for n in &o.shapes {
            r.push_str(&format!("- {n}\n"));
        }
        r.push('\n');
    }
    table(
        "Not claimed (not confirmed on validation, or short of the noise level):",
        &s.unconfirmed,
        &mut r,
    );
    if !s.passengers.is_empty() {
        r.push_str("Eliminated:\n\n");
        for p in &s.passengers {
            r.push_str(&format!("- {p}\n"));
        }
        r.push('\n');
    }
    if s.verdict == Verdict::None {
        r.push_str("No force was named.\n\n");
    }
    if let Some(note) = &s.judge_note
        && s.claim_bound.is_finite()
    {
        r.push_str(&format!(
            "## How the verdict was judged\n\n{note}; the bound is {:.4}.\n",
            s.claim_bound
        ));
    }
    r
}
