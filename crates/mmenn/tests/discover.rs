//! `mmenn discover` on data in which an effect is hidden from the assumed model: it must
//! name the effect, calibrate its coefficient, and show the gap shrink; run again on its
//! own augmented model it must find nothing more.

use std::path::PathBuf;

use mmenn::discover::{DiscoverOptions, run_discover};
use mmenn::plants::{Recipe, SimulationRequest};
use mmenn::simulate::run_simulate;

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("mmenn-discover-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

fn coefficient(s: &mmenn::discover::DiscoverSummary, name: &str) -> f64 {
    s.effects
        .iter()
        .find(|e| e.name == name)
        .unwrap_or_else(|| panic!("{name} not named: {:?}", s.effects))
        .coefficient
}

#[test]
fn cubic_spring_and_damping_hidden_from_the_msd_model() {
    // Truth m ẍ + c ẋ + k(x + x³) = u (m = 1, c = 0.1, k = 0.5); the assumed model has
    // only the linear spring, so the missing correction is −0.5·x³ − 0.1·v.
    let dir = scratch("msd");
    let req = |recipe| SimulationRequest {
        system: "msd_cubic".into(),
        recipe,
        seed: 2,
        ..Default::default()
    };
    let train = run_simulate(&req(Recipe::Train), &dir.join("train")).unwrap();
    let test = run_simulate(&req(Recipe::Test), &dir.join("test")).unwrap();
    let s = run_discover(
        std::slice::from_ref(&train.data),
        &train.model,
        std::slice::from_ref(&test.data),
        &DiscoverOptions::default(),
        &dir.join("out"),
    )
    .unwrap();
    assert_eq!(format!("{:?}", s.verdict), "Found");
    assert_eq!(s.effects.len(), 2, "{:?}", s.effects);
    // Noise variance 0.09 m² on 1001 samples: calibrated coefficients within a few percent.
    let k3 = coefficient(&s, "cubic_stiffness");
    let c = coefficient(&s, "viscous_damping");
    assert!((k3 + 0.5).abs() < 0.025, "cubic coefficient {k3}");
    assert!((c + 0.1).abs() < 0.01, "damping coefficient {c}");
    let (b, a) = (&s.gap.before, &s.gap.after);
    assert!(
        a.fit_percent["x"] > b.fit_percent["x"] + 50.0,
        "fit {} → {}",
        b.fit_percent["x"],
        a.fit_percent["x"]
    );
    assert!(a.d_rms["v"] < 0.1 * b.d_rms["v"]);
    let v = s.validation_gap.as_ref().unwrap();
    assert!(
        v.after.rmse["x"] < 0.2 * v.before.rmse["x"],
        "validation RMSE {} → {}",
        v.before.rmse["x"],
        v.after.rmse["x"]
    );

    // The augmented model explains the data: a second run finds no significant missing effect.
    let again = run_discover(
        std::slice::from_ref(&train.data),
        &dir.join("out/model.discovered.toml"),
        &[],
        &DiscoverOptions::default(),
        &dir.join("again"),
    )
    .unwrap();
    assert_eq!(
        format!("{:?}", again.verdict),
        "None",
        "{:?}",
        again.effects
    );
    assert!(again.effects.is_empty());
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn gravity_nonlinearity_hidden_from_the_linearised_pendulum() {
    // At the system's default noise (σ² = 0.01 rad², σ = 0.1 rad) and at 1e-4 rad².
    for noise in [None, Some(1e-4)] {
        let dir = scratch(&format!("pendulum-{noise:?}"));
        let req = SimulationRequest {
            system: "pendulum".into(),
            recipe: Recipe::Train,
            seed: 4,
            noise_variance: noise,
            ..Default::default()
        };
        let train = run_simulate(&req, &dir.join("train")).unwrap();
        let s = run_discover(
            std::slice::from_ref(&train.data),
            &train.model,
            &[],
            &DiscoverOptions::default(),
            &dir.join("out"),
        )
        .unwrap();
        // θ̈ = −(g/l) sin θ − … − (1/l) cos θ·u with g/l = 19.62, 1/l = 2: the linearised
        // model misses −19.62·(sin θ − θ) and −2·(u cos θ − u).
        let mut names: Vec<&str> = s.effects.iter().map(|e| e.name.as_str()).collect();
        names.sort_unstable();
        assert_eq!(
            names,
            ["gravity_nonlinearity", "input_coupling_cos"],
            "{noise:?}"
        );
        let g = coefficient(&s, "gravity_nonlinearity");
        let u = coefficient(&s, "input_coupling_cos");
        assert!((g + 19.62).abs() < 0.02 * 19.62, "gravity coefficient {g}");
        assert!(
            (u + 2.0).abs() < 0.05 * 2.0,
            "input coupling coefficient {u}"
        );
        assert!(s.gap.after.d_rms["omega"] < 0.1 * s.gap.before.d_rms["omega"]);
        let text = std::fs::read_to_string(dir.join("out/model.discovered.toml")).unwrap();
        assert!(text.contains("sin(theta) - theta"));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}

#[test]
fn gravity_coupling_and_coulomb_hidden_from_the_compound_pendulum_rig() {
    compound_pendulum_rig(true);
}

/// Without validation records the second half of the estimation record judges the
/// search (on the training cost alone, viscous + v|v| + Stribeck mimicked Coulomb).
#[test]
fn compound_pendulum_rig_without_validation_records() {
    compound_pendulum_rig(false);
}

fn compound_pendulum_rig(with_validation: bool) {
    // Truth (l = 0.4 m, m = 0.25 kg, I = m l²/3): θ̈ = −(3g/2l) sin θ − (b/I) ω
    // − (τc/I) tanh(ω/ε) − (3/2l) cos θ·u. The assumed model is its linearisation with the
    // viscous term, so the missing correction is −36.79·(sin θ − θ) − 3.75·(u cos θ − u)
    // − 0.375·tanh(ω/ε); only θ is measured (σ² = 1e-5 rad²).
    let dir = scratch(if with_validation {
        "compound"
    } else {
        "compound-noval"
    });
    let req = |recipe, seed| SimulationRequest {
        system: "compound_pendulum".into(),
        recipe,
        seed,
        ..Default::default()
    };
    let train = run_simulate(&req(Recipe::Train, 1), &dir.join("train")).unwrap();
    let test = run_simulate(&req(Recipe::Test, 2), &dir.join("test")).unwrap();
    let s = run_discover(
        std::slice::from_ref(&train.data),
        &train.model,
        if with_validation {
            std::slice::from_ref(&test.data)
        } else {
            &[]
        },
        &DiscoverOptions::default(),
        &dir.join("out"),
    )
    .unwrap();
    assert_eq!(format!("{:?}", s.verdict), "Found", "{:?}", s.unconfirmed);
    let mut names: Vec<&str> = s.effects.iter().map(|e| e.name.as_str()).collect();
    names.sort_unstable();
    assert_eq!(
        names,
        [
            "coulomb_friction_smooth",
            "gravity_nonlinearity",
            "input_coupling_cos"
        ],
        "{:?}",
        s.effects
    );
    for (name, truth) in [
        ("gravity_nonlinearity", -36.7875),
        ("input_coupling_cos", -3.75),
        ("coulomb_friction_smooth", -0.375),
    ] {
        let c = coefficient(&s, name);
        assert!(
            (c - truth).abs() < 0.01 * truth.abs(),
            "{name}: {c} vs {truth}"
        );
    }
    if let Some(v) = &s.validation_gap {
        assert!(v.after.rmse["theta"] < 0.1 * v.before.rmse["theta"]);
    }
    assert_eq!(s.validation_gap.is_some(), with_validation);
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A band-limited input sampled 12.6 times per period of a lightly damped oscillator
/// (ẍ = −4x − 0.4ẋ + u − x³, x measured, σ = 0.01): the truth is simulated with the input
/// linear between samples. With `intersample = "foh"` in the model file the cubic spring
/// must be found, its interval covering −1, and the held-out record simulated to its
/// noise level; holding the same samples (`zoh`, the default) delays the input by half a
/// sample (0.25 rad at ω = 2), which no catalogue term can undo, and the validation error
/// after discovery must stay at least twice the `foh` one.
#[test]
fn band_limited_input_needs_the_first_order_hold() {
    use mmenn::sysid_core::{InterSample, TermModel};

    use crate::band_limited::{oscillator, record, write_spec};

    let linear = oscillator();
    let truth =
        TermModel::from_specs(linear.clone(), [("v", "cubic_stiffness", "x^3", -1.0)]).unwrap();
    let dir = scratch("foh");
    std::fs::create_dir_all(&dir).unwrap();
    let (train, _) = record(&dir, &truth, "train", 480, 0.0, 1);
    let (val, _) = record(&dir, &truth, "val", 240, 0.8, 2);
    let run = |hold: InterSample| {
        let model = dir.join(format!("model_{hold:?}.toml"));
        write_spec(&model, &linear, hold);
        run_discover(
            std::slice::from_ref(&train),
            &model,
            std::slice::from_ref(&val),
            &DiscoverOptions::default(),
            &dir.join(format!("out_{hold:?}")),
        )
        .unwrap()
    };
    let foh = run(InterSample::Foh);
    assert_eq!(
        format!("{:?}", foh.verdict),
        "Found",
        "{:?}",
        foh.unconfirmed
    );
    let names: Vec<&str> = foh.effects.iter().map(|e| e.name.as_str()).collect();
    assert_eq!(names, ["cubic_stiffness"], "{:?}", foh.effects);
    let [lo, hi] = foh.effects[0].ci95.unwrap();
    assert!(lo <= -1.0 && -1.0 <= hi, "[{lo}, {hi}]");
    let rmse =
        |s: &mmenn::discover::DiscoverSummary| s.validation_gap.as_ref().unwrap().after.rmse["x"];
    // The noise level: σ = 0.01, within 3σ of its estimate over 240 samples (±14 %).
    assert!(rmse(&foh) < 0.0114, "foh validation RMSE {}", rmse(&foh));
    let zoh = run(InterSample::Zoh);
    assert!(
        rmse(&zoh) > 2.0 * rmse(&foh),
        "zoh {} vs foh {}",
        rmse(&zoh),
        rmse(&foh)
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// One recorded event: task, done, total, stage, the "still running" line a display
/// would print after this report, and the note.
type Event = (String, usize, Option<usize>, String, String, String);

/// Records progress reports and task ends, in order.
#[derive(Default)]
struct Recorder(std::sync::Mutex<Vec<Event>>);

impl mmenn::progress::ProgressSink for Recorder {
    fn report(&self, p: &mmenn::progress::Progress) {
        self.0.lock().unwrap().push((
            p.task.clone(),
            p.done,
            p.total,
            p.stage.clone(),
            p.running_line(5.0),
            p.note.clone(),
        ));
    }
    fn finish(&self, task: &str) {
        self.0.lock().unwrap().push((
            format!("finished {task}"),
            0,
            None,
            String::new(),
            String::new(),
            String::new(),
        ));
    }
}

/// Issue 18: `discover` reports one task with a known total (the workflow's steps), so a
/// terminal bar can show an ETA: the reports arrive in order (done never decreases and
/// never exceeds the total), name the round and step as the stage — also in the line a
/// display prints while a step runs without reporting — end with done = total, and the
/// task is finished once, last.
#[test]
fn discover_reports_its_steps_against_a_known_total() {
    let dir = scratch("progress");
    let train = run_simulate(
        &SimulationRequest {
            system: "msd_cubic".into(),
            recipe: Recipe::Train,
            seed: 2,
            ..Default::default()
        },
        &dir.join("train"),
    )
    .unwrap();
    let opts = DiscoverOptions {
        workflow: mmenn::discover::WorkflowConfig {
            max_rounds: 3,
            ..Default::default()
        },
        ..Default::default()
    };
    let rec = Recorder::default();
    let s = mmenn::discover::run_discover_with_progress(
        std::slice::from_ref(&train.data),
        &train.model,
        &[],
        &opts,
        &dir.join("out"),
        &rec,
    )
    .unwrap();
    let events = rec.0.into_inner().unwrap();
    let (last, all) = events.split_last().unwrap();
    assert_eq!(last.0, "finished discover", "{events:?}");
    // MME's steps within a workflow step come as notes on that step's report: the same
    // task, count and stage as the step report before them.
    let mut step: Option<&Event> = None;
    let mut notes = Vec::new();
    for e in all {
        if e.5.is_empty() {
            step = Some(e);
            continue;
        }
        let at = step.expect("an MME note before any step report");
        assert_eq!(&e.0[..], &at.0[..]);
        assert_eq!((e.1, e.2, &e.3), (at.1, at.2, &at.3), "{e:?} after {at:?}");
        assert!(e.5.starts_with("MME "), "{e:?}");
        notes.push(e.5.as_str());
    }
    assert!(
        notes
            .iter()
            .any(|n| n.starts_with("MME W search: W trial 1 of at most ")),
        "{notes:?}"
    );
    let reports: Vec<Event> = all.iter().filter(|e| e.5.is_empty()).cloned().collect();
    assert!(reports.len() >= 6, "{events:?}");
    let planned = 1
        + opts.workflow.max_rounds * mmenn::discovery::workflow::STEPS_PER_ROUND
        + mmenn::discovery::workflow::FINAL_STEPS;
    assert_eq!(reports[0].1, 0);
    assert_eq!(reports[0].2, Some(planned), "{events:?}");
    assert_eq!(reports[0].3, "MME with the assumed model");
    assert_eq!(reports[1].3, "round 1: noise floor of d̂");
    assert_eq!(
        reports[1].4,
        format!("discover: round 1: noise floor of d̂ (step 2 of {planned}), running for 5 s")
    );
    let mut prev = 0;
    for (task, done, total, stage, line, _) in &reports {
        assert!(line.contains(stage.as_str()), "{events:?}");
        assert_eq!(task, mmenn::discover::DISCOVER_TASK);
        let total = total.expect("a known total");
        assert!(*done >= prev && *done <= total, "{events:?}");
        prev = *done;
    }
    let end = &reports[reports.len() - 1];
    assert_eq!(Some(end.1), end.2, "{events:?}");
    // Every step begun is counted: the rounds run plus the first MME run.
    assert!(end.1 > s.rounds.len() * 3, "{events:?}");
    std::fs::remove_dir_all(&dir).unwrap();
}
