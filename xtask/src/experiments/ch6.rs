//! Thesis ch. 6 (Tables 6-2…6-5 analogue): condition monitoring of the cubic
//! mass–spring–damper at damping c ∈ {0.1, 0.15, 0.2} N·s/m. Per class and noise seed:
//! MME gives `d̂`, a network learns `(x̂, v̂, u) → d̂`; its weights (raw, as in the thesis, or
//! canonicalised) or named physical coefficients are the features; cross-validated error %
//! of LDA, QDA, k-NN and naive Bayes, with and without PCA. The double-pendulum study
//! (Tables 6-4, 6-5) is in [`double`]; both share the table layout defined here.

mod double;

use anyhow::{Context, Result};
use mmenn::condmon::{
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

/// The jobs: the mass–spring–damper study and the double-pendulum study.
pub fn jobs() -> Vec<Job> {
    vec![job(), double::job()]
}

/// The mass–spring–damper job.
fn job() -> Job {
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
    let mut table = new_table(
        TABLE,
        "Ch. 6 (Tables 6-2, 6-3 analogue): damping classification error, cubic MSD, leave-one-out",
        n,
    );
    let mut sets: Vec<FeatureSet> = Vec::new();
    for (i, h) in HIDDEN.iter().enumerate() {
        sets.push(FeatureSet {
            name: format!("raw weights, {h}-node net"),
            labels: labels.clone(),
            features: samples.iter().map(|s| raw_weights(&s.nets[i])).collect(),
        });
        sets.push(FeatureSet {
            name: format!("canonical weights, {h}-node net"),
            labels: labels.clone(),
            features: samples
                .iter()
                .map(|s| canonical_weights(&s.nets[i]))
                .collect::<mmenn::condmon::Result<Vec<_>>>()?,
        });
    }
    sets.push(FeatureSet {
        name: "physical (a_v, b_x3 from d̂)".into(),
        labels,
        features: samples.iter().map(|s| s.physical.clone()).collect(),
    });
    for set in &sets {
        error_rows(&mut table, set)?;
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

/// One feature variant: a name, the class of each sample and its features.
pub struct FeatureSet {
    /// Row label (`raw weights, 3-node net`…).
    pub name: String,
    /// Class index per sample.
    pub labels: Vec<usize>,
    /// Features per sample (same names in every sample).
    pub features: Vec<NamedFeatures>,
}

/// An empty condition-monitoring table; `n` is the smallest sample count of its rows
/// (sets the tolerance: three samples may flip class).
pub fn new_table(id: &str, title: &str, n: usize) -> Table {
    let flips = 3.0 * 100.0 / n.max(1) as f64;
    Table::new(
        id,
        title,
        &["features", "classifier", "preprocessing"],
        vec![
            Column::checked(
                "error_percent",
                "%",
                Tolerance::abs(flips),
                "one sample is 100/N %; networks trained on another machine may land on other \
                 equivalent weights, so three samples (of the smallest set) may change class",
                3,
            ),
            Column::info("n_features", "-", "feature count before PCA", 3),
            Column::info(
                "n_samples",
                "-",
                "samples (networks or records) classified",
                3,
            ),
        ],
    )
}

/// Leave-one-out error % of LDA, QDA, k-NN and naive Bayes, without and with PCA (95 %
/// of the variance), on one feature set; a set whose error table cannot be made gets
/// empty cells and a note.
pub fn error_rows(table: &mut Table, set: &FeatureSet) -> Result<()> {
    let x = stack(&set.features)?;
    let p = x.values().ncols() as f64;
    let n = set.labels.len() as f64;
    let columns = [Preprocessing::default(), Preprocessing::pca_fraction(0.95)];
    let config = CvConfig {
        scheme: CvScheme::LeaveOneOut,
        ..CvConfig::default()
    };
    let classifiers = ClassifierSpec::thesis_set();
    let name = &set.name;
    match error_table(x.values(), &set.labels, &classifiers, &columns, &config) {
        Ok(t) => {
            for (r, row) in t.rows.iter().enumerate() {
                for (c, col) in t.columns.iter().enumerate() {
                    let e = t.cell(r, c).map(|cell| cell.error_percent());
                    table.push(&[name, row, col], &[e, Some(p), Some(n)]);
                }
            }
        }
        Err(e) => {
            table.note(format!("{name}: no error table: {e}"));
            for spec in &classifiers {
                for col in &columns {
                    table.push(
                        &[name, &spec.label(), &col.label()],
                        &[None, Some(p), Some(n)],
                    );
                }
            }
        }
    }
    Ok(())
}
