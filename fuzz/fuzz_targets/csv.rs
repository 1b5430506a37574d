//! The CSV reader on arbitrary bytes: a table or a typed error, then an experiment from
//! its columns or a typed error.
#![no_main]

use std::path::Path;

use libfuzzer_sys::fuzz_target;
use mmenn::data_file::{parse_table, table_to_experiment};

fuzz_target!(|bytes: &[u8]| {
    if let Ok(table) = parse_table(Path::new("d.csv"), bytes) {
        let names: Vec<String> = table.header.iter().filter(|n| *n != "t").cloned().collect();
        let (inputs, outputs) = names.split_at(names.len().min(1));
        let _ = table_to_experiment(&table, inputs, outputs);
    }
});
