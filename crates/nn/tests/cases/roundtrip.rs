//! Weight-vector and serde round trips.

use nn::{Architecture, Mlp, NetCorrection};

use crate::common::uniform_inputs;

#[test]
fn weight_vector_round_trip_gives_same_outputs() {
    let x = uniform_inputs(3, 25, -4.0, 4.0, 9);
    let t = uniform_inputs(2, 25, 10.0, 20.0, 10);
    let a = Mlp::for_data(&x, &t, &[4, 3], 1).unwrap();
    let mut b = Mlp::for_data(&x, &t, &[4, 3], 2).unwrap();
    assert_ne!(a.predict(&x).unwrap(), b.predict(&x).unwrap());
    b.set_weights(a.weights()).unwrap();
    // Same weights and scalers, same arithmetic: identical outputs.
    assert_eq!(a.predict(&x).unwrap(), b.predict(&x).unwrap());
    assert_eq!(
        a.weights().len(),
        Architecture {
            inputs: 3,
            hidden: vec![4, 3],
            outputs: 2
        }
        .n_weights()
    );
}

#[test]
fn serde_round_trip_and_validation() {
    let x = uniform_inputs(2, 30, -1.0, 3.0, 4);
    let t = uniform_inputs(1, 30, -5.0, 5.0, 5);
    let net = Mlp::for_data(&x, &t, &[6], 3).unwrap();
    let json = serde_json::to_string(&net).unwrap();
    let back: Mlp = serde_json::from_str(&json).unwrap();
    assert_eq!(back, net);
    assert_eq!(back.predict(&x).unwrap(), net.predict(&x).unwrap());

    // Tampered weight count is rejected by the validating deserialiser.
    let mut v: serde_json::Value = serde_json::from_str(&json).unwrap();
    v["weights"].as_array_mut().unwrap().pop();
    assert!(serde_json::from_value::<Mlp>(v).is_err());
    // Zero half-range is rejected too.
    let mut v: serde_json::Value = serde_json::from_str(&json).unwrap();
    v["input_scaler"]["half_range"][0] = 0.0.into();
    assert!(serde_json::from_value::<Mlp>(v).is_err());

    let corr = NetCorrection::new(net, 1).unwrap();
    let back: NetCorrection = serde_json::from_str(&serde_json::to_string(&corr).unwrap()).unwrap();
    assert_eq!(back, corr);
}
