//! Causal car state from measured poses: a Savitzky–Golay fit over the latest poses.

use std::collections::VecDeque;

use dynlab_learn::dynamics::data::{SavGol, savgol};
use dynlab_sim::{CarState, wrap_angle};

use super::plant::State;

/// Estimates `[x, y, ψ, vx, vy, ω]` from time-stamped poses as the model issue's pipeline does
/// (Savitzky–Golay smoothing and differentiation, yaw unwrapped, velocities rotated into the
/// body frame), but causally: the polynomial is fitted to the latest `window` poses (the yaw's
/// to the latest `yaw_window`) and evaluated at the newest stamp (the fit's edge value, as
/// `savgol` does at a trajectory's end).
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

    /// Adds a pose `(x, y, ψ)` at time `t` \[s\] and returns the state estimate once
    /// [`SavGol::span`] poses are in (`None` before, and for a stamp not after the previous one, which is
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
        let span = self.sg.span();
        while self.buf.len() > span {
            self.buf.pop_front();
        }
        if self.buf.len() < span {
            return None;
        }
        // each component's fit over its own latest window, evaluated at the newest pose
        let newest = |c: usize| {
            let sg = self.sg.for_component(c, span);
            let tail = self.buf.range(span.saturating_sub(sg.window)..);
            let t: Vec<f64> = tail.clone().map(|b| b.0).collect();
            let v: Vec<f64> = tail.map(|b| b.1[c]).collect();
            let (value, slope) = savgol(&t, &v, &sg).ok()?;
            Some((value[sg.window - 1], slope[sg.window - 1]))
        };
        let (x, xd) = newest(0)?;
        let (y, yd) = newest(1)?;
        let (psi, psid) = newest(2)?;
        let (s, c) = psi.sin_cos();
        Some([x, y, psi, c * xd + s * yd, -s * xd + c * yd, psid])
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

#[cfg(test)]
mod tests {
    use super::*;
    use dynlab_learn::dynamics::data::{Trajectory, car_states};

    /// The causal estimate at each pose is the offline pipeline's state at the newest pose of
    /// the same poses, with the position's and the yaw's windows each their own.
    #[test]
    fn the_estimate_is_the_offline_state_at_the_window_edge_with_a_window_per_component() {
        let sg = SavGol {
            window: 21,
            yaw_window: Some(11),
            ..SavGol::default()
        };
        let mut est = CarStateEstimator::new(sg);
        let dt_ns = 10_000_000_i64;
        // a curving drive with a wobble, the yaw through ±π
        let pose = |i: i64| {
            let t = i as f64 * 1e-2;
            let psi = 2.5 + 0.9 * t + 0.05 * (7.0 * t).sin();
            [1.2 * t.cos() + 0.3 * t, 0.8 * t.sin(), wrap_angle(psi)]
        };
        let mut poses = Vec::new();
        let mut checked = 0;
        let mut last = None;
        for i in 0..120 {
            poses.push(pose(i));
            let got = est.push(i as f64 * 1e-2, pose(i));
            if poses.len() < sg.span() {
                assert!(got.is_none(), "an estimate from {} poses", poses.len());
                continue;
            }
            let tail = &poses[poses.len() - sg.span()..];
            let mut unwrapped: Vec<[f64; 3]> = tail.to_vec();
            for k in 1..unwrapped.len() {
                unwrapped[k][2] = unwrapped[k - 1][2] + wrap_angle(tail[k][2] - tail[k - 1][2]);
            }
            let traj = Trajectory {
                t_ns: (0..sg.span() as i64).map(|k| k * dt_ns).collect(),
                pose: unwrapped,
                u: Vec::new(),
                dim_u: 0,
                dt: 1e-2,
                resampled: false,
            };
            let want = *car_states(&traj, &sg).unwrap().last().unwrap();
            let got = got.expect("an estimate once a span of poses is in");
            last = Some(got);
            assert!(
                (wrap_angle(got[2] - want[2])).abs() < 1e-9,
                "yaw {got:?} vs {want:?}"
            );
            for c in [0, 1, 3, 4, 5] {
                assert!(
                    (got[c] - want[c]).abs() < 1e-7,
                    "state {c}: {got:?} vs {want:?}"
                );
            }
            checked += 1;
        }
        assert_eq!(checked, 120 - sg.span() + 1);
        // with the yaw on the position's window, ω differs: the windows are each their own
        let mut one = CarStateEstimator::new(SavGol {
            yaw_window: None,
            ..sg
        });
        let both = (0..120)
            .filter_map(|i| one.push(i as f64 * 1e-2, pose(i)))
            .last()
            .unwrap();
        let last = last.unwrap();
        assert_eq!(both[0..2], last[0..2]);
        assert!(
            (both[5] - last[5]).abs() > 1e-6,
            "ω {} vs {}",
            both[5],
            last[5]
        );
    }
}
