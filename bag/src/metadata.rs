//! `metadata.yaml`, the bag directory's index, in the form rosbag2 Jazzy writes (version 9).
//!
//! The field order and layout follow rosbag2's yaml-cpp output (`rosbag2_storage/yaml.hpp`):
//! `version, storage_identifier, duration, starting_time, message_count,
//! topics_with_message_count, compression_format, compression_mode, relative_file_paths, files,
//! custom_data, ros_distro`, under a top-level `rosbag2_bagfile_information` key.

use std::path::Path;

use serde_yaml::Value;

use crate::error::BagError;
use crate::qos::QosProfile;

/// The metadata version this crate writes (rosbag2 Jazzy).
pub const METADATA_VERSION: u32 = 9;

/// One topic's entry in `topics_with_message_count`.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct MetadataTopic {
    pub name: String,
    pub type_name: String,
    pub qos: Vec<QosProfile>,
    pub type_description_hash: String,
    pub message_count: u64,
}

/// One entry in `files`.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct MetadataFile {
    pub path: String,
    pub starting_time_ns: u64,
    pub duration_ns: u64,
    pub message_count: u64,
}

/// The content of `metadata.yaml`.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Metadata {
    pub duration_ns: u64,
    pub starting_time_ns: u64,
    pub message_count: u64,
    pub topics: Vec<MetadataTopic>,
    pub files: Vec<MetadataFile>,
    pub ros_distro: String,
}

/// A YAML scalar for `s`: plain when that reads back as the same string, else double-quoted
/// (JSON string escapes are valid YAML double-quoted escapes).
pub(crate) fn yaml_str(s: &str) -> String {
    let plain_ok = !s.is_empty()
        && s.chars()
            .all(|c| c.is_ascii_alphanumeric() || "/_.-".contains(c))
        && !s.starts_with(['-', '.'])
        && serde_yaml::from_str::<Value>(s).ok() == Some(Value::String(s.to_string()));
    if plain_ok {
        s.to_string()
    } else {
        let mut out = String::from("\"");
        for c in s.chars() {
            match c {
                '"' => out.push_str("\\\""),
                '\\' => out.push_str("\\\\"),
                '\n' => out.push_str("\\n"),
                '\t' => out.push_str("\\t"),
                '\r' => out.push_str("\\r"),
                c if (c as u32) < 0x20 => out.push_str(&format!("\\x{:02x}", c as u32)),
                c => out.push(c),
            }
        }
        out.push('"');
        out
    }
}

impl Metadata {
    /// The metadata as rosbag2 serializes the bag information node, each line indented by
    /// `base` spaces. With `base = 0` this is the `serialized_metadata` text rosbag2 stores in
    /// the MCAP `rosbag2` metadata record.
    pub fn body_yaml(&self, base: usize) -> String {
        let p = " ".repeat(base);
        let mut o = Vec::new();
        o.push(format!("{p}version: {METADATA_VERSION}"));
        o.push(format!("{p}storage_identifier: mcap"));
        o.push(format!(
            "{p}duration:\n{p}  nanoseconds: {}",
            self.duration_ns
        ));
        o.push(format!(
            "{p}starting_time:\n{p}  nanoseconds_since_epoch: {}",
            self.starting_time_ns
        ));
        o.push(format!("{p}message_count: {}", self.message_count));
        if self.topics.is_empty() {
            o.push(format!("{p}topics_with_message_count: []"));
        } else {
            o.push(format!("{p}topics_with_message_count:"));
            for t in &self.topics {
                o.push(format!("{p}  - topic_metadata:"));
                o.push(format!("{p}      name: {}", yaml_str(&t.name)));
                o.push(format!("{p}      type: {}", yaml_str(&t.type_name)));
                o.push(format!("{p}      serialization_format: cdr"));
                if t.qos.is_empty() {
                    o.push(format!("{p}      offered_qos_profiles: []"));
                } else {
                    o.push(format!("{p}      offered_qos_profiles:"));
                    o.push(QosProfile::list_to_yaml(&t.qos, base + 8));
                }
                o.push(format!(
                    "{p}      type_description_hash: {}",
                    yaml_str(&t.type_description_hash)
                ));
                o.push(format!("{p}    message_count: {}", t.message_count));
            }
        }
        o.push(format!("{p}compression_format: \"\""));
        o.push(format!("{p}compression_mode: \"\""));
        if self.files.is_empty() {
            o.push(format!("{p}relative_file_paths: []"));
            o.push(format!("{p}files: []"));
        } else {
            o.push(format!("{p}relative_file_paths:"));
            for f in &self.files {
                o.push(format!("{p}  - {}", yaml_str(&f.path)));
            }
            o.push(format!("{p}files:"));
            for f in &self.files {
                o.push(format!("{p}  - path: {}", yaml_str(&f.path)));
                o.push(format!(
                    "{p}    starting_time:\n{p}      nanoseconds_since_epoch: {}",
                    f.starting_time_ns
                ));
                o.push(format!(
                    "{p}    duration:\n{p}      nanoseconds: {}",
                    f.duration_ns
                ));
                o.push(format!("{p}    message_count: {}", f.message_count));
            }
        }
        o.push(format!("{p}custom_data: ~"));
        o.push(format!("{p}ros_distro: {}", yaml_str(&self.ros_distro)));
        o.join("\n")
    }

    /// The whole `metadata.yaml` file.
    pub fn file_yaml(&self) -> String {
        format!("rosbag2_bagfile_information:\n{}\n", self.body_yaml(2))
    }
}

/// What this crate needs from an existing `metadata.yaml`: the version and the data files in
/// order.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct ReadMetadata {
    pub version: u64,
    pub relative_file_paths: Vec<String>,
    pub message_count: Option<u64>,
    /// `starting_time.nanoseconds_since_epoch`, when given.
    pub starting_time_ns: Option<u64>,
    /// `duration.nanoseconds`, when given.
    pub duration_ns: Option<u64>,
}

/// Reads the parts of `metadata.yaml` this crate uses.
pub(crate) fn read_metadata(path: &Path) -> Result<ReadMetadata, BagError> {
    let text = std::fs::read_to_string(path).map_err(|e| BagError::io("reading", path, e))?;
    let bad = |reason: String| BagError::BadMetadata {
        path: path.to_path_buf(),
        reason,
    };
    let doc: Value =
        serde_yaml::from_str(&text).map_err(|e| bad(format!("not valid YAML ({e})")))?;
    let info = doc
        .get("rosbag2_bagfile_information")
        .ok_or_else(|| bad("no `rosbag2_bagfile_information` key".into()))?;
    let version = info
        .get("version")
        .and_then(Value::as_u64)
        .ok_or_else(|| bad("no integer `version`".into()))?;
    if let Some(storage) = info.get("storage_identifier").and_then(Value::as_str)
        && storage != "mcap"
    {
        return Err(bad(format!(
            "storage `{storage}` is not supported, only `mcap`; convert the bag with \
             `ros2 bag convert` to MCAP storage"
        )));
    }
    let paths = info
        .get("relative_file_paths")
        .and_then(Value::as_sequence)
        .ok_or_else(|| bad("no `relative_file_paths` list".into()))?;
    let relative_file_paths = paths
        .iter()
        .map(|p| p.as_str().map(str::to_string))
        .collect::<Option<Vec<_>>>()
        .ok_or_else(|| bad("`relative_file_paths` holds something other than file names".into()))?;
    if let Some(mode) = info.get("compression_mode").and_then(Value::as_str)
        && !mode.is_empty()
        && !mode.eq_ignore_ascii_case("none")
    {
        return Err(bad(format!(
            "compression_mode `{mode}` (whole-file or per-message compression) is not supported; \
             decompress the bag with `ros2 bag convert` first"
        )));
    }
    let message_count = info.get("message_count").and_then(Value::as_u64);
    let starting_time_ns = info
        .get("starting_time")
        .and_then(|t| t.get("nanoseconds_since_epoch"))
        .and_then(Value::as_u64);
    let duration_ns = info
        .get("duration")
        .and_then(|t| t.get("nanoseconds"))
        .and_then(Value::as_u64);
    Ok(ReadMetadata {
        version,
        relative_file_paths,
        message_count,
        starting_time_ns,
        duration_ns,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn yaml_strings_quote_when_needed() {
        assert_eq!(yaml_str("/car/pose"), "/car/pose");
        assert_eq!(
            yaml_str("geometry_msgs/msg/PoseStamped"),
            "geometry_msgs/msg/PoseStamped"
        );
        assert_eq!(yaml_str(""), "\"\"");
        assert_eq!(yaml_str("true"), "\"true\"");
        assert_eq!(yaml_str("123"), "\"123\"");
        assert_eq!(yaml_str("a: b"), "\"a: b\"");
        for s in [
            "",
            "true",
            "1e3",
            "a: b",
            "x\"y",
            "- item",
            "~",
            "null",
            "tab\there",
        ] {
            let back: Value = serde_yaml::from_str(&yaml_str(s)).unwrap();
            assert_eq!(back, Value::String(s.to_string()), "{s}");
        }
    }

    #[test]
    fn file_yaml_parses_with_every_field() {
        let m = Metadata {
            duration_ns: 5,
            starting_time_ns: 10,
            message_count: 3,
            topics: vec![MetadataTopic {
                name: "/a".into(),
                type_name: "std_msgs/msg/Header".into(),
                qos: vec![QosProfile::default_profile()],
                type_description_hash: String::new(),
                message_count: 3,
            }],
            files: vec![MetadataFile {
                path: "b_0.mcap".into(),
                starting_time_ns: 10,
                duration_ns: 5,
                message_count: 3,
            }],
            ros_distro: "jazzy".into(),
        };
        let doc: Value = serde_yaml::from_str(&m.file_yaml()).unwrap();
        let info = &doc["rosbag2_bagfile_information"];
        for key in [
            "version",
            "storage_identifier",
            "duration",
            "starting_time",
            "message_count",
            "topics_with_message_count",
            "compression_format",
            "compression_mode",
            "relative_file_paths",
            "files",
            "custom_data",
            "ros_distro",
        ] {
            assert!(info.get(key).is_some(), "missing {key}");
        }
        assert_eq!(info["version"].as_u64(), Some(9));
        let topic = &info["topics_with_message_count"][0];
        assert_eq!(topic["message_count"].as_u64(), Some(3));
        let qos = QosProfile::list_from_yaml(&topic["topic_metadata"]["offered_qos_profiles"]);
        assert_eq!(qos.unwrap(), vec![QosProfile::default_profile()]);
        assert_eq!(
            info["files"][0]["duration"]["nanoseconds"].as_u64(),
            Some(5)
        );
        // The record body (no wrapper) parses too.
        let body: Value = serde_yaml::from_str(&m.body_yaml(0)).unwrap();
        assert_eq!(body["ros_distro"].as_str(), Some("jazzy"));
    }
}
