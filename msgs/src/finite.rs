//! Finding NaN and infinite fields, by path, to reject bad input with a clear message.
//!
//! ```
//! use dynlab_msgs::geometry_msgs::PoseStamped;
//! use dynlab_msgs::RosMessage;
//! let mut msg = PoseStamped::default();
//! msg.pose.position.x = f64::NAN;
//! msg.pose.orientation.w = f64::INFINITY;
//! let err = msg.check_finite().unwrap_err();
//! assert_eq!(err.to_string(),
//!            "geometry_msgs/msg/PoseStamped has non-finite fields: pose.position.x is NaN, \
//!             pose.orientation.w is +inf");
//! ```

use std::fmt;

use serde::Serialize;
use serde::ser::{self, Impossible};

use crate::RosMessage;

/// One non-finite float field.
#[derive(Debug, Clone, PartialEq)]
pub struct NonFiniteField {
    /// Path of the field, e.g. `pose.position.x`, `poses[3].pose.orientation.w`,
    /// `pose.covariance[7]`.
    pub path: String,
    /// The value: NaN or ±∞.
    pub value: f64,
}

impl fmt::Display for NonFiniteField {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let what = if self.value.is_nan() {
            "NaN"
        } else if self.value > 0.0 {
            "+inf"
        } else {
            "-inf"
        };
        write!(f, "{} is {what}", self.path)
    }
}

/// A message with NaN or infinite fields.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub struct NonFiniteError {
    /// The ROS type name of the message.
    pub type_name: &'static str,
    /// Every non-finite field, in field order.
    pub fields: Vec<NonFiniteField>,
}

impl fmt::Display for NonFiniteError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        const SHOWN: usize = 8;
        write!(f, "{} has non-finite fields: ", self.type_name)?;
        for (i, field) in self.fields.iter().take(SHOWN).enumerate() {
            if i > 0 {
                f.write_str(", ")?;
            }
            write!(f, "{field}")?;
        }
        if self.fields.len() > SHOWN {
            write!(f, " and {} more", self.fields.len() - SHOWN)?;
        }
        Ok(())
    }
}

/// Every NaN or infinite float in `msg` (any serde-serializable value), with its path.
pub fn non_finite_fields<T: Serialize + ?Sized>(msg: &T) -> Vec<NonFiniteField> {
    let mut found = Vec::new();
    // The walker's only error is a custom one a Serialize impl might raise; then the fields
    // found so far are still reported.
    let _ = msg.serialize(Walker {
        path: String::new(),
        found: &mut found,
    });
    found
}

/// `Ok` if every float in `msg` is finite, otherwise an error naming each bad field by path.
pub fn check_finite<T: RosMessage>(msg: &T) -> Result<(), NonFiniteError> {
    let fields = non_finite_fields(msg);
    if fields.is_empty() {
        Ok(())
    } else {
        Err(NonFiniteError {
            type_name: T::TYPE_NAME,
            fields,
        })
    }
}

/// A serializer that records the path of every non-finite float instead of writing anything.
struct Walker<'a> {
    path: String,
    found: &'a mut Vec<NonFiniteField>,
}

#[derive(Debug)]
struct WalkError(String);

impl fmt::Display for WalkError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}
impl std::error::Error for WalkError {}
impl ser::Error for WalkError {
    fn custom<T: fmt::Display>(msg: T) -> Self {
        WalkError(msg.to_string())
    }
}

impl<'a> Walker<'a> {
    fn float(self, v: f64) -> Result<(), WalkError> {
        if !v.is_finite() {
            self.found.push(NonFiniteField {
                path: self.path,
                value: v,
            });
        }
        Ok(())
    }
    fn child(&mut self, field: &str) -> Walker<'_> {
        let path = if self.path.is_empty() {
            field.to_string()
        } else {
            format!("{}.{field}", self.path)
        };
        Walker {
            path,
            found: self.found,
        }
    }
    fn element(&mut self, index: usize) -> Walker<'_> {
        Walker {
            path: format!("{}[{index}]", self.path),
            found: self.found,
        }
    }
}

/// Compound walker: fields and elements of structs, sequences, tuples and maps.
struct Compound<'a> {
    walker: Walker<'a>,
    index: usize,
}

impl Compound<'_> {
    fn next_element<T: Serialize + ?Sized>(&mut self, value: &T) -> Result<(), WalkError> {
        let i = self.index;
        self.index += 1;
        value.serialize(self.walker.element(i))
    }
}

macro_rules! ignore_scalars {
    ($($method:ident($ty:ty)),* $(,)?) => {
        $(fn $method(self, _v: $ty) -> Result<(), WalkError> { Ok(()) })*
    };
}

impl<'a> ser::Serializer for Walker<'a> {
    type Ok = ();
    type Error = WalkError;
    type SerializeSeq = Compound<'a>;
    type SerializeTuple = Compound<'a>;
    type SerializeTupleStruct = Compound<'a>;
    type SerializeTupleVariant = Compound<'a>;
    type SerializeMap = Impossible<(), WalkError>;
    type SerializeStruct = Compound<'a>;
    type SerializeStructVariant = Compound<'a>;

    ignore_scalars!(
        serialize_bool(bool),
        serialize_i8(i8),
        serialize_i16(i16),
        serialize_i32(i32),
        serialize_i64(i64),
        serialize_u8(u8),
        serialize_u16(u16),
        serialize_u32(u32),
        serialize_u64(u64),
        serialize_char(char),
        serialize_str(&str),
        serialize_bytes(&[u8]),
    );

    fn serialize_f32(self, v: f32) -> Result<(), WalkError> {
        self.float(v as f64)
    }
    fn serialize_f64(self, v: f64) -> Result<(), WalkError> {
        self.float(v)
    }
    fn serialize_none(self) -> Result<(), WalkError> {
        Ok(())
    }
    fn serialize_some<T: Serialize + ?Sized>(self, value: &T) -> Result<(), WalkError> {
        value.serialize(self)
    }
    fn serialize_unit(self) -> Result<(), WalkError> {
        Ok(())
    }
    fn serialize_unit_struct(self, _name: &'static str) -> Result<(), WalkError> {
        Ok(())
    }
    fn serialize_unit_variant(
        self,
        _name: &'static str,
        _index: u32,
        _variant: &'static str,
    ) -> Result<(), WalkError> {
        Ok(())
    }
    fn serialize_newtype_struct<T: Serialize + ?Sized>(
        self,
        _name: &'static str,
        value: &T,
    ) -> Result<(), WalkError> {
        value.serialize(self)
    }
    fn serialize_newtype_variant<T: Serialize + ?Sized>(
        mut self,
        _name: &'static str,
        _index: u32,
        variant: &'static str,
        value: &T,
    ) -> Result<(), WalkError> {
        value.serialize(self.child(variant))
    }
    fn serialize_seq(self, _len: Option<usize>) -> Result<Compound<'a>, WalkError> {
        Ok(Compound {
            walker: self,
            index: 0,
        })
    }
    fn serialize_tuple(self, _len: usize) -> Result<Compound<'a>, WalkError> {
        Ok(Compound {
            walker: self,
            index: 0,
        })
    }
    fn serialize_tuple_struct(
        self,
        _name: &'static str,
        _len: usize,
    ) -> Result<Compound<'a>, WalkError> {
        Ok(Compound {
            walker: self,
            index: 0,
        })
    }
    fn serialize_tuple_variant(
        self,
        _name: &'static str,
        _index: u32,
        _variant: &'static str,
        _len: usize,
    ) -> Result<Compound<'a>, WalkError> {
        Ok(Compound {
            walker: self,
            index: 0,
        })
    }
    fn serialize_map(self, _len: Option<usize>) -> Result<Self::SerializeMap, WalkError> {
        Err(WalkError("maps are not ROS message fields".into()))
    }
    fn serialize_struct(self, _name: &'static str, _len: usize) -> Result<Compound<'a>, WalkError> {
        Ok(Compound {
            walker: self,
            index: 0,
        })
    }
    fn serialize_struct_variant(
        self,
        _name: &'static str,
        _index: u32,
        _variant: &'static str,
        _len: usize,
    ) -> Result<Compound<'a>, WalkError> {
        Ok(Compound {
            walker: self,
            index: 0,
        })
    }
    fn is_human_readable(&self) -> bool {
        // Floats must arrive as floats, not as the "NaN" strings of the JSON form.
        false
    }
}

impl ser::SerializeSeq for Compound<'_> {
    type Ok = ();
    type Error = WalkError;
    fn serialize_element<T: Serialize + ?Sized>(&mut self, value: &T) -> Result<(), WalkError> {
        self.next_element(value)
    }
    fn end(self) -> Result<(), WalkError> {
        Ok(())
    }
}

impl ser::SerializeTuple for Compound<'_> {
    type Ok = ();
    type Error = WalkError;
    fn serialize_element<T: Serialize + ?Sized>(&mut self, value: &T) -> Result<(), WalkError> {
        self.next_element(value)
    }
    fn end(self) -> Result<(), WalkError> {
        Ok(())
    }
}

impl ser::SerializeTupleStruct for Compound<'_> {
    type Ok = ();
    type Error = WalkError;
    fn serialize_field<T: Serialize + ?Sized>(&mut self, value: &T) -> Result<(), WalkError> {
        self.next_element(value)
    }
    fn end(self) -> Result<(), WalkError> {
        Ok(())
    }
}

impl ser::SerializeTupleVariant for Compound<'_> {
    type Ok = ();
    type Error = WalkError;
    fn serialize_field<T: Serialize + ?Sized>(&mut self, value: &T) -> Result<(), WalkError> {
        self.next_element(value)
    }
    fn end(self) -> Result<(), WalkError> {
        Ok(())
    }
}

impl ser::SerializeStruct for Compound<'_> {
    type Ok = ();
    type Error = WalkError;
    fn serialize_field<T: Serialize + ?Sized>(
        &mut self,
        key: &'static str,
        value: &T,
    ) -> Result<(), WalkError> {
        value.serialize(self.walker.child(key))
    }
    fn end(self) -> Result<(), WalkError> {
        Ok(())
    }
}

impl ser::SerializeStructVariant for Compound<'_> {
    type Ok = ();
    type Error = WalkError;
    fn serialize_field<T: Serialize + ?Sized>(
        &mut self,
        key: &'static str,
        value: &T,
    ) -> Result<(), WalkError> {
        value.serialize(self.walker.child(key))
    }
    fn end(self) -> Result<(), WalkError> {
        Ok(())
    }
}
