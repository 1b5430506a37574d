//! The CSV data file of SPEC §5: a header row, a `t` column in seconds (uniformly
//! sampled), then inputs and measured channels. Empty cells in measured columns are missing
//! samples; inputs and time must be complete. Several files are several experiments.
//!
//! A record logged otherwise is prepared explicitly ([`prepare_table`], the CLI's `--map`
//! and `--resample DT`): columns renamed to the model's names, and a non-uniform time
//! column linearly interpolated onto a uniform grid, with a [`PrepareReport`] saying what
//! was done (original spacing statistics, method). Without `--resample` a non-uniform
//! time column is an error naming the row.

use std::path::{Path, PathBuf};

use nalgebra::DMatrix;
use sysid_core::dataset::{time_resolves_step, uniform_step_tolerance};
use sysid_core::{Channel, Dataset, Experiment};

use crate::atomic::write_atomic;
use crate::error::{CsvProblem, MmennError, Result};

/// A numeric CSV table as read from disk: header, one vector per column (NaN for empty
/// cells), and the 1-based file line of every data row.
#[derive(Debug, Clone, PartialEq)]
pub struct Table {
    /// The file it came from.
    pub path: PathBuf,
    /// Column names.
    pub header: Vec<String>,
    /// Column values (NaN = empty cell).
    pub columns: Vec<Vec<f64>>,
    /// File line of each data row.
    pub lines: Vec<usize>,
}

impl Table {
    /// Index of a column by name.
    pub fn column_index(&self, name: &str) -> Option<usize> {
        self.header.iter().position(|h| h == name)
    }

    fn err(&self, line: usize, column: Option<&str>, problem: CsvProblem) -> MmennError {
        MmennError::Csv {
            path: self.path.clone(),
            line,
            column: column.map(str::to_string),
            problem,
        }
    }
}

/// Read a numeric CSV table. Empty cells and `NaN` become NaN; anything else that is not a
/// number is an error naming line and column.
pub fn read_table(path: &Path) -> Result<Table> {
    let text = std::fs::read(path).map_err(|source| MmennError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    parse_table(path, &text)
}

/// Parse CSV bytes (see [`read_table`]); `path` is only used in errors.
pub fn parse_table(path: &Path, bytes: &[u8]) -> Result<Table> {
    let err = |line, column: Option<String>, problem| MmennError::Csv {
        path: path.to_path_buf(),
        line,
        column,
        problem,
    };
    let mut reader = csv::ReaderBuilder::new()
        .has_headers(false)
        .flexible(true)
        .trim(csv::Trim::All)
        .from_reader(bytes);
    let mut records = reader.records();
    let header: Vec<String> = match records.next() {
        None => return Err(err(1, None, CsvProblem::Empty)),
        Some(Err(e)) => return Err(err(1, None, CsvProblem::Syntax(e.to_string()))),
        Some(Ok(r)) => r.iter().map(str::to_string).collect(),
    };
    let mut seen = std::collections::HashSet::new();
    for h in &header {
        if h.is_empty() {
            return Err(err(1, None, CsvProblem::EmptyColumnName));
        }
        if !seen.insert(h.as_str()) {
            return Err(err(
                1,
                Some(h.clone()),
                CsvProblem::DuplicateColumn(h.clone()),
            ));
        }
    }
    let mut columns = vec![Vec::new(); header.len()];
    let mut lines = Vec::new();
    for rec in records {
        let rec = rec.map_err(|e| {
            let line = e.position().map(|p| p.line() as usize).unwrap_or(0);
            err(line, None, CsvProblem::Syntax(e.to_string()))
        })?;
        let line = rec.position().map(|p| p.line() as usize).unwrap_or(0);
        if rec.len() == 1 && rec.get(0).is_some_and(str::is_empty) {
            continue; // blank line
        }
        if rec.len() != header.len() {
            return Err(err(
                line,
                None,
                CsvProblem::Ragged {
                    expected: header.len(),
                    found: rec.len(),
                },
            ));
        }
        for (j, cell) in rec.iter().enumerate() {
            let v = if cell.is_empty() {
                f64::NAN
            } else {
                cell.parse::<f64>().map_err(|_| {
                    err(
                        line,
                        Some(header[j].clone()),
                        CsvProblem::NotANumber {
                            text: cell.to_string(),
                        },
                    )
                })?
            };
            if v.is_infinite() {
                return Err(err(line, Some(header[j].clone()), CsvProblem::Infinite));
            }
            columns[j].push(v);
        }
        lines.push(line);
    }
    Ok(Table {
        path: path.to_path_buf(),
        header,
        columns,
        lines,
    })
}

/// Check a time column: at least two rows, complete and increasing (errors name the row).
fn check_increasing(table: &Table, t: &[f64]) -> Result<()> {
    if t.len() < 2 {
        return Err(table.err(
            table.lines.first().copied().unwrap_or(1),
            None,
            CsvProblem::TooFewRows(t.len()),
        ));
    }
    for (k, v) in t.iter().enumerate() {
        if v.is_nan() {
            return Err(table.err(
                table.lines[k],
                Some("t"),
                CsvProblem::Missing { kind: "time" },
            ));
        }
    }
    for k in 1..t.len() {
        if t[k] <= t[k - 1] {
            return Err(table.err(
                table.lines[k],
                Some("t"),
                CsvProblem::NonIncreasingTime {
                    t_prev: t[k - 1],
                    t: t[k],
                },
            ));
        }
    }
    Ok(())
}

/// Check a time column: complete, increasing, uniform. Returns `(t0, dt)`.
fn check_time(table: &Table, t: &[f64]) -> Result<(f64, f64)> {
    check_increasing(table, t)?;
    let dt = (t[t.len() - 1] - t[0]) / (t.len() - 1) as f64;
    let t_max = t[0].abs().max(t[t.len() - 1].abs());
    if !time_resolves_step(t_max, dt) {
        let k = if t[0].abs() >= t[t.len() - 1].abs() {
            0
        } else {
            t.len() - 1
        };
        return Err(table.err(
            table.lines[k],
            Some("t"),
            CsvProblem::TimeResolution { t: t_max, dt },
        ));
    }
    for k in 1..t.len() {
        let step = t[k] - t[k - 1];
        // Same tolerance as sysid-core: relative to the step, plus round-off of |t| capped
        // at a share of the step (a missing row is caught at any |t|).
        if (step - dt).abs() > uniform_step_tolerance(dt, t[k]) {
            return Err(table.err(
                table.lines[k],
                Some("t"),
                CsvProblem::NonUniformTime { step, dt },
            ));
        }
    }
    Ok((t[0], dt))
}

/// How to prepare a data file before use: column renames and resampling.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct PrepareOptions {
    /// `(model name, file column)` pairs: the file's column is used under the model's
    /// name (`t=time` maps the time column).
    pub map: Vec<(String, String)>,
    /// Resample onto a uniform grid with this step, s (linear interpolation).
    pub resample: Option<f64>,
}

impl PrepareOptions {
    /// Parse `--map` entries `name=column` (each may hold several, comma-separated).
    pub fn parse_map(entries: &[String]) -> std::result::Result<Vec<(String, String)>, String> {
        let mut out = Vec::new();
        for entry in entries.iter().flat_map(|e| e.split(',')) {
            let entry = entry.trim();
            if entry.is_empty() {
                continue;
            }
            match entry.split_once('=') {
                Some((a, b)) if !a.trim().is_empty() && !b.trim().is_empty() => {
                    out.push((a.trim().to_owned(), b.trim().to_owned()));
                }
                _ => return Err(format!("--map '{entry}': expected NAME=COLUMN")),
            }
        }
        Ok(out)
    }

    /// Whether anything is to be done.
    pub fn is_identity(&self) -> bool {
        self.map.is_empty() && self.resample.is_none()
    }
}

/// Statistics of a time column's spacing, s.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Spacing {
    /// Smallest step.
    pub min: f64,
    /// Median step.
    pub median: f64,
    /// Mean step.
    pub mean: f64,
    /// Largest step.
    pub max: f64,
    /// Standard deviation of the steps.
    pub std: f64,
}

impl Spacing {
    /// The spacing of an increasing time column (at least two values).
    pub fn of(t: &[f64]) -> Spacing {
        let mut steps: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).collect();
        let n = steps.len().max(1) as f64;
        let mean = steps.iter().sum::<f64>() / n;
        let std = (steps.iter().map(|s| (s - mean).powi(2)).sum::<f64>() / n).sqrt();
        steps.sort_by(f64::total_cmp);
        let median = match steps.len() {
            0 => f64::NAN,
            k if k % 2 == 1 => steps[k / 2],
            k => 0.5 * (steps[k / 2 - 1] + steps[k / 2]),
        };
        Spacing {
            min: steps.first().copied().unwrap_or(f64::NAN),
            median,
            mean,
            max: steps.last().copied().unwrap_or(f64::NAN),
            std,
        }
    }
}

/// What [`prepare_table`] did to one file.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct PrepareReport {
    /// The file.
    pub path: PathBuf,
    /// Columns renamed, `(model name, file column)`.
    pub mapped: Vec<(String, String)>,
    /// Rows read.
    pub rows_in: usize,
    /// Spacing of the file's time column.
    pub spacing_in: Option<Spacing>,
    /// Rows after resampling (equal to `rows_in` without).
    pub rows_out: usize,
    /// The uniform step, when resampled.
    pub resampled_dt: Option<f64>,
    /// How, in words.
    pub method: String,
}

impl PrepareReport {
    /// One line of text for the terminal and the report.
    pub fn describe(&self) -> String {
        let mut parts = Vec::new();
        if !self.mapped.is_empty() {
            let m: Vec<String> = self
                .mapped
                .iter()
                .map(|(a, b)| format!("{b} → {a}"))
                .collect();
            parts.push(format!("columns {}", m.join(", ")));
        }
        if let (Some(s), Some(dt)) = (&self.spacing_in, self.resampled_dt) {
            parts.push(format!(
                "time steps min {:.4e} / median {:.4e} / mean {:.4e} / max {:.4e} s (std {:.2e}); \
                 {} rows resampled to {} rows at dt = {dt} s by {}",
                s.min, s.median, s.mean, s.max, s.std, self.rows_in, self.rows_out, self.method
            ));
        }
        format!("{}: {}", self.path.display(), parts.join("; "))
    }
}

/// Rename and resample a table as `opts` says (see the module documentation).
///
/// Resampling keeps `[t0, t_end]`: grid `t0 + k·dt` up to the last time; each column is
/// linearly interpolated between the two neighbouring rows; a measured cell that is empty
/// on either side stays empty (an input must be complete). The time column must be
/// complete and increasing (an error names the row).
pub fn prepare_table(mut table: Table, opts: &PrepareOptions) -> Result<(Table, PrepareReport)> {
    for (name, col) in &opts.map {
        let Some(j) = table.column_index(col) else {
            return Err(table.err(1, Some(col), CsvProblem::MissingChannel(col.clone())));
        };
        if let Some(other) = table.column_index(name)
            && other != j
        {
            // The model's name is already a column: it gives way to the mapped one.
            table.header[other] = format!("{name}__unmapped");
        }
        table.header[j] = name.clone();
    }
    let rows_in = table.lines.len();
    let mut report = PrepareReport {
        path: table.path.clone(),
        mapped: opts.map.clone(),
        rows_in,
        spacing_in: None,
        rows_out: rows_in,
        resampled_dt: None,
        method: "none".into(),
    };
    let Some(dt) = opts.resample else {
        // Not resampled: a time column that is not uniform fails here, naming the row
        // of the file as given (not of the prepared copy).
        if let Some(j) = table.column_index("t") {
            check_time(&table, &table.columns[j])?;
        }
        return Ok((table, report));
    };
    if !(dt.is_finite() && dt > 0.0) {
        return Err(table.err(
            1,
            Some("t"),
            CsvProblem::Syntax(format!("--resample {dt}: the step must be positive")),
        ));
    }
    let t_col = table
        .column_index("t")
        .ok_or_else(|| table.err(1, None, CsvProblem::NoTimeColumn))?;
    let t = table.columns[t_col].clone();
    check_increasing(&table, &t)?;
    let (t0, t_end) = (t[0], t[t.len() - 1]);
    // A grid point within a millionth of a step of the end still counts.
    let n = ((t_end - t0) / dt + 1e-6).floor() as usize + 1;
    let grid: Vec<f64> = (0..n).map(|k| t0 + k as f64 * dt).collect();
    let mut columns = Vec::with_capacity(table.columns.len());
    for (j, col) in table.columns.iter().enumerate() {
        if j == t_col {
            columns.push(grid.clone());
            continue;
        }
        let mut out = Vec::with_capacity(n);
        let mut i = 0;
        for &tk in &grid {
            while i + 2 < t.len() && t[i + 1] <= tk {
                i += 1;
            }
            let (ta, tb) = (t[i], t[i + 1]);
            let w = ((tk - ta) / (tb - ta)).clamp(0.0, 1.0);
            // Exactly on a row: that row's value (an empty cell stays empty).
            let v = if w <= 0.0 {
                col[i]
            } else if w >= 1.0 {
                col[i + 1]
            } else {
                col[i] + w * (col[i + 1] - col[i])
            };
            out.push(v);
        }
        columns.push(out);
    }
    report.spacing_in = Some(Spacing::of(&t));
    report.rows_out = n;
    report.resampled_dt = Some(dt);
    report.method = "linear interpolation between neighbouring rows".into();
    let lines = (0..n).map(|k| k + 2).collect();
    Ok((
        Table {
            path: table.path,
            header: table.header,
            columns,
            lines,
        },
        report,
    ))
}

/// Read a data file and prepare it ([`prepare_table`]).
pub fn read_prepared(path: &Path, opts: &PrepareOptions) -> Result<(Table, PrepareReport)> {
    prepare_table(read_table(path)?, opts)
}

/// Prepare data files for a command ([`prepare_table`] on each): unchanged paths when
/// `opts` does nothing; otherwise each prepared file is written as
/// `dir/prepared/<k>_<file name>` and the reports as `dir/prepared/prepare.json`, and the
/// new paths are returned (in order) with the reports.
pub fn prepare_files(
    paths: &[PathBuf],
    opts: &PrepareOptions,
    dir: &Path,
) -> Result<(Vec<PathBuf>, Vec<PrepareReport>)> {
    if opts.is_identity() || paths.is_empty() {
        return Ok((paths.to_vec(), Vec::new()));
    }
    let out = dir.join("prepared");
    crate::atomic::ensure_dir(&out)?;
    let mut new_paths = Vec::with_capacity(paths.len());
    let mut reports = Vec::with_capacity(paths.len());
    for (k, p) in paths.iter().enumerate() {
        let (table, report) = read_prepared(p, opts)?;
        let name = p
            .file_name()
            .map_or_else(|| "data.csv".into(), |n| n.to_string_lossy().into_owned());
        let target = out.join(format!("{k}_{name}"));
        let cols: Vec<&[f64]> = table.columns.iter().map(Vec::as_slice).collect();
        write_csv(&target, &table.header, &cols)?;
        new_paths.push(target);
        reports.push(report);
    }
    let json = serde_json::to_string_pretty(&reports).map_err(|e| MmennError::Csv {
        path: out.join("prepare.json"),
        line: 0,
        column: None,
        problem: CsvProblem::Syntax(e.to_string()),
    })?;
    write_atomic(&out.join("prepare.json"), json.as_bytes())?;
    Ok((new_paths, reports))
}

/// Turn one table into an experiment with the given input and output columns.
pub fn table_to_experiment(
    table: &Table,
    inputs: &[String],
    outputs: &[String],
) -> Result<Experiment> {
    let t_col = table
        .column_index("t")
        .ok_or_else(|| table.err(1, None, CsvProblem::NoTimeColumn))?;
    let (t0, dt) = check_time(table, &table.columns[t_col])?;
    let n = table.lines.len();
    let pick = |names: &[String], complete: bool| -> Result<DMatrix<f64>> {
        let mut m = DMatrix::zeros(names.len(), n);
        for (i, name) in names.iter().enumerate() {
            let j = table
                .column_index(name)
                .ok_or_else(|| table.err(1, None, CsvProblem::MissingChannel(name.clone())))?;
            for k in 0..n {
                let v = table.columns[j][k];
                if complete && v.is_nan() {
                    return Err(table.err(
                        table.lines[k],
                        Some(name),
                        CsvProblem::Missing { kind: "an input" },
                    ));
                }
                m[(i, k)] = v;
            }
        }
        Ok(m)
    };
    let u = pick(inputs, true)?;
    let y = pick(outputs, false)?;
    Experiment::new(t0, dt, u, y).map_err(|source| MmennError::Core {
        context: "building an experiment",
        source,
    })
}

/// Read several CSV files (one experiment each) into a dataset with the given input and
/// measured channels (units are attached when known).
pub fn read_dataset(
    paths: &[PathBuf],
    inputs: &[String],
    outputs: &[String],
    units: &std::collections::BTreeMap<String, String>,
) -> Result<Dataset> {
    let mut experiments = Vec::with_capacity(paths.len());
    for p in paths {
        let table = read_table(p)?;
        experiments.push(table_to_experiment(&table, inputs, outputs)?);
    }
    let channel = |n: &String| Channel {
        name: n.clone(),
        unit: units.get(n).cloned(),
    };
    Dataset::new(
        inputs.iter().map(channel).collect(),
        outputs.iter().map(channel).collect(),
        experiments,
    )
    .map_err(|source| MmennError::Core {
        context: "building a dataset",
        source,
    })
}

/// Read the data files of a workflow with a model's channels: the estimation files and,
/// when any are given, the validation files (`None` otherwise). Both follow the model
/// file's `intersample` (inputs held or interpolated between samples), which MME and every
/// free-run simulation of the records then use.
pub fn read_with_validation(
    data_paths: &[PathBuf],
    val_paths: &[PathBuf],
    spec: &crate::model_file::ModelSpec,
) -> Result<(Dataset, Option<Dataset>)> {
    let lin = &spec.linear;
    let data = read_dataset(
        data_paths,
        lin.input_names(),
        lin.output_names(),
        &spec.units,
    )?
    .with_intersample(spec.intersample);
    let val = if val_paths.is_empty() {
        None
    } else {
        Some(
            read_dataset(
                val_paths,
                lin.input_names(),
                lin.output_names(),
                &spec.units,
            )?
            .with_intersample(spec.intersample),
        )
    };
    Ok((data, val))
}

/// Render columns as CSV text: header, then one row per sample; NaN becomes an empty cell.
/// Numbers are the shortest text that reads back to the same bits (ryu).
pub fn format_csv(header: &[String], columns: &[&[f64]]) -> String {
    let rows = columns.first().map_or(0, |c| c.len());
    // A shortest round-trip number is at most 24 characters; most are about 20.
    let mut s = String::with_capacity(rows * columns.len() * 21 + 64);
    let mut buf = ryu::Buffer::new();
    s.push_str(&header.join(","));
    s.push('\n');
    for k in 0..rows {
        for (j, c) in columns.iter().enumerate() {
            if j > 0 {
                s.push(',');
            }
            let v = c[k];
            if !v.is_nan() {
                // The shortest text that reads back to the same bits (ryu; `inf`, `-inf`
                // for infinities), formatted without a string per value.
                s.push_str(buf.format(v));
            }
        }
        s.push('\n');
    }
    s
}

/// Write columns to a CSV file atomically (see [`format_csv`]).
pub fn write_csv(path: &Path, header: &[String], columns: &[&[f64]]) -> Result<()> {
    write_atomic(path, format_csv(header, columns).as_bytes())
}

/// Write one experiment of a dataset as a data file (`t`, inputs, outputs).
pub fn write_experiment(path: &Path, data: &Dataset, experiment: usize) -> Result<()> {
    let exp = data.experiments().get(experiment).ok_or(MmennError::Core {
        context: "writing a data file",
        source: sysid_core::CoreError::Range {
            start: experiment,
            end: experiment + 1,
            len: data.experiments().len(),
        },
    })?;
    let t = exp.times();
    let mut header = vec!["t".to_string()];
    header.extend(data.input_names());
    header.extend(data.output_names());
    let rows: Vec<Vec<f64>> = (0..exp.n_inputs())
        .map(|i| exp.inputs().row(i).iter().copied().collect())
        .chain((0..exp.n_outputs()).map(|i| exp.outputs().row(i).iter().copied().collect()))
        .collect();
    let mut cols: Vec<&[f64]> = vec![&t];
    cols.extend(rows.iter().map(Vec::as_slice));
    write_csv(path, &header, &cols)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<Table> {
        parse_table(Path::new("d.csv"), text.as_bytes())
    }

    fn problem(r: Result<impl std::fmt::Debug>) -> (usize, Option<String>, CsvProblem) {
        match r {
            Err(MmennError::Csv {
                line,
                column,
                problem,
                ..
            }) => (line, column, problem),
            other => panic!("expected a CSV error, got {other:?}"),
        }
    }

    fn names(v: &[&str]) -> Vec<String> {
        v.iter().map(|s| s.to_string()).collect()
    }

    #[test]
    fn round_trip_is_bit_exact_with_missing_samples() {
        let t = [0.0, 0.1, 0.2, 0.30000000000000004];
        let u = [1.0 / 3.0, -2.5e-17, 7.0, 1e300];
        let y = [f64::NAN, 0.1 + 0.2, -0.0, 5.0];
        let text = format_csv(&names(&["t", "u", "y"]), &[&t, &u, &y]);
        let table = parse(&text).unwrap();
        let exp = table_to_experiment(&table, &names(&["u"]), &names(&["y"])).unwrap();
        for k in 0..4 {
            assert_eq!(exp.input(k)[0].to_bits(), u[k].to_bits());
            if y[k].is_nan() {
                assert!(exp.output(k)[0].is_nan());
            } else {
                assert_eq!(exp.output(k)[0].to_bits(), y[k].to_bits());
            }
        }
        assert_eq!(table.lines, vec![2, 3, 4, 5]);
    }

    #[test]
    fn bad_input_classes_name_line_and_column() {
        let io = (names(&["u"]), names(&["y"]));
        let exp = |text: &str| parse(text).and_then(|t| table_to_experiment(&t, &io.0, &io.1));
        assert!(matches!(
            problem(exp("t,u,y\n0,1,2\n0.1,1\n")),
            (
                3,
                None,
                CsvProblem::Ragged {
                    expected: 3,
                    found: 2
                }
            )
        ));
        assert!(
            matches!(problem(exp("t,u,y\n0,1,2\n0.1,x,2\n")), (3, Some(c), CsvProblem::NotANumber { .. }) if c == "u")
        );
        assert!(
            matches!(problem(exp("t,u,y\n0,1,2\n0.1,,2\n0.2,1,1\n")), (3, Some(c), CsvProblem::Missing { .. }) if c == "u")
        );
        assert!(matches!(
            problem(exp("t,u,y\n0,1,2\n0.1,NaN,2\n0.2,1,1\n")),
            (3, _, CsvProblem::Missing { .. })
        ));
        assert!(matches!(
            problem(exp("t,u,y\n0,1,2\n0.1,1,2\n0.1,1,1\n")),
            (4, _, CsvProblem::NonIncreasingTime { .. })
        ));
        assert!(matches!(
            problem(exp("t,u,y\n0,1,2\n0.1,1,2\n0.25,1,1\n0.3,1,1\n")),
            (4, _, CsvProblem::NonUniformTime { .. })
        ));
        assert!(matches!(
            problem(exp("u,y\n1,2\n1,2\n")),
            (1, _, CsvProblem::NoTimeColumn)
        ));
        assert!(matches!(
            problem(exp("t,u,u\n0,1,2\n0.1,1,2\n")),
            (1, _, CsvProblem::DuplicateColumn(_))
        ));
        assert!(
            matches!(problem(exp("t,u\n0,1\n0.1,1\n")), (1, _, CsvProblem::MissingChannel(c)) if c == "y")
        );
        assert!(matches!(problem(exp("")), (1, _, CsvProblem::Empty)));
        assert!(matches!(
            problem(exp("t,u,y\n0,1,2\n")),
            (_, _, CsvProblem::TooFewRows(1))
        ));
        assert!(matches!(
            problem(exp("t,u,y\n0,1,inf\n0.1,1,2\n")),
            (2, _, CsvProblem::Infinite)
        ));
    }

    /// A jittered time column (±30 % of a 2 ms step, seeded) is an error naming its
    /// first off-grid row without `--resample`; resampled, a linear signal comes back
    /// exactly (linear interpolation is exact on it), a sine within the interpolation
    /// bound `h²/8·max|y''|`, and the report states the spacing and the method.
    #[test]
    fn jittered_time_is_rejected_or_resampled_explicitly() {
        let mut state = 7_u64;
        let mut jitter = move || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((state >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 0.6
        };
        let n = 500;
        let t: Vec<f64> = (0..n).map(|k| 0.002 * (k as f64 + jitter())).collect();
        let u: Vec<f64> = t.iter().map(|t| 1.0 + 3.0 * t).collect();
        let y: Vec<f64> = t.iter().map(|t| (5.0 * t).sin()).collect();
        let text = format_csv(&names(&["time", "torque", "pos"]), &[&t, &u, &y]);
        let table = parse(&text).unwrap();
        let map =
            PrepareOptions::parse_map(&["t=time,u=torque".into(), "theta=pos".into()]).unwrap();
        let mapped = PrepareOptions {
            map: map.clone(),
            resample: None,
        };
        // Renaming alone keeps the rows; a jittered time column then fails naming its row.
        let uniform = parse("time,torque,pos\n0,1,2\n0.5,1,2\n1,1,2\n").unwrap();
        let (plain, report) = prepare_table(uniform, &mapped).unwrap();
        assert_eq!(plain.header, names(&["t", "u", "theta"]));
        assert_eq!((report.rows_in, report.rows_out), (3, 3));
        let (line, column, p) = problem(prepare_table(table.clone(), &mapped));
        assert!(matches!(p, CsvProblem::NonUniformTime { .. }), "{p:?}");
        assert!((3..=n + 1).contains(&line) && column.as_deref() == Some("t"));
        assert!(p.to_string().contains("--resample"), "{p}");

        let opts = PrepareOptions {
            map,
            resample: Some(0.002),
        };
        let (table, report) = prepare_table(table, &opts).unwrap();
        let exp = table_to_experiment(&table, &names(&["u"]), &names(&["theta"])).unwrap();
        assert!((exp.dt() - 0.002).abs() < 1e-15);
        assert_eq!(report.rows_in, n);
        assert_eq!(report.rows_out, table.lines.len());
        let s = report.spacing_in.unwrap();
        assert!(s.min < 0.002 && s.max > 0.002 && s.std > 1e-4, "{s:?}");
        assert!(report.describe().contains("linear interpolation"));
        assert!(report.describe().contains("torque → u"));
        for k in 0..exp.len() {
            let tk = exp.t0() + k as f64 * 0.002;
            assert!(
                (exp.input(k)[0] - (1.0 + 3.0 * tk)).abs() < 1e-12,
                "u at {tk}"
            );
            // Steps up to 1.6·2 ms: h²/8·25 = 2.6e-5.
            assert!(
                (exp.output(k)[0] - (5.0 * tk).sin()).abs() < 2.6e-5,
                "y at {tk}"
            );
        }
        // A column the map names that the file lacks; an unmapped model name.
        let bad = PrepareOptions {
            map: vec![("u".into(), "tau".into())],
            resample: None,
        };
        let r = prepare_table(parse("t,x\n0,1\n1,2\n").unwrap(), &bad);
        assert!(matches!(problem(r), (1, _, CsvProblem::MissingChannel(c)) if c == "tau"));
        assert!(PrepareOptions::parse_map(&["t".into()]).is_err());
        // Decreasing time names the row even when resampling.
        let r = prepare_table(
            parse("t,x\n0,1\n0.2,2\n0.1,3\n").unwrap(),
            &opts_resample(0.1),
        );
        assert!(matches!(
            problem(r),
            (4, _, CsvProblem::NonIncreasingTime { .. })
        ));
    }

    fn opts_resample(dt: f64) -> PrepareOptions {
        PrepareOptions {
            map: Vec::new(),
            resample: Some(dt),
        }
    }

    #[test]
    fn empty_measured_cells_are_missing_samples() {
        let t = parse("t,u,y\n0,1,\n0.1,1,2\n0.2,1,\n").unwrap();
        let e = table_to_experiment(&t, &names(&["u"]), &names(&["y"])).unwrap();
        assert!(e.output(0)[0].is_nan() && e.output(2)[0].is_nan());
        assert!((e.output(1)[0] - 2.0).abs() < 1e-15);
    }
}
