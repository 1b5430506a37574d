//! Summary statistics of the generated data files (`fixtures/data_summary.json`): what
//! `--check` compares instead of committed CSVs, so the data can be regenerated rather
//! than stored. Per column: largest magnitude, mean, RMS deviation, min, max, first and
//! last value, a time-weighted mean (moves when the signal shifts in time) and the mean
//! absolute sample-to-sample step (moves when the noise changes).

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::{Context, Result, bail};
use mmenn::data_file::Table as CsvTable;
use serde::{Deserialize, Serialize};

/// Format tag of the summary file.
pub const SUMMARY_FORMAT: &str = "mmenn-xtask-data-summary-1";

/// Statistics of one CSV column.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ColumnSummary {
    /// Header name.
    pub name: String,
    /// Largest magnitude (the scale every difference is measured against).
    pub scale: f64,
    /// Mean.
    pub mean: f64,
    /// Root-mean-square deviation from the mean.
    pub rms_deviation: f64,
    /// Smallest value.
    pub min: f64,
    /// Largest value.
    pub max: f64,
    /// First value.
    pub first: f64,
    /// Last value.
    pub last: f64,
    /// `Σ w_k x_k / N` with `w_k = k/(N−1)` rising from 0 to 1 over the record.
    pub ramp_mean: f64,
    /// `Σ |x_{k+1} − x_k| / (N−1)`.
    pub mean_abs_step: f64,
}

impl ColumnSummary {
    fn of(name: &str, x: &[f64]) -> Self {
        let n = x.len().max(1) as f64;
        let mean = x.iter().sum::<f64>() / n;
        let last_index = (x.len().max(2) - 1) as f64;
        Self {
            name: name.to_string(),
            scale: x.iter().fold(0.0_f64, |m, v| m.max(v.abs())),
            mean,
            rms_deviation: (x.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n).sqrt(),
            min: x.iter().copied().fold(f64::INFINITY, f64::min),
            max: x.iter().copied().fold(f64::NEG_INFINITY, f64::max),
            first: x.first().copied().unwrap_or(f64::NAN),
            last: x.last().copied().unwrap_or(f64::NAN),
            ramp_mean: x
                .iter()
                .enumerate()
                .map(|(k, v)| k as f64 / last_index * v)
                .sum::<f64>()
                / n,
            mean_abs_step: x.windows(2).map(|w| (w[1] - w[0]).abs()).sum::<f64>() / last_index,
        }
    }

    fn values(&self) -> [(&'static str, f64); 9] {
        [
            ("scale", self.scale),
            ("mean", self.mean),
            ("rms_deviation", self.rms_deviation),
            ("min", self.min),
            ("max", self.max),
            ("first", self.first),
            ("last", self.last),
            ("ramp_mean", self.ramp_mean),
            ("mean_abs_step", self.mean_abs_step),
        ]
    }
}

/// Statistics of one CSV file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FileSummary {
    /// Data rows.
    pub rows: usize,
    /// One entry per column, in header order.
    pub columns: Vec<ColumnSummary>,
}

impl FileSummary {
    /// Summarise a parsed CSV.
    pub fn of(table: &CsvTable) -> Self {
        Self {
            rows: table.lines.len(),
            columns: table
                .header
                .iter()
                .zip(&table.columns)
                .map(|(name, x)| ColumnSummary::of(name, x))
                .collect(),
        }
    }

    /// Largest difference of any statistic from `old`'s, relative to the column's scale in
    /// `old` (so it reads the same for metres and radians), and the statistic's name.
    ///
    /// Errors: different row counts or headers.
    pub fn difference(&self, old: &FileSummary) -> Result<(f64, String)> {
        if self.rows != old.rows {
            bail!("{} rows, the summary has {}", self.rows, old.rows);
        }
        let names = |s: &FileSummary| s.columns.iter().map(|c| c.name.clone()).collect::<Vec<_>>();
        if names(self) != names(old) {
            bail!(
                "header {:?} differs from the summary's {:?}",
                names(self),
                names(old)
            );
        }
        let mut worst = (0.0_f64, String::new());
        for (a, b) in self.columns.iter().zip(&old.columns) {
            let scale = b.scale.max(1e-300);
            for ((what, x), (_, y)) in a.values().iter().zip(b.values()) {
                let d = (x - y).abs() / scale;
                // NaN (an empty column) only matches NaN.
                let d = if x.is_nan() && y.is_nan() {
                    0.0
                } else if d.is_nan() {
                    f64::INFINITY
                } else {
                    d
                };
                if d > worst.0 {
                    worst = (d, format!("{} {what}", a.name));
                }
            }
        }
        Ok(worst)
    }
}

/// The summary file: one entry per `<data set>/<recipe>/<file>`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DataSummary {
    /// [`SUMMARY_FORMAT`].
    pub format: String,
    /// Entries by relative path.
    pub files: BTreeMap<String, FileSummary>,
}

impl Default for DataSummary {
    fn default() -> Self {
        Self {
            format: SUMMARY_FORMAT.into(),
            files: BTreeMap::new(),
        }
    }
}

impl DataSummary {
    /// Read `path`; an absent file is an empty summary.
    pub fn read(path: &Path) -> Result<Self> {
        if !path.exists() {
            return Ok(Self::default());
        }
        let text =
            std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
        let s: Self =
            serde_json::from_str(&text).with_context(|| format!("parsing {}", path.display()))?;
        if s.format != SUMMARY_FORMAT {
            bail!(
                "{}: format {:?}, expected {SUMMARY_FORMAT:?}",
                path.display(),
                s.format
            );
        }
        Ok(s)
    }

    /// Write `path` (pretty JSON, stable key order).
    pub fn write(&self, path: &Path) -> Result<()> {
        mmenn::atomic::write_atomic(path, serde_json::to_string_pretty(self)?.as_bytes())?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn table(cols: &[(&str, Vec<f64>)]) -> CsvTable {
        let n = cols[0].1.len();
        CsvTable {
            path: std::path::PathBuf::new(),
            header: cols.iter().map(|(h, _)| h.to_string()).collect(),
            columns: cols.iter().map(|(_, c)| c.clone()).collect(),
            lines: (0..n).collect(),
        }
    }

    /// Statistics of a known column: x = [1, 2, 3, 4] has mean 2.5, RMS deviation
    /// √1.25, ramp weights [0, 1/3, 2/3, 1] so ramp mean (0 + 2/3 + 2 + 4)/4 = 5/3, mean
    /// step 1.
    #[test]
    fn statistics_of_a_known_column() {
        let s = ColumnSummary::of("x", &[1.0, 2.0, 3.0, 4.0]);
        assert!((s.mean - 2.5).abs() < 1e-15);
        assert!((s.rms_deviation - 1.25_f64.sqrt()).abs() < 1e-15);
        assert!((s.ramp_mean - 5.0 / 3.0).abs() < 1e-15);
        assert!((s.mean_abs_step - 1.0).abs() < 1e-15);
        assert_eq!(
            (s.min, s.max, s.first, s.last, s.scale),
            (1.0, 4.0, 1.0, 4.0, 4.0)
        );
    }

    /// A one-sample time shift of a pulse leaves mean, spread and range unchanged but moves
    /// the ramp mean by scale/(N (N−1)) = 1/56 ≈ 0.018 of the scale for N = 8, far above
    /// the 1e-6 check tolerance; identical data differ by exactly 0.
    #[test]
    fn a_time_shift_is_caught() {
        let x = vec![0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0];
        let mut y = x.clone();
        y.rotate_right(1);
        let a = FileSummary::of(&table(&[("x", x.clone())]));
        let b = FileSummary::of(&table(&[("x", y)]));
        let same = FileSummary::of(&table(&[("x", x)]));
        let (d, what) = b.difference(&a).unwrap();
        assert!(d > 1e-2, "{d} {what}");
        assert!(what.contains("ramp_mean"), "{what}");
        assert_eq!(same.difference(&a).unwrap().0.to_bits(), 0.0_f64.to_bits());
    }

    /// Different row counts or headers are errors, not differences.
    #[test]
    fn shape_changes_are_errors() {
        let a = FileSummary::of(&table(&[("x", vec![1.0, 2.0])]));
        let b = FileSummary::of(&table(&[("x", vec![1.0, 2.0, 3.0])]));
        let c = FileSummary::of(&table(&[("y", vec![1.0, 2.0])]));
        assert!(b.difference(&a).is_err());
        assert!(c.difference(&a).is_err());
    }
}
