//! A whole `estimate` (MME with automatic W and, when the file says so, the noise
//! variance) on a fuzzed model file and a fuzzed CSV, kept tiny (at most 3 states and 64
//! samples) so that each run is short: a result or a typed error, never a panic or hang.
//! Input: the model text, a NUL byte, the CSV.
#![no_main]

use std::path::Path;

use libfuzzer_sys::fuzz_target;
use mmenn::data_file::{parse_table, table_to_experiment};
use mmenn::estimate::{EstimateOptions, compute_estimate};
use mmenn::model_file::parse_model;
use mmenn::sysid_core::{Channel, Dataset};

fuzz_target!(|bytes: &[u8]| {
    let Some(split) = bytes.iter().position(|&b| b == 0) else {
        return;
    };
    let Ok(text) = std::str::from_utf8(&bytes[..split]) else {
        return;
    };
    let Ok(spec) = parse_model(Path::new("m.toml"), text) else {
        return;
    };
    if spec.linear.n_states() > 3 {
        return;
    }
    let Ok(table) = parse_table(Path::new("d.csv"), &bytes[split + 1..]) else {
        return;
    };
    if table.lines.len() > 64 {
        return;
    }
    let (inputs, outputs) = (spec.linear.input_names(), spec.linear.output_names());
    let Ok(exp) = table_to_experiment(&table, inputs, outputs) else {
        return;
    };
    let channel = |n: &String| Channel {
        name: n.clone(),
        unit: None,
    };
    let Ok(data) = Dataset::new(
        inputs.iter().map(channel).collect(),
        outputs.iter().map(channel).collect(),
        vec![exp],
    ) else {
        return;
    };
    let opts = EstimateOptions {
        substeps: Some(4),
        ..EstimateOptions::default()
    };
    let _ = compute_estimate(&data, &spec, &opts, None);
});
