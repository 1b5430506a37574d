//! The hybrid `model.json` reader on arbitrary text.
#![no_main]

use std::path::Path;

use libfuzzer_sys::fuzz_target;

fuzz_target!(|text: &str| {
    let _ = mmenn::fit::HybridFile::parse(Path::new("model.json"), text);
});
