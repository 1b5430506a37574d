//! Weight canonicalisation: symmetric copies of a network (hidden units permuted, tanh
//! signs flipped) compute the same outputs and get bit-identical canonical vectors;
//! distinct networks get distinct ones; and canonical features fix the thesis's failure
//! mode on networks that differ only by these symmetries.

use condmon::{
    ClassifierSpec, CondmonError, CvConfig, CvScheme, KnnConfig, LdaConfig, Preprocessing,
    canonical_weights, canonicalise, cross_validate, raw_weights, stack,
};
use nalgebra::DMatrix;
use nn::{Architecture, Mlp, Scaler};
use rand::RngExt;
use rand::rngs::ChaCha8Rng;

use crate::common::rng;

/// Apply a hidden-unit permutation and sign flips to a single-hidden-layer weight vector,
/// written from the layout documented in `nn::Mlp`: new unit `r` is old unit `perm[r]`
/// times `sign[r]` (input weights, bias and every outgoing weight).
fn permute_and_flip(net: &Mlp, perm: &[usize], sign: &[f64]) -> Mlp {
    let arch = net.architecture();
    let (n, h, q) = (arch.inputs, arch.hidden[0], arch.outputs);
    let w = net.weights();
    let mut out = w.to_vec();
    let o = h * (n + 1);
    for r in 0..h {
        let u = perm[r];
        for j in 0..=n {
            out[r * (n + 1) + j] = sign[r] * w[u * (n + 1) + j];
        }
        for k in 0..q {
            out[o + k * (h + 1) + r] = sign[r] * w[o + k * (h + 1) + u];
        }
    }
    let mut copy = net.clone();
    copy.set_weights(&out).unwrap();
    copy
}

fn random_symmetry(r: &mut ChaCha8Rng, h: usize) -> (Vec<usize>, Vec<f64>) {
    let mut perm: Vec<usize> = (0..h).collect();
    for i in (1..h).rev() {
        perm.swap(i, r.random_range(0..=i));
    }
    let sign = (0..h)
        .map(|_| if r.random_bool(0.5) { -1.0 } else { 1.0 })
        .collect();
    (perm, sign)
}

/// A network with non-trivial scalers and uniform random weights in [−2, 2].
fn random_net(arch: &Architecture, r: &mut ChaCha8Rng) -> Mlp {
    let mut net = Mlp::new(arch, 0)
        .unwrap()
        .with_scalers(
            Scaler::new(vec![0.5; arch.inputs], vec![2.0; arch.inputs]).unwrap(),
            Scaler::new(vec![-1.0; arch.outputs], vec![3.0; arch.outputs]).unwrap(),
        )
        .unwrap();
    let w: Vec<f64> = (0..net.n_weights())
        .map(|_| r.random_range(-2.0..2.0))
        .collect();
    net.set_weights(&w).unwrap();
    net
}

fn max_output_gap(a: &Mlp, b: &Mlp, r: &mut ChaCha8Rng) -> f64 {
    let x = DMatrix::from_fn(a.n_inputs(), 50, |_, _| r.random_range(-3.0..3.0));
    (a.predict(&x).unwrap() - b.predict(&x).unwrap()).amax()
}

#[test]
fn symmetric_copies_have_same_outputs_and_canonical_vector() {
    let mut r = rng(31);
    for arch in [Architecture::single(2, 3, 1), Architecture::single(4, 6, 2)] {
        for _ in 0..25 {
            let net = random_net(&arch, &mut r);
            let canon = canonical_weights(&net).unwrap();
            let (perm, sign) = random_symmetry(&mut r, arch.hidden[0]);
            let copy = permute_and_flip(&net, &perm, &sign);
            // Same function: only the summation order of the output layer changes, so
            // outputs agree to a few ulps of values of order 10 (1e-12 is generous).
            assert!(max_output_gap(&net, &copy, &mut r) < 1e-12);
            // Canonical vectors are bit-identical.
            assert_eq!(canonical_weights(&copy).unwrap(), canon);
            // The canonical network is itself equivalent, and canonicalisation is
            // idempotent.
            let c = canonicalise(&net).unwrap();
            assert!(max_output_gap(&net, &c, &mut r) < 1e-12);
            assert_eq!(canonicalise(&c).unwrap(), c);
            // Raw weights do change (unless the symmetry happened to be the identity).
            let identity =
                perm.iter().enumerate().all(|(i, p)| i == *p) && sign.iter().all(|s| *s > 0.0);
            assert_eq!(raw_weights(&copy) == raw_weights(&net), identity);
        }
    }
}

#[test]
fn distinct_networks_have_distinct_canonical_vectors() {
    let mut r = rng(32);
    let arch = Architecture::single(2, 3, 1);
    let canon: Vec<Vec<f64>> = (0..30)
        .map(|_| {
            canonical_weights(&random_net(&arch, &mut r))
                .unwrap()
                .values()
                .to_vec()
        })
        .collect();
    for i in 0..canon.len() {
        for j in i + 1..canon.len() {
            let gap = canon[i]
                .iter()
                .zip(&canon[j])
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max);
            assert!(gap > 1e-3, "networks {i} and {j} collide");
        }
    }
}

#[test]
fn deeper_networks_are_rejected() {
    let net = Mlp::new(
        &Architecture {
            inputs: 2,
            hidden: vec![3, 2],
            outputs: 1,
        },
        0,
    )
    .unwrap();
    assert!(matches!(
        canonical_weights(&net),
        Err(CondmonError::UnsupportedArchitecture { hidden_layers: 2 })
    ));
    // Raw weights still work for any depth.
    assert_eq!(raw_weights(&net).len(), net.n_weights());
}

#[test]
fn canonical_features_separate_classes_hidden_by_symmetry() {
    // Three conditions: class c is the network B + c·δ (δ = ±0.1 per weight), and every
    // "trained" sample is that network plus noise in ±0.02, then a random permutation and
    // sign pattern — the thesis's "different but equivalent weight configurations".
    // Symmetric images of B are O(1) apart, far more than the classes (‖δ‖ ≈ 0.36).
    let b = [
        1.0, 0.2, 0.1, -0.5, 1.2, 0.3, 0.8, -0.4, -0.2, 1.5, 0.9, 0.4, 0.05,
    ];
    let delta: Vec<f64> = (0..13)
        .map(|i| if i % 3 == 1 { -0.1 } else { 0.1 })
        .collect();
    let bases: Vec<Vec<f64>> = (0..3)
        .map(|c| {
            b.iter()
                .zip(&delta)
                .map(|(v, d)| v + c as f64 * d)
                .collect()
        })
        .collect();
    let arch = Architecture::single(2, 3, 1);
    let mut r = rng(33);
    let mut raw = Vec::new();
    let mut canon = Vec::new();
    let mut labels = Vec::new();
    for (class, base) in bases.iter().enumerate() {
        for _ in 0..12 {
            let mut net = Mlp::new(&arch, 0).unwrap();
            let w: Vec<f64> = base
                .iter()
                .map(|v| v + r.random_range(-0.02..0.02))
                .collect();
            net.set_weights(&w).unwrap();
            let (perm, sign) = random_symmetry(&mut r, 3);
            let net = permute_and_flip(&net, &perm, &sign);
            raw.push(raw_weights(&net));
            canon.push(canonical_weights(&net).unwrap());
            labels.push(class);
        }
    }
    let raw = stack(&raw).unwrap().into_parts().1;
    let canon = stack(&canon).unwrap().into_parts().1;
    let config = CvConfig {
        scheme: CvScheme::LeaveOneOut,
        ..CvConfig::default()
    };
    let knn = ClassifierSpec::Knn(KnnConfig { k: 1 });
    let lda = ClassifierSpec::Lda(LdaConfig::default());
    let pre = Preprocessing::default();
    for clf in [&knn, &lda] {
        // Noise ≤ 0.02 per weight vs class shifts of 0.1 in every weight: perfect.
        let on_canon = cross_validate(&canon, &labels, &pre, clf, &config).unwrap();
        assert_eq!(on_canon.errors, 0, "{}", clf.label());
    }
    // Raw weights scatter each class over up to 48 sign/permutation images, each nearer to
    // other classes' copies of the same image than to its own class: the nearest
    // neighbour is often of the wrong class. (LDA is not asserted on raw weights: with
    // 33 residual degrees of freedom for 13 features it can find a direction that partly
    // survives the symmetries of this synthetic set.)
    let on_raw = cross_validate(&raw, &labels, &pre, &knn, &config).unwrap();
    assert!(
        on_raw.error_rate > 0.3,
        "raw 1-NN error {}",
        on_raw.error_rate
    );
}
