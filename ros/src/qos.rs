//! Quality-of-service presets equal to ROS 2's.
//!
//! The profile type is ros2-client's [`QosProfile`] (re-exported here), so presets go straight
//! into publishers and subscriptions. The presets copy the values of `rmw/qos_profiles.h`
//! (ROS 2 Jazzy); `deadline`, `lifespan` and the liveliness lease are "infinite" (`None`), which is
//! what the `*_DEFAULT` values of those headers mean on every DDS vendor.

use std::time::Duration;

pub use ros2_client::QosProfile;
pub use ros2_client::qos::{Durability, History, Liveliness, Reliability, WhenFull};

/// How long a reliable publisher waits for room in its send window before `publish` fails
/// (the DDS default `max_blocking_time`, 100 ms).
pub const MAX_BLOCKING_TIME: Duration = Duration::from_millis(100);

/// Named QoS presets, for parameters and command lines (`sensor_data`, `default`, …).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum QosPreset {
    /// `rmw_qos_profile_sensor_data`: best effort, keep last 5, volatile.
    SensorData,
    /// `rmw_qos_profile_default`: reliable, keep last 10, volatile.
    Default,
    /// `rclcpp::ClockQoS`: best effort, keep last 1, volatile.
    Clock,
    /// `rclcpp::QoS(n).transient_local()` as used for latched topics: reliable, keep last 1,
    /// transient local.
    Latched,
}

impl QosPreset {
    /// The profile of this preset.
    pub fn profile(self) -> QosProfile {
        match self {
            QosPreset::SensorData => sensor_data(),
            QosPreset::Default => default_profile(),
            QosPreset::Clock => clock(),
            QosPreset::Latched => latched(),
        }
    }

    /// Parses a preset name as written in parameters (`sensor_data`, `default`, `clock`,
    /// `latched`).
    pub fn from_name(name: &str) -> Option<QosPreset> {
        match name {
            "sensor_data" => Some(QosPreset::SensorData),
            "default" | "reliable" => Some(QosPreset::Default),
            "clock" => Some(QosPreset::Clock),
            "latched" | "transient_local" => Some(QosPreset::Latched),
            _ => None,
        }
    }
}

fn base(reliability: Reliability, depth: usize) -> QosProfile {
    QosProfile {
        reliability,
        durability: Durability::Volatile,
        history: History::KeepLast { depth },
        deadline: None,
        lifespan: None,
        liveliness: Liveliness::Automatic,
        liveliness_lease: None,
    }
}

fn reliable() -> Reliability {
    Reliability::Reliable {
        when_full: WhenFull::Wait(MAX_BLOCKING_TIME),
    }
}

/// `rmw_qos_profile_sensor_data`: best effort, keep last 5, volatile — for measurements where
/// the newest sample matters more than every sample (poses, scans).
pub fn sensor_data() -> QosProfile {
    base(Reliability::BestEffort, 5)
}

/// `rmw_qos_profile_default`: reliable, keep last 10, volatile — commands and anything that
/// must not be lost on a healthy link.
pub fn default_profile() -> QosProfile {
    base(reliable(), 10)
}

/// `rclcpp::ClockQoS`: best effort, keep last 1 — what ROS 2 uses on `/clock`.
pub fn clock() -> QosProfile {
    base(Reliability::BestEffort, 1)
}

/// Latched: reliable, keep last 1, transient local — late subscribers get the last sample.
pub fn latched() -> QosProfile {
    QosProfile {
        durability: Durability::TransientLocal,
        ..base(reliable(), 1)
    }
}

/// `rmw_qos_profile_services_default`: reliable, keep last 10, volatile — service requests and
/// replies.
pub fn services() -> QosProfile {
    base(reliable(), 10)
}

/// `rmw_qos_profile_parameter_events`: reliable, keep last 1000, volatile — `/parameter_events`.
pub fn parameter_events() -> QosProfile {
    base(reliable(), 1000)
}

/// rcl's `/rosout` profile: reliable, keep last 1000, transient local, lifespan 10 s — late
/// subscribers get the last 10 s of log lines.
pub fn rosout() -> QosProfile {
    QosProfile {
        durability: Durability::TransientLocal,
        lifespan: Some(Duration::from_secs(10)),
        ..base(reliable(), 1000)
    }
}

/// The profile a recorder subscribes with so that it matches every publisher offering one of
/// `offered`: reliable only if all of them are reliable (a reliable reader does not match a
/// best-effort writer), transient local only if all of them are (to receive latched samples),
/// and a deep history so that bursts are not dropped before they are written. This is how
/// rosbag2 adapts its subscriptions to the offered QoS.
pub fn recording_profile(offered: &[QosProfile], depth: usize) -> QosProfile {
    let all_reliable = !offered.is_empty()
        && offered
            .iter()
            .all(|q| matches!(q.reliability, Reliability::Reliable { .. }));
    let all_transient_local = !offered.is_empty()
        && offered
            .iter()
            .all(|q| q.durability == Durability::TransientLocal);
    QosProfile {
        reliability: if all_reliable {
            reliable()
        } else {
            Reliability::BestEffort
        },
        durability: if all_transient_local {
            Durability::TransientLocal
        } else {
            Durability::Volatile
        },
        history: History::KeepLast {
            depth: depth.max(1),
        },
        deadline: None,
        lifespan: None,
        liveliness: Liveliness::Automatic,
        liveliness_lease: None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ros2_client::dds::rustdds::{QosPolicies, policy};

    /// The fields of `rmw_qos_profile_t` that ROS 2 presets set, as in `rmw/qos_profiles.h`.
    struct RmwProfile {
        depth: i32,
        best_effort: bool,
        transient_local: bool,
    }

    const RMW_QOS_PROFILE_SENSOR_DATA: RmwProfile = RmwProfile {
        depth: 5,
        best_effort: true,
        transient_local: false,
    };
    const RMW_QOS_PROFILE_DEFAULT: RmwProfile = RmwProfile {
        depth: 10,
        best_effort: false,
        transient_local: false,
    };

    fn assert_matches(profile: &QosProfile, rmw: &RmwProfile) {
        let dds = QosPolicies::from(profile);
        assert_eq!(
            dds.history(),
            Some(policy::History::KeepLast { depth: rmw.depth })
        );
        match dds.reliability() {
            Some(policy::Reliability::BestEffort) => assert!(rmw.best_effort),
            Some(policy::Reliability::Reliable { .. }) => assert!(!rmw.best_effort),
            None => panic!("reliability not set"),
        }
        let expected_durability = if rmw.transient_local {
            policy::Durability::TransientLocal
        } else {
            policy::Durability::Volatile
        };
        assert_eq!(dds.durability(), Some(expected_durability));
        assert_eq!(profile.deadline, None);
        assert_eq!(profile.lifespan, None);
        assert_eq!(profile.liveliness, Liveliness::Automatic);
    }

    #[test]
    fn sensor_data_equals_rmw_qos_profile_sensor_data() {
        assert_matches(&sensor_data(), &RMW_QOS_PROFILE_SENSOR_DATA);
        assert_eq!(
            QosPreset::from_name("sensor_data").unwrap().profile(),
            sensor_data()
        );
    }

    #[test]
    fn default_equals_rmw_qos_profile_default() {
        assert_matches(&default_profile(), &RMW_QOS_PROFILE_DEFAULT);
        assert_eq!(
            QosPreset::from_name("default").unwrap().profile(),
            default_profile()
        );
    }

    #[test]
    fn clock_and_latched_presets() {
        assert_matches(
            &clock(),
            &RmwProfile {
                depth: 1,
                best_effort: true,
                transient_local: false,
            },
        );
        assert_matches(
            &latched(),
            &RmwProfile {
                depth: 1,
                best_effort: false,
                transient_local: true,
            },
        );
        assert_eq!(QosPreset::from_name("nonsense"), None);
    }

    #[test]
    fn recording_profile_follows_the_offers() {
        let r = recording_profile(&[sensor_data()], 1000);
        assert_eq!(r.reliability, Reliability::BestEffort);
        assert_eq!(r.history, History::KeepLast { depth: 1000 });
        let r = recording_profile(&[latched()], 0);
        assert!(matches!(r.reliability, Reliability::Reliable { .. }));
        assert_eq!(r.durability, Durability::TransientLocal);
        assert_eq!(r.history, History::KeepLast { depth: 1 });
        // one best-effort publisher among reliable ones: the reader must be best effort
        let r = recording_profile(&[default_profile(), sensor_data()], 10);
        assert_eq!(r.reliability, Reliability::BestEffort);
        let r = recording_profile(&[latched(), default_profile()], 10);
        assert!(matches!(r.reliability, Reliability::Reliable { .. }));
        assert_eq!(r.durability, Durability::Volatile);
        assert_eq!(
            recording_profile(&[], 10).reliability,
            Reliability::BestEffort
        );
    }
}
