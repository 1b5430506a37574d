//! The model file's optional `[acquisition]` table: the filter a record's input and output
//! channels share ([`sysid_core::acquisition::AcquisitionFilter`]), carried with the model
//! so that every command judging it applies the same measurement model
//! `y_meas = Ã·N(Ã⁻¹·u_meas)`:
//!
//! ```toml
//! [acquisition]
//! pass_below_hz = 190.0
//! bands = [[202.5, 0.90, -0.46], [207.5, 0.72, -0.55, 0.02]]   # centre Hz, real, imaginary
//! ```
//!
//! A band's optional fourth number is the standard error of its complex gain, as
//! [`AcquisitionFilter::estimate`] gives it; `show` prints it, nothing judges with it.
//!
//! The response is one up to `pass_below_hz`, linear in real and imaginary parts between
//! it and the band centres, held past the last centre. Centres must increase from above
//! `pass_below_hz`; every number must be finite; the response must stay away from zero
//! (its inverse deconvolves the records).
//!
//! A model with the table is judged on each record with its inputs *and* outputs passed
//! through the filter's inverse (the system's own signals under the measurement model:
//! the initial state is fitted and the model run there) and its simulated outputs passed
//! through the filter before they are scored against the recorded outputs, printed or
//! written ([`crate::model::judge_free_run`]); `fit` deconvolves its training and
//! validation records before MME, the network sweep, the guard and trajectory training.

use nalgebra::{Complex, DMatrix};
use serde::{Deserialize, Serialize};
use sysid_core::acquisition::AcquisitionFilter;
use sysid_core::{Dataset, Experiment};

use crate::error::{MmennError, ModelProblem, Result};

/// The closest the response may come to zero (its inverse deconvolves the records).
pub const MIN_GAIN: f64 = 1e-9;

/// `[acquisition]` as written in the file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct AcquisitionToml {
    pass_below_hz: f64,
    bands: Vec<Vec<f64>>,
}

fn problem(key: &'static str, row: Option<usize>, reason: String) -> ModelProblem {
    ModelProblem::Acquisition { key, row, reason }
}

/// The smallest modulus on the segment from `a` to `b` in the complex plane.
fn closest_to_zero(a: Complex<f64>, b: Complex<f64>) -> f64 {
    let d = b - a;
    let len2 = d.norm_sqr();
    let s = if len2 > 0.0 {
        (-(a.re * d.re + a.im * d.im) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (a + d * s).norm()
}

impl AcquisitionToml {
    /// The table of a filter (round-trips exactly: TOML writes each number's shortest
    /// exact form).
    pub(crate) fn of(filter: &AcquisitionFilter) -> Self {
        Self {
            pass_below_hz: filter.pass_below_hz(),
            bands: filter
                .bands()
                .iter()
                .zip(filter.standard_errors())
                .map(|(&(c, g), se)| match se {
                    Some(se) => vec![c, g.re, g.im, *se],
                    None => vec![c, g.re, g.im],
                })
                .collect(),
        }
    }

    /// The filter the table describes. Errors name the key and, for a band, its row
    /// (0-based): a row not of three numbers, a number that is not finite, a centre not
    /// above `pass_below_hz` or not above the previous row's, a response that reaches
    /// zero.
    pub(crate) fn filter(&self) -> Result<AcquisitionFilter, ModelProblem> {
        let pass = self.pass_below_hz;
        if !(pass.is_finite() && pass >= 0.0) {
            return Err(problem(
                "acquisition.pass_below_hz",
                None,
                format!("{pass} must be finite and non-negative"),
            ));
        }
        let mut bands = Vec::with_capacity(self.bands.len());
        let mut errors = Vec::with_capacity(self.bands.len());
        let mut last = (pass, Complex::new(1.0, 0.0));
        for (row, entry) in self.bands.iter().enumerate() {
            let bad = |reason: String| Err(problem("acquisition.bands", Some(row), reason));
            let (c, re, im, se) = match *entry.as_slice() {
                [c, re, im] => (c, re, im, None),
                [c, re, im, se] => (c, re, im, Some(se)),
                _ => {
                    return bad(format!(
                        "has {} numbers, expected 3 (centre Hz, real part, imaginary part) \
                         or 4 (and the gain's standard error)",
                        entry.len()
                    ));
                }
            };
            if let Some(v) = [c, re, im]
                .iter()
                .chain(se.as_ref())
                .find(|v| !v.is_finite())
            {
                return bad(format!("{v} is not a finite number"));
            }
            if let Some(se) = se.filter(|v| *v < 0.0) {
                return bad(format!("standard error {se} must not be negative"));
            }
            errors.push(se);
            if c <= last.0 {
                return bad(if row == 0 {
                    format!("centre {c} Hz must lie above pass_below_hz ({pass} Hz)")
                } else {
                    format!(
                        "centre {c} Hz must lie above the previous row's ({} Hz): centres increase",
                        last.0
                    )
                });
            }
            let g = Complex::new(re, im);
            if closest_to_zero(last.1, g) < MIN_GAIN {
                return bad(format!(
                    "the response reaches zero (below {MIN_GAIN}) between {} Hz and this centre: \
                     the filter has no usable inverse",
                    last.0
                ));
            }
            bands.push((c, g));
            last = (c, g);
        }
        AcquisitionFilter::from_bands(pass, bands)
            .and_then(|f| f.with_standard_errors(errors))
            .map_err(ModelProblem::Model)
    }
}

fn core(context: &'static str) -> impl FnOnce(sysid_core::CoreError) -> MmennError {
    move |source| MmennError::Core { context, source }
}

/// Each row of `m` (channels × samples, every `dt` s) through the filter, or through its
/// inverse.
pub fn filter_rows(
    filter: &AcquisitionFilter,
    m: &DMatrix<f64>,
    dt: f64,
    inverse: bool,
) -> Result<DMatrix<f64>> {
    let mut out = DMatrix::zeros(m.nrows(), m.ncols());
    for i in 0..m.nrows() {
        let x: Vec<f64> = m.row(i).iter().copied().collect();
        let y = if inverse {
            filter.apply_inverse(&x, dt)
        } else {
            filter.apply(&x, dt)
        }
        .map_err(core("the model's acquisition filter"))?;
        for (k, v) in y.into_iter().enumerate() {
            out[(i, k)] = v;
        }
    }
    Ok(out)
}

/// `exp` with its inputs and outputs through the filter's inverse (its `intersample`
/// kept): the system's own signals under the measurement model. `outputs` names its
/// output rows in errors: every output sample must be present (a missing one, NaN, would
/// spread over the filter's length).
pub fn deconvolved(
    filter: &AcquisitionFilter,
    exp: &Experiment,
    outputs: &[String],
) -> Result<Experiment> {
    let y = exp.outputs();
    for i in 0..y.nrows() {
        if let Some(sample) = y.row(i).iter().position(|v| v.is_nan()) {
            return Err(MmennError::AcquisitionMissing {
                channel: outputs
                    .get(i)
                    .cloned()
                    .unwrap_or_else(|| format!("output {i}")),
                sample,
            });
        }
    }
    let dt = exp.dt();
    let inputs = filter_rows(filter, exp.inputs(), dt, true)?;
    let outputs = filter_rows(filter, y, dt, true)?;
    Ok(Experiment::new(exp.t0(), dt, inputs, outputs)
        .map_err(core(
            "the record deconvolved by the model's acquisition filter",
        ))?
        .with_intersample(exp.intersample()))
}

/// Every record of `data` [`deconvolved`] (each keeps its `intersample`).
pub fn deconvolved_dataset(filter: &AcquisitionFilter, data: &Dataset) -> Result<Dataset> {
    let names = data.output_names();
    let experiments = data
        .experiments()
        .iter()
        .map(|e| deconvolved(filter, e, &names))
        .collect::<Result<Vec<_>>>()?;
    Dataset::new(
        data.input_channels().to_vec(),
        data.output_channels().to_vec(),
        experiments,
    )
    .map_err(core(
        "the records deconvolved by the model's acquisition filter",
    ))
}
