//! `mmenn compare` on the single pendulum (thesis §5.2): four models, one free-run table.

use mmenn::compare::{CompareOptions, run_compare};
use mmenn::fit::FitOptions;
use mmenn::plants::{Recipe, SimulationRequest};
use mmenn::simulate::run_simulate;
use mmenn::sysid_core::Horizon;

#[test]
fn four_models_on_one_free_run_table() {
    let dir = std::env::temp_dir().join(format!("mmenn-compare-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let req = |recipe| SimulationRequest {
        system: "pendulum".into(),
        recipe,
        seed: 3,
        ..Default::default()
    };
    let train = run_simulate(&req(Recipe::Train), &dir.join("train")).unwrap();
    let test = run_simulate(&req(Recipe::Test), &dir.join("test")).unwrap();
    let opts = CompareOptions {
        fit: FitOptions {
            max_hidden: 5,
            inits: 3,
            ..FitOptions::default()
        },
        narx_lags: Some(6),
        ..CompareOptions::default()
    };
    let s = run_compare(
        std::slice::from_ref(&train.data),
        &train.model,
        std::slice::from_ref(&test.data),
        &opts,
        &dir.join("cmp"),
    )
    .unwrap();
    let val = s.validation.as_ref().unwrap();
    assert_eq!(val.horizon(), Horizon::FreeRun);
    let r2 = |label: &str| {
        val.rows()
            .iter()
            .find(|r| r.label == label)
            .unwrap()
            .evaluation
            .channel("theta")
            .unwrap()
            .r2
    };
    // The linearised model cannot follow large swings; the hybrid model can (thesis
    // Table 5-1). With this noise (σ = 0.1 rad) the hybrid's test R² varies with the noise
    // realisation (0.93–1.00 seen over seeds), so the check is the thesis's ranking.
    assert!(r2("MME/NN") > 0.9, "MME/NN validation R² {}", r2("MME/NN"));
    assert!(r2("MME/NN") > r2("assumed model") && r2("MME/NN") > r2("linear OE"));
    for f in [
        "compare.json",
        "report.md",
        "compare_validation_theta.svg",
        "residual_acf_MME_NN_theta.svg",
    ] {
        assert!(dir.join("cmp").join(f).exists(), "missing {f}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}
