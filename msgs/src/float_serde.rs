//! Serde adapters for floating-point fields.
//!
//! In binary formats (CDR) a float is written as itself. In human-readable formats (JSON) a
//! finite float is a number and a non-finite one is one of the strings `"NaN"`, `"Infinity"`,
//! `"-Infinity"` (the convention of the protobuf JSON mapping), since JSON numbers cannot hold
//! them. Reading JSON accepts numbers and those strings (case-insensitively, also `"inf"`,
//! `"-inf"`, `"+Infinity"`).

use std::fmt;

use serde::de::{self, Deserializer, SeqAccess, Visitor};
use serde::ser::{SerializeTuple, Serializer};

/// The JSON string for a non-finite value, `None` for a finite one.
pub(crate) fn non_finite_name(v: f64) -> Option<&'static str> {
    if v.is_nan() {
        Some("NaN")
    } else if v == f64::INFINITY {
        Some("Infinity")
    } else if v == f64::NEG_INFINITY {
        Some("-Infinity")
    } else {
        None
    }
}

fn parse_non_finite(s: &str) -> Option<f64> {
    match s.to_ascii_lowercase().as_str() {
        "nan" => Some(f64::NAN),
        "infinity" | "+infinity" | "inf" | "+inf" => Some(f64::INFINITY),
        "-infinity" | "-inf" => Some(f64::NEG_INFINITY),
        _ => None,
    }
}

/// Accepts a number or a non-finite name; yields f64.
struct JsonFloatVisitor;

impl Visitor<'_> for JsonFloatVisitor {
    type Value = f64;

    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("a number or one of \"NaN\", \"Infinity\", \"-Infinity\"")
    }
    fn visit_f64<E: de::Error>(self, v: f64) -> Result<f64, E> {
        Ok(v)
    }
    fn visit_f32<E: de::Error>(self, v: f32) -> Result<f64, E> {
        Ok(v as f64)
    }
    fn visit_i64<E: de::Error>(self, v: i64) -> Result<f64, E> {
        Ok(v as f64)
    }
    fn visit_u64<E: de::Error>(self, v: u64) -> Result<f64, E> {
        Ok(v as f64)
    }
    fn visit_str<E: de::Error>(self, v: &str) -> Result<f64, E> {
        parse_non_finite(v).ok_or_else(|| E::invalid_value(de::Unexpected::Str(v), &self))
    }
}

/// Reads one f64 the way the format wants: JSON-style in human-readable formats.
fn read_f64<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    if d.is_human_readable() {
        d.deserialize_any(JsonFloatVisitor)
    } else {
        <f64 as serde::Deserialize>::deserialize(d)
    }
}

/// `#[serde(with = "f64_field")]` for `f64` fields.
pub(crate) mod f64_field {
    use super::*;

    pub(crate) fn serialize<S: Serializer>(v: &f64, s: S) -> Result<S::Ok, S::Error> {
        match non_finite_name(*v) {
            Some(name) if s.is_human_readable() => s.serialize_str(name),
            _ => s.serialize_f64(*v),
        }
    }

    pub(crate) fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
        read_f64(d)
    }
}

/// `#[serde(with = "f32_field")]` for `f32` fields.
pub(crate) mod f32_field {
    use super::*;

    pub(crate) fn serialize<S: Serializer>(v: &f32, s: S) -> Result<S::Ok, S::Error> {
        match non_finite_name(*v as f64) {
            Some(name) if s.is_human_readable() => s.serialize_str(name),
            _ => s.serialize_f32(*v),
        }
    }

    pub(crate) fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<f32, D::Error> {
        if d.is_human_readable() {
            let v = d.deserialize_any(JsonFloatVisitor)?;
            let narrowed = v as f32;
            if v.is_finite() && !narrowed.is_finite() {
                return Err(de::Error::custom(format_args!(
                    "{v} is out of range for float32 (largest magnitude {:e})",
                    f32::MAX
                )));
            }
            Ok(narrowed)
        } else {
            <f32 as serde::Deserialize>::deserialize(d)
        }
    }
}

/// One f64 element of a fixed-size array, read JSON-style in human-readable formats.
struct F64Elem(f64);

impl<'de> serde::Deserialize<'de> for F64Elem {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        read_f64(d).map(F64Elem)
    }
}

struct F64Ser(f64);

impl serde::Serialize for F64Ser {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        f64_field::serialize(&self.0, s)
    }
}

/// `#[serde(with = "f64_array")]` for fixed-size `[f64; N]` fields (ROS `float64[N]`): a serde
/// tuple, so CDR writes the N values with no length prefix, as ROS does for fixed-size arrays.
pub(crate) mod f64_array {
    use super::*;

    pub(crate) fn serialize<S: Serializer, const N: usize>(
        v: &[f64; N],
        s: S,
    ) -> Result<S::Ok, S::Error> {
        let mut t = s.serialize_tuple(N)?;
        for x in v {
            t.serialize_element(&F64Ser(*x))?;
        }
        t.end()
    }

    struct ArrayVisitor<const N: usize>;

    impl<'de, const N: usize> Visitor<'de> for ArrayVisitor<N> {
        type Value = [f64; N];

        fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
            write!(f, "an array of exactly {N} numbers")
        }

        fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<[f64; N], A::Error> {
            let mut out = [0.0; N];
            for (i, slot) in out.iter_mut().enumerate() {
                match seq.next_element::<F64Elem>()? {
                    Some(F64Elem(v)) => *slot = v,
                    None => return Err(de::Error::invalid_length(i, &self)),
                }
            }
            // JSON arrays may be longer than N; count what is left to say so.
            let mut extra = 0usize;
            while seq.next_element::<de::IgnoredAny>()?.is_some() {
                extra += 1;
            }
            if extra > 0 {
                return Err(de::Error::invalid_length(N + extra, &self));
            }
            Ok(out)
        }
    }

    pub(crate) fn deserialize<'de, D: Deserializer<'de>, const N: usize>(
        d: D,
    ) -> Result<[f64; N], D::Error> {
        d.deserialize_tuple(N, ArrayVisitor::<N>)
    }
}
