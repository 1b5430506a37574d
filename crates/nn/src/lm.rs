//! Levenberg–Marquardt training of an [`Mlp`] (MATLAB `trainlm`-style by default): damped
//! Gauss–Newton steps `(JᵀJ + μD) δ = Jᵀe` solved by Cholesky (with `JᵀJ` and `Jᵀe`
//! accumulated in the private `normal` module without forming `J`), μ adaptation
//! ([`Damping`]), early stopping on a validation split, optional weight decay, and the
//! [`TrainReport`].

use nalgebra::{Cholesky, DMatrix, DVector};
use rand::SeedableRng;
use rand::rngs::ChaCha8Rng;
use rand::seq::SliceRandom;
use serde::{Deserialize, Serialize};

mod kernel;
mod normal;
mod part;
mod schedule;

use normal::{Cutoff, Linearisation, Use};
use part::Part;
use schedule::Schedule;

use crate::config::{Acceleration, Damping, ErrorSpace, LmConfig, ValidationSplit};
use crate::error::{NnError, Result};
use crate::mlp::{Mlp, Workspace, check_training_data};

/// Why training stopped. Not converging is a reason, not an error.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
#[non_exhaustive]
pub enum StopReason {
    /// [`LmConfig::max_epochs`] epochs were run.
    MaxEpochs,
    /// The training MSE reached [`LmConfig::goal_mse`].
    GoalReached,
    /// The gradient norm fell below [`LmConfig::min_gradient`].
    MinGradient,
    /// No step reduced the objective before μ exceeded [`LmConfig::mu_max`].
    MuMax,
    /// The validation MSE failed to improve [`LmConfig::max_fail`] epochs in a row.
    ValidationStop,
}

/// State after one epoch, passed to the progress callback.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct EpochInfo {
    /// Epoch number (1 = after the first accepted step).
    pub epoch: usize,
    /// Training MSE after the step.
    pub train_mse: f64,
    /// Validation MSE after the step (`None` without a validation split).
    pub val_mse: Option<f64>,
    /// Damping μ after the step's adaptation.
    pub mu: f64,
    /// Norm of the objective's gradient after the step.
    pub gradient_norm: f64,
}

/// What training did. MSEs are in [`LmConfig::error_space`] units.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrainReport {
    /// Why it stopped.
    pub termination: StopReason,
    /// Epochs run (accepted steps).
    pub epochs: usize,
    /// Epoch whose weights were returned: the best-validation epoch when a validation
    /// split is used, otherwise the last epoch.
    pub best_epoch: usize,
    /// Training MSE of the returned weights.
    pub train_mse: f64,
    /// Validation MSE of the returned weights (`None` without validation).
    pub val_mse: Option<f64>,
    /// Training MSE per epoch; index 0 is the initial network.
    pub train_history: Vec<f64>,
    /// Validation MSE per epoch (index 0 = initial); empty without validation.
    pub val_history: Vec<f64>,
    /// Final damping μ.
    pub mu: f64,
    /// Gradient norm at the last epoch.
    pub gradient_norm: f64,
    /// Samples used for training.
    pub n_train: usize,
    /// Samples used for validation.
    pub n_val: usize,
}

/// Geodesic acceleration's bound on the correction: a step with `2‖a‖ > α‖δ‖` is
/// rejected (Transtrum & Sethna 2012 recommend α ≈ 0.75).
const GEODESIC_ALPHA: f64 = 0.75;

/// Per-output factor `ρ_o` turning scaled errors into [`ErrorSpace`] errors.
fn error_weights(net: &Mlp, space: ErrorSpace) -> Vec<f64> {
    match space {
        ErrorSpace::Original => net.output_scaler().half_range().to_vec(),
        ErrorSpace::Normalised => vec![1.0; net.n_outputs()],
    }
}

impl Mlp {
    /// Mean squared error `Σ (t − y)² / (N·q)` on `inputs` (`n × N`) and `targets`
    /// (`q × N`), in `space` units.
    ///
    /// Errors: shape mismatch, zero samples, non-finite data.
    pub fn mse(
        &self,
        inputs: &DMatrix<f64>,
        targets: &DMatrix<f64>,
        space: ErrorSpace,
    ) -> Result<f64> {
        check_training_data(self.architecture(), inputs, targets)?;
        let idx: Vec<usize> = (0..inputs.ncols()).collect();
        let part = Part::gather(self, inputs, targets, &idx);
        let mut ws = Workspace::new();
        ws.prepare(self.architecture());
        let rho = error_weights(self, space);
        Ok(part.sse(self, &rho, &mut ws) / (part.len() * self.n_outputs()) as f64)
    }
}

/// Split sample indices `0..n` into sorted (training, validation) lists.
///
/// Errors: a split that leaves either side empty.
pub fn split_indices(n: usize, split: &ValidationSplit) -> Result<(Vec<usize>, Vec<usize>)> {
    let fraction = match *split {
        ValidationSplit::None => return Ok(((0..n).collect(), Vec::new())),
        ValidationSplit::Random { fraction, .. } | ValidationSplit::Tail { fraction } => fraction,
    };
    let n_val = (fraction * n as f64).round() as usize;
    if n_val == 0 || n_val >= n {
        // Smallest n for which round(f·n) ≥ 1 and n − round(f·n) ≥ 1.
        let needed = 2usize
            .max((0.5 / fraction).ceil() as usize)
            .max((0.5 / (1.0 - fraction)).ceil() as usize);
        return Err(NnError::TooFewSamples {
            what: "validation split",
            found: n,
            needed,
        });
    }
    match *split {
        ValidationSplit::Random { seed, .. } => {
            let mut perm: Vec<usize> = (0..n).collect();
            perm.shuffle(&mut ChaCha8Rng::seed_from_u64(seed));
            let mut val = perm[..n_val].to_vec();
            let mut train = perm[n_val..].to_vec();
            val.sort_unstable();
            train.sort_unstable();
            Ok((train, val))
        }
        _ => Ok(((0..n - n_val).collect(), (n - n_val..n).collect())),
    }
}

/// Train `net` in place by Levenberg–Marquardt on `inputs` (`n × N`) and `targets`
/// (`q × N`), one sample per column. The network's scalers are used as they are (build
/// it with [`Mlp::for_data`] to fit them to the data).
///
/// Each epoch solves `(JᵀJ + cI + μD) δ = Jᵀe − c·w` by Cholesky, where `J = ∂y/∂w`
/// (rows `k·q + o`), `e = t − y`, `c = λ·N_train·q / n_w` carries the weight decay λ (it
/// makes the step minimise `MSE + λ·‖w‖²/n_w`) and `D` is `I` except for
/// [`Damping::NielsenMarquardt`]. A step is accepted if it lowers that objective; μ then
/// follows [`LmConfig::damping`] (default `trainlm`'s: μ ← μ·`mu_decrease` after an
/// accepted step, μ ← μ·`mu_increase` after a rejected one), and a rejected step is solved
/// again with the larger μ (a failed factorisation counts as a rejected step) until
/// μ > `mu_max`. With [`LmConfig::acceleration`] = [`crate::Acceleration::Geodesic`] the
/// trial point is `w + δ + a/2` with the geodesic correction `a` from the same
/// factorisation, and a step whose correction is too large counts as rejected. A trial
/// step's error sum stops as soon as a partial sum shows it cannot lower the objective
/// (the same decision as the full sum). Stopping is checked before
/// each epoch in this order: goal MSE, gradient norm, validation failures, epoch budget
/// (Hagan & Menhaj, IEEE TNN 1994; MATLAB `trainlm`).
///
/// Sums over samples run in parallel on rayon's pool over chunks fixed by the sample count,
/// added in a fixed order: the result is the same, bit for bit, for any number of threads.
///
/// With a validation split the returned network carries the weights of the epoch with
/// the lowest validation MSE (the first one on ties); otherwise the last weights.
/// `progress` is called after every epoch.
///
/// Errors: invalid config, shape mismatch, zero samples, non-finite data, a split that
/// leaves a side empty. On error `net` is unchanged.
pub fn train_lm(
    net: &mut Mlp,
    inputs: &DMatrix<f64>,
    targets: &DMatrix<f64>,
    config: &LmConfig,
    mut progress: Option<&mut dyn FnMut(EpochInfo)>,
) -> Result<TrainReport> {
    config.validate()?;
    check_training_data(net.architecture(), inputs, targets)?;
    let (train_idx, val_idx) = split_indices(inputs.ncols(), &config.validation)?;
    let train = Part::gather(net, inputs, targets, &train_idx);
    let val = (!val_idx.is_empty()).then(|| Part::gather(net, inputs, targets, &val_idx));

    let q = net.n_outputs();
    let nw = net.n_weights();
    let rho = error_weights(net, config.error_space);
    let m_train = (train.len() * q) as f64;
    let m_val = val.as_ref().map_or(1.0, |v| (v.len() * q) as f64);
    let decay = config.weight_decay * m_train / nw as f64;

    let mut lin = Linearisation::new(net, train.len(), Use::NormalEquations);
    let mut val_lin = val
        .as_ref()
        .map(|v| Linearisation::new(net, v.len(), Use::SseOnly));
    let mut rhs = DVector::zeros(nw);
    let mut w = DVector::from_column_slice(net.weights());

    // Objective scaled by m_train: SSE + c·‖w‖². `current` holds the activations at `w`
    // (the same bits as a build with its own forward pass), `kept` a trial's.
    let mut current = vec![0.0; lin.keep_len(net)];
    let mut kept = vec![0.0; lin.keep_len(net)];
    // Without a cutoff the sum always completes; `build` returns the same SSE.
    let _ = lin.sse(&train, net, &rho, Some(&mut current), None);
    let mut sse = lin.build(&train, net, &rho, Some(&current));
    let mut objective = sse + decay * w.norm_squared();
    let mut val_mse = |net: &Mlp| {
        val.as_ref()
            .zip(val_lin.as_mut())
            .and_then(|(v, l)| l.sse(v, net, &rho, None, None))
            .map(|sse| sse / m_val)
    };

    let mut train_history = vec![sse / m_train];
    let mut val_history = Vec::new();
    let mut best = (f64::INFINITY, w.clone(), 0);
    if let Some(v) = val_mse(net) {
        val_history.push(v);
        best = (v, w.clone(), 0);
    }
    let mut fails = 0;
    let mut mu = config.mu_initial;
    let mut epoch = 0;

    // Gradient of the objective MSE + λ‖w‖²/n_w: −(2/M)(Jᵀe − c·w).
    let gradient = |jte: &DVector<f64>, w: &DVector<f64>, rhs: &mut DVector<f64>| {
        rhs.copy_from(jte);
        rhs.axpy(-decay, w, 1.0);
        2.0 * rhs.norm() / m_train
    };
    let mut gradient_norm = gradient(&lin.jte, &w, &mut rhs);
    // The scaling D (identity, or for NielsenMarquardt the running maximum of diag(JᵀJ)
    // with zeros starting at 1, as MINPACK) and μ's schedule.
    let mut scale = DVector::from_element(nw, 1.0);
    let mut schedule = Schedule::new(config);
    let marquardt = config.damping == Damping::NielsenMarquardt;
    let geodesic = config.acceleration == Acceleration::Geodesic;
    let mut jt_rvv = DVector::zeros(if geodesic { nw } else { 0 });
    if marquardt {
        for (d, &jj) in scale.iter_mut().zip(lin.jtj.diagonal().iter()) {
            *d = if jj > 0.0 { jj } else { 1.0 };
        }
    }

    let termination = loop {
        if sse / m_train <= config.goal_mse {
            break StopReason::GoalReached;
        }
        if gradient_norm < config.min_gradient {
            break StopReason::MinGradient;
        }
        if fails >= config.max_fail {
            break StopReason::ValidationStop;
        }
        if epoch >= config.max_epochs {
            break StopReason::MaxEpochs;
        }
        // rhs already holds Jᵀe − c·w from the gradient evaluation.
        let mut accepted = None;
        while mu <= config.mu_max {
            let mut a = lin.jtj.clone();
            if marquardt {
                for i in 0..nw {
                    a[(i, i)] += decay + mu * scale[i];
                }
            } else {
                for i in 0..nw {
                    a[(i, i)] += decay + mu;
                }
            }
            if let Some(chol) = Cholesky::new(a) {
                let delta = chol.solve(&rhs);
                // The trial step: δ, or with geodesic acceleration δ + a/2 (None: the
                // correction is too large, a rejected step).
                let step = if geodesic && schedule.accelerates() {
                    net.weights_mut().copy_from_slice(w.as_slice());
                    if lin.curvature(&train, net, &rho, &current, delta.as_slice(), &mut jt_rvv) {
                        let acc = -chol.solve(&jt_rvv);
                        let norm = |x: &DVector<f64>| {
                            x.iter()
                                .zip(scale.iter())
                                .map(|(xi, s)| xi * xi * s)
                                .sum::<f64>()
                                .sqrt()
                        };
                        (2.0 * norm(&acc) <= GEODESIC_ALPHA * norm(&delta))
                            .then(|| &delta + 0.5 * acc)
                    } else {
                        Some(delta.clone())
                    }
                } else {
                    Some(delta.clone())
                };
                if let Some(step) = step.filter(|d| d.iter().all(|d| d.is_finite())) {
                    let trial = &w + &step;
                    net.weights_mut().copy_from_slice(trial.as_slice());
                    // A step that cannot lower the objective is rejected as soon as a
                    // partial sum shows it (the same decision as the full sum).
                    let cutoff = Cutoff {
                        offset: decay * trial.norm_squared(),
                        limit: objective,
                    };
                    let trial_obj = lin
                        .sse(&train, net, &rho, Some(&mut kept), Some(cutoff))
                        .map(|sse| sse + cutoff.offset);
                    if let Some(trial_obj) = trial_obj.filter(|&o| o < objective) {
                        let gain = if schedule.uses_gain() {
                            // Decrease predicted by the linear model,
                            // L(0) − L(δ) = δᵀ(Jᵀe − c·w) + μ·δᵀDδ (> 0).
                            let predicted = delta.dot(&rhs)
                                + mu * delta
                                    .iter()
                                    .zip(scale.iter())
                                    .map(|(d, s)| d * d * s)
                                    .sum::<f64>();
                            (objective - trial_obj) / predicted
                        } else {
                            f64::NAN
                        };
                        mu = schedule.accepted(mu, gain);
                        accepted = Some((trial, trial_obj));
                        break;
                    }
                }
            }
            mu = schedule.rejected(mu);
        }
        let Some((trial, trial_obj)) = accepted else {
            net.weights_mut().copy_from_slice(w.as_slice());
            break StopReason::MuMax;
        };
        epoch += 1;
        w = trial;
        objective = trial_obj;
        net.weights_mut().copy_from_slice(w.as_slice());
        // `kept` holds the accepted trial's activations: the forward pass is not repeated.
        std::mem::swap(&mut current, &mut kept);
        sse = lin.build(&train, net, &rho, Some(&current));
        gradient_norm = gradient(&lin.jte, &w, &mut rhs);
        if marquardt {
            for (d, &jj) in scale.iter_mut().zip(lin.jtj.diagonal().iter()) {
                *d = d.max(jj);
            }
        }
        train_history.push(sse / m_train);
        let v = val_mse(net);
        if let Some(v) = v {
            val_history.push(v);
            if v < best.0 {
                best = (v, w.clone(), epoch);
                fails = 0;
            } else if v > best.0 {
                fails += 1;
            }
        }
        if let Some(cb) = progress.as_mut() {
            cb(EpochInfo {
                epoch,
                train_mse: sse / m_train,
                val_mse: v,
                mu,
                gradient_norm,
            });
        }
    };

    let (best_epoch, val_best) = if val.is_some() {
        net.weights_mut().copy_from_slice(best.1.as_slice());
        (best.2, Some(best.0))
    } else {
        (epoch, None)
    };
    Ok(TrainReport {
        termination,
        epochs: epoch,
        best_epoch,
        train_mse: train_history[best_epoch],
        val_mse: val_best,
        train_history,
        val_history,
        mu,
        gradient_norm,
        n_train: train.len(),
        n_val: val_idx.len(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn split_sizes_and_disjointness() {
        let (tr, va) = split_indices(
            20,
            &ValidationSplit::Random {
                fraction: 0.25,
                seed: 9,
            },
        )
        .unwrap();
        assert_eq!((tr.len(), va.len()), (15, 5));
        let mut all: Vec<usize> = tr.iter().chain(&va).copied().collect();
        all.sort_unstable();
        assert_eq!(all, (0..20).collect::<Vec<_>>());
        let (tr, va) = split_indices(10, &ValidationSplit::Tail { fraction: 0.3 }).unwrap();
        assert_eq!(tr, (0..7).collect::<Vec<_>>());
        assert_eq!(va, vec![7, 8, 9]);
        // round(0.15·3) = 0 validation samples: the smallest workable N is 4 (round(0.6) = 1).
        assert_eq!(
            split_indices(
                3,
                &ValidationSplit::Random {
                    fraction: 0.15,
                    seed: 0
                }
            )
            .unwrap_err(),
            NnError::TooFewSamples {
                what: "validation split",
                found: 3,
                needed: 4
            }
        );
    }
}
