//! `mmenn monitor`: condition monitoring from identified models (thesis ch. 6). Each
//! labelled record is identified (MME, then a small network on `d̂`, and the regression
//! update's coefficients); features from those models train the classifiers; a new record
//! is identified the same way and classified.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use condmon::{
    ClassifierSpec, CvConfig, CvScheme, ErrorTable, KnnConfig, NamedFeatures, Preprocessing,
    TrainedPipeline,
};
use nalgebra::DMatrix;
use nn::{LmConfig, Mlp};
use serde::{Deserialize, Serialize};
use sysid_core::Dataset;

use crate::atomic::{ensure_dir, write_atomic};
use crate::data_file::read_dataset;
use crate::error::{MmennError, Result};
use crate::estimate::{EstimateOptions, estimate_spec, mme_config};
use crate::fit::training_pairs;
use crate::model_file::{ModelSpec, format_model, parse_model};

/// Which features describe an identified model.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FeatureKind {
    /// The network's flat weights (the thesis).
    Raw,
    /// Weights with the tanh sign and hidden-unit permutation symmetries removed.
    Canonical,
    /// The regression update's coefficients of `d̂` on `[x̂, u]` (identified physics).
    Physical,
    /// Canonical weights and physical coefficients together.
    #[default]
    CanonicalAndPhysical,
}

impl std::str::FromStr for FeatureKind {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, Self::Err> {
        match s {
            "raw" => Ok(Self::Raw),
            "canonical" => Ok(Self::Canonical),
            "physical" => Ok(Self::Physical),
            "canonical+physical" => Ok(Self::CanonicalAndPhysical),
            _ => Err(format!(
                "'{s}' is not one of raw, canonical, physical, canonical+physical"
            )),
        }
    }
}

impl FeatureKind {
    /// What the features are, in words (for reports and the terminal).
    pub fn describe(self) -> &'static str {
        match self {
            Self::Raw => "the networks' raw weights",
            Self::Canonical => {
                "the networks' weights in canonical form (tanh sign and hidden-unit order fixed)"
            }
            Self::Physical => "the regression coefficients of d̂ on the states and inputs",
            Self::CanonicalAndPhysical => {
                "canonical network weights and the regression coefficients of d̂ together"
            }
        }
    }
}

/// Options of [`train_monitor`].
#[derive(Debug, Clone, PartialEq)]
pub struct MonitorOptions {
    /// Features.
    pub features: FeatureKind,
    /// Hidden units of each record's network (thesis: 3 or 1 for the mass–spring–damper).
    pub hidden: usize,
    /// Seed of the networks' initialisation.
    pub seed: u64,
    /// MME settings.
    pub estimate: EstimateOptions,
}

impl Default for MonitorOptions {
    fn default() -> Self {
        Self {
            features: FeatureKind::default(),
            hidden: 3,
            seed: 1,
            estimate: EstimateOptions::default(),
        }
    }
}

/// A trained monitor as saved in `monitor.json`: the model file, the feature recipe, the
/// training features and labels, the classifier chosen by cross-validation, and the
/// cross-validated error table. Classifiers are refitted from the stored features when
/// classifying (they are cheap; condmon's fitted models are not serialisable).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MonitorFile {
    /// Always `mmenn-monitor/1`.
    pub format: String,
    /// The assumed model (model-file TOML).
    pub model_toml: String,
    /// Feature recipe.
    pub features: FeatureKind,
    /// Hidden units per network.
    pub hidden: usize,
    /// Seed of the networks.
    pub seed: u64,
    /// Class names; label `i` is `classes[i]`.
    pub classes: Vec<String>,
    /// Feature names.
    pub feature_names: Vec<String>,
    /// Training features, one row per record.
    pub rows: Vec<Vec<f64>>,
    /// Label of each row.
    pub labels: Vec<usize>,
    /// The classifier used by `classify`.
    pub classifier: ClassifierSpec,
    /// Its preprocessing.
    pub preprocessing: Preprocessing,
    /// Cross-validated error table of every classifier × preprocessing.
    pub table: ErrorTable,
}

/// Read one record as the model's channels.
fn read_record(spec: &ModelSpec, path: &Path) -> Result<Dataset> {
    let lin = &spec.linear;
    read_dataset(
        &[path.to_path_buf()],
        lin.input_names(),
        lin.output_names(),
        &spec.units,
    )
}

/// Identify one record (a data file) and return its features.
pub fn record_features(
    spec: &ModelSpec,
    path: &Path,
    opts: &MonitorOptions,
) -> Result<NamedFeatures> {
    features_of(spec, &read_record(spec, path)?, opts)
}

/// Identify one record in memory and return its features.
pub fn features_of(
    spec: &ModelSpec,
    data: &Dataset,
    opts: &MonitorOptions,
) -> Result<NamedFeatures> {
    let lin = &spec.linear;
    // MME follows the model file's inputs-between-samples setting.
    let data = &data.clone().with_intersample(spec.intersample);
    let out = estimate_spec(spec, data, &mme_config(spec, &opts.estimate))?;
    let mut parts: Vec<NamedFeatures> = Vec::new();
    if opts.features != FeatureKind::Physical {
        let (x, d) = training_pairs(&out.estimate, data, 0.02);
        let mut net = Mlp::for_data(&x, &d, &[opts.hidden], opts.seed)?;
        nn::train_lm(&mut net, &x, &d, &LmConfig::default(), None)?;
        parts.push(match opts.features {
            FeatureKind::Raw => condmon::raw_weights(&net),
            _ => condmon::canonical_weights(&net)?,
        });
    }
    if matches!(
        opts.features,
        FeatureKind::Physical | FeatureKind::CanonicalAndPhysical
    ) {
        let up =
            mme_core::update_model(lin, data, &out.estimate, &mme_core::UpdateConfig::default())?;
        let mut named: Vec<(String, Vec<f64>)> = Vec::new();
        for reg in &up.regressions {
            for c in &reg.coefficients {
                named.push((format!("{}:{}", reg.correction, c.regressor), vec![c.value]));
            }
        }
        let refs: Vec<(&str, &[f64])> = named
            .iter()
            .map(|(n, v)| (n.as_str(), v.as_slice()))
            .collect();
        parts.push(condmon::physical_features(&refs)?);
    }
    let mut it = parts.into_iter();
    let first = it.next().ok_or(MmennError::Core {
        context: "monitor features",
        source: sysid_core::CoreError::TooFewSamples {
            what: "feature groups",
            found: 0,
            needed: 1,
        },
    })?;
    Ok(it.fold(first, |a, b| a.concat(&b)))
}

fn to_matrix(rows: &[Vec<f64>]) -> DMatrix<f64> {
    let p = rows.first().map_or(0, Vec::len);
    DMatrix::from_fn(rows.len(), p, |i, j| rows[i][j])
}

/// Train a monitor from labelled records: `classes` maps each condition name to its files.
/// Reads the files, [`compute_monitor`], [`write_monitor`]. The model may be any model
/// file (with or without `[[terms]]`) or a hybrid `model.json` (its model-file part).
pub fn train_monitor(
    classes: &[(String, Vec<PathBuf>)],
    model_path: &Path,
    opts: &MonitorOptions,
    out: &Path,
) -> Result<MonitorFile> {
    let loaded = crate::model::LoadedModel::read(model_path)?;
    loaded.refuse_x0_prior("monitor")?;
    let spec = loaded.spec;
    spec.refuse_acquisition("monitor", model_path)?;
    spec.refuse_uncorrected("monitor", model_path)?;
    let records = classes
        .iter()
        .map(|(name, files)| {
            let data = files
                .iter()
                .map(|f| read_record(&spec, f))
                .collect::<Result<Vec<_>>>()?;
            Ok((name.clone(), data))
        })
        .collect::<Result<Vec<_>>>()?;
    let file = compute_monitor(&records, &spec, opts)?;
    write_monitor(&file, out)?;
    Ok(file)
}

/// Write a trained monitor into `out`: `monitor.json` and `report.md` (atomically).
pub fn write_monitor(file: &MonitorFile, out: &Path) -> Result<()> {
    ensure_dir(out)?;
    write_atomic(
        &out.join("monitor.json"),
        serde_json::to_string_pretty(file)?.as_bytes(),
    )?;
    crate::html::write_report(out, &monitor_report(file))
}

/// `mmenn monitor train` without files: every labelled record (in memory) identified,
/// its features, the cross-validated error table and the chosen classifier.
pub fn compute_monitor(
    classes: &[(String, Vec<Dataset>)],
    spec: &ModelSpec,
    opts: &MonitorOptions,
) -> Result<MonitorFile> {
    spec.refuse_acquisition("monitor", Path::new("<model>"))?;
    spec.refuse_uncorrected("monitor", Path::new("<model>"))?;
    let mut samples = Vec::new();
    let mut labels = Vec::new();
    for (label, (_, records)) in classes.iter().enumerate() {
        for r in records {
            samples.push(features_of(spec, r, opts)?);
            labels.push(label);
        }
    }
    let matrix = condmon::stack(&samples)?;
    let (names, x) = matrix.into_parts();
    let n = x.nrows();
    let min_class = (0..classes.len())
        .map(|c| labels.iter().filter(|&&l| l == c).count())
        .min()
        .unwrap_or(0);
    let scheme = if min_class >= 5 {
        CvScheme::KFold {
            folds: 5.min(min_class),
            seed: opts.seed,
        }
    } else {
        CvScheme::LeaveOneOut
    };
    let knn_k = 3.min(n.saturating_sub(1)).max(1);
    let classifiers = vec![
        ClassifierSpec::Lda(Default::default()),
        ClassifierSpec::Qda(Default::default()),
        ClassifierSpec::Knn(KnnConfig { k: knn_k }),
        ClassifierSpec::NaiveBayes(Default::default()),
    ];
    let columns = vec![Preprocessing::default(), Preprocessing::pca_fraction(0.95)];
    let table = condmon::error_table(
        &x,
        &labels,
        &classifiers,
        &columns,
        &CvConfig {
            scheme,
            ..CvConfig::default()
        },
    )?;
    let pct = table.percentages();
    let (mut best, mut best_err) = ((0, 0), f64::INFINITY);
    for i in 0..pct.nrows() {
        for j in 0..pct.ncols() {
            if pct[(i, j)] < best_err {
                best_err = pct[(i, j)];
                best = (i, j);
            }
        }
    }
    let file = MonitorFile {
        format: "mmenn-monitor/1".into(),
        model_toml: format_model(spec)?,
        features: opts.features,
        hidden: opts.hidden,
        seed: opts.seed,
        classes: classes.iter().map(|(n, _)| n.clone()).collect(),
        feature_names: names,
        rows: (0..n).map(|i| x.row(i).iter().copied().collect()).collect(),
        labels,
        classifier: classifiers[best.0].clone(),
        preprocessing: columns[best.1],
        table,
    };
    Ok(file)
}

fn monitor_report(m: &MonitorFile) -> String {
    let mut r = format!(
        "# Condition monitor\n\n{} records in {} classes ({}); features: {} ({} values per record; networks with {} hidden units).\n\n",
        m.rows.len(),
        m.classes.len(),
        m.classes.join(", "),
        m.features.describe(),
        m.feature_names.len(),
        m.hidden
    );
    r.push_str("Cross-validated error % (95 % Wilson interval):\n\n| classifier |");
    for c in &m.table.columns {
        r.push_str(&format!(" {c} |"));
    }
    r.push_str("\n|---|");
    r.push_str(&"---|".repeat(m.table.columns.len()));
    r.push('\n');
    for (i, row) in m.table.rows.iter().enumerate() {
        r.push_str(&format!("| {row} |"));
        for j in 0..m.table.columns.len() {
            if let Some(cell) = m.table.cell(i, j) {
                r.push_str(&format!(
                    " {:.1} [{:.1}, {:.1}] |",
                    cell.error_percent(),
                    100.0 * cell.interval.lower,
                    100.0 * cell.interval.upper
                ));
            }
        }
        r.push('\n');
    }
    r.push_str(&format!(
        "\n`classify` uses {} with {}.\n",
        m.classifier.label(),
        m.preprocessing.label()
    ));
    r.push_str(&format!(
        "\n*Error %*: the share of records whose condition the classifier got wrong when \
         they were held out of its training (cross-validation); 0 is perfect, and guessing \
         the most common of the {} conditions would score about {:.0} %. The interval is \
         the 95 % Wilson score interval of that share: with few records it is wide, and two \
         classifiers whose intervals overlap are not told apart by this data.\n",
        m.classes.len(),
        chance_error_percent(&m.labels)
    ));
    r
}

/// Error % of always answering the most common label.
fn chance_error_percent(labels: &[usize]) -> f64 {
    let mut counts = BTreeMap::new();
    for &l in labels {
        *counts.entry(l).or_insert(0usize) += 1;
    }
    let most = counts.values().copied().max().unwrap_or(0);
    if labels.is_empty() {
        f64::NAN
    } else {
        100.0 * (1.0 - most as f64 / labels.len() as f64)
    }
}

/// The verdict on one record.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Classification {
    /// Predicted condition.
    pub condition: String,
    /// Score per condition (posterior probability or k-NN vote share, see `score_kind`).
    pub scores: BTreeMap<String, f64>,
    /// What the scores are.
    pub score_kind: String,
    /// Classifier used.
    pub classifier: String,
}

/// Classify one record with a trained monitor directory.
pub fn classify(monitor_dir: &Path, data: &Path) -> Result<Classification> {
    let path = monitor_dir.join("monitor.json");
    let text = std::fs::read_to_string(&path).map_err(|source| MmennError::Io {
        path: path.clone(),
        source,
    })?;
    let m: MonitorFile = serde_json::from_str(&text).map_err(|e| MmennError::Model {
        path: path.clone(),
        line: Some(e.line()),
        column: Some(e.column()),
        problem: crate::error::ModelProblem::Syntax {
            message: e.to_string(),
        },
    })?;
    let spec = parse_model(&path, &m.model_toml)?;
    classify_record(&m, &read_record(&spec, data)?)
}

/// Classify one record in memory with a trained monitor.
pub fn classify_record(m: &MonitorFile, data: &Dataset) -> Result<Classification> {
    let spec = parse_model(Path::new("monitor.json:model_toml"), &m.model_toml)?;
    let opts = MonitorOptions {
        features: m.features,
        hidden: m.hidden,
        seed: m.seed,
        estimate: EstimateOptions::default(),
    };
    let f = features_of(&spec, data, &opts)?;
    let pipeline = TrainedPipeline::fit(
        &m.preprocessing,
        &m.classifier,
        &to_matrix(&m.rows),
        &m.labels,
    )?;
    let p = pipeline.predict(&DMatrix::from_row_slice(1, f.len(), f.values()))?;
    let scores = p
        .classes
        .iter()
        .enumerate()
        .map(|(j, &c)| (m.classes[c].clone(), p.scores[(0, j)]))
        .collect();
    Ok(Classification {
        condition: m.classes[p.labels[0]].clone(),
        scores,
        score_kind: crate::words::score_kind(p.kind).to_string(),
        classifier: m.classifier.label(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn chance_error_is_one_minus_the_largest_class_share() {
        // Two of three records are class 0: always answering 0 is wrong once in three.
        assert!((chance_error_percent(&[0, 0, 1]) - 100.0 / 3.0).abs() < 1e-12);
        assert!(chance_error_percent(&[2, 2]).abs() < 1e-12);
        assert!(chance_error_percent(&[]).is_nan());
    }

    #[test]
    fn feature_kinds_read_as_words() {
        for k in [
            FeatureKind::Raw,
            FeatureKind::Canonical,
            FeatureKind::Physical,
            FeatureKind::CanonicalAndPhysical,
        ] {
            let d = k.describe();
            assert!(!d.contains("Canonical") && !d.contains("Raw") && !d.is_empty());
        }
    }
}
