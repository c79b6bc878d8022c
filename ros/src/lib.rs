//! Thin node runtime over ros2-client: ROS 2 command line, parameters, QoS, sim time, shutdown
#![warn(missing_docs)]
