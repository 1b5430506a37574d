//! Error tables shaped like thesis Tables 6-2…6-5: rows = classifiers, columns =
//! preprocessing variants (no PCA / after PCA), cells = cross-validated error results,
//! all computed on the same folds.

use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

use crate::classify::ClassifierSpec;
use crate::cv::{CvConfig, CvResult, cross_validate_with_folds, folds_for};
use crate::data::check_labelled;
use crate::error::{CondmonError, Result};
use crate::pipeline::Preprocessing;

/// Cross-validated error rates, classifier × preprocessing.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ErrorTable {
    /// Row labels (classifier names).
    pub rows: Vec<String>,
    /// Column labels (preprocessing variants).
    pub columns: Vec<String>,
    /// Classifier of each row.
    pub classifiers: Vec<ClassifierSpec>,
    /// Preprocessing of each column.
    pub preprocessing: Vec<Preprocessing>,
    /// Cross-validation settings shared by every cell.
    pub config: CvConfig,
    /// `cells[row][column]`.
    pub cells: Vec<Vec<CvResult>>,
}

impl ErrorTable {
    /// The cell at (`row`, `column`), if in range.
    pub fn cell(&self, row: usize, column: usize) -> Option<&CvResult> {
        self.cells.get(row)?.get(column)
    }

    /// Error percentages, `rows × columns`.
    pub fn percentages(&self) -> DMatrix<f64> {
        DMatrix::from_fn(self.rows.len(), self.columns.len(), |r, c| {
            self.cells[r][c].error_percent()
        })
    }
}

/// Cross-validate every classifier behind every preprocessing variant on the same folds
/// (a paired comparison: differences between cells are not fold noise).
///
/// Errors: empty classifier or column list, bad data or configuration (checked before
/// any fitting), or a fit failing inside a fold.
pub fn error_table(
    x: &DMatrix<f64>,
    labels: &[usize],
    classifiers: &[ClassifierSpec],
    columns: &[Preprocessing],
    config: &CvConfig,
) -> Result<ErrorTable> {
    if classifiers.is_empty() || columns.is_empty() {
        return Err(CondmonError::Length {
            what: "error table classifiers × columns",
            found: classifiers.len() * columns.len(),
            expected: 1,
        });
    }
    config.validate()?;
    let classes = check_labelled(x, labels)?;
    let folds = folds_for(labels, config.scheme)?;
    let cells = classifiers
        .iter()
        .map(|c| {
            columns
                .iter()
                .map(|p| cross_validate_with_folds(x, labels, &classes, &folds, p, c, config))
                .collect::<Result<Vec<_>>>()
        })
        .collect::<Result<Vec<_>>>()?;
    Ok(ErrorTable {
        rows: classifiers.iter().map(ClassifierSpec::label).collect(),
        columns: columns.iter().map(Preprocessing::label).collect(),
        classifiers: classifiers.to_vec(),
        preprocessing: columns.to_vec(),
        config: *config,
        cells,
    })
}
