//! Measurement noise on poses, as a motion-capture system produces it.

use serde::{Deserialize, Serialize};

use crate::error::SimError;
use crate::geometry::{Pose2, finite3, in_range, non_negative};
use crate::rng::SimRng;

/// Mocap-like measurement noise on a planar pose.
///
/// Every measurement draws the same count of random numbers whatever the settings, so changing
/// a standard deviation never shifts the rest of the stream.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct MeasurementNoise {
    /// Gaussian standard deviation on x and y \[m\]. Default 0.0005 (0.5 mm, a good mocap system).
    pub position_std: f64,
    /// Gaussian standard deviation on the heading \[rad\]. Default 0.002 (≈ 0.1°).
    pub yaw_std: f64,
    /// Constant bias added to `[x, y, yaw]` (calibration error). Default zero.
    pub bias: [f64; 3],
    /// Probability that a measurement is an outlier. Default 0 (off).
    pub outlier_probability: f64,
    /// Standard deviation of an outlier's extra position error \[m\]. Default 0.02.
    pub outlier_position_std: f64,
    /// Standard deviation of an outlier's extra heading error \[rad\]. Default 0.2.
    pub outlier_yaw_std: f64,
}

impl Default for MeasurementNoise {
    fn default() -> Self {
        Self {
            position_std: 0.0005,
            yaw_std: 0.002,
            bias: [0.0; 3],
            outlier_probability: 0.0,
            outlier_position_std: 0.02,
            outlier_yaw_std: 0.2,
        }
    }
}

impl MeasurementNoise {
    /// No noise at all: measurements equal the ground truth.
    pub fn none() -> Self {
        Self {
            position_std: 0.0,
            yaw_std: 0.0,
            ..Self::default()
        }
    }

    /// Checks every field; `key` is the table's dotted key (normally `noise`).
    pub fn validate(&self, key: &str) -> Result<(), SimError> {
        non_negative(&format!("{key}.position_std"), self.position_std)?;
        non_negative(&format!("{key}.yaw_std"), self.yaw_std)?;
        finite3(&format!("{key}.bias"), self.bias)?;
        in_range(
            &format!("{key}.outlier_probability"),
            self.outlier_probability,
            0.0,
            1.0,
        )?;
        non_negative(
            &format!("{key}.outlier_position_std"),
            self.outlier_position_std,
        )?;
        non_negative(&format!("{key}.outlier_yaw_std"), self.outlier_yaw_std)
    }

    /// A noisy measurement of `truth`.
    pub fn measure(&self, truth: Pose2, rng: &mut SimRng) -> Pose2 {
        let n = [rng.normal(), rng.normal(), rng.normal()];
        let outlier = rng.bernoulli(self.outlier_probability);
        let o = [rng.normal(), rng.normal(), rng.normal()];
        let mut x = truth.x + self.bias[0] + self.position_std * n[0];
        let mut y = truth.y + self.bias[1] + self.position_std * n[1];
        let mut th = truth.theta + self.bias[2] + self.yaw_std * n[2];
        if outlier {
            x += self.outlier_position_std * o[0];
            y += self.outlier_position_std * o[1];
            th += self.outlier_yaw_std * o[2];
        }
        Pose2::new(x, y, th)
    }
}
