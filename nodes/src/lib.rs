//! ROS 2 node binaries: recorder, player and the robot nodes
#![warn(missing_docs)]
