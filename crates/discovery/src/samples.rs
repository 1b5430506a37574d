//! The data discovery works on, per experiment: smooth state estimates `x̂` (`n × N`), the
//! inputs (`m × N`) and the model correction `d̂` (`q × N`) at the sample times — built
//! from an MME estimate, or given directly (e.g. a plant's truth correction in tests).

use nalgebra::DMatrix;
use sysid_core::{Dataset, ExperimentEstimate, MmeEstimate};

use crate::error::{DiscoveryError, Result};

/// One experiment's states, inputs and corrections at the sample times.
#[derive(Debug, Clone, PartialEq)]
pub struct Samples {
    states: DMatrix<f64>,
    inputs: DMatrix<f64>,
    corrections: DMatrix<f64>,
}

impl Samples {
    /// Combine states (`n × N`), inputs (`m × N`) and corrections (`q × N`). Errors when
    /// the sample counts differ or a value is not finite (named by matrix, row and sample;
    /// the experiment index is reported as 0 — [`crate::propose()`] re-checks with the real
    /// index).
    pub fn new(
        states: DMatrix<f64>,
        inputs: DMatrix<f64>,
        corrections: DMatrix<f64>,
    ) -> Result<Self> {
        let s = Self {
            states,
            inputs,
            corrections,
        };
        s.check(0, s.states.nrows(), s.inputs.nrows(), s.corrections.nrows())?;
        Ok(s)
    }

    /// From one experiment of an MME estimate and that experiment's inputs (`m × N`),
    /// with the correction centred on the samples ([`centred_corrections`]).
    pub fn from_estimate(estimate: &ExperimentEstimate, inputs: &DMatrix<f64>) -> Result<Self> {
        Self::new(
            estimate.states.clone(),
            inputs.clone(),
            centred_corrections(estimate),
        )
    }

    /// Number of samples `N`.
    pub fn len(&self) -> usize {
        self.states.ncols()
    }

    /// True when there are no samples.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// States `n × N`.
    pub fn states(&self) -> &DMatrix<f64> {
        &self.states
    }

    /// Inputs `m × N`.
    pub fn inputs(&self) -> &DMatrix<f64> {
        &self.inputs
    }

    /// Corrections `q × N`.
    pub fn corrections(&self) -> &DMatrix<f64> {
        &self.corrections
    }

    /// Check shapes against a model (`n` states, `m` inputs, `q` corrections) and that
    /// every value is finite.
    pub(crate) fn check(&self, experiment: usize, n: usize, m: usize, q: usize) -> Result<()> {
        let len = self.states.ncols();
        for (what, mat, rows) in [
            ("states", &self.states, n),
            ("inputs", &self.inputs, m),
            ("corrections", &self.corrections, q),
        ] {
            if mat.nrows() != rows || mat.ncols() != len {
                return Err(DiscoveryError::Shape {
                    what,
                    experiment,
                    rows: mat.nrows(),
                    cols: mat.ncols(),
                    expected_rows: rows,
                    expected_cols: len,
                });
            }
            for k in 0..len {
                for r in 0..rows {
                    if !mat[(r, k)].is_finite() {
                        return Err(DiscoveryError::NonFinite {
                            what,
                            experiment,
                            row: r,
                            sample: k,
                        });
                    }
                }
            }
        }
        Ok(())
    }

    /// The values of state-or-input variable `v` (index into states then inputs) at
    /// sample `k`, as `(x, u)` slices.
    pub(crate) fn point(&self, k: usize) -> (&[f64], &[f64]) {
        let n = self.states.nrows();
        let m = self.inputs.nrows();
        (
            &self.states.as_slice()[k * n..(k + 1) * n],
            &self.inputs.as_slice()[k * m..(k + 1) * m],
        )
    }
}

/// The correction at each sample time, averaged over the half-interval on either side of
/// it: sample `k` takes the time-weighted mean of the pieces overlapping
/// `[t_k − dt/2, t_k + dt/2]` (clipped to the record), `q × N`.
///
/// MME's pieces are held on `[t0 + j·h, t0 + (j+1)·h)` with `h = dt/substeps`; the piece
/// that *starts* at `t_k` ([`ExperimentEstimate::corrections_at_samples`]) is centred
/// half a sub-step later, which lags `d̂` behind `x̂(t_k)` by up to half a sample when
/// `substeps = 1`. The centred mean removes that lag.
pub fn centred_corrections(estimate: &ExperimentEstimate) -> DMatrix<f64> {
    let q = estimate.corrections.nrows();
    let len = estimate.len();
    let pieces = estimate.corrections.ncols();
    let s = estimate.substeps.max(1) as f64;
    let mut out = DMatrix::zeros(q, len);
    if pieces == 0 {
        return out;
    }
    let total = pieces as f64;
    for k in 0..len {
        let a = (k as f64 * s - 0.5 * s).max(0.0);
        let b = (k as f64 * s + 0.5 * s).min(total);
        if b <= a {
            // Only when the record has more samples than its pieces cover.
            let j = pieces - 1;
            for i in 0..q {
                out[(i, k)] = estimate.corrections[(i, j)];
            }
            continue;
        }
        let first = a.floor() as usize;
        let last = (b.ceil() as usize).min(pieces);
        let mut weight = 0.0;
        for j in first..last {
            let w = b.min(j as f64 + 1.0) - a.max(j as f64);
            if w <= 0.0 {
                continue;
            }
            weight += w;
            for i in 0..q {
                out[(i, k)] += w * estimate.corrections[(i, j)];
            }
        }
        for i in 0..q {
            out[(i, k)] /= weight;
        }
    }
    out
}

/// One [`Samples`] per experiment of an MME estimate over `data` (inputs from the
/// dataset, corrections centred on the samples).
pub fn samples_from_estimate(estimate: &MmeEstimate, data: &Dataset) -> Result<Vec<Samples>> {
    let exps = data.experiments();
    if exps.len() != estimate.experiments.len() {
        return Err(DiscoveryError::Length {
            what: "experiments of the estimate vs the dataset",
            found: estimate.experiments.len(),
            expected: exps.len(),
        });
    }
    estimate
        .experiments
        .iter()
        .zip(exps)
        .enumerate()
        .map(|(e, (est, exp))| {
            if est.len() != exp.len() {
                return Err(DiscoveryError::Shape {
                    what: "estimated states",
                    experiment: e,
                    rows: est.states.nrows(),
                    cols: est.len(),
                    expected_rows: est.states.nrows(),
                    expected_cols: exp.len(),
                });
            }
            let s = Samples::from_estimate(est, exp.inputs());
            s.map_err(|err| match err {
                DiscoveryError::NonFinite {
                    what, row, sample, ..
                } => DiscoveryError::NonFinite {
                    what,
                    experiment: e,
                    row,
                    sample,
                },
                other => other,
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn estimate(substeps: usize, pieces: &[f64]) -> ExperimentEstimate {
        let len = pieces.len() / substeps + 1;
        ExperimentEstimate {
            t0: 0.0,
            dt: 0.1,
            substeps,
            states: DMatrix::zeros(1, len),
            corrections: DMatrix::from_row_slice(1, pieces.len(), pieces),
        }
    }

    /// With one piece per interval, inner samples average the two neighbouring pieces and
    /// the ends take the single piece they touch (hand-computed).
    #[test]
    fn centred_mean_of_neighbouring_pieces() {
        let d = centred_corrections(&estimate(1, &[1.0, 3.0, 7.0]));
        assert_eq!(d.as_slice(), &[1.0, 2.0, 5.0, 7.0]);
        // Two pieces per interval: sample 1 covers pieces 1 and 2 fully.
        let d = centred_corrections(&estimate(2, &[1.0, 2.0, 4.0, 8.0]));
        assert_eq!(d.as_slice(), &[1.0, 3.0, 8.0]);
    }

    /// A correction linear in time is sampled without lag: the centred mean of a linear
    /// function over a symmetric window is its value at the centre.
    #[test]
    fn linear_correction_has_no_lag() {
        let (s, dt) = (4usize, 0.1);
        let pieces: Vec<f64> = (0..40)
            .map(|j| 2.0 * (j as f64 + 0.5) * dt / s as f64)
            .collect();
        let d = centred_corrections(&estimate(s, &pieces));
        for k in 1..10 {
            assert!(
                (d[(0, k)] - 2.0 * k as f64 * dt).abs() < 1e-12,
                "sample {k}"
            );
        }
    }

    /// An estimate over a dataset: inputs come from the data, corrections are centred, and
    /// a record-length mismatch names the experiment.
    #[test]
    fn samples_from_an_mme_estimate() {
        use sysid_core::{Channel, Experiment, SolveReport};
        let exp = |len: usize| {
            Experiment::new(
                0.0,
                0.1,
                DMatrix::from_fn(1, len, |_, k| k as f64),
                DMatrix::zeros(1, len),
            )
            .unwrap_or_else(|e| panic!("{e}"))
        };
        let data = Dataset::new(
            vec![Channel::new("u")],
            vec![Channel::new("y")],
            vec![exp(4)],
        )
        .unwrap_or_else(|e| panic!("{e}"));
        let mut est = MmeEstimate {
            state_names: vec!["x".into()],
            correction_names: vec!["x".into()],
            output_names: vec!["y".into()],
            experiments: vec![estimate(1, &[1.0, 3.0, 7.0])],
            w: DMatrix::identity(1, 1),
            noise_variance: vec![1.0],
            residual_variance: vec![1.0],
            cost: 0.0,
            report: SolveReport::default(),
        };
        let s = samples_from_estimate(&est, &data).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(s[0].inputs().as_slice(), &[0.0, 1.0, 2.0, 3.0]);
        assert_eq!(s[0].corrections().as_slice(), &[1.0, 2.0, 5.0, 7.0]);
        est.experiments[0] = estimate(1, &[1.0, 3.0]);
        assert!(matches!(
            samples_from_estimate(&est, &data),
            Err(DiscoveryError::Shape { experiment: 0, .. })
        ));
    }

    #[test]
    fn shapes_and_values_are_checked() {
        let ok = Samples::new(
            DMatrix::zeros(2, 5),
            DMatrix::zeros(1, 5),
            DMatrix::zeros(1, 5),
        );
        assert!(ok.is_ok());
        let short = Samples::new(
            DMatrix::zeros(2, 5),
            DMatrix::zeros(1, 4),
            DMatrix::zeros(1, 5),
        );
        assert!(matches!(
            short,
            Err(DiscoveryError::Shape { what: "inputs", .. })
        ));
        let mut x = DMatrix::zeros(2, 5);
        x[(1, 3)] = f64::NAN;
        let bad = Samples::new(x, DMatrix::zeros(1, 5), DMatrix::zeros(1, 5));
        assert!(matches!(
            bad,
            Err(DiscoveryError::NonFinite {
                what: "states",
                row: 1,
                sample: 3,
                ..
            })
        ));
    }
}
