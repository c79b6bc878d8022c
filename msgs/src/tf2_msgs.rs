//! `tf2_msgs` messages: [`TFMessage`], what tf2 publishes on `/tf` and `/tf_static`.

use serde::{Deserialize, Serialize};

use crate::geometry_msgs::TransformStamped;

/// `tf2_msgs/msg/TFMessage`: a batch of transforms, each one edge `parent → child` of the tf
/// tree. `/tf` carries the moving edges (best effort or reliable, volatile), `/tf_static` the
/// fixed ones (reliable, transient local: late subscribers get them too).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TFMessage {
    /// The transforms (a sequence: serialized with a length prefix).
    pub transforms: Vec<TransformStamped>,
}

/// `TFMessage.msg` text.
pub(crate) const TF_MESSAGE_MSG: &str = "\
# A batch of transforms, as tf2 publishes them on /tf and /tf_static.

geometry_msgs/TransformStamped[] transforms
";

impl_ros_message!(TFMessage, "tf2_msgs/msg/TFMessage", TF_MESSAGE_MSG);
