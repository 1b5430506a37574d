//! A hand-written classical RK4 for two-state truths, sharing no code with the workspace's
//! integrators, so a test's record is not made by the code it checks.

/// The state of `ẋ = f(t, x)` at `t = k·dt` for `k = 0..len`, from `x0`, by RK4 with
/// `sub` equal steps per sample.
pub fn rk4_samples(
    f: impl Fn(f64, [f64; 2]) -> [f64; 2],
    x0: [f64; 2],
    dt: f64,
    len: usize,
    sub: usize,
) -> Vec<[f64; 2]> {
    let h = dt / sub as f64;
    let mut x = x0;
    let mut out = Vec::with_capacity(len);
    for k in 0..len {
        let t = k as f64 * dt;
        out.push(x);
        for j in 0..sub {
            let s = t + j as f64 * h;
            let k1 = f(s, x);
            let k2 = f(
                s + h / 2.0,
                [x[0] + h / 2.0 * k1[0], x[1] + h / 2.0 * k1[1]],
            );
            let k3 = f(
                s + h / 2.0,
                [x[0] + h / 2.0 * k2[0], x[1] + h / 2.0 * k2[1]],
            );
            let k4 = f(s + h, [x[0] + h * k3[0], x[1] + h * k3[1]]);
            for i in 0..2 {
                x[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
            }
        }
    }
    out
}
