//! `mmenn estimate` and `mmenn compare` on measured data (Cascaded Tanks benchmark, read in
//! place from `../shared/data` or `MMENN_DATA_DIR`), with the noise variance estimated.

use std::path::PathBuf;

use mmenn::benchmarks::{Benchmark, DataDirSearch};
use mmenn::estimate::{EstimateOptions, run_estimate};

const MODEL: &str = r#"
states = ["x1", "y"]
inputs = ["u"]
A = [[-0.01, 0.0], [0.01, -0.01]]
B = [[0.01], [0.0]]
measured = ["y"]
corrected = ["x1", "y"]
noise_variance = "auto"
units = { y = "V", u = "V" }
"#;

#[test]
#[allow(clippy::print_stderr)]
fn cascaded_tanks_with_estimated_noise() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..");
    let Ok(folder) = DataDirSearch::from_env(None, Some(root)).locate(Benchmark::CascadedTanks)
    else {
        eprintln!(
            "SKIPPED: the Cascaded Tanks data folder is absent (set MMENN_DATA_DIR or provide ../shared/data)"
        );
        return;
    };
    let dir = std::env::temp_dir().join(format!("mmenn-real-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("model.toml"), MODEL).unwrap();
    let s = run_estimate(
        &[folder.join("estimation.csv")],
        &dir.join("model.toml"),
        &EstimateOptions::default(),
        &dir.join("est"),
    )
    .unwrap();
    // The benchmark states an output SNR near 40 dB on a level of a few volts: the noise
    // variance must be positive and below (0.1 V)², and the covariance constraint met.
    let nv = s.noise_variance["y"];
    assert!(nv > 0.0 && nv < 1e-2, "noise variance {nv}");
    assert!(
        (s.residual_to_noise["y"] - 1.0).abs() < 0.1,
        "ratio {}",
        s.residual_to_noise["y"]
    );
    std::fs::remove_dir_all(&dir).unwrap();
}
