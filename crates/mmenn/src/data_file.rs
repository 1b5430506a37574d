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
use sysid_core::dataset::{first_irregular_step, time_resolves_step};
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
    /// The problem "no column `name`", with the header the file does have.
    pub fn missing(&self, name: &str) -> CsvProblem {
        CsvProblem::MissingChannel {
            name: name.to_string(),
            header: self.header.join(", "),
        }
    }

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
///
/// A plain numeric file is read a block at a time straight into the columns (see
/// [`parse_table`] for what counts as plain); anything else is read whole and parsed by
/// the general reader.
pub fn read_table(path: &Path) -> Result<Table> {
    let io = |source| MmennError::Io {
        path: path.to_path_buf(),
        source,
    };
    let file = std::fs::File::open(path).map_err(io)?;
    let len = file.metadata().map_err(io)?.len();
    if let Some(parsed) = usize::try_from(len)
        .ok()
        .and_then(|len| fast::read(&file, len))
    {
        return fast_table(path, parsed);
    }
    drop(file);
    let text = std::fs::read(path).map_err(io)?;
    parse_table_general(path, &text)
}

/// Parse CSV bytes (see [`read_table`]); `path` is only used in errors.
///
/// Plain numeric files (ASCII, no quotes, `,` between cells, `\n` or `\r\n` at line
/// ends) take a fast path that splits lines itself and parses the rows on two threads
/// when the file is large. Whenever that path meets anything else — a quote, a cell
/// that is not a finite number, a ragged row, an empty file — the whole file is parsed
/// again by the general reader below, which produces the same values and the typed
/// errors naming file, line and column.
pub fn parse_table(path: &Path, bytes: &[u8]) -> Result<Table> {
    if let Some(parsed) = fast::parse(bytes) {
        return fast_table(path, parsed);
    }
    parse_table_general(path, bytes)
}

/// The table of what the fast path parsed, once its header passes [`check_header`].
fn fast_table(path: &Path, (header, columns, lines): fast::Parsed) -> Result<Table> {
    check_header(path, &header)?;
    Ok(Table {
        path: path.to_path_buf(),
        header,
        columns,
        lines,
    })
}

/// Header checks shared by both parse paths: no empty and no repeated column name.
fn check_header(path: &Path, header: &[String]) -> Result<()> {
    let err = |column: Option<String>, problem| MmennError::Csv {
        path: path.to_path_buf(),
        line: 1,
        column,
        problem,
    };
    let mut seen = std::collections::HashSet::new();
    for h in header {
        if h.is_empty() {
            return Err(err(None, CsvProblem::EmptyColumnName));
        }
        if !seen.insert(h.as_str()) {
            return Err(err(Some(h.clone()), CsvProblem::DuplicateColumn(h.clone())));
        }
    }
    Ok(())
}

mod fast;

/// File lines of records by counting `\n` up to each record's first byte. (The `csv`
/// crate's own line count is one low after a CRLF line end and after an empty line that
/// follows a record.) Records come in file order, so the count carries on.
#[derive(Default)]
struct FileLines {
    /// Bytes counted so far.
    at: usize,
    /// `\n` seen before `at`.
    newlines: usize,
}

impl FileLines {
    /// The 1-based file line of the record at `pos`.
    fn line(&mut self, bytes: &[u8], pos: &csv::Position) -> usize {
        let mut b = usize::try_from(pos.byte())
            .unwrap_or(usize::MAX)
            .min(bytes.len());
        // A record never starts with a line end: skip the rest of the previous one.
        while b < bytes.len() && (bytes[b] == b'\n' || bytes[b] == b'\r') {
            b += 1;
        }
        if b < self.at {
            *self = Self::default();
        }
        self.newlines += bytes[self.at..b].iter().filter(|&&c| c == b'\n').count();
        self.at = b;
        self.newlines + 1
    }
}

/// The general reader of [`parse_table`] (the `csv` crate).
fn parse_table_general(path: &Path, bytes: &[u8]) -> Result<Table> {
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
    check_header(path, &header)?;
    let mut columns = vec![Vec::new(); header.len()];
    let mut lines = Vec::new();
    let mut file_lines = FileLines::default();
    for rec in records {
        let rec = rec.map_err(|e| {
            let line = e
                .position()
                .map_or(0, |p| FileLines::default().line(bytes, p));
            err(line, None, CsvProblem::Syntax(e.to_string()))
        })?;
        let line = rec.position().map_or(0, |p| file_lines.line(bytes, p));
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
    // The shared rule (sysid-core): each step against the median step, so a missing or
    // doubled row is named where it is.
    if let Some((k, step, typical)) = first_irregular_step(t) {
        return Err(table.err(
            table.lines[k],
            Some("t"),
            CsvProblem::NonUniformTime { step, dt: typical },
        ));
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
            return Err(table.err(1, Some(col), table.missing(col)));
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
    let (t0, dt, ju, jy) = checked_channels(table, inputs, outputs)?;
    let pick = |js: &[usize]| {
        DMatrix::from_fn(js.len(), table.lines.len(), |i, k| table.columns[js[i]][k])
    };
    experiment(t0, dt, pick(&ju), pick(&jy))
}

/// [`table_to_experiment`] consuming the table: a matrix of one channel takes its
/// column as it is (no copy), unless the column serves both inputs and outputs.
pub fn table_into_experiment(
    mut table: Table,
    inputs: &[String],
    outputs: &[String],
) -> Result<Experiment> {
    let (t0, dt, ju, jy) = checked_channels(&table, inputs, outputs)?;
    let n = table.lines.len();
    let shared = ju.iter().any(|j| jy.contains(j));
    let mut pick = |js: &[usize]| match js {
        [j] if !shared => DMatrix::from_vec(1, n, std::mem::take(&mut table.columns[*j])),
        _ => DMatrix::from_fn(js.len(), n, |i, k| table.columns[js[i]][k]),
    };
    let u = pick(&ju);
    let y = pick(&jy);
    experiment(t0, dt, u, y)
}

fn experiment(t0: f64, dt: f64, u: DMatrix<f64>, y: DMatrix<f64>) -> Result<Experiment> {
    Experiment::new(t0, dt, u, y).map_err(|source| MmennError::Core {
        context: "building an experiment",
        source,
    })
}

/// The checks of [`table_to_experiment`] in its order (time column, then each input —
/// present and complete —, then each output present): `t0`, `dt` and the column indices
/// of the inputs and of the outputs.
fn checked_channels(
    table: &Table,
    inputs: &[String],
    outputs: &[String],
) -> Result<(f64, f64, Vec<usize>, Vec<usize>)> {
    let t_col = table
        .column_index("t")
        .ok_or_else(|| table.err(1, None, CsvProblem::NoTimeColumn))?;
    let (t0, dt) = check_time(table, &table.columns[t_col])?;
    let n = table.lines.len();
    let find = |names: &[String], complete: bool| -> Result<Vec<usize>> {
        let mut js = Vec::with_capacity(names.len());
        for name in names {
            let j = table
                .column_index(name)
                .ok_or_else(|| table.err(1, None, table.missing(name)))?;
            if complete && let Some(k) = table.columns[j][..n].iter().position(|v| v.is_nan()) {
                return Err(table.err(
                    table.lines[k],
                    Some(name),
                    CsvProblem::Missing { kind: "an input" },
                ));
            }
            js.push(j);
        }
        Ok(js)
    };
    let ju = find(inputs, true)?;
    let jy = find(outputs, false)?;
    Ok((t0, dt, ju, jy))
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
        experiments.push(table_into_experiment(read_table(p)?, inputs, outputs)?);
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
/// Numbers are the shortest text that reads back to the same bits, written as ryu writes
/// them (`push_shortest`).
pub fn format_csv(header: &[String], columns: &[&[f64]]) -> String {
    let mut out = Vec::new();
    // Writing into a Vec cannot fail.
    let _ = write_csv_to(&mut out, header, columns);
    // ASCII digits, signs, `e`, `.`, `,`, `\n` and the header's (UTF-8) names only.
    String::from_utf8(out).unwrap_or_default()
}

/// Rows formatted per chunk of [`write_csv_to`] (about 1 MB of text at a time).
const CSV_CHUNK_ROWS: usize = 8192;

/// Write CSV text (see [`format_csv`]) to `out` through one reused buffer of a few
/// thousand rows, so a large file is never held in memory whole.
pub fn write_csv_to(
    out: &mut impl std::io::Write,
    header: &[String],
    columns: &[&[f64]],
) -> std::io::Result<()> {
    let rows = columns.first().map_or(0, |c| c.len());
    // A shortest round-trip number is at most 24 characters; most are about 20.
    let chunk = rows.min(CSV_CHUNK_ROWS);
    let mut s: Vec<u8> = Vec::with_capacity(chunk * (columns.len() * 25 + 1) + 64);
    let mut buf = zmij::Buffer::new();
    s.extend_from_slice(header.join(",").as_bytes());
    s.push(b'\n');
    for k in 0..rows {
        for (j, c) in columns.iter().enumerate() {
            if j > 0 {
                s.push(b',');
            }
            let v = c[k];
            if !v.is_nan() {
                push_shortest(&mut s, &mut buf, v);
            }
        }
        s.push(b'\n');
        if (k + 1) % CSV_CHUNK_ROWS == 0 {
            out.write_all(&s)?;
            s.clear();
        }
    }
    out.write_all(&s)
}

/// Append the shortest text that reads back to the same bits of `v` (not NaN; `inf`,
/// `-inf` for infinities), byte for byte as ryu writes it (the files written before
/// used ryu): zmij finds the same digits faster but writes a positive exponent as `e+N`
/// where ryu writes `eN`, so the `+` is dropped.
fn push_shortest(s: &mut Vec<u8>, buf: &mut zmij::Buffer, v: f64) {
    let text = buf.format(v).as_bytes();
    // Both write an exponent only below 1e-5 and from 1e16 up (the test against ryu
    // covers both sides of either switch); a positive one is all that differs.
    if v.abs() < 1e16 {
        s.extend_from_slice(text);
        return;
    }
    match text.iter().position(|&b| b == b'+') {
        Some(plus) => {
            s.extend_from_slice(&text[..plus]);
            s.extend_from_slice(&text[plus + 1..]);
        }
        None => s.extend_from_slice(text),
    }
}

/// Write columns to a CSV file atomically (see [`format_csv`]).
pub fn write_csv(path: &Path, header: &[String], columns: &[&[f64]]) -> Result<()> {
    crate::atomic::write_atomic_with(path, |f| write_csv_to(f, header, columns))
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
mod tests;
