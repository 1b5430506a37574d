//! Thesis §2.5: cubic mass–spring–damper, position measured with noise variance 0.09,
//! linear assumed model without damping or cubic term, velocity corrected, W by the
//! covariance constraint, one sub-step, 20 s records (2001 samples).

use mme_core::{MmeConfig, NoiseSpec, WeightSpec, estimate_with_report};
use sysid_core::Termination;

use super::common::{CubicMsd, msd_assumed, msd_data, r2, row};

/// `(R² of d̂ over the record, R² of d̂ without the first and last 5 %, R² of v̂)`.
fn run(seed: u64) -> (f64, f64, f64) {
    let len = 2001;
    let (data, truth) = msd_data(len, 0.09, seed);
    let config = MmeConfig {
        w: WeightSpec::default(),
        noise_variance: NoiseSpec::Given(vec![0.09]),
        substeps: Some(1),
        ..MmeConfig::default()
    };
    let out = estimate_with_report(&msd_assumed(), &data, &config).unwrap();
    assert_eq!(
        out.w_search.as_ref().unwrap().termination,
        Termination::Converged
    );
    let est = &out.estimate.experiments[0];
    // Piece k is held on [t_k, t_k+1): compare with the truth at the interval midpoint.
    let d_true: Vec<f64> = (0..len - 1)
        .map(|k| {
            let c = |k: usize| CubicMsd::correction(truth[(0, k)], truth[(1, k)]);
            0.5 * (c(k) + c(k + 1))
        })
        .collect();
    let d_hat = row(&est.corrections, 0);
    let cut = (len - 1) / 20;
    let inner = r2(&d_true[cut..len - 1 - cut], &d_hat[cut..len - 1 - cut]);
    (
        r2(&d_true, &d_hat),
        inner,
        r2(&row(&truth, 1), &row(&est.states, 1)),
    )
}

/// The targets (R² ≥ 0.85 / 0.95 / 0.99) are asserted on the median of nine noise
/// realisations. Single realisations scatter around them (observed: 0.851–0.895 /
/// 0.928–0.965 / 0.986–0.995) because the covariance constraint sets W from a residual
/// variance that itself has a sampling error of √(2/N) ≈ 3 %, which moves W by a factor
/// of up to ~3; even the best constant W for each realisation (found by a scan) reaches
/// only 0.955–0.966 in the interior. Every realisation must clear floors 0.01–0.03 below
/// the targets.
#[test]
fn cubic_msd_correction_and_unmeasured_velocity_are_recovered() {
    let mut all = Vec::new();
    let mut inner = Vec::new();
    let mut vel = Vec::new();
    for seed in 1..=9 {
        let (a, i, v) = run(seed);
        assert!(
            a >= 0.84 && i >= 0.92 && v >= 0.985,
            "seed {seed}: {a} {i} {v}"
        );
        all.push(a);
        inner.push(i);
        vel.push(v);
    }
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let (a, i, v) = (median(&mut all), median(&mut inner), median(&mut vel));
    assert!(a >= 0.85, "median whole-record R² of d̂ {a}");
    assert!(i >= 0.95, "median interior R² of d̂ {i}");
    assert!(v >= 0.99, "median R² of the unmeasured velocity {v}");
}
