//! Levenberg–Marquardt training of an [`Mlp`] (MATLAB `trainlm`-style): damped
//! Gauss–Newton steps `(JᵀJ + μI) δ = Jᵀe` solved by Cholesky (with `JᵀJ` and `Jᵀe`
//! accumulated over cache-sized blocks of samples, never forming `J`), μ adaptation,
//! early stopping on a validation split, optional weight decay, and the [`TrainReport`].

use nalgebra::storage::Storage;
use nalgebra::{Cholesky, DMatrix, DMatrixView, DMatrixViewMut, DVector, DVectorView, Dyn, Matrix};
use rand::SeedableRng;
use rand::rngs::ChaCha8Rng;
use rand::seq::SliceRandom;
use serde::{Deserialize, Serialize};

use crate::config::{ErrorSpace, LmConfig, ValidationSplit};
use crate::error::{NnError, Result};
use crate::mlp::{Mlp, Workspace, check_training_data};

/// μ never drops below this: far below any useful damping, it only stops μ from
/// underflowing after long runs of accepted steps.
const MU_FLOOR: f64 = 1e-20;

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

/// Samples of one part (training or validation), in scaled units.
struct Part {
    x: DMatrix<f64>,
    t: DMatrix<f64>,
}

impl Part {
    fn gather(net: &Mlp, inputs: &DMatrix<f64>, targets: &DMatrix<f64>, idx: &[usize]) -> Self {
        let mut x = DMatrix::zeros(inputs.nrows(), idx.len());
        let mut t = DMatrix::zeros(targets.nrows(), idx.len());
        for (c, &k) in idx.iter().enumerate() {
            net.input_scaler()
                .scale_into(inputs.column(k).as_slice(), x.column_mut(c).as_mut_slice());
            net.output_scaler()
                .scale_into(targets.column(k).as_slice(), t.column_mut(c).as_mut_slice());
        }
        Self { x, t }
    }

    fn len(&self) -> usize {
        self.x.ncols()
    }

    /// Sum of squared errors `Σ (ρ_o·(t̂ − ŷ))²` over the part.
    fn sse(&self, net: &Mlp, rho: &[f64], ws: &mut Workspace) -> f64 {
        self.sse_keeping(net, rho, ws, &mut [])
    }

    /// [`Part::sse`], also keeping every sample's activations in `keep` (sample `k` at
    /// `k·A..(k+1)·A`, `A` = activations per sample) when it is long enough, so that
    /// [`Part::normal_equations`] at the same weights can skip the forward pass.
    fn sse_keeping(&self, net: &Mlp, rho: &[f64], ws: &mut Workspace, keep: &mut [f64]) -> f64 {
        let n = net.n_inputs();
        let out = net.output_range();
        let a = out.end;
        let keeping = keep.len() >= a * self.len();
        let mut sse = 0.0;
        for (k, (x, t)) in self.x.column_iter().zip(self.t.column_iter()).enumerate() {
            ws.acts[..n].copy_from_slice(x.as_slice());
            net.forward_scaled(ws);
            for ((&y, &t), &r) in ws.acts[out.clone()].iter().zip(t.iter()).zip(rho) {
                let e = r * (t - y);
                sse += e * e;
            }
            if keeping {
                keep[k * a..(k + 1) * a].copy_from_slice(&ws.acts[..a]);
            }
        }
        sse
    }

    /// Normal equations of the linearised problem, without forming the full Jacobian:
    /// `jtj = JᵀJ` and `jte = Jᵀe` (with `J = ∂y/∂w`, rows `k·q + o`, and `e = t − y`),
    /// accumulated over blocks of [`BLOCK`] samples whose Jacobian rows fit in cache;
    /// returns the SSE. Blocks are visited in order, so the sums are deterministic.
    ///
    /// With `kept` (activations from [`Part::sse_keeping`] at the same weights) the forward
    /// pass is skipped; the numbers are identical either way.
    fn normal_equations(
        &self,
        net: &Mlp,
        rho: &[f64],
        ws: &mut Workspace,
        lin: &mut Linearisation,
        kept: Option<&[f64]>,
    ) -> f64 {
        let n = net.n_inputs();
        let q = net.n_outputs();
        let out = net.output_range();
        let a = out.end;
        let nw = net.n_weights();
        // One hidden layer (the thesis networks): Jacobian rows in closed form, written
        // row-major so each sample's row is contiguous; otherwise back-propagation.
        let single = net.hidden().len() == 1;
        let mut sse = 0.0;
        lin.jtj.fill(0.0);
        lin.jte.fill(0.0);
        let len = self.len();
        let mut k0 = 0;
        while k0 < len {
            let kb = BLOCK.min(len - k0);
            for k in 0..kb {
                let (x, t) = (self.x.column(k0 + k), self.t.column(k0 + k));
                match kept {
                    Some(acts) => {
                        ws.acts[..a].copy_from_slice(&acts[(k0 + k) * a..(k0 + k + 1) * a]);
                    }
                    None => {
                        ws.acts[..n].copy_from_slice(x.as_slice());
                        net.forward_scaled(ws);
                    }
                }
                for (o, ((&y, &t), &r)) in ws.acts[out.clone()]
                    .iter()
                    .zip(t.iter())
                    .zip(rho)
                    .enumerate()
                {
                    let ek = r * (t - y);
                    lin.e_block[k * q + o] = ek;
                    sse += ek * ek;
                }
                if single {
                    let rows = &mut lin.row_major[k * q * nw..(k + 1) * q * nw];
                    single_layer_rows(net, &ws.acts[..a], rho, rows);
                } else {
                    net.weight_rows_scaled(ws, rho, &mut lin.j_block, k * q);
                }
            }
            let rows = kb * q;
            let eb = lin.e_block.rows(0, rows);
            // The block as J (rows × n_w, column-major) and Jᵀ (n_w × rows, column-major):
            // one of them was filled, the other is its transpose (rows·n_w copies, against
            // rows·n_w² flops of the product). Both are plain column-major views, which every
            // nalgebra kernel handles.
            let jt_buf = &mut lin.row_major[..rows * nw];
            if single {
                DMatrixView::from_slice(jt_buf, nw, rows)
                    .transpose_to(&mut lin.j_block.rows_mut(0, rows));
            } else {
                lin.j_block
                    .rows(0, rows)
                    .transpose_to(&mut DMatrixViewMut::from_slice(jt_buf, nw, rows));
            }
            let jt = DMatrixView::from_slice(&lin.row_major[..rows * nw], nw, rows);
            accumulate(
                &mut lin.jtj,
                &mut lin.jte,
                &jt,
                &lin.j_block.rows(0, rows),
                &eb,
            );
            k0 += kb;
        }
        lin.jtj.fill_lower_triangle_with_upper_triangle();
        sse
    }
}

/// The Jacobian rows `ρ_o·∂ŷ_o/∂w` (`o = 0..q`, row-major, `q × n_w`) of a network with one
/// hidden layer, from its activations `acts = [s; a; ŷ]` (scaled input, hidden outputs,
/// scaled output): for hidden unit `i`, `g = ρ_o·v_{o,i}·(1 − a_i²)` gives `g·s_j` and `g`
/// (bias); output unit `o` gets `ρ_o·a_i` and `ρ_o`, the other output units 0. The same
/// numbers back-propagation gives, without its loops over layers.
fn single_layer_rows(net: &Mlp, acts: &[f64], rho: &[f64], rows: &mut [f64]) {
    let n = net.n_inputs();
    let h = net.hidden()[0];
    let nw = net.n_weights();
    let (s, hid) = (&acts[..n], &acts[n..n + h]);
    let out_offset = h * (n + 1);
    let w = net.weights();
    for (o, (row, &r)) in rows.chunks_exact_mut(nw).zip(rho).enumerate() {
        let v = &w[out_offset + o * (h + 1)..out_offset + o * (h + 1) + h];
        let (hidden_part, out_part) = row.split_at_mut(out_offset);
        for ((unit, &vi), &ai) in hidden_part.chunks_exact_mut(n + 1).zip(v).zip(hid) {
            let g = r * vi * (1.0 - ai * ai);
            for (u, &sj) in unit.iter_mut().zip(s) {
                *u = g * sj;
            }
            unit[n] = g;
        }
        for (u, unit) in out_part.chunks_exact_mut(h + 1).enumerate() {
            if u == o {
                for (x, &ai) in unit.iter_mut().zip(hid) {
                    *x = r * ai;
                }
                unit[h] = r;
            } else {
                unit.fill(0.0);
            }
        }
    }
}

/// `jtj += JᵀJ` (upper triangle only, by column panels:
/// `JᵀJ[0..c1, c0..c1] += Jᵀ[0..c1, :]·J[:, c0..c1]`) and `jte += Jᵀe` for one block, given
/// column-major views of `Jᵀ` and `J`. Plain `gemm` (not `gemm_tr`, which nalgebra evaluates as one
/// matrix–vector product per column) so that the blocked `matrixmultiply` kernel runs.
fn accumulate<S1, S2>(
    jtj: &mut DMatrix<f64>,
    jte: &mut DVector<f64>,
    jt: &Matrix<f64, Dyn, Dyn, S1>,
    j: &Matrix<f64, Dyn, Dyn, S2>,
    eb: &DVectorView<'_, f64>,
) where
    S1: Storage<f64, Dyn, Dyn>,
    S2: Storage<f64, Dyn, Dyn>,
{
    let nw = j.ncols();
    let mut c0 = 0;
    while c0 < nw {
        let c1 = (c0 + PANEL).min(nw);
        jtj.view_mut((0, c0), (c1, c1 - c0)).gemm(
            1.0,
            &jt.rows(0, c1),
            &j.columns(c0, c1 - c0),
            1.0,
        );
        c0 = c1;
    }
    jte.gemv(1.0, jt, eb, 1.0);
}

/// Samples per block of Jacobian rows in [`Part::normal_equations`]: 128 rows of up to
/// ~100 weights stay in L2 cache.
const BLOCK: usize = 128;

/// Column panel width of the upper-triangular `JᵀJ` accumulation: for 51 weights two
/// panels do 77 % of the full product's flops while each stays large enough for the
/// blocked kernel (16 and 32 measured equally fast).
const PANEL: usize = 32;

/// Buffers of the linearisation: one block of Jacobian rows and residuals, and the normal
/// equations.
struct Linearisation {
    j_block: DMatrix<f64>,
    row_major: Vec<f64>,
    e_block: DVector<f64>,
    jtj: DMatrix<f64>,
    jte: DVector<f64>,
}

impl Linearisation {
    fn new(q: usize, nw: usize) -> Self {
        Self {
            j_block: DMatrix::zeros(BLOCK * q, nw),
            row_major: vec![0.0; BLOCK * q * nw],
            e_block: DVector::zeros(BLOCK * q),
            jtj: DMatrix::zeros(nw, nw),
            jte: DVector::zeros(nw),
        }
    }
}

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
/// Each epoch solves `(JᵀJ + (c + μ)I) δ = Jᵀe − c·w` by Cholesky, where `J = ∂y/∂w`
/// (rows `k·q + o`), `e = t − y` and `c = λ·N_train·q / n_w` carries the weight decay λ
/// (it makes the step minimise `MSE + λ·‖w‖²/n_w`). A step is accepted if it lowers that
/// objective; then μ ← μ·`mu_decrease`, else μ ← μ·`mu_increase` and the solve is
/// repeated (a failed factorisation counts as a rejected step) until μ > `mu_max`.
/// Stopping is checked before each epoch in this order: goal MSE, gradient norm,
/// validation failures, epoch budget (Hagan & Menhaj, IEEE TNN 1994; MATLAB `trainlm`).
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

    let mut ws = Workspace::new();
    ws.prepare(net.architecture());
    let mut lin = Linearisation::new(q, nw);
    let mut rhs = DVector::zeros(nw);
    let mut w = DVector::from_column_slice(net.weights());

    // Objective scaled by m_train: SSE + c·‖w‖².
    let mut sse = train.normal_equations(net, &rho, &mut ws, &mut lin, None);
    let mut kept = vec![0.0; train.len() * net.output_range().end];
    let mut objective = sse + decay * w.norm_squared();
    let val_mse =
        |net: &Mlp, ws: &mut Workspace| val.as_ref().map(|v| v.sse(net, &rho, ws) / m_val);

    let mut train_history = vec![sse / m_train];
    let mut val_history = Vec::new();
    let mut best = (f64::INFINITY, w.clone(), 0);
    if let Some(v) = val_mse(net, &mut ws) {
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
            for i in 0..nw {
                a[(i, i)] += decay + mu;
            }
            if let Some(chol) = Cholesky::new(a) {
                let delta = chol.solve(&rhs);
                if delta.iter().all(|d| d.is_finite()) {
                    let trial = &w + &delta;
                    net.weights_mut().copy_from_slice(trial.as_slice());
                    let trial_sse = train.sse_keeping(net, &rho, &mut ws, &mut kept);
                    let trial_obj = trial_sse + decay * trial.norm_squared();
                    if trial_obj < objective {
                        accepted = Some((trial, trial_obj));
                        mu = (mu * config.mu_decrease).max(MU_FLOOR);
                        break;
                    }
                }
            }
            mu *= config.mu_increase;
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
        sse = train.normal_equations(net, &rho, &mut ws, &mut lin, Some(&kept));
        gradient_norm = gradient(&lin.jte, &w, &mut rhs);
        train_history.push(sse / m_train);
        let v = val_mse(net, &mut ws);
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
    fn blocked_normal_equations_match_the_full_jacobian() {
        // One hidden layer (closed-form rows) and two (back-propagation), two outputs, a
        // sample count that leaves a partial last block: JᵀJ and Jᵀe against the products
        // of the full Jacobian from `weight_jacobian`, to round-off of sums of ~300 terms.
        use crate::mlp::Architecture;
        for hidden in [vec![5], vec![4, 3]] {
            let arch = Architecture {
                inputs: 3,
                hidden,
                outputs: 2,
            };
            let n_samples = BLOCK * 2 + 37;
            let x = DMatrix::from_fn(3, n_samples, |i, k| {
                ((i * 7 + k * 13) % 17) as f64 / 8.0 - 1.0
            });
            let t = DMatrix::from_fn(2, n_samples, |o, k| {
                (x[(0, k)] + o as f64 * x[(2, k)]).sin()
            });
            let net = Mlp::new(&arch, 3).unwrap();
            let rho = [1.5, 0.5];
            let net = net
                .with_scalers(
                    crate::scaling::Scaler::identity(3),
                    crate::scaling::Scaler::new(vec![0.0, 0.0], rho.to_vec()).unwrap(),
                )
                .unwrap();
            let idx: Vec<usize> = (0..n_samples).collect();
            let part = Part::gather(&net, &x, &t, &idx);
            let mut ws = Workspace::new();
            ws.prepare(net.architecture());
            let mut lin = Linearisation::new(2, net.n_weights());
            let sse = part.normal_equations(&net, &rho, &mut ws, &mut lin, None);
            let jac = net.weight_jacobian(&x).unwrap();
            let y = net.predict(&x).unwrap();
            let e = DVector::from_iterator(n_samples * 2, (&t - &y).iter().copied());
            let jtj = jac.transpose() * &jac;
            let jte = jac.transpose() * &e;
            let scale = jtj.amax();
            assert!((&lin.jtj - &jtj).amax() < 1e-12 * scale);
            assert!((&lin.jte - &jte).amax() < 1e-12 * scale.max(jte.amax()));
            assert!((sse - e.norm_squared()).abs() < 1e-12 * sse);
        }
    }

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
