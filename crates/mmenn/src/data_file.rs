//! The CSV data file of SPEC §5: a header row, a `t` column in seconds (uniformly
//! sampled), then inputs and measured channels. Empty cells in measured columns are missing
//! samples; inputs and time must be complete. Several files are several experiments.

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

/// Check a time column: complete, increasing, uniform. Returns `(t0, dt)`.
fn check_time(table: &Table, t: &[f64]) -> Result<(f64, f64)> {
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

    #[test]
    fn empty_measured_cells_are_missing_samples() {
        let t = parse("t,u,y\n0,1,\n0.1,1,2\n0.2,1,\n").unwrap();
        let e = table_to_experiment(&t, &names(&["u"]), &names(&["y"])).unwrap();
        assert!(e.output(0)[0].is_nan() && e.output(2)[0].is_nan());
        assert!((e.output(1)[0] - 2.0).abs() < 1e-15);
    }
}
