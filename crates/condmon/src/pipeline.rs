//! Preprocessing before a classifier — optional standardisation, then optional PCA — fitted
//! on training rows only, and a trained pipeline that applies both before predicting.

use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

use crate::classify::{Classifier, ClassifierModel, Predictions};
use crate::data::check_labelled;
use crate::error::Result;
use crate::pca::{ComponentSelection, Pca};
use crate::standardise::Standardiser;

/// Feature scaling before everything else.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub enum FeatureScaling {
    /// Use the features as they are.
    None,
    /// z-scores with the training rows' mean and standard deviation (see
    /// [`Standardiser`]).
    #[default]
    Standardise,
}

/// Dimension reduction after scaling.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub enum Reduction {
    /// Keep every feature ("no PCA" column of the thesis tables).
    #[default]
    None,
    /// Project on principal components of the (scaled) training rows ("after PCA").
    Pca(ComponentSelection),
}

/// What happens to features before the classifier. Default: standardise, no PCA.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Preprocessing {
    /// Scaling step.
    pub scaling: FeatureScaling,
    /// Reduction step.
    pub reduction: Reduction,
}

impl Preprocessing {
    /// Standardise, then PCA keeping `fraction` of the variance (thesis: 0.90 / 0.95).
    pub fn pca_fraction(fraction: f64) -> Self {
        Self {
            scaling: FeatureScaling::Standardise,
            reduction: Reduction::Pca(ComponentSelection::VarianceFraction(fraction)),
        }
    }

    /// Column label for error tables, e.g. `no PCA`, `after PCA (95 % variance)`.
    pub fn label(&self) -> String {
        let scale = match self.scaling {
            FeatureScaling::None => ", unscaled",
            FeatureScaling::Standardise => "",
        };
        match self.reduction {
            Reduction::None => format!("no PCA{scale}"),
            Reduction::Pca(ComponentSelection::VarianceFraction(d)) => {
                format!(
                    "after PCA ({} % variance{scale})",
                    (1e6 * 100.0 * d).round() / 1e6
                )
            }
            Reduction::Pca(ComponentSelection::Fixed(k)) => format!("after PCA ({k} PCs{scale})"),
            Reduction::Pca(ComponentSelection::All) => format!("after PCA (all PCs{scale})"),
        }
    }
}

/// Preprocessing fitted to training rows.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FittedPreprocessing {
    /// The standardiser, if scaling was requested.
    pub standardiser: Option<Standardiser>,
    /// The PCA, if reduction was requested.
    pub pca: Option<Pca>,
}

impl FittedPreprocessing {
    /// Fit `config` to training rows `x`.
    ///
    /// Errors: see [`Standardiser::fit`] and [`Pca::fit`].
    pub fn fit(config: &Preprocessing, x: &DMatrix<f64>) -> Result<Self> {
        let (standardiser, z) = match config.scaling {
            FeatureScaling::None => (None, None),
            FeatureScaling::Standardise => {
                let s = Standardiser::fit(x)?;
                let z = s.transform(x)?;
                (Some(s), Some(z))
            }
        };
        let pca = match config.reduction {
            Reduction::None => None,
            Reduction::Pca(selection) => Some(Pca::fit(z.as_ref().unwrap_or(x), selection)?),
        };
        Ok(Self { standardiser, pca })
    }

    /// Apply to any rows.
    ///
    /// Errors: wrong number of columns, a non-finite entry.
    pub fn transform(&self, x: &DMatrix<f64>) -> Result<DMatrix<f64>> {
        let z = match &self.standardiser {
            Some(s) => s.transform(x)?,
            None => x.clone(),
        };
        match &self.pca {
            Some(p) => p.transform(&z),
            None => Ok(z),
        }
    }
}

/// A classifier trained behind its preprocessing.
#[derive(Debug, Clone)]
pub struct TrainedPipeline<M> {
    /// Fitted preprocessing.
    pub preprocessing: FittedPreprocessing,
    /// Fitted classifier (sees preprocessed features).
    pub model: M,
}

impl<M: ClassifierModel> TrainedPipeline<M> {
    /// Fit preprocessing on `x`, then `classifier` on the preprocessed rows.
    ///
    /// Errors: bad data (checked before any fitting), or any error of the steps.
    pub fn fit<C: Classifier<Model = M>>(
        config: &Preprocessing,
        classifier: &C,
        x: &DMatrix<f64>,
        labels: &[usize],
    ) -> Result<Self> {
        check_labelled(x, labels)?;
        let preprocessing = FittedPreprocessing::fit(config, x)?;
        let z = preprocessing.transform(x)?;
        let model = classifier.fit(&z, labels)?;
        Ok(Self {
            preprocessing,
            model,
        })
    }

    /// Preprocess rows of `x` (original features) and classify them.
    ///
    /// Errors: wrong number of columns, a non-finite entry.
    pub fn predict(&self, x: &DMatrix<f64>) -> Result<Predictions> {
        self.model.predict(&self.preprocessing.transform(x)?)
    }
}
