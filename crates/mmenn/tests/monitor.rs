//! `mmenn monitor` on the thesis's mass–spring–damper damping classes (c ∈ {0.1, 0.15,
//! 0.2}): train on five noisy records per class, classify held-out records.

use std::path::PathBuf;

use mmenn::monitor::{FeatureKind, MonitorOptions, classify, train_monitor};
use mmenn::plants::{Recipe, SimulationRequest};
use mmenn::simulate::run_simulate;

#[test]
fn physical_features_tell_damping_conditions_apart() {
    let dir = std::env::temp_dir().join(format!("mmenn-monitor-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let classes = [0.1, 0.15, 0.2];
    let record = |c: f64, seed: u64| {
        let req = SimulationRequest {
            system: "msd_cubic".into(),
            recipe: Recipe::Train,
            seed,
            params: vec![("c".into(), c)],
            ..Default::default()
        };
        run_simulate(&req, &dir.join(format!("c{c}-s{seed}"))).unwrap()
    };
    let mut labelled: Vec<(String, Vec<PathBuf>)> = Vec::new();
    let mut model = PathBuf::new();
    for c in classes {
        let files: Vec<PathBuf> = (1..=5)
            .map(|s| record(c, s))
            .map(|o| {
                model = o.model.clone();
                o.data
            })
            .collect();
        labelled.push((format!("c={c}"), files));
    }
    let opts = MonitorOptions {
        features: FeatureKind::Physical,
        ..MonitorOptions::default()
    };
    let m = train_monitor(&labelled, &model, &opts, &dir.join("monitor")).unwrap();
    // The regression update identifies the damping coefficient directly, so the classes
    // separate: leave-one-out LDA error at most 1 record in 15.
    let lda = m.table.cell(0, 0).unwrap();
    assert!(
        lda.errors <= 1,
        "LDA misclassified {} of {}",
        lda.errors,
        lda.n
    );
    for (i, c) in classes.iter().enumerate() {
        let held_out = record(*c, 100 + i as u64);
        let verdict = classify(&dir.join("monitor"), &held_out.data).unwrap();
        assert_eq!(verdict.condition, format!("c={c}"), "{verdict:?}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}
