//! NARX orders and regressor vectors: which past outputs and inputs feed the network, and
//! the series-parallel training matrices built from measured data (rows touching a
//! missing sample are skipped).

use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};
use sysid_core::Dataset;

use crate::error::{BaselineError, Result};

/// Tapped delays of a NARX model (thesis eq. 3.2):
/// `y(k) = F(y(k−1), …, y(k−na), u(k−nk), …, u(k−nk−nb+1))`, the same taps for every
/// output and input channel.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct NarxOrders {
    /// Output (feedback) delays `na`.
    pub na: usize,
    /// Input taps `nb`.
    pub nb: usize,
    /// Input dead time `nk` (1: the newest input used is `u(k−1)`, as for a sampled
    /// plant whose input is held between samples; 0 also uses `u(k)`).
    pub nk: usize,
}

impl Default for NarxOrders {
    /// `na = nb = 2`, `nk = 1`: the smallest structure of a second-order sampled plant.
    fn default() -> Self {
        Self {
            na: 2,
            nb: 2,
            nk: 1,
        }
    }
}

impl NarxOrders {
    /// Equal output and input delays (the thesis's choice), `nk = 1`.
    pub fn symmetric(delays: usize) -> Self {
        Self {
            na: delays,
            nb: delays,
            nk: 1,
        }
    }

    /// Oldest sample a regressor reaches back: `max(na, nk + nb − 1)`.
    pub fn max_lag(&self) -> usize {
        let input = if self.nb == 0 {
            0
        } else {
            self.nk + self.nb - 1
        };
        self.na.max(input)
    }

    /// Regressor length for `p` outputs and `m` inputs.
    pub fn regressor_len(&self, p: usize, m: usize) -> usize {
        self.na * p + self.nb * m
    }

    /// Error unless at least one tap is used.
    pub fn validate(&self) -> Result<()> {
        if self.na + self.nb == 0 {
            return Err(BaselineError::InvalidConfig {
                field: "orders",
                value: 0.0,
                reason: "na + nb must be at least 1",
            });
        }
        Ok(())
    }
}

/// Fill `out` with the regressor of sample `k`: for each output channel its `na` past
/// values (newest first), then for each input channel its `nb` taps (newest first).
/// `y(ch, j)` and `u(ch, j)` read sample `j` of a channel; `k ≥ max_lag` is the caller's
/// responsibility.
pub(crate) fn fill_regressor(
    y: impl Fn(usize, usize) -> f64,
    u: impl Fn(usize, usize) -> f64,
    (p, m): (usize, usize),
    k: usize,
    o: &NarxOrders,
    out: &mut [f64],
) {
    let mut i = 0;
    for ch in 0..p {
        for lag in 1..=o.na {
            out[i] = y(ch, k - lag);
            i += 1;
        }
    }
    for ch in 0..m {
        for tap in 0..o.nb {
            out[i] = u(ch, k - o.nk - tap);
            i += 1;
        }
    }
}

/// Series-parallel training data: regressors (`n_reg × rows`) and one-step targets
/// (`p × rows`) from every experiment; rows whose regressor or target touches a missing
/// sample are skipped.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct TrainingRows {
    pub inputs: DMatrix<f64>,
    pub targets: DMatrix<f64>,
    /// Rows per experiment (in order), so callers can split per experiment.
    pub per_experiment: Vec<usize>,
    /// Rows skipped because of missing samples.
    pub skipped: usize,
}

pub(crate) fn training_rows(data: &Dataset, o: &NarxOrders) -> Result<TrainingRows> {
    o.validate()?;
    let p = data.output_channels().len();
    let m = data.input_channels().len();
    let len = o.regressor_len(p, m);
    let lag = o.max_lag();
    let mut cols_in: Vec<f64> = Vec::new();
    let mut cols_t: Vec<f64> = Vec::new();
    let mut per_experiment = Vec::with_capacity(data.experiments().len());
    let mut skipped = 0;
    let mut reg = vec![0.0; len];
    for (e, exp) in data.experiments().iter().enumerate() {
        if exp.len() <= lag {
            return Err(BaselineError::LagsExceedData {
                what: "NARX regressor window",
                experiment: e,
                needed: lag + 1,
                available: exp.len(),
            });
        }
        let mut rows = 0;
        for k in lag..exp.len() {
            let (y, u) = (exp.outputs(), exp.inputs());
            fill_regressor(|c, j| y[(c, j)], |c, j| u[(c, j)], (p, m), k, o, &mut reg);
            let target = exp.output(k);
            if reg.iter().chain(target).any(|v| v.is_nan()) {
                skipped += 1;
                continue;
            }
            cols_in.extend_from_slice(&reg);
            cols_t.extend_from_slice(target);
            rows += 1;
        }
        per_experiment.push(rows);
    }
    let total: usize = per_experiment.iter().sum();
    if total == 0 {
        return Err(BaselineError::TooFewRows {
            what: "NARX training rows without missing samples",
            found: 0,
            needed: 1,
        });
    }
    Ok(TrainingRows {
        inputs: DMatrix::from_vec(len, total, cols_in),
        targets: DMatrix::from_vec(p, total, cols_t),
        per_experiment,
        skipped,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use sysid_core::{Channel, Experiment};

    #[test]
    fn regressor_layout_and_nan_skipping() {
        // y0(k) = k, y1(k) = 100 + k, u(k) = 1000 + k.
        let n = 8;
        let u = DMatrix::from_fn(1, n, |_, k| 1000.0 + k as f64);
        let mut y = DMatrix::from_fn(2, n, |i, k| 100.0 * i as f64 + k as f64);
        y[(1, 5)] = f64::NAN;
        let data = Dataset::new(
            vec![Channel::new("u")],
            vec![Channel::new("a"), Channel::new("b")],
            vec![Experiment::new(0.0, 1.0, u, y).unwrap()],
        )
        .unwrap();
        let o = NarxOrders {
            na: 2,
            nb: 3,
            nk: 1,
        };
        assert_eq!(o.max_lag(), 3);
        let rows = training_rows(&data, &o).unwrap();
        // k = 3..8 are 5 candidate rows; y1(5) is missing, which touches the target of
        // k = 5 and the lags of k = 6, 7.
        assert_eq!(rows.skipped, 3);
        assert_eq!(rows.inputs.ncols(), 2);
        let first: Vec<f64> = rows.inputs.column(0).iter().copied().collect();
        assert_eq!(first, vec![2.0, 1.0, 102.0, 101.0, 1002.0, 1001.0, 1000.0]);
        assert_eq!(rows.targets.column(1).as_slice(), &[4.0, 104.0]);
    }
}
