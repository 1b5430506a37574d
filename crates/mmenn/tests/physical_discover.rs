//! Discovery and grey-box estimation on data mmenn did not make: the two-link pendulum
//! records of `fixtures/two_link/` (scipy RK45 at rtol 1e-10, per-joint viscous and
//! smooth Coulomb friction `b_i·ω_i + fc_i·(2/π)·atan(ω_i/vs)`, 14-bit encoder angles;
//! true values in `truth.json`). Issue 20, items 3 and 7.

use std::path::{Path, PathBuf};

use mmenn::discover::{DiscoverOptions, NamedEffect, run_discover};
use mmenn::discovery::Verdict;
use mmenn::greyest::{GreyestOptions, run_greyest};
use mmenn::predict::InitialChoice;
use mmenn::predict::run_predict;
use mmenn::progress::NoProgress;
use mmenn::sysid_core::Dynamics;

fn fixture() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/two_link")
}

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!(
        "mmenn-physical-discover-{}-{name}",
        std::process::id()
    ));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn truth(name: &str) -> f64 {
    let text = std::fs::read_to_string(fixture().join("truth.json")).unwrap();
    let t: serde_json::Value = serde_json::from_str(&text).unwrap();
    t["parameters"][name].as_f64().unwrap()
}

/// The fixture's model file without its two friction terms and without the friction
/// parameters only they use: the rigid body alone, with the true rigid-body parameters.
fn rigid_body_only() -> String {
    let text = std::fs::read_to_string(fixture().join("model.toml")).unwrap();
    let body = &text[..text.find("[[terms]]").unwrap()];
    let kept: Vec<&str> = body
        .lines()
        .filter(|l| {
            !["b1 ", "b2 ", "fc1 ", "fc2 ", "vs "]
                .iter()
                .any(|p| l.starts_with(p))
        })
        .collect();
    assert!(!kept.iter().any(|l| l.contains("atan")), "friction left");
    kept.join("\n") + "\n"
}

/// Whether `interval` holds `value`.
fn covers(interval: [f64; 2], value: f64) -> bool {
    interval[0] <= value && value <= interval[1]
}

/// `mmenn discover` on the rigid-body model (no friction), `est.csv` estimating and
/// `val.csv` validating, must name the missing joint friction **per joint, as torques**.
///
/// The rule, written before the results were seen:
/// 1. verdict `found`;
/// 2. every named effect enters `omega1` or `omega2` and its term reads only that
///    joint's own rate (no `theta`/`omega` of the other joint): no cross-joint term;
/// 3. on each joint, a viscous term (`viscous_damping`, term `omega_j`) and a Coulomb
///    law (`coulomb_friction_smooth` or `coulomb_friction_atan`) are named, both with a
///    negative coefficient read as opposing the motion;
/// 4. the 95 % intervals cover the truth: viscous `−b_j`; Coulomb `−fc_j` when the
///    named law is the generator's `(2/π)·atan(ω/ε)`, whose calibrated `ε` must then be
///    within 10 % of `vs` = 0.05 rad/s. A `tanh` law is a different function of `ω` (no
///    `1 − 2ε/(π|ω|)` tail), so its level is not `fc_j` and the test then fails on purpose:
///    force-space discovery tries both shapes and must prefer the one that fits.
/// 5. units: N·m for the Coulomb level, (N·m)/(rad/s) for viscous damping;
/// 6. `model.discovered.toml` loads and `predict` fits both validation angles above 99 %
///    free-run (the true model's fit is 99.94/99.97 %, `tests/physical.rs`).
///
/// Measured on the commit that added this test (2 cores shared by 4 agents): found in
/// ~7 s; b1 3.9985e-3 [3.9946e-3, 4.0025e-3], fc1 1.2003e-2 [1.1995e-2, 1.2011e-2],
/// ε1 0.05; b2 2.0001e-3 [1.9996e-3, 2.0005e-3], fc2 7.9996e-3 [7.9974e-3, 8.0019e-3],
/// ε2 0.0499 (signs negative); validation free-run cost 1.56e7 → 1.03 (× noise level).
/// With the `tanh` law alone the intervals missed: fc2 7.76e-3 [7.72e-3, 7.80e-3],
/// b2 2.034e-3 [2.025e-3, 2.043e-3] — the bias of the wrong smooth law, not of W or of
/// the quantisation.
#[test]
fn two_link_friction_is_named_per_joint_as_torques() {
    let dir = scratch("discover");
    let model = dir.join("rigid_body.toml");
    std::fs::write(&model, rigid_body_only()).unwrap();
    let out = dir.join("out");
    let s = run_discover(
        &[fixture().join("est.csv")],
        &model,
        &[fixture().join("val.csv")],
        &DiscoverOptions::default(),
        &out,
    )
    .unwrap();
    assert_eq!(s.verdict, Verdict::Found, "{s:#?}");
    // Decided by intervals, the validation cost and the fixed noise-level bound, not by
    // the bootstrap judge: the words say so.
    assert!(s.generalized_forces && s.judgement.is_none());
    let words = mmenn::words::discover_verdict(&s);
    assert!(
        words.contains("noise level on the estimation records")
            && words.contains("not by a bootstrap"),
        "{words}"
    );
    // The claim was judged (the bound of the record's M, not NaN), and the report says at
    // what cost (measured: s² 1.0113 against 1.0548).
    assert!(
        s.claim_bound > 1.0 && s.claim_bound < 1.1,
        "{}",
        s.claim_bound
    );
    let note = s.judge_note.as_deref().unwrap_or("");
    assert!(note.contains("With the kept forces that cost"), "{note}");
    let joints = [("omega1", "theta1"), ("omega2", "theta2")];
    for e in &s.effects {
        let (own, _) = joints
            .iter()
            .find(|(w, _)| *w == e.state)
            .unwrap_or_else(|| panic!("{} enters {}", e.name, e.state));
        for (w, t) in joints {
            if w != *own {
                assert!(
                    !e.term.contains(w) && !e.term.contains(t),
                    "cross-joint term {} on {}",
                    e.term,
                    e.state
                );
            }
        }
        assert!(e.into.is_none());
    }
    let named = |state: &str, names: &[&str]| -> &NamedEffect {
        s.effects
            .iter()
            .find(|e| e.state == state && names.contains(&e.name.as_str()))
            .unwrap_or_else(|| panic!("no {names:?} on {state}: {:#?}", s.effects))
    };
    for (j, (state, _)) in joints.iter().enumerate() {
        let (b, fc) = (
            truth(&format!("b{}", j + 1)),
            truth(&format!("fc{}", j + 1)),
        );
        let viscous = named(state, &["viscous_damping"]);
        assert_eq!(viscous.term, *state);
        assert_eq!(viscous.unit.as_deref(), Some("(N*m)/(rad/s)"));
        let ci = viscous.ci95.expect("viscous interval");
        assert!(covers(ci, -b), "{state} viscous {ci:?} vs −{b}");
        let coulomb = named(state, &["coulomb_friction_smooth", "coulomb_friction_atan"]);
        assert_eq!(coulomb.unit.as_deref(), Some("N*m"));
        for e in [viscous, coulomb] {
            assert!(e.coefficient < 0.0, "{e:?}");
            let reading = e.reading.as_deref().unwrap_or("");
            assert!(reading.contains("opposing motion") || reading.contains("more viscous"));
        }
        assert_eq!(
            coulomb.name, "coulomb_friction_atan",
            "{state}: the tanh law was kept ({coulomb:?})"
        );
        let eps = coulomb.parameters["eps"];
        assert!(
            (eps - truth("vs")).abs() <= 0.1 * truth("vs"),
            "{state} ε {eps}"
        );
        let ci = coulomb.ci95.expect("Coulomb interval");
        assert!(covers(ci, -fc), "{state} Coulomb {ci:?} vs −{fc}");
    }
    let p = run_predict(
        &out.join("model.discovered.toml"),
        &fixture().join("val.csv"),
        &InitialChoice::Fit,
        200,
        &dir.join("predict"),
    )
    .unwrap();
    for name in ["theta1", "theta2"] {
        let fit = p.free_run.channels[name].fit_percent;
        assert!(fit > 99.0, "{name}: {fit} %");
    }
}

/// `mmenn greyest` on the fixture's model with the friction as free parameters and the
/// rigid body's masses and inertias free (link lengths, centres of mass and `g` held:
/// with `l1` known, `m2` and `lc2` enter only as `m2·lc2`, so one of each pair must be
/// measured), every free parameter started 25 % off the truth: each estimate's
/// `±1.96 σ` covers the true value.
///
/// Measured on the commit that added this test (one free-run solve, 7 iterations,
/// s² = 1.012): m1 0.449997 ± 5.5e-6 kg, m2 0.250001 ± 1.4e-6 kg, I1 3.59996e-3 ±
/// 2.4e-7, I2 1.10001e-3 ± 3.2e-8 kg·m², b1 3.99987e-3 ± 2.1e-6, b2 1.99994e-3 ± 1.6e-7
/// N·m·s/rad, fc1 1.20006e-2 ± 3.4e-6, fc2 8.00034e-3 ± 6.8e-7 N·m (b–fc correlations
/// −0.95 and −0.93). The model is the generator's, so s² ≈ 1 and the σ are honest here.
#[test]
fn greyest_covers_the_true_rigid_body_and_friction() {
    let dir = scratch("greyest");
    let text = std::fs::read_to_string(fixture().join("model.toml"))
        .unwrap()
        .replace(
            "lc1 = { value = 0.14, unit = \"m\", bounds = [0.0, 0.3] }",
            "lc1 = { value = 0.14, unit = \"m\", fixed = true }",
        )
        .replace(
            "lc2 = { value = 0.12, unit = \"m\", bounds = [0.0, 0.3] }",
            "lc2 = { value = 0.12, unit = \"m\", fixed = true }",
        );
    let free = ["m1", "m2", "I1", "I2", "b1", "b2", "fc1", "fc2"];
    let mut text = text;
    for name in free {
        let v = truth(name);
        let line_start = format!("{name} = {{ value = ");
        let at = text.find(&line_start).unwrap() + line_start.len();
        let end = at + text[at..].find(',').unwrap();
        text.replace_range(at..end, &format!("{}", v * 1.25));
    }
    let model = dir.join("model.toml");
    std::fs::write(&model, &text).unwrap();
    let o = run_greyest(
        &model,
        &[fixture().join("est.csv")],
        &GreyestOptions::default(),
        &dir.join("out"),
        &NoProgress,
    )
    .unwrap();
    for name in free {
        let p = o.parameter(name).unwrap();
        let sigma = p.sigma.unwrap_or_else(|| panic!("{name}: no σ ({p:?})"));
        let t = truth(name);
        assert!(
            (p.value - t).abs() <= 1.96 * sigma,
            "{name}: {} ± {sigma} vs {t} (start {})",
            p.value,
            p.start
        );
    }
    // Issue 20, item 6: the estimated start state's angles are the measured first angles
    // (the record starts at [0.2001845, −0.1000922] rad) to within 1e-3 rad.
    let x0 = &o.summary.records[0].x0;
    for (name, y0) in [("theta1", 0.2001844928), ("theta2", -0.1000922464)] {
        assert!(
            (x0[name] - y0).abs() <= 1e-3,
            "{name}(0) = {} vs {y0}",
            x0[name]
        );
    }
}

/// README's physics section shows `fixtures/two_link/rigid_body.toml` as it is, and that
/// file is the fixture's model without its friction: same right-hand side, friction
/// switched off in the fixture (`b = fc = 0`), at a few states.
#[test]
fn readme_shows_the_rigid_body_fixture() {
    let readme = include_str!("../../../README.md");
    let start = readme
        .find("## Model files with physics: parameters and mass matrix")
        .unwrap();
    let block = &readme[start..];
    let open = block.find("```toml\n").unwrap() + "```toml\n".len();
    let shown = &block[open..open + block[open..].find("```").unwrap()];
    let file = std::fs::read_to_string(fixture().join("rigid_body.toml")).unwrap();
    assert_eq!(shown, file);
    let rigid = mmenn::LoadedModel::parse(Path::new("rigid_body.toml"), &file).unwrap();
    let frictionless = std::fs::read_to_string(fixture().join("model.toml"))
        .unwrap()
        .replace("value = 0.004,", "value = 0.0,")
        .replace("value = 0.002,", "value = 0.0,")
        .replace("value = 0.012,", "value = 0.0,")
        .replace("value = 0.008,", "value = 0.0,");
    let full = mmenn::LoadedModel::parse(Path::new("model.toml"), &frictionless).unwrap();
    for x in [[0.3, -0.2, 1.0, -2.0], [0.1, 1.0, -0.5, 0.7]] {
        let (mut a, mut b) = ([0.0; 4], [0.0; 4]);
        rigid.dynamics.rhs(0.0, &x, &[0.1, -0.05], &mut a);
        full.dynamics.rhs(0.0, &x, &[0.1, -0.05], &mut b);
        for i in 0..4 {
            assert!(
                (a[i] - b[i]).abs() <= 1e-12 * (1.0 + b[i].abs()),
                "{a:?} {b:?}"
            );
        }
    }
}

/// `discover --budget SECONDS` stops like `estimate`, `fit` and `greyest` do: a spent
/// budget is exit status 4 with a message naming the budget and the stage that ran out;
/// no output folder is left behind. A budget of 0 s runs out at the first charge (MME
/// with the assumed model), on the mass-matrix path (rigid-body model) and on the
/// state-space path (a mass-spring-damper case of the discovery suite) alike.
#[test]
fn cli_discover_stops_at_its_budget_with_status_4() {
    use std::process::Command;
    let dir = scratch("budget");
    let msd = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures/discovery_suite/cases/msd_coulomb");
    let runs = [
        (fixture().join("rigid_body.toml"), fixture().join("est.csv")),
        (msd.join("model.toml"), msd.join("est.csv")),
    ];
    for (i, (model, data)) in runs.iter().enumerate() {
        let out = dir.join(format!("out{i}"));
        let run = Command::new(env!("CARGO_BIN_EXE_mmenn"))
            .args(["--quiet", "discover", "--data"])
            .arg(data)
            .arg("--model")
            .arg(model)
            .args(["--budget", "0", "--out"])
            .arg(&out)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&run.stderr);
        assert_eq!(run.status.code(), Some(4), "{}: {err}", model.display());
        assert!(
            err.contains("the budget of 0 s ran out during") && err.contains("MME"),
            "{err}"
        );
        assert!(!out.exists(), "{}", out.display());
    }
}

/// `discover` with the rigid-body model on the offset + Stribeck records (estimation and
/// validation), default options, results under `dir/out`.
fn discover_offset_stribeck(dir: &Path) -> mmenn::discover::DiscoverSummary {
    run_discover(
        &[fixture().join("offset_stribeck_est.csv")],
        &fixture().join("rigid_body.toml"),
        &[fixture().join("offset_stribeck_val.csv")],
        &DiscoverOptions::default(),
        &dir.join("out"),
    )
    .unwrap()
}

/// Issue 20, item 3: the force path's Offset and Stribeck candidates on data containing
/// them (`offset_stribeck_*.csv`: the base arm and friction plus a constant torque
/// `tau0 = +0.02` N·m on joint 1 and Stribeck breakaway friction on joint 2,
/// `(fs2 − fc2)·exp(−(ω2/0.3)²)·(2/π)·atan(ω2/vs)`, `fs2 = 0.014` N·m;
/// `offset_stribeck_truth.json`). `discover` on `rigid_body.toml` must find the offset on
/// joint 1 (`constant_bias` on `omega1`, positive, 95 % interval covering 0.02 N·m) with
/// every force on its own joint — and, since the Stribeck hump is not among them, must
/// not claim them: the verdict is `unexplained`, the forces unconfirmed, because with
/// them the free run on the estimation records is still above the noise-level bound.
///
/// Measured (release, ~19 s, load ~2.5): offset 1.9988e-2 [1.9921e-2, 2.0055e-2] N·m;
/// joint 1 also viscous −4.087e-3 and `(2/π)·atan(ω1/0.0351)` × −1.1696e-2, joint 2
/// viscous −2.012e-3 and `tanh(ω2/0.0355)` × −7.867e-3; validation free-run cost
/// 5.6e10 → 51.6 (× the noise level), fit 99.84 % on both validation angles. Until the
/// force path judged its claim at the noise level this was `found`; its estimation cost
/// with the forces is 4.70 × the noise level against a bound of 1.055. The Stribeck term
/// is not proposed: see [`two_link_stribeck_is_named_on_joint_2`].
#[test]
fn two_link_offset_is_found_but_not_claimed_without_the_stribeck_hump() {
    let dir = scratch("offset");
    let s = discover_offset_stribeck(&dir);
    assert_eq!(s.verdict, Verdict::Unexplained, "{s:#?}");
    assert!(s.effects.is_empty(), "{:#?}", s.effects);
    assert!(
        s.warnings
            .iter()
            .any(|w| w.contains("something else is missing") && w.contains("not claimed")),
        "{:?}",
        s.warnings
    );
    assert!(
        s.claim_bound > 1.0 && s.claim_bound < 1.1,
        "{}",
        s.claim_bound
    );
    for e in &s.unconfirmed {
        let other = if e.state == "omega1" { "2" } else { "1" };
        assert!(
            !e.term.contains(&format!("omega{other}"))
                && !e.term.contains(&format!("theta{other}")),
            "cross-joint term {} on {}",
            e.term,
            e.state
        );
    }
    let offset = s
        .unconfirmed
        .iter()
        .find(|e| e.name == "constant_bias")
        .unwrap_or_else(|| panic!("no offset found: {:#?}", s.unconfirmed));
    assert_eq!(offset.state, "omega1");
    let ci = offset.ci95.unwrap();
    assert!(covers(ci, 0.02), "offset {} {ci:?}", offset.coefficient);
    assert_eq!(offset.unit.as_deref(), Some("N*m"));
}

/// What item 3 asks and the force path does not do yet (ignored: it fails). The
/// Stribeck hump on joint 2 (0.006 N·m at rest, gone above |ω2| ≈ 0.3 rad/s, where the
/// joint spends 6.5 % of the record) removes 0.06 % of `Σ τ̂₂²` after viscous and Coulomb
/// terms (computed on the generator's true ω2), 30× below `ForceConfig::min_share`
/// (2 %), so it is never proposed; and the catalogue's smooth Stribeck is
/// `tanh(v/ε)·exp(−(v/v_s)²)` with `v_s = 0.1·RMS(v)` = 0.417 rad/s held fixed, while the
/// generator's is `(2/π)·atan(v/vs)·exp(−(v/0.3)²)`, whose low-speed difference from a
/// tanh Coulomb law is of the hump's size — so even when proposed its coefficient would
/// not estimate `−(fs2 − fc2)`. Needs: a share rule that sees low-speed forces (e.g. the
/// share within the low-speed samples, or a free-run test of each remaining candidate),
/// an atan form of the Stribeck law and a calibrated `v_s`.
#[test]
#[ignore = "the force path does not propose the Stribeck term on this record (see doc)"]
fn two_link_stribeck_is_named_on_joint_2() {
    let dir = scratch("stribeck");
    let s = discover_offset_stribeck(&dir);
    let stribeck = s
        .effects
        .iter()
        .find(|e| e.name.starts_with("stribeck"))
        .unwrap_or_else(|| panic!("no Stribeck term named: {:#?}", s.effects));
    assert_eq!(stribeck.state, "omega2");
    assert!(covers(stribeck.ci95.unwrap(), -(0.014 - 0.008)));
}

/// A budget that runs out in the force-space calibration (after MME) stops `discover`
/// with the typed error naming that stage — not an "unexplained" verdict, which is what a
/// failed calibration used to become. Work units make it deterministic: 1e5 sub-steps
/// cover MME on the rigid-body model but not the calibration of the proposed forces.
/// (The CLI maps this error to exit status 4 like every other spent budget.)
#[test]
fn discover_budget_running_out_in_the_calibration_is_an_error() {
    use mmenn::discovery::DiscoveryError;
    use mmenn::sysid_core::{Budget, CoreError};
    let dir = scratch("budget-calibration");
    let mut opts = DiscoverOptions::default();
    opts.estimate.budget = Budget::work_units(100_000);
    let e = run_discover(
        &[fixture().join("est.csv")],
        &fixture().join("rigid_body.toml"),
        &[fixture().join("val.csv")],
        &opts,
        &dir.join("out"),
    )
    .expect_err("the budget must run out");
    let text = e.to_string();
    match &e {
        mmenn::MmennError::Discovery(DiscoveryError::Core(CoreError::BudgetExhausted(b))) => {
            assert!(b.stage.contains("force-space discovery"), "{text}");
        }
        other => panic!("{other:?}"),
    }
    assert!(
        text.contains("ran out during force-space discovery"),
        "{text}"
    );
}

/// The negative control on the scipy records: given the generator's own model (the
/// fixture's `model.toml`: true parameters and both friction laws), force-space discovery
/// names nothing, and its `none` is now judged against the noise level: the assumed
/// model's free-run cost on `est.csv` is at most `1 + 3√(2/M)` (the noise variance is
/// given: the encoder's quantisation). Rule fixed before the run: verdict `none`, no
/// named or unconfirmed force, and the bound reported is that of the record's `M`.
#[test]
fn the_true_two_link_model_is_none_at_the_noise_level() {
    let dir = scratch("true-model");
    let s = run_discover(
        &[fixture().join("est.csv")],
        &fixture().join("model.toml"),
        &[fixture().join("val.csv")],
        &DiscoverOptions::default(),
        &dir.join("out"),
    )
    .unwrap();
    assert_eq!(s.verdict, Verdict::None, "{s:#?}");
    assert!(s.effects.is_empty() && s.unconfirmed.is_empty(), "{s:#?}");
    let table = mmenn::data_file::read_table(&fixture().join("est.csv")).unwrap();
    let m = ["theta1", "theta2"]
        .iter()
        .map(|c| {
            table.columns[table.column_index(c).unwrap()]
                .iter()
                .filter(|v| !v.is_nan())
                .count()
        })
        .sum::<usize>();
    let bound = 1.0 + 3.0 * (2.0 / m as f64).sqrt();
    assert!(
        (s.claim_bound - bound).abs() < 1e-12,
        "{} vs {bound}",
        s.claim_bound
    );
    assert!(mmenn::words::discover_verdict(&s).contains("noise level"));
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `mmenn fit` on a `[mechanics]` model: the MME/NN hybrid `M⁻¹Q + E·NN` on the scipy
/// two-link records, the rigid body alone as the physics (no friction). Rule: with the
/// validation record scored only, both angles' validation free-run fit is at least 80 %
/// and above the rigid body's own, and `predict` on the written `model.json` gives the
/// fit's validation numbers (one judge). The 80 % was set after one full-sweep CLI run
/// (95.39 / 97.04 %; the rigid body 13.9 / −42.3 %) and before this reduced sweep ran.
#[test]
fn fit_builds_a_hybrid_on_a_mass_matrix_model() {
    use mmenn::fit::{FitOptions, run_fit};
    let dir = scratch("fit");
    let model = fixture().join("rigid_body.toml");
    let val = fixture().join("val.csv");
    let opts = FitOptions {
        max_hidden: 3,
        inits: 3,
        ..FitOptions::default()
    };
    let s = run_fit(
        &[fixture().join("est.csv")],
        &model,
        std::slice::from_ref(&val),
        &opts,
        &dir.join("fit"),
    )
    .unwrap();
    let v = s.validation.expect("validation judged");
    let physics =
        run_predict(&model, &val, &InitialChoice::Fit, 200, &dir.join("physics")).unwrap();
    let hybrid = run_predict(
        &dir.join("fit/model.json"),
        &val,
        &InitialChoice::Fit,
        200,
        &dir.join("hybrid"),
    )
    .unwrap();
    for joint in ["theta1", "theta2"] {
        let fit = v.channels[joint].fit_percent;
        let alone = physics.free_run.channels[joint].fit_percent;
        assert!(
            fit >= 80.0 && fit > alone,
            "{joint}: hybrid {fit} %, rigid body {alone} %"
        );
        let judged = hybrid.free_run.channels[joint].fit_percent;
        assert!(
            (judged - fit).abs() < 1e-9,
            "{joint}: predict {judged} vs fit {fit}"
        );
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `mmenn compare` on the `[mechanics]` rigid body: no "assumed model" row (its linear part
/// is zero: the dynamics are the given model's row), the given model and MME/NN rows
/// judged, and MME/NN's validation numbers those `fit` gives with the same options.
#[test]
fn compare_takes_a_mass_matrix_model() {
    use mmenn::compare::{CompareOptions, GIVEN_MODEL_ROW, run_compare};
    use mmenn::fit::{FitOptions, run_fit};
    let dir = scratch("compare");
    let model = fixture().join("rigid_body.toml");
    let (est, val) = (fixture().join("est.csv"), fixture().join("val.csv"));
    let fit_opts = FitOptions {
        max_hidden: 2,
        inits: 2,
        ..FitOptions::default()
    };
    let opts = CompareOptions {
        fit: fit_opts.clone(),
        ..CompareOptions::default()
    };
    let c = run_compare(
        std::slice::from_ref(&est),
        &model,
        std::slice::from_ref(&val),
        &opts,
        &dir.join("compare"),
    )
    .unwrap();
    let table = c.validation.expect("validation table");
    let labels: Vec<&str> = table.rows().iter().map(|r| r.label.as_str()).collect();
    assert!(!labels.contains(&"assumed model"), "{labels:?}");
    assert!(labels.contains(&GIVEN_MODEL_ROW), "{labels:?}");
    let f = run_fit(&[est], &model, &[val], &fit_opts, &dir.join("fit")).unwrap();
    let v = f.validation.expect("validation judged");
    let row = table
        .rows()
        .iter()
        .find(|r| r.label == "MME/NN")
        .expect("MME/NN row");
    for joint in ["theta1", "theta2"] {
        let cmp = row.evaluation.channel(joint).unwrap().fit_percent;
        assert_eq!(
            cmp.to_bits(),
            v.channels[joint].fit_percent.to_bits(),
            "{joint}"
        );
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Force-space discovery reports MME's own steps while its first estimate runs: notes on
/// the "MME with the assumed model" step of the discover task, W trials among them.
#[test]
fn force_space_discover_reports_mme_steps() {
    use mmenn::progress::Progress;
    let dir = scratch("progress");
    let seen = std::sync::Mutex::new(Vec::<Progress>::new());
    let sink = |p: &Progress| {
        if let Ok(mut s) = seen.lock() {
            s.push(p.clone());
        }
    };
    mmenn::discover::run_discover_with_progress(
        &[fixture().join("est.csv")],
        &fixture().join("model.toml"),
        &[],
        &DiscoverOptions::default(),
        &dir.join("out"),
        &sink,
    )
    .unwrap();
    let seen = seen.into_inner().unwrap();
    let mme: Vec<&Progress> = seen.iter().filter(|p| p.note.starts_with("MME ")).collect();
    assert!(!mme.is_empty(), "no MME notes among {} reports", seen.len());
    assert!(
        mme.iter()
            .all(|p| p.task == "discover" && p.stage == "MME with the assumed model"),
        "{mme:?}"
    );
    assert!(
        mme.iter().any(|p| p.note.contains("W trial 1 of at most")),
        "{:?}",
        mme.iter().map(|p| &p.note).collect::<Vec<_>>()
    );
    std::fs::remove_dir_all(&dir).unwrap();
}
