//! Small dense linear solves on the stack for the mass-matrix form: LU with partial
//! pivoting of an `n × n` matrix, `n ≤ MAX_DOF`, no allocation.

/// Most generalized coordinates a mechanical model may have (the factor lives on the
/// stack: `MAX_DOF²` values).
pub const MAX_DOF: usize = 8;

/// An LU factorisation `P·M = L·U` of a small matrix, stored row-major in place.
#[derive(Debug, Clone, Copy)]
pub(crate) struct SmallLu {
    n: usize,
    lu: [f64; MAX_DOF * MAX_DOF],
    perm: [usize; MAX_DOF],
    /// Whether every pivot was finite and nonzero (else solves give NaN).
    ok: bool,
}

impl SmallLu {
    /// Factor the row-major `n × n` matrix `m` (`m.len() ≥ n²`, `n ≤ MAX_DOF`).
    pub(crate) fn factor(m: &[f64], n: usize) -> SmallLu {
        debug_assert!(n <= MAX_DOF && m.len() >= n * n);
        let mut lu = [0.0; MAX_DOF * MAX_DOF];
        lu[..n * n].copy_from_slice(&m[..n * n]);
        let mut perm = [0; MAX_DOF];
        for (i, p) in perm.iter_mut().enumerate().take(n) {
            *p = i;
        }
        let mut ok = true;
        for k in 0..n {
            // Partial pivoting: the largest magnitude in column k at or below row k.
            let mut piv = k;
            for i in k + 1..n {
                if lu[i * n + k].abs() > lu[piv * n + k].abs() {
                    piv = i;
                }
            }
            if piv != k {
                for j in 0..n {
                    lu.swap(k * n + j, piv * n + j);
                }
                perm.swap(k, piv);
            }
            let d = lu[k * n + k];
            if !(d.is_finite() && d != 0.0) {
                ok = false;
                break;
            }
            for i in k + 1..n {
                let l = lu[i * n + k] / d;
                lu[i * n + k] = l;
                for j in k + 1..n {
                    lu[i * n + j] -= l * lu[k * n + j];
                }
            }
        }
        SmallLu { n, lu, perm, ok }
    }

    /// Solve `M·x = b` in place (`b.len() ≥ n`); all NaN when `M` was singular.
    pub(crate) fn solve(&self, b: &mut [f64]) {
        let n = self.n;
        if !self.ok {
            b[..n].iter_mut().for_each(|v| *v = f64::NAN);
            return;
        }
        let mut y = [0.0; MAX_DOF];
        for i in 0..n {
            let row = &self.lu[i * n..i * n + i];
            let s: f64 = row.iter().zip(&y[..i]).map(|(l, y)| l * y).sum();
            y[i] = b[self.perm[i]] - s;
        }
        for i in (0..n).rev() {
            let row = &self.lu[i * n + i + 1..i * n + n];
            let s: f64 = row.iter().zip(&y[i + 1..n]).map(|(u, y)| u * y).sum();
            y[i] = (y[i] - s) / self.lu[i * n + i];
        }
        b[..n].copy_from_slice(&y[..n]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Residuals `‖M x − b‖` of random well-conditioned systems (diagonally dominant, so
    /// the condition number is below ~10) are at round-off, ~n·ε·‖M‖·‖x‖; a matrix that
    /// needs pivoting (zero leading entry) is solved too; a singular one gives NaN.
    #[test]
    fn solves_to_round_off_and_flags_singular_matrices() {
        let mut state = 0x9E37_79B9_7F4A_7C15_u64;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        for n in 1..=MAX_DOF {
            let mut m = vec![0.0; n * n];
            for i in 0..n {
                for j in 0..n {
                    m[i * n + j] = next() + if i == j { n as f64 } else { 0.0 };
                }
            }
            let b: Vec<f64> = (0..n).map(|_| next()).collect();
            let mut x = b.clone();
            SmallLu::factor(&m, n).solve(&mut x);
            for i in 0..n {
                let r: f64 = (0..n).map(|j| m[i * n + j] * x[j]).sum::<f64>() - b[i];
                assert!(r.abs() < 1e-13 * n as f64, "n {n} row {i}: {r}");
            }
        }
        // [[0, 1], [1, 0]] needs a row swap.
        let mut x = [2.0, 3.0];
        SmallLu::factor(&[0.0, 1.0, 1.0, 0.0], 2).solve(&mut x);
        assert_eq!(x.map(f64::to_bits), [3.0_f64, 2.0].map(f64::to_bits));
        let mut x = [1.0, 1.0];
        SmallLu::factor(&[1.0, 2.0, 2.0, 4.0], 2).solve(&mut x);
        assert!(x.iter().all(|v| v.is_nan()));
    }
}
