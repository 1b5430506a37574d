//! Result tables: named key columns, numeric value columns with a unit and a stated
//! tolerance, rendering as Markdown and JSON (the format of `fixtures/tables/*.json`).

use serde::{Deserialize, Serialize};

/// How far a rerun's value may drift from the fixture's: it passes when
/// `|new − old| ≤ abs + rel·|old|`. A column without a tolerance is recorded, not checked.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Tolerance {
    /// Absolute part, in the column's unit.
    pub abs: f64,
    /// Relative part (fraction of the fixture's value).
    pub rel: f64,
}

impl Tolerance {
    /// Absolute tolerance only.
    pub const fn abs(abs: f64) -> Self {
        Self { abs, rel: 0.0 }
    }
    /// Relative tolerance only.
    pub const fn rel(rel: f64) -> Self {
        Self { abs: 0.0, rel }
    }
    /// Both parts.
    pub const fn both(abs: f64, rel: f64) -> Self {
        Self { abs, rel }
    }
    /// Allowed difference from `old`.
    pub fn allowed(&self, old: f64) -> f64 {
        self.abs + self.rel * old.abs()
    }
}

/// A value column.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Column {
    /// Column name (e.g. `r2`, `fit_percent`).
    pub name: String,
    /// Unit or `-`.
    pub unit: String,
    /// Tolerance of `--check`; `None`: informational, not compared.
    pub tolerance: Option<Tolerance>,
    /// Why this tolerance (stated in the fixture).
    pub why: String,
    /// Significant digits in Markdown.
    pub digits: usize,
}

impl Column {
    /// A checked column.
    pub fn checked(name: &str, unit: &str, tolerance: Tolerance, why: &str, digits: usize) -> Self {
        Self {
            name: name.into(),
            unit: unit.into(),
            tolerance: Some(tolerance),
            why: why.into(),
            digits,
        }
    }
    /// An informational column (not compared by `--check`).
    pub fn info(name: &str, unit: &str, why: &str, digits: usize) -> Self {
        Self {
            name: name.into(),
            unit: unit.into(),
            tolerance: None,
            why: why.into(),
            digits,
        }
    }
}

/// One row: key cells and one value per column (`None`: not applicable / not available).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Row {
    /// Key cells, one per key column.
    pub key: Vec<String>,
    /// Values, one per value column; `null` in JSON for N/A.
    pub values: Vec<Option<f64>>,
    /// What the table shows instead of "N/A" for this row's missing values (e.g. "diverged
    /// at t = 12.3 s"): a model that failed is reported as failed, never as a number.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub remark: Option<String>,
}

/// A table of results.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Table {
    /// Stable identifier (file name of the fixture).
    pub id: String,
    /// Title (what the thesis calls it).
    pub title: String,
    /// Names of the key columns.
    pub keys: Vec<String>,
    /// Value columns.
    pub columns: Vec<Column>,
    /// Rows.
    pub rows: Vec<Row>,
    /// Notes printed under the table (protocol, sources).
    pub notes: Vec<String>,
}

impl Table {
    /// An empty table.
    pub fn new(id: &str, title: &str, keys: &[&str], columns: Vec<Column>) -> Self {
        Self {
            id: id.into(),
            title: title.into(),
            keys: keys.iter().map(|k| k.to_string()).collect(),
            columns,
            rows: Vec::new(),
            notes: Vec::new(),
        }
    }

    /// Append a row (values `NaN` and infinities are stored as N/A). `values` gives the
    /// leading columns; columns past its end are N/A (see [`Table::set_for_model`]).
    pub fn push(&mut self, key: &[&str], values: &[Option<f64>]) {
        debug_assert_eq!(key.len(), self.keys.len());
        debug_assert!(values.len() <= self.columns.len());
        let mut values: Vec<Option<f64>> =
            values.iter().map(|v| v.filter(|x| x.is_finite())).collect();
        values.resize(self.columns.len(), None);
        self.rows.push(Row {
            key: key.iter().map(|k| k.to_string()).collect(),
            values,
            remark: None,
        });
    }

    /// Set `column` to `value` on every row whose first key cell is `model` (a value
    /// that belongs to the model rather than to one of its test records, such as its
    /// training time). No-op when the column does not exist.
    pub fn set_for_model(&mut self, model: &str, column: &str, value: f64) {
        let Some(j) = self.column(column) else {
            return;
        };
        for r in self.rows.iter_mut().filter(|r| r.key[0] == model) {
            r.values[j] = Some(value).filter(|v| v.is_finite());
        }
    }

    /// Append a row whose missing values read `remark` (why there is no number).
    pub fn push_remark(&mut self, key: &[&str], values: &[Option<f64>], remark: &str) {
        self.push(key, values);
        if let Some(r) = self.rows.last_mut() {
            r.remark = Some(remark.to_string());
        }
    }

    /// Add a note.
    pub fn note(&mut self, text: impl Into<String>) {
        self.notes.push(text.into());
    }

    /// Index of a value column.
    pub fn column(&self, name: &str) -> Option<usize> {
        self.columns.iter().position(|c| c.name == name)
    }

    /// The value at a row key and column name.
    pub fn get(&self, key: &[&str], column: &str) -> Option<f64> {
        let j = self.column(column)?;
        self.rows
            .iter()
            .find(|r| r.key.iter().map(String::as_str).eq(key.iter().copied()))
            .and_then(|r| r.values[j])
    }

    /// Append another part of the same table (same columns) — used when independent
    /// experiments fill rows of one table.
    pub fn merge(&mut self, other: Table) {
        self.rows.extend(other.rows);
        for n in other.notes {
            if !self.notes.contains(&n) {
                self.notes.push(n);
            }
        }
    }

    /// Markdown rendering.
    pub fn markdown(&self) -> String {
        let mut s = format!("### {}\n\n", self.title);
        let head: Vec<String> = self
            .keys
            .iter()
            .cloned()
            .chain(self.columns.iter().map(|c| {
                if c.unit == "-" || c.unit.is_empty() {
                    c.name.clone()
                } else {
                    format!("{} ({})", c.name, c.unit)
                }
            }))
            .collect();
        s.push_str(&format!("| {} |\n", head.join(" | ")));
        s.push_str(&format!("|{}\n", "---|".repeat(head.len())));
        for r in &self.rows {
            let cells: Vec<String> = r
                .key
                .iter()
                .cloned()
                .chain(r.values.iter().zip(&self.columns).map(|(v, c)| {
                    v.map_or_else(
                        || r.remark.clone().unwrap_or_else(|| "N/A".to_string()),
                        |x| format_value(x, c.digits),
                    )
                }))
                .collect();
            s.push_str(&format!("| {} |\n", cells.join(" | ")));
        }
        if !self.notes.is_empty() {
            s.push('\n');
            for n in &self.notes {
                s.push_str(&format!("- {n}\n"));
            }
        }
        s
    }
}

/// `digits` significant digits; scientific notation outside [1e-3, 1e5).
pub fn format_value(x: f64, digits: usize) -> String {
    let digits = digits.max(1);
    if x == 0.0 {
        return "0".into();
    }
    let a = x.abs();
    if !(1e-3..1e5).contains(&a) {
        return format!("{:.*e}", digits - 1, x);
    }
    let mag = a.log10().floor() as i64;
    let decimals = (digits as i64 - 1 - mag).max(0) as usize;
    format!("{x:.decimals$}")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn significant_digits() {
        assert_eq!(format_value(0.99951, 4), "0.9995");
        assert_eq!(format_value(97.314, 4), "97.31");
        assert_eq!(format_value(1.234e-5, 3), "1.23e-5");
        assert_eq!(format_value(-12.0, 2), "-12");
    }

    #[test]
    fn tolerance_is_abs_plus_rel() {
        let t = Tolerance::both(0.1, 0.5);
        assert!((t.allowed(-2.0) - 1.1).abs() < 1e-15);
    }

    #[test]
    fn non_finite_values_become_na_and_lookup_by_key() {
        let mut t = Table::new(
            "x",
            "X",
            &["set"],
            vec![Column::info("a", "-", "", 3), Column::info("b", "-", "", 3)],
        );
        t.push(&["p"], &[Some(f64::NAN), Some(2.0)]);
        assert_eq!(t.get(&["p"], "a"), None);
        assert_eq!(t.get(&["p"], "b"), Some(2.0));
        assert!(t.markdown().contains("| p | N/A | 2.00 |"));
        t.push_remark(
            &["q"],
            &[Some(f64::INFINITY), Some(1.0)],
            "diverged at t = 3 s",
        );
        assert_eq!(t.get(&["q"], "a"), None);
        assert!(t.markdown().contains("| q | diverged at t = 3 s | 1.00 |"));
    }
}
