//! Subspace identification of a discrete-time linear state-space model by PO-MOESP
//! (Verhaegen 1994; Katayama, *Subspace Methods for System Identification*, Springer 2005,
//! ch. 9–10; Verhaegen & Verdult, *Filtering and System Identification*, CUP 2007, §9.6):
//!
//! 1. block Hankel matrices of past and future inputs and outputs with `s` block rows,
//!    stacked as `[U_f; U_p; Y_p; Y_f]`;
//! 2. their LQ factorisation, computed here as the R factor of a QR factorisation of the
//!    transposed (tall) matrix, streamed in row chunks so memory stays `O(s²)`;
//! 3. the SVD of the block `L32` (future outputs against past inputs and outputs, the
//!    future inputs projected out), whose singular values show the order and whose left
//!    singular vectors span the extended observability matrix `Γ_s`;
//! 4. `C` from the first block row of `Γ_s`, `A` from its shift invariance (least squares);
//! 5. `B`, `D` and the initial state `x0` by linear least squares on the data, the outputs
//!    being linear in them once `A` and `C` are fixed.
//!
//! Everything is plain nalgebra (no LAPACK). Written here: no maintained pure-Rust crate
//! provides MOESP.

use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

use crate::error::{BaselineError, Result};

/// Rows gathered before each QR update of [`StreamingQr`].
const CHUNK: usize = 512;

/// Relative threshold on the diagonal of R below which a least-squares column counts as
/// dependent on the others.
const LSQ_RTOL: f64 = 1e-12;

/// The R factor of the QR factorisation of a tall matrix given row by row: each chunk of
/// rows is stacked under the current R and factorised again, so `QᵀQ = I` is never
/// formed and memory is one chunk plus R.
pub(crate) struct StreamingQr {
    cols: usize,
    r: DMatrix<f64>,
    pending: Vec<f64>,
}

impl StreamingQr {
    pub(crate) fn new(cols: usize) -> Self {
        Self {
            cols,
            r: DMatrix::zeros(0, cols),
            pending: Vec::with_capacity(CHUNK * cols),
        }
    }

    pub(crate) fn push(&mut self, row: &[f64]) {
        debug_assert_eq!(row.len(), self.cols);
        self.pending.extend_from_slice(row);
        if self.pending.len() >= CHUNK * self.cols {
            self.flush();
        }
    }

    fn flush(&mut self) {
        if self.pending.is_empty() {
            return;
        }
        let new_rows = self.pending.len() / self.cols;
        let top = self.r.nrows();
        let mut stack = DMatrix::zeros(top + new_rows, self.cols);
        stack.view_mut((0, 0), (top, self.cols)).copy_from(&self.r);
        for (i, row) in self.pending.chunks(self.cols).enumerate() {
            for (j, v) in row.iter().enumerate() {
                stack[(top + i, j)] = *v;
            }
        }
        self.pending.clear();
        self.r = stack.qr().r();
    }

    /// The `cols × cols` upper-triangular factor (zero rows added when fewer rows than
    /// columns were pushed).
    pub(crate) fn finish(mut self) -> DMatrix<f64> {
        self.flush();
        let mut r = DMatrix::zeros(self.cols, self.cols);
        let k = self.r.nrows().min(self.cols);
        r.view_mut((0, 0), (k, self.cols))
            .copy_from(&self.r.view((0, 0), (k, self.cols)));
        r
    }
}

/// Least-squares solution of `Φ θ ≈ y` from the streamed R factor of `[Φ | y]`
/// (`r` is `(p+1) × (p+1)`). Errors with [`BaselineError::Unidentifiable`] naming the
/// first column that depends on the earlier ones.
pub(crate) fn solve_augmented_r(
    r: &DMatrix<f64>,
    names: &dyn Fn(usize) -> String,
) -> Result<DVector<f64>> {
    let p = r.nrows() - 1;
    let dmax = (0..p).map(|i| r[(i, i)].abs()).fold(0.0, f64::max);
    for i in 0..p {
        let ratio = if dmax > 0.0 {
            r[(i, i)].abs() / dmax
        } else {
            0.0
        };
        // NaN counts as dependent too.
        if ratio.is_nan() || ratio <= LSQ_RTOL {
            return Err(BaselineError::Unidentifiable {
                name: names(i),
                ratio,
            });
        }
    }
    let r11 = r.view((0, 0), (p, p)).into_owned();
    let rhs = r.view((0, p), (p, 1)).into_owned();
    let x = r11
        .solve_upper_triangular(&rhs)
        .ok_or_else(|| BaselineError::Unidentifiable {
            name: names(0),
            ratio: 0.0,
        })?;
    Ok(x.column(0).into_owned())
}

/// A discrete-time linear state-space model `x⁺ = A x + B u`, `y = C x + D u`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DiscreteStateSpace {
    /// `n × n`.
    pub a: DMatrix<f64>,
    /// `n × m`.
    pub b: DMatrix<f64>,
    /// `p × n`.
    pub c: DMatrix<f64>,
    /// `p × m`.
    pub d: DMatrix<f64>,
}

impl DiscreteStateSpace {
    /// Number of states.
    pub fn order(&self) -> usize {
        self.a.nrows()
    }

    /// Outputs `p × N` of the free run from `x0` over `inputs` (`m × N`).
    pub fn simulate(&self, inputs: &DMatrix<f64>, x0: &DVector<f64>) -> DMatrix<f64> {
        let n = inputs.ncols();
        let mut x = x0.clone();
        let mut y = DMatrix::zeros(self.c.nrows(), n);
        for k in 0..n {
            let u = inputs.column(k);
            y.set_column(k, &(&self.c * &x + &self.d * u));
            x = &self.a * &x + &self.b * u;
        }
        y
    }

    /// Markov parameters `D, CB, CAB, …` (the impulse response), `count` of them, each
    /// `p × m`: two realisations with the same list (long enough) have the same transfer
    /// function.
    pub fn markov(&self, count: usize) -> Vec<DMatrix<f64>> {
        let mut out = Vec::with_capacity(count);
        if count == 0 {
            return out;
        }
        out.push(self.d.clone());
        let mut ak_b = self.b.clone();
        for _ in 1..count {
            out.push(&self.c * &ak_b);
            ak_b = &self.a * ak_b;
        }
        out
    }

    /// Eigenvalues of `A` as `(re, im)`.
    pub fn eigenvalues(&self) -> Vec<(f64, f64)> {
        self.a
            .complex_eigenvalues()
            .iter()
            .map(|z| (z.re, z.im))
            .collect()
    }
}

/// The data-dependent part of PO-MOESP: the singular values of `L32` and the basis of the
/// extended observability matrix, from which models of any order up to the horizon are
/// realised.
#[derive(Debug, Clone, PartialEq)]
pub struct Moesp {
    horizon: usize,
    n_inputs: usize,
    n_outputs: usize,
    singular_values: Vec<f64>,
    /// Left singular vectors of `L32` (`s·p × s·p`), columns by decreasing singular value.
    basis: DMatrix<f64>,
}

/// PO-MOESP on one record: `inputs` `m × N`, `outputs` `p × N`, `horizon` block rows `s`
/// of the past and of the future. Needs `N − 2s + 1 ≥ 2s(m + p)` Hankel columns and
/// finite data.
pub fn moesp(inputs: &DMatrix<f64>, outputs: &DMatrix<f64>, horizon: usize) -> Result<Moesp> {
    let (m, p, n) = (inputs.nrows(), outputs.nrows(), inputs.ncols());
    if outputs.ncols() != n {
        return Err(BaselineError::Dimension {
            what: "output samples vs input samples (MOESP)",
            found: outputs.ncols(),
            expected: n,
        });
    }
    if m == 0 || p == 0 {
        return Err(BaselineError::Dimension {
            what: "input or output channels (MOESP)",
            found: 0,
            expected: 1,
        });
    }
    if horizon < 2 {
        return Err(BaselineError::InvalidConfig {
            field: "horizon",
            value: horizon as f64,
            reason: "MOESP needs at least 2 block rows",
        });
    }
    if let Some(k) = (0..n).find(|&k| {
        inputs.column(k).iter().any(|v| !v.is_finite())
            || outputs.column(k).iter().any(|v| !v.is_finite())
    }) {
        return Err(BaselineError::NoInitialWindow {
            experiment: 0,
            window: k,
        });
    }
    let s = horizon;
    let rows = 2 * s * (m + p);
    let cols = (n + 1).saturating_sub(2 * s);
    if cols < rows {
        return Err(BaselineError::TooFewRows {
            what: "Hankel columns for MOESP (samples − 2·horizon + 1)",
            found: cols,
            needed: rows,
        });
    }
    // Row j of the transposed Hankel stack [U_f; U_p; Y_p; Y_f].
    let mut qr = StreamingQr::new(rows);
    let mut row = vec![0.0; rows];
    for j in 0..cols {
        let mut c = 0;
        for (signal, width, offset) in [
            (inputs, m, s),
            (inputs, m, 0),
            (outputs, p, 0),
            (outputs, p, s),
        ] {
            for i in 0..s {
                for ch in 0..width {
                    row[c] = signal[(ch, j + offset + i)];
                    c += 1;
                }
            }
        }
        qr.push(&row);
    }
    let l = qr.finish().transpose();
    let l32 = l
        .view((2 * s * m + s * p, s * m), (s * p, s * (m + p)))
        .into_owned();
    let svd = l32.svd(true, false);
    let basis = svd.u.ok_or(BaselineError::TooFewRows {
        what: "singular vectors of L32",
        found: 0,
        needed: 1,
    })?;
    Ok(Moesp {
        horizon: s,
        n_inputs: m,
        n_outputs: p,
        singular_values: svd.singular_values.iter().copied().collect(),
        basis,
    })
}

impl Moesp {
    /// Singular values of `L32`, decreasing: a gap after the `n`-th suggests order `n`.
    pub fn singular_values(&self) -> &[f64] {
        &self.singular_values
    }

    /// Block rows used.
    pub fn horizon(&self) -> usize {
        self.horizon
    }

    /// Largest order that can be realised: `(s − 1)·p` (the shift-invariance equations
    /// must determine `A`).
    pub fn max_order(&self) -> usize {
        (self.horizon - 1) * self.n_outputs
    }

    /// `A` and `C` of order `n`: `Γ = U_n Σ_n^{1/2}`, `C` its first block row, `A` the
    /// least-squares solution of `Γ_↑ A = Γ_↓` (Γ without its last / first block row).
    pub fn a_c(&self, n: usize) -> Result<(DMatrix<f64>, DMatrix<f64>)> {
        if n == 0 || n > self.max_order() {
            return Err(BaselineError::InvalidConfig {
                field: "order",
                value: n as f64,
                reason: "must be between 1 and (horizon − 1)·outputs",
            });
        }
        let (s, p) = (self.horizon, self.n_outputs);
        let mut gamma = self.basis.columns(0, n).into_owned();
        for (j, sv) in self.singular_values.iter().take(n).enumerate() {
            gamma.column_mut(j).scale_mut(sv.max(0.0).sqrt());
        }
        let c = gamma.rows(0, p).into_owned();
        let up = gamma.rows(0, (s - 1) * p).into_owned();
        let down = gamma.rows(p, (s - 1) * p).into_owned();
        let svd = up.svd(true, true);
        let smax = svd.singular_values.max();
        if smax.is_nan() || smax <= 0.0 || svd.singular_values.min() < 1e-12 * smax {
            return Err(BaselineError::Unidentifiable {
                name: format!("A of order {n} (Γ is rank deficient)"),
                ratio: svd.singular_values.min() / smax,
            });
        }
        let a = svd
            .solve(&down, 1e-12 * smax)
            .map_err(|_| BaselineError::Unidentifiable {
                name: format!("A of order {n}"),
                ratio: 0.0,
            })?;
        Ok((a, c))
    }

    /// The model of order `n` on the record: `A`, `C` from [`Moesp::a_c`], then `B`, `D`
    /// and the record's initial state by least squares (the outputs are linear in them).
    /// Returns the model and `x0`.
    pub fn realise(
        &self,
        n: usize,
        inputs: &DMatrix<f64>,
        outputs: &DMatrix<f64>,
    ) -> Result<(DiscreteStateSpace, DVector<f64>)> {
        let (m, p) = (self.n_inputs, self.n_outputs);
        if inputs.nrows() != m || outputs.nrows() != p || inputs.ncols() != outputs.ncols() {
            return Err(BaselineError::Dimension {
                what: "record channels vs the MOESP decomposition",
                found: inputs.nrows() + outputs.nrows(),
                expected: m + p,
            });
        }
        let (a, c) = self.a_c(n)?;
        let (b, d, x0) = fit_b_d_x0(&a, &c, inputs, outputs)?;
        Ok((DiscreteStateSpace { a, b, c, d }, x0))
    }
}

/// `B`, `D`, `x0` minimising `Σ_k ‖y_k − C A^k x0 − Σ_{j<k} C A^{k−1−j} B u_j − D u_k‖²`:
/// one regressor column per unknown, each the model's response to that unknown alone.
pub fn fit_b_d_x0(
    a: &DMatrix<f64>,
    c: &DMatrix<f64>,
    inputs: &DMatrix<f64>,
    outputs: &DMatrix<f64>,
) -> Result<(DMatrix<f64>, DMatrix<f64>, DVector<f64>)> {
    let (n, m, p, len) = (a.nrows(), inputs.nrows(), c.nrows(), inputs.ncols());
    let unknowns = n * m + p * m + n;
    if len * p <= unknowns {
        return Err(BaselineError::TooFewRows {
            what: "samples for B, D and x0",
            found: len * p,
            needed: unknowns + 1,
        });
    }
    // Columns: B[i,l] (i fastest), D[j,l], x0[i]; rows: sample-major, outputs inside.
    let mut phi = DMatrix::zeros(len * p, unknowns);
    for l in 0..m {
        // States driven by input l through each unit column e_i: n trajectories at once.
        let mut x = DMatrix::<f64>::zeros(n, n);
        for k in 0..len {
            let y = c * &x;
            for i in 0..n {
                for j in 0..p {
                    phi[(k * p + j, l * n + i)] = y[(j, i)];
                }
            }
            x = a * x;
            for i in 0..n {
                x[(i, i)] += inputs[(l, k)];
            }
        }
        for j in 0..p {
            for k in 0..len {
                phi[(k * p + j, n * m + l * p + j)] = inputs[(l, k)];
            }
        }
    }
    let mut free = DMatrix::<f64>::identity(n, n);
    for k in 0..len {
        let y = c * &free;
        for i in 0..n {
            for j in 0..p {
                phi[(k * p + j, n * m + p * m + i)] = y[(j, i)];
            }
        }
        free = a * free;
    }
    let mut qr = StreamingQr::new(unknowns + 1);
    let mut row = vec![0.0; unknowns + 1];
    for r in 0..len * p {
        for (j, v) in row.iter_mut().take(unknowns).enumerate() {
            *v = phi[(r, j)];
        }
        row[unknowns] = outputs[(r % p, r / p)];
        qr.push(&row);
    }
    let names = |i: usize| {
        if i < n * m {
            format!("B[{},{}]", i % n, i / n)
        } else if i < n * m + p * m {
            let k = i - n * m;
            format!("D[{},{}]", k % p, k / p)
        } else {
            format!("x0[{}]", i - n * m - p * m)
        }
    };
    let theta = solve_augmented_r(&qr.finish(), &names)?;
    let b = DMatrix::from_fn(n, m, |i, l| theta[l * n + i]);
    let d = DMatrix::from_fn(p, m, |j, l| theta[n * m + l * p + j]);
    let x0 = DVector::from_fn(n, |i, _| theta[n * m + p * m + i]);
    Ok((b, d, x0))
}
