//! The JSON form of messages.
//!
//! A message's JSON form is its serde form: an object with the ROS field names, nested messages
//! as objects, `Time` as `{"sec": .., "nanosec": ..}`, sequences and fixed-size arrays as JSON
//! arrays, strings as strings. JSON numbers cannot hold NaN or infinities, so a non-finite float
//! is written as one of the strings `"NaN"`, `"Infinity"`, `"-Infinity"` (the protobuf JSON
//! convention); reading accepts those (case-insensitively, also `"inf"`, `"-inf"`). Finite floats
//! round-trip exactly (serde_json prints the shortest representation that parses back to the same
//! bits, `-0.0` included). Reading is strict: every field must be present and unknown fields are
//! errors, so a misspelt field name is reported rather than silently defaulted.
//!
//! ```
//! use dynlab_msgs::geometry_msgs::Point;
//! let p = Point { x: 1.5, y: f64::NAN, z: f64::NEG_INFINITY };
//! let v = dynlab_msgs::to_json(&p)?;
//! assert_eq!(v, serde_json::json!({"x": 1.5, "y": "NaN", "z": "-Infinity"}));
//! let back: Point = dynlab_msgs::from_json(&v)?;
//! assert!(back.y.is_nan() && back.z == f64::NEG_INFINITY);
//! # Ok::<(), dynlab_msgs::CdrError>(())
//! ```

use serde_json::Value;

use crate::{CdrError, RosMessage, from_cdr, to_cdr};

/// The JSON form of a message.
pub fn to_json<T: RosMessage>(msg: &T) -> Result<Value, CdrError> {
    serde_json::to_value(msg).map_err(|source| CdrError::Json {
        type_name: T::TYPE_NAME,
        source,
    })
}

/// A message from its JSON form.
pub fn from_json<T: RosMessage>(value: &Value) -> Result<T, CdrError> {
    T::deserialize(value).map_err(|source| CdrError::Json {
        type_name: T::TYPE_NAME,
        source,
    })
}

/// Decodes a CDR payload of type `T` into its JSON form.
pub fn cdr_to_json<T: RosMessage>(bytes: &[u8]) -> Result<Value, CdrError> {
    to_json(&from_cdr::<T>(bytes)?)
}

/// Encodes the JSON form of a `T` as a CDR payload.
pub fn json_to_cdr<T: RosMessage>(value: &Value) -> Result<Vec<u8>, CdrError> {
    to_cdr(&from_json::<T>(value)?)
}
