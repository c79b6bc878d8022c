//! A curvature-aware reference speed along the track: as fast as the lateral acceleration
//! allows in every bend, braking in time before it.

use dynlab_sim::Track;

use super::RacingError;

/// Reference speed over the arc length of a track: `v(s) = min(v_max, √(a_lat / |κ(s)|))`,
/// lowered so that the car can brake into every bend at `a_brake` (a backward pass around the
/// closed track) and accelerate out of it at `a_accel` (a forward pass).
#[derive(Debug, Clone, PartialEq)]
pub struct SpeedProfile {
    arc: Vec<f64>,
    speed: Vec<f64>,
    length: f64,
    acceleration: f64,
}

impl SpeedProfile {
    /// The profile of `track` with top speed `max_speed` \[m/s\], lateral acceleration
    /// `lateral_acceleration`, braking `braking` and acceleration `acceleration` \[m/s²\]
    /// (all `∞`: constant `max_speed`); curvature averaged over `±smooth` \[m\] of arc length.
    pub fn new(
        track: &Track,
        max_speed: f64,
        lateral_acceleration: f64,
        braking: f64,
        acceleration: f64,
        smooth: f64,
    ) -> Result<Self, RacingError> {
        if !(max_speed > 0.0 && max_speed.is_finite()) {
            return Err(RacingError::setting(
                "reference_speed",
                max_speed,
                "the reference speed must be a finite speed > 0 (m/s)",
            ));
        }
        if !(lateral_acceleration > 0.0 && braking > 0.0 && acceleration > 0.0 && smooth >= 0.0) {
            return Err(RacingError::setting(
                "lateral_acceleration/braking/acceleration/curvature_smoothing",
                format!("{lateral_acceleration} / {braking} / {acceleration} / {smooth}"),
                "accelerations must be > 0 (inf: unlimited) and the smoothing ≥ 0",
            ));
        }
        let arc = track.arc_lengths();
        let length = track.length();
        let n = arc.len();
        let mut speed: Vec<f64> = track
            .curvatures(smooth)
            .iter()
            .map(|k| {
                (lateral_acceleration / k.abs().max(1e-9))
                    .sqrt()
                    .min(max_speed)
            })
            .collect();
        if braking.is_finite() || acceleration.is_finite() {
            let ds = |i: usize| {
                let j = (i + 1) % n;
                if j == 0 {
                    length - arc[i]
                } else {
                    arc[j] - arc[i]
                }
            };
            // twice around: the closed track has no start
            for _ in 0..2 {
                for i in (0..n).rev() {
                    let next = speed[(i + 1) % n];
                    speed[i] = speed[i].min((next * next + 2.0 * braking * ds(i)).sqrt());
                }
                for i in 0..n {
                    let prev = speed[(i + n - 1) % n];
                    let d = ds((i + n - 1) % n);
                    speed[i] = speed[i].min((prev * prev + 2.0 * acceleration * d).sqrt());
                }
            }
        }
        Ok(Self {
            arc,
            speed,
            length,
            acceleration,
        })
    }

    /// Reference speed at arc length `s` \[m\] (any `s`: wrapped around the track; linear
    /// between centre points).
    pub fn speed_at(&self, s: f64) -> f64 {
        let s = s.rem_euclid(self.length);
        let i = self.arc.partition_point(|a| *a <= s).saturating_sub(1);
        let j = (i + 1) % self.arc.len();
        let next_arc = if j == 0 { self.length } else { self.arc[j] };
        let span = next_arc - self.arc[i];
        let t = if span > 0.0 {
            ((s - self.arc[i]) / span).clamp(0.0, 1.0)
        } else {
            0.0
        };
        self.speed[i] + t * (self.speed[j] - self.speed[i])
    }

    /// Slowest reference speed on the track \[m/s\].
    pub fn min_speed(&self) -> f64 {
        self.speed.iter().copied().fold(f64::INFINITY, f64::min)
    }

    /// Reference progress from arc length `s0` after each of `n` control steps of `dt` \[s\]
    /// (`n` values, metres ahead of `s0`), integrating the profile with 4 sub-steps per step.
    pub fn progress(&self, s0: f64, dt: f64, n: usize) -> Vec<f64> {
        self.progress_from_speed(s0, f64::INFINITY, dt, n)
    }

    /// As [`SpeedProfile::progress`], for a car now driving at `v0` \[m/s\]: the reference
    /// speed at time `t` is at most `v0 + a·t` (`a`: the profile's acceleration), so a car slower
    /// than the profile (after a slow cycle, a standing start) is asked to catch up at the
    /// acceleration the profile allows instead of at once (which demands full throttle, in a
    /// bend a spin). `v0 = ∞` (or an unlimited acceleration): the profile itself.
    pub fn progress_from_speed(&self, s0: f64, v0: f64, dt: f64, n: usize) -> Vec<f64> {
        let v0 = if v0.is_nan() { 0.0 } else { v0.max(0.0) };
        let cap = |t: f64| {
            if self.acceleration.is_finite() {
                v0 + self.acceleration * t
            } else {
                f64::INFINITY
            }
        };
        let mut out = Vec::with_capacity(n);
        let mut p = 0.0;
        let h = dt / 4.0;
        let mut t = 0.0;
        for _ in 0..n {
            for _ in 0..4 {
                // midpoint rule
                let mid = p + 0.5 * h * self.speed_at(s0 + p).min(cap(t));
                p += h * self.speed_at(s0 + mid).min(cap(t + 0.5 * h));
                t += h;
            }
            out.push(p);
        }
        out
    }
}
