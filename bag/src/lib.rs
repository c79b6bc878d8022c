//! rosbag2-compatible MCAP bags: writing, reading, metadata.yaml
#![warn(missing_docs)]
