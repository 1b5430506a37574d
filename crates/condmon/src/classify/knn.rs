//! k-nearest-neighbour classification: a linfa-nn index finds candidates, then our own
//! Euclidean distances define the neighbour set (ties at the k-th distance included) and
//! a majority vote with a nearest-neighbour tie rule picks the class.

use linfa_nn::distance::L2Dist;
use linfa_nn::{CommonNearestNeighbour, NearestNeighbour};
use nalgebra::DMatrix;
use ndarray::{Array2, ArrayView1};
use serde::{Deserialize, Serialize};

use super::{Classifier, ClassifierModel, Predictions, ScoreKind};
use crate::data::{check_labelled, check_query, to_array2};
use crate::error::{CondmonError, Result};

/// Feature dimension up to which a k-d tree is used for the candidate search; above it a
/// linear scan (k-d trees lose their advantage in high dimensions). The result does not
/// depend on the index: the neighbour set is defined by exact distances (see
/// [`KnnModel`]).
pub const KD_TREE_MAX_DIM: usize = 8;

/// Relative widening of the range query that collects every training point tied with the
/// k-th nearest one (the index computes distances in its own order, so a tie may differ by
/// a few ulps there; 1e-9 covers that with a wide margin).
const RANGE_WIDENING: f64 = 1e-9;

/// k-NN settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct KnnConfig {
    /// Number of neighbours (default 5). Must not exceed the training set size.
    pub k: usize,
}

impl Default for KnnConfig {
    fn default() -> Self {
        Self { k: 5 }
    }
}

impl Classifier for KnnConfig {
    type Model = KnnModel;

    /// Errors: `k = 0`, bad data, `k` larger than the number of training samples.
    fn fit(&self, x: &DMatrix<f64>, labels: &[usize]) -> Result<KnnModel> {
        if self.k == 0 {
            return Err(CondmonError::InvalidConfig {
                field: "KnnConfig::k",
                value: 0.0,
                reason: "k must be at least 1",
            });
        }
        let classes = check_labelled(x, labels)?;
        if self.k > x.nrows() {
            return Err(CondmonError::TooFewSamples {
                what: "k-NN training samples (k)",
                found: x.nrows(),
                needed: self.k,
            });
        }
        let class_index = labels
            .iter()
            .map(|l| classes.binary_search(l).unwrap_or(0))
            .collect();
        Ok(KnnModel {
            k: self.k,
            train: to_array2(x),
            class_index,
            classes,
        })
    }
}

/// A fitted k-NN model (the stored training set).
///
/// **Neighbour set.** For a query point, let `d_k` be the k-th smallest Euclidean distance
/// to the training points. The neighbour set is every training point at distance ≤ `d_k`,
/// so it has k members unless several points tie at `d_k` (duplicated training points are
/// common with converged network weights); then all tied points vote. The set does not
/// depend on the search structure or on training-set order.
///
/// **Vote.** Each neighbour gives one vote; scores are vote shares. The class with most
/// votes wins. **Tie rule:** among the classes tied for most votes, the one owning the
/// nearest neighbour in the set wins; if that distance ties too, the lowest class label.
#[derive(Debug, Clone, PartialEq)]
pub struct KnnModel {
    k: usize,
    train: Array2<f64>,
    /// Position in `classes` of each training row's label.
    class_index: Vec<usize>,
    classes: Vec<usize>,
}

impl KnnModel {
    /// Number of neighbours.
    pub fn k(&self) -> usize {
        self.k
    }

    fn sq_dist(&self, row: usize, q: &[f64]) -> f64 {
        self.train
            .row(row)
            .iter()
            .zip(q)
            .map(|(a, b)| (a - b) * (a - b))
            .sum()
    }
}

impl ClassifierModel for KnnModel {
    fn classes(&self) -> &[usize] {
        &self.classes
    }
    fn n_features(&self) -> usize {
        self.train.ncols()
    }

    fn predict(&self, x: &DMatrix<f64>) -> Result<Predictions> {
        check_query("k-NN test features", x, self.n_features())?;
        let algorithm = if self.n_features() <= KD_TREE_MAX_DIM {
            CommonNearestNeighbour::KdTree
        } else {
            CommonNearestNeighbour::LinearSearch
        };
        let index = algorithm.from_batch(&self.train, L2Dist)?;
        let n_classes = self.classes.len();
        let mut scores = DMatrix::zeros(x.nrows(), n_classes);
        let mut labels = Vec::with_capacity(x.nrows());
        let mut q = vec![0.0; x.ncols()];
        let mut cand: Vec<(f64, usize)> = Vec::new();
        for i in 0..x.nrows() {
            for (j, v) in q.iter_mut().enumerate() {
                *v = x[(i, j)];
            }
            let query = ArrayView1::from(&q[..]);
            // Candidates: the index's k nearest, then everything within their radius.
            let nearest = index.k_nearest(query, self.k)?;
            let radius = nearest
                .iter()
                .map(|(_, r)| self.sq_dist(*r, &q))
                .fold(0.0, f64::max)
                .sqrt();
            let widened = radius * (1.0 + RANGE_WIDENING) + 1e-150;
            cand.clear();
            cand.extend(nearest.iter().map(|(_, r)| (self.sq_dist(*r, &q), *r)));
            for (_, r) in index.within_range(query, widened)? {
                cand.push((self.sq_dist(r, &q), r));
            }
            cand.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
            cand.dedup_by_key(|c| c.1);
            let Some(&(dk, _)) = cand.get(self.k - 1) else {
                return Err(CondmonError::TooFewSamples {
                    what: "k-NN neighbours found",
                    found: cand.len(),
                    needed: self.k,
                });
            };
            let mut votes = vec![0usize; n_classes];
            let mut closest = vec![f64::INFINITY; n_classes];
            let mut members = 0usize;
            for &(d, r) in cand.iter().take_while(|c| c.0 <= dk) {
                let c = self.class_index[r];
                votes[c] += 1;
                closest[c] = closest[c].min(d);
                members += 1;
            }
            let mut best = 0;
            for c in 1..n_classes {
                if votes[c] > votes[best] || (votes[c] == votes[best] && closest[c] < closest[best])
                {
                    best = c;
                }
            }
            for (c, v) in votes.iter().enumerate() {
                scores[(i, c)] = *v as f64 / members as f64;
            }
            labels.push(self.classes[best]);
        }
        Ok(Predictions {
            classes: self.classes.clone(),
            labels,
            scores,
            kind: ScoreKind::VoteShare,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn col(v: &[f64]) -> DMatrix<f64> {
        DMatrix::from_column_slice(v.len(), 1, v)
    }

    #[test]
    fn majority_vote_and_tie_rule() {
        // Training: class 0 at 0, 1; class 1 at 3, 4, 5.
        let m = KnnConfig { k: 3 }
            .fit(&col(&[0.0, 1.0, 3.0, 4.0, 5.0]), &[0, 0, 1, 1, 1])
            .unwrap();
        // Query 1.2: neighbours 1 (0.2), 0 (1.2), 3 (1.8) → 2 votes class 0.
        // Query 2.9: neighbours 3, 4, 1 → 2 votes class 1.
        let p = m.predict(&col(&[1.2, 2.9])).unwrap();
        assert_eq!(p.labels, vec![0, 1]);
        assert!((p.scores[(0, 0)] - 2.0 / 3.0).abs() < 1e-15);

        // k = 2 vote tie: query 1.9 has neighbours 1 (0.9, class 0) and 3 (1.1, class 1) →
        // tie → the nearest neighbour's class, 0. Query 2.1 → class 1.
        let m = KnnConfig { k: 2 }
            .fit(&col(&[0.0, 1.0, 3.0, 4.0, 5.0]), &[0, 0, 1, 1, 1])
            .unwrap();
        assert_eq!(m.predict(&col(&[1.9, 2.1])).unwrap().labels, vec![0, 1]);
        // Exactly midway (2.0): equal votes and equal nearest distance → lowest label.
        assert_eq!(m.predict(&col(&[2.0])).unwrap().labels, vec![0]);
    }

    #[test]
    fn ties_at_kth_distance_all_vote() {
        // k = 1 but three training points coincide at distance 1 from the query 0:
        // two of class 5 at +1 and one of class 2 at −1 → neighbour set of 3, class 5 wins.
        let m = KnnConfig { k: 1 }
            .fit(&col(&[1.0, 1.0, -1.0, 10.0]), &[5, 5, 2, 2])
            .unwrap();
        let p = m.predict(&col(&[0.0])).unwrap();
        assert_eq!(p.labels, vec![5]);
        assert!((p.scores[(0, 1)] - 2.0 / 3.0).abs() < 1e-15);
        assert!((p.scores[(0, 0)] - 1.0 / 3.0).abs() < 1e-15);
    }

    #[test]
    fn bad_k() {
        let x = col(&[0.0, 1.0]);
        assert!(matches!(
            KnnConfig { k: 0 }.fit(&x, &[0, 1]),
            Err(CondmonError::InvalidConfig { .. })
        ));
        assert!(matches!(
            KnnConfig { k: 3 }.fit(&x, &[0, 1]),
            Err(CondmonError::TooFewSamples {
                found: 2,
                needed: 3,
                ..
            })
        ));
    }
}
