//! The model-file reader on arbitrary text; a model it accepts is printed back and read
//! again (the round trip must also succeed or fail with a typed error).
#![no_main]

use std::path::Path;

use libfuzzer_sys::fuzz_target;
use mmenn::model_file::{format_model, parse_model};

fuzz_target!(|text: &str| {
    if let Ok(spec) = parse_model(Path::new("m.toml"), text)
        && let Ok(printed) = format_model(&spec)
    {
        let _ = parse_model(Path::new("m.toml"), &printed);
    }
});
