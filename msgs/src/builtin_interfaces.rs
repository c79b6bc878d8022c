//! `builtin_interfaces` messages: [`Time`] and [`Duration`].
//!
//! Both are a signed count of whole seconds plus a non-negative count of nanoseconds within the
//! second, so −0.25 s is `{sec: -1, nanosec: 750_000_000}`. The conversions here keep that
//! normal form, round float seconds to the nearest nanosecond, and saturate at the representable
//! range (±2³¹ s, about 68 years) rather than wrap; the `checked_*` forms return `None` instead.

use serde::{Deserialize, Serialize};

const NANOS_PER_SEC: i64 = 1_000_000_000;

/// Shared conversions of the two `{sec: int32, nanosec: uint32}` types.
macro_rules! sec_nanosec_conversions {
    ($ty:ident, $what:literal) => {
        impl $ty {
            /// Zero.
            pub const ZERO: $ty = $ty { sec: 0, nanosec: 0 };
            /// The largest representable value.
            pub const MAX: $ty = $ty { sec: i32::MAX, nanosec: 999_999_999 };
            /// The smallest (most negative) representable value.
            pub const MIN: $ty = $ty { sec: i32::MIN, nanosec: 0 };

            #[doc = concat!("The ", $what, " of `ns` nanoseconds, or `None` if the whole seconds do not fit in `int32`.")]
            pub fn checked_from_nanos(ns: i64) -> Option<Self> {
                let sec = i32::try_from(ns.div_euclid(NANOS_PER_SEC)).ok()?;
                Some($ty { sec, nanosec: ns.rem_euclid(NANOS_PER_SEC) as u32 })
            }

            #[doc = concat!("The ", $what, " of `ns` nanoseconds, saturating at [`Self::MIN`] and [`Self::MAX`].")]
            pub fn from_nanos(ns: i64) -> Self {
                Self::checked_from_nanos(ns)
                    .unwrap_or(if ns < 0 { Self::MIN } else { Self::MAX })
            }

            /// Total nanoseconds (exact for every value, also when `nanosec` is out of its
            /// normal range `0..1_000_000_000`).
            pub fn to_nanos(self) -> i64 {
                self.sec as i64 * NANOS_PER_SEC + self.nanosec as i64
            }

            #[doc = concat!("The ", $what, " of `s` seconds rounded to the nearest nanosecond, or `None` if `s` is NaN, infinite or out of range.")]
            pub fn checked_from_secs_f64(s: f64) -> Option<Self> {
                if !s.is_finite() {
                    return None;
                }
                let whole = s.floor();
                let mut nanos = ((s - whole) * 1e9).round();
                let mut whole = whole;
                if nanos >= 1e9 {
                    nanos -= 1e9;
                    whole += 1.0;
                }
                if whole < i32::MIN as f64 || whole > i32::MAX as f64 {
                    return None;
                }
                Some($ty { sec: whole as i32, nanosec: nanos as u32 })
            }

            #[doc = concat!("The ", $what, " of `s` seconds rounded to the nearest nanosecond, saturating at [`Self::MIN`] and [`Self::MAX`]; NaN gives zero.")]
            pub fn from_secs_f64(s: f64) -> Self {
                if s.is_nan() {
                    return Self::ZERO;
                }
                Self::checked_from_secs_f64(s)
                    .unwrap_or(if s < 0.0 { Self::MIN } else { Self::MAX })
            }

            /// Seconds as a float (nanosecond resolution is lost beyond about 10⁷ s).
            pub fn as_secs_f64(self) -> f64 {
                self.sec as f64 + self.nanosec as f64 * 1e-9
            }
        }
    };
}

/// `builtin_interfaces/msg/Time`: seconds and nanoseconds since the epoch of the clock in use.
#[derive(
    Debug, Clone, Copy, Default, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize,
)]
#[serde(deny_unknown_fields)]
pub struct Time {
    /// Whole seconds (negative before the epoch).
    pub sec: i32,
    /// Nanoseconds within the second, `0..1_000_000_000`.
    pub nanosec: u32,
}

sec_nanosec_conversions!(Time, "time");

/// `builtin_interfaces/msg/Duration`: a signed span of time.
#[derive(
    Debug, Clone, Copy, Default, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize,
)]
#[serde(deny_unknown_fields)]
pub struct Duration {
    /// Whole seconds (negative for negative durations).
    pub sec: i32,
    /// Nanoseconds added to `sec`, `0..1_000_000_000`.
    pub nanosec: u32,
}

sec_nanosec_conversions!(Duration, "duration");

impl Duration {
    /// The same span as a [`std::time::Duration`], or `None` if it is negative.
    pub fn to_std(self) -> Option<std::time::Duration> {
        u64::try_from(self.to_nanos())
            .ok()
            .map(std::time::Duration::from_nanos)
    }

    /// The span of a [`std::time::Duration`], saturating at [`Self::MAX`].
    pub fn from_std(d: std::time::Duration) -> Self {
        Self::from_nanos(i64::try_from(d.as_nanos()).unwrap_or(i64::MAX))
    }
}

impl Time {
    /// The signed span from `earlier` to `self`, saturating at the range of [`Duration`].
    pub fn since(self, earlier: Time) -> Duration {
        Duration::from_nanos(self.to_nanos() - earlier.to_nanos())
    }
}

/// `Time.msg` text.
pub(crate) const TIME_MSG: &str = "\
# A point in time: whole seconds and nanoseconds since the epoch of the clock in use
# (the Unix epoch for system time; the start of the simulation for simulated time).

int32 sec

# Nanoseconds within the second, in [0, 1e9).
uint32 nanosec
";

/// `Duration.msg` text.
pub(crate) const DURATION_MSG: &str = "\
# A signed span of time: whole seconds plus nanoseconds.
# A negative duration has negative sec and nanosec in [0, 1e9).

int32 sec

# Nanoseconds added to sec, in [0, 1e9).
uint32 nanosec
";

impl_ros_message!(Time, "builtin_interfaces/msg/Time", TIME_MSG);
impl_ros_message!(Duration, "builtin_interfaces/msg/Duration", DURATION_MSG);
