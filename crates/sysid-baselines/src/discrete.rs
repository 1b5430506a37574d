//! Exact discretisation of `ẋ = A x + B u` over one sample period for the two kinds of
//! inputs between samples ([`InterSample`]), and its derivatives with respect to one entry
//! of `A` or `B`:
//!
//! - held (zero-order hold): `x⁺ = Ad x + Bd u_k`, from `exp([[A h, B h], [0, 0]])`;
//! - linear (first-order hold): `x⁺ = Ad x + Bd u_k + Γ₂ (u_{k+1} − u_k)` with
//!   `Γ₂ = (1/h)∫₀ʰ exp(A(h − τ)) τ dτ · B` (`sysid_core::ramp_gain`); its derivative comes
//!   from `exp([[A h, B h, 0], [0, 0, I], [0, 0, 0]])`, whose top block row is
//!   `[Ad, Bd, Γ₂]` (the input as a state that ramps by `Δ = u_{k+1} − u_k` over the
//!   period).
//!
//! A derivative is the Fréchet derivative of the block exponential `exp(M)` in the
//! direction `E` (the unit change of the entry, times `h`), read off the upper-right block
//! of `exp([[M, E], [0, M]])` (Van Loan, IEEE TAC 23(3), 1978; Najfeld & Havel, Adv. Appl.
//! Math. 16, 1995).

use nalgebra::{DMatrix, DVector};
use sysid_core::{InterSample, discretize_zoh, ramp_gain};

use crate::error::Result;
use crate::free_params::{FreeParameter, StateMatrix};

/// `(Ad, Bd)` of `(A, B)` over a step `h` (zero-order hold).
pub(crate) fn zoh(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    h: f64,
) -> Result<(DMatrix<f64>, DMatrix<f64>)> {
    let mut blocks = discretize_zoh(a, &[b], h)?;
    let bd = blocks.pop().unwrap_or_else(|| DMatrix::zeros(a.nrows(), 0));
    let ad = blocks.pop().unwrap_or_else(|| DMatrix::zeros(0, 0));
    Ok((ad, bd))
}

/// Derivatives `(∂Ad/∂θ, ∂Bd/∂θ)` of the zero-order hold with respect to one free entry.
pub(crate) fn zoh_derivative(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    h: f64,
    p: &FreeParameter,
) -> (DMatrix<f64>, DMatrix<f64>) {
    let (n, m) = (a.nrows(), b.ncols());
    let s = n + m;
    let mut big = DMatrix::zeros(2 * s, 2 * s);
    for block in [0, s] {
        big.view_mut((block, block), (n, n)).copy_from(&(a * h));
        big.view_mut((block, block + n), (n, m)).copy_from(&(b * h));
    }
    big[(p.row, s + column_of(p, n))] = h;
    let ex = big.exp();
    let d_ad = ex.view((0, s), (n, n)).into_owned();
    let d_bd = ex.view((0, s + n), (n, m)).into_owned();
    (d_ad, d_bd)
}

/// Column of the free entry in the augmented matrix's top block row `[A h, B h, …]`.
fn column_of(p: &FreeParameter, n: usize) -> usize {
    match p.matrix {
        StateMatrix::A => p.col,
        StateMatrix::B => n + p.col,
    }
}

/// The first-order-hold block matrix `[[A h, B h, 0], [0, 0, I], [0, 0, 0]]` placed at
/// `(offset, offset)` of `big`.
fn place_ramp_block(
    big: &mut DMatrix<f64>,
    offset: usize,
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    h: f64,
) {
    let (n, m) = (a.nrows(), b.ncols());
    big.view_mut((offset, offset), (n, n)).copy_from(&(a * h));
    big.view_mut((offset, offset + n), (n, m))
        .copy_from(&(b * h));
    for i in 0..m {
        big[(offset + n + i, offset + n + m + i)] = 1.0;
    }
}

/// One sample period of the exact discretisation.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct SampleStep {
    /// `exp(A h)`.
    pub(crate) ad: DMatrix<f64>,
    /// `∫₀ʰ exp(A s) ds · B`.
    pub(crate) bd: DMatrix<f64>,
    /// `Γ₂` when the inputs are linear between samples; `None` when they are held.
    pub(crate) ramp: Option<DMatrix<f64>>,
}

impl SampleStep {
    /// The step of `ẋ = A x + B u` over `h` for inputs `hold` between samples.
    ///
    /// Errors: `h` not positive and finite, `A` not square, `B` of the wrong height.
    pub(crate) fn new(
        a: &DMatrix<f64>,
        b: &DMatrix<f64>,
        h: f64,
        hold: InterSample,
    ) -> Result<Self> {
        // The held part is the same matrices (and bits) for either hold.
        let (ad, bd) = zoh(a, b, h)?;
        // A band-limited input is read linear between samples here (an exact
        // discretisation needs the whole record).
        let ramp = match hold {
            InterSample::Zoh => None,
            InterSample::Foh | InterSample::Bl => Some(ramp_gain(a, b, h)?),
        };
        Ok(Self { ad, bd, ramp })
    }

    /// The state after sample `k` from the state `x` at sample `k`: `Ad x + Bd u_k`, plus
    /// `Γ₂ (u_{k+1} − u_k)` for linear inputs (`inputs` is `m × N`; at the last sample,
    /// where no `u_{k+1}` exists, the input is held).
    pub(crate) fn advance(
        &self,
        x: &DVector<f64>,
        inputs: &DMatrix<f64>,
        k: usize,
    ) -> DVector<f64> {
        let mut out = DVector::zeros(x.len());
        self.advance_into(x, inputs, k, &mut out);
        out
    }

    /// [`SampleStep::advance`] into `out` (length `n`, not aliasing `x`), without
    /// allocating: the free-run and sensitivity loops call it once per sample.
    pub(crate) fn advance_into(
        &self,
        x: &DVector<f64>,
        inputs: &DMatrix<f64>,
        k: usize,
        out: &mut DVector<f64>,
    ) {
        out.gemv(1.0, &self.ad, x, 0.0);
        out.gemv(1.0, &self.bd, &inputs.column(k), 1.0);
        if let Some(g2) = &self.ramp
            && k + 1 < inputs.ncols()
        {
            out.gemv(1.0, g2, &inputs.column(k + 1), 1.0);
            out.gemv(-1.0, g2, &inputs.column(k), 1.0);
        }
    }
}

/// Derivatives of a [`SampleStep`] with respect to one free entry of `A` or `B`.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct StepDerivative {
    /// `∂Ad/∂θ`.
    pub(crate) d_ad: DMatrix<f64>,
    /// `∂Bd/∂θ`.
    pub(crate) d_bd: DMatrix<f64>,
    /// `∂Γ₂/∂θ` for linear inputs.
    pub(crate) d_ramp: Option<DMatrix<f64>>,
}

impl StepDerivative {
    /// The derivatives of the step over `h` for inputs `hold` with respect to `p`. Held
    /// inputs: the two-block Fréchet derivative ([`zoh_derivative`]). Linear inputs: one
    /// exponential of the doubled three-block matrix gives all three.
    pub(crate) fn new(
        a: &DMatrix<f64>,
        b: &DMatrix<f64>,
        h: f64,
        hold: InterSample,
        p: &FreeParameter,
    ) -> Self {
        match hold {
            InterSample::Zoh => {
                let (d_ad, d_bd) = zoh_derivative(a, b, h, p);
                Self {
                    d_ad,
                    d_bd,
                    d_ramp: None,
                }
            }
            InterSample::Foh | InterSample::Bl => {
                let (n, m) = (a.nrows(), b.ncols());
                let s = n + 2 * m;
                let mut big = DMatrix::zeros(2 * s, 2 * s);
                place_ramp_block(&mut big, 0, a, b, h);
                place_ramp_block(&mut big, s, a, b, h);
                big[(p.row, s + column_of(p, n))] = h;
                let ex = big.exp();
                Self {
                    d_ad: ex.view((0, s), (n, n)).into_owned(),
                    d_bd: ex.view((0, s + n), (n, m)).into_owned(),
                    d_ramp: Some(ex.view((0, s + n + m), (n, m)).into_owned()),
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use sysid_core::integrate::DEFAULT_BLOW_UP;
    use sysid_core::{Integrator, LinearModel, ModelNames, simulate_with};

    fn system() -> (DMatrix<f64>, DMatrix<f64>) {
        let a = DMatrix::from_row_slice(3, 3, &[0.0, 1.0, 0.0, -2.0, -0.3, 0.5, 0.1, 0.0, -1.0]);
        let b = DMatrix::from_row_slice(3, 2, &[0.0, 1.0, 1.0, 0.0, 0.5, -0.2]);
        (a, b)
    }

    const NAMES: [&str; 5] = ["A[1,0]", "A[2,2]", "A[0,2]", "B[1,0]", "B[2,1]"];

    /// `(A, B)` with the entry `p` moved by `delta`.
    fn shifted(
        a: &DMatrix<f64>,
        b: &DMatrix<f64>,
        p: &FreeParameter,
        delta: f64,
    ) -> (DMatrix<f64>, DMatrix<f64>) {
        let (mut a2, mut b2) = (a.clone(), b.clone());
        match p.matrix {
            StateMatrix::A => a2[(p.row, p.col)] += delta,
            StateMatrix::B => b2[(p.row, p.col)] += delta,
        }
        (a2, b2)
    }

    /// Fréchet derivatives against central differences of the blocks, for both holds;
    /// the step `1e-5` balances truncation (~h²·‖d³/dθ³‖ ≈ 1e-10) and round-off
    /// (~ε/h ≈ 1e-11). The linear-input derivative's `∂Ad`, `∂Bd` are the held ones.
    #[test]
    fn derivatives_match_central_differences() {
        let (a, b) = system();
        let h = 0.07;
        let eps = 1e-5;
        for name in NAMES {
            let p = FreeParameter::parse(name).unwrap();
            let held = StepDerivative::new(&a, &b, h, InterSample::Zoh, &p);
            let ramped = StepDerivative::new(&a, &b, h, InterSample::Foh, &p);
            let step = |delta: f64| {
                let (a2, b2) = shifted(&a, &b, &p, delta);
                SampleStep::new(&a2, &b2, h, InterSample::Foh).unwrap()
            };
            let (plus, minus) = (step(eps), step(-eps));
            let fd = |x: &DMatrix<f64>, y: &DMatrix<f64>| (x - y) / (2.0 * eps);
            let fd_ad = fd(&plus.ad, &minus.ad);
            let fd_bd = fd(&plus.bd, &minus.bd);
            let fd_g2 = fd(plus.ramp.as_ref().unwrap(), minus.ramp.as_ref().unwrap());
            for der in [&held, &ramped] {
                assert!((&fd_ad - &der.d_ad).amax() < 1e-9, "{name}");
                assert!((&fd_bd - &der.d_bd).amax() < 1e-9, "{name}");
            }
            assert!(held.d_ramp.is_none());
            assert!((fd_g2 - ramped.d_ramp.unwrap()).amax() < 1e-9, "{name}");
        }
    }

    /// Scalar `ẋ = a x + b u`: `Ad = e^{ah}`, `Bd = b(e^{ah} − 1)/a`,
    /// `Γ₂ = (1/h)∫₀ʰ e^{a(h−τ)} τ dτ · b = b(e^{ah} − 1 − ah)/(a²h)`, and its derivatives
    /// `∂Γ₂/∂a = b((ah − 2)e^{ah} + ah + 2)/(a³h)`, `∂Γ₂/∂b = Γ₂/b`,
    /// `∂Bd/∂a = b(ahe^{ah} − e^{ah} + 1)/a²`, `∂Ad/∂a = h e^{ah}`, `∂Ad/∂b = 0` — to
    /// 1e-12 relative (the closed forms lose a few digits to cancellation at ah = −0.15).
    #[test]
    fn scalar_closed_forms() {
        let (av, bv, h): (f64, f64, f64) = (-1.5, 0.8, 0.1);
        let (a, b) = (
            DMatrix::from_element(1, 1, av),
            DMatrix::from_element(1, 1, bv),
        );
        let e = (av * h).exp();
        let g2 = bv * (e - 1.0 - av * h) / (av * av * h);
        let close = |x: f64, y: f64| (x - y).abs() <= 1e-12 * y.abs().max(1e-300);
        let step = SampleStep::new(&a, &b, h, InterSample::Foh).unwrap();
        assert!(close(step.ad[(0, 0)], e));
        assert!(close(step.bd[(0, 0)], bv * (e - 1.0) / av));
        assert!(close(step.ramp.as_ref().unwrap()[(0, 0)], g2));
        let da = StepDerivative::new(
            &a,
            &b,
            h,
            InterSample::Foh,
            &FreeParameter::parse("A[0,0]").unwrap(),
        );
        let db = StepDerivative::new(
            &a,
            &b,
            h,
            InterSample::Foh,
            &FreeParameter::parse("B[0,0]").unwrap(),
        );
        let ah = av * h;
        assert!(close(da.d_ad[(0, 0)], h * e));
        assert!(close(da.d_bd[(0, 0)], bv * (ah * e - e + 1.0) / (av * av)));
        assert!(close(
            da.d_ramp.unwrap()[(0, 0)],
            bv * ((ah - 2.0) * e + ah + 2.0) / (av * av * av * h)
        ));
        assert!(db.d_ad[(0, 0)].abs() < 1e-300, "{}", db.d_ad[(0, 0)]);
        assert!(close(db.d_bd[(0, 0)], (e - 1.0) / av));
        assert!(close(db.d_ramp.unwrap()[(0, 0)], g2 / bv));
    }

    /// One step with linear inputs against RK4 with 400 sub-steps on the ramp
    /// (`sysid_core::simulate_with`, independent code): from `x = 0` and `u` going from 0
    /// to 1 the state after the step is `Γ₂`, from `u_k = 1` to `1` it is `Bd`, to round-off
    /// (RK4's error at h/400 ≈ 2e-4 is ~1e-18 per step).
    #[test]
    fn one_step_matches_a_fine_simulation_of_the_ramp() {
        let (a, b) = system();
        let h = 0.07;
        let model = LinearModel::with_names(
            a.clone(),
            b.clone(),
            DMatrix::identity(3, 3),
            DMatrix::zeros(3, 0),
            ModelNames::numbered(3, 2, 3, 0),
        )
        .unwrap();
        let step = SampleStep::new(&a, &b, h, InterSample::Foh).unwrap();
        for col in 0..2 {
            let mut ramp = DMatrix::zeros(2, 2);
            ramp[(col, 1)] = 1.0;
            let mut flat = DMatrix::zeros(2, 2);
            flat[(col, 0)] = 1.0;
            flat[(col, 1)] = 1.0;
            for (inputs, want) in [(ramp, step.ramp.as_ref().unwrap()), (flat, &step.bd)] {
                let xs = simulate_with(
                    &model,
                    &[0.0; 3],
                    0.0,
                    h,
                    &inputs,
                    InterSample::Foh,
                    &Integrator::Rk4 { substeps: 400 },
                    DEFAULT_BLOW_UP,
                )
                .unwrap();
                let exact = step.advance(&DVector::zeros(3), &inputs, 0);
                for i in 0..3 {
                    assert!((xs[(i, 1)] - want[(i, col)]).abs() < 1e-13, "{i} {col}");
                    assert!((exact[i] - xs[(i, 1)]).abs() < 1e-13);
                }
            }
        }
    }

    /// Held inputs: the same `Ad`, `Bd` bits as `discretize_zoh`; a bad step is a typed
    /// error for either hold.
    #[test]
    fn held_step_is_the_zoh_and_bad_steps_are_errors() {
        let (a, b) = system();
        let (ad, bd) = zoh(&a, &b, 0.07).unwrap();
        for hold in [InterSample::Zoh, InterSample::Foh] {
            let step = SampleStep::new(&a, &b, 0.07, hold).unwrap();
            assert_eq!(step.ad, ad);
            assert_eq!(step.bd, bd);
            assert_eq!(step.ramp.is_some(), hold == InterSample::Foh);
            for h in [0.0, -0.1, f64::NAN] {
                assert!(matches!(
                    SampleStep::new(&a, &b, h, hold),
                    Err(crate::error::BaselineError::Core(
                        sysid_core::CoreError::InvalidArgument { name: "h", .. }
                    ))
                ));
            }
        }
    }
}
