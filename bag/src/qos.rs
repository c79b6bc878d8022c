//! The QoS profiles rosbag2 stores with each topic (`offered_qos_profiles`), so `ros2 bag play`
//! can offer the same QoS the recorded publishers offered.
//!
//! rosbag2 Jazzy (metadata version 9) writes each profile as a YAML mapping with enum values as
//! lower-case names (`keep_last`, `best_effort`, …); version 8 and older wrote the rmw integer
//! values. [`QosProfile::list_from_yaml`] reads both; this crate always writes version 9.

use serde_yaml::Value;

/// `history` policy of a QoS profile.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum History {
    /// The middleware's default.
    SystemDefault,
    /// Keep the last `depth` samples.
    KeepLast,
    /// Keep all samples.
    KeepAll,
    /// Not known (as reported for some remote endpoints).
    Unknown,
}

/// `reliability` policy of a QoS profile.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Reliability {
    /// The middleware's default.
    SystemDefault,
    /// Resend lost samples.
    Reliable,
    /// Do not resend lost samples.
    BestEffort,
    /// Not known.
    Unknown,
    /// Match the most reliable compatible endpoint (subscriptions only).
    BestAvailable,
}

/// `durability` policy of a QoS profile.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Durability {
    /// The middleware's default.
    SystemDefault,
    /// Late joiners receive the last samples ("latched").
    TransientLocal,
    /// Late joiners receive only new samples.
    Volatile,
    /// Not known.
    Unknown,
    /// Match the most durable compatible endpoint (subscriptions only).
    BestAvailable,
}

/// `liveliness` policy of a QoS profile.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Liveliness {
    /// The middleware's default.
    SystemDefault,
    /// The middleware asserts liveliness.
    Automatic,
    /// Deprecated in ROS 2; kept so old bags read.
    ManualByNode,
    /// The publisher asserts liveliness per topic.
    ManualByTopic,
    /// Not known.
    Unknown,
    /// Match the most demanding compatible endpoint (subscriptions only).
    BestAvailable,
}

macro_rules! named_enum {
    ($ty:ident { $($variant:ident = $num:literal, $name:literal;)* }) => {
        impl $ty {
            /// The name rosbag2 (metadata version 9) writes, e.g. `keep_last`.
            pub fn name(self) -> &'static str {
                match self { $($ty::$variant => $name,)* }
            }
            /// The rmw integer value (metadata version 8 and older).
            pub fn rmw_value(self) -> i64 {
                match self { $($ty::$variant => $num,)* }
            }
            fn from_yaml(value: &Value) -> Option<Self> {
                match value {
                    Value::String(s) => match s.to_ascii_lowercase().as_str() {
                        $($name => Some($ty::$variant),)*
                        _ => None,
                    },
                    Value::Number(n) => match n.as_i64()? {
                        $($num => Some($ty::$variant),)*
                        _ => None,
                    },
                    _ => None,
                }
            }
        }
    };
}

named_enum!(History {
    SystemDefault = 0, "system_default";
    KeepLast = 1, "keep_last";
    KeepAll = 2, "keep_all";
    Unknown = 3, "unknown";
});
named_enum!(Reliability {
    SystemDefault = 0, "system_default";
    Reliable = 1, "reliable";
    BestEffort = 2, "best_effort";
    Unknown = 3, "unknown";
    BestAvailable = 4, "best_available";
});
named_enum!(Durability {
    SystemDefault = 0, "system_default";
    TransientLocal = 1, "transient_local";
    Volatile = 2, "volatile";
    Unknown = 3, "unknown";
    BestAvailable = 4, "best_available";
});
named_enum!(Liveliness {
    SystemDefault = 0, "system_default";
    Automatic = 1, "automatic";
    ManualByNode = 2, "manual_by_node";
    ManualByTopic = 3, "manual_by_topic";
    Unknown = 4, "unknown";
    BestAvailable = 5, "best_available";
});

/// A duration as rosbag2 writes it in QoS profiles: whole seconds and nanoseconds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct QosDuration {
    /// Seconds.
    pub sec: u64,
    /// Nanoseconds.
    pub nsec: u64,
}

impl QosDuration {
    /// "Infinite" as ROS 2 Jazzy reports it (`RMW_DURATION_INFINITE`, i64::MAX nanoseconds split
    /// into 9223372036 s and 854775807 ns). This is what `ros2 bag record` stores for a publisher
    /// that set no deadline, lifespan or lease duration.
    pub const INFINITE: QosDuration = QosDuration {
        sec: 9_223_372_036,
        nsec: 854_775_807,
    };
    /// Zero, which ROS 2 reads as "use the default" in a requested profile.
    pub const ZERO: QosDuration = QosDuration { sec: 0, nsec: 0 };

    fn from_yaml(value: &Value) -> Option<Self> {
        Some(QosDuration {
            sec: value.get("sec")?.as_u64()?,
            nsec: value.get("nsec")?.as_u64()?,
        })
    }
}

/// One offered QoS profile of a topic, with exactly the fields rosbag2 writes in
/// `offered_qos_profiles`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct QosProfile {
    /// History policy.
    pub history: History,
    /// Queue depth for [`History::KeepLast`].
    pub depth: u64,
    /// Reliability policy.
    pub reliability: Reliability,
    /// Durability policy.
    pub durability: Durability,
    /// Deadline between samples.
    pub deadline: QosDuration,
    /// How long a sample stays valid.
    pub lifespan: QosDuration,
    /// Liveliness policy.
    pub liveliness: Liveliness,
    /// Liveliness lease duration.
    pub liveliness_lease_duration: QosDuration,
    /// Whether the topic name bypasses ROS namespace conventions (`rt/` prefix).
    pub avoid_ros_namespace_conventions: bool,
}

impl QosProfile {
    /// ROS 2's sensor-data profile as a publisher offers it: best effort, keep last 5, volatile,
    /// automatic liveliness, no deadline, lifespan or lease (infinite).
    pub fn sensor_data() -> Self {
        QosProfile {
            history: History::KeepLast,
            depth: 5,
            reliability: Reliability::BestEffort,
            ..Self::default_profile()
        }
    }

    /// ROS 2's default profile as a publisher offers it: reliable, keep last 10, volatile,
    /// automatic liveliness, no deadline, lifespan or lease (infinite).
    pub fn default_profile() -> Self {
        QosProfile {
            history: History::KeepLast,
            depth: 10,
            reliability: Reliability::Reliable,
            durability: Durability::Volatile,
            deadline: QosDuration::INFINITE,
            lifespan: QosDuration::INFINITE,
            liveliness: Liveliness::Automatic,
            liveliness_lease_duration: QosDuration::INFINITE,
            avoid_ros_namespace_conventions: false,
        }
    }

    /// Writes `profiles` as the YAML block sequence rosbag2 (Jazzy, metadata version 9) writes,
    /// every line indented by `indent` spaces; `[]` when there are none. The text has no trailing
    /// newline, like yaml-cpp's output.
    pub fn list_to_yaml(profiles: &[QosProfile], indent: usize) -> String {
        if profiles.is_empty() {
            return "[]".to_string();
        }
        let pad = " ".repeat(indent);
        let mut lines = Vec::new();
        for p in profiles {
            let dur = |lines: &mut Vec<String>, key: &str, d: QosDuration| {
                lines.push(format!("{pad}  {key}:"));
                lines.push(format!("{pad}    sec: {}", d.sec));
                lines.push(format!("{pad}    nsec: {}", d.nsec));
            };
            lines.push(format!("{pad}- history: {}", p.history.name()));
            lines.push(format!("{pad}  depth: {}", p.depth));
            lines.push(format!("{pad}  reliability: {}", p.reliability.name()));
            lines.push(format!("{pad}  durability: {}", p.durability.name()));
            dur(&mut lines, "deadline", p.deadline);
            dur(&mut lines, "lifespan", p.lifespan);
            lines.push(format!("{pad}  liveliness: {}", p.liveliness.name()));
            dur(
                &mut lines,
                "liveliness_lease_duration",
                p.liveliness_lease_duration,
            );
            lines.push(format!(
                "{pad}  avoid_ros_namespace_conventions: {}",
                p.avoid_ros_namespace_conventions
            ));
        }
        lines.join("\n")
    }

    /// Reads the profiles from a parsed `offered_qos_profiles` value: a sequence of mappings
    /// (version 9) or a string holding YAML (version 8 and older, and MCAP channel metadata).
    /// Enum values may be names or rmw integers. Returns a description of the first problem.
    pub fn list_from_yaml(value: &Value) -> Result<Vec<QosProfile>, String> {
        match value {
            Value::Null => Ok(Vec::new()),
            Value::String(text) if text.trim().is_empty() => Ok(Vec::new()),
            Value::String(text) => {
                let inner: Value = serde_yaml::from_str(text)
                    .map_err(|e| format!("offered_qos_profiles is not YAML: {e}"))?;
                if matches!(inner, Value::String(_)) {
                    return Err("offered_qos_profiles is a string, not a list of profiles".into());
                }
                Self::list_from_yaml(&inner)
            }
            Value::Sequence(items) => items.iter().map(Self::from_yaml).collect(),
            _ => Err("offered_qos_profiles is neither a list nor YAML text".into()),
        }
    }

    /// Parses the YAML text of an MCAP channel's `offered_qos_profiles` entry.
    pub fn list_from_yaml_text(text: &str) -> Result<Vec<QosProfile>, String> {
        Self::list_from_yaml(&Value::String(text.to_string()))
    }

    fn from_yaml(item: &Value) -> Result<QosProfile, String> {
        fn field<'a>(item: &'a Value, key: &str) -> Result<&'a Value, String> {
            item.get(key)
                .ok_or_else(|| format!("QoS profile has no `{key}`"))
        }
        fn bad(key: &str, v: &Value) -> String {
            format!("QoS `{key}` has an unknown value {v:?}")
        }
        let get_enum = |key: &str| field(item, key);
        let history = get_enum("history")?;
        let reliability = get_enum("reliability")?;
        let durability = get_enum("durability")?;
        let liveliness = get_enum("liveliness")?;
        let duration = |key: &str| {
            field(item, key).and_then(|v| {
                QosDuration::from_yaml(v).ok_or_else(|| format!("QoS `{key}` is not {{sec, nsec}}"))
            })
        };
        Ok(QosProfile {
            history: History::from_yaml(history).ok_or_else(|| bad("history", history))?,
            depth: field(item, "depth")?
                .as_u64()
                .ok_or_else(|| "QoS `depth` is not a non-negative integer".to_string())?,
            reliability: Reliability::from_yaml(reliability)
                .ok_or_else(|| bad("reliability", reliability))?,
            durability: Durability::from_yaml(durability)
                .ok_or_else(|| bad("durability", durability))?,
            deadline: duration("deadline")?,
            lifespan: duration("lifespan")?,
            liveliness: Liveliness::from_yaml(liveliness)
                .ok_or_else(|| bad("liveliness", liveliness))?,
            liveliness_lease_duration: duration("liveliness_lease_duration")?,
            avoid_ros_namespace_conventions: field(item, "avoid_ros_namespace_conventions")?
                .as_bool()
                .ok_or_else(|| "QoS `avoid_ros_namespace_conventions` is not a bool".to_string())?,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn yaml_round_trip_of_both_presets() {
        let profiles = [QosProfile::sensor_data(), QosProfile::default_profile()];
        let text = QosProfile::list_to_yaml(&profiles, 0);
        assert!(text.starts_with("- history: keep_last\n  depth: 5\n  reliability: best_effort"));
        assert_eq!(QosProfile::list_from_yaml_text(&text).unwrap(), profiles);
    }

    #[test]
    fn reads_version_8_integer_enums() {
        let text = "- history: 1\n  depth: 7\n  reliability: 2\n  durability: 1\n  deadline:\n    \
                    sec: 0\n    nsec: 0\n  lifespan:\n    sec: 0\n    nsec: 0\n  liveliness: 3\n  \
                    liveliness_lease_duration:\n    sec: 1\n    nsec: 5\n  \
                    avoid_ros_namespace_conventions: true";
        let p = QosProfile::list_from_yaml_text(text).unwrap();
        assert_eq!(p.len(), 1);
        assert_eq!(p[0].depth, 7);
        assert_eq!(p[0].reliability, Reliability::BestEffort);
        assert_eq!(p[0].durability, Durability::TransientLocal);
        assert_eq!(p[0].liveliness, Liveliness::ManualByTopic);
        assert_eq!(
            p[0].liveliness_lease_duration,
            QosDuration { sec: 1, nsec: 5 }
        );
        assert!(p[0].avoid_ros_namespace_conventions);
    }

    #[test]
    fn empty_and_bad_input() {
        assert_eq!(QosProfile::list_to_yaml(&[], 4), "[]");
        assert!(QosProfile::list_from_yaml_text("").unwrap().is_empty());
        assert!(QosProfile::list_from_yaml_text("[]").unwrap().is_empty());
        let err = QosProfile::list_from_yaml_text("- history: sometimes").unwrap_err();
        assert!(err.contains("has no `reliability`"), "{err}");
        let mut text = QosProfile::list_to_yaml(&[QosProfile::default_profile()], 0);
        text = text.replace("keep_last", "sometimes");
        let err = QosProfile::list_from_yaml_text(&text).unwrap_err();
        assert!(err.contains("`history` has an unknown value"), "{err}");
        assert!(QosProfile::list_from_yaml_text("{{{").is_err());
    }
}
