//! Initial states for calibration: a model-free start from the first measured outputs,
//! and the fit of a model's initial states by free-run error from several starts.

use nalgebra::{DMatrix, DVector};
use sysid_core::{Dataset, TermModel};

use super::{Calibration, CalibrationConfig, InitialState, calibrate};
use crate::error::{DiscoveryError, Result};

/// The state at the first sample of every record that reproduces its measured outputs
/// with the least norm (`x = C⁺y(t0)`, unmeasured directions 0; a missing output counts
/// as unmeasured): a start for fitting initial states that owes nothing to any model.
pub fn data_start(model: &TermModel, data: &Dataset) -> Vec<Vec<f64>> {
    let c = model.linear().c();
    let n = c.ncols();
    data.experiments()
        .iter()
        .map(|exp| {
            let rows: Vec<usize> = (0..c.nrows())
                .filter(|&i| exp.outputs()[(i, 0)].is_finite())
                .collect();
            if rows.is_empty() {
                return vec![0.0; n];
            }
            let cr = DMatrix::from_fn(rows.len(), n, |r, j| c[(rows[r], j)]);
            let y = DVector::from_iterator(rows.len(), rows.iter().map(|&i| exp.outputs()[(i, 0)]));
            match cr.pseudo_inverse(1e-12) {
                Ok(pinv) => (pinv * y).iter().copied().collect(),
                Err(_) => vec![0.0; n],
            }
        })
        .collect()
}

/// Initial states of `model` fitted by free-run error on every record of `data`
/// (coefficients fixed; `config`'s `terms` and `initial_state` are overridden), from
/// each start in `starts` and from [`data_start`]; the lowest cost wins. One start can
/// strand the fit: an initial state fitted with a wrong model puts a dry-friction model
/// into a stick–slip valley whose free run forgets where it started, and the gradient
/// with it. Errors: those of [`calibrate`] when every start fails.
pub fn fit_initial_states(
    model: &TermModel,
    data: &Dataset,
    starts: &[&[Vec<f64>]],
    config: &CalibrationConfig,
) -> Result<Calibration> {
    let config = CalibrationConfig {
        terms: Some(vec![]),
        initial_state: InitialState::Estimate,
        ..config.clone()
    };
    let from_data = data_start(model, data);
    // A non-finite cost never beats a finite one.
    let mut best: Option<Calibration> = None;
    let mut first_error = None;
    for start in starts
        .iter()
        .copied()
        .chain(std::iter::once(from_data.as_slice()))
    {
        match calibrate(model, data, start, &config) {
            Ok(fit) => {
                let key = |c: &Calibration| {
                    if c.cost_after.is_finite() {
                        c.cost_after
                    } else {
                        f64::INFINITY
                    }
                };
                if best.as_ref().is_none_or(|b| key(&fit) < key(b)) {
                    best = Some(fit);
                }
            }
            Err(e) => {
                first_error.get_or_insert(e);
            }
        }
    }
    match best {
        Some(b) => Ok(b),
        // Every start failed, so an error was kept (the data start is always tried).
        None => Err(first_error.unwrap_or(DiscoveryError::InvalidConfig {
            field: "starts",
            value: 0.0,
            reason: "no initial-state start could be calibrated",
        })),
    }
}
