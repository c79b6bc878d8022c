//! The planar pushing world: a block on a table pushed quasi-statically by a disc pusher
//! (after Tu & Lin), on rapier2d with hand-written Coulomb table friction.
//!
//! # Model
//!
//! rapier2d sees the table from above, so it has no table under the block; table friction is
//! ours. The block's footprint carries an `N × N` grid of support points (cell centres). Each
//! point `i` carries a normal load `Nᵢ` (uniform, or linearly varying so that the load centroid
//! is the centre of mass under `com_offset`) and a friction coefficient `μᵢ` (`table_friction`,
//! or the patch's `mu` when the point lies on a `friction_patch`). Before every physics step the
//! force at each point is the force that would stop that point's share of the mass within the
//! step, `Fᵢ = −(mᵢ vᵢ / dt + mᵢ/m · F_ext)`, clamped to the Coulomb cone `|Fᵢ| ≤ μᵢ Nᵢ`; when it
//! is clamped the point slides and the force is `−μᵢ Nᵢ vᵢ/|vᵢ|`. This is Coulomb friction with
//! exact sticking: a block at rest under a tilt below the friction angle does not creep, a block
//! whose pusher stops stops, and a block pushed off-centre turns about the point its support
//! distribution dictates. On an anisotropic table (`anisotropic_friction`) the cone is an
//! ellipse and a sliding point takes the force of maximum dissipation on it
//! ([`AnisotropicFriction`]). The forces and the torque about the centre of mass go to rapier as
//! user forces; rapier solves the block–pusher and block–obstacle contacts.
//!
//! The pusher is a kinematic disc. An action `[p, φ, ℓ]` (Tu & Lin's convention, from their
//! `panda_pushing_env`) places the pusher behind the block's −x face (the edge facing away from
//! the block's heading) at lateral offset `p · b/2 · location_margin` in the block frame, a small
//! `approach_gap` away; the pusher approaches along the block heading until it touches, then
//! moves along `θ + φ` for `ℓ · push_scale`, with a trapezoidal speed profile whose deceleration
//! is below `μ g` (so the block stops with the pusher), is lifted off and the block settles.
//! Quasi-static: with the default speed (0.1 m/s) inertial effects are a fraction of a millimetre.

use rapier2d::prelude::*;
use serde::{Deserialize, Serialize};

use crate::error::SimError;
use crate::geometry::{
    OrientedBox, Pose2, Region, finite, finite2, finite3, in_range, non_negative, positive,
};
use crate::noise::MeasurementNoise;
use crate::rng::SimRng;
use crate::scenario_file;

/// Standard gravity \[m/s²\].
pub const GRAVITY: f64 = 9.81;

/// One push, in Tu & Lin's action space.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct PushAction {
    /// `p ∈ [−1, 1]`: where along the pushed edge (block frame +y is +1).
    pub location: f64,
    /// `φ ∈ [−π/2, π/2]`: push direction relative to the block heading \[rad\].
    pub angle: f64,
    /// `ℓ ∈ [0, 1]`: push length as a fraction of `pusher.push_scale` (0.1 m).
    pub length: f64,
}

impl PushAction {
    /// An action from `[p, φ, ℓ]`.
    pub fn new(location: f64, angle: f64, length: f64) -> Self {
        Self {
            location,
            angle,
            length,
        }
    }

    /// The action clipped into the action space (as Tu & Lin's environment does).
    pub fn clamped(self) -> Self {
        use std::f64::consts::FRAC_PI_2;
        Self {
            location: self.location.clamp(-1.0, 1.0),
            angle: self.angle.clamp(-FRAC_PI_2, FRAC_PI_2),
            length: self.length.clamp(0.0, 1.0),
        }
    }

    /// Checks that every component is finite and inside the action space.
    pub fn validate(&self) -> Result<(), SimError> {
        use std::f64::consts::FRAC_PI_2;
        let check = |what: &'static str, v: f64, lo: f64, hi: f64| {
            if v.is_finite() && v >= lo && v <= hi {
                Ok(())
            } else {
                Err(SimError::Input {
                    what,
                    message: format!(
                        "must be within [{lo}, {hi}], got {v}; clip it (PushAction::clamped)"
                    ),
                })
            }
        };
        check("PushAction.location", self.location, -1.0, 1.0)?;
        check("PushAction.angle", self.angle, -FRAC_PI_2, FRAC_PI_2)?;
        check("PushAction.length", self.length, 0.0, 1.0)
    }
}

/// The block and its contact with the table.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct BlockParams {
    /// Footprint `[a, b]` \[m\]: `a` along the block heading (x), `b` across (y). Default 0.1 × 0.1
    /// (Tu & Lin).
    pub size: [f64; 2],
    /// Mass \[kg\]. Default 10 (Tu & Lin's PyBullet block).
    pub mass: f64,
    /// Block–table Coulomb coefficient μ. Default 0.1 (Tu & Lin).
    pub table_friction: f64,
    /// Support points per side of the footprint grid (`N × N` points). Default 5. Used by the
    /// `grid` layout only.
    pub support_grid: u32,
    /// Where the block rests on the table: `grid` (default: the `N × N` cell centres, close to a
    /// uniform pressure) or `corners` (the four footprint corners, as a rigid box on a plane is
    /// resolved by PyBullet and most point-contact engines; it turns about 2× less per
    /// off-centre push).
    pub support: SupportLayout,
    /// Block–obstacle Coulomb coefficient (rapier contact). Default 0.3.
    pub obstacle_friction: f64,
}

impl Default for BlockParams {
    fn default() -> Self {
        Self {
            size: [0.1, 0.1],
            mass: 10.0,
            table_friction: 0.1,
            support_grid: 5,
            support: SupportLayout::Grid,
            obstacle_friction: 0.3,
        }
    }
}

/// Where a block's weight meets the table (see [`BlockParams::support`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum SupportLayout {
    /// Cell centres of an `N × N` grid over the footprint.
    #[default]
    Grid,
    /// The four corners of the footprint.
    Corners,
}

/// The pusher and its motion.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PusherParams {
    /// Disc radius \[m\]. Default 0.01 (a finger tip).
    pub radius: f64,
    /// Cruise speed \[m/s\]. Default 0.1.
    pub speed: f64,
    /// Acceleration and deceleration \[m/s²\]. Default 0.4 (below μ g ≈ 0.98, so the block stops
    /// with the pusher instead of sliding on).
    pub acceleration: f64,
    /// Distance between pusher and face before the approach \[m\]. Default 0.002.
    pub approach_gap: f64,
    /// Push length for `ℓ = 1` \[m\]. Default 0.1 (Tu & Lin).
    pub push_scale: f64,
    /// Fraction of the half edge that `p = ±1` reaches. Default 0.95 (Tu & Lin's 5 % gap).
    pub location_margin: f64,
    /// Time the block is left to settle after the pusher is lifted \[s\]. Default 0.2.
    pub settle_time: f64,
    /// Half the width of a flat pusher \[m\]: a pad `2·radius` thick and this wide on each
    /// side, held at the world yaw `pad_yaw` whatever the block's heading, as a gripper kept at
    /// one orientation pushes (Tu & Lin's Panda). Turned against the pushed face, it touches
    /// with a corner, off the commanded point, and the block turns until face and pad align.
    /// Not in the diagnosis library. Default 0: the disc of `radius`.
    pub pad_half_width: f64,
    /// World yaw of the flat pusher's face normal \[rad\] (with `pad_half_width > 0`). Default 0.
    pub pad_yaw: f64,
}

impl Default for PusherParams {
    fn default() -> Self {
        Self {
            radius: 0.01,
            speed: 0.1,
            acceleration: 0.4,
            approach_gap: 0.002,
            push_scale: 0.1,
            location_margin: 0.95,
            settle_time: 0.2,
            pad_half_width: 0.0,
            pad_yaw: 0.0,
        }
    }
}

/// Integration settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PushSimParams {
    /// Physics step \[s\]. Default 0.002 (500 Hz).
    pub dt: f64,
    /// Rate at which [`PushOutcome::trajectory`] samples the block pose \[Hz\]. Default 100.
    pub sample_rate: f64,
}

impl Default for PushSimParams {
    fn default() -> Self {
        Self {
            dt: 0.002,
            sample_rate: 100.0,
        }
    }
}

/// The usable table area (the explorer ends an episode when the block leaves it).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TableParams {
    /// Lower corner `[x, y]` \[m\]. Default `[0.0, −0.5]`.
    pub min: [f64; 2],
    /// Upper corner `[x, y]` \[m\]. Default `[1.0, 0.5]`.
    pub max: [f64; 2],
}

impl Default for TableParams {
    fn default() -> Self {
        Self {
            min: [0.0, -0.5],
            max: [1.0, 0.5],
        }
    }
}

impl TableParams {
    /// Whether a point lies on the table.
    pub fn contains(&self, p: [f64; 2]) -> bool {
        p[0] >= self.min[0] && p[0] <= self.max[0] && p[1] >= self.min[1] && p[1] <= self.max[1]
    }
}

/// A fixed rectangular obstacle on the table.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Obstacle {
    /// Centre \[m\]. Default `[0.6, 0.2]` (Tu & Lin).
    pub centre: [f64; 2],
    /// Side lengths \[m\]. Default `[0.1, 0.5]` (Tu & Lin).
    pub size: [f64; 2],
    /// Rotation \[rad\]. Default 0.
    pub angle: f64,
}

impl Default for Obstacle {
    fn default() -> Self {
        Self {
            centre: [0.6, 0.2],
            size: [0.1, 0.5],
            angle: 0.0,
        }
    }
}

impl Obstacle {
    /// The obstacle's footprint.
    pub fn footprint(&self) -> OrientedBox {
        OrientedBox {
            pose: Pose2::new(self.centre[0], self.centre[1], self.angle),
            half: [0.5 * self.size[0], 0.5 * self.size[1]],
        }
    }
}

/// Hidden effect: the centre of mass is not at the block's geometric centre.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ComOffset {
    /// Switch; a present table is on unless this is `false`. Default true.
    pub enabled: bool,
    /// Offset `[x, y]` in the block frame \[m\]. Default `[0.02, 0.0]`.
    pub offset: [f64; 2],
}

impl Default for ComOffset {
    fn default() -> Self {
        Self {
            enabled: true,
            offset: [0.02, 0.0],
        }
    }
}

/// Hidden effect: the table is tilted, so gravity has a component along it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TableTilt {
    /// Switch. Default true.
    pub enabled: bool,
    /// Downhill direction in the table frame \[rad\]. Default 0 (+x).
    pub direction: f64,
    /// Slope angle \[rad\]. Default 0.02 (≈ 1.1°, below the friction angle atan 0.1 ≈ 5.7°).
    pub angle: f64,
}

impl Default for TableTilt {
    fn default() -> Self {
        Self {
            enabled: true,
            direction: 0.0,
            angle: 0.02,
        }
    }
}

/// Hidden effect: a region of the table with another friction coefficient, applied per
/// support point (a block partly on it feels a torque).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FrictionPatch {
    /// Switch. Default true.
    pub enabled: bool,
    /// Block–table μ on the patch. Default 0.3.
    pub mu: f64,
    /// Where the patch is. Default a 0.2 × 0.2 m square at (0.6, 0).
    pub region: Region,
}

impl Default for FrictionPatch {
    fn default() -> Self {
        Self {
            enabled: true,
            mu: 0.3,
            region: Region {
                centre: [0.6, 0.0],
                ..Region::default()
            },
        }
    }
}

/// Hidden effect: friction between pusher and block (nominal: frictionless contact).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PusherFriction {
    /// Switch. Default true.
    pub enabled: bool,
    /// Pusher–block μ. Default 0.5.
    pub mu: f64,
}

impl Default for PusherFriction {
    fn default() -> Self {
        Self {
            enabled: true,
            mu: 0.5,
        }
    }
}

/// Hidden effect: anisotropic block–table friction (a brushed or grooved table surface).
///
/// The table has a grain direction `e₁ = (cos angle, sin angle)` and the cross direction
/// `e₂ = (−sin angle, cos angle)`. At a support point with coefficient μ (the table's
/// `table_friction`, or the patch's `mu` on a `friction_patch`: the grain runs under the whole
/// table) and load N the friction coefficients are `μ₁ = μ` along the grain and
/// `μ₂ = ratio · μ` across it. The set of friction forces the point can carry is the ellipse
///
/// ```text
/// (F·e₁ / (μ₁ N))² + (F·e₂ / (μ₂ N))² ≤ 1
/// ```
///
/// (an elliptic limit surface; Goyal, Ruina & Papadopoulos 1991). A sticking point takes the
/// force that stops it if that force is inside the ellipse (exact sticking, as for isotropic
/// friction). A sliding point with velocity `v = v₁ e₁ + v₂ e₂` takes the force of maximum
/// dissipation on the ellipse,
///
/// ```text
/// F = −N (μ₁² v₁ e₁ + μ₂² v₂ e₂) / √(μ₁² v₁² + μ₂² v₂²)
/// ```
///
/// which is `−μ₁ N` along the grain for sliding along it, `−μ₂ N` across, and for sliding at
/// an angle is not anti-parallel to the velocity: a block pushed obliquely to the grain veers
/// towards the grain. `ratio = 1` is isotropic Coulomb friction (the same forces up to rounding).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct AnisotropicFriction {
    /// Switch. Default true.
    pub enabled: bool,
    /// `μ₂ / μ₁`, friction across the grain over friction along it (> 0, ≤ 100). Default 2.
    pub ratio: f64,
    /// Grain direction in the table frame \[rad\]. Default 0 (along +x: μ_y = 2 μ_x).
    pub angle: f64,
}

impl Default for AnisotropicFriction {
    fn default() -> Self {
        Self {
            enabled: true,
            ratio: 2.0,
            angle: 0.0,
        }
    }
}

/// The hidden effects of the pushing world; each is off unless its table is present.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PushEffects {
    /// Centre of mass off the geometric centre.
    pub com_offset: Option<ComOffset>,
    /// Tilted table.
    pub table_tilt: Option<TableTilt>,
    /// A patch of other friction.
    pub friction_patch: Option<FrictionPatch>,
    /// Pusher–block friction.
    pub pusher_friction: Option<PusherFriction>,
    /// Friction that differs along and across a grain of the table (not in the diagnosis
    /// library).
    pub anisotropic_friction: Option<AnisotropicFriction>,
}

impl PushEffects {
    /// Names of the effects that are switched on.
    pub fn active(&self) -> Vec<&'static str> {
        let mut v = Vec::new();
        if on(&self.com_offset, |e| e.enabled).is_some() {
            v.push("com_offset");
        }
        if on(&self.table_tilt, |e| e.enabled).is_some() {
            v.push("table_tilt");
        }
        if on(&self.friction_patch, |e| e.enabled).is_some() {
            v.push("friction_patch");
        }
        if on(&self.pusher_friction, |e| e.enabled).is_some() {
            v.push("pusher_friction");
        }
        if on(&self.anisotropic_friction, |e| e.enabled).is_some() {
            v.push("anisotropic_friction");
        }
        v
    }
}

fn on<T>(e: &Option<T>, enabled: impl Fn(&T) -> bool) -> Option<&T> {
    e.as_ref().filter(|x| enabled(x))
}

/// Everything that defines a pushing world. Loadable from TOML; every key has a default.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PushScenario {
    /// A name for reports. Default `"free"`.
    pub name: String,
    /// Seed for measurement noise when a node runs this scenario live. Default 0.
    pub seed: u64,
    /// Start pose `[x, y, θ]`. Default `[0.4, 0, 0.2π]` (Tu & Lin, free space).
    pub start: [f64; 3],
    /// Goal pose `[x, y, θ]`. Default `[0.8, 0, 0]`.
    pub goal: [f64; 3],
    /// The block.
    pub block: BlockParams,
    /// The pusher.
    pub pusher: PusherParams,
    /// Integration.
    pub sim: PushSimParams,
    /// The table area.
    pub table: TableParams,
    /// Fixed obstacles (`[[obstacles]]`). Default none.
    pub obstacles: Vec<Obstacle>,
    /// Hidden effects (`[effects.<name>]`). Default none.
    pub effects: PushEffects,
    /// Measurement noise on the block pose.
    pub noise: MeasurementNoise,
}

impl Default for PushScenario {
    fn default() -> Self {
        Self::free()
    }
}

impl PushScenario {
    /// Tu & Lin's free-space scene: start (0.4, 0, 0.2π), goal (0.8, 0, 0).
    pub fn free() -> Self {
        Self {
            name: "free".into(),
            seed: 0,
            start: [0.4, 0.0, 0.2 * std::f64::consts::PI],
            goal: [0.8, 0.0, 0.0],
            block: BlockParams::default(),
            pusher: PusherParams::default(),
            sim: PushSimParams::default(),
            table: TableParams::default(),
            obstacles: Vec::new(),
            effects: PushEffects::default(),
            noise: MeasurementNoise::default(),
        }
    }

    /// Tu & Lin's obstacle scene: a 0.1 × 0.5 m box at (0.6, 0.2), start (0.4, 0, −0.2π),
    /// goal (0.8, −0.1, 0).
    pub fn obstacle() -> Self {
        Self {
            name: "obstacle".into(),
            start: [0.4, 0.0, -0.2 * std::f64::consts::PI],
            goal: [0.8, -0.1, 0.0],
            obstacles: vec![Obstacle::default()],
            ..Self::free()
        }
    }

    /// Parses a TOML scenario and validates it.
    pub fn from_toml_str(text: &str) -> Result<Self, SimError> {
        let s: Self = scenario_file::parse(text, "<string>")?;
        s.validate()?;
        Ok(s)
    }

    /// Reads a TOML scenario file and validates it.
    pub fn from_file(path: impl AsRef<std::path::Path>) -> Result<Self, SimError> {
        let s: Self = scenario_file::load(path.as_ref())?;
        s.validate()?;
        Ok(s)
    }

    /// As TOML text (round-trips through [`PushScenario::from_toml_str`]).
    pub fn to_toml_string(&self) -> String {
        toml::to_string(self).unwrap_or_default()
    }

    /// The start pose.
    pub fn start_pose(&self) -> Pose2 {
        Pose2::from_array(self.start)
    }

    /// The goal pose.
    pub fn goal_pose(&self) -> Pose2 {
        Pose2::from_array(self.goal)
    }

    /// The block footprint at `pose`.
    pub fn block_footprint(&self, pose: Pose2) -> OrientedBox {
        OrientedBox {
            pose,
            half: [0.5 * self.block.size[0], 0.5 * self.block.size[1]],
        }
    }

    /// Whether the block at `pose` overlaps any obstacle.
    pub fn collides(&self, pose: Pose2) -> bool {
        let b = self.block_footprint(pose);
        self.obstacles.iter().any(|o| o.footprint().overlaps(&b))
    }

    /// Rejects impossible values; the error names the key and what to set.
    pub fn validate(&self) -> Result<(), SimError> {
        finite3("start", self.start)?;
        finite3("goal", self.goal)?;
        let b = &self.block;
        positive("block.size[0]", b.size[0])?;
        positive("block.size[1]", b.size[1])?;
        positive("block.mass", b.mass)?;
        non_negative("block.table_friction", b.table_friction)?;
        non_negative("block.obstacle_friction", b.obstacle_friction)?;
        if !(1..=32).contains(&b.support_grid) {
            return Err(SimError::invalid(
                "block.support_grid",
                format!("must be within [1, 32], got {}", b.support_grid),
            ));
        }
        let p = &self.pusher;
        positive("pusher.radius", p.radius)?;
        positive("pusher.speed", p.speed)?;
        positive("pusher.acceleration", p.acceleration)?;
        non_negative("pusher.approach_gap", p.approach_gap)?;
        positive("pusher.push_scale", p.push_scale)?;
        in_range("pusher.location_margin", p.location_margin, 0.0, 1.0)?;
        non_negative("pusher.settle_time", p.settle_time)?;
        non_negative("pusher.pad_half_width", p.pad_half_width)?;
        finite("pusher.pad_yaw", p.pad_yaw)?;
        positive("sim.dt", self.sim.dt)?;
        if self.sim.dt > 0.02 {
            return Err(SimError::invalid(
                "sim.dt",
                format!("must be ≤ 0.02 s for stable contacts, got {}", self.sim.dt),
            ));
        }
        positive("sim.sample_rate", self.sim.sample_rate)?;
        finite2("table.min", self.table.min)?;
        finite2("table.max", self.table.max)?;
        if self.table.min[0] >= self.table.max[0] || self.table.min[1] >= self.table.max[1] {
            return Err(SimError::invalid(
                "table.max",
                format!(
                    "must be greater than table.min in x and y, got min {:?} max {:?}",
                    self.table.min, self.table.max
                ),
            ));
        }
        for (i, o) in self.obstacles.iter().enumerate() {
            finite2(&format!("obstacles[{i}].centre"), o.centre)?;
            positive(&format!("obstacles[{i}].size[0]"), o.size[0])?;
            positive(&format!("obstacles[{i}].size[1]"), o.size[1])?;
            finite(&format!("obstacles[{i}].angle"), o.angle)?;
        }
        let e = &self.effects;
        if let Some(c) = &e.com_offset {
            finite2("effects.com_offset.offset", c.offset)?;
            for k in 0..2 {
                if c.offset[k].abs() > 0.5 * b.size[k] {
                    return Err(SimError::invalid(
                        format!("effects.com_offset.offset[{k}]"),
                        format!(
                            "must lie inside the block footprint (|offset| ≤ {}), got {}",
                            0.5 * b.size[k],
                            c.offset[k]
                        ),
                    ));
                }
            }
        }
        if let Some(t) = &e.table_tilt {
            finite("effects.table_tilt.direction", t.direction)?;
            in_range("effects.table_tilt.angle", t.angle, 0.0, 0.5)?;
        }
        if let Some(f) = &e.friction_patch {
            non_negative("effects.friction_patch.mu", f.mu)?;
            f.region.validate("effects.friction_patch.region")?;
        }
        if let Some(f) = &e.pusher_friction {
            non_negative("effects.pusher_friction.mu", f.mu)?;
        }
        if let Some(a) = &e.anisotropic_friction {
            if !(a.ratio.is_finite() && a.ratio > 0.0 && a.ratio <= 100.0) {
                return Err(SimError::invalid(
                    "effects.anisotropic_friction.ratio",
                    format!(
                        "must be within (0, 100] (μ across the grain over μ along it; 1 is isotropic), got {}",
                        a.ratio
                    ),
                ));
            }
            finite("effects.anisotropic_friction.angle", a.angle)?;
        }
        self.noise.validate("noise")
    }

    /// This scenario with the physical constants of block, table and pusher each scaled by a
    /// factor drawn uniformly from `[1 − fraction, 1 + fraction]` (seeded: the same seed gives
    /// the same world): a block whose true friction and geometry differ from the nominal ones,
    /// for tests of identification and diagnosis.
    ///
    /// Scaled, in this order: `block.size[0]`, `block.size[1]`, `block.mass`,
    /// `block.table_friction`, `block.obstacle_friction`, `pusher.radius`. Kept: the pusher's
    /// motion (speed, acceleration, gaps, `push_scale`: the commanded, known part), the support
    /// layout, the integration settings, the poses, obstacles, effects and noise.
    ///
    /// Errors: `fraction` outside `[0, 1)`; the perturbed scenario failing
    /// [`PushScenario::validate`] (e.g. a `com_offset` outside the shrunken block).
    pub fn perturbed(&self, seed: u64, fraction: f64) -> Result<Self, SimError> {
        crate::rng::check_fraction("PushScenario::perturbed fraction", fraction)?;
        let mut s = self.clone();
        let mut f = crate::rng::Perturb::new(seed, fraction);
        let [a, b] = &mut s.block.size;
        for v in [
            a,
            b,
            &mut s.block.mass,
            &mut s.block.table_friction,
            &mut s.block.obstacle_friction,
            &mut s.pusher.radius,
        ] {
            f.scale(v);
        }
        s.validate()?;
        Ok(s)
    }

    /// Duration of the pusher motion for `action` (approach plus push) \[s\].
    pub fn push_motion_time(&self, action: &PushAction) -> f64 {
        let l = self.pusher.approach_gap + action.length.clamp(0.0, 1.0) * self.pusher.push_scale;
        Trapezoid::new(l, self.pusher.speed, self.pusher.acceleration).duration
    }

    /// The longest time a push can take, motion plus settling \[s\].
    pub fn max_push_time(&self) -> f64 {
        self.push_motion_time(&PushAction::new(0.0, 0.0, 1.0)) + self.pusher.settle_time
    }
}

/// A trapezoidal (or triangular) speed profile over a path of length `length`.
#[derive(Debug, Clone, Copy)]
struct Trapezoid {
    length: f64,
    speed: f64,
    accel: f64,
    t_acc: f64,
    duration: f64,
}

impl Trapezoid {
    fn new(length: f64, speed: f64, accel: f64) -> Self {
        let t_full = speed / accel;
        if length >= speed * t_full {
            Self {
                length,
                speed,
                accel,
                t_acc: t_full,
                duration: length / speed + t_full,
            }
        } else {
            let t_acc = (length / accel).sqrt();
            Self {
                length,
                speed: accel * t_acc,
                accel,
                t_acc,
                duration: 2.0 * t_acc,
            }
        }
    }

    /// Arc length reached at time `t`.
    fn position(&self, t: f64) -> f64 {
        let t = t.clamp(0.0, self.duration);
        let d_acc = 0.5 * self.accel * self.t_acc * self.t_acc;
        if t <= self.t_acc {
            0.5 * self.accel * t * t
        } else if t <= self.duration - self.t_acc {
            d_acc + self.speed * (t - self.t_acc)
        } else {
            let r = self.duration - t;
            self.length - 0.5 * self.accel * r * r
        }
    }
}

/// The block pose at a time since the push began.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TimedPose {
    /// Time since the push began \[s\].
    pub t: f64,
    /// Ground-truth block pose.
    pub pose: Pose2,
}

/// What one push did.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PushOutcome {
    /// The action applied.
    pub action: PushAction,
    /// Block pose before the push.
    pub start_pose: Pose2,
    /// Block pose sampled at `sim.sample_rate` from the start to the end of settling.
    pub trajectory: Vec<TimedPose>,
    /// Block pose after settling.
    pub final_pose: Pose2,
    /// Push duration including settling \[s\].
    pub duration: f64,
    /// Whether the pusher touched the block at all.
    pub contact_made: bool,
    /// Whether the pusher touched the block and had lost contact when its motion ended
    /// (slid off the edge, or pushed so obliquely that it left the face).
    pub lost_contact: bool,
    /// Whether the block touched an obstacle during the push.
    pub obstacle_collision: bool,
}

/// A push in progress.
#[derive(Debug, Clone)]
struct ActivePush {
    action: PushAction,
    start_pose: Pose2,
    /// Pusher centre path: start, touching point, end.
    path: [[f64; 2]; 3],
    profile: Trapezoid,
    /// Physics steps since the push began.
    step: u64,
    motion_steps: u64,
    total_steps: u64,
    contact_made: bool,
    in_contact: bool,
    obstacle_collision: bool,
}

#[derive(Debug, Clone, Copy)]
struct SupportPoint {
    /// Position in the block frame (relative to the geometric centre) \[m\].
    local: [f64; 2],
    /// Normal load \[N\].
    load: f64,
    /// Share of the mass \[kg\].
    mass: f64,
}

/// A pushing world. Single-threaded and deterministic: the same scenario and the same calls
/// give bit-identical poses.
pub struct PushWorld {
    scenario: PushScenario,
    world: PhysicsWorld,
    block: RigidBodyHandle,
    block_collider: ColliderHandle,
    pusher: RigidBodyHandle,
    pusher_collider: ColliderHandle,
    obstacle_colliders: Vec<ColliderHandle>,
    support: Vec<SupportPoint>,
    /// Gravity along the table when tilted \[N\] (world frame).
    tilt_force: Option<[f64; 2]>,
    steps: u64,
    push: Option<ActivePush>,
    last_outcome: Option<PushOutcome>,
}

impl std::fmt::Debug for PushWorld {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PushWorld")
            .field("scenario", &self.scenario.name)
            .field("steps", &self.steps)
            .field("block_pose", &self.block_pose())
            .finish()
    }
}

impl PushWorld {
    /// Builds the world with the block at the scenario's start pose.
    pub fn new(scenario: &PushScenario) -> Result<Self, SimError> {
        scenario.validate()?;
        let s = scenario.clone();
        let mut world = PhysicsWorld::new();
        world.gravity = Vector::ZERO;
        world.integration_parameters.dt = s.sim.dt as f32;
        world.integration_parameters.length_unit = 0.1;

        let [a, b] = s.block.size;
        let m = s.block.mass;
        let com = on(&s.effects.com_offset, |e| e.enabled).map_or([0.0, 0.0], |c| c.offset);
        // Inertia of the uniform box about its centroid; with a com offset the block is taken to
        // carry the same inertia about its (shifted) centre of mass.
        let inertia = m * (a * a + b * b) / 12.0;
        let start = s.start_pose();
        let block_body = RigidBodyBuilder::dynamic()
            .pose(Pose::new(
                Vector::new(start.x as f32, start.y as f32),
                start.theta as f32,
            ))
            .additional_mass_properties(MassProperties::new(
                Vector::new(com[0] as f32, com[1] as f32),
                m as f32,
                inertia as f32,
            ))
            .can_sleep(false)
            .build();
        let block_collider = ColliderBuilder::cuboid((0.5 * a) as f32, (0.5 * b) as f32)
            .density(0.0)
            .friction(1.0)
            .friction_combine_rule(CoefficientCombineRule::Min)
            .restitution(0.0)
            .build();
        let block = world.bodies.insert(block_body);
        let block_collider =
            world
                .colliders
                .insert_with_parent(block_collider, block, &mut world.bodies);

        let pusher_mu = on(&s.effects.pusher_friction, |e| e.enabled).map_or(0.0, |p| p.mu);
        let pusher_body = RigidBodyBuilder::kinematic_position_based()
            .translation(Vector::new(-10.0, -10.0))
            .build();
        let pusher_collider = match s.pusher.pad_half_width > 0.0 {
            true => ColliderBuilder::cuboid(s.pusher.radius as f32, s.pusher.pad_half_width as f32),
            false => ColliderBuilder::ball(s.pusher.radius as f32),
        }
        .friction(pusher_mu as f32)
        .friction_combine_rule(CoefficientCombineRule::Min)
        .restitution(0.0)
        .enabled(false)
        .build();
        let pusher = world.bodies.insert(pusher_body);
        let pusher_collider =
            world
                .colliders
                .insert_with_parent(pusher_collider, pusher, &mut world.bodies);

        let mut obstacle_colliders = Vec::new();
        for o in &s.obstacles {
            let body = RigidBodyBuilder::fixed()
                .pose(Pose::new(
                    Vector::new(o.centre[0] as f32, o.centre[1] as f32),
                    o.angle as f32,
                ))
                .build();
            let h = world.bodies.insert(body);
            let c = ColliderBuilder::cuboid((0.5 * o.size[0]) as f32, (0.5 * o.size[1]) as f32)
                .friction(s.block.obstacle_friction as f32)
                .friction_combine_rule(CoefficientCombineRule::Min)
                .restitution(0.0)
                .build();
            obstacle_colliders.push(world.colliders.insert_with_parent(c, h, &mut world.bodies));
        }

        let tilt = on(&s.effects.table_tilt, |e| e.enabled);
        let normal_total = match tilt {
            Some(t) => m * GRAVITY * t.angle.cos(),
            None => m * GRAVITY,
        };
        let tilt_force = tilt.map(|t| {
            let f = m * GRAVITY * t.angle.sin();
            [f * t.direction.cos(), f * t.direction.sin()]
        });
        let support = support_points(&s.block, com, normal_total);
        debug_assert!(support.iter().all(|p| p.mass >= 0.0));
        Ok(Self {
            scenario: s,
            world,
            block,
            block_collider,
            pusher,
            pusher_collider,
            obstacle_colliders,
            support,
            tilt_force,
            steps: 0,
            push: None,
            last_outcome: None,
        })
    }

    /// The scenario this world was built from.
    pub fn scenario(&self) -> &PushScenario {
        &self.scenario
    }

    /// Puts the block at rest at `pose` and cancels any push in progress.
    pub fn reset(&mut self, pose: Pose2) -> Result<(), SimError> {
        if !pose.is_finite() {
            return Err(SimError::Input {
                what: "PushWorld::reset pose",
                message: format!("must be finite, got {pose:?}"),
            });
        }
        let body = &mut self.world.bodies[self.block];
        body.set_position(
            Pose::new(Vector::new(pose.x as f32, pose.y as f32), pose.theta as f32),
            true,
        );
        body.set_linvel(Vector::ZERO, true);
        body.set_angvel(0.0, true);
        body.reset_forces(true);
        body.reset_torques(true);
        self.lift_pusher();
        self.push = None;
        // Refresh contacts so nothing from the old pose survives into the next step.
        self.world.detect_collisions(&(), &());
        Ok(())
    }

    /// Ground-truth pose of the block's geometric centre.
    pub fn block_pose(&self) -> Pose2 {
        let body = &self.world.bodies[self.block];
        let t = body.translation();
        Pose2::new(t.x as f64, t.y as f64, body.rotation().angle() as f64)
    }

    /// Ground-truth block velocity `[vx, vy, ω]` (world frame, at the centre of mass).
    pub fn block_velocity(&self) -> [f64; 3] {
        let body = &self.world.bodies[self.block];
        let v = body.linvel();
        [v.x as f64, v.y as f64, body.angvel() as f64]
    }

    /// A noisy measurement of the block pose (the scenario's `noise`).
    pub fn measure(&self, rng: &mut SimRng) -> Pose2 {
        self.scenario.noise.measure(self.block_pose(), rng)
    }

    /// Simulated time since construction \[s\].
    pub fn time(&self) -> f64 {
        self.steps as f64 * self.scenario.sim.dt
    }

    /// Physics steps since construction.
    pub fn steps(&self) -> u64 {
        self.steps
    }

    /// The physics step \[s\].
    pub fn dt(&self) -> f64 {
        self.scenario.sim.dt
    }

    /// Whether a push is in progress (pusher moving or block settling).
    pub fn push_active(&self) -> bool {
        self.push.is_some()
    }

    /// The outcome of the last completed push, taken (a second call returns `None`).
    pub fn take_outcome(&mut self) -> Option<PushOutcome> {
        self.last_outcome.take()
    }

    /// Starts a push from the current block pose; advance it with [`PushWorld::step`].
    /// A push already in progress is abandoned.
    pub fn begin_push(&mut self, action: PushAction) -> Result<(), SimError> {
        action.validate()?;
        let s = &self.scenario;
        let pose = self.block_pose();
        let [a, b] = s.block.size;
        // how far the pusher reaches towards the face ahead of its centre: a flat pusher turned
        // against the face by β reaches with a corner
        let beta = s.pusher.pad_yaw - pose.theta;
        let r = s.pusher.radius;
        let reach = match s.pusher.pad_half_width > 0.0 {
            true => r * beta.cos().abs() + s.pusher.pad_half_width * beta.sin().abs(),
            false => r,
        };
        let lateral = action.location * 0.5 * b * s.pusher.location_margin;
        let touch = [-0.5 * a - reach, lateral];
        let start = [touch[0] - s.pusher.approach_gap, lateral];
        let push_len = action.length * s.pusher.push_scale;
        let end = [
            touch[0] + push_len * action.angle.cos(),
            touch[1] + push_len * action.angle.sin(),
        ];
        let path = [
            pose.transform_point(start),
            pose.transform_point(touch),
            pose.transform_point(end),
        ];
        let profile = Trapezoid::new(
            s.pusher.approach_gap + push_len,
            s.pusher.speed,
            s.pusher.acceleration,
        );
        let dt = s.sim.dt;
        let motion_steps = (profile.duration / dt).ceil() as u64;
        let settle_steps = (s.pusher.settle_time / dt).ceil() as u64;
        {
            let pusher = &mut self.world.bodies[self.pusher];
            let p0 = Pose::new(
                Vector::new(path[0][0] as f32, path[0][1] as f32),
                s.pusher.pad_yaw as f32,
            );
            pusher.set_position(p0, true);
            pusher.set_next_kinematic_position(p0);
        }
        if let Some(c) = self.world.colliders.get_mut(self.pusher_collider) {
            c.set_enabled(true);
        }
        self.push = Some(ActivePush {
            action,
            start_pose: pose,
            path,
            profile,
            step: 0,
            motion_steps,
            total_steps: motion_steps + settle_steps,
            contact_made: false,
            in_contact: false,
            obstacle_collision: false,
        });
        Ok(())
    }

    fn lift_pusher(&mut self) {
        if let Some(c) = self.world.colliders.get_mut(self.pusher_collider) {
            c.set_enabled(false);
        }
        let far = Vector::new(-10.0, -10.0);
        let pusher = &mut self.world.bodies[self.pusher];
        pusher.set_translation(far, true);
        pusher.set_next_kinematic_translation(far);
    }

    /// Advances the world by one physics step (`sim.dt`). This is the one step function used by
    /// headless collection and by a live node alike.
    pub fn step(&mut self) {
        let dt = self.scenario.sim.dt;
        let mut lift = false;
        if let Some(p) = &mut self.push {
            p.step += 1;
            if p.step <= p.motion_steps {
                let s = p.profile.position(p.step as f64 * dt);
                let target = path_point(&p.path, s);
                self.world.bodies[self.pusher].set_next_kinematic_translation(Vector::new(
                    target[0] as f32,
                    target[1] as f32,
                ));
            } else if p.step == p.motion_steps + 1 {
                lift = true;
            }
        }
        if lift {
            self.lift_pusher();
        }

        let idle = self.push.is_none() && self.tilt_force.is_none() && {
            let v = self.block_velocity();
            v[0] == 0.0 && v[1] == 0.0 && v[2] == 0.0
        };
        if !idle {
            self.apply_table_forces();
            self.world.step();
        }
        self.steps += 1;

        if let Some(p) = &mut self.push {
            let touching = self
                .world
                .narrow_phase
                .contact_pair(self.block_collider, self.pusher_collider)
                .is_some_and(|c| c.has_any_active_contact());
            if p.step <= p.motion_steps {
                p.contact_made |= touching;
                p.in_contact = touching;
            }
            for &o in &self.obstacle_colliders {
                p.obstacle_collision |= self
                    .world
                    .narrow_phase
                    .contact_pair(self.block_collider, o)
                    .is_some_and(|c| c.has_any_active_contact());
            }
            if p.step >= p.total_steps {
                let done = self.push.take();
                if let Some(p) = done {
                    self.last_outcome = Some(PushOutcome {
                        action: p.action,
                        start_pose: p.start_pose,
                        trajectory: Vec::new(),
                        final_pose: self.block_pose(),
                        duration: p.total_steps as f64 * dt,
                        contact_made: p.contact_made,
                        lost_contact: p.contact_made && !p.in_contact && p.action.length > 0.0,
                        obstacle_collision: p.obstacle_collision,
                    });
                }
            }
        }
    }

    /// Applies one push from the current pose and runs it to the end of settling.
    pub fn apply(&mut self, action: PushAction) -> Result<PushOutcome, SimError> {
        self.begin_push(action)?;
        self.last_outcome = None;
        let every =
            ((1.0 / (self.scenario.sim.sample_rate * self.scenario.sim.dt)).round() as u64).max(1);
        let t0 = self.steps;
        let mut trajectory = vec![TimedPose {
            t: 0.0,
            pose: self.block_pose(),
        }];
        while self.push.is_some() {
            self.step();
            let k = self.steps - t0;
            if k.is_multiple_of(every) || self.push.is_none() {
                trajectory.push(TimedPose {
                    t: k as f64 * self.scenario.sim.dt,
                    pose: self.block_pose(),
                });
            }
        }
        let mut outcome = self.last_outcome.take().ok_or(SimError::Input {
            what: "PushWorld::apply",
            message: "the push ended without an outcome (internal state lost)".into(),
        })?;
        outcome.trajectory = trajectory;
        Ok(outcome)
    }

    /// Table friction (and tilt) as user forces on the block for the next step.
    fn apply_table_forces(&mut self) {
        let dt = self.scenario.sim.dt;
        let m = self.scenario.block.mass;
        let mu_table = self.scenario.block.table_friction;
        let patch = on(&self.scenario.effects.friction_patch, |e| e.enabled);
        // Grain frame of an anisotropic table: (μ₂/μ₁, cos, sin).
        let grain = on(&self.scenario.effects.anisotropic_friction, |e| e.enabled).map(|a| {
            let (s, c) = a.angle.sin_cos();
            (a.ratio, c, s)
        });
        let ext = self.tilt_force;
        let body = &self.world.bodies[self.block];
        let t = body.translation();
        let (origin, angle) = ([t.x as f64, t.y as f64], body.rotation().angle() as f64);
        let c = body.center_of_mass();
        let com = [c.x as f64, c.y as f64];
        let v = body.linvel();
        let (vx, vy, w) = (v.x as f64, v.y as f64, body.angvel() as f64);
        let (sn, cs) = angle.sin_cos();
        let mut force = [0.0f64; 2];
        let mut torque = 0.0f64;
        for sp in &self.support {
            let r = [
                origin[0] + cs * sp.local[0] - sn * sp.local[1],
                origin[1] + sn * sp.local[0] + cs * sp.local[1],
            ];
            let arm = [r[0] - com[0], r[1] - com[1]];
            let vi = [vx - w * arm[1], vy + w * arm[0]];
            let mu = match patch {
                Some(p) if p.region.contains(r) => p.mu,
                _ => mu_table,
            };
            let limit = mu * sp.load;
            let mut need = [-sp.mass * vi[0] / dt, -sp.mass * vi[1] / dt];
            if let Some(f) = ext {
                need[0] -= f[0] * sp.mass / m;
                need[1] -= f[1] * sp.mass / m;
            }
            let need_norm = need[0].hypot(need[1]);
            let fi = if let Some((ratio, c, s)) = grain {
                elliptic_friction(need, vi, [limit, ratio * limit], c, s)
            } else if need_norm <= limit {
                need
            } else {
                let speed = vi[0].hypot(vi[1]);
                if speed > 1e-9 {
                    [-limit * vi[0] / speed, -limit * vi[1] / speed]
                } else {
                    [limit * need[0] / need_norm, limit * need[1] / need_norm]
                }
            };
            force[0] += fi[0];
            force[1] += fi[1];
            torque += arm[0] * fi[1] - arm[1] * fi[0];
        }
        if let Some(f) = ext {
            force[0] += f[0];
            force[1] += f[1];
        }
        let body = &mut self.world.bodies[self.block];
        body.reset_forces(false);
        body.reset_torques(false);
        body.add_force(Vector::new(force[0] as f32, force[1] as f32), false);
        body.add_torque(torque as f32, false);
    }
}

/// Friction force at one support point on an anisotropic table (see
/// [`AnisotropicFriction`]): `need` is the force that would stop the point within the step,
/// `v` its velocity, `limit = [μ₁ N, μ₂ N]` the ellipse's half axes along the grain
/// `(c, s)` and across it. All vectors in the world frame.
fn elliptic_friction(need: [f64; 2], v: [f64; 2], limit: [f64; 2], c: f64, s: f64) -> [f64; 2] {
    let [l1, l2] = limit;
    if l1 <= 0.0 || l2 <= 0.0 {
        return [0.0, 0.0];
    }
    let to_grain = |p: [f64; 2]| [c * p[0] + s * p[1], -s * p[0] + c * p[1]];
    let n = to_grain(need);
    let e = (n[0] / l1).powi(2) + (n[1] / l2).powi(2);
    let f = if e <= 1.0 {
        n
    } else {
        let vg = to_grain(v);
        let q = (l1 * vg[0]).hypot(l2 * vg[1]);
        if v[0].hypot(v[1]) > 1e-9 && q > 0.0 {
            [-l1 * l1 * vg[0] / q, -l2 * l2 * vg[1] / q]
        } else {
            let k = e.sqrt();
            [n[0] / k, n[1] / k]
        }
    };
    [c * f[0] - s * f[1], s * f[0] + c * f[1]]
}

/// The point at arc length `s` along a polyline of three points.
fn path_point(path: &[[f64; 2]; 3], s: f64) -> [f64; 2] {
    let mut s = s.max(0.0);
    for seg in path.windows(2) {
        let d = [seg[1][0] - seg[0][0], seg[1][1] - seg[0][1]];
        let len = d[0].hypot(d[1]);
        if s <= len || len == 0.0 && s == 0.0 {
            let f = if len > 0.0 { s / len } else { 0.0 };
            return [seg[0][0] + f * d[0], seg[0][1] + f * d[1]];
        }
        s -= len;
    }
    path[2]
}

/// The support points ([`SupportLayout`]), with loads varying linearly so that their centroid is
/// the centre of mass (clamped at zero, then renormalised).
fn support_points(block: &BlockParams, com: [f64; 2], normal_total: f64) -> Vec<SupportPoint> {
    let [a, b] = block.size;
    let pts: Vec<[f64; 2]> = match block.support {
        SupportLayout::Grid => {
            let n = block.support_grid as usize;
            let cell = |i: usize| (i as f64 + 0.5) / n as f64 - 0.5;
            (0..n)
                .flat_map(|i| (0..n).map(move |j| [cell(i) * a, cell(j) * b]))
                .collect()
        }
        SupportLayout::Corners => [[-0.5, -0.5], [-0.5, 0.5], [0.5, -0.5], [0.5, 0.5]]
            .iter()
            .map(|c| [c[0] * a, c[1] * b])
            .collect(),
    };
    let count = pts.len() as f64;
    let sxx: f64 = pts.iter().map(|p| p[0] * p[0]).sum();
    let syy: f64 = pts.iter().map(|p| p[1] * p[1]).sum();
    // Σ wᵢ rᵢ = count · com with wᵢ = 1 + kx xᵢ + ky yᵢ (the grid is symmetric about the centre).
    let kx = if sxx > 0.0 { count * com[0] / sxx } else { 0.0 };
    let ky = if syy > 0.0 { count * com[1] / syy } else { 0.0 };
    let weights: Vec<f64> = pts
        .iter()
        .map(|p| (1.0 + kx * p[0] + ky * p[1]).max(0.0))
        .collect();
    let total: f64 = weights.iter().sum();
    let mass = block.mass;
    pts.iter()
        .zip(&weights)
        .map(|(p, w)| SupportPoint {
            local: *p,
            load: normal_total * w / total,
            mass: mass * w / total,
        })
        .collect()
}
