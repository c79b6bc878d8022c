//! Planar poses, regions of the table or floor, and oriented boxes.

use serde::{Deserialize, Serialize};

use crate::error::SimError;

/// A planar pose: position `(x, y)` in metres and heading `theta` in radians, wrapped to (−π, π].
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Pose2 {
    /// x position \[m\].
    pub x: f64,
    /// y position \[m\].
    pub y: f64,
    /// Heading \[rad\].
    pub theta: f64,
}

impl Pose2 {
    /// A pose from its three components (the heading is wrapped).
    pub fn new(x: f64, y: f64, theta: f64) -> Self {
        Self {
            x,
            y,
            theta: wrap_angle(theta),
        }
    }

    /// From `[x, y, θ]`.
    pub fn from_array(a: [f64; 3]) -> Self {
        Self::new(a[0], a[1], a[2])
    }

    /// As `[x, y, θ]`.
    pub fn to_array(self) -> [f64; 3] {
        [self.x, self.y, self.theta]
    }

    /// All components finite.
    pub fn is_finite(self) -> bool {
        self.x.is_finite() && self.y.is_finite() && self.theta.is_finite()
    }

    /// A point given in this pose's frame, expressed in the world frame.
    pub fn transform_point(self, p: [f64; 2]) -> [f64; 2] {
        let (s, c) = self.theta.sin_cos();
        [self.x + c * p[0] - s * p[1], self.y + s * p[0] + c * p[1]]
    }

    /// Distance between the positions of two poses.
    pub fn distance(self, other: Pose2) -> f64 {
        (self.x - other.x).hypot(self.y - other.y)
    }
}

/// Wraps an angle to (−π, π].
pub fn wrap_angle(a: f64) -> f64 {
    use std::f64::consts::{PI, TAU};
    if a > -PI && a <= PI {
        return a;
    }
    let w = a - TAU * ((a + PI) / TAU).floor();
    if w <= -PI { w + TAU } else { w }
}

/// The shape of a [`Region`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RegionShape {
    /// A rectangle: `centre`, `size` (full side lengths), `angle`.
    #[default]
    Rect,
    /// A disc: `centre`, `radius`.
    Disc,
    /// An unbounded straight strip (a stripe across the whole floor): the points within
    /// `width / 2` of the line through `centre` running along `angle`, i.e.
    /// `|n · (p − centre)| ≤ width / 2` with the normal `n = (−sin angle, cos angle)`.
    Band,
    /// A ring: `inner_radius ≤ |p − centre| ≤ radius`.
    Annulus,
}

/// A region of the table or floor (a rectangle, a disc, a band or an annulus), used by patch
/// effects. Each shape reads only its own keys; the others keep their defaults and are ignored.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Region {
    /// `"rect"` (default), `"disc"`, `"band"` or `"annulus"`.
    pub shape: RegionShape,
    /// Centre \[m\] (band: a point on its centre line).
    pub centre: [f64; 2],
    /// Rectangle side lengths \[m\] (rect only). Default 0.2 × 0.2 m.
    pub size: [f64; 2],
    /// Rectangle rotation, or the direction the band runs along \[rad\] (rect and band).
    /// Default 0.
    pub angle: f64,
    /// Disc radius, or the annulus's outer radius \[m\] (disc and annulus). Default 0.1 m.
    pub radius: f64,
    /// Full width of a band \[m\] (band only). Default 0.2 m.
    pub width: f64,
    /// Inner radius of an annulus \[m\], `< radius` (annulus only). Default 0.05 m.
    pub inner_radius: f64,
}

impl Default for Region {
    fn default() -> Self {
        Self {
            shape: RegionShape::Rect,
            centre: [0.0, 0.0],
            size: [0.2, 0.2],
            angle: 0.0,
            radius: 0.1,
            width: 0.2,
            inner_radius: 0.05,
        }
    }
}

impl Region {
    /// Whether the world point `p` lies inside (boundary included).
    pub fn contains(&self, p: [f64; 2]) -> bool {
        let d = [p[0] - self.centre[0], p[1] - self.centre[1]];
        match self.shape {
            RegionShape::Disc => d[0] * d[0] + d[1] * d[1] <= self.radius * self.radius,
            RegionShape::Rect => {
                let (s, c) = self.angle.sin_cos();
                let lx = c * d[0] + s * d[1];
                let ly = -s * d[0] + c * d[1];
                lx.abs() <= 0.5 * self.size[0] && ly.abs() <= 0.5 * self.size[1]
            }
            RegionShape::Band => {
                let (s, c) = self.angle.sin_cos();
                (-s * d[0] + c * d[1]).abs() <= 0.5 * self.width
            }
            RegionShape::Annulus => {
                let r2 = d[0] * d[0] + d[1] * d[1];
                r2 <= self.radius * self.radius && r2 >= self.inner_radius * self.inner_radius
            }
        }
    }

    /// Rejects non-finite or non-positive dimensions; `key` is this region's dotted key.
    pub(crate) fn validate(&self, key: &str) -> Result<(), SimError> {
        finite2(&format!("{key}.centre"), self.centre)?;
        finite(&format!("{key}.angle"), self.angle)?;
        match self.shape {
            RegionShape::Rect => {
                positive(&format!("{key}.size[0]"), self.size[0])?;
                positive(&format!("{key}.size[1]"), self.size[1])?;
            }
            RegionShape::Disc => positive(&format!("{key}.radius"), self.radius)?,
            RegionShape::Band => positive(&format!("{key}.width"), self.width)?,
            RegionShape::Annulus => {
                positive(&format!("{key}.radius"), self.radius)?;
                non_negative(&format!("{key}.inner_radius"), self.inner_radius)?;
                if self.inner_radius >= self.radius {
                    return Err(SimError::invalid(
                        format!("{key}.inner_radius"),
                        format!(
                            "must be < {key}.radius ({}), got {}",
                            self.radius, self.inner_radius
                        ),
                    ));
                }
            }
        }
        Ok(())
    }
}

/// An oriented rectangle (block footprint or obstacle), for overlap tests.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OrientedBox {
    /// Centre pose (heading = rotation of the box).
    pub pose: Pose2,
    /// Half side lengths \[m\].
    pub half: [f64; 2],
}

impl OrientedBox {
    fn axes(&self) -> [[f64; 2]; 2] {
        let (s, c) = self.pose.theta.sin_cos();
        [[c, s], [-s, c]]
    }

    /// Half-extent of the box projected on unit axis `a`.
    fn radius_on(&self, a: [f64; 2]) -> f64 {
        let ax = self.axes();
        self.half[0] * (ax[0][0] * a[0] + ax[0][1] * a[1]).abs()
            + self.half[1] * (ax[1][0] * a[0] + ax[1][1] * a[1]).abs()
    }

    /// Separating-axis test: `true` when the two rectangles overlap (touching counts).
    pub fn overlaps(&self, other: &OrientedBox) -> bool {
        let d = [other.pose.x - self.pose.x, other.pose.y - self.pose.y];
        for a in self.axes().into_iter().chain(other.axes()) {
            let dist = (d[0] * a[0] + d[1] * a[1]).abs();
            if dist > self.radius_on(a) + other.radius_on(a) {
                return false;
            }
        }
        true
    }
}

pub(crate) fn finite(key: &str, v: f64) -> Result<(), SimError> {
    if v.is_finite() {
        Ok(())
    } else {
        Err(SimError::invalid(
            key,
            format!("must be a finite number, got {v}"),
        ))
    }
}

pub(crate) fn finite2(key: &str, v: [f64; 2]) -> Result<(), SimError> {
    finite(&format!("{key}[0]"), v[0])?;
    finite(&format!("{key}[1]"), v[1])
}

pub(crate) fn finite3(key: &str, v: [f64; 3]) -> Result<(), SimError> {
    for (i, x) in v.iter().enumerate() {
        finite(&format!("{key}[{i}]"), *x)?;
    }
    Ok(())
}

pub(crate) fn positive(key: &str, v: f64) -> Result<(), SimError> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(SimError::invalid(key, format!("must be > 0, got {v}")))
    }
}

pub(crate) fn non_negative(key: &str, v: f64) -> Result<(), SimError> {
    if v.is_finite() && v >= 0.0 {
        Ok(())
    } else {
        Err(SimError::invalid(key, format!("must be ≥ 0, got {v}")))
    }
}

pub(crate) fn in_range(key: &str, v: f64, lo: f64, hi: f64) -> Result<(), SimError> {
    if v.is_finite() && v >= lo && v <= hi {
        Ok(())
    } else {
        Err(SimError::invalid(
            key,
            format!("must be within [{lo}, {hi}], got {v}"),
        ))
    }
}
