//! Levenberg–Marquardt against known answers: a teacher network of the same shape, the
//! sine function, and linear (ridge) regression with the closed-form minimiser.

use nalgebra::{DMatrix, DVector};
use nn::{
    Acceleration, Architecture, Damping, ErrorSpace, LmConfig, Mlp, Scaler, StopReason,
    TrainReport, ValidationSplit, train_lm,
};

use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};

use crate::common::{grid, mse, uniform_inputs};

fn no_validation(max_epochs: usize) -> LmConfig {
    LmConfig {
        validation: ValidationSplit::None,
        max_epochs,
        ..LmConfig::default()
    }
}

#[test]
fn teacher_student_error_goes_to_zero() {
    // Targets come from a 2-5-1 teacher, so a 2-5-1 student can fit them exactly: the
    // global minimum of the MSE is 0. LM converges locally, so (as in the thesis's
    // practice) several initialisations are tried and the best must reach ~0. The
    // default schedule, and the two-phase one that starts as it does.
    // And the two-phase one with geodesic acceleration (`trainlm` with it falls short
    // here: best of four 2.9e-10 of the variance; exact fits from 50 starts in the
    // `teacher_starts` example: 41 of 300 against `trainlm`'s 50 and 48 for this one).
    for (damping, acceleration) in [
        (Damping::Trainlm, Acceleration::None),
        (Damping::TrainlmThenGainRatio, Acceleration::None),
        (Damping::TrainlmThenGainRatio, Acceleration::Geodesic),
    ] {
        teacher_student_with(damping, acceleration);
    }
}

fn teacher_student_with(damping: Damping, acceleration: Acceleration) {
    let (_, x, t, var_t) = teacher_data(2, 5, 300);
    let config = LmConfig {
        damping,
        acceleration,
        ..no_validation(400)
    };
    let best = (0..4)
        .map(|seed| {
            let mut student = Mlp::for_data(&x, &t, &[5], 100 + seed).unwrap();
            let report = train_lm(&mut student, &x, &t, &config, None).unwrap();
            // The report's MSE is the one of the returned weights.
            let direct = mse(&student.predict(&x).unwrap(), &t);
            assert!((report.train_mse - direct).abs() <= 1e-12 * var_t + 1e-12 * direct);
            direct
        })
        .fold(f64::INFINITY, f64::min);
    // "Near zero": below 1e-10 of the target variance (a 1e-5 relative RMS error). An
    // exact fit is limited only by round-off and the gradient stop, far below this.
    assert!(
        best < 1e-10 * var_t,
        "{damping:?} {acceleration:?}: best student MSE {best:e}, target variance {var_t:e}"
    );
}

fn variance(t: &DMatrix<f64>) -> f64 {
    let mean = t.mean();
    t.map(|v| (v - mean).powi(2)).mean()
}

/// Train a copy of `net` from the weights `start` with `damping` (300 epochs, no
/// validation); the report and the training MSE reached.
fn train_from(
    net: &Mlp,
    start: &[f64],
    damping: Damping,
    x: &DMatrix<f64>,
    t: &DMatrix<f64>,
) -> (TrainReport, f64) {
    train_accelerated_from(net, start, damping, Acceleration::None, x, t)
}

/// [`train_from`] with a step correction.
fn train_accelerated_from(
    net: &Mlp,
    start: &[f64],
    damping: Damping,
    acceleration: Acceleration,
    x: &DMatrix<f64>,
    t: &DMatrix<f64>,
) -> (TrainReport, f64) {
    let mut student = net.clone();
    student.set_weights(start).unwrap();
    let config = LmConfig {
        damping,
        acceleration,
        ..no_validation(300)
    };
    let report = train_lm(&mut student, x, t, &config, None).unwrap();
    let direct = mse(&student.predict(x).unwrap(), t);
    (report, direct)
}

/// A single-output teacher network (`inputs`-`hidden`-1, seed 11), `samples` inputs
/// uniform on ±1.5 (seed 1), its outputs as targets, and their variance.
fn teacher_data(
    inputs: usize,
    hidden: usize,
    samples: usize,
) -> (Mlp, DMatrix<f64>, DMatrix<f64>, f64) {
    let teacher = Mlp::new(&Architecture::single(inputs, hidden, 1), 11).unwrap();
    let x = uniform_inputs(inputs, samples, -1.5, 1.5, 1);
    let t = teacher.predict(&x).unwrap();
    let var_t = variance(&t);
    (teacher, x, t, var_t)
}

#[test]
fn every_damping_schedule_reaches_the_teacher_from_nearby() {
    // Local convergence of each μ schedule to an exact zero-residual minimum: the student
    // starts at the 2-5-1 teacher's weights moved by up to ±0.1 (MSE ≈ 2 % of the target
    // variance) and must reach ~0 (below 1e-10 of the variance, as above). From random
    // starts the gain-ratio schedules settle in other minima of this problem.
    let (teacher, x, t, var_t) = teacher_data(2, 5, 300);
    let start: Vec<f64> = teacher
        .weights()
        .iter()
        .enumerate()
        .map(|(i, w)| {
            let sign = if i % 2 == 0 { 1.0 } else { -1.0 };
            w + 0.1 * sign * (1.0 + (i % 3) as f64) / 3.0
        })
        .collect();
    for damping in Damping::ALL {
        let mut student = teacher.clone();
        student.set_weights(&start).unwrap();
        assert!(mse(&student.predict(&x).unwrap(), &t) > 1e-2 * var_t);
        let (report, direct) = train_from(&teacher, &start, damping, &x, &t);
        assert!(
            direct < 1e-10 * var_t,
            "{damping:?}: MSE {direct:e}, target variance {var_t:e}, {:?}",
            report.termination
        );
        // Every accepted step lowered the objective.
        assert!(report.train_history.windows(2).all(|w| w[1] < w[0]));
    }
}

#[test]
fn geodesic_acceleration_reaches_the_teacher_from_nearby() {
    // The same local convergence with geodesic acceleration (for the two-phase schedule it
    // starts after the trainlm phase, here never reached: 6 epochs). The accelerated path
    // must differ from the plain one (the correction is applied), every accepted step must lower the objective, and the
    // fit must be exact (below 1e-10 of the target variance). Not NielsenMarquardt: with
    // acceleration it stops in another minimum from 3 of 10 such starts (this one
    // included, MSE 9e-4 of the variance) where it reaches the exact fit from all 10
    // without; the other schedules reach it from 10 of 10 either way.
    let (teacher, x, t, var_t) = teacher_data(3, 4, 500);
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let start: Vec<f64> = teacher
        .weights()
        .iter()
        .map(|w| w + rng.random_range(-0.15..0.15))
        .collect();
    for damping in Damping::ALL
        .into_iter()
        .filter(|&d| d != Damping::NielsenMarquardt)
    {
        let (plain, _) = train_from(&teacher, &start, damping, &x, &t);
        let (report, direct) =
            train_accelerated_from(&teacher, &start, damping, Acceleration::Geodesic, &x, &t);
        assert!(
            direct < 1e-10 * var_t,
            "{damping:?}: MSE {direct:e}, target variance {var_t:e}, {:?}",
            report.termination
        );
        assert!(report.train_history.windows(2).all(|w| w[1] < w[0]));
        if damping == Damping::TrainlmThenGainRatio && report.epochs <= 10 {
            // Done within the trainlm phase, which takes plain steps.
            assert_eq!(plain.train_history, report.train_history);
        } else {
            assert_ne!(plain.train_history, report.train_history, "{damping:?}");
        }
    }
}

#[test]
fn new_schedules_reach_the_teacher_from_seeded_nearby_starts() {
    // Local convergence from several starts: a 3-4-1 teacher's weights moved by
    // independent uniform ±0.15 perturbations (five seeds) must all reach the exact fit
    // (MSE below 1e-10 of the target variance, as above) with the gain-ratio,
    // delayed-gratification and two-phase schedules, and with trainlm for reference.
    let (teacher, x, t, var_t) = teacher_data(3, 4, 500);
    for seed in 0..5 {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let start: Vec<f64> = teacher
            .weights()
            .iter()
            .map(|w| w + rng.random_range(-0.15..0.15))
            .collect();
        for damping in [
            Damping::Trainlm,
            Damping::GainRatio,
            Damping::DelayedGratification,
            Damping::TrainlmThenGainRatio,
        ] {
            let (report, direct) = train_from(&teacher, &start, damping, &x, &t);
            assert!(
                direct < 1e-10 * var_t,
                "seed {seed}, {damping:?}: MSE {direct:e}, variance {var_t:e}, {:?}",
                report.termination
            );
        }
    }
}

#[test]
fn new_schedules_reach_the_teacher_from_random_starts() {
    // From Nguyen–Widrow starts (seeds 100…107) the best of eight students must fit a
    // 3-4-1 teacher exactly (below 1e-10 of the target variance). The gain-ratio
    // schedules reach this exact minimum less often than trainlm (measured on 50 starts,
    // `teacher_starts` example: trainlm 21, GainRatio 10, DelayedGratification 15,
    // TrainlmThenGainRatio 20; the others stop near 1e-3 of the variance), hence the best
    // of eight rather than of four as for trainlm above.
    let (_, x, t, var_t) = teacher_data(3, 4, 500);
    for damping in [
        Damping::GainRatio,
        Damping::DelayedGratification,
        Damping::TrainlmThenGainRatio,
    ] {
        let best = (100..108)
            .map(|seed| {
                let mut student = Mlp::for_data(&x, &t, &[4], seed).unwrap();
                let config = LmConfig {
                    damping,
                    ..no_validation(400)
                };
                train_lm(&mut student, &x, &t, &config, None).unwrap();
                mse(&student.predict(&x).unwrap(), &t)
            })
            .fold(f64::INFINITY, f64::min);
        assert!(
            best < 1e-10 * var_t,
            "{damping:?}: best student MSE {best:e}, target variance {var_t:e}"
        );
    }
}

#[test]
fn fits_sine_with_three_hidden_units() {
    // sin on [−π, π] with 3 tanh units: a smooth odd target that 3 units approximate to an
    // RMS error of about 1e-4 (measured 5.9e-9 MSE with these seeds). Stated bound: MSE < 1e-6
    // on a denser, independent grid.
    let pi = std::f64::consts::PI;
    let x = grid(80, -pi, pi);
    let t = x.map(f64::sin);
    let best = (0..3)
        .map(|seed| {
            let mut net = Mlp::for_data(&x, &t, &[3], seed).unwrap();
            train_lm(&mut net, &x, &t, &no_validation(500), None).unwrap();
            let xt = grid(1001, -pi, pi);
            mse(&net.predict(&xt).unwrap(), &xt.map(f64::sin))
        })
        .fold(f64::INFINITY, f64::min);
    assert!(best < 1e-6, "sine test MSE {best:e}");
}

#[test]
fn affine_network_with_decay_is_ridge_regression() {
    // With no hidden layer and identity scaling the network is y = a·x₁ + b·x₂ + c, and
    // the LM objective MSE + λ‖w‖²/3 is a ridge problem with the closed-form minimiser
    // (XᵀX/N + (λ/3)I) w = Xᵀt/N (X has a column of ones for c).
    let x = uniform_inputs(2, 50, -2.0, 2.0, 5);
    let t = DMatrix::from_fn(1, 50, |_, k| {
        1.5 * x[(0, k)] - 0.7 * x[(1, k)] + 0.3 + 0.1 * (k as f64).sin()
    });
    // Every damping schedule (the gain-ratio ones use the decay term in their predicted
    // decrease).
    for (lambda, damping) in [0.0, 0.5]
        .into_iter()
        .flat_map(|l| Damping::ALL.map(|d| (l, d)))
    {
        let arch = Architecture {
            inputs: 2,
            hidden: vec![],
            outputs: 1,
        };
        let mut net = Mlp::new(&arch, 1).unwrap();
        let config = LmConfig {
            weight_decay: lambda,
            min_gradient: 1e-13,
            damping,
            ..no_validation(200)
        };
        let report = train_lm(&mut net, &x, &t, &config, None).unwrap();
        let design = DMatrix::from_fn(50, 3, |k, j| if j < 2 { x[(j, k)] } else { 1.0 });
        let n = 50.0;
        let lhs = design.transpose() * &design / n + DMatrix::identity(3, 3) * (lambda / 3.0);
        let rhs = design.transpose() * t.transpose() / n;
        let w = lhs.lu().solve(&rhs).unwrap();
        let got = DVector::from_column_slice(net.weights());
        // Quadratic objective: LM converges to round-off of the O(1) solution (the
        // closed form itself carries ~1e-15 relative error from the LU solve).
        assert!(
            (got - w.column(0)).amax() < 1e-9,
            "λ = {lambda}, {damping:?}: {report:?}"
        );
    }
}

#[test]
fn normalised_error_space_scales_mse_by_half_range() {
    // For one output, a normalised MSE is the original MSE divided by the squared
    // half-range of the target scaler.
    let x = grid(41, -1.0, 1.0);
    let t = x.map(|v| 50.0 * v * v + 10.0);
    let mut net = Mlp::for_data(&x, &t, &[2], 3).unwrap();
    train_lm(&mut net, &x, &t, &no_validation(5), None).unwrap();
    let h = Scaler::fit(&t).unwrap().half_range()[0];
    assert!((h - 25.0).abs() < 1e-12);
    let orig = net.mse(&x, &t, ErrorSpace::Original).unwrap();
    let norm = net.mse(&x, &t, ErrorSpace::Normalised).unwrap();
    assert!((orig / (h * h) - norm).abs() <= 1e-12 * norm);
}

#[test]
fn progress_callback_sees_every_epoch_and_goal_stops() {
    let x = grid(60, -2.0, 2.0);
    let t = x.map(f64::tanh);
    let mut net = Mlp::for_data(&x, &t, &[2], 0).unwrap();
    let mut seen = Vec::new();
    let config = LmConfig {
        goal_mse: 1e-8,
        ..no_validation(1000)
    };
    let report = train_lm(
        &mut net,
        &x,
        &t,
        &config,
        Some(&mut |info: nn::EpochInfo| seen.push(info)),
    )
    .unwrap();
    assert_eq!(report.termination, StopReason::GoalReached);
    assert_eq!(seen.len(), report.epochs);
    assert!(report.train_mse <= 1e-8);
    // Accepted LM steps never increase the (undecayed) objective.
    assert!(report.train_history.windows(2).all(|w| w[1] < w[0]));
    for (i, info) in seen.iter().enumerate() {
        assert_eq!(info.epoch, i + 1);
        assert_eq!(
            info.train_mse.to_bits(),
            report.train_history[i + 1].to_bits()
        );
    }
}
