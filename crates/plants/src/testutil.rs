//! Test helpers shared by the plant modules (compiled for tests only).

use nalgebra::DMatrix;
use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};
use sysid_core::Dynamics;

/// Uniform random point in the given per-coordinate ranges.
pub(crate) fn random_point(rng: &mut ChaCha8Rng, ranges: &[(f64, f64)]) -> Vec<f64> {
    ranges
        .iter()
        .map(|(lo, hi)| lo + (hi - lo) * rng.random::<f64>())
        .collect()
}

/// Compare a plant's `jacobians` with central differences of its `rhs` at 100 random
/// points. Central differences with step `h = 1e-5·max(1, |x|)` have truncation error
/// ~h²·|f'''| and round-off ~ε|f|/h; 1e-6 relative to the entry scale covers both here.
pub(crate) fn check_jacobians<D: Dynamics>(
    f: &D,
    x_ranges: &[(f64, f64)],
    u_range: (f64, f64),
    seed: u64,
) {
    let n = f.n_states();
    let m = f.n_inputs();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut a = DMatrix::zeros(n, n);
    let mut b = DMatrix::zeros(n, m);
    let mut fp = vec![0.0; n];
    let mut fm = vec![0.0; n];
    for _ in 0..100 {
        let x = random_point(&mut rng, x_ranges);
        let u = random_point(&mut rng, &vec![u_range; m]);
        f.jacobians(0.0, &x, &u, &mut a, &mut b);
        for j in 0..n + m {
            let (mut xp, mut up) = (x.clone(), u.clone());
            let (mut xm, mut um) = (x.clone(), u.clone());
            let h = if j < n {
                let h = 1e-5 * x[j].abs().max(1.0);
                xp[j] += h;
                xm[j] -= h;
                h
            } else {
                let h = 1e-5 * u[j - n].abs().max(1.0);
                up[j - n] += h;
                um[j - n] -= h;
                h
            };
            f.rhs(0.0, &xp, &up, &mut fp);
            f.rhs(0.0, &xm, &um, &mut fm);
            for i in 0..n {
                let fd = (fp[i] - fm[i]) / (2.0 * h);
                let an = if j < n { a[(i, j)] } else { b[(i, j - n)] };
                assert!(
                    (fd - an).abs() <= 1e-6 * an.abs().max(1.0),
                    "entry ({i}, {j}) at x = {x:?}, u = {u:?}: analytic {an}, differences {fd}"
                );
            }
        }
    }
}
