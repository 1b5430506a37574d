//! `mmenn greyest --starts N --seed S`: the multi-start. Two small models on records
//! generated here from exact (zero-order-hold) discretisations, not by mmenn's RK4, with
//! seeded Gaussian noise of the model file's variance:
//! - `x' = −p²·x + b·u`: the output depends on `p` only through `p²`, so `+p` and `−p`
//!   are two minima of exactly the same cost; the warning must fire and name `p`, not `b`;
//! - a damped oscillator with free stiffness and damping, which these records pin: every
//!   converged start ends at one minimum and nothing is reported.
//!
//! - a first-order tank with an overflow term `c·max(h − 10, 0)` that the record (|h| < 2)
//!   never reaches: the starts end with different `c`, which must be reported as not
//!   exercised by the records, not as a parameter the data do not pin.
//!
//! Plus: `--starts 0` is the single-start estimation with `greyest.json` unchanged, and the
//! result does not depend on the number of threads.

use std::path::{Path, PathBuf};

use mmenn::greyest::{GreyestOptions, GreyestOutcome, run_greyest};
use mmenn::progress::NoProgress;
use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};
use rand_distr::{Distribution, StandardNormal};

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("mmenn-starts-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap_or_else(|e| panic!("{e}"));
    dir
}

fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap_or_else(|e| panic!("{e}"));
    p
}

/// Sample interval, s.
const DT: f64 = 0.05;

/// A piecewise-constant input: a new level, uniform in [−1, 1], every 12 samples.
fn steps(n: usize, rng: &mut ChaCha8Rng) -> Vec<f64> {
    let mut u = Vec::with_capacity(n);
    let mut level = 0.0;
    for k in 0..n {
        if k % 12 == 0 {
            level = rng.random_range(-1.0..1.0);
        }
        u.push(level);
    }
    u
}

/// `t,u,<output>` with the given samples.
fn csv(output: &str, u: &[f64], y: &[f64]) -> String {
    let mut text = format!("t,u,{output}\n");
    for (k, (u, y)) in u.iter().zip(y).enumerate() {
        text.push_str(&format!("{},{u},{y}\n", k as f64 * DT));
    }
    text
}

/// `x' = −p²·x + b·u`, `y = x`. `p` starts at 0 within [−2, 2] (a zero start value is
/// drawn uniformly within its bounds, so seeded starts fall on either side of 0); `b`
/// starts at 0.5 within [0, 10].
const SQUARE: &str = r#"
states = ["x"]
inputs = ["u"]
measured = ["x"]
corrected = ["x"]
noise_variance = [1.0e-4]

[parameters]
p = { value = 0.0, bounds = [-2.0, 2.0] }
b = { value = 0.5, bounds = [0.0, 10.0] }

[[terms]]
state = "x"
effect = "decay"
term = "-p^2*x + b*u"
"#;

/// 400 samples of `x' = −x + u` (p² = 1, b = 1) from x(0) = 0.3, exact under a
/// zero-order hold, with N(0, 0.01²) noise.
fn square_record(dir: &Path) -> PathBuf {
    first_order_record(dir, "square.csv", 11, 0.3, 0.0)
}

/// 400 samples of `x' = −x + u + d` from `x(0) = x0`, exact under a zero-order hold, with
/// N(0, 0.01²) noise seeded by `seed`, written to `file` in `dir`.
fn first_order_record(dir: &Path, file: &str, seed: u64, x0: f64, d: f64) -> PathBuf {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let n = 400;
    let u = steps(n, &mut rng);
    let phi = (-DT).exp();
    let gamma = 1.0 - phi;
    let mut x = x0;
    let mut y = Vec::with_capacity(n);
    for &uk in &u {
        let e: f64 = StandardNormal.sample(&mut rng);
        y.push(x + 0.01 * e);
        x = phi * x + gamma * (uk + d);
    }
    write(dir, file, &csv("x", &u, &y))
}

/// A damped oscillator `x'' = −k·x − c·v + u`, position measured; started at k = 3,
/// c = 0.8 (truth 4 and 0.5).
const OSCILLATOR: &str = r#"
states = ["x", "v"]
inputs = ["u"]
A = [[0.0, 1.0], [0.0, 0.0]]
B = [[0.0], [1.0]]
measured = ["x"]
corrected = ["v"]
noise_variance = [1.0e-6]

[parameters]
k = { value = 3.0, bounds = [0.01, 100.0] }
c = { value = 0.8, bounds = [0.0, 20.0] }

[[terms]]
state = "v"
effect = "spring_damper"
term = "-k*x - c*v"
"#;

/// 400 samples of the oscillator at k = 4, c = 0.5 from rest at x = 0.1, exact under a
/// zero-order hold (the matrix exponential of the augmented system), N(0, 0.001²) noise.
fn oscillator_record(dir: &Path) -> PathBuf {
    let mut rng = ChaCha8Rng::seed_from_u64(12);
    let n = 400;
    let u = steps(n, &mut rng);
    let aug = nalgebra::Matrix3::new(0.0, 1.0, 0.0, -4.0, -0.5, 1.0, 0.0, 0.0, 0.0) * DT;
    let e = aug.exp();
    let mut x = nalgebra::Vector3::new(0.1, 0.0, 0.0);
    let mut y = Vec::with_capacity(n);
    for &uk in &u {
        let noise: f64 = StandardNormal.sample(&mut rng);
        y.push(x[0] + 0.001 * noise);
        x[2] = uk;
        x = e * x;
    }
    write(dir, "oscillator.csv", &csv("x", &u, &y))
}

fn greyest(model: &Path, data: &Path, opts: &GreyestOptions, out: &Path) -> GreyestOutcome {
    run_greyest(model, &[data.to_path_buf()], opts, out, &NoProgress)
        .unwrap_or_else(|e| panic!("{e}"))
}

fn starts(n: usize, seed: u64) -> GreyestOptions {
    GreyestOptions {
        starts: n,
        seed,
        ..GreyestOptions::default()
    }
}

/// `+p` and `−p` explain the record equally well. The file's own start (p = 0) is a
/// stationary point in `p` (∂f/∂p = −2p·x = 0), so its solve only moves `b` and the start
/// state and ends far above the others; the seeded starts draw `p` uniformly in (−2, 2),
/// on both sides of 0, and end at `p ≈ +1` or `p ≈ −1` (not always of the sign they start
/// with: the solver's change of variable for two bounds, `sin`, can carry `p` across 0).
/// With seed 1 and 6 seeded starts both signs are reached (asserted, so a change of the
/// draw or the solver that loses one is seen here rather than passing silently). The
/// kept estimate is one of them; the other is a distinct minimum of the same cost with
/// `p` of the other sign: the warning names `p` with both values, and not `b`, which both
/// minima share.
#[test]
fn a_parameter_entering_squared_is_reported_not_pinned() {
    let dir = scratch("square");
    let model = write(&dir, "model.toml", SQUARE);
    let data = square_record(&dir);
    let out = dir.join("out");
    let outcome = greyest(&model, &data, &starts(6, 1), &out);
    let ms = outcome
        .summary
        .multi_start
        .as_ref()
        .unwrap_or_else(|| panic!("no multi-start"));
    assert_eq!(ms.starts.len(), 7);
    let at = ms
        .parameter_names
        .iter()
        .position(|n| n == "p")
        .unwrap_or_else(|| panic!("{:?}", ms.parameter_names));
    assert_eq!(ms.parameter_names.len(), 2);
    let p_of = |values: &[f64]| values[at];
    // Both signs among the converged starts, each at |p| ≈ 1, b ≈ 1.
    let converged: Vec<_> = ms.starts.iter().filter(|s| s.converged).collect();
    assert!(
        converged.iter().any(|s| p_of(&s.values) > 0.9)
            && converged.iter().any(|s| p_of(&s.values) < -0.9),
        "{ms:#?}"
    );
    // The kept start is a seeded one with |p| ≈ 1 (the file's own stays at p = 0).
    assert_ne!(ms.kept, 0, "{ms:#?}");
    let kept = outcome.parameter("p").unwrap_or_else(|| panic!("p"));
    assert!((kept.value.abs() - 1.0).abs() < 0.05, "{kept:?}");
    let own = ms.starts.iter().find(|s| s.index == 0).unwrap();
    assert_eq!(p_of(&own.values).to_bits(), 0f64.to_bits(), "{own:?}");
    assert!(own.relative_to_best.is_some_and(|r| r > 0.5), "{own:?}");
    // p = 0 is a stationary point of the cost but not a minimum: the output depends on p²,
    // so p has no first-order effect there (the nudges ±δ give the same free run: a
    // sensitivity of exactly 0), yet either nudge lowers the cost. The probe marks the
    // start a saddle along p and leaves it out of the minima; p is not "not exercised".
    assert!(own.converged, "{own:?}");
    assert!(own.saddle, "{own:?}");
    assert_eq!(own.minimum, None, "{own:?}");
    assert_eq!(own.sensitivity[at], Some(0.0), "{own:?}");
    assert!(own.not_exercised.is_empty(), "{own:?}");
    assert!(
        !own.cost_falls.is_empty()
            && own.cost_falls.iter().all(
                |f| f.name == "p" && f.relative_change < -mmenn::greyest::multistart::COST_FALL
            ),
        "{own:?}"
    );
    assert_eq!(own.note(), "saddle (cost falls along p)");
    assert_eq!(ms.saddles, vec![0], "{ms:#?}");
    assert!(ms.minima.iter().all(|m| !m.starts.contains(&0)), "{ms:#?}");
    // The minima at p ≈ ±1 are minima: no nudge lowers their cost, every parameter
    // exercised.
    for s in converged.iter().filter(|s| s.index != 0) {
        assert!(!s.saddle && s.not_exercised.is_empty(), "{s:?}");
        assert!(
            s.sensitivity.iter().all(|v| v.is_some_and(|v| v > 1e-2)),
            "{s:?}"
        );
    }
    assert!(
        ms.terminal_lines()
            .iter()
            .any(|l| l.contains("1 of them a saddle") && l.contains("multi-start:")),
        "{:#?}",
        ms.terminal_lines()
    );
    // The table is sorted by cost, the kept start first.
    assert_eq!(ms.starts[0].index, ms.kept);
    assert!(
        ms.starts
            .windows(2)
            .all(|w| w[0].final_cost.unwrap_or(f64::INFINITY)
                <= w[1].final_cost.unwrap_or(f64::INFINITY)),
        "{ms:#?}"
    );
    // The warning: one other minimum, within 1e-6 of the cost, p of the other sign, b not
    // named.
    assert_eq!(ms.not_pinned.len(), 1, "{ms:#?}");
    let w = &ms.not_pinned[0];
    assert!(w.relative_cost.abs() < 1e-6, "{w:?}");
    assert_eq!(w.parameters.len(), 1, "{w:?}");
    assert_eq!(w.parameters[0].name, "p");
    assert!(
        (w.parameters[0].kept + w.parameters[0].other).abs() < 1e-3,
        "{w:?}"
    );
    assert!(!ms.minima[w.minimum].kept);
    let sentence = w.sentence();
    assert!(sentence.contains("do not pin p:"), "{sentence}");
    assert!(!sentence.contains(" b "), "{sentence}");
    let report = std::fs::read_to_string(out.join("report.md")).unwrap_or_default();
    assert!(report.contains("## Multi-start"), "{report}");
    assert!(report.contains("**Identifiability warning**"), "{report}");
    assert!(report.contains("do not pin p"), "{report}");
    assert!(
        report.contains(&format!("**Kept: start {}**", ms.kept)),
        "{report}"
    );
    let json: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(out.join("greyest.json")).unwrap_or_default(),
    )
    .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(json["multi_start"]["kept"], ms.kept);
    assert_eq!(
        json["multi_start"]["not_pinned"][0]["parameters"][0]["name"],
        "p"
    );
    let own_json = json["multi_start"]["starts"]
        .as_array()
        .and_then(|a| a.iter().find(|s| s["index"] == 0))
        .unwrap_or_else(|| panic!("{json}"));
    assert_eq!(own_json["saddle"], true);
    assert_eq!(own_json["minimum"], serde_json::Value::Null);
    assert_eq!(own_json["cost_falls"][0]["name"], "p");
    assert_eq!(json["multi_start"]["saddles"][0], 0);
}

/// The same through the binary: `--starts 6 --seed 1` prints the table, which start was
/// kept and the warning; without `--starts` nothing of it.
#[test]
fn cli_prints_the_starts_and_the_warning() {
    let dir = scratch("cli");
    let model = write(&dir, "model.toml", SQUARE);
    let data = square_record(&dir);
    let run = |extra: &[&str], out: &str| {
        super::greyest::cli_greyest(&model, std::slice::from_ref(&data), extra, &dir.join(out))
    };
    let multi = run(&["--starts", "6", "--seed", "1"], "multi");
    assert!(multi.contains("multi-start: 7 starts"), "{multi}");
    assert!(multi.contains("kept start"), "{multi}");
    assert!(
        multi
            .lines()
            .any(|l| l.starts_with("warning: these data do not pin p:")),
        "{multi}"
    );
    let single = run(&[], "single");
    assert!(!single.contains("multi-start"), "{single}");
    assert!(!single.contains("do not pin"), "{single}");
}

/// Stiffness and damping of an oscillator are pinned by its record: every seeded start
/// that converges ends at the file's own start's minimum (one distinct minimum, no
/// warning), and the kept estimate equals the single-start estimate to 1e-9 relative.
#[test]
fn a_well_identified_model_has_one_minimum_and_no_warning() {
    let dir = scratch("oscillator");
    let model = write(&dir, "model.toml", OSCILLATOR);
    let data = oscillator_record(&dir);
    let single = greyest(&model, &data, &GreyestOptions::default(), &dir.join("one"));
    let multi = greyest(&model, &data, &starts(8, 1), &dir.join("multi"));
    let ms = multi.summary.multi_start.as_ref().unwrap();
    assert_eq!(ms.converged(), ms.starts.len(), "{ms:#?}");
    assert_eq!(ms.minima.len(), 1, "{ms:#?}");
    assert!(ms.minima[0].kept);
    assert!(ms.not_pinned.is_empty(), "{ms:#?}");
    // The probe finds every start a minimum with both parameters exercised.
    assert!(
        ms.saddles.is_empty() && ms.not_exercised.is_empty(),
        "{ms:#?}"
    );
    for s in &ms.starts {
        assert!(!s.saddle && s.not_exercised.is_empty(), "{s:?}");
        assert_eq!(s.sensitivity.len(), 2, "{s:?}");
        assert!(
            s.sensitivity.iter().all(|v| v.is_some_and(|v| v > 1e-2)),
            "{s:?}"
        );
        assert!(
            s.probe
                .iter()
                .all(|q| q.cost_down.is_some_and(|c| c >= 0.0)
                    && q.cost_up.is_some_and(|c| c >= 0.0)),
            "{s:?}"
        );
    }
    for name in ["k", "c"] {
        let a = single.parameter(name).unwrap().value;
        let b = multi.parameter(name).unwrap().value;
        assert!((a - b).abs() <= 1e-9 * a.abs(), "{name}: {a} vs {b}");
    }
    let k = single.parameter("k").unwrap();
    let c = single.parameter("c").unwrap();
    assert!(
        (k.value - 4.0).abs() < 0.02 && (c.value - 0.5).abs() < 0.02,
        "{k:?} {c:?}"
    );
    let report = std::fs::read_to_string(dir.join("multi/report.md")).unwrap_or_default();
    assert!(report.contains("1 distinct minimum"), "{report}");
    assert!(!report.contains("Identifiability warning"), "{report}");
}

/// `starts = 0` (the default) is the single-start estimation: no `multi_start` in the
/// summary, `greyest.json` with exactly the keys it had before, no multi-start section,
/// and the estimates bit for bit those of start 0 of a multi-start run (the file's own
/// start runs the same estimation there).
#[test]
fn no_starts_is_the_single_start_estimation() {
    let dir = scratch("zero");
    let model = write(&dir, "model.toml", OSCILLATOR);
    let data = oscillator_record(&dir);
    let single = greyest(&model, &data, &GreyestOptions::default(), &dir.join("one"));
    assert!(single.summary.multi_start.is_none());
    let json: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(dir.join("one/greyest.json")).unwrap_or_default(),
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let keys: Vec<&str> = json
        .as_object()
        .map(|o| o.keys().map(String::as_str).collect())
        .unwrap_or_default();
    let mut before = [
        "model",
        "weighting",
        "parameters",
        "correlation_names",
        "correlation",
        "records",
        "stages",
        "residual_variance_ratio",
        "rank",
        "files",
    ];
    before.sort_unstable();
    let mut keys = keys;
    keys.sort_unstable();
    assert_eq!(keys, before);
    let report = std::fs::read_to_string(dir.join("one/report.md")).unwrap_or_default();
    assert!(!report.contains("Multi-start"), "{report}");

    let multi = greyest(&model, &data, &starts(2, 1), &dir.join("multi"));
    let ms = multi.summary.multi_start.as_ref().unwrap();
    let own = ms.starts.iter().find(|s| s.index == 0).unwrap();
    let values: Vec<f64> = single.summary.parameters.iter().map(|p| p.value).collect();
    assert_eq!(
        own.values.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
        values.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
    );
    let cost = single.summary.stages.last().unwrap().final_cost;
    assert_eq!(own.final_cost.map(f64::to_bits), Some(cost.to_bits()));
}

/// The same multi-start in a 1-thread and a 2-thread pool: the same summary, bit for bit
/// (the starts are combined in start order).
#[test]
fn multi_start_does_not_depend_on_the_thread_count() {
    let dir = scratch("threads");
    let model = write(&dir, "model.toml", SQUARE);
    let data = square_record(&dir);
    let in_pool = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap_or_else(|e| panic!("{e}"));
        let out = dir.join(format!("out{threads}"));
        let mut summary = pool.install(|| greyest(&model, &data, &starts(5, 3), &out).summary);
        summary.files.clear();
        (
            summary.clone(),
            std::fs::read_to_string(out.join("greyest.json")).unwrap_or_default(),
        )
    };
    let (one, json_one) = in_pool(1);
    let (two, json_two) = in_pool(2);
    assert!(one.multi_start.is_some());
    assert_eq!(one, two);
    assert_eq!(json_one, json_two);
}

/// `x' = a·x + u` with `a` started at 0 within [−20, 20]: the seeded starts draw `a` on
/// both sides, and from a start with `a` above ~0.7 the 20-s record's simulation passes
/// the blow-up bound before the first iteration (`CoreError::Diverged`). Those starts
/// are listed with their error, the others still calibrate `a ≈ −1`, and the run
/// succeeds. With `a` within [4, 20] every start diverges: the error is the file's own
/// start's, typed.
#[test]
fn failing_starts_are_listed_and_only_all_failing_is_an_error() {
    let dir = scratch("failing");
    let data = square_record(&dir);
    let text = r#"
states = ["x"]
inputs = ["u"]
measured = ["x"]
corrected = ["x"]
noise_variance = [1.0e-4]

[parameters]
a = { value = 0.0, bounds = [-20.0, 20.0] }

[[terms]]
state = "x"
effect = "decay"
term = "a*x + u"
"#;
    let model = write(&dir, "model.toml", text);
    let outcome = greyest(&model, &data, &starts(6, 1), &dir.join("out"));
    let ms = outcome.summary.multi_start.as_ref().unwrap();
    assert!(ms.failed() >= 1 && ms.failed() < 7, "{ms:#?}");
    for s in ms.starts.iter().filter(|s| s.error.is_some()) {
        assert!(s.start[0] > 0.0, "{s:?}");
        assert!(s.final_cost.is_none() && s.values.is_empty(), "{s:?}");
        assert!(
            s.error.as_deref().is_some_and(|e| e.contains("diverged")),
            "{s:?}"
        );
    }
    // Failed starts come last in the table.
    let first_failed = ms.starts.iter().position(|s| s.error.is_some()).unwrap();
    assert!(ms.starts[first_failed..].iter().all(|s| s.error.is_some()));
    let a = outcome.parameter("a").unwrap().value;
    assert!((a + 1.0).abs() < 0.05, "a = {a}");
    let report = std::fs::read_to_string(dir.join("out/report.md")).unwrap_or_default();
    assert!(report.contains("failed: simulation diverged"), "{report}");

    let all_unstable = text.replace(
        "a = { value = 0.0, bounds = [-20.0, 20.0] }",
        "a = { value = 5.0, bounds = [4.0, 20.0] }",
    );
    let model = write(&dir, "unstable.toml", &all_unstable);
    let e = run_greyest(
        &model,
        std::slice::from_ref(&data),
        &starts(4, 1),
        &dir.join("unstable"),
        &NoProgress,
    )
    .err();
    assert!(
        matches!(
            &e,
            Some(mmenn::MmennError::Core {
                source: mmenn::sysid_core::CoreError::Diverged { .. },
                ..
            })
        ),
        "{e:?}"
    );
}

/// `x' = −a·x + b·u + d`, `y = x`: the offset `d` starts at 0 and is unbounded.
const OFFSET: &str = r#"
states = ["x"]
inputs = ["u"]
measured = ["x"]
corrected = ["x"]
noise_variance = [1.0e-4]

[parameters]
a = { value = 0.5, bounds = [0.01, 10.0] }
b = { value = 0.8, bounds = [0.0, 10.0] }
d = { value = 0.0 }

[[terms]]
state = "x"
effect = "decay_offset"
term = "-a*x + b*u + d"
"#;

/// A parameter that starts at 0 with infinite bounds is explored at the scale of the file's
/// own start's estimate (before, it stayed 0 in every seeded start). Record: 400 samples of
/// `x' = −x + u + 0.3` from x(0) = 0.2, exact under a zero-order hold, N(0, 0.01²) noise.
/// Every seeded start must draw `d` away from 0 with an RMS within a factor of 3 of `|d̂|`
/// of start 0 (about 0.3; 8 draws), and the starts still end at one minimum.
#[test]
fn a_zero_start_parameter_is_drawn_at_its_estimates_scale() {
    let dir = scratch("offset");
    let model = write(&dir, "model.toml", OFFSET);
    let data = first_order_record(&dir, "offset.csv", 13, 0.2, 0.3);
    let single = greyest(&model, &data, &GreyestOptions::default(), &dir.join("one"));
    let d0 = single.parameter("d").unwrap().value;
    assert!((d0 - 0.3).abs() < 0.05, "d̂ = {d0}");
    let multi = greyest(&model, &data, &starts(8, 1), &dir.join("multi"));
    let ms = multi.summary.multi_start.as_ref().unwrap();
    let j = ms.parameter_names.iter().position(|p| p == "d").unwrap();
    let drawn: Vec<f64> = ms
        .starts
        .iter()
        .filter(|s| s.index > 0)
        .map(|s| s.start[j])
        .collect();
    assert_eq!(drawn.len(), 8);
    assert!(drawn.iter().all(|v| *v != 0.0), "{drawn:?}");
    let rms = (drawn.iter().map(|v| v * v).sum::<f64>() / drawn.len() as f64).sqrt();
    assert!(rms > d0 / 3.0 && rms < 3.0 * d0, "RMS {rms} against d̂ {d0}");
    assert_eq!(ms.minima.len(), 1, "{ms:#?}");
}

/// `x' = −a·x + b·u − c·max(x − 10, 0)`: a tank (level `x`) whose overflow above 10 drains at
/// rate `c`. `c` starts at 1 within [0, 100], so every seeded start draws it
/// (`1·exp(0.7·z)`).
const OVERFLOW: &str = r#"
states = ["x"]
inputs = ["u"]
measured = ["x"]
corrected = ["x"]
noise_variance = [1.0e-4]

[parameters]
a = { value = 0.5, bounds = [0.01, 10.0] }
b = { value = 0.8, bounds = [0.0, 10.0] }
c = { value = 1.0, bounds = [0.0, 100.0] }

[[terms]]
state = "x"
effect = "leak_overflow"
term = "-a*x + b*u - c*max(x - 10, 0)"
"#;

/// The record of `x' = −x + u` (|x| stays under 2) never reaches the overflow level 10: the
/// overflow term is 0 along every free run, `c` has no effect on it and its gradient is 0,
/// so every start ends with the `c` it drew while `a` and `b` reach the same values.
/// Before, those starts were distinct minima of the same cost and the warning said "these
/// data do not pin c". Now: `c` is not exercised (sensitivity 0) at every converged start,
/// it is left out of the comparison (one minimum, no warning), and a note says plainly that
/// the records never exercise it. `a` and `b` are exercised, and no start is a saddle.
#[test]
fn a_term_the_records_never_reach_is_not_exercised_rather_than_not_pinned() {
    let dir = scratch("overflow");
    let model = write(&dir, "model.toml", OVERFLOW);
    let data = first_order_record(&dir, "overflow.csv", 11, 0.3, 0.0);
    let out = dir.join("out");
    let outcome = greyest(&model, &data, &starts(6, 1), &out);
    let ms = outcome.summary.multi_start.as_ref().unwrap();
    let c = ms.parameter_names.iter().position(|n| n == "c").unwrap();
    let converged: Vec<_> = ms.starts.iter().filter(|s| s.converged).collect();
    assert!(converged.len() >= 4, "{ms:#?}");
    // The starts really end with different c (it never moves): over 10 % apart, which the
    // comparison of all parameters would call different minima.
    let cs: Vec<f64> = converged.iter().map(|s| s.values[c]).collect();
    let (lo, hi) = cs
        .iter()
        .fold((f64::INFINITY, 0.0f64), |(l, h), v| (l.min(*v), h.max(*v)));
    assert!(hi > 1.1 * lo, "{cs:?}");
    for s in &converged {
        // (To rounding: the solver's change of variable for two bounds.)
        assert!(
            (s.values[c] - s.start[c]).abs() <= 1e-12 * s.start[c],
            "{s:?}"
        );
        assert_eq!(s.not_exercised, vec!["c".to_string()], "{s:?}");
        assert_eq!(s.sensitivity[c], Some(0.0), "{s:?}");
        assert!(!s.saddle, "{s:?}");
        for (j, v) in s.sensitivity.iter().enumerate() {
            if j != c {
                assert!(v.is_some_and(|v| v > 1e-2), "{s:?}");
            }
        }
    }
    // One minimum (c left out), no warning naming c.
    assert_eq!(ms.minima.len(), 1, "{ms:#?}");
    assert_eq!(ms.minima[0].not_exercised, vec!["c".to_string()]);
    assert_eq!(ms.minima[0].starts.len(), converged.len(), "{ms:#?}");
    assert!(
        ms.not_pinned
            .iter()
            .all(|w| w.parameters.iter().all(|p| p.name != "c")),
        "{ms:#?}"
    );
    assert!(ms.not_pinned.is_empty(), "{ms:#?}");
    assert_eq!(ms.valleys.len(), 1, "{ms:#?}");
    assert!(ms.valleys[0].spread < DIFFERENT, "{ms:#?}");
    // The note.
    assert_eq!(ms.not_exercised.len(), 1, "{ms:#?}");
    let note = &ms.not_exercised[0];
    assert_eq!(note.name, "c");
    assert_eq!(note.starts.len(), converged.len());
    assert!((note.lowest - lo).abs() < 1e-12 && (note.highest - hi).abs() < 1e-12);
    let lines = ms.terminal_lines();
    assert!(
        lines.iter().any(|l| l.starts_with(
            "note: parameter c has no effect on the free run at the kept estimate: the \
             records never exercise it"
        )),
        "{lines:#?}"
    );
    assert!(
        !lines.iter().any(|l| l.starts_with("warning:")),
        "{lines:#?}"
    );
    assert!(
        lines
            .iter()
            .any(|l| l.contains("not exercised by these records: c")),
        "{lines:#?}"
    );
    let report = std::fs::read_to_string(out.join("report.md")).unwrap_or_default();
    assert!(!report.contains("do not pin"), "{report}");
    assert!(
        report.contains("**Note**: parameter c has no effect"),
        "{report}"
    );
    let json: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(out.join("greyest.json")).unwrap_or_default(),
    )
    .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(json["multi_start"]["minima"][0]["not_exercised"][0], "c");
    assert_eq!(json["multi_start"]["starts"][0]["not_exercised"][0], "c");
    assert_eq!(json["multi_start"]["not_exercised"][0]["name"], "c");
    assert_eq!(json["multi_start"]["probe"]["not_exercised"], 1e-6);
}

/// [`mmenn::greyest::multistart::DIFFERENT_PARAMETER`].
const DIFFERENT: f64 = mmenn::greyest::multistart::DIFFERENT_PARAMETER;
