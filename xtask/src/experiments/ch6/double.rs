//! Thesis ch. 6 §6.3 (Tables 6-4, 6-5 and Fig. 6.4 analogue): condition monitoring of the
//! double pendulum at five joint-damping classes. Per class and noise seed: MME with the
//! ignorance model gives `d̂ = [ω̇1, ω̇2]`; 1-node and 6-node networks learn
//! `(x̂, u) → d̂`, kept when their training MSE is under a cut-off; their weights (raw or
//! canonicalised) or the regression update's coefficients are the features.

use anyhow::{Context, Result};
use mmenn::condmon::{
    ComponentSelection, NamedFeatures, Pca, Standardiser, canonical_weights, physical_features,
    raw_weights, stack,
};
use mmenn::estimate::{EstimateOptions, estimate_spec, mme_config};
use mmenn::fit::training_pairs;
use mmenn::mme_core::{UpdateConfig, update_model};
use mmenn::nn::{ErrorSpace, LmConfig, Mlp, train_lm};
use mmenn::plants::{
    DoublePendulum, DoublePendulumParams, JOINT_DAMPING_CLASSES, Recipe, SimulationRequest,
    simulate_system,
};
use mmenn::plot::{Figure, Series};
use mmenn::simulate::assumed_model_spec;
use rayon::prelude::*;

use super::{FeatureSet, error_rows, new_table};
use crate::experiments::{Ctx, FIT_SEED, Job, Mode, Outcome, median};

/// Table id.
pub const TABLE: &str = "ch6_double_pendulum_condition";

/// Hidden units of the feature networks (thesis: 6-node, sized for the MME/NN model, and
/// 1-node).
const HIDDEN: [usize; 2] = [1, 6];

/// A network is kept when its normalised training MSE is at most this many times the
/// median of its size over all records (the thesis kept networks under a fixed MSE; a
/// multiple of the median is the scale-free version of that rule).
const CUTOFF: f64 = 2.0;

/// Noise seeds (one record and one network initialisation of each size per seed) per
/// damping class.
fn seeds(mode: Mode) -> u64 {
    match mode {
        Mode::Quick => 4,
        Mode::Full => 12,
    }
}

/// The job.
pub fn job() -> Job {
    Job {
        name: "ch6 condition monitoring (double pendulum joint damping)".into(),
        group: "ch6",
        tables: vec![TABLE],
        cost: 60,
        run: Box::new(run),
    }
}

/// What one record yields.
struct Record {
    label: usize,
    /// Per size in [`HIDDEN`]: the trained network and its normalised training MSE.
    nets: Vec<(Mlp, f64)>,
    physical: NamedFeatures,
}

fn record(label: usize, c2: f64, seed: u64) -> Result<Record> {
    let name = format!("double pendulum c2 = {c2}, noise seed {seed}");
    let sim = simulate_system(&SimulationRequest {
        system: "double_pendulum".into(),
        recipe: Recipe::Train,
        noise_variance: None,
        fs: None,
        seed,
        params: vec![("c2".into(), c2)],
        duration: None,
    })
    .with_context(|| format!("simulating {name}"))?;
    let spec = assumed_model_spec(&sim);
    let out = estimate_spec(
        &spec,
        &sim.data,
        &mme_config(&spec, &EstimateOptions::default()),
    )
    .with_context(|| format!("MME on {name}"))?;
    // Physical features: the regression update's coefficients of d̂ on [x̂, u] (thesis
    // §4.3.3) — the linearised model's stiffness, damping and input rows.
    let up = update_model(
        &spec.linear,
        &sim.data,
        &out.estimate,
        &UpdateConfig::default(),
    )
    .with_context(|| format!("regression update on {name}"))?;
    let named: Vec<(String, Vec<f64>)> = up
        .regressions
        .iter()
        .flat_map(|r| {
            r.coefficients
                .iter()
                .map(move |c| (format!("{}~{}", r.correction, c.regressor), vec![c.value]))
        })
        .collect();
    let refs: Vec<(&str, &[f64])> = named
        .iter()
        .map(|(n, v)| (n.as_str(), v.as_slice()))
        .collect();
    let physical = physical_features(&refs)?;
    let (x, d) = training_pairs(&out.estimate, &sim.data, 0.02);
    let mut nets = Vec::new();
    for h in HIDDEN {
        let mut net = Mlp::for_data(&x, &d, &[h], FIT_SEED + seed)?;
        train_lm(&mut net, &x, &d, &LmConfig::default(), None)?;
        let mse = net.mse(&x, &d, ErrorSpace::Normalised)?;
        nets.push((net, mse));
    }
    Ok(Record {
        label,
        nets,
        physical,
    })
}

/// Damping ratios of the linearised model's two modes at joint damping `c2` (the other
/// parameters at their defaults), lowest mode first.
fn damping_ratios(c2: f64) -> Result<Vec<f64>> {
    let p = DoublePendulum::new(DoublePendulumParams {
        c2,
        ..DoublePendulumParams::default()
    })?;
    let a = p.linearised_model()?.a().clone();
    let mut modes: Vec<(f64, f64)> = a
        .complex_eigenvalues()
        .iter()
        .filter(|l| l.im > 0.0)
        .map(|l| {
            let w = l.re.hypot(l.im);
            (w, -l.re / w)
        })
        .collect();
    modes.sort_by(|a, b| a.0.total_cmp(&b.0));
    Ok(modes.into_iter().map(|(_, z)| z).collect())
}

/// Fig. 6.4 analogue: the first two principal components (standardised features, PCA on
/// every sample) coloured by class.
fn pca_figure(title: &str, set: &FeatureSet) -> Result<Figure> {
    let x = stack(&set.features)?;
    let z = Standardiser::fit(x.values())?.transform(x.values())?;
    let pca = Pca::fit(&z, ComponentSelection::Fixed(2))?;
    let s = pca.transform(&z)?;
    let ratio = pca.explained_variance_ratio();
    let series = JOINT_DAMPING_CLASSES
        .iter()
        .enumerate()
        .map(|(k, c)| {
            let rows: Vec<usize> = (0..set.labels.len())
                .filter(|&i| set.labels[i] == k)
                .collect();
            Series::points(
                format!("c2 = {c}"),
                rows.iter().map(|&i| s[(i, 0)]).collect::<Vec<f64>>(),
                rows.iter().map(|&i| s[(i, 1)]).collect::<Vec<f64>>(),
            )
        })
        .collect();
    let pct = |i: usize| ratio.get(i).map_or(f64::NAN, |r| 100.0 * r);
    Ok(Figure {
        title: title.to_string(),
        x_label: format!("1st principal component ({:.0} % of the variance)", pct(0)),
        y_label: format!("2nd principal component ({:.0} % of the variance)", pct(1)),
        series,
        bands: vec![],
    })
}

fn run(ctx: &Ctx) -> Result<Outcome> {
    let seeds = seeds(ctx.mode);
    let jobs: Vec<(usize, f64, u64)> = JOINT_DAMPING_CLASSES
        .iter()
        .enumerate()
        .flat_map(|(label, c)| (1..=seeds).map(move |s| (label, *c, s)))
        .collect();
    let records = jobs
        .par_iter()
        .map(|(label, c, seed)| record(*label, *c, *seed))
        .collect::<Result<Vec<_>>>()?;
    let mut sets: Vec<FeatureSet> = Vec::new();
    let mut kept_note = Vec::new();
    for (i, h) in HIDDEN.iter().enumerate() {
        let mut mses: Vec<f64> = records.iter().map(|r| r.nets[i].1).collect();
        let cut = CUTOFF * median(&mut mses);
        let kept: Vec<&Record> = records.iter().filter(|r| r.nets[i].1 <= cut).collect();
        kept_note.push(format!(
            "{h}-node: {} of {} networks kept (normalised training MSE ≤ {})",
            kept.len(),
            records.len(),
            crate::table::format_value(cut, 3)
        ));
        let labels: Vec<usize> = kept.iter().map(|r| r.label).collect();
        sets.push(FeatureSet {
            name: format!("raw weights, {h}-node net"),
            labels: labels.clone(),
            features: kept.iter().map(|r| raw_weights(&r.nets[i].0)).collect(),
        });
        sets.push(FeatureSet {
            name: format!("canonical weights, {h}-node net"),
            labels,
            features: kept
                .iter()
                .map(|r| canonical_weights(&r.nets[i].0))
                .collect::<mmenn::condmon::Result<Vec<_>>>()?,
        });
    }
    sets.push(FeatureSet {
        name: "physical (regression update Θ of d̂ on x̂, u)".into(),
        labels: records.iter().map(|r| r.label).collect(),
        features: records.iter().map(|r| r.physical.clone()).collect(),
    });
    let n_min = sets.iter().map(|s| s.labels.len()).min().unwrap_or(0);
    let mut table = new_table(
        TABLE,
        "Ch. 6 (Tables 6-4, 6-5 analogue): joint-damping classification error, double \
         pendulum, leave-one-out",
        n_min,
    );
    for set in &sets {
        error_rows(&mut table, set)?;
    }
    let ratios = JOINT_DAMPING_CLASSES
        .iter()
        .map(|c| {
            damping_ratios(*c).map(|z| {
                let z: Vec<String> = z.iter().map(|v| format!("{v:.3}")).collect();
                format!("c2 = {c}: ζ = {}", z.join(" / "))
            })
        })
        .collect::<Result<Vec<_>>>()?;
    table.note(format!(
        "{} records: {seeds} noise seeds × 5 joint-damping classes c2 ∈ {{0.024, 0.027, 0.030, \
         0.033, 0.036}} N·m·s/rad (the thesis printed \".24 … .36\" with lost digits; read as \
         0.024 … 0.036, ±20 % around the ch. 4/5 system's c2 = 0.03 that the 6-node MME/NN \
         model was sized on; for these light rods that is a strongly damped joint — damping \
         ratios of the linearised modes, slow / fast: {}), double_pendulum training recipe \
         (20 s at 100 Hz, angle noise 1e-6 rad²), ignorance model. Networks (tanh, LM, seed \
         {FIT_SEED} + noise seed) map (x̂, u) to d̂; {}. Physical features: the 10 \
         coefficients of the regression update (one record each, no cut-off). Chance level \
         is 80 %. Standardised features; PCA keeps 95 % of the variance, refitted in every \
         fold.",
        records.len(),
        ratios.join("; "),
        kept_note.join("; ")
    ));
    let mut out = Outcome {
        tables: vec![table],
        ..Outcome::default()
    };
    for (name, idx, what) in [
        (
            "ch6_double_pendulum_pca_raw_1node",
            0,
            "raw weights of the 1-node networks",
        ),
        (
            "ch6_double_pendulum_pca_canonical_1node",
            1,
            "canonical weights of the 1-node networks",
        ),
        (
            "ch6_double_pendulum_pca_physical",
            4,
            "regression-update coefficients",
        ),
    ] {
        if let Some(set) = sets.get(idx) {
            let fig = pca_figure(
                &format!(
                    "Double pendulum joint damping: first 2 PCs of the {what} (thesis Fig. 6.4)"
                ),
                set,
            )?;
            out.figures.push(ctx.figure(name, &fig)?);
        }
    }
    Ok(out)
}
