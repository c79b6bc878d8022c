//! Causal car state from measured poses: a Savitzky–Golay fit over the latest poses.

use std::collections::VecDeque;

use dynlab_learn::dynamics::data::{SavGol, savgol};
use dynlab_sim::{CarState, wrap_angle};

use super::plant::State;

/// Estimates `[x, y, ψ, vx, vy, ω]` from time-stamped poses as the model issue's pipeline does
/// (Savitzky–Golay smoothing and differentiation, yaw unwrapped, velocities rotated into the
/// body frame), but causally: the polynomial is fitted to the latest `window` poses and
/// evaluated at the newest stamp (the fit's edge value, as `savgol` does at a trajectory's end).
#[derive(Debug, Clone)]
pub struct CarStateEstimator {
    sg: SavGol,
    buf: VecDeque<(f64, [f64; 3])>,
}

impl CarStateEstimator {
    /// An estimator with the given fit (the default: window 15, order 3).
    pub fn new(sg: SavGol) -> Self {
        Self {
            sg,
            buf: VecDeque::new(),
        }
    }

    /// Forgets every pose.
    pub fn reset(&mut self) {
        self.buf.clear();
    }

    /// Adds a pose `(x, y, ψ)` at time `t` \[s\] and returns the state estimate once `window`
    /// poses are in (`None` before, and for a stamp not after the previous one, which is
    /// dropped).
    pub fn push(&mut self, t: f64, pose: [f64; 3]) -> Option<State> {
        if !(t.is_finite() && pose.iter().all(|v| v.is_finite())) {
            return None;
        }
        if let Some((t_last, p_last)) = self.buf.back() {
            if t <= *t_last {
                return None;
            }
            // unwrap the yaw against the previous sample
            let psi = p_last[2] + wrap_angle(pose[2] - p_last[2]);
            self.buf.push_back((t, [pose[0], pose[1], psi]));
        } else {
            self.buf.push_back((t, pose));
        }
        while self.buf.len() > self.sg.window {
            self.buf.pop_front();
        }
        if self.buf.len() < self.sg.window {
            return None;
        }
        let t: Vec<f64> = self.buf.iter().map(|b| b.0).collect();
        let col = |c: usize| self.buf.iter().map(|b| b.1[c]).collect::<Vec<_>>();
        let (x, xd) = savgol(&t, &col(0), &self.sg).ok()?;
        let (y, yd) = savgol(&t, &col(1), &self.sg).ok()?;
        let (psi, psid) = savgol(&t, &col(2), &self.sg).ok()?;
        let i = t.len() - 1;
        let (s, c) = psi[i].sin_cos();
        Some([
            x[i],
            y[i],
            psi[i],
            c * xd[i] + s * yd[i],
            -s * xd[i] + c * yd[i],
            psid[i],
        ])
    }
}

impl CarStateEstimator {
    /// The state a racer sees in a simulated run at time `t`: the estimate from the measured
    /// `pose` (`estimate`) or the simulator's true state; while the estimator has fewer than a
    /// window of poses, the car is still at its known standing `start`.
    pub(crate) fn observe(
        &mut self,
        estimate: bool,
        t: f64,
        pose: [f64; 3],
        truth: &CarState,
        start: &CarState,
    ) -> State {
        let measured = if estimate {
            self.push(t, pose)
        } else {
            Some([truth.x, truth.y, truth.psi, truth.vx, truth.vy, truth.omega])
        };
        measured.unwrap_or([start.x, start.y, start.psi, 0.0, 0.0, 0.0])
    }
}

impl Default for CarStateEstimator {
    fn default() -> Self {
        Self::new(SavGol::default())
    }
}
