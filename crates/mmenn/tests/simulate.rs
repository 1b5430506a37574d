//! `mmenn simulate` for every system and recipe, read back by mmenn's own readers and
//! checked against the in-memory simulation it came from.

use std::path::PathBuf;
use std::process::Command;

use mmenn::data_file::{read_dataset, read_table};
use mmenn::plants::{self, Recipe, SimulationRequest};
use mmenn::{NoiseVariance, read_model};

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("mmenn-it-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

#[test]
fn every_system_and_recipe_round_trips_through_files() {
    for info in plants::systems() {
        for recipe in [Recipe::Train, Recipe::Test] {
            let request = SimulationRequest {
                system: info.name.to_string(),
                recipe,
                seed: 11,
                ..Default::default()
            };
            let sim = plants::simulate_system(&request).unwrap();
            let dir = scratch(&format!("{}-{recipe}", info.name));
            let files = mmenn::simulate::write_simulation(&sim, &dir).unwrap();

            // The model file reproduces the assumed model exactly.
            let spec = read_model(&files.model).unwrap();
            assert_eq!(spec.linear, sim.assumed.model, "{}", info.name);
            assert_eq!(
                spec.noise_variance,
                NoiseVariance::Given(sim.assumed.noise_variance.clone())
            );

            // The data file, read with the model's channel names, is the simulated dataset bit for bit.
            let data = read_dataset(
                std::slice::from_ref(&files.data),
                spec.linear.input_names(),
                spec.linear.output_names(),
                &spec.units,
            )
            .unwrap();
            let (a, b) = (&data.experiments()[0], &sim.data.experiments()[0]);
            assert_eq!(a.inputs(), b.inputs());
            assert_eq!(a.len(), b.len());
            for k in 0..a.len() {
                for (x, y) in a.output(k).iter().zip(b.output(k)) {
                    assert_eq!(x.to_bits(), y.to_bits());
                }
            }
            assert!(
                (a.dt() - b.dt()).abs() <= 1e-12 * b.dt(),
                "{}: dt {} vs {}",
                info.name,
                a.dt(),
                b.dt()
            );

            // truth.csv holds every state and a d_<state> column per corrected state.
            let truth = read_table(&files.truth).unwrap();
            for s in spec.linear.state_names() {
                assert!(
                    truth.column_index(s).is_some(),
                    "{}: truth lacks {s}",
                    info.name
                );
            }
            for s in spec.linear.correction_names() {
                assert!(
                    truth.column_index(&format!("d_{s}")).is_some(),
                    "{}: truth lacks d_{s}",
                    info.name
                );
            }
            // Measured minus true state is the noise: its variance matches the model file's
            // noise variance (sampling error of a variance estimate ~ sqrt(2/N); 5σ bound).
            for (i, name) in spec.linear.output_names().iter().enumerate() {
                let col = truth.column_index(name).unwrap();
                let n = a.len();
                let e: Vec<f64> = (0..n)
                    .map(|k| a.output(k)[i] - truth.columns[col][k])
                    .filter(|v| v.is_finite())
                    .collect();
                let var = e.iter().map(|v| v * v).sum::<f64>() / e.len() as f64;
                let want = sim.assumed.noise_variance[i];
                let tol = 5.0 * (2.0 / e.len() as f64).sqrt();
                assert!(
                    (var / want - 1.0).abs() < tol,
                    "{} {name}: noise variance {var} vs {want}",
                    info.name
                );
            }
            std::fs::remove_dir_all(&dir).unwrap();
        }
    }
}

#[test]
fn cli_lists_systems_and_reports_bad_requests() {
    let bin = env!("CARGO_BIN_EXE_mmenn");
    let out = Command::new(bin)
        .args(["simulate", "--list"])
        .output()
        .unwrap();
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    for info in plants::systems() {
        assert!(text.contains(info.name), "--list lacks {}", info.name);
    }
    let dir = scratch("cli-bad");
    let out = Command::new(bin)
        .args(["simulate", "--system", "no_such_plant", "--out"])
        .arg(&dir)
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("no_such_plant"));
    assert!(
        !dir.join("data.csv").exists(),
        "no output may be written on error"
    );

    let out = Command::new(bin)
        .args([
            "simulate", "--system", "pendulum", "--recipe", "test", "--fs", "50", "--seed", "3",
            "--out",
        ])
        .arg(&dir)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let spec = read_model(&dir.join("model.toml")).unwrap();
    let data = read_dataset(
        &[dir.join("data.csv")],
        spec.linear.input_names(),
        spec.linear.output_names(),
        &spec.units,
    )
    .unwrap();
    assert!((data.experiments()[0].dt() - 0.02).abs() < 1e-12);
    std::fs::remove_dir_all(&dir).unwrap();
}
