//! Free entries of an output-error model's `A(θ)` and `B(θ)`, named as `"A[i,j]"` or
//! `"B[i,j]"` (0-based row and column), parsed and checked against the model's shapes.

use serde::{Deserialize, Serialize};
use sysid_core::LinearModel;

use crate::error::{BaselineError, Result};

/// Which matrix a free parameter lives in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum StateMatrix {
    /// The state matrix `A` (`n × n`).
    A,
    /// The input matrix `B` (`n × m`).
    B,
}

impl StateMatrix {
    /// `"A"` or `"B"`.
    pub fn name(self) -> &'static str {
        match self {
            StateMatrix::A => "A",
            StateMatrix::B => "B",
        }
    }
}

/// One free entry of `A` or `B`.
#[derive(Debug, Clone, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct FreeParameter {
    /// Its name in canonical form, e.g. `A[1,0]`.
    pub name: String,
    /// Which matrix.
    pub matrix: StateMatrix,
    /// Row, 0-based.
    pub row: usize,
    /// Column, 0-based.
    pub col: usize,
}

impl FreeParameter {
    /// Parse `"A[i,j]"` / `"B[i,j]"` (spaces allowed around the parts, indices 0-based).
    ///
    /// Errors: [`BaselineError::BadParameterName`] with what is wrong.
    pub fn parse(text: &str) -> Result<Self> {
        let bad = |reason| BaselineError::BadParameterName {
            name: text.to_string(),
            reason,
        };
        let s = text.trim();
        let mut chars = s.chars();
        let matrix = match chars.next() {
            Some('A') => StateMatrix::A,
            Some('B') => StateMatrix::B,
            _ => return Err(bad("must start with the matrix name A or B")),
        };
        let rest = chars.as_str().trim_start();
        let inner = rest
            .strip_prefix('[')
            .and_then(|r| r.strip_suffix(']'))
            .ok_or_else(|| bad("indices must be written as [row,col]"))?;
        let mut parts = inner.split(',');
        let (Some(r), Some(c), None) = (parts.next(), parts.next(), parts.next()) else {
            return Err(bad("expected exactly two indices [row,col]"));
        };
        let index = |p: &str| {
            p.trim()
                .parse::<usize>()
                .map_err(|_| bad("indices must be non-negative integers (0-based)"))
        };
        let (row, col) = (index(r)?, index(c)?);
        Ok(Self {
            name: format!("{}[{row},{col}]", matrix.name()),
            matrix,
            row,
            col,
        })
    }

    /// Check the entry lies inside the model's `A` or `B`.
    pub fn check(&self, model: &LinearModel, given: &str) -> Result<()> {
        let (rows, cols) = match self.matrix {
            StateMatrix::A => (model.n_states(), model.n_states()),
            StateMatrix::B => (model.n_states(), model.n_inputs()),
        };
        if self.row >= rows || self.col >= cols {
            return Err(BaselineError::ParameterIndex {
                name: given.to_string(),
                matrix: self.matrix.name(),
                rows,
                cols,
            });
        }
        Ok(())
    }

    /// The entry's value in a model.
    pub fn value_in(&self, model: &LinearModel) -> f64 {
        match self.matrix {
            StateMatrix::A => model.a()[(self.row, self.col)],
            StateMatrix::B => model.b()[(self.row, self.col)],
        }
    }
}

/// Parse and check a list of names against a model; duplicates (after canonicalisation,
/// so `A[1, 0]` equals `A[1,0]`) are errors.
pub fn parse_free_parameters(names: &[String], model: &LinearModel) -> Result<Vec<FreeParameter>> {
    let mut out: Vec<FreeParameter> = Vec::with_capacity(names.len());
    for given in names {
        let p = FreeParameter::parse(given)?;
        p.check(model, given)?;
        if out.iter().any(|q| q.name == p.name) {
            return Err(BaselineError::DuplicateParameter {
                name: given.clone(),
            });
        }
        out.push(p);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_canonical_and_spaced_names() {
        let p = FreeParameter::parse(" A [ 1 , 0 ] ").unwrap();
        assert_eq!((p.matrix, p.row, p.col), (StateMatrix::A, 1, 0));
        assert_eq!(p.name, "A[1,0]");
        let p = FreeParameter::parse("B[2,1]").unwrap();
        assert_eq!((p.matrix, p.row, p.col), (StateMatrix::B, 2, 1));
    }

    #[test]
    fn rejects_malformed_names() {
        for bad in [
            "C[0,0]", "A(1,0)", "A[1]", "A[1,0,2]", "A[-1,0]", "A[x,0]", "", "A[1,0",
        ] {
            assert!(
                matches!(
                    FreeParameter::parse(bad),
                    Err(BaselineError::BadParameterName { .. })
                ),
                "{bad}"
            );
        }
    }
}
