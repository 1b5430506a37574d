//! The discovery workflow on the `oscillator` test bench: one known linear oscillator,
//! one hidden effect at a time (or two, or none, or one outside the catalogue), at 2 %
//! and 5 % measurement noise (σ = 1 cm and 2.5 cm on a response of RMS ≈ 0.48 m). The
//! truth is known, so every verdict, name and calibrated coefficient is checked against
//! it, and the validation record (a different input) must be simulated better.
//!
//! Also the two-tank plant, whose assumed model has linear outflows where the truth has
//! orifice (`√h`) outflows: the named terms must be the orifice laws and the exact
//! cancellation of the assumed linear outflows — and, with only the lower level
//! measured, no name at all (the upper level's scale is free and several term sets fit).

use mmenn::discover::{DiscoverOptions, DiscoverSummary, run_discover};
use mmenn::plants::{Recipe, SimulationRequest};
use mmenn::simulate::run_simulate;
/// σ = 1 cm (2 % of the response RMS) and σ = 2.5 cm (5 %).
const LOW: f64 = 1e-4;
const HIGH: f64 = 6.25e-4;

fn run(label: &str, params: &[(&str, f64)], noise: f64) -> DiscoverSummary {
    run_system("oscillator", None, label, params, noise, 5, &[])
}

/// Remove the `hidden` output channels from a simulated record's data and model (the
/// measured-states list and the per-channel noise variances, all `noise`).
fn hide_outputs(data: &std::path::Path, model: &std::path::Path, hidden: &[&str], noise: f64) {
    let text = std::fs::read_to_string(data).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let keep: Vec<usize> = (0..header.len())
        .filter(|&i| !hidden.contains(&header[i]))
        .collect();
    let pick = |row: &str| {
        let cells: Vec<&str> = row.split(',').collect();
        keep.iter().map(|&i| cells[i]).collect::<Vec<_>>().join(",")
    };
    let mut out = pick(&header.join(","));
    for row in lines {
        out.push('\n');
        out.push_str(&pick(row));
    }
    std::fs::write(data, out + "\n").unwrap();
    let spec = std::fs::read_to_string(model).unwrap();
    let mut edited = Vec::new();
    for line in spec.lines() {
        if let Some(list) = line.strip_prefix("measured = ") {
            let names: Vec<&str> = list
                .trim_matches(|c| c == '[' || c == ']')
                .split(',')
                .map(|n| n.trim().trim_matches('"'))
                .filter(|n| !hidden.contains(n))
                .collect();
            let quoted: Vec<String> = names.iter().map(|n| format!("\"{n}\"")).collect();
            edited.push(format!("measured = [{}]", quoted.join(", ")));
            edited.push(format!(
                "noise_variance = [{}]",
                vec![format!("{noise:e}"); names.len()].join(", ")
            ));
        } else if !line.starts_with("noise_variance") {
            edited.push(line.to_string());
        }
    }
    std::fs::write(model, edited.join("\n") + "\n").unwrap();
}

/// Simulate training (seed `seed`) and test (seed `seed + 1`) records, hide the
/// `hidden` outputs, and discover.
fn run_system(
    system: &str,
    fs: Option<f64>,
    label: &str,
    params: &[(&str, f64)],
    noise: f64,
    seed: u64,
    hidden: &[&str],
) -> DiscoverSummary {
    let dir = std::env::temp_dir().join(format!(
        "mmenn-hidden-{}-{label}-{noise}",
        std::process::id()
    ));
    let _ = std::fs::remove_dir_all(&dir);
    let req = |recipe, seed| SimulationRequest {
        system: system.into(),
        recipe,
        seed,
        fs,
        noise_variance: Some(noise),
        params: params.iter().map(|(n, v)| (n.to_string(), *v)).collect(),
        ..Default::default()
    };
    let train = run_simulate(&req(Recipe::Train, seed), &dir.join("train")).unwrap();
    let test = run_simulate(&req(Recipe::Test, seed + 1), &dir.join("test")).unwrap();
    if !hidden.is_empty() {
        hide_outputs(&train.data, &train.model, hidden, noise);
        hide_outputs(&test.data, &test.model, hidden, noise);
    }
    let s = run_discover(
        std::slice::from_ref(&train.data),
        &train.model,
        std::slice::from_ref(&test.data),
        &DiscoverOptions::default(),
        &dir.join("out"),
    )
    .unwrap();
    std::fs::remove_dir_all(&dir).unwrap();
    s
}

/// The verdict is `found`, exactly the expected effects are named (catalogue name and
/// truth coefficient of the correction `d` on `v̇`, i.e. force / m with m = 1), each
/// calibrated coefficient within 3 % of the truth (measured errors are below 1 %) with
/// its 95 % interval covering the truth, and
/// the validation free-run RMSE falls at least threefold.
fn expect_found(s: &DiscoverSummary, expected: &[(&str, f64)]) {
    assert_eq!(format!("{:?}", s.verdict), "Found", "{:?}", s.unconfirmed);
    let mut names: Vec<&str> = s.effects.iter().map(|e| e.name.as_str()).collect();
    names.sort_unstable();
    let mut want: Vec<&str> = expected.iter().map(|(n, _)| *n).collect();
    want.sort_unstable();
    assert_eq!(names, want, "{:?}", s.effects);
    for (name, truth) in expected {
        let e = s.effects.iter().find(|e| e.name == *name).unwrap();
        assert_eq!(e.state, "v");
        assert!(
            (e.coefficient - truth).abs() < 0.03 * truth.abs(),
            "{name}: {} vs truth {truth}",
            e.coefficient
        );
        let [lo, hi] = e.ci95.expect("calibrated interval");
        assert!(
            lo <= *truth && *truth <= hi,
            "{name}: 95 % interval [{lo}, {hi}] misses the truth {truth}"
        );
    }
    let v = s.validation_gap.as_ref().unwrap();
    assert!(
        v.after.rmse["x"] < v.before.rmse["x"] / 3.0,
        "validation RMSE {} → {}",
        v.before.rmse["x"],
        v.after.rmse["x"]
    );
}

#[test]
fn cubic_hardening_at_both_noise_levels() {
    for noise in [LOW, HIGH] {
        expect_found(
            &run("hard", &[("k3", 1.0)], noise),
            &[("cubic_stiffness", -1.0)],
        );
    }
}

#[test]
fn cubic_softening_at_both_noise_levels() {
    for noise in [LOW, HIGH] {
        expect_found(
            &run("soft", &[("k3", -0.4)], noise),
            &[("cubic_stiffness", 0.4)],
        );
    }
}

#[test]
fn quadratic_drag_at_both_noise_levels() {
    for noise in [LOW, HIGH] {
        expect_found(
            &run("drag", &[("cq", 0.5)], noise),
            &[("quadratic_drag", -0.5)],
        );
    }
}

#[test]
fn coulomb_friction_at_both_noise_levels() {
    // Truth −0.2·tanh(v/0.001); the catalogue's smooth Coulomb term uses its own
    // velocity scale, which is equivalent away from v = 0.
    for noise in [LOW, HIGH] {
        expect_found(
            &run("coulomb", &[("fc", 0.2)], noise),
            &[("coulomb_friction_smooth", -0.2)],
        );
    }
}

#[test]
fn two_effects_at_once_high_noise() {
    expect_found(
        &run("two", &[("k3", 1.0), ("fc", 0.2)], HIGH),
        &[("cubic_stiffness", -1.0), ("coulomb_friction_smooth", -0.2)],
    );
}

/// An actuator that saturates at 1 N, a limit between the library's starting thresholds
/// (the 75 % and 90 % quantiles of |u|): one saturation term, its limit calibrated to the
/// truth within 3 %.
#[test]
fn input_saturation_off_the_library_grid_low_noise() {
    let s = run("sat", &[("u_max", 1.0)], LOW);
    expect_found(&s, &[("input_saturation", -1.0)]);
    let limit = s.effects[0].parameters["limit"];
    assert!((limit - 1.0).abs() < 0.03, "limit {limit}");
}

/// An actuator dead zone of half-width 0.3 N (between the library's starting widths at
/// the 10 % and 25 % quantiles of |u|): one dead-zone term — not an input gain plus a
/// saturation, its two-term equivalent — with its width calibrated within 5 %.
#[test]
fn dead_zone_off_the_library_grid_high_noise() {
    let s = run("dead", &[("u_dead", 0.3)], HIGH);
    expect_found(&s, &[("dead_zone", -1.0)]);
    let width = s.effects[0].parameters["width"];
    assert!((width - 0.3).abs() < 0.015, "width {width}");
}

/// Coulomb friction with a wide transition (tanh(v/0.05), five times the library's
/// starting smoothing velocity): named as Coulomb alone — no Stribeck hump making up for
/// the shape — with its transition velocity calibrated within 25 % (measured: 10 %).
#[test]
fn wide_coulomb_transition_high_noise() {
    let s = run("coulomb-wide", &[("fc", 0.15), ("eps", 0.05)], HIGH);
    expect_found(&s, &[("coulomb_friction_smooth", -0.15)]);
    let eps = s.effects[0].parameters["eps"];
    assert!((eps / 0.05 - 1.0).abs() < 0.25, "eps {eps}");
}

#[test]
fn correct_model_gives_none() {
    for noise in [LOW, HIGH] {
        let s = run("none", &[], noise);
        assert_eq!(format!("{:?}", s.verdict), "None", "noise {noise}");
        assert!(s.effects.is_empty() && s.unconfirmed.is_empty());
    }
}

/// A correct model at 1 % noise (σ = 4.8 mm) where MME's automatic W reaches its cap and
/// `d̂` is numerical zero (RMS ~1e-13, its floor likewise): the regression then sees a
/// ratio of two zeros and proposes nothing. The free-run cost decides, and it is at the
/// noise level: `none` (this record gave `unexplained` before the first round's free-run
/// search ran without a proposal).
#[test]
fn correct_model_with_d_hat_at_numerical_zero_gives_none() {
    let s = run_system("oscillator", None, "zero", &[], 2.3e-5, 49, &[]);
    assert_eq!(format!("{:?}", s.verdict), "None");
    assert!(s.effects.is_empty() && s.unconfirmed.is_empty());
}

#[test]
fn contact_spring_outside_the_catalogue_is_unexplained_without_a_name() {
    // A one-sided spring kc·max(0, x − 0.3): no catalogue term has this shape.
    let s = run("contact", &[("kc", 20.0)], LOW);
    assert_eq!(format!("{:?}", s.verdict), "Unexplained");
    assert!(s.effects.is_empty(), "wrongly named: {:?}", s.effects);
}

/// Two tanks with the default parameters (α1 = 0.03, α2 = 0.035 m^½/s, β = 0.003,
/// u0 = 5 V; levels 0.15–0.29 m), both levels measured at 2 Hz with σ = 3.2 mm and
/// 6.3 mm (about 1.3 % and 2.5 % of the mean level). The truth's correction of the
/// assumed chord model is `d1 = −α1√h1 + a1 h1`, `d2 = +α1√h1 − a1 h1 − α2√h2 + a2 h2`
/// with `a1 = α1/√h1*`, `a2 = α2/√h2*` (`h1* = (β u0/α1)²`, `h2* = (α1/α2)² h1*`): the
/// upper tank's orifice outflow, which is the lower tank's inflow (one transfer term
/// `h1 → h2`), the cancellation of the assumed linear outflow (another transfer), and
/// the lower tank's own orifice outflow and linear cancellation. Each must be named with
/// its 95 % interval covering the truth, and the validation free-run RMSE of both
/// levels must fall at least twofold (measured: about fivefold).
fn expect_tank_orifices(noise: f64) {
    let (alpha1, alpha2, beta, u0) = (0.03_f64, 0.035_f64, 0.003, 5.0);
    let h1 = (beta * u0 / alpha1).powi(2);
    let h2 = (alpha1 / alpha2).powi(2) * h1;
    let (a1, a2) = (alpha1 / h1.sqrt(), alpha2 / h2.sqrt());
    let s = run_system("two_tank", Some(2.0), "tank", &[], noise, 5, &[]);
    assert_eq!(format!("{:?}", s.verdict), "Found", "{:?}", s.unconfirmed);
    // (effect, equation, transfer target, term, truth)
    let want = [
        (
            "orifice_outflow",
            "h1",
            Some("h2"),
            "sqrt(abs(h1))",
            -alpha1,
        ),
        ("linear_coupling", "h1", Some("h2"), "h1", a1),
        ("orifice_outflow", "h2", None, "sqrt(abs(h2))", -alpha2),
        ("linear_coupling", "h2", None, "h2", a2),
    ];
    assert_eq!(s.effects.len(), want.len(), "{:?}", s.effects);
    for (name, state, into, term, truth) in want {
        let e = s
            .effects
            .iter()
            .find(|e| e.state == state && e.term == term)
            .unwrap_or_else(|| panic!("{term} in d({state}) not named: {:?}", s.effects));
        assert_eq!((e.name.as_str(), e.into.as_deref()), (name, into), "{e:?}");
        let [lo, hi] = e.ci95.expect("calibrated interval");
        assert!(
            lo <= truth && truth <= hi,
            "{term} in d({state}): 95 % interval [{lo}, {hi}] misses the truth {truth}"
        );
    }
    let v = s.validation_gap.as_ref().unwrap();
    for level in ["h1", "h2"] {
        assert!(
            v.after.rmse[level] < v.before.rmse[level] / 2.0,
            "{level}: validation RMSE {} → {}",
            v.before.rmse[level],
            v.after.rmse[level]
        );
    }
}

#[test]
fn tank_orifice_outflow_low_noise() {
    expect_tank_orifices(1e-5);
}

#[test]
fn tank_orifice_outflow_high_noise() {
    expect_tank_orifices(4e-5);
}

/// The same two tanks with only the lower level measured. The upper level's scale is
/// then free (both tank equations are corrected), and several sets of catalogue terms
/// simulate the lower level to the noise level: at this seed the search reaches it with
/// a halved input gain into the upper tank, a reverse coupling and `√h2` (judged cost
/// 1.007), and without those terms with `√h1` into the lower tank and a bias (1.040, bound
/// 1.158). No set may be claimed; the ambiguity is reported with both explanations.
#[test]
fn tank_with_only_the_lower_level_measured_is_ambiguous() {
    let s = run_system("two_tank", Some(2.0), "tank-h2", &[], 1e-5, 5, &["h1"]);
    assert_eq!(format!("{:?}", s.verdict), "Unexplained");
    assert!(s.effects.is_empty(), "claimed: {:?}", s.effects);
    let a = s.ambiguity.as_ref().expect("ambiguity reported");
    assert_eq!(a.free_states, vec!["h1".to_string()]);
    assert_ne!(a.named, a.alternative);
    for cost in [a.named_cost, a.alternative_cost] {
        assert!(cost <= s.claim_bound, "{a:?} against {}", s.claim_bound);
    }
}
