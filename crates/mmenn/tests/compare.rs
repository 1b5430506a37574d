//! `mmenn compare` on the single pendulum (thesis §5.2): four models, one free-run table;
//! and its linear columns on a record whose inputs are linear between samples.

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

/// A linear oscillator (the assumed model is the truth) driven by a band-limited input,
/// simulated with the input linear between samples: with `intersample = "foh"` the
/// "assumed model" and "linear OE" columns simulate it exactly, so their validation
/// RMSE is the measurement noise (σ = 0.01); with the hold they see the input half a
/// sample late. Measured: foh 0.0101 (assumed) / 0.0101 (OE); zoh 0.202 / 0.092 (the
/// OE fit absorbs part of the lag into its parameters). Bounds: the noise level within 3σ
/// of its estimate over 240 samples (+14 %), and the held columns at least twice as far
/// off as the interpolated ones (measured 20 times for the assumed model, 9 for OE).
#[test]
fn linear_columns_follow_the_first_order_hold() {
    use mmenn::sysid_core::{InterSample, TermModel};

    use crate::band_limited::{oscillator, record, write_spec};

    let dir = std::env::temp_dir().join(format!("mmenn-compare-foh-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let linear = oscillator();
    let truth = TermModel::new(linear.clone(), vec![]).unwrap();
    let (train, _) = record(&dir, &truth, "train", 480, 0.0, 1);
    let (val, _) = record(&dir, &truth, "val", 240, 0.8, 2);
    let run = |hold: InterSample| {
        let model = dir.join(format!("model_{hold:?}.toml"));
        write_spec(&model, &linear, hold);
        let opts = CompareOptions {
            fit: FitOptions {
                hidden: mmenn::fit::HiddenChoice::Fixed(2),
                inits: 2,
                ..FitOptions::default()
            },
            narx_lags: Some(4),
            ..CompareOptions::default()
        };
        let s = run_compare(
            std::slice::from_ref(&train),
            &model,
            std::slice::from_ref(&val),
            &opts,
            &dir.join(format!("cmp_{hold:?}")),
        )
        .unwrap();
        let val = s.validation.unwrap();
        let rmse = |label: &str| {
            val.rows()
                .iter()
                .find(|r| r.label == label)
                .unwrap()
                .evaluation
                .channel("x")
                .unwrap()
                .rmse
        };
        [rmse("assumed model"), rmse("linear OE")]
    };
    let foh = run(InterSample::Foh);
    let zoh = run(InterSample::Zoh);
    for (i, label) in ["assumed model", "linear OE"].iter().enumerate() {
        assert!(foh[i] < 0.0114, "{label}: foh RMSE {}", foh[i]);
        assert!(
            zoh[i] > 2.0 * foh[i],
            "{label}: zoh {} vs foh {}",
            zoh[i],
            foh[i]
        );
    }
    std::fs::remove_dir_all(&dir).unwrap();
}
