//! The assumed linear model `ẋ = A x + B u + E d`, `y = C x`, with named states, inputs,
//! outputs and corrections, shape checks, and exact zero-order-hold discretisation.

// Index loops over small state vectors read like the equations they implement.
#![allow(clippy::needless_range_loop)]

use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

use crate::dataset::check_unique;
use crate::dynamics::Dynamics;
use crate::error::{CoreError, Result, check_finite};

/// The assumed linear model of MME.
///
/// `A` is `n × n`, `B` is `n × m`, `C` is `p × n`, `E` is `n × q` (which state equations
/// receive the model correction `d`, `q` components).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LinearModel {
    a: DMatrix<f64>,
    b: DMatrix<f64>,
    c: DMatrix<f64>,
    e: DMatrix<f64>,
    states: Vec<String>,
    inputs: Vec<String>,
    outputs: Vec<String>,
    corrections: Vec<String>,
}

/// Names for a [`LinearModel`]'s states, inputs, outputs and corrections.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct ModelNames {
    /// State names (`n`).
    pub states: Vec<String>,
    /// Input names (`m`).
    pub inputs: Vec<String>,
    /// Output names (`p`), one per row of `C`.
    pub outputs: Vec<String>,
    /// Correction names (`q`), one per column of `E`.
    pub corrections: Vec<String>,
}

impl ModelNames {
    /// Default names `x1…`, `u1…`, `y1…`, `d1…`.
    pub fn numbered(n: usize, m: usize, p: usize, q: usize) -> Self {
        let f = |prefix: &str, k: usize| (1..=k).map(|i| format!("{prefix}{i}")).collect();
        Self {
            states: f("x", n),
            inputs: f("u", m),
            outputs: f("y", p),
            corrections: f("d", q),
        }
    }
}

impl LinearModel {
    /// Build a model with numbered names; checks shapes and finiteness.
    pub fn new(a: DMatrix<f64>, b: DMatrix<f64>, c: DMatrix<f64>, e: DMatrix<f64>) -> Result<Self> {
        let names = ModelNames::numbered(a.nrows(), b.ncols(), c.nrows(), e.ncols());
        Self::with_names(a, b, c, e, names)
    }

    /// Build a model with the given names; checks shapes, finiteness and name counts.
    pub fn with_names(
        a: DMatrix<f64>,
        b: DMatrix<f64>,
        c: DMatrix<f64>,
        e: DMatrix<f64>,
        names: ModelNames,
    ) -> Result<Self> {
        let n = a.nrows();
        if a.ncols() != n {
            return Err(CoreError::NotSquare {
                matrix: "A",
                rows: a.nrows(),
                cols: a.ncols(),
            });
        }
        let shape = |matrix, m: &DMatrix<f64>, er, ec| {
            if m.nrows() != er || m.ncols() != ec {
                Err(CoreError::Shape {
                    matrix,
                    rows: m.nrows(),
                    cols: m.ncols(),
                    expected_rows: er,
                    expected_cols: ec,
                })
            } else {
                Ok(())
            }
        };
        shape("B", &b, n, b.ncols())?;
        shape("C", &c, c.nrows(), n)?;
        shape("E", &e, n, e.ncols())?;
        for (name, m) in [("A", &a), ("B", &b), ("C", &c), ("E", &e)] {
            check_finite(name, m)?;
        }
        let count = |what, v: &Vec<String>, expected| {
            if v.len() != expected {
                Err(CoreError::Length {
                    what,
                    found: v.len(),
                    expected,
                })
            } else {
                Ok(())
            }
        };
        count("state names", &names.states, n)?;
        count("input names", &names.inputs, b.ncols())?;
        count("output names", &names.outputs, c.nrows())?;
        count("correction names", &names.corrections, e.ncols())?;
        check_unique("state", names.states.iter().map(String::as_str))?;
        check_unique("input", names.inputs.iter().map(String::as_str))?;
        check_unique("output", names.outputs.iter().map(String::as_str))?;
        check_unique("correction", names.corrections.iter().map(String::as_str))?;
        Ok(Self {
            a,
            b,
            c,
            e,
            states: names.states,
            inputs: names.inputs,
            outputs: names.outputs,
            corrections: names.corrections,
        })
    }

    /// State matrix `A`.
    pub fn a(&self) -> &DMatrix<f64> {
        &self.a
    }
    /// Input matrix `B`.
    pub fn b(&self) -> &DMatrix<f64> {
        &self.b
    }
    /// Output matrix `C`.
    pub fn c(&self) -> &DMatrix<f64> {
        &self.c
    }
    /// Correction matrix `E`.
    pub fn e(&self) -> &DMatrix<f64> {
        &self.e
    }
    /// State names.
    pub fn state_names(&self) -> &[String] {
        &self.states
    }
    /// Input names.
    pub fn input_names(&self) -> &[String] {
        &self.inputs
    }
    /// Output names.
    pub fn output_names(&self) -> &[String] {
        &self.outputs
    }
    /// Correction names.
    pub fn correction_names(&self) -> &[String] {
        &self.corrections
    }
    /// Number of states `n`.
    pub fn n_states(&self) -> usize {
        self.a.nrows()
    }
    /// Number of inputs `m`.
    pub fn n_inputs(&self) -> usize {
        self.b.ncols()
    }
    /// Number of outputs `p`.
    pub fn n_outputs(&self) -> usize {
        self.c.nrows()
    }
    /// Number of corrections `q`.
    pub fn n_corrections(&self) -> usize {
        self.e.ncols()
    }

    /// Index of a state by name.
    pub fn state_index(&self, name: &str) -> Result<usize> {
        self.states
            .iter()
            .position(|s| s == name)
            .ok_or_else(|| CoreError::UnknownName {
                kind: "state",
                name: name.into(),
            })
    }

    /// A copy with `A` and `B` replaced (same shapes required), e.g. after a regression
    /// update of the corrected rows.
    pub fn with_ab(&self, a: DMatrix<f64>, b: DMatrix<f64>) -> Result<Self> {
        let names = ModelNames {
            states: self.states.clone(),
            inputs: self.inputs.clone(),
            outputs: self.outputs.clone(),
            corrections: self.corrections.clone(),
        };
        if b.nrows() != self.n_states() || b.ncols() != self.n_inputs() {
            return Err(CoreError::Shape {
                matrix: "B",
                rows: b.nrows(),
                cols: b.ncols(),
                expected_rows: self.n_states(),
                expected_cols: self.n_inputs(),
            });
        }
        Self::with_names(a, b, self.c.clone(), self.e.clone(), names)
    }

    /// If `C` is a selection matrix (each row one unit entry), the selected state indices.
    pub fn measured_states(&self) -> Option<Vec<usize>> {
        selection_indices(&self.c)
    }

    /// If `E` is a selection matrix (each column one unit entry), the corrected state indices.
    pub fn corrected_states(&self) -> Option<Vec<usize>> {
        selection_indices(&self.e.transpose())
    }

    /// Exact zero-order-hold discretisation over a step `h`, with `u` and `d` held constant:
    /// `x⁺ = Ad x + Bd u + Ed d`, where
    /// `exp([[A, B, E], [0, 0, 0]]·h) = [[Ad, Bd, Ed], [0, I, 0], [0, 0, I]]`.
    pub fn discretize(&self, h: f64) -> Result<DiscreteLinear> {
        discretize_zoh(&self.a, &[&self.b, &self.e], h).map(|mut blocks| {
            let ed = blocks
                .pop()
                .unwrap_or_else(|| DMatrix::zeros(self.n_states(), 0));
            let bd = blocks
                .pop()
                .unwrap_or_else(|| DMatrix::zeros(self.n_states(), 0));
            let ad = blocks.pop().unwrap_or_else(|| DMatrix::zeros(0, 0));
            DiscreteLinear { h, ad, bd, ed }
        })
    }
}

fn selection_indices(m: &DMatrix<f64>) -> Option<Vec<usize>> {
    let mut out = Vec::with_capacity(m.nrows());
    for i in 0..m.nrows() {
        let row = m.row(i);
        let ones: Vec<usize> = (0..m.ncols()).filter(|&j| row[j] != 0.0).collect();
        if ones.len() != 1 || (row[ones[0]] - 1.0).abs() > 0.0 {
            return None;
        }
        out.push(ones[0]);
    }
    Some(out)
}

/// A linear model discretised exactly over a step `h` (inputs and corrections held).
#[derive(Debug, Clone, PartialEq)]
pub struct DiscreteLinear {
    /// Step, s.
    pub h: f64,
    /// `exp(A h)`.
    pub ad: DMatrix<f64>,
    /// `∫₀ʰ exp(A s) ds · B`.
    pub bd: DMatrix<f64>,
    /// `∫₀ʰ exp(A s) ds · E`.
    pub ed: DMatrix<f64>,
}

/// Exact ZOH discretisation of `ẋ = A x + Σ_i G_i w_i` over `h`: returns
/// `[exp(A h), Γ G_1, Γ G_2, …]` with `Γ = ∫₀ʰ exp(A s) ds`, from one matrix exponential
/// of the augmented matrix (Van Loan's block trick).
pub fn discretize_zoh(
    a: &DMatrix<f64>,
    inputs: &[&DMatrix<f64>],
    h: f64,
) -> Result<Vec<DMatrix<f64>>> {
    if !(h.is_finite() && h > 0.0) {
        return Err(CoreError::InvalidArgument {
            name: "h",
            value: h,
            reason: "step must be positive and finite",
        });
    }
    let n = a.nrows();
    if a.ncols() != n {
        return Err(CoreError::NotSquare {
            matrix: "A",
            rows: a.nrows(),
            cols: a.ncols(),
        });
    }
    let widths: Vec<usize> = inputs.iter().map(|g| g.ncols()).collect();
    for g in inputs {
        if g.nrows() != n {
            return Err(CoreError::Shape {
                matrix: "input block",
                rows: g.nrows(),
                cols: g.ncols(),
                expected_rows: n,
                expected_cols: g.ncols(),
            });
        }
    }
    let total = n + widths.iter().sum::<usize>();
    let mut big = DMatrix::zeros(total, total);
    big.view_mut((0, 0), (n, n)).copy_from(&(a * h));
    let mut col = n;
    for g in inputs {
        big.view_mut((0, col), (n, g.ncols())).copy_from(&(*g * h));
        col += g.ncols();
    }
    let ex = big.exp();
    check_finite("exp([A G]h)", &ex)?;
    let mut out = Vec::with_capacity(inputs.len() + 1);
    out.push(ex.view((0, 0), (n, n)).into_owned());
    let mut col = n;
    for w in widths {
        out.push(ex.view((0, col), (n, w)).into_owned());
        col += w;
    }
    Ok(out)
}

impl Dynamics for LinearModel {
    fn n_states(&self) -> usize {
        self.a.nrows()
    }
    fn n_inputs(&self) -> usize {
        self.b.ncols()
    }
    fn rhs(&self, _t: f64, x: &[f64], u: &[f64], dx: &mut [f64]) {
        let n = self.a.nrows();
        for i in 0..n {
            let mut s = 0.0;
            for j in 0..n {
                s += self.a[(i, j)] * x[j];
            }
            for (j, uj) in u.iter().enumerate() {
                s += self.b[(i, j)] * uj;
            }
            dx[i] = s;
        }
    }
    fn jacobians(
        &self,
        _t: f64,
        _x: &[f64],
        _u: &[f64],
        a: &mut DMatrix<f64>,
        b: &mut DMatrix<f64>,
    ) {
        a.copy_from(&self.a);
        b.copy_from(&self.b);
    }
}

/// The input gain of a linear ramp over one step: with `u(t + τ) = u₀ + (τ/h)·Δ` on
/// `[0, h]`, the exact step of `ẋ = A x + B u` is `x⁺ = Ad x + Bd u₀ + Γ₂ Δ` with
/// `Γ₂ = (1/h)∫₀ʰ exp(A(h−τ)) τ dτ · B` (`n × m`).
///
/// Computed exactly as the zero-order-hold input gain of the augmented system
/// `ż = [[A, B], [0, 0]] z + [0; I/h] v`, `z = [x; u]`: from `z = 0` with `v = Δ` held,
/// `u(τ) = τΔ/h` and `x(h) = Γ₂ Δ` (one block matrix exponential, Van Loan 1978).
///
/// Errors: `h` not positive and finite, `A` not square, `B` not `n × m`.
pub fn ramp_gain(a: &DMatrix<f64>, b: &DMatrix<f64>, h: f64) -> Result<DMatrix<f64>> {
    let (n, m) = (a.nrows(), b.ncols());
    if a.ncols() != n {
        return Err(CoreError::NotSquare {
            matrix: "A",
            rows: n,
            cols: a.ncols(),
        });
    }
    if b.nrows() != n {
        return Err(CoreError::Shape {
            matrix: "B",
            rows: b.nrows(),
            cols: m,
            expected_rows: n,
            expected_cols: m,
        });
    }
    let mut big = DMatrix::zeros(n + m, n + m);
    big.view_mut((0, 0), (n, n)).copy_from(a);
    big.view_mut((0, n), (n, m)).copy_from(b);
    let mut drive = DMatrix::zeros(n + m, m);
    for l in 0..m {
        drive[(n + l, l)] = 1.0 / h;
    }
    let blocks = discretize_zoh(&big, &[&drive], h)?;
    Ok(blocks[1].view((0, 0), (n, m)).into_owned())
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    /// Closed form for the damped oscillator `ẍ + 2ζω ẋ + ω² x = u` (ζ < 1):
    /// `exp(A h)` and `∫exp(A s)ds·B` written out by hand.
    #[test]
    fn zoh_matches_closed_form_for_underdamped_oscillator() {
        let (w, z, h) = (2.0_f64, 0.1_f64, 0.3_f64);
        let a = DMatrix::from_row_slice(2, 2, &[0.0, 1.0, -w * w, -2.0 * z * w]);
        let b = DMatrix::from_row_slice(2, 1, &[0.0, 1.0]);
        let c = DMatrix::from_row_slice(1, 2, &[1.0, 0.0]);
        let e = DMatrix::from_row_slice(2, 1, &[0.0, 1.0]);
        let m = LinearModel::new(a, b, c, e).unwrap();
        let d = m.discretize(h).unwrap();
        let s = z * w;
        let wd = w * (1.0 - z * z).sqrt();
        let (ex, co, si) = ((-s * h).exp(), (wd * h).cos(), (wd * h).sin());
        let ad = DMatrix::from_row_slice(
            2,
            2,
            &[
                ex * (co + s / wd * si),
                ex * si / wd,
                -w * w * ex * si / wd,
                ex * (co - s / wd * si),
            ],
        );
        // Step response of x from rest with unit input: x(h) = (1 - Ad00)/w², v(h) = Ad01 (impulse response of x).
        let bd = DMatrix::from_row_slice(2, 1, &[(1.0 - ad[(0, 0)]) / (w * w), ad[(0, 1)]]);
        assert_relative_eq!(d.ad, ad, epsilon = 1e-13);
        assert_relative_eq!(d.bd, bd, epsilon = 1e-13);
        assert_relative_eq!(d.ed, bd, epsilon = 1e-13);
    }

    #[test]
    fn shape_errors_name_the_matrix() {
        let a = DMatrix::zeros(2, 3);
        let r = LinearModel::new(
            a,
            DMatrix::zeros(2, 1),
            DMatrix::zeros(1, 2),
            DMatrix::zeros(2, 1),
        );
        assert!(matches!(r, Err(CoreError::NotSquare { matrix: "A", .. })));
        let r = LinearModel::new(
            DMatrix::zeros(2, 2),
            DMatrix::zeros(3, 1),
            DMatrix::zeros(1, 2),
            DMatrix::zeros(2, 1),
        );
        assert!(matches!(r, Err(CoreError::Shape { matrix: "B", .. })));
        let r = LinearModel::new(
            DMatrix::zeros(2, 2),
            DMatrix::zeros(2, 1),
            DMatrix::zeros(1, 3),
            DMatrix::zeros(2, 1),
        );
        assert!(matches!(r, Err(CoreError::Shape { matrix: "C", .. })));
        let r = LinearModel::new(
            DMatrix::zeros(2, 2),
            DMatrix::zeros(2, 1),
            DMatrix::zeros(1, 2),
            DMatrix::zeros(1, 1),
        );
        assert!(matches!(r, Err(CoreError::Shape { matrix: "E", .. })));
    }

    #[test]
    fn selections_are_recognised() {
        let m = LinearModel::new(
            DMatrix::zeros(3, 3),
            DMatrix::zeros(3, 1),
            DMatrix::from_row_slice(1, 3, &[0.0, 0.0, 1.0]),
            DMatrix::from_row_slice(3, 2, &[0.0, 0.0, 1.0, 0.0, 0.0, 1.0]),
        )
        .unwrap();
        assert_eq!(m.measured_states(), Some(vec![2]));
        assert_eq!(m.corrected_states(), Some(vec![1, 2]));
    }

    /// `Γ₂` against two independent truths: the closed form for a scalar
    /// (`b(e^{λh} − 1 − λh)/(λ²h)`; `bh/2` for `λ = 0`), and for a damped oscillator with
    /// two inputs the state after one step of the RK4 first-order-hold
    /// simulation from `x = 0` with input ramping from 0 to a unit vector (400 sub-steps:
    /// local error ~ (|λ|h/400)⁵ per sub-step, ≈ 1e-15 here).
    #[test]
    fn ramp_gain_matches_closed_form_and_a_fine_ramp_simulation() {
        for (lambda, b, h) in [(-3.0, 2.0, 0.4), (1.5, -0.7, 0.3), (0.0, 1.3, 0.25)] {
            let g = ramp_gain(
                &DMatrix::from_element(1, 1, lambda),
                &DMatrix::from_element(1, 1, b),
                h,
            )
            .unwrap();
            let lh: f64 = lambda * h;
            let exact = if lambda == 0.0 {
                b * h / 2.0
            } else {
                b * (lh.exp() - 1.0 - lh) / (lambda * lambda * h)
            };
            assert!(
                (g[(0, 0)] - exact).abs() < 1e-14,
                "{} vs {exact}",
                g[(0, 0)]
            );
        }
        let model = LinearModel::new(
            DMatrix::from_row_slice(2, 2, &[0.0, 1.0, -25.0, -1.5]),
            DMatrix::from_row_slice(2, 2, &[0.0, 0.5, 1.0, -2.0]),
            DMatrix::from_row_slice(1, 2, &[1.0, 0.0]),
            DMatrix::from_row_slice(2, 1, &[0.0, 1.0]),
        )
        .unwrap();
        let h = 0.3;
        let g = ramp_gain(model.a(), model.b(), h).unwrap();
        for l in 0..2 {
            let mut u = DMatrix::zeros(2, 2);
            u[(l, 1)] = 1.0;
            let xs = crate::integrate::simulate_with(
                &model,
                &[0.0, 0.0],
                0.0,
                h,
                &u,
                crate::dataset::InterSample::Foh,
                &crate::integrate::Integrator::Rk4 { substeps: 400 },
                1e9,
            )
            .unwrap();
            for r in 0..2 {
                assert!(
                    (g[(r, l)] - xs[(r, 1)]).abs() < 1e-12,
                    "Γ₂[{r},{l}] {} vs {}",
                    g[(r, l)],
                    xs[(r, 1)]
                );
            }
        }
        // Not the trivial `Bd/2` (the ramp's mean times Bd): the state moves within h.
        let bd = model.discretize(h).unwrap().bd;
        assert!((&g - &bd * 0.5).amax() > 1e-2 * bd.amax());
    }
}
