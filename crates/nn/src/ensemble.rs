//! Averaging networks into one: [`average`] builds the single [`Mlp`] whose output is the
//! mean of its members' outputs (the sweep rows to average are
//! [`band_members`](crate::sweep::band_members)).
//!
//! Averaging equally good restarts is bagging over initialisations: each restart lands in
//! its own local minimum; the mean's variance is at most the members' average variance,
//! and its bias is the members' mean bias. The merged network is exact, not an approximation:
//! the members' hidden units sit side by side (layer by layer, block-diagonal between
//! hidden layers, so no unit sees another member's units), and the linear output layer
//! takes each member's output weights divided by the member count, biases averaged. With
//! one set of input and output scalers (the sweep fits them to the training data, so every
//! member shares them) the mean of the scaled outputs is the scaled mean, so the merged
//! network is one ordinary `Mlp`: `model.json`, `predict` and the trajectory training take
//! it as they take any other.

use crate::error::{NnError, Result};
use crate::mlp::{Architecture, Mlp};

/// The network whose output is the mean of `members`' outputs (see the module docs).
///
/// Errors: no members; members with different inputs, outputs, number of hidden layers
/// or scalers ([`NnError::Incompatible`]).
pub fn average(members: &[Mlp]) -> Result<Mlp> {
    let first = members.first().ok_or(NnError::TooFewSamples {
        what: "networks to average",
        found: 0,
        needed: 1,
    })?;
    let arch0 = first.architecture();
    for (k, m) in members.iter().enumerate().skip(1) {
        let a = m.architecture();
        let why = if a.inputs != arch0.inputs {
            Some("a different number of inputs")
        } else if a.outputs != arch0.outputs {
            Some("a different number of outputs")
        } else if a.hidden.len() != arch0.hidden.len() {
            Some("a different number of hidden layers")
        } else if m.input_scaler() != first.input_scaler() {
            Some("a different input scaler")
        } else if m.output_scaler() != first.output_scaler() {
            Some("a different output scaler")
        } else {
            None
        };
        if let Some(reason) = why {
            return Err(NnError::Incompatible {
                what: "network to average",
                index: k,
                reason,
            });
        }
    }
    let n_layers = arch0.n_layers();
    let arch = Architecture {
        inputs: arch0.inputs,
        hidden: (0..arch0.hidden.len())
            .map(|l| members.iter().map(|m| m.hidden()[l]).sum())
            .collect(),
        outputs: arch0.outputs,
    };
    let mut weights = Vec::with_capacity(arch.n_weights());
    let scale = 1.0 / members.len() as f64;
    for layer in 0..n_layers {
        let (fan_in, units) = arch.layer_shape(layer);
        if layer + 1 < n_layers {
            // Hidden units of each member in turn; a unit's weights are zero outside its
            // own member's block of the previous layer (the scaled inputs, for layer 0,
            // are shared by everyone).
            let mut col = 0;
            for m in members {
                let a = m.architecture();
                let (m_fan, m_units) = a.layer_shape(layer);
                for u in 0..m_units {
                    let w = m.unit_weights(layer, u).expect("unit inside its layer");
                    if layer == 0 {
                        weights.extend_from_slice(&w[..m_fan]);
                    } else {
                        weights.extend(std::iter::repeat_n(0.0, col));
                        weights.extend_from_slice(&w[..m_fan]);
                        weights.extend(std::iter::repeat_n(0.0, fan_in - col - m_fan));
                    }
                    weights.push(w[m_fan]);
                }
                if layer > 0 {
                    col += m_fan;
                }
            }
            debug_assert_eq!(
                weights.len(),
                arch.layer_offset(layer) + units * (fan_in + 1)
            );
        } else {
            // The linear output layer: every member's weights over its own last hidden
            // units, scaled by 1/K; biases averaged.
            for out in 0..units {
                let mut bias = 0.0;
                for m in members {
                    let w = m.unit_weights(layer, out).expect("unit inside its layer");
                    let m_fan = w.len() - 1;
                    weights.extend(w[..m_fan].iter().map(|v| v * scale));
                    bias += w[m_fan] * scale;
                }
                weights.push(bias);
            }
        }
    }
    Mlp::from_parts(
        arch,
        weights,
        first.input_scaler().clone(),
        first.output_scaler().clone(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mlp::Workspace;
    use crate::scaling::Scaler;

    fn net(hidden: &[usize], seed: u64) -> Mlp {
        let arch = Architecture {
            inputs: 3,
            hidden: hidden.to_vec(),
            outputs: 2,
        };
        let s_in = Scaler::new(vec![0.5, -1.0, 2.0], vec![2.0, 0.5, 3.0]).unwrap();
        let s_out = Scaler::new(vec![0.1, -0.2], vec![4.0, 0.25]).unwrap();
        Mlp::new(&arch, seed)
            .unwrap()
            .with_scalers(s_in, s_out)
            .unwrap()
    }

    /// The merged network's output is the mean of the members' outputs, evaluated one by
    /// one, for one and for two hidden layers of unequal widths.
    #[test]
    fn merged_output_is_the_members_mean() {
        for hidden in [
            vec![vec![2], vec![3], vec![1]],
            vec![vec![2, 3], vec![4, 1]],
        ] {
            let members: Vec<Mlp> = hidden
                .iter()
                .enumerate()
                .map(|(k, h)| net(h, 11 + k as u64))
                .collect();
            let merged = average(&members).unwrap();
            let width: usize = hidden.iter().map(|h| h[0]).sum();
            assert_eq!(merged.hidden()[0], width);
            let mut ws = Workspace::new();
            for x in [[0.3, -0.7, 4.0], [-2.0, 1.5, 0.0], [10.0, -3.0, -8.0]] {
                let mut mean = [0.0; 2];
                for m in &members {
                    let mut y = [0.0; 2];
                    m.forward(&x, &mut y, &mut ws).unwrap();
                    for (a, b) in mean.iter_mut().zip(y) {
                        *a += b / members.len() as f64;
                    }
                }
                let mut y = [0.0; 2];
                merged.forward(&x, &mut y, &mut ws).unwrap();
                for (a, b) in mean.iter().zip(y) {
                    assert!((a - b).abs() <= 1e-12 * (1.0 + a.abs()), "{a} vs {b}");
                }
            }
        }
    }

    #[test]
    fn one_member_is_itself_and_mismatches_are_named() {
        let a = net(&[3], 5);
        assert_eq!(average(std::slice::from_ref(&a)).unwrap(), a);
        assert!(matches!(
            average(&[]),
            Err(NnError::TooFewSamples { found: 0, .. })
        ));
        let deeper = net(&[2, 2], 6);
        assert!(matches!(
            average(&[a.clone(), deeper]),
            Err(NnError::Incompatible { index: 1, .. })
        ));
        let other_scaler = net(&[2], 7)
            .with_scalers(Scaler::identity(3), Scaler::identity(2))
            .unwrap();
        assert!(matches!(
            average(&[a, other_scaler]),
            Err(NnError::Incompatible { index: 1, reason, .. }) if reason.contains("input scaler")
        ));
    }
}
