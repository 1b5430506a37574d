//! The observer of a running estimate: events come in the order the estimator runs,
//! the `W` trials are the returned `W` curve one to one, the Gauss–Newton iterations of
//! the final solve are the returned history, and the result is the same bits with or
//! without an observer.

use std::sync::Mutex;

use mme_core::{
    MmeConfig, MmeEvent, MmeOutput, MmePhase, NoiseSpec, NonlinearModel, RobustConfig, WeightSpec,
    estimate_nonlinear_with_observer, estimate_nonlinear_with_report, estimate_robust,
    estimate_robust_with_observer, estimate_with_observer, estimate_with_report,
};
use nalgebra::DMatrix;
use sysid_core::ModelNames;

use super::common::{CubicMsd, msd_assumed, msd_data};

/// Every event an estimate told, in order.
#[derive(Default)]
struct Recorder(Mutex<Vec<MmeEvent>>);

impl Recorder {
    fn observer(&self) -> impl Fn(&MmeEvent) + Sync + '_ {
        |e: &MmeEvent| self.0.lock().unwrap().push(*e)
    }
    fn events(self) -> Vec<MmeEvent> {
        self.0.into_inner().unwrap()
    }
}

/// The output with the wall-clock phase times (which differ between any two runs)
/// cleared, printed with `{:?}`: `f64`'s `Debug` is its shortest round-trip form, so two
/// equal strings mean equal bits.
fn bits(out: &MmeOutput) -> String {
    let mut out = out.clone();
    out.estimate.report.phase_seconds.clear();
    format!("{out:?}")
}

/// The events after the first `Phase(phase)` up to the next phase.
fn in_phase(events: &[MmeEvent], phase: MmePhase) -> Vec<MmeEvent> {
    let Some(at) = events.iter().position(|e| *e == MmeEvent::Phase(phase)) else {
        return Vec::new();
    };
    events[at + 1..]
        .iter()
        .take_while(|e| !matches!(e, MmeEvent::Phase(_)))
        .copied()
        .collect()
}

/// `(trial, α, ratio)` of the `W` trials among `events`.
fn trials(events: &[MmeEvent]) -> Vec<(usize, f64, f64)> {
    events
        .iter()
        .filter_map(|e| match *e {
            MmeEvent::WTrial {
                trial,
                alpha,
                ratio,
                ..
            } => Some((trial, alpha, ratio)),
            _ => None,
        })
        .collect()
}

/// The phases in the order announced.
fn phases(events: &[MmeEvent]) -> Vec<MmePhase> {
    events
        .iter()
        .filter_map(|e| match e {
            MmeEvent::Phase(p) => Some(*p),
            _ => None,
        })
        .collect()
}

/// The `W` trials of a search, sorted by `α`, against its curve: the same points, bit
/// for bit, numbered 1, 2, … in the order tried.
fn assert_trials_are_the_curve(found: &[(usize, f64, f64)], out: &MmeOutput) {
    let numbers: Vec<usize> = found.iter().map(|t| t.0).collect();
    assert_eq!(numbers, (1..=found.len()).collect::<Vec<_>>());
    let mut told: Vec<(u64, u64)> = found
        .iter()
        .map(|t| (t.1.to_bits(), t.2.to_bits()))
        .collect();
    told.sort_by(|a, b| f64::from_bits(a.0).total_cmp(&f64::from_bits(b.0)));
    let curve: Vec<(u64, u64)> = out
        .w_curve
        .iter()
        .map(|p| (p.alpha.to_bits(), p.ratio.to_bits()))
        .collect();
    assert_eq!(told, curve);
    let search = out.w_search.as_ref().unwrap();
    assert_eq!(found.len(), search.evaluations);
}

#[test]
fn linear_estimate_tells_noise_search_w_trials_and_final_sweep_in_order() {
    let (data, _) = msd_data(801, 0.01, 7);
    let config = MmeConfig {
        noise_variance: NoiseSpec::Auto,
        ..MmeConfig::default()
    };
    let plain = estimate_with_report(&msd_assumed(), &data, &config).unwrap();
    let rec = Recorder::default();
    let seen = estimate_with_observer(&msd_assumed(), &data, &config, &rec.observer()).unwrap();
    assert_eq!(bits(&seen), bits(&plain));
    let events = rec.events();
    assert_eq!(
        phases(&events),
        [
            MmePhase::NoiseVariance,
            MmePhase::WeightSearch,
            MmePhase::FinalSolve
        ]
    );
    assert_eq!(events[0], MmeEvent::Phase(MmePhase::NoiseVariance));
    // Nothing after the final sweep is announced: a linear sweep has no iterations.
    assert_eq!(events.last(), Some(&MmeEvent::Phase(MmePhase::FinalSolve)));

    // The noise search: its covariance-constraint start (W trials from 1), then the
    // likelihood evaluations counted on from there up to the report's count.
    let noise = in_phase(&events, MmePhase::NoiseVariance);
    let start = trials(&noise);
    assert!(!start.is_empty());
    assert!(matches!(noise[0], MmeEvent::WTrial { trial: 1, .. }));
    let steps: Vec<usize> = noise
        .iter()
        .filter_map(|e| match e {
            MmeEvent::NoiseStep { evaluation, .. } => Some(*evaluation),
            _ => None,
        })
        .collect();
    assert_eq!(start.len() + steps.len(), noise.len());
    assert_eq!(
        steps,
        (start.len() + 1..=plain.noise.evaluations).collect::<Vec<_>>()
    );
    // The start's trials all come before the first likelihood evaluation.
    assert!(matches!(noise[start.len()], MmeEvent::NoiseStep { .. }));
    // The last evaluation is the solve at the optimum: its value is finite.
    match noise.last() {
        Some(MmeEvent::NoiseStep {
            neg2_log_likelihood,
            ..
        }) => assert!(neg2_log_likelihood.is_finite()),
        other => panic!("{other:?}"),
    }

    // The W search: trial after trial, the returned curve one to one.
    let search = in_phase(&events, MmePhase::WeightSearch);
    let found = trials(&search);
    assert_eq!(found.len(), search.len());
    assert_trials_are_the_curve(&found, &plain);
    // The target and the bound are the configuration's.
    let MmeEvent::WTrial {
        target, max_trials, ..
    } = search[0]
    else {
        panic!("{:?}", search[0]);
    };
    let WeightSpec::Auto(auto) = &config.w else {
        panic!("automatic W expected");
    };
    assert_eq!(
        (target, max_trials),
        (auto.target_ratio, auto.max_evaluations)
    );
}

/// The cubic mass–spring–damper as the nonlinear assumed model.
fn cubic_model() -> NonlinearModel<CubicMsd> {
    let v = |s: &[&str]| s.iter().map(|x| x.to_string()).collect();
    NonlinearModel::new(
        CubicMsd,
        DMatrix::from_row_slice(1, 2, &[1.0, 0.0]),
        DMatrix::from_row_slice(2, 1, &[0.0, 1.0]),
        ModelNames {
            states: v(&["x", "v"]),
            inputs: v(&["u"]),
            outputs: v(&["x"]),
            corrections: v(&["d"]),
        },
    )
    .unwrap()
}

#[test]
fn nonlinear_estimate_tells_every_gauss_newton_iteration_of_every_solve() {
    let (data, _) = msd_data(601, 0.01, 11);
    let config = MmeConfig {
        noise_variance: NoiseSpec::Given(vec![0.01]),
        ..MmeConfig::default()
    };
    let model = cubic_model();
    let plain = estimate_nonlinear_with_report(&model, &data, &config).unwrap();
    let rec = Recorder::default();
    let seen = estimate_nonlinear_with_observer(&model, &data, &config, &rec.observer()).unwrap();
    assert_eq!(bits(&seen), bits(&plain));
    let events = rec.events();
    // A given noise variance: no noise search.
    assert_eq!(
        phases(&events),
        [MmePhase::WeightSearch, MmePhase::FinalSolve]
    );

    // Each W trial is one solve: its iterations (numbered from 1, within the bound)
    // come before it.
    let search = in_phase(&events, MmePhase::WeightSearch);
    let max = config.iterations.max_iterations;
    let mut run = Vec::new();
    for e in &search {
        match *e {
            MmeEvent::Iteration {
                iteration,
                max_iterations,
                ..
            } => {
                assert_eq!(max_iterations, max);
                run.push(iteration);
            }
            MmeEvent::WTrial { trial, .. } => {
                assert_eq!(run, (1..=run.len()).collect::<Vec<_>>(), "trial {trial}");
                assert!(
                    !run.is_empty() && run.len() <= max,
                    "trial {trial}: {run:?}"
                );
                run.clear();
            }
            other => panic!("{other:?} in the W search"),
        }
    }
    assert!(run.is_empty(), "iterations after the last trial: {run:?}");
    assert_trials_are_the_curve(&trials(&search), &plain);

    // The final solve's iterations are the returned history: index and cost, bit for bit,
    // with the relative change the convergence test reads.
    let last = in_phase(&events, MmePhase::FinalSolve);
    let told: Vec<(usize, u64)> = last
        .iter()
        .map(|e| match *e {
            MmeEvent::Iteration {
                iteration, cost, ..
            } => (iteration, cost.to_bits()),
            other => panic!("{other:?} in the final solve"),
        })
        .collect();
    let history: Vec<(usize, u64)> = plain
        .estimate
        .report
        .iterations
        .iter()
        .map(|r| (r.iteration, r.cost.to_bits()))
        .collect();
    assert!(!history.is_empty());
    assert_eq!(told, history);
    let costs: Vec<f64> = history.iter().map(|h| f64::from_bits(h.1)).collect();
    for (k, e) in last.iter().enumerate().skip(1) {
        let MmeEvent::Iteration {
            relative_change,
            tolerance,
            ..
        } = *e
        else {
            unreachable!()
        };
        let expected = (costs[k - 1] - costs[k]).abs() / costs[k].abs();
        assert_eq!(relative_change.to_bits(), expected.to_bits());
        assert_eq!(
            tolerance.to_bits(),
            config.iterations.cost_tolerance.to_bits()
        );
    }
}

#[test]
fn robust_estimate_tells_each_pass_after_its_inner_estimate() {
    let (mut data_src, _) = msd_data(401, 0.01, 5);
    // One wild sample so that the passes have something to do.
    let mut y = data_src.experiments()[0].outputs().clone();
    y[(0, 200)] += 3.0;
    let exp = &data_src.experiments()[0];
    let wild = sysid_core::Experiment::new(exp.t0(), exp.dt(), exp.inputs().clone(), y).unwrap();
    data_src = super::common::dataset(&["u"], &["x"], vec![wild]);
    let config = MmeConfig {
        noise_variance: NoiseSpec::Given(vec![0.01]),
        ..MmeConfig::default()
    };
    let robust = RobustConfig::default();
    let plain = estimate_robust(&msd_assumed(), &data_src, &config, &robust).unwrap();
    let rec = Recorder::default();
    let seen =
        estimate_robust_with_observer(&msd_assumed(), &data_src, &config, &robust, &rec.observer())
            .unwrap();
    assert_eq!(bits(&seen.output), bits(&plain.output));
    assert_eq!(
        (seen.passes, seen.clipped, seen.converged),
        (plain.passes, plain.clipped, plain.converged)
    );
    let events = rec.events();
    let passes: Vec<(usize, usize)> = events
        .iter()
        .enumerate()
        .filter_map(|(at, e)| match e {
            MmeEvent::RobustPass { pass, .. } => Some((at, *pass)),
            _ => None,
        })
        .collect();
    assert!(plain.passes >= 2, "{} passes", plain.passes);
    assert_eq!(
        passes.iter().map(|p| p.1).collect::<Vec<_>>(),
        (1..=plain.passes).collect::<Vec<_>>()
    );
    // Each pass is one inner estimate: its W search and final sweep come first.
    let mut from = 0;
    for &(at, pass) in &passes {
        assert_eq!(
            phases(&events[from..at]),
            [MmePhase::WeightSearch, MmePhase::FinalSolve],
            "pass {pass}"
        );
        from = at + 1;
    }
    assert_eq!(from, events.len());
    // The last pass moved no pseudo-observation by more than the tolerance when the
    // passes converged.
    if let Some(MmeEvent::RobustPass {
        moved, tolerance, ..
    }) = events.last()
    {
        assert_eq!(*moved <= *tolerance, plain.converged);
    }
}
