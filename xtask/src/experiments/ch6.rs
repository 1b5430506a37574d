//! Thesis ch. 6 (Tables 6-2…6-5 analogue): condition monitoring of the cubic
//! mass–spring–damper at damping c ∈ {0.1, 0.15, 0.2} N·s/m. Per class and noise seed:
//! MME gives `d̂`, a network learns `(x̂, v̂, u) → d̂`; its weights (raw, as in the thesis, or
//! canonicalised) or named physical coefficients are the features; cross-validated error %
//! of LDA, QDA, k-NN and naive Bayes, with and without PCA.

use anyhow::{Context, Result};
use condmon::{
    ClassifierSpec, CvConfig, CvScheme, NamedFeatures, Preprocessing, canonical_weights,
    error_table, physical_features, raw_weights, stack,
};
use mmenn::estimate::{EstimateOptions, estimate_spec, mme_config};
use mmenn::fit::training_pairs;
use mmenn::nn::{LmConfig, Mlp, train_lm};
use mmenn::simulate::assumed_model_spec;
use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;

use super::{Ctx, FIT_SEED, Job, Outcome};
use crate::data::{MSD_CLASSES, find, msd_class_name};
use crate::table::{Column, Table, Tolerance};

/// Table id.
pub const TABLE: &str = "ch6_msd_condition";

/// Hidden units of the feature networks (the thesis used 1-node and 3- or 6-node nets).
const HIDDEN: [usize; 2] = [1, 3];

/// The job.
pub fn job() -> Job {
    Job {
        name: "ch6 condition monitoring (MSD damping classes)".into(),
        group: "ch6",
        tables: vec![TABLE],
        cost: 3,
        run: Box::new(run),
    }
}

/// Features of one record.
struct Sample {
    label: usize,
    nets: Vec<Mlp>,
    physical: NamedFeatures,
}

/// Least-squares coefficients of `d̂ ≈ a·v̂ + b·x̂³` (for the truth: a = −c/m, b = −k/m).
fn physical(x: &DMatrix<f64>, d: &DMatrix<f64>) -> Result<NamedFeatures> {
    let n = x.ncols();
    let phi = DMatrix::from_fn(
        n,
        2,
        |k, j| if j == 0 { x[(1, k)] } else { x[(0, k)].powi(3) },
    );
    let y = DVector::from_iterator(n, d.row(0).iter().copied());
    let coef = (phi.transpose() * &phi)
        .cholesky()
        .context("regressors v̂ and x̂³ are collinear")?
        .solve(&(phi.transpose() * y));
    Ok(physical_features(&[
        ("a_v", &[coef[0]]),
        ("b_x3", &[coef[1]]),
    ])?)
}

fn sample(ctx: &Ctx, label: usize, name: &str, seed: u64) -> Result<Sample> {
    let set = find(&ctx.sets, name)?;
    let sim = &set.train.sim;
    let spec = assumed_model_spec(sim);
    let out = estimate_spec(
        &spec,
        &sim.data,
        &mme_config(&spec, &EstimateOptions::default()),
    )
    .with_context(|| format!("MME on {name}"))?;
    let (x, d) = training_pairs(&out.estimate, &sim.data, 0.02);
    let mut nets = Vec::new();
    for h in HIDDEN {
        let mut net = Mlp::for_data(&x, &d, &[h], FIT_SEED + seed)?;
        train_lm(&mut net, &x, &d, &LmConfig::default(), None)?;
        nets.push(net);
    }
    Ok(Sample {
        label,
        nets,
        physical: physical(&x, &d)?,
    })
}

fn run(ctx: &Ctx) -> Result<Outcome> {
    let seeds = ctx.mode.class_seeds();
    let jobs: Vec<(usize, String, u64)> = MSD_CLASSES
        .iter()
        .enumerate()
        .flat_map(|(label, c)| (1..=seeds).map(move |s| (label, msd_class_name(*c, s), s)))
        .collect();
    let samples = jobs
        .par_iter()
        .map(|(label, name, seed)| sample(ctx, *label, name, *seed))
        .collect::<Result<Vec<_>>>()?;
    let labels: Vec<usize> = samples.iter().map(|s| s.label).collect();
    let n = samples.len();
    // One sample is 100/n % of the error; allow three samples to flip between machines.
    let flips = 3.0 * 100.0 / n as f64;
    let mut table = Table::new(
        TABLE,
        "Ch. 6 (Tables 6-2…6-5 analogue): damping classification error, cubic MSD, leave-one-out",
        &["features", "classifier", "preprocessing"],
        vec![
            Column::checked(
                "error_percent",
                "%",
                Tolerance::abs(flips),
                "one sample is 100/N %; networks trained on another machine may land on other \
                 equivalent weights, so three samples may change class",
                3,
            ),
            Column::info("n_features", "-", "feature count before PCA", 3),
        ],
    );
    let mut sets: Vec<(String, Vec<NamedFeatures>)> = Vec::new();
    for (i, h) in HIDDEN.iter().enumerate() {
        sets.push((
            format!("raw weights, {h}-node net"),
            samples.iter().map(|s| raw_weights(&s.nets[i])).collect(),
        ));
        sets.push((
            format!("canonical weights, {h}-node net"),
            samples
                .iter()
                .map(|s| canonical_weights(&s.nets[i]))
                .collect::<condmon::Result<Vec<_>>>()?,
        ));
    }
    sets.push((
        "physical (a_v, b_x3 from d̂)".into(),
        samples.iter().map(|s| s.physical.clone()).collect(),
    ));
    let columns = [Preprocessing::default(), Preprocessing::pca_fraction(0.95)];
    let config = CvConfig {
        scheme: CvScheme::LeaveOneOut,
        ..CvConfig::default()
    };
    let classifiers = ClassifierSpec::thesis_set();
    for (name, feats) in sets {
        let x = stack(&feats)?;
        let p = x.values().ncols() as f64;
        match error_table(x.values(), &labels, &classifiers, &columns, &config) {
            Ok(t) => {
                for (r, row) in t.rows.iter().enumerate() {
                    for (c, col) in t.columns.iter().enumerate() {
                        let e = t.cell(r, c).map(|cell| cell.error_percent());
                        table.push(&[&name, row, col], &[e, Some(p)]);
                    }
                }
            }
            Err(e) => {
                table.note(format!("{name}: no error table: {e}"));
                for spec in &classifiers {
                    for col in &columns {
                        table.push(&[&name, &spec.label(), &col.label()], &[None, Some(p)]);
                    }
                }
            }
        }
    }
    table.note(format!(
        "{n} records: {seeds} noise seeds × 3 damping classes (c = 0.1, 0.15, 0.2 N·s/m), \
         msd_cubic training recipe; networks (1 and 3 tanh units, LM, seed {FIT_SEED} + noise \
         seed) trained on MME's d̂; chance level is 66.7 %. Standardised features; PCA keeps \
         95 % of the variance, refitted in every fold."
    ));
    Ok(Outcome {
        tables: vec![table],
        ..Outcome::default()
    })
}
