//! `--check` and `--bless`: the fixture file format (`fixtures/tables/<mode>/<id>.json`) and
//! the comparison of a rerun's tables with it, column by column, within the tolerances
//! the fixture states.

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::{Context, Result};
use serde::{Deserialize, Serialize};

use crate::stamp::Stamp;
use crate::table::Table;

/// Format tag of table files.
pub const TABLE_FORMAT: &str = "mmenn-table/1";

/// A table as written to `docs/results/tables/*.json` and `fixtures/tables/*/*.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TableFile {
    /// Always [`TABLE_FORMAT`].
    pub format: String,
    /// `quick` or `full`.
    pub mode: String,
    /// Revision, host, seeds of the run that wrote it.
    pub stamp: Stamp,
    /// The table, with its per-column tolerances.
    pub table: Table,
}

/// Read every fixture table in `dir` (by id).
pub fn read_fixtures(dir: &Path) -> Result<BTreeMap<String, TableFile>> {
    let mut out = BTreeMap::new();
    let entries = std::fs::read_dir(dir)
        .with_context(|| format!("reading fixture folder {}", dir.display()))?;
    for e in entries {
        let p = e?.path();
        if p.extension().is_some_and(|x| x == "json") {
            let text =
                std::fs::read_to_string(&p).with_context(|| format!("reading {}", p.display()))?;
            let f: TableFile = serde_json::from_str(&text)
                .with_context(|| format!("{}: not a table file", p.display()))?;
            out.insert(f.table.id.clone(), f);
        }
    }
    Ok(out)
}

/// What `--check` found.
#[derive(Debug, Default, Clone, PartialEq)]
pub struct CheckReport {
    /// Values compared.
    pub compared: usize,
    /// Differences beyond tolerance and structural mismatches, one line each.
    pub failures: Vec<String>,
    /// Fixture tables not produced by this run, with the reason.
    pub skipped: Vec<String>,
}

fn key_text(key: &[String]) -> String {
    format!("[{}]", key.join(", "))
}

/// Compare `tables` with the fixtures. `not_run` maps a table id the run did not produce
/// to the reason (not selected, benchmark data absent): those are reported as skipped.
pub fn compare(
    tables: &[Table],
    fixtures: &BTreeMap<String, TableFile>,
    not_run: &BTreeMap<String, String>,
) -> CheckReport {
    let mut rep = CheckReport::default();
    let by_id: BTreeMap<&str, &Table> = tables.iter().map(|t| (t.id.as_str(), t)).collect();
    for (id, fixture) in fixtures {
        let Some(new) = by_id.get(id.as_str()) else {
            match not_run.get(id) {
                Some(why) => rep.skipped.push(format!("{id}: {why}")),
                None => rep.failures.push(format!(
                    "{id}: in the fixtures but not produced by this run"
                )),
            }
            continue;
        };
        compare_table(new, &fixture.table, &mut rep);
    }
    for t in tables {
        if !fixtures.contains_key(&t.id) {
            rep.failures.push(format!(
                "{}: no fixture table (run `cargo xtask reproduce --bless` with the same mode)",
                t.id
            ));
        }
    }
    rep
}

fn compare_table(new: &Table, old: &Table, rep: &mut CheckReport) {
    let id = &old.id;
    for row in &old.rows {
        let Some(nrow) = new.rows.iter().find(|r| r.key == row.key) else {
            rep.failures.push(format!(
                "{id} {}: row missing from this run",
                key_text(&row.key)
            ));
            continue;
        };
        for (j, col) in old.columns.iter().enumerate() {
            let Some(tol) = col.tolerance else {
                continue;
            };
            let Some(nj) = new.column(&col.name) else {
                rep.failures
                    .push(format!("{id}: column '{}' missing from this run", col.name));
                continue;
            };
            let (o, n) = (row.values[j], nrow.values[nj]);
            rep.compared += 1;
            match (o, n) {
                (None, None) => {}
                (Some(o), Some(n)) => {
                    let diff = (n - o).abs();
                    let allowed = tol.allowed(o);
                    if diff > allowed || diff.is_nan() {
                        rep.failures.push(format!(
                            "{id} {} {}: got {n:.6e}, fixture {o:.6e}, |Δ| = {diff:.3e} > {allowed:.3e} (abs {} + rel {})",
                            key_text(&row.key),
                            col.name,
                            tol.abs,
                            tol.rel
                        ));
                    }
                }
                (o, n) => rep.failures.push(format!(
                    "{id} {} {}: got {}, fixture {}",
                    key_text(&row.key),
                    col.name,
                    n.map_or("N/A".into(), |v| format!("{v:.6e}")),
                    o.map_or("N/A".into(), |v| format!("{v:.6e}")),
                )),
            }
        }
    }
    for nrow in &new.rows {
        if !old.rows.iter().any(|r| r.key == nrow.key) {
            rep.failures.push(format!(
                "{id} {}: row not in the fixture",
                key_text(&nrow.key)
            ));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::table::{Column, Tolerance};

    fn table(v: f64, w: Option<f64>) -> Table {
        let mut t = Table::new(
            "t",
            "T",
            &["k"],
            vec![
                Column::checked("a", "-", Tolerance::both(0.01, 0.1), "", 3),
                Column::info("b", "-", "", 3),
                Column::checked("c", "-", Tolerance::abs(0.0), "", 3),
            ],
        );
        t.push(&["x"], &[Some(v), Some(v * 100.0), w]);
        t
    }

    fn fixtures(t: Table) -> BTreeMap<String, TableFile> {
        let mut m = BTreeMap::new();
        m.insert(
            t.id.clone(),
            TableFile {
                format: TABLE_FORMAT.into(),
                mode: "quick".into(),
                stamp: Stamp::default(),
                table: t,
            },
        );
        m
    }

    /// Fixture a = 1 with abs 0.01 + rel 0.1 allows |Δ| ≤ 0.11: 1.1 passes, 1.12 fails;
    /// the informational column b never fails; N/A must stay N/A.
    #[test]
    fn within_and_beyond_tolerance() {
        let f = fixtures(table(1.0, None));
        let ok = compare(&[table(1.1, None)], &f, &BTreeMap::new());
        assert!(ok.failures.is_empty(), "{:?}", ok.failures);
        assert_eq!(ok.compared, 2);
        let bad = compare(&[table(1.12, Some(3.0))], &f, &BTreeMap::new());
        assert_eq!(bad.failures.len(), 2, "{:?}", bad.failures);
        assert!(bad.failures[0].contains("[x] a"));
        assert!(bad.failures[1].contains("fixture N/A"));
    }

    #[test]
    fn missing_tables_fail_unless_a_reason_is_given() {
        let f = fixtures(table(1.0, None));
        assert_eq!(compare(&[], &f, &BTreeMap::new()).failures.len(), 1);
        let mut why = BTreeMap::new();
        why.insert("t".to_string(), "benchmark data absent".to_string());
        let r = compare(&[], &f, &why);
        assert!(r.failures.is_empty());
        assert_eq!(r.skipped.len(), 1);
        let mut extra = table(1.0, None);
        extra.id = "new".into();
        assert_eq!(compare(&[extra], &f, &why).failures.len(), 1);
    }
}
