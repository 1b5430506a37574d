//! Real measured benchmarks (read in place from the shared data folder, never copied):
//! Cascaded Tanks, Silverbox and EMPS under the `nonlinear_benchmarks` 1.0.1 protocol
//! (official split, full rate, its initialisation windows). Each gets a linear
//! state-space baseline (MOESP + free-run output error), the calibrated physics-first grey
//! box, MME/NN on that grey box (guarded: physics alone, the network, or the refined
//! network, kept by held-out training free run), and a NARX network; Cascaded Tanks also
//! the linear output-error model of the physics structure and MME/NN on it. Free-run RMSE
//! on the official test records, beside the published numbers.
//!
//! `--quick` keeps every row and the protocol; it cuts effort only: linear SS orders up
//! to 4 (6), one grey-box candidate on Silverbox (5) and two on Cascaded Tanks (3), hybrid
//! sweeps of 1–3 hidden units × 2 initialisations with 5–10 refinement steps, and NARX on
//! two orders (4, 4), (8, 8) with 3 hidden units and one restart, selected on 8192 samples.

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::{Context, Result};
use mmenn::benchmarks::{Benchmark, load};
use mmenn::data_file::{read_table, write_csv};
use mmenn::fit::{FitOptions, InitialChoice, run_fit};
use mmenn::model_file::{ModelSpec, NoiseVariance, write_model};
use mmenn::plot::Figure;
use mmenn::sysid_baselines::{LinearSsConfig, OeConfig, X0Policy, fit_linear_ss, fit_oe};
use mmenn::sysid_core::{
    Channel, Dataset, Experiment, InterSample, LinearModel, Model, ModelNames,
};
use nalgebra::{DMatrix, DVector};

use super::{Ctx, FIT_SEED, Job, Mode, Outcome, grey, line, row};
use crate::table::{Column, Table, Tolerance};

mod hybrid;
mod narx;

/// Cascaded Tanks table id.
pub const TANKS: &str = "real_cascaded_tanks";
/// Silverbox table id.
pub const SILVERBOX: &str = "real_silverbox";
/// EMPS table id.
pub const EMPS: &str = "real_emps";

/// The jobs.
pub fn jobs() -> Vec<Job> {
    vec![
        Job {
            name: "real Cascaded Tanks".into(),
            group: "real",
            tables: vec![TANKS],
            cost: 20,
            run: Box::new(|ctx: &Ctx| run_benchmark(ctx, Benchmark::CascadedTanks, TANKS, tanks)),
        },
        Job {
            name: "real Silverbox".into(),
            group: "real",
            tables: vec![SILVERBOX],
            cost: 120,
            run: Box::new(|ctx: &Ctx| {
                run_benchmark(ctx, Benchmark::Silverbox, SILVERBOX, silverbox)
            }),
        },
        Job {
            name: "real EMPS".into(),
            group: "real",
            tables: vec![EMPS],
            // Full rate since the grey-box hybrid and NARX rows: 283 s against Silverbox's
            // 351 s in a full run on 2 loaded cores (60dc832).
            cost: 100,
            run: Box::new(|ctx: &Ctx| run_benchmark(ctx, Benchmark::Emps, EMPS, emps)),
        },
    ]
}

/// A single-output benchmark prepared for the OE → MME/NN → NARX pipeline.
struct Setup {
    title: &'static str,
    /// Estimation record: input `u`, output named after the measured state.
    est: Dataset,
    /// Test records (official names), same channels.
    tests: Vec<(String, Dataset)>,
    /// The physics model (OE starting point): output = the measured state.
    initial: LinearModel,
    /// Free entries of the OE fit.
    oe_free: &'static [&'static str],
    /// Noise variance for MME.
    noise: NoiseVariance,
    /// MME/NN sizing sweep (largest network, initialisations).
    sweep: (usize, usize),
    /// Test samples used to initialise the state (at this record's rate); scored after.
    window: usize,
    /// Factor to the published unit, and that unit.
    scale: f64,
    unit: &'static str,
    /// Units of states, input and corrections.
    units: &'static [(&'static str, &'static str)],
    /// Added to outputs in figures (operating point removed before modelling).
    offset: f64,
    /// Whether to add the "x0 of the estimation record" row (Cascaded Tanks).
    same_x0: bool,
    /// How the input behaves between samples (every record and the model file follow it).
    intersample: InterSample,
    /// Protocol notes and published numbers.
    notes: Vec<String>,
    /// How the OE, MME/NN and NARX rows depart from the official protocol (`None`: they
    /// follow it).
    shortened: Option<&'static str>,
}

/// The protocol every full-protocol number follows.
const OFFICIAL: &str = "nonlinear_benchmarks 1.0.1 protocol";

fn channel_dataset(
    u: DMatrix<f64>,
    y: DMatrix<f64>,
    t0: f64,
    dt: f64,
    output: &str,
) -> Result<Dataset> {
    Ok(Dataset::new(
        vec![Channel::new("u")],
        vec![Channel::new(output)],
        vec![Experiment::new(t0, dt, u, y)?],
    )?)
}

fn model(
    a: &[f64],
    b: &[f64],
    c: &[f64],
    e: &[f64],
    states: [&str; 2],
    output: &str,
    corrected: &str,
) -> Result<LinearModel> {
    Ok(LinearModel::with_names(
        DMatrix::from_row_slice(2, 2, a),
        DMatrix::from_row_slice(2, 1, b),
        DMatrix::from_row_slice(1, 2, c),
        DMatrix::from_row_slice(2, 1, e),
        ModelNames {
            states: states.iter().map(|s| s.to_string()).collect(),
            inputs: vec!["u".into()],
            outputs: vec![output.into()],
            corrections: vec![corrected.into()],
        },
    )?)
}

/// Cascaded Tanks: deviations from the estimation record's mean; the linearised two-tank
/// model `h1' = −a1 h1 + b u`, `h2' = a12 h1 − a2 h2 + d`, `y = h2` (upper level
/// unmeasured; `a12` held at its start value because it only sets the scale of the
/// unmeasured level; the correction on the measured lower tank only, since one on the
/// upper level would make its initial state unobservable). Starting values: time constants
/// of 50 and 67 s (distinct poles) and a static gain of 2 V/V (mean output / mean input of
/// the estimation record, 5.6 V / 2.8 V).
fn tanks(_mode: Mode, b: &mmenn::benchmarks::BenchmarkData) -> Result<Setup> {
    let e = &b.estimation.experiments()[0];
    let (u0, y0) = (e.inputs().mean(), e.outputs().mean());
    let shift = |d: &Dataset| -> Result<Dataset> {
        let x = &d.experiments()[0];
        channel_dataset(
            x.inputs().map(|v| v - u0),
            x.outputs().map(|v| v - y0),
            x.t0(),
            x.dt(),
            "h2",
        )
    };
    let est = shift(&b.estimation)?;
    let y = row(est.experiments()[0].outputs(), 0);
    // The benchmark states an output SNR close to 40 dB: noise variance = var(y) / 10⁴.
    // (The marginal-likelihood estimate, `noise_variance = "auto"`, made the upper level's
    // initial state unobservable on this record.)
    let noise = y.iter().map(|v| v * v).sum::<f64>() / (y.len() as f64 - 1.0) / 1e4;
    Ok(Setup {
        title: "Real data: Cascaded Tanks (Schoukens et al. 2016), free-run simulation RMSE on the official test record",
        tests: b
            .tests
            .iter()
            .map(|t| Ok((t.name.clone(), shift(&t.data)?)))
            .collect::<Result<_>>()?,
        est,
        initial: model(
            &[-0.02, 0.0, 0.02, -0.015],
            &[0.03, 0.0],
            &[0.0, 1.0],
            &[0.0, 1.0],
            ["h1", "h2"],
            "h2",
            "h2",
        )?,
        oe_free: &["A[0,0]", "A[1,1]", "B[0,0]"],
        noise: NoiseVariance::Given(vec![noise]),
        sweep: (10, 10),
        window: Benchmark::CascadedTanks.init_window(),
        scale: 1.0,
        unit: "V",
        units: &[("h1", "V"), ("h2", "V"), ("u", "V"), ("d_h2", "V/s")],
        offset: y0,
        same_x0: true,
        intersample: InterSample::Zoh,
        notes: vec![
            format!(
                "Deviations from the estimation record's mean (u0 = {u0:.4} V, y0 = {y0:.4} V); \
                 MME noise variance {noise:.3e} V² from the stated 40 dB SNR."
            ),
            "Published free-run test RMSE (shared/data/README.md; Champneys et al. 2024, \
             arXiv:2405.10779 and the papers it cites): grey-box model with a physical overflow \
             term 0.18–0.191 V (best); continuous-time SUBNET 0.306; physics-structured neural \
             ODE 0.33; NL state-space 0.34; GP-SSM 0.45; PNLSS 0.45; Volterra 0.54; linear \
             state-space 0.588; BLA 0.75. Protocols differ slightly (window of 0, 5 or 50 samples)."
                .into(),
        ],
        shortened: None,
    })
}

/// Least-squares ARX(2, 2) of `y` on `u` turned into the continuous oscillator
/// `y'' = −k y − c y' + b u` (poles `z = e^{sT}`, DC gain kept): the OE starting point for
/// Silverbox.
fn oscillator_guess(exp: &Experiment) -> Result<(f64, f64, f64)> {
    let (u, y) = (row(exp.inputs(), 0), row(exp.outputs(), 0));
    let n = y.len();
    let phi = DMatrix::from_fn(n - 2, 4, |r, j| {
        let k = r + 2;
        match j {
            0 => -y[k - 1],
            1 => -y[k - 2],
            2 => u[k - 1],
            _ => u[k - 2],
        }
    });
    let target = DVector::from_iterator(n - 2, y[2..].iter().copied());
    let theta = (phi.transpose() * &phi)
        .cholesky()
        .context("ARX regressors are collinear")?
        .solve(&(phi.transpose() * target));
    let (a1, a2, b1, b2) = (theta[0], theta[1], theta[2], theta[3]);
    let t = exp.dt();
    let disc = a1 * a1 - 4.0 * a2;
    anyhow::ensure!(
        disc < 0.0 && a2 > 0.0,
        "ARX poles are not a damped complex pair"
    );
    let r = a2.sqrt();
    let angle = (-a1 / (2.0 * r)).clamp(-1.0, 1.0).acos();
    let (sigma, omega) = (r.ln() / t, angle / t);
    let k = sigma * sigma + omega * omega;
    let c = -2.0 * sigma;
    let gain = (b1 + b2) / (1.0 + a1 + a2);
    Ok((k, c, gain * k))
}

/// Silverbox: the linear oscillator part of `m y'' + d y' + k(y) y = u` (Wigren &
/// Schoukens 2013) from an ARX guess, fitted by OE on a window of the estimation record;
/// MME corrects the velocity equation (the cubic spring is the missing effect).
fn silverbox(mode: Mode, b: &mmenn::benchmarks::BenchmarkData) -> Result<Setup> {
    // One multisine period plus its gap: longer windows made the NARX and network
    // training the slowest part of the full run (> 5 min for 16 384 samples).
    let n = 8192;
    let rename = |d: &Dataset, len: Option<usize>| -> Result<Dataset> {
        let x = &d.experiments()[0];
        let len = len.unwrap_or(x.len()).min(x.len());
        channel_dataset(
            x.inputs().columns(0, len).into_owned(),
            x.outputs().columns(0, len).into_owned(),
            x.t0(),
            x.dt(),
            "y",
        )
    };
    let est = rename(&b.estimation, Some(n))?;
    let (k, c, gain) = oscillator_guess(&est.experiments()[0])?;
    Ok(Setup {
        title: "Real data: Silverbox (Wigren & Schoukens 2013), free-run simulation RMSE on the official test records",
        tests: b
            .tests
            .iter()
            .map(|t| Ok((t.name.clone(), rename(&t.data, None)?)))
            .collect::<Result<_>>()?,
        est,
        initial: model(
            &[0.0, 1.0, -k, -c],
            &[0.0, gain],
            &[1.0, 0.0],
            &[0.0, 1.0],
            ["y", "v"],
            "y",
            "v",
        )?,
        oe_free: &["A[1,0]", "A[1,1]", "B[1,0]"],
        // σ = 0.1 mV: far below the linear model's error (≈ 15 mV), above the CSV
        // rounding (0.8 µV RMS, data README). The marginal-likelihood estimate
        // (`"auto"`) made the velocity's initial state unobservable on this record.
        noise: NoiseVariance::Given(vec![1e-8]),
        sweep: match mode {
            Mode::Quick => (5, 3),
            Mode::Full => (6, 4),
        },
        window: Benchmark::Silverbox.init_window(),
        scale: 1000.0,
        unit: "mV",
        units: &[("y", "V"), ("v", "V/s"), ("u", "V"), ("d_v", "V/s^2")],
        offset: 0.0,
        same_x0: false,
        // The excitation is band-limited (multisines and a filtered noise arrow from an
        // arbitrary waveform generator), sampled about 8 times per resonance period: held
        // between samples, it reaches the model half a sample late.
        intersample: InterSample::Foh,
        notes: vec![
            "Inputs linear between samples (`intersample = \"foh\"`: grey-box calibration, \
             MME, the network's training and every free run of the physics-first models)."
                .to_string(),
            "Published free-run RMSE (shared/data/README.md): arrow full 0.26 mV (PNLSS, older \
             protocol), GP-NARX 0.60, LSTM 2.68, linear state-space 14.4; multisine test / arrow \
             without extrapolation: GP-NARX 0.301 / 0.259, LSTM 1.50 / 0.96, linear 6.96 / 6.58."
                .into(),
        ],
        shortened: Some("estimation on the first 8192 of the 65 062 training samples"),
    })
}

/// EMPS decimated by 10 to 100 Hz: the input averaged over each 10 ms block (it is held
/// over the new sample interval), the position sampled at the block start.
fn decimate_emps(d: &Dataset) -> Result<Dataset> {
    const F: usize = 10;
    let x = &d.experiments()[0];
    let len = x.len() / F;
    let u = DMatrix::from_fn(1, len, |_, j| {
        (0..F).map(|i| x.inputs()[(0, j * F + i)]).sum::<f64>() / F as f64
    });
    let y = DMatrix::from_fn(1, len, |_, j| x.outputs()[(0, j * F)]);
    channel_dataset(u, y, x.t0(), x.dt() * F as f64, "q")
}

/// EMPS: `M q'' = gτ u − Fv q' (− Fc sign q' − offset)`, the bracket missing from the
/// linear model; started from the reference IDIM estimates (Janot et al. 2019: M = 95.1089
/// kg, Fv = 203.5034 N·s/m, gτ = 35.15 N/V, `u = vir` in volts), OE on `Fv/M` and `gτ/M`.
fn emps(_mode: Mode, b: &mmenn::benchmarks::BenchmarkData) -> Result<Setup> {
    let (m, fv, gtau) = (95.1089, 203.5034, 35.15);
    Ok(Setup {
        title: "Real data: EMPS (Janot et al. 2019), open-loop free-run simulation RMSE on the official test record",
        est: decimate_emps(&b.estimation)?,
        tests: b
            .tests
            .iter()
            .map(|t| Ok((t.name.clone(), decimate_emps(&t.data)?)))
            .collect::<Result<_>>()?,
        initial: model(
            &[0.0, 1.0, 0.0, -fv / m],
            &[0.0, gtau / m],
            &[1.0, 0.0],
            &[0.0, 1.0],
            ["q", "v"],
            "q",
            "v",
        )?,
        oe_free: &["A[1,1]", "B[1,0]"],
        noise: NoiseVariance::Auto,
        sweep: (6, 4),
        window: 2,
        scale: 1000.0,
        unit: "mm",
        units: &[("q", "m"), ("v", "m/s"), ("u", "V"), ("d_v", "m/s^2")],
        offset: 0.0,
        same_x0: false,
        intersample: InterSample::Zoh,
        notes: vec![
            "Published (shared/data/README.md): dynoNet 2.64 mm (best); continuous-time SUBNET \
             4.61; polynomial NARX 5.17; linear state-space 5.53."
                .into(),
            format!("{DYNONET_NOTE}."),
        ],
        shortened: Some("records decimated to 100 Hz, window 2 samples = 20 ms"),
    })
}

/// The EMPS rows scored as dynoNet's published script scores its model: the estimation
/// record (DATA_EMPS.mat), free run over every sample from the model's own initial state.
pub(super) const DYNONET_RECORD: &str = "estimation (dynoNet's protocol)";

/// Where the published dynoNet EMPS number was measured, with the evidence.
const DYNONET_NOTE: &str = "dynoNet's 2.64 mm (Forgione & Piga; paper source \
     doc/paper/ms.tex of github.com/forgi86/dynonet: \"on the test dataset … RMSE = 2.64\") \
     was scored on the estimation record: the repository's examples/EMPS/EMPS_test.py (at \
     5669940) sets dataset = 'test' and chooses DATA_EMPS_PULSES.mat as its file name, then \
     loads DATA_EMPS.mat, the training record, and reports the RMSE over every sample of a \
     free run from the model's zero initial conditions. The rows marked \"estimation \
     (dynoNet's protocol)\" score our models the same way (the estimation record, every \
     sample, free run from the calibrated initial state); on the official test record the \
     best published number is continuous-time SUBNET's 4.61 mm";

/// Issue 16's target 4 for each test record that has one: the best published free-run
/// RMSE, its source, and the best black box, in the published unit.
fn targets(b: Benchmark) -> &'static [(&'static str, f64, &'static str, f64)] {
    match b {
        Benchmark::CascadedTanks => {
            &[("test", 0.18, "grey box with overflow, 0.18–0.191 V", 0.306)]
        }
        Benchmark::Silverbox => &[
            ("test_multisine", 0.30, "GP-NARX 0.301 mV", 0.301),
            (
                "test_arrow_full",
                0.26,
                "PNLSS 0.26 mV (older protocol)",
                0.60,
            ),
        ],
        Benchmark::Emps => &[
            (
                "test",
                2.64,
                "dynoNet 2.64 mm, scored on the estimation record (see the notes); on this \
                 record continuous-time SUBNET 4.61 mm",
                4.61,
            ),
            (
                DYNONET_RECORD,
                2.64,
                "dynoNet 2.64 mm under its published script's protocol",
                2.64,
            ),
        ],
    }
}

/// Training times the published anchors state, where their sources state one.
fn published_times(b: Benchmark) -> &'static str {
    match b {
        Benchmark::Emps => {
            "dynoNet: 50 000 Adam iterations on the whole record, about 1900 s with the loss \
             still falling (comment in examples/EMPS/EMPS_train.py of github.com/forgi86/dynonet; \
             hardware not stated); the other anchors' sources as used here (shared/data/README.md) \
             state none"
        }
        _ => "none stated in the sources used here (shared/data/README.md)",
    }
}

/// Why a physics-first model misses the target where it does (what the runs show; see the
/// grey-box notes).
fn gap_cause(b: Benchmark) -> &'static str {
    match b {
        Benchmark::CascadedTanks => {
            "the grey box's test error is spread over the whole record (RMSE 0.12–0.37 V in \
             every 64-sample stretch) rather than held in its overflow episodes: the samples \
             where the sensor reads its top (10 V) carry 1.5 % of the test squared error and \
             clipping the simulated level at 10 V changes the test RMSE by 0.0001 V (the \
             lower tank's overflow, which holds the level at the sensor top, is in the model); \
             a saturating first-order sensor instead of that overflow, a smooth overflow, a \
             linear term in the upper outflow or a sensor offset each fit the training record \
             worse or the test record worse (explore_tanks on d52faee). The hybrid's gain is \
             judged on 204 held-out training samples, which do not rank its variants on the \
             test record: with 256-sample shooting windows the guard keeps the refined network \
             (held-out 0.155 V against 0.160 V) and the test RMSE rises to 0.199 V; 4–6 \
             initialisations give 0.1791 V on test with a slightly worse held-out score \
             (0.1603 V), so they are not taken. The upper level is not measured, so its test \
             state comes from the first 50 samples of the lower level alone. The hybrid's \
             test RMSE moves with the seed of its network training more than its distance \
             to the target (below). Both records also show an effect the model has no state \
             for: every descent of the reading through about 5.5 V that had been above 6.9 V \
             drops 0.34–0.63 V within one 4-s sample (training at 1432 and 3756 s, test at \
             776, 1876, 2456, 2748, 3296 and 3776 s), while descents from 6.5 V or lower and \
             every ascent through the same band move 0.1–0.2 V per sample, and the grey box's \
             test error next to these drops reaches 0.76 V — a hysteresis of the level or of \
             its sensor. A hysteretic offset of the reading (a state filling above 6.5–6.7 V \
             and emptying below 5.0–5.2 V) fits the training record a little better with \
             calibrated rates (0.179–0.181 V against 0.189 V; the fill converges to nearly \
             nothing) or worse with held ones (0.193–0.205 V), and the test record no better \
             (0.242–0.254 V against 0.244 V), and a cross-section that \
             varies with the level (lower tank, or both: `TanksOptions::area2`, `area1`) fits \
             the training record better (0.143–0.150 V) but not the test record (0.235 and \
             0.282 V), and calibrated on the first 80 % of the training record it scores \
             worse on the last 20 % than this structure (0.269 and 0.366 V against 0.242 V), \
             so a held-out choice would not take it either (explore_tanks on 35b555b). The \
             hybrid's network training with `mmenn fit` on this model and record (up to 3 hidden units × 3 \
             initialisations, refinement windows of 128 samples, W held at 1.877e4) with \
             seeds 1–7, then `mmenn predict --x0-window 50` on the test record (48923f2), \
             gives 0.1818, 0.1788, 0.1814, 0.1787, 0.1789, 0.1786 and 0.1801 V, and the mean \
             of the first five members' free runs 0.1796 V, so a result this close to 0.18 V \
             meets or misses it by chance"
        }
        Benchmark::Silverbox => {
            "test_multisine and test_arrow_no_extrapolation are within 0.01 mV of the training \
             free-run error (0.2392 mV); on test_arrow_full the grey box's error is 0.231 mV up \
             to sample 29 049, where the output first exceeds the largest training amplitude \
             (0.216 V), and 0.410 mV after it: the last 28 % of the record carries 55 % of the \
             squared error (samples with |y| in 0.1–0.2 V: 0.49 mV, 0.2–0.25 V: 1.06 mV, \
             above 0.25 V: 1.71 mV; below 0.1 V: 0.26 mV; explore_silverbox with quadratic \
             drag on 7a8efb5). The polynomial spring and damping fitted on the training \
             amplitudes do not hold at the arrow's largest ones, and the network, trained on \
             the same amplitudes, does not change that. Quadratic drag (v·|v|) is what moved \
             the arrow most: without it (training 0.2565 mV) test_arrow_full was 0.378 mV. \
             With it, a further quintic spring, cubic damping (v³) or an odd quadratic spring \
             (y·|y|) lowers the training RMSE by at most 0.0016 mV and moves test_arrow_full \
             to 0.288–0.322 mV (explore_silverbox on 7a8efb5), so the training record does \
             not pick the extrapolation among them; without the quadratic spring the arrow is \
             worse (0.369 mV, training 0.2959 mV)"
        }
        Benchmark::Emps => {
            "the published 2.64 mm was not measured on the test record: dynoNet's script scores \
             the estimation record (first note), and under that protocol the rows marked \
             \"estimation (dynoNet's protocol)\" compare with it. On the official test record \
             the training free run is at 2.43 mm but the test error of the grey box (5.97 mm) \
             is almost all slow drift: its 1-s moving average carries 5.76 mm RMS and the rest \
             0.45 mm; it does not depend on speed (5.8–6.2 mm RMS at every |v| band from rest \
             to 0.2 m/s), moves in steps during the strokes and stays between them (segment \
             means from −11.3 to +8.6 mm), and grows with position (slope −0.042 mm/mm; \
             removing an affine function of position leaves 3.9 mm) — measured with \
             explore_emps on 7b7e0a7. The position is the integral of the simulated velocity: \
             a force the input vir does not carry (the test record adds force pulses) or a \
             flexibility the training record does not excite (data README) leaves a permanent \
             position offset that the open-loop model cannot remove; the same training run \
             started from a state fitted to its first 20 samples (the test protocol) gives \
             5.21 mm instead of 2.43 mm from the calibrated state, so part of it is the \
             20-sample state itself. Training error does not rank the structures on the \
             test record (the asymmetric-friction row)"
        }
    }
}

/// The physics-first rows against target 4, per test record with a target.
fn target_note(b: Benchmark, table: &Table) -> String {
    let (_, unit) = b.reporting_unit();
    let mut parts = Vec::new();
    let mut missed = false;
    for &(record, target, best, black_box) in targets(b) {
        let ours: Vec<String> = table
            .rows
            .iter()
            .filter(|r| {
                r.key[1] == record
                    && (r.key[0].starts_with("physics-first grey box") || r.key[0] == hybrid::LABEL)
            })
            .map(|r| {
                let name = if r.key[0] == hybrid::LABEL {
                    "MME/NN on the grey box".to_string()
                } else {
                    r.key[0].clone()
                };
                match r.values[0] {
                    Some(v) => {
                        let verdict = if v <= target {
                            "meets it"
                        } else if v < black_box {
                            "misses it, below the best black box"
                        } else {
                            "misses it"
                        };
                        missed |= v > target;
                        format!("{name} {v:.4} {unit} ({verdict})")
                    }
                    None => {
                        missed = true;
                        format!("{name}: {}", r.remark.as_deref().unwrap_or("no number"))
                    }
                }
            })
            .collect();
        parts.push(format!(
            "{record}: target ≤ {target} {unit} (best published: {best}; best black box \
             {black_box} {unit}) — {}",
            ours.join("; ")
        ));
    }
    let mut note = format!(
        "Target 4 of issue 16 (free-run RMSE, {OFFICIAL}; every physics-first model chosen \
         without the test records): {}.",
        parts.join(". ")
    );
    if missed {
        note.push_str(&format!(
            " Where a target is missed, the cause: {}.",
            gap_cause(b)
        ));
    }
    note
}

fn rmse_after(y: &[f64], sim: &[f64], skip: usize, scale: f64) -> Option<f64> {
    let pairs: Vec<(f64, f64)> = y
        .iter()
        .zip(sim)
        .skip(skip)
        .map(|(a, b)| (*a, *b))
        .collect();
    if pairs.is_empty() || pairs.iter().any(|(_, s)| !s.is_finite()) {
        return None;
    }
    let sse: f64 = pairs.iter().map(|(a, b)| (a - b) * (a - b)).sum();
    Some(scale * (sse / pairs.len() as f64).sqrt())
}

fn write_record(path: &Path, data: &Dataset) -> Result<()> {
    let e = &data.experiments()[0];
    let t = e.times();
    let (u, y) = (row(e.inputs(), 0), row(e.outputs(), 0));
    write_csv(
        path,
        &["t".into(), "u".into(), data.output_names()[0].clone()],
        &[&t, &u, &y],
    )?;
    Ok(())
}

/// Free-run output `output` of a fitted model (`model.json` or any model file) on a test
/// record, computed in memory by `mmenn::predict::compute_predict` (nothing written).
fn hybrid_output(
    model_json: &Path,
    csv: &Path,
    choice: &InitialChoice,
    window: usize,
    output: &str,
) -> Result<Vec<f64>> {
    let model = mmenn::model::LoadedModel::read(model_json)?;
    let record = read_table(csv)?;
    let opts = mmenn::predict::PredictOptions {
        x0: choice.clone(),
        x0_window: Some(window),
        horizon: None,
    };
    let outcome = mmenn::predict::compute_predict(&model, &record, &opts)?;
    outcome
        .column(output)
        .map(<[f64]>::to_vec)
        .with_context(|| format!("the prediction has no channel {output}"))
}

type Setter = fn(Mode, &mmenn::benchmarks::BenchmarkData) -> Result<Setup>;

fn run_benchmark(
    ctx: &Ctx,
    benchmark: Benchmark,
    id: &'static str,
    setup: Setter,
) -> Result<Outcome> {
    let mut out = Outcome::default();
    let dir = match ctx.bench.locate(benchmark) {
        Ok(d) => d,
        Err(e) => {
            out.skipped.insert(id.into(), format!("{e}"));
            return Ok(out);
        }
    };
    let data = load(benchmark, &dir)?;
    let mut s = setup(ctx.mode, &data)?;
    s.est = s.est.with_intersample(s.intersample);
    for (_, test) in &mut s.tests {
        *test = test.clone().with_intersample(s.intersample);
    }
    let output = s.est.output_names()[0].clone();
    let protocol = match &s.shortened {
        None => format!(
            "{OFFICIAL}: x0 from the first {} test samples, RMSE after them",
            s.window
        ),
        Some(how) => format!(
            "shortened ({how}); x0 from the first {} test samples, RMSE after them",
            s.window
        ),
    };
    let mut table = Table::new(
        id,
        s.title,
        &["model", "test record", "protocol"],
        vec![
            Column::checked(
                "rmse",
                s.unit,
                Tolerance::rel(0.25),
                "networks and fits on another machine may land on nearby optima; 25 % still \
                 separates linear from good nonlinear models",
                3,
            ),
            Column::info(
                "train_s",
                "s",
                "time to accuracy: wall time from the training record to this model on the \
                 machine of the run (2 shared cores), every candidate it was chosen among \
                 included; a model built on another row's model includes that one's time",
                3,
            ),
            Column::info("threads", "-", "threads the training used", 1),
        ],
    );
    // NARX is independent of the other rows: it runs on its own thread beside them (the
    // two cores stay busy when this job is the last one running) and its rows, notes and
    // figure line join the table after the others, as if run last.
    let narx_table = table.clone();
    for n in &s.notes {
        table.note(n.clone());
    }
    // The figure's sample grid (its first test record) leads the list of simulated series,
    // so that every model run on that grid joins the figure; removed before plotting.
    // The grid is the official record at full rate (a shortened setup's decimated record
    // would leave out every full-protocol model).
    let grid: Vec<(String, Vec<f64>)> = data
        .tests
        .first()
        .map(|t| (String::new(), vec![0.0; t.data.experiments()[0].len()]))
        .into_iter()
        .collect();
    let mut sims = grid.clone();
    let (mode, offset) = (ctx.mode, s.offset);
    let (data_ref, grid_ref) = (&data, &grid);
    std::thread::scope(|scope| -> Result<()> {
        let narx = scope.spawn(move || {
            let (mut t, mut v) = (narx_table, grid_ref.clone());
            narx::narx_rows(data_ref, mode, &mut t, &mut v, offset);
            (t, v)
        });
        let physics = physics_rows(ctx, &s, &data, &protocol, &mut table, &mut sims, benchmark);
        let (narx_table, narx_sims) = narx
            .join()
            .map_err(|_| anyhow::anyhow!("the NARX rows panicked"))?;
        physics?;
        table.merge(narx_table);
        sims.extend(narx_sims.into_iter().skip(grid.len()));
        Ok(())
    })?;
    sims.drain(..grid.len());
    table.note(target_note(benchmark, &table));
    table.note(format!(
        "Time to accuracy (issue 16, item 6): train_s is each model's wall time from the \
         training record to the model on this run's machine (2 cores shared by the \
         experiments running beside it, so an upper bound of a quiet machine's time), with \
         every candidate it was chosen among and the model it was built on; threads is the \
         number of threads it used. Published training times: {}.",
        published_times(benchmark)
    ));

    // Figures: the first test record at full rate with every model's free run, and each
    // model's error (simulated − measured) over it.
    if let Some(first) = data.tests.first() {
        let (name, e) = (&first.name, &first.data.experiments()[0]);
        let t = e.times();
        let measured = row(e.outputs(), 0);
        let (scale, unit) = benchmark.reporting_unit();
        let shift = |v: &[f64]| v.iter().map(|x| x + s.offset).collect::<Vec<_>>();
        let mut series = vec![line("measured", &t, &measured)];
        let mut errors = Vec::new();
        for (label, y) in &sims {
            let y = shift(y);
            let err: Vec<f64> = y
                .iter()
                .zip(&measured)
                .map(|(a, b)| scale * (a - b))
                .collect();
            series.push(line(label.clone(), &t, &y));
            errors.push(line(label.clone(), &t, &err));
        }
        let fig = Figure {
            title: format!("{benchmark} {name}: free-run simulation"),
            x_label: "t (s)".into(),
            y_label: format!("{output} (as recorded)"),
            series,
            bands: vec![],
        };
        out.figures
            .push(ctx.figure(&format!("real_{}_{name}", benchmark.folder()), &fig)?);
        let fig = Figure {
            title: format!("{benchmark} {name}: free-run error of each model"),
            x_label: "t (s)".into(),
            y_label: format!("simulated − measured {output} ({unit})"),
            series: errors,
            bands: vec![],
        };
        out.figures
            .push(ctx.figure(&format!("real_{}_{name}_error", benchmark.folder()), &fig)?);
    }
    out.tables.push(table);
    Ok(out)
}

/// Every row but NARX's: linear OE and MME/NN on it (where the protocol allows), the linear
/// SS baseline, the grey box and MME/NN on the grey box, in table order.
fn physics_rows(
    ctx: &Ctx,
    s: &Setup,
    data: &mmenn::benchmarks::BenchmarkData,
    protocol: &str,
    table: &mut Table,
    sims: &mut Vec<(String, Vec<f64>)>,
    benchmark: Benchmark,
) -> Result<()> {
    // Linear output-error model from the physics structure, and MME/NN on it: only where
    // the estimation record follows the official protocol (Cascaded Tanks).
    let oe = match &s.shortened {
        None => Some(oe_rows(s, protocol, table, sims, benchmark)?),
        Some(how) => {
            table.note(format!(
                "Not run here: the linear output-error model of the physics structure and \
                 MME/NN on it. They ran only on a shortened protocol ({how}); the same model \
                 class (a second-order linear model) is the linear SS baseline below, run under \
                 the full protocol, and MME/NN runs on the grey box under the full protocol."
            ));
            None
        }
    };

    // Linear state-space baseline on the official records (full rate, every training
    // sample): MOESP, then free-run output error, order chosen on held-out data.
    linear_ss_rows(data, table, sims, ctx.mode, s.offset);

    // Physics-first grey box on the official records.
    let chosen = grey_rows(data, table, sims, ctx.mode, s.offset);

    // MME/NN on top of the calibrated grey box, trained on trajectories.
    match &chosen {
        Some(g) => hybrid::hybrid_rows(ctx, data, g, table, sims, s.offset),
        None => table.note(format!("{}: not built: no grey box", hybrid::LABEL)),
    }

    if let Some(oe) = &oe {
        oe_hybrid_rows(ctx, s, oe, protocol, table, sims, benchmark)?;
    }

    Ok(())
}

/// The linear output-error model of the physics structure and its fit's wall time.
struct OeRows {
    fit: mmenn::sysid_baselines::OeFit,
    seconds: f64,
}

/// Rows of the linear output-error model of the physics structure on the test records;
/// returns the fit (MME/NN on it starts from its model) and its wall time.
fn oe_rows(
    s: &Setup,
    protocol: &str,
    table: &mut Table,
    sims: &mut Vec<(String, Vec<f64>)>,
    benchmark: Benchmark,
) -> Result<OeRows> {
    let oe_cfg = OeConfig {
        free: s.oe_free.iter().map(|p| p.to_string()).collect(),
        ..OeConfig::default()
    };
    let clock = std::time::Instant::now();
    let oe =
        fit_oe(&s.initial, &s.est, &oe_cfg).with_context(|| format!("OE fit on {benchmark}"))?;
    let oe_seconds = clock.elapsed().as_secs_f64();
    let mut oe_model = oe.model.clone();
    oe_model.initial_state = X0Policy::FromData;
    oe_model.observer_window = s.window;
    for (i, (name, test)) in s.tests.iter().enumerate() {
        let y = row(test.experiments()[0].outputs(), 0);
        let r = oe_model
            .simulate(&test.experiments()[0])
            .map_err(anyhow::Error::from)
            .map(|p| row(&p.outputs, 0));
        if let Err(e) = &r {
            table.note(format!("linear OE on {name}: {e:#}"));
        }
        let rmse = r
            .as_ref()
            .ok()
            .and_then(|sim| rmse_after(&y, sim, s.window, s.scale));
        match &r {
            Err(e) => table.push_remark(
                &["linear OE (physics structure)", name, protocol],
                &[None],
                &hybrid::failure_text(&format!("{e:#}")),
            ),
            Ok(_) => table.push(&["linear OE (physics structure)", name, protocol], &[rmse]),
        }
        if let (0, Ok(sim)) = (i, r) {
            sims.push(("linear OE".into(), sim));
        }
    }
    table.set_for_model("linear OE (physics structure)", "train_s", oe_seconds);
    table.set_for_model("linear OE (physics structure)", "threads", 1.0);
    let params: Vec<String> = oe
        .parameters
        .iter()
        .map(|p| {
            format!(
                "{} = {:.4e} ± {:.1e} (from {:.4e})",
                p.name, p.value, p.std, p.initial
            )
        })
        .collect();
    table.note(format!(
        "Linear OE (free-run error, initial state estimated): {}.",
        params.join(", ")
    ));

    Ok(OeRows {
        fit: oe,
        seconds: oe_seconds,
    })
}

/// Rows of MME/NN on the output-error model (the thesis method: the network as trained
/// on `d̂`, then the guard of `mmenn fit`); a free run that diverges is reported with its
/// time.
fn oe_hybrid_rows(
    ctx: &Ctx,
    s: &Setup,
    oe: &OeRows,
    protocol: &str,
    table: &mut Table,
    sims: &mut Vec<(String, Vec<f64>)>,
    benchmark: Benchmark,
) -> Result<()> {
    let work = ctx.work.join("real").join(benchmark.folder());
    std::fs::create_dir_all(&work)?;
    let est_csv = work.join("estimation.csv");
    let model_toml = work.join("model.toml");
    write_record(&est_csv, &s.est)?;
    let units: BTreeMap<String, String> = s
        .units
        .iter()
        .map(|(k, v)| (k.to_string(), v.to_string()))
        .collect();
    write_model(
        &model_toml,
        &ModelSpec {
            linear: oe.fit.model.model.clone(),
            noise_variance: s.noise.clone(),
            units,
            terms: Vec::new(),
            // As the output-error fit above treated the inputs between samples.
            intersample: s.intersample,
            parameters: Vec::new(),
            mechanics: None,
        },
    )?;
    let (max_hidden, inits) = match ctx.mode {
        Mode::Quick => ctx.mode.sweep(),
        Mode::Full => s.sweep,
    };
    let opts = FitOptions {
        max_hidden,
        inits,
        seed: FIT_SEED,
        // The thesis's method: the network as trained on d̂ (the trajectory refinement
        // of `mmenn fit` is the thesis's future work, §7.1, and costs minutes here).
        refine: mmenn::fit::RefineChoice::None,
        ..FitOptions::default()
    };
    let fit_dir = work.join("fit");
    let clock = std::time::Instant::now();
    let fit = run_fit(
        std::slice::from_ref(&est_csv),
        &model_toml,
        &[],
        &opts,
        &fit_dir,
    );
    let fit_seconds = clock.elapsed().as_secs_f64();
    match &fit {
        Err(e) => table.note(format!("MME/NN: fit failed: {e:#}")),
        Ok(summary) => table.note(format!(
            "MME/NN: MME on the estimation record with the OE model (correction on the {} \
             equation), network of {} hidden units from a 1–{max_hidden} × {inits} sweep; \
             kept: {} ({}).",
            s.initial.correction_names().join(", "),
            summary.hidden,
            summary.guard.chosen.describe(),
            summary.guard.reason
        )),
    }
    let model_json = fit_dir.join("model.json");
    let output = s.est.output_names()[0].clone();
    for (i, (name, test)) in s.tests.iter().enumerate() {
        let y = row(test.experiments()[0].outputs(), 0);
        let csv = work.join(format!("{name}.csv"));
        write_record(&csv, test)?;
        let mut variants = vec![(InitialChoice::Fit, protocol.to_string(), "fit")];
        if let (true, Ok(summary)) = (s.same_x0 && i == 0, &fit) {
            variants.push((
                InitialChoice::Given(summary.train.x0.clone()),
                format!(
                    "{OFFICIAL} split; x0 of the estimation record (the benchmark states they \
                     share it), RMSE on all samples"
                ),
                "same_x0",
            ));
        }
        for (choice, proto, tag) in variants {
            let sim = match &fit {
                Ok(_) => hybrid_output(&model_json, &csv, &choice, s.window, &output),
                Err(_) => Err(anyhow::anyhow!("no fitted model")),
            };
            if let (Err(e), Ok(_)) = (&sim, &fit) {
                table.note(format!("MME/NN on {name} ({tag}): {e:#}"));
            }
            let skip = if tag == "fit" { s.window } else { 0 };
            let rmse = sim
                .as_ref()
                .ok()
                .and_then(|v| rmse_after(&y, v, skip, s.scale));
            let key = ["MME/NN (OE model + network)", name.as_str(), proto.as_str()];
            match (&sim, &fit) {
                (Err(e), Ok(_)) => {
                    table.push_remark(&key, &[None], &hybrid::failure_text(&format!("{e:#}")))
                }
                (Ok(_), _) if rmse.is_none() => {
                    table.push_remark(&key, &[None], "diverged (non-finite output)")
                }
                _ => table.push(&key, &[rmse]),
            }
            if let (0, "fit", Ok(v)) = (i, tag, sim) {
                sims.push(("MME/NN".into(), v));
            }
        }
    }
    if fit.is_ok() {
        // Built on the linear OE model: its fit time counts too.
        let label = "MME/NN (OE model + network)";
        table.set_for_model(label, "train_s", oe.seconds + fit_seconds);
        table.set_for_model(label, "threads", rayon::current_num_threads() as f64);
    }

    Ok(())
}

/// Rows of the linear state-space baseline (subspace model and its free-run refinement)
/// under the official protocol, read from the records as the loader defines them; the
/// first test record's refined simulation joins the figure when it has the figure's
/// sample grid (`offset`: what the figure adds back to every series).
fn linear_ss_rows(
    data: &mmenn::benchmarks::BenchmarkData,
    table: &mut Table,
    sims: &mut Vec<(String, Vec<f64>)>,
    mode: Mode,
    offset: f64,
) {
    // EMPS: position is the integral of velocity; the second variant holds that pole at
    // z = 1 (an unconstrained fit puts it slightly outside the unit circle).
    let variants: &[bool] = match data.benchmark {
        Benchmark::Emps => &[false, true],
        _ => &[false],
    };
    let mut held_out = Vec::new();
    for &integrator in variants {
        if let Some(v) = linear_ss_variant(data, table, mode, integrator) {
            held_out.push(v);
        }
    }
    // With two variants, the baseline is the one with the smaller held-out free-run RMSE
    // of its chosen order (training record only); its rows say so, and it joins the
    // figure (the figure adds the setup's offset back; this model works in recorded units).
    let best = held_out.iter().min_by(|a, b| a.1.total_cmp(&b.1));
    if let Some((_, _, Some(v))) = best
        && sims.first().is_some_and(|(_, f)| f.len() == v.len())
    {
        sims.push(("linear SS".into(), v.iter().map(|x| x - offset).collect()));
    }
    if held_out.len() > 1
        && let Some((label, _, _)) = best.cloned()
    {
        let (scale, unit) = data.benchmark.reporting_unit();
        let scores: Vec<String> = held_out
            .iter()
            .map(|(l, h, _)| format!("{l}: {:.4} {unit}", scale * h))
            .collect();
        let chosen = format!("{label}; {LINEAR_BASELINE}");
        for r in table.rows.iter_mut().filter(|r| r.key[0] == label) {
            r.key[0] = chosen.clone();
        }
        table.note(format!(
            "Linear baseline (issue 16, item 2): of the two linear SS variants, the one with \
             the smaller held-out free-run RMSE of its chosen order on the last 25 % of the \
             training record ({}); the test records play no part.",
            scores.join("; ")
        ));
    }
}

/// Published anchors of one record of the glance table: the published linear model's
/// RMSE (where there is one) and the best published result with its source, in the
/// table's unit (shared/data/README.md).
pub fn anchors(table_id: &str, record: &str) -> (Option<f64>, Option<(f64, &'static str)>) {
    match (table_id, record) {
        ("real_cascaded_tanks", "test") => (Some(0.588), Some((0.18, "grey box with overflow"))),
        ("real_silverbox", "test_multisine") => (Some(6.96), Some((0.301, "GP-NARX"))),
        ("real_silverbox", "test_arrow_full") => {
            (Some(14.4), Some((0.26, "PNLSS, older protocol")))
        }
        ("real_silverbox", "test_arrow_no_extrapolation") => (Some(6.58), Some((0.259, "GP-NARX"))),
        ("real_emps", "test") => (Some(5.53), Some((4.61, "CT-SUBNET"))),
        ("real_emps", DYNONET_RECORD) => (None, Some((2.64, "dynoNet"))),
        _ => (None, None),
    }
}

/// Marks the linear SS variant that is the benchmark's linear baseline, where there are
/// several (the glance table reads it).
pub const LINEAR_BASELINE: &str = "the linear baseline, chosen on held-out training data";

/// One linear SS variant's rows; returns its refined label, the held-out RMSE of its
/// chosen order and its free run on the first test record.
fn linear_ss_variant(
    data: &mmenn::benchmarks::BenchmarkData,
    table: &mut Table,
    mode: Mode,
    integrator: bool,
) -> Option<(String, f64, Option<Vec<f64>>)> {
    let benchmark = data.benchmark;
    let window = benchmark.init_window();
    let (scale, unit) = benchmark.reporting_unit();
    let cfg = LinearSsConfig {
        window,
        max_order: match mode {
            Mode::Quick => 4,
            Mode::Full => 6,
        },
        integrator,
        ..LinearSsConfig::default()
    };
    let held = if integrator {
        ", pole at z = 1 held"
    } else {
        ""
    };
    let clock = std::time::Instant::now();
    let fit = match fit_linear_ss(&data.estimation, &cfg) {
        Ok(f) => f,
        Err(e) => {
            table.note(format!("linear SS{held}: fit failed: {e}"));
            return None;
        }
    };
    let seconds = clock.elapsed().as_secs_f64();
    let protocol = format!("{OFFICIAL}: x0 from the first {window} test samples, RMSE after them");
    let n = fit.order;
    let mut first_sim = None;
    for (refined, label, model) in [
        (
            false,
            format!("linear SS, MOESP only (n = {n}{held})"),
            &fit.subspace,
        ),
        (
            true,
            format!("linear SS, MOESP + free-run OE (n = {n}{held})"),
            &fit.model,
        ),
    ] {
        for (i, test) in data.tests.iter().enumerate() {
            let e = &test.data.experiments()[0];
            let (u, y) = (row(e.inputs(), 0), row(e.outputs(), 0));
            let sim = model.simulate_signal(&u, &y);
            if sim.is_none() {
                table.note(format!("{label} on {}: diverged", test.name));
            }
            let rmse = sim.as_ref().and_then(|v| rmse_after(&y, v, window, scale));
            table.push(&[&label, &test.name, &protocol], &[rmse]);
            if refined {
                table.set_for_model(&label, "train_s", seconds);
                table.set_for_model(&label, "threads", 1.0);
            }
            if let (0, Some(v), true) = (i, sim, refined) {
                first_sim = Some(v);
            }
        }
    }
    let poles: Vec<String> = fit
        .model
        .poles()
        .iter()
        .map(|(r, i)| {
            if i.abs() > 0.0 {
                format!("{r:.6}{i:+.6}i")
            } else {
                format!("{r:.6}")
            }
        })
        .collect();
    let candidates: Vec<String> = fit
        .candidates
        .iter()
        .map(|c| match (c.refined_rmse, &c.failure) {
            (Some(r), _) => format!("n = {}: {:.4} {unit}", c.order, scale * r),
            (None, Some(f)) => format!("n = {}: failed ({f})", c.order),
            (None, None) => format!("n = {}: diverged", c.order),
        })
        .collect();
    let sv: Vec<String> = fit
        .singular_values
        .iter()
        .take(8)
        .map(|v| format!("{v:.2e}"))
        .collect();
    table.note(format!(
        "Linear SS{held} ({OFFICIAL}: official split, full sampling rate, all {} estimation samples): \
         PO-MOESP (20 block rows) on the first 75 % of the estimation record, poles grouped \
         into parallel second-order sections, numerators and feedthrough by least squares, then \
         free-run output error (Levenberg–Marquardt; x0 fitted to the first {window} samples as \
         in the test protocol; input bias fitted) for each order up to {}; order {n} = the smallest \
         within 2 % of the best held-out free-run RMSE on the last 25 % ({}), then refined on \
         the whole record. MOESP singular values (relative): {}. Poles of the refined model: \
         {}; input offset {:.6}, output offset {:.6} (recorded units); training free-run RMSE \
         {:.4} {unit}; fit time {seconds:.1} s (1 core).",
        data.estimation.experiments()[0].len(),
        cfg.max_order,
        candidates.join(", "),
        sv.join(", "),
        poles.join(", "),
        fit.model.input_offset,
        fit.model.output_offset,
        scale * fit.training_rmse,
    ));
    let held_out = fit
        .candidates
        .iter()
        .find(|c| c.order == n)
        .and_then(|c| c.refined_rmse)?;
    Some((
        format!("linear SS, MOESP + free-run OE (n = {n}{held})"),
        held_out,
        first_sim,
    ))
}

/// Candidate grey boxes of a benchmark (several structures or starting points; the one
/// with the lowest training free-run RMSE is reported) and a label.
fn grey_candidates(
    data: &mmenn::benchmarks::BenchmarkData,
    mode: Mode,
) -> Result<(String, Vec<(String, grey::GreySpec)>)> {
    Ok(match data.benchmark {
        Benchmark::Emps => (
            "physics-first grey box (M q'' = gτ u − Fv q' − Fc tanh(q'/ε) − offset)".into(),
            vec![("ε = 0.3 mm/s".into(), grey::emps_spec(3e-4)?)],
        ),
        Benchmark::CascadedTanks => {
            let base = grey::TanksOptions::default();
            let mut v = vec![(
                "Torricelli outflows, overflows, pump offset".to_string(),
                grey::tanks_model(&grey::TanksOptions {
                    linear_outflow: false,
                    ..base
                })?,
            )];
            v.push((
                "+ linear term in the lower outflow".into(),
                grey::tanks_spec(base.h1_top, base.h2_top, base.rate)?,
            ));
            if mode == Mode::Full {
                v.push((
                    "+ lower sensor offset 1 V".into(),
                    grey::tanks_model(&grey::TanksOptions {
                        sensor_offset: 1.0,
                        ..base
                    })?,
                ));
            }
            (
                "physics-first grey box (√h outflows, both overflows, pump offset)".into(),
                v,
            )
        }
        Benchmark::Silverbox => {
            let (k, c, b) = oscillator_guess(&data.estimation.experiments()[0])?;
            use grey::SilverboxExtra::{
                DisplacementDamping, Feedthrough, QuadraticDrag, QuadraticSpring,
            };
            let mut v = vec![(
                "cubic + quadratic spring, y²·y' damping, quadratic drag, input stage τ = 0.2 ms"
                    .to_string(),
                grey::silverbox_model(
                    k,
                    c,
                    b,
                    &[
                        QuadraticSpring,
                        DisplacementDamping,
                        QuadraticDrag,
                        Feedthrough(2e-4),
                    ],
                )?,
            )];
            if mode == Mode::Full {
                v.push((
                    "cubic + quadratic spring, y²·y' damping, input stage τ = 0.2 ms".into(),
                    grey::silverbox_model(
                        k,
                        c,
                        b,
                        &[QuadraticSpring, DisplacementDamping, Feedthrough(2e-4)],
                    )?,
                ));
                v.push(("cubic spring".into(), grey::silverbox_spec(k, c, b)?));
                v.push((
                    "cubic + quadratic spring".into(),
                    grey::silverbox_model(k, c, b, &[QuadraticSpring])?,
                ));
                v.push((
                    "cubic + quadratic spring, y²·y' damping".into(),
                    grey::silverbox_model(k, c, b, &[QuadraticSpring, DisplacementDamping])?,
                ));
            }
            (
                "physics-first grey box (polynomial spring and damping, input stage, input offset)"
                    .into(),
                v,
            )
        }
    })
}

/// The grey box the table reports (lowest training free-run RMSE among the candidates):
/// its structure, calibration, candidate name and the wall time of all candidates' calibration.
/// MME/NN on the grey box starts from it (no second calibration).
pub struct ChosenGrey {
    pub spec: grey::GreySpec,
    pub fit: grey::GreyFit,
    pub name: String,
    pub seconds: f64,
}

/// Rows of the physics-first grey box (see [`grey`]): calibrated by free-run output error
/// on the whole training record at full rate, scored under the official protocol. Returns
/// the chosen grey box (`None` when every calibration failed).
fn grey_rows(
    data: &mmenn::benchmarks::BenchmarkData,
    table: &mut Table,
    sims: &mut Vec<(String, Vec<f64>)>,
    mode: Mode,
    offset: f64,
) -> Option<ChosenGrey> {
    let window = data.benchmark.init_window();
    let (scale, unit) = data.benchmark.reporting_unit();
    let (label, candidates) = match grey_candidates(data, mode) {
        Ok(c) => c,
        Err(e) => {
            table.note(format!("grey box: not built: {e:#}"));
            return None;
        }
    };
    let tests: Vec<(String, Experiment)> = data
        .tests
        .iter()
        .map(|t| (t.name.clone(), t.data.experiments()[0].clone()))
        .collect();
    let est = &data.estimation.experiments()[0];
    let clock = std::time::Instant::now();
    let mut best: Option<(String, grey::GreySpec, grey::GreyFit)> = None;
    let mut tried = Vec::new();
    for (name, spec) in candidates {
        match grey::fit_grey(&spec, est, &tests, window) {
            Ok(fit) => {
                tried.push(format!("{name}: {:.4} {unit}", scale * fit.train_rmse));
                if fit.train_rmse.is_finite()
                    && best
                        .as_ref()
                        .is_none_or(|(_, _, b)| fit.train_rmse < b.train_rmse)
                {
                    best = Some((name, spec, fit));
                }
            }
            Err(e) => tried.push(format!("{name}: failed ({e:#})")),
        }
    }
    let seconds = clock.elapsed().as_secs_f64();
    let Some((chosen, chosen_spec, fit)) = best else {
        table.note(format!(
            "grey box: every calibration failed: {}",
            tried.join("; ")
        ));
        return None;
    };
    push_grey(
        table,
        sims,
        &label,
        &fit,
        &tests,
        window,
        scale,
        Some(offset),
    );
    if data.benchmark == Benchmark::Emps {
        push_dynonet(table, &label, &fit, scale);
    }
    table.set_for_model(&label, "train_s", seconds);
    table.set_for_model(&label, "threads", 1.0);
    table.note(format!(
        "Grey box ({OFFICIAL}): the published physics as named terms, coefficients and the \
         training initial state calibrated by free-run output error (mmenn::discovery::calibrate: \
         Levenberg–Marquardt with exact RK4 sensitivities, growing horizons) on all {} \
         training samples at full rate; test state fitted to the first {window} test \
         outputs with the coefficients held. Candidates (training free-run RMSE; the lowest \
         is reported, chosen without the test records): {}. Chosen: {chosen}. Calibrated \
         terms: {}. Training initial state {:?} (recorded units); training free-run RMSE {:.4} {unit}; training wall time {seconds:.1} s \
         for all candidates (1 core of 2 shared).",
        est.len(),
        tried.join("; "),
        grey_terms(&fit),
        fit.x0.iter().map(|v| format!("{v:.5e}")).collect::<Vec<_>>(),
        scale * fit.train_rmse,
    ));
    if data.benchmark == Benchmark::Emps {
        // Janot et al. 2019 (§3) report direction-dependent friction; started from the
        // symmetric fit, reported beside it as its own structure.
        let grey_seconds = seconds;
        let clock = std::time::Instant::now();
        let asym = grey::emps_asymmetric_from(&fit.model, 3e-4)
            .and_then(|spec| grey::fit_grey(&spec, est, &tests, window));
        let seconds = clock.elapsed().as_secs_f64();
        let label = "physics-first grey box, asymmetric friction (Fv±, Fc±)";
        match asym {
            Ok(a) => {
                push_grey(table, sims, label, &a, &tests, window, scale, None);
                push_dynonet(table, label, &a, scale);
                // Started from the symmetric grey box: its calibration time counts too.
                table.set_for_model(label, "train_s", grey_seconds + seconds);
                table.set_for_model(label, "threads", 1.0);
                table.note(format!(
                    "{label} ({OFFICIAL}): `M q'' = gτ·u − Fv+·max(q', 0) − Fv−·min(q', 0) − \
                     Fc·tanh(q'/ε) − ΔFc·|tanh(q'/ε)| − offset` (Janot et al. 2019, §3), \
                     calibrated as above from the symmetric grey box's coefficients; \
                     calibrated terms: {}; training free-run RMSE {:.4} {unit} (symmetric: \
                     {:.4}); training wall time {seconds:.1} s. It fits the training record \
                     better and the test record worse: the test experiment adds force pulses \
                     that the input vir does not carry and excites a flexibility the \
                     training record does not (data README), so training error does not \
                     rank these structures on the test record.",
                    grey_terms(&a),
                    scale * a.train_rmse,
                    scale * fit.train_rmse,
                ));
            }
            Err(e) => table.note(format!("{label}: failed: {e:#}")),
        }
    }
    Some(ChosenGrey {
        spec: chosen_spec,
        fit,
        name: chosen,
        seconds,
    })
}

/// The row of a grey box scored under dynoNet's published EMPS protocol
/// ([`DYNONET_RECORD`]).
fn push_dynonet(table: &mut Table, label: &str, fit: &grey::GreyFit, scale: f64) {
    let value = fit
        .train_rmse_all
        .is_finite()
        .then_some(scale * fit.train_rmse_all);
    table.push(
        &[
            label,
            DYNONET_RECORD,
            "dynoNet's published EMPS script: estimation record (DATA_EMPS), free run over \
             every sample from the calibrated initial state",
        ],
        &[value],
    );
}

/// A grey box's calibrated terms for a note.
fn grey_terms(fit: &grey::GreyFit) -> String {
    fit.model
        .terms()
        .iter()
        .map(|t| {
            format!(
                "{} {}: {:+.5e}·{}",
                fit.model.linear().state_names()[t.state],
                t.effect,
                t.coefficient,
                t.expr
            )
        })
        .collect::<Vec<_>>()
        .join("; ")
}

/// The rows of one grey box's test runs (and, with `figure_offset`, its first test run in
/// the figure, shifted by that offset).
#[allow(clippy::too_many_arguments)]
fn push_grey(
    table: &mut Table,
    sims: &mut Vec<(String, Vec<f64>)>,
    label: &str,
    fit: &grey::GreyFit,
    tests: &[(String, Experiment)],
    window: usize,
    scale: f64,
    figure_offset: Option<f64>,
) {
    let protocol = format!(
        "{OFFICIAL}: all training samples at full rate; x0 from the first {window} test samples, RMSE after them"
    );
    for (i, (t, (_, e))) in fit.tests.iter().zip(tests).enumerate() {
        let y = row(e.outputs(), 0);
        let rmse = match &t.sim {
            Ok(v) => rmse_after(&y, v, window, scale),
            Err(m) => {
                table.note(format!("{label} on {}: diverged: {m}", t.name));
                None
            }
        };
        table.push(&[label, &t.name, &protocol], &[rmse]);
        if let (0, Ok(v), Some(offset)) = (i, &t.sim, figure_offset)
            && sims.first().is_some_and(|(_, f)| f.len() == v.len())
        {
            sims.push(("grey box".into(), v.iter().map(|x| x - offset).collect()));
        }
    }
}
