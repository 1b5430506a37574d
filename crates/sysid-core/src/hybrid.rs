//! The completed plant model of MME/NN (thesis ch. 4): the assumed dynamics plus a
//! correction term, `ẋ = f(x, u) + E·g(x, u)`, simulated free-run from an initial state
//! with blow-up detection. `g` is any [`Correction`] (a trained network, a sum of named
//! effects); `f` is any [`Dynamics`] (the assumed linear model, or a `TermModel`). Inputs
//! between samples are held or interpolated as the experiment's [`InterSample`] says.

use nalgebra::DMatrix;

use crate::dataset::InterSample;
use crate::dynamics::{Correction, Dynamics, Horizon, Model, Prediction};
use crate::error::{CoreError, Result};
use crate::integrate::{Integrator, simulate, simulate_experiment, simulate_with};

/// `ẋ = f(x, u) + E·g(x, u)`, `y = C x`, with a free-run initial state.
#[derive(Debug, Clone)]
pub struct CorrectedModel<F, G> {
    base: F,
    correction: G,
    e: DMatrix<f64>,
    c: DMatrix<f64>,
    output_names: Vec<String>,
    /// Initial state used by [`Model::simulate`].
    pub x0: Vec<f64>,
    /// Integrator for free-run simulation.
    pub integrator: Integrator,
    /// States beyond this magnitude count as a diverged simulation.
    pub blow_up: f64,
}

impl<F: Dynamics, G: Correction> CorrectedModel<F, G> {
    /// Combine assumed dynamics `f` (`n` states, `m` inputs) with a correction `g`
    /// (`q` outputs, reading `n` states and `m` inputs) entering through `E` (`n × q`);
    /// outputs `y = C x` named `output_names`.
    ///
    /// Defaults: `x0 = 0`, RK4 with 4 sub-steps per sample, blow-up bound 1e12.
    pub fn new(
        base: F,
        correction: G,
        e: DMatrix<f64>,
        c: DMatrix<f64>,
        output_names: Vec<String>,
    ) -> Result<Self> {
        let n = base.n_states();
        let m = base.n_inputs();
        let q = correction.n_outputs();
        let shape = |matrix, r: usize, cc: usize, er, ec| {
            if r != er || cc != ec {
                Err(CoreError::Shape {
                    matrix,
                    rows: r,
                    cols: cc,
                    expected_rows: er,
                    expected_cols: ec,
                })
            } else {
                Ok(())
            }
        };
        shape("E", e.nrows(), e.ncols(), n, q)?;
        shape("C", c.nrows(), c.ncols(), output_names.len(), n)?;
        CoreError::check_len("states read by the correction", correction.n_states(), n)?;
        CoreError::check_len("inputs read by the correction", correction.n_inputs(), m)?;
        Ok(Self {
            base,
            correction,
            e,
            c,
            output_names,
            x0: vec![0.0; n],
            integrator: Integrator::Rk4 { substeps: 4 },
            blow_up: crate::integrate::DEFAULT_BLOW_UP,
        })
    }

    /// The assumed dynamics.
    pub fn base(&self) -> &F {
        &self.base
    }

    /// The correction term.
    pub fn correction(&self) -> &G {
        &self.correction
    }

    /// The correction term, mutable (e.g. a network whose weights are being trained; its
    /// state, input and output counts must stay those the model was built with).
    pub fn correction_mut(&mut self) -> &mut G {
        &mut self.correction
    }

    /// `E`, `n × q`: how the correction enters the state equations.
    pub fn e(&self) -> &DMatrix<f64> {
        &self.e
    }

    /// `C`, `p × n`: the outputs.
    pub fn c(&self) -> &DMatrix<f64> {
        &self.c
    }

    /// The same model with the assumed dynamics borrowed and the correction, `E`, `C`,
    /// names, initial state and settings copied: a working copy whose correction can be
    /// changed (one per thread, say) without cloning the base dynamics.
    pub fn with_borrowed_base(&self) -> CorrectedModel<&F, G>
    where
        G: Clone,
    {
        CorrectedModel {
            base: &self.base,
            correction: self.correction.clone(),
            e: self.e.clone(),
            c: self.c.clone(),
            output_names: self.output_names.clone(),
            x0: self.x0.clone(),
            integrator: self.integrator,
            blow_up: self.blow_up,
        }
    }

    /// Free-run states over an input sequence (`m × N`), from `x0`, `n × N`, inputs held
    /// between samples.
    pub fn simulate_states(
        &self,
        x0: &[f64],
        t0: f64,
        dt: f64,
        inputs: &DMatrix<f64>,
    ) -> Result<DMatrix<f64>> {
        simulate(self, x0, t0, dt, inputs, &self.integrator, self.blow_up)
    }

    /// [`CorrectedModel::simulate_states`] with the inputs between samples as `hold`
    /// says (interpolated linearly for [`InterSample::Foh`]; the same bits as
    /// `simulate_states` for [`InterSample::Zoh`]).
    pub fn simulate_states_with(
        &self,
        x0: &[f64],
        t0: f64,
        dt: f64,
        inputs: &DMatrix<f64>,
        hold: InterSample,
    ) -> Result<DMatrix<f64>> {
        simulate_with(
            self,
            x0,
            t0,
            dt,
            inputs,
            hold,
            &self.integrator,
            self.blow_up,
        )
    }

    /// Free-run states over samples `range` of `exp` from `x0` (the state at
    /// `range.start`), the inputs between samples as the record says; a band-limited
    /// record is read through its own grid ([`simulate_experiment`]).
    pub fn simulate_experiment_states(
        &self,
        x0: &[f64],
        exp: &crate::Experiment,
        range: std::ops::Range<usize>,
    ) -> Result<DMatrix<f64>> {
        simulate_experiment(self, x0, exp, range, &self.integrator, self.blow_up)
    }
}

impl<F: Dynamics, G: Correction> Dynamics for CorrectedModel<F, G> {
    fn n_states(&self) -> usize {
        self.base.n_states()
    }
    fn n_inputs(&self) -> usize {
        self.base.n_inputs()
    }
    fn rhs(&self, t: f64, x: &[f64], u: &[f64], dx: &mut [f64]) {
        self.base.rhs(t, x, u, dx);
        let q = self.correction.n_outputs();
        // Corrections are few (q ≤ n); a small stack buffer avoids allocation.
        let mut buf = [0.0; 16];
        let mut heap;
        let d: &mut [f64] = if q <= buf.len() {
            &mut buf[..q]
        } else {
            heap = vec![0.0; q];
            &mut heap
        };
        self.correction.eval(x, u, d);
        for (j, dj) in d.iter().enumerate() {
            for (i, dxi) in dx.iter_mut().enumerate() {
                *dxi += self.e[(i, j)] * dj;
            }
        }
    }
}

impl<F: Dynamics, G: Correction> Model for CorrectedModel<F, G> {
    type Error = CoreError;

    fn output_names(&self) -> Vec<String> {
        self.output_names.clone()
    }

    /// Free-run simulation from `self.x0` over the experiment's inputs, held or
    /// interpolated between samples as [`crate::Experiment::intersample`] says.
    fn simulate(&self, experiment: &crate::Experiment) -> Result<Prediction> {
        let xs = self.simulate_experiment_states(&self.x0, experiment, 0..experiment.len())?;
        Ok(Prediction {
            horizon: Horizon::FreeRun,
            outputs: &self.c * xs,
            initial_samples: 0,
        })
    }

    /// k-step prediction needs a state estimate at every sample, which only full-state
    /// measurement gives here: with `C = I`-like selections of every state, the state at
    /// sample `k − steps` is taken from the measurement and simulated `steps` ahead (inputs
    /// between samples as the experiment's [`InterSample`] says).
    fn predict(&self, experiment: &crate::Experiment, steps: usize) -> Result<Prediction> {
        let n = self.n_states();
        let idx = full_state_selection(&self.c, n).ok_or(CoreError::InvalidArgument {
            name: "steps",
            value: steps as f64,
            reason: "k-step prediction of a state-space model needs every state measured (C a permutation)",
        })?;
        let len = experiment.len();
        let mut out = DMatrix::from_element(self.c.nrows(), len, f64::NAN);
        let mut x = vec![0.0; n];
        let mut ws = crate::integrate::Workspace::new(n);
        for k in steps..len {
            let start = k - steps;
            let y = experiment.output(start);
            if y.iter().any(|v| v.is_nan()) {
                continue;
            }
            for (row, &state) in idx.iter().enumerate() {
                x[state] = y[row];
            }
            for j in start..k {
                crate::integrate::integrate_record_interval(
                    self,
                    experiment,
                    j,
                    &mut x,
                    &self.integrator,
                    &mut ws,
                )?;
            }
            let yk = &self.c * nalgebra::DVector::from_column_slice(&x);
            out.column_mut(k).copy_from(&yk);
        }
        Ok(Prediction {
            horizon: Horizon::Steps(steps),
            outputs: out,
            initial_samples: steps,
        })
    }
}

fn full_state_selection(c: &DMatrix<f64>, n: usize) -> Option<Vec<usize>> {
    if c.nrows() != n {
        return None;
    }
    let mut idx = Vec::with_capacity(n);
    for i in 0..n {
        let nz: Vec<usize> = (0..n).filter(|&j| c[(i, j)] != 0.0).collect();
        if nz.len() != 1 || (c[(i, nz[0])] - 1.0).abs() > 0.0 || idx.contains(&nz[0]) {
            return None;
        }
        idx.push(nz[0]);
    }
    Some(idx)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::LinearModel;

    /// Correction `d = −c·v − k·x³` (the cubic spring and damper missing from the assumed model).
    struct Cubic {
        c: f64,
        k: f64,
    }
    impl Correction for Cubic {
        fn n_states(&self) -> usize {
            2
        }
        fn n_inputs(&self) -> usize {
            1
        }
        fn n_outputs(&self) -> usize {
            1
        }
        fn eval(&self, x: &[f64], _u: &[f64], d: &mut [f64]) {
            d[0] = -self.c * x[1] - self.k * x[0].powi(3);
        }
    }

    /// Truth written directly: ẍ = −k x − c ẋ − k x³ + u.
    struct Truth;
    impl Dynamics for Truth {
        fn n_states(&self) -> usize {
            2
        }
        fn n_inputs(&self) -> usize {
            1
        }
        fn rhs(&self, _t: f64, x: &[f64], u: &[f64], dx: &mut [f64]) {
            dx[0] = x[1];
            dx[1] = -0.5 * x[0] - 0.1 * x[1] - 0.5 * x[0].powi(3) + u[0];
        }
    }

    fn assumed() -> LinearModel {
        LinearModel::new(
            DMatrix::from_row_slice(2, 2, &[0.0, 1.0, -0.5, 0.0]),
            DMatrix::from_row_slice(2, 1, &[0.0, 1.0]),
            DMatrix::from_row_slice(1, 2, &[1.0, 0.0]),
            DMatrix::from_row_slice(2, 1, &[0.0, 1.0]),
        )
        .unwrap()
    }

    #[test]
    fn exact_correction_reproduces_the_truth() {
        let lin = assumed();
        let mut hybrid = CorrectedModel::new(
            lin.clone(),
            Cubic { c: 0.1, k: 0.5 },
            lin.e().clone(),
            lin.c().clone(),
            vec!["x".into()],
        )
        .unwrap();
        hybrid.x0 = vec![1.5, 0.0];
        hybrid.integrator = Integrator::Rk4 { substeps: 8 };
        let u = DMatrix::from_fn(1, 500, |_, k| (0.01 * k as f64).sin());
        let exp = crate::Experiment::new(0.0, 0.01, u.clone(), DMatrix::zeros(1, 500)).unwrap();
        let pred = hybrid.simulate(&exp).unwrap();
        let truth = simulate(
            &Truth,
            &[1.5, 0.0],
            0.0,
            0.01,
            &u,
            &Integrator::Rk4 { substeps: 8 },
            1e12,
        )
        .unwrap();
        let err = (0..500)
            .map(|k| (pred.outputs[(0, k)] - truth[(0, k)]).abs())
            .fold(0.0, f64::max);
        assert!(err < 1e-12, "max error {err}");
        assert_eq!(pred.horizon, Horizon::FreeRun);
    }

    /// Correction `d = u`: the input enters only through the correction.
    struct InputOnly;
    impl Correction for InputOnly {
        fn n_states(&self) -> usize {
            1
        }
        fn n_inputs(&self) -> usize {
            1
        }
        fn n_outputs(&self) -> usize {
            1
        }
        fn eval(&self, _x: &[f64], u: &[f64], d: &mut [f64]) {
            d[0] = u[0];
        }
    }

    /// `ẋ = −x + E·d`, `d = u`, with the ramp `u = a + b·t` sampled every `dt`: the
    /// closed form is `x(t) = (x₀ − p(t₀))·e^{−(t−t₀)} + p(t)`, `p(t) = a + b·t − b`.
    /// Interpolated (first-order hold), the hybrid model must meet it to 1e-9 (RK4 with
    /// 20 sub-steps, local error ~h⁵/120 ≈ 3e-14 per step); held, it lags the ramp by about
    /// half a sample, a steady error near `b·dt/2`. The held path is the same bits whichever way
    /// it is asked for, and one-step prediction from exact states follows the hold too.
    #[test]
    fn first_order_hold_follows_a_ramp_input() {
        let (a, b, t0, dt, len, x0) = (0.3, 1.5, 0.2, 0.1, 81, 0.4);
        let p = |t: f64| a + b * t - b;
        let exact = |t: f64| (x0 - p(t0)) * (-(t - t0)).exp() + p(t);
        let lin = LinearModel::new(
            DMatrix::from_element(1, 1, -1.0),
            DMatrix::zeros(1, 1),
            DMatrix::from_element(1, 1, 1.0),
            DMatrix::from_element(1, 1, 1.0),
        )
        .unwrap();
        let mut hybrid = CorrectedModel::new(
            lin.clone(),
            InputOnly,
            lin.e().clone(),
            lin.c().clone(),
            vec!["x".into()],
        )
        .unwrap();
        hybrid.x0 = vec![x0];
        hybrid.integrator = Integrator::Rk4 { substeps: 20 };
        let u = DMatrix::from_fn(1, len, |_, k| a + b * (t0 + k as f64 * dt));
        let truth = DMatrix::from_fn(1, len, |_, k| exact(t0 + k as f64 * dt));
        let exp = crate::Experiment::new(t0, dt, u.clone(), truth.clone()).unwrap();
        let foh = exp.clone().with_intersample(InterSample::Foh);

        let sim = hybrid.simulate(&foh).unwrap().outputs;
        let states = hybrid
            .simulate_states_with(&[x0], t0, dt, &u, InterSample::Foh)
            .unwrap();
        let foh_err = (0..len)
            .map(|k| (sim[(0, k)] - truth[(0, k)]).abs())
            .fold(0.0, f64::max);
        assert!(foh_err < 1e-9, "foh max error {foh_err}");
        assert_eq!(sim, states);

        let held = hybrid.simulate(&exp).unwrap().outputs;
        // The held error obeys e_{k+1} = e^{−dt}·e_k + b·(dt − 1 + e^{−dt}) from e_0 = 0, so
        // after 80 samples it is e_∞·(1 − e^{−8}), e_∞ = b·(dt − 1 + e^{−dt})/(1 − e^{−dt})
        // ≈ b·dt/2 (0.0762 here; e_∞·e^{−8} ≈ 3e-5).
        let lag = truth[(0, len - 1)] - held[(0, len - 1)];
        let e_inf = b * (dt - 1.0 + (-dt).exp()) / (1.0 - (-dt).exp());
        let expected = e_inf * (1.0 - (-8.0_f64).exp());
        assert!((lag - expected).abs() < 1e-9, "zoh lag {lag} vs {expected}");
        assert!(lag > 1e5 * foh_err);
        let bits = |m: &DMatrix<f64>| m.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
        let zoh = hybrid
            .simulate_states_with(&[x0], t0, dt, &u, InterSample::Zoh)
            .unwrap();
        let old = hybrid.simulate_states(&[x0], t0, dt, &u).unwrap();
        assert_eq!(bits(&zoh), bits(&old));
        assert_eq!(bits(&held), bits(&old));
        // The held input through B instead of the correction: the same flow to rounding.
        let via_b = LinearModel::new(
            DMatrix::from_element(1, 1, -1.0),
            DMatrix::from_element(1, 1, 1.0),
            DMatrix::from_element(1, 1, 1.0),
            DMatrix::from_element(1, 1, 1.0),
        )
        .unwrap();
        let plain_b = simulate(&via_b, &[x0], t0, dt, &u, &hybrid.integrator, 1e12).unwrap();
        assert!((&old - plain_b).abs().max() < 1e-13);

        let one_step = hybrid.predict(&foh, 1).unwrap().outputs;
        let held_step = hybrid.predict(&exp, 1).unwrap().outputs;
        for k in 1..len {
            assert!(
                (one_step[(0, k)] - truth[(0, k)]).abs() < 1e-11,
                "sample {k}"
            );
            // One held interval from the exact state misses by b·(dt − 1 + e^{−dt}) ≈ b·dt²/2.
            let miss = truth[(0, k)] - held_step[(0, k)];
            let expected = b * (dt - 1.0 + (-dt).exp());
            assert!(
                (miss - expected).abs() < 1e-9,
                "sample {k}: {miss} vs {expected}"
            );
        }
    }

    #[test]
    fn wrong_shapes_and_divergence_are_errors() {
        let lin = assumed();
        let bad = CorrectedModel::new(
            lin.clone(),
            Cubic { c: 0.1, k: 0.5 },
            DMatrix::zeros(3, 1),
            lin.c().clone(),
            vec!["x".into()],
        );
        assert!(matches!(bad, Err(CoreError::Shape { matrix: "E", .. })));
        // A destabilising correction (negative damping, anti-spring) must blow up with a typed error.
        let mut wild = CorrectedModel::new(
            lin.clone(),
            Cubic { c: -5.0, k: -5.0 },
            lin.e().clone(),
            lin.c().clone(),
            vec!["x".into()],
        )
        .unwrap();
        wild.x0 = vec![2.0, 0.0];
        let exp = crate::Experiment::new(0.0, 0.1, DMatrix::zeros(1, 200), DMatrix::zeros(1, 200))
            .unwrap();
        assert!(matches!(
            wild.simulate(&exp),
            Err(CoreError::Diverged { .. })
        ));
    }
}
