//! `d̂` against each network input (every state and input) with the network's output at
//! the same training pairs overlaid: where the learnt correction follows MME's estimate
//! and where it does not, in the variables a reader thinks in.

use std::path::Path;

use nalgebra::DMatrix;

use crate::error::Result;
use crate::model_file::ModelSpec;
use crate::plot::{Figure, Series};

/// `name (unit)`, or the name alone without a unit.
fn with_unit(name: &str, spec: &ModelSpec) -> String {
    match spec.unit_of(name) {
        Some(u) => format!("{name} ({u})"),
        None => name.to_string(),
    }
}

/// Write `nn_d_<correction>_vs_<variable>.svg` for every row of `x` (named by
/// `variables`); `d` and `pred` are MME's `d̂` and the network's output of one correction
/// at the same columns of `x`. Returns the file names.
pub(crate) fn d_against_variables(
    correction: &str,
    d: &[f64],
    pred: &[f64],
    x: &DMatrix<f64>,
    variables: &[String],
    spec: &ModelSpec,
    out: &Path,
) -> Result<Vec<String>> {
    let mut files = Vec::new();
    let d_name = format!("d_{correction}");
    for (j, var) in variables.iter().enumerate().take(x.nrows()) {
        let xs: Vec<f64> = x.row(j).iter().copied().collect();
        let fig = Figure {
            title: format!("{d_name} against {var}: MME estimate and network"),
            x_label: with_unit(var, spec),
            y_label: with_unit(&d_name, spec),
            series: vec![
                Series::points("MME d̂", xs.clone(), d.to_vec()),
                Series::points("NN(x̂, u) at the same samples", xs, pred.to_vec()),
            ],
            bands: vec![],
        };
        let file = format!("nn_{d_name}_vs_{var}.svg");
        fig.write(&out.join(&file))?;
        files.push(file);
    }
    Ok(files)
}
