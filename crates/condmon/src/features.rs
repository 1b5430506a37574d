//! Feature vectors from trained models: raw network weights (the thesis's features),
//! canonicalised weights (tanh sign and hidden-unit permutation symmetries removed), named
//! physical coefficients, and stacking of per-model vectors into a feature matrix.
//!
//! Weights act on the network's *scaled* inputs and outputs; the scalers are not part of
//! the features (each network's scalers are fitted to its own training data).

use nalgebra::DMatrix;
use nn::Mlp;
use serde::{Deserialize, Serialize};

use crate::error::{CondmonError, Result};

/// One model's feature vector with a name per entry.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NamedFeatures {
    names: Vec<String>,
    values: Vec<f64>,
}

impl NamedFeatures {
    /// Feature names, in order.
    pub fn names(&self) -> &[String] {
        &self.names
    }

    /// Feature values, in order.
    pub fn values(&self) -> &[f64] {
        &self.values
    }

    /// Number of features.
    pub fn len(&self) -> usize {
        self.values.len()
    }

    /// True when there are no features.
    pub fn is_empty(&self) -> bool {
        self.values.is_empty()
    }

    /// This vector followed by `other` (e.g. canonical weights, then physical
    /// coefficients).
    pub fn concat(&self, other: &NamedFeatures) -> NamedFeatures {
        NamedFeatures {
            names: self.names.iter().chain(&other.names).cloned().collect(),
            values: self.values.iter().chain(&other.values).copied().collect(),
        }
    }
}

/// Feature vectors of several models stacked as rows (`n_models × n_features`), with the
/// shared feature names.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FeatureMatrix {
    names: Vec<String>,
    values: DMatrix<f64>,
}

impl FeatureMatrix {
    /// Feature (column) names.
    pub fn names(&self) -> &[String] {
        &self.names
    }

    /// The matrix, rows = models (samples), columns = features.
    pub fn values(&self) -> &DMatrix<f64> {
        &self.values
    }

    /// Split into names and matrix.
    pub fn into_parts(self) -> (Vec<String>, DMatrix<f64>) {
        (self.names, self.values)
    }
}

/// Stack per-model feature vectors as rows. All must carry the same names in the same
/// order.
///
/// Errors: no samples, a vector of different length or with a different name.
pub fn stack(samples: &[NamedFeatures]) -> Result<FeatureMatrix> {
    let Some(first) = samples.first() else {
        return Err(CondmonError::TooFewSamples {
            what: "feature vectors to stack",
            found: 0,
            needed: 1,
        });
    };
    let p = first.len();
    for (sample, s) in samples.iter().enumerate().skip(1) {
        if s.len() != p {
            return Err(CondmonError::Length {
                what: "feature vector (same as sample 0)",
                found: s.len(),
                expected: p,
            });
        }
        if let Some(position) = (0..p).find(|&j| s.names[j] != first.names[j]) {
            return Err(CondmonError::FeatureNameMismatch {
                sample,
                position,
                found: s.names[position].clone(),
                expected: first.names[position].clone(),
            });
        }
    }
    Ok(FeatureMatrix {
        names: first.names.clone(),
        values: DMatrix::from_fn(samples.len(), p, |i, j| samples[i].values[j]),
    })
}

/// Named physical coefficients (values come from elsewhere, e.g. identified damping):
/// each `(name, coefficients)` pair contributes `name` for a single value, or `name[0]`,
/// `name[1]`, … for several.
///
/// Errors: an empty coefficient list, a non-finite value.
pub fn physical_features(coefficients: &[(&str, &[f64])]) -> Result<NamedFeatures> {
    let mut names = Vec::new();
    let mut values = Vec::new();
    for (name, vals) in coefficients {
        if vals.is_empty() {
            return Err(CondmonError::Length {
                what: "physical coefficient vector",
                found: 0,
                expected: 1,
            });
        }
        for (i, &v) in vals.iter().enumerate() {
            if !v.is_finite() {
                return Err(CondmonError::NonFinite {
                    matrix: "physical features",
                    sample: 0,
                    feature: values.len(),
                });
            }
            names.push(if vals.len() == 1 {
                (*name).to_owned()
            } else {
                format!("{name}[{i}]")
            });
            values.push(v);
        }
    }
    Ok(NamedFeatures { names, values })
}

/// Names of the flat weight vector of `net`, in its layout order (see `nn::Mlp`):
/// `layer{l}.unit{u}.w{j}` and `layer{l}.unit{u}.bias`, 0-based, the last layer being the
/// output layer.
pub fn weight_names(net: &Mlp) -> Vec<String> {
    let arch = net.architecture();
    let mut names = Vec::with_capacity(net.n_weights());
    for layer in 0..arch.n_layers() {
        let (fan_in, units) = arch.layer_shape(layer);
        for unit in 0..units {
            for j in 0..fan_in {
                names.push(format!("layer{layer}.unit{unit}.w{j}"));
            }
            names.push(format!("layer{layer}.unit{unit}.bias"));
        }
    }
    names
}

/// The network's flat weight vector as features (thesis ch. 6: "the trained network
/// parameters are used as features").
pub fn raw_weights(net: &Mlp) -> NamedFeatures {
    NamedFeatures {
        names: weight_names(net),
        values: net.weights().to_vec(),
    }
}

/// An equivalent network in canonical form (single hidden layer only).
///
/// A `tanh` network is unchanged by (a) negating a hidden unit's input weights, bias and
/// outgoing weights (tanh is odd), and (b) permuting hidden units. The canonical form
/// picks one representative of that class of 2ᴴ·H! equivalent weight vectors:
///
/// 1. **Sign:** each hidden unit's key is `(v₀ₕ, …, v_{q−1,h}, bₕ, wₕ₀, …, wₕ,ₙ₋₁)`
///    (outgoing weights to each output, bias, input weights). The unit is negated if the
///    first non-zero entry of its key is negative, so the weight to the first output is
///    non-negative (falling back to later entries when it is exactly zero).
/// 2. **Order:** units are sorted by their (sign-fixed) key, lexicographically descending:
///    largest weight to the first output first.
///
/// Output biases are untouched. Both steps use exact negation and comparisons, so any
/// permuted or sign-flipped copy of a network maps to bit-identical weights (zeros are
/// normalised to +0).
///
/// Errors: a network with other than one hidden layer.
pub fn canonicalise(net: &Mlp) -> Result<Mlp> {
    let arch = net.architecture();
    if arch.hidden.len() != 1 {
        return Err(CondmonError::UnsupportedArchitecture {
            hidden_layers: arch.hidden.len(),
        });
    }
    let (n, h, q) = (arch.inputs, arch.hidden[0], arch.outputs);
    let w = net.weights();
    let out_offset = h * (n + 1);
    // Key of unit u, in the documented order.
    let key = |u: usize| -> Vec<f64> {
        let mut k: Vec<f64> = (0..q).map(|o| w[out_offset + o * (h + 1) + u]).collect();
        k.push(w[u * (n + 1) + n]);
        k.extend_from_slice(&w[u * (n + 1)..u * (n + 1) + n]);
        k
    };
    let mut units: Vec<(Vec<f64>, usize, f64)> = (0..h)
        .map(|u| {
            let mut k = key(u);
            let sign = match k.iter().find(|v| **v != 0.0) {
                Some(v) if *v < 0.0 => -1.0,
                _ => 1.0,
            };
            k.iter_mut().for_each(|v| *v *= sign);
            (k, u, sign)
        })
        .collect();
    units.sort_by(|a, b| {
        a.0.iter()
            .zip(&b.0)
            .map(|(x, y)| y.total_cmp(x))
            .find(|o| o.is_ne())
            .unwrap_or(std::cmp::Ordering::Equal)
    });
    // +0.0 turns a negated zero back into +0.
    let mut out = vec![0.0; w.len()];
    for (slot, (_, u, sign)) in units.iter().enumerate() {
        for j in 0..=n {
            out[slot * (n + 1) + j] = sign * w[u * (n + 1) + j] + 0.0;
        }
        for o in 0..q {
            out[out_offset + o * (h + 1) + slot] = sign * w[out_offset + o * (h + 1) + u] + 0.0;
        }
    }
    for o in 0..q {
        let bias = out_offset + o * (h + 1) + h;
        out[bias] = w[bias] + 0.0;
    }
    Ok(Mlp::from_parts(
        arch.clone(),
        out,
        net.input_scaler().clone(),
        net.output_scaler().clone(),
    )?)
}

/// Canonicalised weights as features (see [`canonicalise`] for the rule). Names follow
/// [`weight_names`]; `unit{u}` is then the canonical rank of a hidden unit, not its
/// position in the trained network.
///
/// Errors: a network with other than one hidden layer.
pub fn canonical_weights(net: &Mlp) -> Result<NamedFeatures> {
    Ok(raw_weights(&canonicalise(net)?))
}

#[cfg(test)]
mod tests {
    use super::*;
    use nn::Architecture;

    #[test]
    fn hand_canonicalised_two_unit_network() {
        // 1-2-1: unit 0 (w 2, b 0.1, v −0.5), unit 1 (w −1, b 0.3, v 1.5), c 0.25.
        // Unit 0 flips to (w −2, b −0.1, v 0.5); order by v descending: unit 1 then 0.
        let mut net = Mlp::new(&Architecture::single(1, 2, 1), 0).unwrap();
        net.set_weights(&[2.0, 0.1, -1.0, 0.3, -0.5, 1.5, 0.25])
            .unwrap();
        let c = canonical_weights(&net).unwrap();
        assert_eq!(c.values(), &[-1.0, 0.3, -2.0, -0.1, 1.5, 0.5, 0.25]);
        assert_eq!(
            c.names(),
            &[
                "layer0.unit0.w0",
                "layer0.unit0.bias",
                "layer0.unit1.w0",
                "layer0.unit1.bias",
                "layer1.unit0.w0",
                "layer1.unit0.w1",
                "layer1.unit0.bias"
            ]
        );
    }

    #[test]
    fn physical_and_stacking() {
        let a = physical_features(&[("c", &[0.1]), ("k", &[0.5, 0.5])]).unwrap();
        assert_eq!(a.names(), &["c", "k[0]", "k[1]"]);
        let b = physical_features(&[("c", &[0.2]), ("k", &[0.4, 0.6])]).unwrap();
        let m = stack(&[a.clone(), b]).unwrap();
        assert_eq!(m.values().shape(), (2, 3));
        assert_eq!(m.values()[(1, 2)].to_bits(), 0.6f64.to_bits());
        let other = physical_features(&[("d", &[0.2]), ("k", &[0.4, 0.6])]).unwrap();
        assert!(matches!(
            stack(&[a.clone(), other]),
            Err(CondmonError::FeatureNameMismatch {
                sample: 1,
                position: 0,
                ..
            })
        ));
        assert!(matches!(
            physical_features(&[("c", &[f64::NAN])]),
            Err(CondmonError::NonFinite { feature: 0, .. })
        ));
        assert!(matches!(
            stack(&[]),
            Err(CondmonError::TooFewSamples { .. })
        ));
    }
}
