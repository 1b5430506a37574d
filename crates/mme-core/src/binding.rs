//! Matching a model's named inputs and outputs to a dataset's channels, by name.

use sysid_core::Dataset;

use crate::error::{MmeError, Result};

/// Where each model channel lives in the dataset.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct Binding {
    /// Model output `i` is dataset output row `outputs[i]`.
    pub outputs: Vec<usize>,
    /// Model input `l` is dataset input row `inputs[l]`.
    pub inputs: Vec<usize>,
    /// Observed (non-NaN) samples per model output, over all experiments.
    pub observed: Vec<usize>,
}

/// Bind model channel names to a dataset; every experiment needs at least 2 samples.
///
/// Extra dataset channels are ignored. A model channel missing from the dataset is
/// [`MmeError::UnknownChannel`].
pub(crate) fn bind(inputs: &[String], outputs: &[String], data: &Dataset) -> Result<Binding> {
    if data.experiments().is_empty() {
        return Err(MmeError::NoExperiments);
    }
    let find = |kind: &'static str, name: &String, list: Vec<String>| {
        list.iter()
            .position(|c| c == name)
            .ok_or_else(|| MmeError::UnknownChannel {
                kind,
                name: name.clone(),
            })
    };
    let out_names = data.output_names();
    let in_names = data.input_names();
    let outputs: Vec<usize> = outputs
        .iter()
        .map(|n| find("output", n, out_names.clone()))
        .collect::<Result<_>>()?;
    let inputs: Vec<usize> = inputs
        .iter()
        .map(|n| find("input", n, in_names.clone()))
        .collect::<Result<_>>()?;
    let mut observed = vec![0usize; outputs.len()];
    for (e, exp) in data.experiments().iter().enumerate() {
        if exp.len() < 2 {
            return Err(MmeError::TooFewSamples {
                experiment: e,
                found: exp.len(),
                needed: 2,
            });
        }
        for (i, &row) in outputs.iter().enumerate() {
            observed[i] += exp
                .outputs()
                .row(row)
                .iter()
                .filter(|v| !v.is_nan())
                .count();
        }
    }
    Ok(Binding {
        outputs,
        inputs,
        observed,
    })
}
