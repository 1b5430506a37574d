//! Serde helpers for floats that may be NaN or infinite (an interval with too few
//! effective samples, a step without a test, a window without measurements): JSON has no
//! such numbers, so they are written as `null` and read back as NaN.

use serde::{Deserialize, Deserializer, Serializer};

fn out(v: f64) -> Option<f64> {
    v.is_finite().then_some(v)
}

/// One float.
pub mod nullable {
    use super::*;

    /// Write a finite value as a number, anything else as `null`.
    pub fn serialize<S: Serializer>(v: &f64, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_some(&out(*v))
    }

    /// Read a number, or `null` as NaN.
    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
        Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::NAN))
    }
}

/// A pair of floats (an interval).
pub mod nullable_pair {
    use super::*;

    /// Write each bound as a number or `null`.
    pub fn serialize<S: Serializer>(v: &[f64; 2], s: S) -> Result<S::Ok, S::Error> {
        s.serialize_some(&[out(v[0]), out(v[1])])
    }

    /// Read each bound, `null` as NaN.
    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<[f64; 2], D::Error> {
        let [a, b] = <[Option<f64>; 2]>::deserialize(d)?;
        Ok([a.unwrap_or(f64::NAN), b.unwrap_or(f64::NAN)])
    }
}

/// A list of floats.
pub mod nullable_vec {
    use super::*;

    /// Write each value as a number or `null`.
    pub fn serialize<S: Serializer>(v: &[f64], s: S) -> Result<S::Ok, S::Error> {
        s.collect_seq(v.iter().map(|x| out(*x)))
    }

    /// Read each value, `null` as NaN.
    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<f64>, D::Error> {
        Ok(Vec::<Option<f64>>::deserialize(d)?
            .into_iter()
            .map(|x| x.unwrap_or(f64::NAN))
            .collect())
    }
}

#[cfg(test)]
mod tests {
    use serde::{Deserialize, Serialize};

    #[derive(Debug, Serialize, Deserialize)]
    struct Record {
        #[serde(with = "super::nullable")]
        a: f64,
        #[serde(with = "super::nullable_pair")]
        b: [f64; 2],
        #[serde(with = "super::nullable_vec")]
        c: Vec<f64>,
    }

    #[test]
    fn non_finite_round_trips_through_null() {
        let r = Record {
            a: f64::NAN,
            b: [1.5, f64::INFINITY],
            c: vec![f64::NEG_INFINITY, 2.0],
        };
        let text = serde_json::to_string(&r).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(text, r#"{"a":null,"b":[1.5,null],"c":[null,2.0]}"#);
        let back: Record = serde_json::from_str(&text).unwrap_or_else(|e| panic!("{e}"));
        assert!(back.a.is_nan() && back.b[1].is_nan() && back.c[0].is_nan());
        assert_eq!(back.b[0].to_bits(), 1.5f64.to_bits());
        assert_eq!(back.c[1].to_bits(), 2.0f64.to_bits());
    }
}
