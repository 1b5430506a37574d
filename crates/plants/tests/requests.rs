//! The entry point `simulate_system`: determinism and noise, rates, parameter
//! overrides, and typed errors for bad requests.

use plants::{
    MIN_NOISE_VARIANCE, MSD_DAMPING_CLASSES, PlantError, Recipe, SimulationRequest, simulate_system,
};

fn req(system: &str) -> SimulationRequest {
    SimulationRequest {
        system: system.into(),
        ..SimulationRequest::default()
    }
}

/// Same seed ⇒ bit-identical data; another seed ⇒ other noise on the same truth; the
/// noise (data − C·truth) has the requested variance. The MSD training record has
/// 1001 samples; the sample variance's relative standard deviation is √(2/1000) ≈ 4.5 %,
/// so 20 % is over four of them. A long pendulum record (20 001 samples, s.d. 1 %) is held
/// to 5 %.
#[test]
fn seeds_and_noise_variance() {
    let a = simulate_system(&SimulationRequest {
        seed: 5,
        ..req("msd_cubic")
    })
    .unwrap();
    let b = simulate_system(&SimulationRequest {
        seed: 5,
        ..req("msd_cubic")
    })
    .unwrap();
    let c = simulate_system(&SimulationRequest {
        seed: 6,
        ..req("msd_cubic")
    })
    .unwrap();
    assert_eq!(a, b);
    assert_eq!(a.truth, c.truth);
    assert_ne!(a.data, c.data);
    for (sim, tol, var) in [
        (a, 0.2, 0.09),
        (
            simulate_system(&SimulationRequest {
                noise_variance: Some(2.5e-3),
                duration: Some(200.0),
                ..req("pendulum")
            })
            .unwrap(),
            0.05,
            2.5e-3,
        ),
    ] {
        let y = sim.data.experiments()[0].outputs();
        let noise = y - sim.assumed.model.c() * &sim.truth.states;
        let n = noise.ncols() as f64;
        let mean = noise.row(0).sum() / n;
        let v = noise.row(0).iter().map(|e| (e - mean).powi(2)).sum::<f64>() / (n - 1.0);
        assert!((v / var - 1.0).abs() < tol, "sample variance {v} vs {var}");
        assert_eq!(sim.assumed.noise_variance, vec![var]);
    }
}

/// Train and test recipes with the same seed draw independent noise (different ChaCha
/// streams): their noise sequences are uncorrelated (|ρ| < 4/√N).
#[test]
fn train_and_test_noise_are_independent() {
    let tr = simulate_system(&SimulationRequest {
        seed: 1,
        ..req("van_der_pol")
    })
    .unwrap();
    let te = simulate_system(&SimulationRequest {
        seed: 1,
        recipe: Recipe::Test,
        ..req("van_der_pol")
    })
    .unwrap();
    let e = |s: &plants::SimulatedData| {
        s.data.experiments()[0].outputs() - s.assumed.model.c() * &s.truth.states
    };
    let (a, b) = (e(&tr), e(&te));
    let n = a.ncols() as f64;
    let rho = a.dot(&b) / (a.norm() * b.norm());
    assert!(rho.abs() < 4.0 / n.sqrt(), "correlation {rho}");
    assert_ne!(tr.truth.inputs, te.truth.inputs);
}

/// A clean request is served with the documented floor, and the spec reports it.
#[test]
fn clean_request_uses_the_floor() {
    let s = simulate_system(&SimulationRequest {
        noise_variance: Some(0.0),
        ..req("pendulum")
    })
    .unwrap();
    assert_eq!(s.assumed.noise_variance, vec![MIN_NOISE_VARIANCE]);
    let noise = s.data.experiments()[0].outputs() - s.assumed.model.c() * &s.truth.states;
    assert!(noise.amax() < 10.0 * MIN_NOISE_VARIANCE.sqrt());
}

/// Two-tank data at 10, 5, 1 and 0.5 Hz share one input (APRBS switches on a 2 s grid),
/// so each slower truth is every k-th sample of the 10 Hz truth, up to integration error
/// (DP rtol 1e-10: 1e-8 m is generous); the record always spans 360 s.
#[test]
fn two_tank_rates_share_one_truth() {
    let fast = simulate_system(&req("two_tank")).unwrap();
    assert_eq!(fast.truth.states.ncols(), 3601);
    for (fs, k) in [(5.0, 2), (1.0, 10), (0.5, 20)] {
        let slow = simulate_system(&SimulationRequest {
            fs: Some(fs),
            ..req("two_tank")
        })
        .unwrap();
        let n = slow.truth.states.ncols();
        assert_eq!(n, 3600 / k + 1, "fs {fs}");
        assert!((slow.truth.dt - 1.0 / fs).abs() < 1e-15);
        for j in 0..n {
            let (us, uf) = (slow.truth.inputs[(0, j)], fast.truth.inputs[(0, k * j)]);
            assert!(
                us.to_bits() == uf.to_bits(),
                "fs {fs} sample {j}: {us} vs {uf}"
            );
            for i in 0..2 {
                let gap = (slow.truth.states[(i, j)] - fast.truth.states[(i, k * j)]).abs();
                assert!(gap < 1e-8, "fs {fs}, state {i}, sample {j}: {gap}");
            }
        }
    }
}

/// Overrides reach the plant: the MSD correction at each damping class is
/// `−(k/m)x³ − (c/m)v` with that `c`, recomputed here from the stored truth states.
#[test]
fn damping_overrides_change_the_truth() {
    for c in MSD_DAMPING_CLASSES {
        let s = simulate_system(&SimulationRequest {
            params: vec![("c".into(), c)],
            ..req("msd_cubic")
        })
        .unwrap();
        for k in (0..s.truth.states.ncols()).step_by(97) {
            let (x, v) = (s.truth.states[(0, k)], s.truth.states[(1, k)]);
            let want = -0.5 * x.powi(3) - c * v;
            assert!((s.truth.corrections[(0, k)] - want).abs() < 1e-12 * want.abs().max(1.0));
        }
    }
    let s = simulate_system(&SimulationRequest {
        params: vec![("c2".into(), plants::JOINT_DAMPING_CLASSES[4])],
        duration: Some(2.0),
        ..req("double_pendulum")
    })
    .unwrap();
    assert_eq!(s.truth.states.ncols(), 201);
}

#[test]
fn data_names_units_and_shapes() {
    let s = simulate_system(&req("double_pendulum")).unwrap();
    assert_eq!(s.data.output_names(), vec!["theta1", "theta2"]);
    assert_eq!(s.data.input_names(), vec!["u"]);
    assert_eq!(s.data.output_channels()[0].unit.as_deref(), Some("rad"));
    assert_eq!(s.data.input_channels()[0].unit.as_deref(), Some("m/s^2"));
    assert_eq!(s.truth.correction_names, vec!["d_omega1", "d_omega2"]);
    assert_eq!(
        s.assumed.units.get("d_omega1").map(String::as_str),
        Some("rad/s^2")
    );
    assert_eq!(s.truth.states.nrows(), 4);
    assert_eq!(s.truth.corrections.nrows(), 2);
    assert_eq!(s.data.experiments()[0].len(), s.truth.states.ncols());
}

#[test]
fn bad_requests_are_typed_errors() {
    let e = simulate_system(&req("triple_pendulum")).unwrap_err();
    assert!(matches!(e, PlantError::UnknownSystem { ref name } if name == "triple_pendulum"));

    let e = simulate_system(&SimulationRequest {
        params: vec![("zeta".into(), 1.0)],
        ..req("msd_cubic")
    })
    .unwrap_err();
    assert!(
        matches!(e, PlantError::UnknownParameter { system: "msd_cubic", ref name } if name == "zeta")
    );

    let e = simulate_system(&SimulationRequest {
        params: vec![("m".into(), f64::NAN)],
        ..req("msd_cubic")
    })
    .unwrap_err();
    assert!(matches!(e, PlantError::InvalidParameter { ref name, .. } if name == "m"));

    let e = simulate_system(&SimulationRequest {
        params: vec![("l".into(), -1.0)],
        ..req("pendulum")
    })
    .unwrap_err();
    assert!(
        matches!(e, PlantError::InvalidParameter { system: "pendulum", ref name, .. } if name == "l")
    );

    let e = simulate_system(&SimulationRequest {
        noise_variance: Some(-0.1),
        ..req("msd_cubic")
    })
    .unwrap_err();
    assert!(matches!(
        e,
        PlantError::InvalidRequest {
            field: "noise_variance",
            ..
        }
    ));

    for fs in [0.0, -10.0, f64::INFINITY, f64::NAN] {
        let e = simulate_system(&SimulationRequest {
            fs: Some(fs),
            ..req("msd_cubic")
        })
        .unwrap_err();
        assert!(
            matches!(e, PlantError::InvalidRequest { field: "fs", .. }),
            "fs {fs}"
        );
    }

    for duration in [0.0, -1.0, 1e-5, 1e9] {
        let e = simulate_system(&SimulationRequest {
            duration: Some(duration),
            ..req("msd_cubic")
        })
        .unwrap_err();
        assert!(
            matches!(
                e,
                PlantError::InvalidRequest {
                    field: "duration",
                    ..
                }
            ),
            "duration {duration}"
        );
    }
}
