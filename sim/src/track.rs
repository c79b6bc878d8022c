//! A closed race track: centre line with inner and outer borders.

use serde::Deserialize;

use crate::error::SimError;
use crate::geometry::{Pose2, wrap_angle};

/// A race track as a polyline centre line with borders (the MPCC `track.json` layout).
#[derive(Debug, Clone, PartialEq)]
pub struct Track {
    centre: Vec<[f64; 2]>,
    half_width: Vec<f64>,
    /// Cumulative arc length at each centre point.
    cum: Vec<f64>,
    /// Length of the closed centre line.
    total: f64,
}

#[derive(Deserialize)]
#[allow(non_snake_case)]
struct TrackFile {
    X: Vec<f64>,
    Y: Vec<f64>,
    X_i: Vec<f64>,
    Y_i: Vec<f64>,
    X_o: Vec<f64>,
    Y_o: Vec<f64>,
}

/// Where a point is relative to the track.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackProjection {
    /// Index of the centre-line segment the point projects onto.
    pub segment: usize,
    /// Signed lateral offset from the centre line \[m\] (left positive).
    pub lateral: f64,
    /// Heading of the centre line there \[rad\].
    pub heading: f64,
    /// Half width of the track there \[m\].
    pub half_width: f64,
}

impl Track {
    /// A track from centre points and half widths (at least 3 points; the loop closes itself).
    pub fn new(centre: Vec<[f64; 2]>, half_width: Vec<f64>) -> Result<Self, SimError> {
        let bad = |m: String| SimError::Track {
            origin: "<memory>".into(),
            message: m,
        };
        if centre.len() < 3 || centre.len() != half_width.len() {
            return Err(bad(format!(
                "need ≥ 3 centre points and one half width each, got {} and {}",
                centre.len(),
                half_width.len()
            )));
        }
        if centre
            .iter()
            .flatten()
            .chain(&half_width)
            .any(|v| !v.is_finite())
            || half_width.iter().any(|w| *w <= 0.0)
        {
            return Err(bad(
                "every coordinate must be finite and every width > 0".into()
            ));
        }
        let mut t = Self {
            centre,
            half_width,
            cum: Vec::new(),
            total: 0.0,
        };
        t.cum = t.arc_lengths();
        let n = t.centre.len();
        let (a, b) = (t.centre[n - 1], t.centre[0]);
        t.total = t.cum[n - 1] + (b[0] - a[0]).hypot(b[1] - a[1]);
        Ok(t)
    }

    /// Parses the MPCC JSON layout (`X, Y, X_i, Y_i, X_o, Y_o` arrays, metres).
    pub fn from_json_str(text: &str, origin: &str) -> Result<Self, SimError> {
        let f: TrackFile = serde_json::from_str(text).map_err(|e| SimError::Track {
            origin: origin.into(),
            message: format!("{e}; expected arrays X, Y, X_i, Y_i, X_o, Y_o"),
        })?;
        let n = f.X.len();
        if [
            f.Y.len(),
            f.X_i.len(),
            f.Y_i.len(),
            f.X_o.len(),
            f.Y_o.len(),
        ]
        .iter()
        .any(|&l| l != n)
        {
            return Err(SimError::Track {
                origin: origin.into(),
                message: "arrays X, Y, X_i, Y_i, X_o, Y_o must have the same length".into(),
            });
        }
        let centre: Vec<[f64; 2]> = (0..n).map(|i| [f.X[i], f.Y[i]]).collect();
        let half_width = (0..n)
            .map(|i| 0.5 * (f.X_o[i] - f.X_i[i]).hypot(f.Y_o[i] - f.Y_i[i]))
            .collect();
        Self::new(centre, half_width).map_err(|e| match e {
            SimError::Track { message, .. } => SimError::Track {
                origin: origin.into(),
                message,
            },
            other => other,
        })
    }

    /// Reads a track file.
    pub fn from_file(path: impl AsRef<std::path::Path>) -> Result<Self, SimError> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path).map_err(|source| SimError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        Self::from_json_str(&text, &path.display().to_string())
    }

    /// An oval (two straights and two half circles) centred at the origin, for tests and demos.
    pub fn oval(
        straight: f64,
        radius: f64,
        half_width: f64,
        points: usize,
    ) -> Result<Self, SimError> {
        let n = points.max(8);
        let perimeter = 2.0 * straight + std::f64::consts::TAU * radius;
        let mut centre = Vec::with_capacity(n);
        for i in 0..n {
            let s = perimeter * i as f64 / n as f64;
            let p = if s < straight {
                [-0.5 * straight + s, -radius]
            } else if s < straight + std::f64::consts::PI * radius {
                let a = (s - straight) / radius - std::f64::consts::FRAC_PI_2;
                [0.5 * straight + radius * a.cos(), radius * a.sin()]
            } else if s < 2.0 * straight + std::f64::consts::PI * radius {
                let d = s - straight - std::f64::consts::PI * radius;
                [0.5 * straight - d, radius]
            } else {
                let a = (s - 2.0 * straight - std::f64::consts::PI * radius) / radius
                    + std::f64::consts::FRAC_PI_2;
                [-0.5 * straight + radius * a.cos(), radius * a.sin()]
            };
            centre.push(p);
        }
        Self::new(centre, vec![half_width; n])
    }

    /// Number of centre points.
    pub fn len(&self) -> usize {
        self.centre.len()
    }

    /// Always false (a track has ≥ 3 points).
    pub fn is_empty(&self) -> bool {
        self.centre.is_empty()
    }

    /// Centre point `i` (wrapping around).
    pub fn point(&self, i: usize) -> [f64; 2] {
        self.centre[i % self.centre.len()]
    }

    /// The first centre point, heading along the track.
    pub fn start_pose(&self) -> Pose2 {
        let a = self.point(0);
        let b = self.point(1);
        Pose2::new(a[0], a[1], (b[1] - a[1]).atan2(b[0] - a[0]))
    }

    /// Lower corner of the bounding box grown by `margin`.
    pub fn bounds_min(&self, margin: f64) -> [f64; 2] {
        let w = self.half_width.iter().cloned().fold(0.0, f64::max);
        let x = self
            .centre
            .iter()
            .map(|p| p[0])
            .fold(f64::INFINITY, f64::min);
        let y = self
            .centre
            .iter()
            .map(|p| p[1])
            .fold(f64::INFINITY, f64::min);
        [x - w - margin, y - w - margin]
    }

    /// Upper corner of the bounding box grown by `margin`.
    pub fn bounds_max(&self, margin: f64) -> [f64; 2] {
        let w = self.half_width.iter().cloned().fold(0.0, f64::max);
        let x = self
            .centre
            .iter()
            .map(|p| p[0])
            .fold(f64::NEG_INFINITY, f64::max);
        let y = self
            .centre
            .iter()
            .map(|p| p[1])
            .fold(f64::NEG_INFINITY, f64::max);
        [x + w + margin, y + w + margin]
    }

    /// Projects a point onto the closest centre-line segment.
    pub fn project(&self, p: [f64; 2]) -> TrackProjection {
        let n = self.centre.len();
        let best = self.nearest_segment(p, 0, n);
        let i = best.1;
        let a = self.centre[i];
        let b = self.centre[(i + 1) % n];
        let heading = (b[1] - a[1]).atan2(b[0] - a[0]);
        let (s, c) = heading.sin_cos();
        let lateral = -(p[0] - a[0]) * s + (p[1] - a[1]) * c;
        let hw = self.half_width[i] + best.2 * (self.half_width[(i + 1) % n] - self.half_width[i]);
        TrackProjection {
            segment: i,
            lateral,
            heading: wrap_angle(heading),
            half_width: hw,
        }
    }

    /// Whether a point lies on the track surface.
    pub fn contains(&self, p: [f64; 2]) -> bool {
        let pr = self.project(p);
        pr.lateral.abs() <= pr.half_width
    }

    /// The centre point roughly `distance` metres ahead of segment `from` along the track.
    pub fn ahead(&self, from: usize, distance: f64) -> [f64; 2] {
        let n = self.centre.len();
        let mut left = distance;
        let mut i = from % n;
        for _ in 0..n {
            let a = self.centre[i];
            let b = self.centre[(i + 1) % n];
            let l = (b[0] - a[0]).hypot(b[1] - a[1]);
            if l >= left {
                let f = if l > 0.0 { left / l } else { 0.0 };
                return [a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1])];
            }
            left -= l;
            i = (i + 1) % n;
        }
        self.centre[i]
    }
}

/// Where a point is along the track, with arc length and the local frame (see [`Track::locate`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackLocation {
    /// Index of the centre-line segment the point projects onto.
    pub segment: usize,
    /// Arc length of the projection along the centre line from point 0 \[m\], in `[0, length)`.
    pub arc: f64,
    /// Unit tangent of the centre line there (direction of travel).
    pub tangent: [f64; 2],
    /// Unit left normal of the centre line there.
    pub normal: [f64; 2],
    /// Signed lateral offset from the centre line \[m\] (left positive).
    pub lateral: f64,
    /// Half width of the track there \[m\].
    pub half_width: f64,
}

impl Track {
    /// Length of the closed centre line \[m\].
    pub fn length(&self) -> f64 {
        self.total
    }

    /// Centre-line curvature at every centre point \[1/m\] (turning angle between the adjacent
    /// segments over their mean length; left turns positive), averaged over `±smooth` \[m\] of
    /// arc length (a car's line through a bend is wider than the centre line's: 0 = raw).
    pub fn curvatures(&self, smooth: f64) -> Vec<f64> {
        let n = self.centre.len();
        let seg = |i: usize| {
            let a = self.centre[i % n];
            let b = self.centre[(i + 1) % n];
            [b[0] - a[0], b[1] - a[1]]
        };
        let raw: Vec<f64> = (0..n)
            .map(|i| {
                let (p, q) = (seg(i + n - 1), seg(i));
                let turn = wrap_angle(q[1].atan2(q[0]) - p[1].atan2(p[0]));
                let len = 0.5 * (p[0].hypot(p[1]) + q[0].hypot(q[1]));
                if len > 0.0 { turn / len } else { 0.0 }
            })
            .collect();
        if smooth <= 0.0 {
            return raw;
        }
        let len = self.total;
        (0..n)
            .map(|i| {
                // total turning within ±smooth over the arc length covered
                let (mut turn, mut j) = (0.0, 0usize);
                let arc_dist = |a: usize, b: usize| {
                    let d = (self.cum[b % n] - self.cum[a % n]).abs();
                    d.min(len - d)
                };
                let mut sum_len = 0.0f64;
                while j < n && arc_dist(i, i + n - j) <= smooth {
                    let k = (i + n - j) % n;
                    turn += raw[k];
                    sum_len += 1.0;
                    j += 1;
                }
                j = 1;
                while j < n && arc_dist(i, i + j) <= smooth {
                    turn += raw[(i + j) % n];
                    sum_len += 1.0;
                    j += 1;
                }
                turn / sum_len.max(1.0)
            })
            .collect()
    }

    /// Arc length from point 0 to centre point `i` \[m\] (cumulative, `i < len()`).
    fn arc_at(&self, i: usize) -> f64 {
        self.cum[i]
    }

    /// Cumulative arc length at every centre point \[m\] (`len()` values, the first 0).
    pub fn arc_lengths(&self) -> Vec<f64> {
        let mut out = Vec::with_capacity(self.centre.len());
        let mut acc = 0.0;
        for i in 0..self.centre.len() {
            out.push(acc);
            let a = self.centre[i];
            let b = self.centre[(i + 1) % self.centre.len()];
            acc += (b[0] - a[0]).hypot(b[1] - a[1]);
        }
        out
    }

    /// Inner and outer border points at centre point `i` (centre ∓ half width along the normal;
    /// inner = right of the direction of travel is not assumed: `[left, right]`).
    pub fn borders(&self, i: usize) -> [[f64; 2]; 2] {
        let n = self.centre.len();
        let a = self.centre[i % n];
        let b = self.centre[(i + 1) % n];
        let l = (b[0] - a[0]).hypot(b[1] - a[1]).max(1e-12);
        let nrm = [-(b[1] - a[1]) / l, (b[0] - a[0]) / l];
        let w = self.half_width[i % n];
        [
            [a[0] + w * nrm[0], a[1] + w * nrm[1]],
            [a[0] - w * nrm[0], a[1] - w * nrm[1]],
        ]
    }

    /// Projects a point onto the closest centre-line segment, with arc length and local frame.
    pub fn locate(&self, p: [f64; 2]) -> TrackLocation {
        let n = self.centre.len();
        self.locate_among(p, 0, n)
    }

    /// As [`Track::locate`], searching only the `window` segments on either side of `hint`
    /// (cheap tracking of a moving point; falls back to a full search when the best segment is
    /// at the edge of the window).
    pub fn locate_near(&self, p: [f64; 2], hint: usize, window: usize) -> TrackLocation {
        let n = self.centre.len();
        if 2 * window + 1 >= n {
            return self.locate(p);
        }
        let start = (hint % n + n - window) % n;
        let loc = self.locate_among(p, start, 2 * window + 1);
        let off = (loc.segment + n - start) % n;
        if off == 0 || off == 2 * window {
            self.locate(p)
        } else {
            loc
        }
    }

    /// The centre-line segment nearest to `p` among `count` segments from `start` (wrapping):
    /// (squared distance, segment index, parameter t ∈ \[0, 1\] along it).
    fn nearest_segment(&self, p: [f64; 2], start: usize, count: usize) -> (f64, usize, f64) {
        let n = self.centre.len();
        let mut best = (f64::INFINITY, start % n, 0.0f64);
        for k in 0..count {
            let i = (start + k) % n;
            let a = self.centre[i];
            let b = self.centre[(i + 1) % n];
            let d = [b[0] - a[0], b[1] - a[1]];
            let l2 = d[0] * d[0] + d[1] * d[1];
            let t = if l2 > 0.0 {
                (((p[0] - a[0]) * d[0] + (p[1] - a[1]) * d[1]) / l2).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let q = [a[0] + t * d[0], a[1] + t * d[1]];
            let dist2 = (p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2);
            if dist2 < best.0 {
                best = (dist2, i, t);
            }
        }
        best
    }

    fn locate_among(&self, p: [f64; 2], start: usize, count: usize) -> TrackLocation {
        let n = self.centre.len();
        let best = self.nearest_segment(p, start, count);
        let (i, t) = (best.1, best.2);
        let a = self.centre[i];
        let b = self.centre[(i + 1) % n];
        let seg = (b[0] - a[0]).hypot(b[1] - a[1]);
        let l = seg.max(1e-12);
        let tangent = [(b[0] - a[0]) / l, (b[1] - a[1]) / l];
        let normal = [-tangent[1], tangent[0]];
        let lateral = (p[0] - a[0]) * normal[0] + (p[1] - a[1]) * normal[1];
        let half_width =
            self.half_width[i] + t * (self.half_width[(i + 1) % n] - self.half_width[i]);
        TrackLocation {
            segment: i,
            arc: self.arc_at(i) + t * seg,
            tangent,
            normal,
            lateral,
            half_width,
        }
    }
}

#[cfg(test)]
mod locate_tests {
    use super::*;

    #[test]
    fn locate_gives_arc_length_and_lateral_offset_on_an_oval() {
        let t = Track::oval(2.0, 0.5, 0.2, 200).unwrap();
        let len = 4.0 + std::f64::consts::TAU * 0.5;
        assert!((t.length() - len).abs() < 0.01, "{}", t.length());
        // on the first straight, 0.5 m along and 0.1 m to the left
        let loc = t.locate([-0.5, -0.4]);
        assert!((loc.arc - 0.5).abs() < 1e-9, "{loc:?}");
        assert!((loc.lateral - 0.1).abs() < 1e-9);
        assert!((loc.tangent[0] - 1.0).abs() < 1e-12);
        let near = t.locate_near([-0.5, -0.4], loc.segment + 3, 10);
        assert_eq!(near, loc);
        // a hint far away falls back to the full search
        let far = t.locate_near([-0.5, -0.4], loc.segment + 100, 5);
        assert_eq!(far, loc);
    }

    #[test]
    fn curvatures_of_an_oval_are_zero_on_the_straights_and_one_over_the_radius_in_the_bends() {
        let (straight, radius) = (2.0, 0.5);
        let t = Track::oval(straight, radius, 0.2, 400).unwrap();
        let arcs = t.arc_lengths();
        for smooth in [0.0, 0.1] {
            let k = t.curvatures(smooth);
            for (i, s) in arcs.iter().enumerate() {
                // away from the joints by more than the smoothing and one segment
                let in_bend = *s > straight + smooth + 0.05
                    && *s < straight + std::f64::consts::PI * radius - smooth - 0.05;
                let on_straight = *s > smooth + 0.05 && *s < straight - smooth - 0.05;
                if in_bend {
                    assert!((k[i] - 1.0 / radius).abs() < 0.02, "{smooth} {s}: {}", k[i]);
                }
                if on_straight {
                    assert!(k[i].abs() < 1e-9, "{smooth} {s}: {}", k[i]);
                }
            }
        }
        assert!((t.length() - t.arc_lengths()[399] - t.length() / 400.0).abs() < 1e-3);
    }
}
