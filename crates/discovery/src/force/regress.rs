//! The proposal of force-space discovery: per joint, forward selection of the joint's own
//! candidate forces on `τ̂_j` by least squares (see the parent module).

use nalgebra::{DMatrix, DVector};
use sysid_core::{Dataset, Expr, MmeEstimate, PhysicalModel, term_variables};

use super::{ForceCandidate, ForceConfig, column};
use crate::error::DiscoveryError;

/// One proposed force of a joint.
#[derive(Debug, Clone, PartialEq)]
pub struct ProposedForce {
    /// Index into the candidates.
    pub candidate: usize,
    /// Least-squares coefficient on `τ̂_j` with the joint's other proposed forces.
    pub coefficient: f64,
    /// Share of `Σ τ̂_j²` its column removed when it entered.
    pub share: f64,
}

/// What the forward selection proposed for one joint.
#[derive(Debug, Clone, PartialEq)]
pub struct JointProposal {
    /// Joint index.
    pub joint: usize,
    /// Its rate state.
    pub state: String,
    /// The proposed forces, in order of entry.
    pub selected: Vec<ProposedForce>,
    /// Share of `Σ τ̂_j²` the proposed forces leave.
    pub remaining_share: f64,
}

/// Residual sum of squares of `y` on the columns `set` (Gram `g`, `b = Xᵀy`, `yy = yᵀy`)
/// and the coefficients; `None` when the columns are (numerically) dependent.
fn least_squares(
    g: &DMatrix<f64>,
    b: &DVector<f64>,
    yy: f64,
    set: &[usize],
) -> Option<(f64, DVector<f64>)> {
    let gs = DMatrix::from_fn(set.len(), set.len(), |i, j| g[(set[i], set[j])]);
    let bs = DVector::from_fn(set.len(), |i, _| b[set[i]]);
    let chol = gs.cholesky()?;
    let diag_min = (0..set.len())
        .map(|i| chol.l()[(i, i)].powi(2) / g[(set[i], set[i])].max(f64::MIN_POSITIVE))
        .fold(f64::INFINITY, f64::min);
    // A column that adds less than 1e-10 of its own norm is a copy of the others.
    if diag_min < 1e-10 {
        return None;
    }
    let beta = chol.solve(&bs);
    Some((yy - bs.dot(&beta), beta))
}

/// Forward selection on every joint's `τ̂_j` (`taus`: per record, joints × samples) among
/// its candidates; also the RMS of `τ̂_j` over the trimmed samples.
pub fn propose_forces(
    model: &PhysicalModel,
    estimate: &MmeEstimate,
    data: &Dataset,
    taus: &[DMatrix<f64>],
    candidates: &[ForceCandidate],
    config: &ForceConfig,
) -> crate::Result<(Vec<JointProposal>, Vec<f64>)> {
    if !(0.0..0.5).contains(&config.trim_fraction) {
        return Err(DiscoveryError::InvalidConfig {
            field: "trim_fraction",
            value: config.trim_fraction,
            reason: "must be in [0, 0.5)",
        });
    }
    let Some((_, rates)) = model.mechanics_states() else {
        return Ok((Vec::new(), Vec::new()));
    };
    let names = model.linear().state_names();
    let variables = term_variables(model.linear());
    let mut proposals = Vec::with_capacity(rates.len());
    let mut rms = Vec::with_capacity(rates.len());
    let mut col = Vec::new();
    for (j, &v) in rates.iter().enumerate() {
        let mine: Vec<usize> = (0..candidates.len())
            .filter(|&c| candidates[c].joint == j)
            .collect();
        // Trimmed samples of every record: y = τ̂_j, X = the candidates' columns.
        let mut y = Vec::new();
        let mut x: Vec<Vec<f64>> = vec![Vec::new(); mine.len()];
        let exprs = mine
            .iter()
            .map(|&c| {
                Expr::parse(&candidates[c].term, &variables).map_err(|source| {
                    DiscoveryError::Expression {
                        effect: candidates[c].effect.name(),
                        equation: candidates[c].state.clone(),
                        text: candidates[c].term.clone(),
                        source,
                    }
                })
            })
            .collect::<crate::Result<Vec<_>>>()?;
        for ((est, exp), tau) in estimate
            .experiments
            .iter()
            .zip(data.experiments())
            .zip(taus)
        {
            let n = est.len();
            let cut = (config.trim_fraction * n as f64).floor() as usize;
            let range = cut..n.saturating_sub(cut);
            y.extend(range.clone().map(|k| tau[(j, k)]));
            for (xs, e) in x.iter_mut().zip(&exprs) {
                column(e, &est.states, exp, &mut col);
                xs.extend(col[range.clone()].iter().copied());
            }
        }
        let m = y.len();
        let yy: f64 = y.iter().map(|v| v * v).sum();
        rms.push((yy / m.max(1) as f64).sqrt());
        let p = mine.len();
        let g = DMatrix::from_fn(p, p, |a, b| {
            x[a].iter().zip(&x[b]).map(|(s, t)| s * t).sum()
        });
        let bvec = DVector::from_fn(p, |a, _| x[a].iter().zip(&y).map(|(s, t)| s * t).sum());
        let mut set: Vec<usize> = Vec::new();
        let mut shares = Vec::new();
        let mut rss = yy;
        while set.len() < config.max_terms_per_joint && yy > 0.0 {
            let best = (0..p)
                .filter(|c| !set.contains(c))
                .filter_map(|c| {
                    let mut trial = set.clone();
                    trial.push(c);
                    least_squares(&g, &bvec, yy, &trial).map(|(r, _)| (c, r))
                })
                .min_by(|a, b| a.1.total_cmp(&b.1));
            let Some((c, r)) = best else { break };
            let share = (rss - r) / yy;
            if share < config.min_share || !share.is_finite() {
                break;
            }
            set.push(c);
            shares.push(share);
            rss = r;
        }
        let beta = least_squares(&g, &bvec, yy, &set)
            .map(|(_, b)| b)
            .unwrap_or_else(|| DVector::zeros(set.len()));
        proposals.push(JointProposal {
            joint: j,
            state: names[v].clone(),
            selected: set
                .iter()
                .zip(&shares)
                .enumerate()
                .map(|(i, (&c, &share))| ProposedForce {
                    candidate: mine[c],
                    coefficient: beta[i],
                    share,
                })
                .collect(),
            remaining_share: if yy > 0.0 { rss / yy } else { 0.0 },
        });
    }
    Ok((proposals, rms))
}
