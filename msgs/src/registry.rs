//! Message types by name, for tools that handle messages they only know at run time
//! (recorder, player, bag export and import).
//!
//! ```
//! let t = dynlab_msgs::lookup("geometry_msgs/msg/PoseStamped").expect("known type");
//! let json = serde_json::json!({
//!     "header": {"stamp": {"sec": 1, "nanosec": 5}, "frame_id": "world"},
//!     "pose": {"position": {"x": 1.0, "y": 2.0, "z": 0.0},
//!              "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}}});
//! let cdr = (t.from_json)(&json)?;
//! assert_eq!((t.to_json)(&cdr)?, json);
//! assert_eq!(dynlab_msgs::ros_to_dds_type_name(t.type_name)?,
//!            "geometry_msgs::msg::dds_::PoseStamped_");
//! # Ok::<(), dynlab_msgs::CdrError>(())
//! ```

use std::sync::LazyLock;

use serde_json::Value;

use crate::definition::split_type_name;
use crate::json::{cdr_to_json, json_to_cdr};
use crate::{CdrError, RosMessage};

/// One message type, known by name at run time.
#[derive(Debug, Clone, Copy)]
pub struct MessageType {
    /// The ROS type name, e.g. `geometry_msgs/msg/PoseStamped`.
    pub type_name: &'static str,
    /// The full `ros2msg` definition as rosbag2 stores it (see [`crate::definition`]).
    pub definition: &'static str,
    /// Decodes a CDR payload (with encapsulation header) into the JSON form (see [`crate::json`]).
    pub to_json: fn(&[u8]) -> Result<Value, CdrError>,
    /// Encodes the JSON form as a CDR payload (little endian, with encapsulation header).
    pub from_json: fn(&Value) -> Result<Vec<u8>, CdrError>,
    /// Lists the NaN and infinite fields of a CDR payload by path (empty when all are finite).
    pub non_finite_fields: fn(&[u8]) -> Result<Vec<crate::NonFiniteField>, CdrError>,
}

impl MessageType {
    /// The entry for `T`.
    pub fn of<T: RosMessage>() -> MessageType {
        MessageType {
            type_name: T::TYPE_NAME,
            definition: T::definition(),
            to_json: cdr_to_json::<T>,
            from_json: json_to_cdr::<T>,
            non_finite_fields: |bytes| Ok(crate::non_finite_fields(&crate::from_cdr::<T>(bytes)?)),
        }
    }

    /// The DDS type name (`geometry_msgs::msg::dds_::PoseStamped_`) of this type.
    pub fn dds_type_name(&self) -> String {
        // Every name in the registry has the `package/msg/Type` form.
        ros_to_dds_type_name(self.type_name).unwrap_or_default()
    }
}

macro_rules! registry_entries {
    ($($t:ty),* $(,)?) => {
        vec![$(MessageType::of::<$t>()),*]
    };
}

static ALL: LazyLock<Vec<MessageType>> =
    LazyLock::new(|| with_all_message_types!(registry_entries));

/// Every message type of this crate.
pub fn all() -> &'static [MessageType] {
    &ALL
}

/// The message type with this name: the ROS form `geometry_msgs/msg/PoseStamped`, the short form
/// `geometry_msgs/PoseStamped` used in `MSG:` lines, or the DDS form
/// `geometry_msgs::msg::dds_::PoseStamped_`.
pub fn lookup(type_name: &str) -> Option<&'static MessageType> {
    let ros;
    let name = if type_name.contains("::") {
        ros = dds_to_ros_type_name(type_name).ok()?;
        ros.as_str()
    } else {
        type_name
    };
    let (package, ty) = split_type_name(name)?;
    if name.split('/').count() == 3 && !name.contains("/msg/") {
        return None;
    }
    all()
        .iter()
        .find(|t| split_type_name(t.type_name) == Some((package, ty)))
}

/// The DDS type name of a ROS type: `geometry_msgs/msg/PoseStamped` →
/// `geometry_msgs::msg::dds_::PoseStamped_` (also for `srv` and `action` namespaces; a name
/// without namespace, `geometry_msgs/PoseStamped`, is taken as a message).
pub fn ros_to_dds_type_name(ros: &str) -> Result<String, CdrError> {
    let invalid = || CdrError::InvalidTypeName(ros.to_string());
    let (package, ty) = split_type_name(ros).ok_or_else(invalid)?;
    let parts: Vec<&str> = ros.split('/').collect();
    let namespace = if parts.len() == 3 { parts[1] } else { "msg" };
    Ok(format!("{package}::{namespace}::dds_::{ty}_"))
}

/// The ROS type name of a DDS type name seen on the wire:
/// `geometry_msgs::msg::dds_::PoseStamped_` → `geometry_msgs/msg/PoseStamped`.
pub fn dds_to_ros_type_name(dds: &str) -> Result<String, CdrError> {
    let invalid = || CdrError::InvalidTypeName(dds.to_string());
    let parts: Vec<&str> = dds.split("::").collect();
    let [package, namespace, "dds_", ty] = parts.as_slice() else {
        return Err(invalid());
    };
    let ty = ty.strip_suffix('_').ok_or_else(invalid)?;
    let ros = format!("{package}/{namespace}/{ty}");
    split_type_name(&ros).ok_or_else(invalid)?;
    Ok(ros)
}
