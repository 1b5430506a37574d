//! The hidden-layer sizing sweep (thesis §3.1): train every (size, initialisation) pair in
//! parallel, tabulate training and test MSE, and pick the smallest network whose test MSE
//! is within a tolerance of the best.

use nalgebra::DMatrix;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::config::LmConfig;
use crate::error::{NnError, Result, check_finite, check_shape};
use crate::lm::{StopReason, train_lm};
use crate::mlp::Mlp;

/// The rule that picks one network from the sweep table.
///
/// Let `best` be the lowest finite test MSE in the table. The candidates are the runs with
/// `test_mse ≤ best·(1 + rel_tolerance) + abs_tolerance`; among them the one with the
/// fewest hidden units wins, then the lower test MSE, then the lower initialisation index.
///
/// Test MSE alone measures the balance the thesis asks for: an under-fitting network has
/// a high training *and* test MSE, an over-fitting one a low training but high test MSE,
/// and both fall outside the tolerance band; the size preference then removes networks
/// that only add units for an insignificant gain.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct SizingRule {
    /// Relative band above the best test MSE, ≥ 0. Default 0.1: with `N_test` samples the
    /// test MSE of equally good networks scatters by about `√(2/N_test)` relative (χ²
    /// spread), which is 10 % at 200 test samples.
    pub rel_tolerance: f64,
    /// Absolute band added to the relative one (squared target units), ≥ 0. Default 0.
    pub abs_tolerance: f64,
}

impl Default for SizingRule {
    fn default() -> Self {
        Self {
            rel_tolerance: 0.1,
            abs_tolerance: 0.0,
        }
    }
}

/// Settings of the sizing sweep.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct SweepConfig {
    /// Hidden-layer sizes to try (one hidden layer each). Default 1..=10 (thesis §3.1).
    pub hidden_sizes: Vec<usize>,
    /// Initialisations per size. Default 10 (thesis §3.1).
    pub inits: usize,
    /// Base seed; run `(size, init)` uses [`derive_seed`]`(seed, size, init)`.
    pub seed: u64,
    /// Training settings shared by every run (including the validation split, which is
    /// therefore the same for all runs).
    pub lm: LmConfig,
    /// How the reported network is chosen.
    pub selection: SizingRule,
}

impl Default for SweepConfig {
    fn default() -> Self {
        Self {
            hidden_sizes: (1..=10).collect(),
            inits: 10,
            seed: 0,
            lm: LmConfig::default(),
            selection: SizingRule::default(),
        }
    }
}

impl SweepConfig {
    /// Check every field is in range.
    pub fn validate(&self) -> Result<()> {
        if self.hidden_sizes.is_empty() {
            return Err(NnError::InvalidConfig {
                field: "hidden_sizes",
                value: 0.0,
                reason: "must list at least one size",
            });
        }
        if let Some(layer) = self.hidden_sizes.iter().position(|&h| h == 0) {
            return Err(NnError::ZeroDimension {
                what: "hidden units",
                layer,
            });
        }
        if self.inits == 0 {
            return Err(NnError::InvalidConfig {
                field: "inits",
                value: 0.0,
                reason: "must be ≥ 1",
            });
        }
        let s = &self.selection;
        if !(s.rel_tolerance.is_finite() && s.rel_tolerance >= 0.0) {
            return Err(NnError::InvalidConfig {
                field: "selection.rel_tolerance",
                value: s.rel_tolerance,
                reason: "must be finite and ≥ 0",
            });
        }
        if !(s.abs_tolerance.is_finite() && s.abs_tolerance >= 0.0) {
            return Err(NnError::InvalidConfig {
                field: "selection.abs_tolerance",
                value: s.abs_tolerance,
                reason: "must be finite and ≥ 0",
            });
        }
        self.lm.validate()
    }
}

/// One trained network of the sweep.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SweepRow {
    /// Hidden units.
    pub hidden: usize,
    /// Initialisation index, `0..inits`.
    pub init: usize,
    /// Seed used for its initial weights.
    pub seed: u64,
    /// Training MSE of the returned weights.
    pub train_mse: f64,
    /// Validation MSE of the returned weights (`None` without a validation split).
    pub val_mse: Option<f64>,
    /// MSE on the test data.
    pub test_mse: f64,
    /// LM epochs run.
    pub epochs: usize,
    /// Why training stopped.
    pub termination: StopReason,
}

/// The full sweep table, every trained network, and the chosen one.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SweepResult {
    /// One row per run, ordered by size (as listed in the config), then initialisation.
    pub rows: Vec<SweepRow>,
    /// The trained networks, parallel to `rows`.
    pub networks: Vec<Mlp>,
    /// Index into `rows`/`networks` of the chosen network.
    pub chosen: usize,
}

impl SweepResult {
    /// The chosen network.
    pub fn chosen_network(&self) -> &Mlp {
        &self.networks[self.chosen]
    }

    /// The chosen row.
    pub fn chosen_row(&self) -> &SweepRow {
        &self.rows[self.chosen]
    }
}

/// A finished run, reported to the sweep's progress callback (in completion order,
/// which depends on scheduling; results do not).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SweepProgress {
    /// Runs finished so far, including this one.
    pub done: usize,
    /// Total runs.
    pub total: usize,
    /// Hidden units of the finished run.
    pub hidden: usize,
    /// Initialisation index of the finished run.
    pub init: usize,
    /// Its test MSE.
    pub test_mse: f64,
}

/// Seed of run `(hidden, init)`: SplitMix64 mixing of the base seed, then the size, then
/// the index, so every run has its own well-separated stream whatever the thread that
/// trains it.
pub fn derive_seed(base: u64, hidden: usize, init: usize) -> u64 {
    fn mix(mut z: u64) -> u64 {
        // SplitMix64 finaliser (Steele, Lea & Flood, OOPSLA 2014).
        z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    mix(mix(mix(base) ^ hidden as u64) ^ init as u64)
}

/// Train `inits` networks of each size in `config.hidden_sizes` on the training data,
/// evaluate each on the test data, and choose one by [`SizingRule`].
///
/// Data are `channels × samples`. Every network's scalers are fitted to the training
/// data. Runs are spread over the current rayon pool; each run depends only on its seed,
/// so the result is bit-for-bit the same for any number of threads. `progress` is called
/// once per finished run, from worker threads.
///
/// Errors: invalid config, shape mismatch between the four matrices, zero samples,
/// non-finite data, a validation split that leaves a side empty, or no run with a finite
/// test MSE.
pub fn sizing_sweep(
    train_inputs: &DMatrix<f64>,
    train_targets: &DMatrix<f64>,
    test_inputs: &DMatrix<f64>,
    test_targets: &DMatrix<f64>,
    config: &SweepConfig,
    progress: Option<&(dyn Fn(SweepProgress) + Sync)>,
) -> Result<SweepResult> {
    config.validate()?;
    let (n, q) = (train_inputs.nrows(), train_targets.nrows());
    // Validate the data once (and the split) before spending any training time.
    let probe = Mlp::for_data(train_inputs, train_targets, &[1], 0)?;
    crate::lm::split_indices(train_inputs.ncols(), &config.lm.validation)?;
    check_shape("test inputs", test_inputs, n, test_inputs.ncols())?;
    check_shape("test targets", test_targets, q, test_inputs.ncols())?;
    if test_inputs.ncols() == 0 {
        return Err(NnError::TooFewSamples {
            what: "test data",
            found: 0,
            needed: 1,
        });
    }
    check_finite("test inputs", test_inputs)?;
    check_finite("test targets", test_targets)?;
    let (in_scaler, out_scaler) = (probe.input_scaler().clone(), probe.output_scaler().clone());

    let jobs: Vec<(usize, usize)> = config
        .hidden_sizes
        .iter()
        .flat_map(|&h| (0..config.inits).map(move |i| (h, i)))
        .collect();
    let total = jobs.len();
    let done = std::sync::atomic::AtomicUsize::new(0);
    let runs: Vec<Result<(SweepRow, Mlp)>> = jobs
        .par_iter()
        .map(|&(hidden, init)| {
            let seed = derive_seed(config.seed, hidden, init);
            let arch = crate::Architecture::single(n, hidden, q);
            let mut net =
                Mlp::new(&arch, seed)?.with_scalers(in_scaler.clone(), out_scaler.clone())?;
            let report = train_lm(&mut net, train_inputs, train_targets, &config.lm, None)?;
            let test_mse = net.mse(test_inputs, test_targets, config.lm.error_space)?;
            if let Some(cb) = progress {
                let done = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
                cb(SweepProgress {
                    done,
                    total,
                    hidden,
                    init,
                    test_mse,
                });
            }
            let row = SweepRow {
                hidden,
                init,
                seed,
                train_mse: report.train_mse,
                val_mse: report.val_mse,
                test_mse,
                epochs: report.epochs,
                termination: report.termination,
            };
            Ok((row, net))
        })
        .collect();
    let mut rows = Vec::with_capacity(total);
    let mut networks = Vec::with_capacity(total);
    for run in runs {
        let (row, net) = run?;
        rows.push(row);
        networks.push(net);
    }
    let chosen = select(&rows, &config.selection).ok_or(NnError::NoFiniteRun { runs: total })?;
    Ok(SweepResult {
        rows,
        networks,
        chosen,
    })
}

/// The rows inside the [`SizingRule`]'s band (finite test MSE at most
/// `best·(1 + rel) + abs`), with their indices.
fn in_band<'a>(
    rows: &'a [SweepRow],
    rule: &SizingRule,
) -> impl Iterator<Item = (usize, &'a SweepRow)> {
    let best = rows
        .iter()
        .map(|r| r.test_mse)
        .filter(|m| m.is_finite())
        .reduce(f64::min);
    let limit = best.map_or(f64::NEG_INFINITY, |b| {
        b * (1.0 + rule.rel_tolerance) + rule.abs_tolerance
    });
    rows.iter()
        .enumerate()
        .filter(move |(_, r)| r.test_mse.is_finite() && r.test_mse <= limit)
}

/// Indices of the sweep rows the [`SizingRule`] counts as equally good (inside its band),
/// in table order: the members [`crate::ensemble::average`] merges. Empty if no row has a
/// finite test MSE.
pub fn band_members(rows: &[SweepRow], rule: &SizingRule) -> Vec<usize> {
    in_band(rows, rule).map(|(i, _)| i).collect()
}

/// Apply the [`SizingRule`] to a sweep table; `None` if no row has a finite test MSE.
pub fn select(rows: &[SweepRow], rule: &SizingRule) -> Option<usize> {
    in_band(rows, rule)
        .min_by(|(_, a), (_, b)| {
            a.hidden
                .cmp(&b.hidden)
                .then(a.test_mse.total_cmp(&b.test_mse))
                .then(a.init.cmp(&b.init))
        })
        .map(|(i, _)| i)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(hidden: usize, init: usize, test_mse: f64) -> SweepRow {
        SweepRow {
            hidden,
            init,
            seed: 0,
            train_mse: 0.0,
            val_mse: None,
            test_mse,
            epochs: 0,
            termination: StopReason::MaxEpochs,
        }
    }

    #[test]
    fn band_members_by_hand() {
        let rows = vec![
            row(1, 0, 1.2),
            row(2, 0, 1.05),
            row(2, 1, f64::NAN),
            row(3, 0, 1.0),
            row(3, 1, 1.1),
        ];
        let rule = SizingRule {
            rel_tolerance: 0.1,
            abs_tolerance: 0.0,
        };
        assert_eq!(band_members(&rows, &rule), vec![1, 3, 4]);
        assert!(band_members(&[row(1, 0, f64::NAN)], &rule).is_empty());
    }

    #[test]
    fn selection_rule_by_hand() {
        // Best is 1.0 (size 5); band 1.1 admits size 3 (1.05 and 1.08) but not size 2 (1.2).
        let rows = vec![
            row(2, 0, 1.2),
            row(3, 0, 1.08),
            row(3, 1, 1.05),
            row(5, 0, 1.0),
            row(4, 0, f64::NAN),
        ];
        let rule = SizingRule {
            rel_tolerance: 0.1,
            abs_tolerance: 0.0,
        };
        assert_eq!(select(&rows, &rule), Some(2));
        // With no band the best network wins outright.
        assert_eq!(
            select(
                &rows,
                &SizingRule {
                    rel_tolerance: 0.0,
                    abs_tolerance: 0.0
                }
            ),
            Some(3)
        );
        assert_eq!(select(&[row(1, 0, f64::NAN)], &rule), None);
    }

    #[test]
    fn derived_seeds_are_distinct() {
        let mut seeds: Vec<u64> = (1..=10)
            .flat_map(|h| (0..10).map(move |i| derive_seed(7, h, i)))
            .collect();
        seeds.sort_unstable();
        seeds.dedup();
        assert_eq!(seeds.len(), 100);
        assert_ne!(derive_seed(7, 1, 2), derive_seed(7, 2, 1));
    }
}
