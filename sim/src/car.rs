//! The car world: a rear-wheel-driven 1:43 RC car as one rigid body with Pacejka tires.
//!
//! # Model
//!
//! The dynamic bicycle model of the ORCA cars (Liniger, Domahidi & Morari 2015; used by
//! Kohler et al.), integrated by us with fixed-step RK4 at `car.substep` (default 1 ms).
//! rapier2d is not used for the car: a single body on a flat floor has no contacts to solve,
//! all forces are ours, and an explicit integrator keeps the model exactly the documented
//! equations (and 50× cheaper than a rapier step).
//!
//! State: pose `(X, Y, ψ)` and body-frame velocities `(vx, vy, ω)`. Inputs: steering `δ` and
//! throttle `d` (normalised motor duty), both clamped to their limits.
//!
//! ```text
//! front slip  α_f = δ − atan2(vy + lf ω, vx)      rear slip  α_r = atan2(lr ω − vy, vx)
//! tire force  F_y = D sin(C atan(B α))            (Pacejka magic formula, D in newtons)
//! drive       F_rx = (Cm1 − Cm2 vx) d
//! resistance  F_res = −Cr0 sat(vx / v_roll) − Cr2 vx|vx|
//! m v̇x = F_rx − F_fy sin δ + F_res + m vy ω
//! m v̇y = F_ry + F_fy cos δ − m vx ω
//! Iz ω̇ = F_fy lf cos δ − F_ry lr
//! ```
//!
//! Two additions to the published model, both documented parameters:
//!
//! * **Friction ellipse on the driven rear axle** (`friction_ellipse`, default on): the rear
//!   tire's combined force `(F_rx, F_ry)` is scaled back onto the circle of radius `D_r` when it
//!   exceeds it. With the ORCA constants full throttle asks more than `D_r` of the rear tire,
//!   so high throttle eats lateral grip: power oversteer and drifting. At gentle inputs the
//!   force stays inside the circle and the model is exactly the published one.
//! * **Low-speed regularisation**: slip angles are computed from the wheel-frame velocity with
//!   the longitudinal speed replaced by `max(|v_long|, slip_speed_floor)` (default 0.05 m/s),
//!   so the slip angle stays finite as v → 0 and the lateral tire force becomes a stiff damper
//!   that brings a stopped car to rest; driving backwards gives sensible (small) slip angles.
//!   Rolling resistance `Cr0` is saturated linearly below `rolling_speed_eps` (1 mm/s) so a car
//!   at rest stays at rest (creep below 1 mm/s). Forward driving above the floor speed is the
//!   published model to first order in the slip angles, and exactly in them.

use std::collections::VecDeque;

use serde::{Deserialize, Serialize};

use crate::error::SimError;
use crate::geometry::{Pose2, Region, finite, finite2, finite3, in_range, positive, wrap_angle};
use crate::noise::MeasurementNoise;
use crate::rng::SimRng;
use crate::scenario_file;
use crate::track::Track;

/// Pacejka magic-formula coefficients `F = D sin(C atan(B α))`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Pacejka {
    /// Stiffness factor B.
    pub b: f64,
    /// Shape factor C.
    pub c: f64,
    /// Peak force D \[N\] (for the ORCA car: a force, not a normalised μ).
    pub d: f64,
}

impl Pacejka {
    /// Lateral force at slip angle `alpha` with the peak scaled by `grip`.
    pub fn force(&self, alpha: f64, grip: f64) -> f64 {
        grip * self.d * (self.c * (self.b * alpha).atan()).sin()
    }
}

/// Physical parameters of the car. Defaults are the published ORCA 1:43 car (Liniger et al.,
/// MPCC project).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CarParams {
    /// Mass \[kg\]. Default 0.041.
    pub mass: f64,
    /// Yaw inertia [kg m²]. Default 27.8e-6.
    pub inertia_z: f64,
    /// Centre of mass to front axle \[m\]. Default 0.029.
    pub lf: f64,
    /// Centre of mass to rear axle \[m\]. Default 0.033.
    pub lr: f64,
    /// Front tire. Default B 2.579, C 1.2, D 0.192 N.
    pub front: Pacejka,
    /// Rear tire. Default B 3.3852, C 1.2691, D 0.1737 N.
    pub rear: Pacejka,
    /// Motor gain Cm1 \[N\]. Default 0.287.
    pub cm1: f64,
    /// Motor back-EMF term Cm2 [N s/m]. Default 0.0545.
    pub cm2: f64,
    /// Rolling resistance Cr0 \[N\]. Default 0.0518.
    pub cr0: f64,
    /// Drag Cr2 [N s²/m²]. Default 0.00035.
    pub cr2: f64,
    /// Steering limit |δ| \[rad\]. Default 0.35.
    pub steering_max: f64,
    /// Lowest throttle. Default −0.1.
    pub throttle_min: f64,
    /// Highest throttle. Default 1.
    pub throttle_max: f64,
    /// Friction ellipse on the rear axle (see the module docs). Default true.
    pub friction_ellipse: bool,
    /// Longitudinal speed floor in slip angles \[m/s\]. Default 0.05.
    pub slip_speed_floor: f64,
    /// Speed below which rolling resistance is linear \[m/s\]. Default 0.001.
    pub rolling_speed_eps: f64,
    /// Internal RK4 step \[s\]. Default 0.001.
    pub substep: f64,
}

impl Default for CarParams {
    fn default() -> Self {
        Self {
            mass: 0.041,
            inertia_z: 27.8e-6,
            lf: 0.029,
            lr: 0.033,
            front: Pacejka {
                b: 2.579,
                c: 1.2,
                d: 0.192,
            },
            rear: Pacejka {
                b: 3.3852,
                c: 1.2691,
                d: 0.1737,
            },
            cm1: 0.287,
            cm2: 0.0545,
            cr0: 0.0518,
            cr2: 0.00035,
            steering_max: 0.35,
            throttle_min: -0.1,
            throttle_max: 1.0,
            friction_ellipse: true,
            slip_speed_floor: 0.05,
            rolling_speed_eps: 0.001,
            substep: 0.001,
        }
    }
}

impl CarParams {
    /// Wheelbase `lf + lr` \[m\].
    pub fn wheelbase(&self) -> f64 {
        self.lf + self.lr
    }

    /// These parameters with every physical constant of the model scaled by its own factor
    /// drawn uniformly from `[1 − fraction, 1 + fraction]` (seeded: the same seed gives the same
    /// car): a car whose true parameters differ from the datasheet, for tests of
    /// identification and diagnosis.
    ///
    /// Scaled, in this order: `mass`, `inertia_z`, `lf`, `lr`, `front.{b, c, d}`,
    /// `rear.{b, c, d}`, `cm1`, `cm2`, `cr0`, `cr2`. Kept: the command limits (`steering_max`,
    /// `throttle_min`, `throttle_max`: known from the command interface), `friction_ellipse`
    /// and the numerical settings (`slip_speed_floor`, `rolling_speed_eps`, `substep`).
    ///
    /// Errors: `fraction` outside `[0, 1)` (a factor must stay positive).
    pub fn perturbed(&self, seed: u64, fraction: f64) -> Result<CarParams, SimError> {
        crate::rng::check_fraction("CarParams::perturbed fraction", fraction)?;
        let mut p = self.clone();
        let mut f = crate::rng::Perturb::new(seed, fraction);
        for v in [
            &mut p.mass,
            &mut p.inertia_z,
            &mut p.lf,
            &mut p.lr,
            &mut p.front.b,
            &mut p.front.c,
            &mut p.front.d,
            &mut p.rear.b,
            &mut p.rear.c,
            &mut p.rear.d,
            &mut p.cm1,
            &mut p.cm2,
            &mut p.cr0,
            &mut p.cr2,
        ] {
            f.scale(v);
        }
        Ok(p)
    }
}

/// Where the car may drive: a rectangular floor, optionally with a race track on it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Arena {
    /// Floor lower corner `[x, y]` \[m\]. Default `[−1.5, −1.5]`.
    pub min: [f64; 2],
    /// Floor upper corner `[x, y]` \[m\]. Default `[1.5, 1.5]`.
    pub max: [f64; 2],
    /// Optional track file (MPCC `track.json` layout: `X, Y, X_i, Y_i, X_o, Y_o`), relative to
    /// the scenario file. When set, the explorer drives along the track. Default none.
    pub track: Option<String>,
}

impl Default for Arena {
    fn default() -> Self {
        Self {
            min: [-1.5, -1.5],
            max: [1.5, 1.5],
            track: None,
        }
    }
}

impl Arena {
    /// Whether a point lies on the floor.
    pub fn contains(&self, p: [f64; 2]) -> bool {
        p[0] >= self.min[0] && p[0] <= self.max[0] && p[1] >= self.min[1] && p[1] <= self.max[1]
    }

    /// Centre of the floor.
    pub fn centre(&self) -> [f64; 2] {
        [
            0.5 * (self.min[0] + self.max[0]),
            0.5 * (self.min[1] + self.max[1]),
        ]
    }
}

/// Hidden effect: aerodynamic drag `F = −c v|v|` on the body velocity.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct AeroDrag {
    /// Switch. Default true.
    pub enabled: bool,
    /// Coefficient c [N s²/m²]. Default 0.01 (full-throttle top speed ≈ 4.0 → 2.8 m/s).
    pub c: f64,
}

impl Default for AeroDrag {
    fn default() -> Self {
        Self {
            enabled: true,
            c: 0.01,
        }
    }
}

/// Hidden effect: first-order lag of the throttle, `ḋ = (d_cmd − d)/τ`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct MotorLag {
    /// Switch. Default true.
    pub enabled: bool,
    /// Time constant τ \[s\]. Default 0.1.
    pub tau: f64,
}

impl Default for MotorLag {
    fn default() -> Self {
        Self {
            enabled: true,
            tau: 0.1,
        }
    }
}

/// Hidden effect: a constant steering offset (misaligned servo), added after the limit.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SteeringOffset {
    /// Switch. Default true.
    pub enabled: bool,
    /// Offset \[rad\]. Default 0.03.
    pub offset: f64,
}

impl Default for SteeringOffset {
    fn default() -> Self {
        Self {
            enabled: true,
            offset: 0.03,
        }
    }
}

/// Hidden effect: a region of the floor where both tires' peak force D is scaled.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GripPatch {
    /// Switch. Default true.
    pub enabled: bool,
    /// Factor on D inside the region. Default 0.5.
    pub scale: f64,
    /// Where the patch is. Default a 1 × 1 m square at (0.5, 0).
    pub region: Region,
}

impl Default for GripPatch {
    fn default() -> Self {
        Self {
            enabled: true,
            scale: 0.5,
            region: Region {
                centre: [0.5, 0.0],
                size: [1.0, 1.0],
                ..Region::default()
            },
        }
    }
}

/// Hidden effect: the steering gain falls with speed. The front wheels turn to
///
/// ```text
/// δ_wheel = δ_servo / (1 + (vx / v0)²)   (+ steering_offset, if on)
/// ```
///
/// where `δ_servo` is the clamped command (or the servo angle under `steering_rate_limit`) and
/// `vx` the body-frame longitudinal speed \[m/s\]. At `vx = v0` the wheels turn half as far as
/// commanded. Why: the tires' self-aligning moment grows with the lateral force, and so with
/// speed at a given steering angle; a compliant steering linkage or a weak servo gives way to
/// it (RC transmitters' "speed-sensitive steering" has the same shape). A model that takes
/// `δ_wheel = δ` sees too little yaw at speed: a `δ·vx²`-like term in the residual. The
/// form is smooth, even in `vx`, never reverses the steering and tends to 0 only as vx → ∞.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SteeringGainSpeed {
    /// Switch. Default true.
    pub enabled: bool,
    /// Speed at which the gain is 1/2, v0 \[m/s\] (> 0). Default 2.5 (the explorer's top
    /// speed): gain 0.76 at the explorer's 1.4 m/s cruise, 0.5 at 2.5 m/s.
    pub v0: f64,
}

impl Default for SteeringGainSpeed {
    fn default() -> Self {
        Self {
            enabled: true,
            v0: 2.5,
        }
    }
}

impl SteeringGainSpeed {
    /// The factor `1 / (1 + (vx / v0)²)` on the steering angle at longitudinal speed `vx`.
    pub fn gain(&self, vx: f64) -> f64 {
        let r = vx / self.v0;
        1.0 / (1.0 + r * r)
    }
}

/// Hidden effect: a steering servo with a slew-rate limit and an optional first-order lag.
///
/// The servo angle `δ_s` is simulator state (reset to 0, wheels straight, by
/// [`CarWorld::reset`]). Every RK4 substep of length `h` it moves towards the clamped command
/// `δ_cmd`:
///
/// ```text
/// Δ = (δ_cmd − δ_s)(1 − e^(−h/τ))     (τ > 0: exact first-order lag over the substep)
/// Δ = δ_cmd − δ_s                      (τ = 0: no lag)
/// δ_s ← δ_s + clamp(Δ, −r h, r h)      so |δ̇_s| ≤ r always
/// ```
///
/// and is held over the substep. Why: a hobby servo slews at a bounded rate (≈ 5–10 rad/s
/// unloaded, slower under tire load) and lags its command; a model that takes `δ = δ_cmd`
/// sees the yaw response late after every steering step (a lagged-input term in the residual).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SteeringRateLimit {
    /// Switch. Default true.
    pub enabled: bool,
    /// Largest steering rate r \[rad/s\] (> 0). Default 3 (a full 0.35 → −0.35 rad swing takes
    /// 0.23 s).
    pub rate: f64,
    /// Time constant τ of the servo's first-order lag \[s\] (≥ 0; 0 = rate limit only).
    /// Default 0.
    pub tau: f64,
}

impl Default for SteeringRateLimit {
    fn default() -> Self {
        Self {
            enabled: true,
            rate: 3.0,
            tau: 0.0,
        }
    }
}

/// Hidden effect: a transport delay: the car applies each command `delay` seconds after it is
/// given (both steering and throttle), as a radio link, a bus or a message queue between the
/// controller and the motor drivers does. Before its first command reaches it after a reset
/// the car holds the neutral command (straight, no throttle). Why: a model that applies the
/// command at once sees every response early by the delay; no memoryless term can stand for
/// that (the diagnosis library's `command_delay` can, as can the term search's lagged command
/// rates for one command: `δ − t_d·δ̇`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CommandDelay {
    /// Switch. Default true.
    pub enabled: bool,
    /// The delay \[s\] (0 … 1). Default 0.06.
    pub delay: f64,
}

impl Default for CommandDelay {
    fn default() -> Self {
        Self {
            enabled: true,
            delay: 0.06,
        }
    }
}

/// The hidden effects of the car world; each is off unless its table is present.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CarEffects {
    /// Aerodynamic drag.
    pub aero_drag: Option<AeroDrag>,
    /// Throttle lag.
    pub motor_lag: Option<MotorLag>,
    /// Steering offset.
    pub steering_offset: Option<SteeringOffset>,
    /// Low-grip region.
    pub grip_patch: Option<GripPatch>,
    /// Steering gain falling with speed (not in the diagnosis library).
    pub steering_gain_speed: Option<SteeringGainSpeed>,
    /// Rate-limited, lagging steering servo (not in the diagnosis library).
    pub steering_rate_limit: Option<SteeringRateLimit>,
    /// Transport delay of the commands (not in the diagnosis library).
    pub command_delay: Option<CommandDelay>,
}

fn on<T>(e: &Option<T>, enabled: impl Fn(&T) -> bool) -> Option<&T> {
    e.as_ref().filter(|x| enabled(x))
}

impl CarEffects {
    /// Names of the effects that are switched on.
    pub fn active(&self) -> Vec<&'static str> {
        let mut v = Vec::new();
        if on(&self.aero_drag, |e| e.enabled).is_some() {
            v.push("aero_drag");
        }
        if on(&self.motor_lag, |e| e.enabled).is_some() {
            v.push("motor_lag");
        }
        if on(&self.steering_offset, |e| e.enabled).is_some() {
            v.push("steering_offset");
        }
        if on(&self.grip_patch, |e| e.enabled).is_some() {
            v.push("grip_patch");
        }
        if on(&self.steering_gain_speed, |e| e.enabled).is_some() {
            v.push("steering_gain_speed");
        }
        if on(&self.steering_rate_limit, |e| e.enabled).is_some() {
            v.push("steering_rate_limit");
        }
        if on(&self.command_delay, |e| e.enabled).is_some() {
            v.push("command_delay");
        }
        v
    }
}

/// Everything that defines a car world. Loadable from TOML; every key has a default.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CarScenario {
    /// A name for reports. Default `"floor"`.
    pub name: String,
    /// Seed for measurement noise when a node runs this scenario live. Default 0.
    pub seed: u64,
    /// Start pose `[x, y, ψ]`. Default `[0, 0, 0]`.
    pub start: [f64; 3],
    /// The car.
    pub car: CarParams,
    /// The floor (and optional track).
    pub arena: Arena,
    /// Hidden effects (`[effects.<name>]`). Default none.
    pub effects: CarEffects,
    /// Measurement noise on the car pose.
    pub noise: MeasurementNoise,
    /// The loaded track (from `arena.track`, or set in code).
    #[serde(skip)]
    pub track_data: Option<Track>,
}

impl Default for CarScenario {
    fn default() -> Self {
        Self {
            name: "floor".into(),
            seed: 0,
            start: [0.0; 3],
            car: CarParams::default(),
            arena: Arena::default(),
            effects: CarEffects::default(),
            noise: MeasurementNoise::default(),
            track_data: None,
        }
    }
}

impl CarScenario {
    /// The nominal ORCA car on a 3 × 3 m floor.
    pub fn floor() -> Self {
        Self::default()
    }

    /// The nominal car on `track`, starting on its first centre-line point facing along it.
    pub fn on_track(track: Track) -> Self {
        let start = track.start_pose();
        Self {
            name: "track".into(),
            start: start.to_array(),
            arena: Arena {
                min: track.bounds_min(0.3),
                max: track.bounds_max(0.3),
                track: None,
            },
            track_data: Some(track),
            ..Self::default()
        }
    }

    /// Parses a TOML scenario and validates it (a `arena.track` path is not loaded: use
    /// [`CarScenario::from_file`] or set `track_data`).
    pub fn from_toml_str(text: &str) -> Result<Self, SimError> {
        let s: Self = scenario_file::parse(text, "<string>")?;
        s.validate()?;
        Ok(s)
    }

    /// Reads a TOML scenario file, loads its track (relative to the file) and validates it.
    pub fn from_file(path: impl AsRef<std::path::Path>) -> Result<Self, SimError> {
        let path = path.as_ref();
        let mut s: Self = scenario_file::load(path)?;
        if let Some(t) = &s.arena.track {
            let base = path.parent().unwrap_or(std::path::Path::new("."));
            s.track_data = Some(Track::from_file(base.join(t))?);
        }
        s.validate()?;
        Ok(s)
    }

    /// As TOML text.
    pub fn to_toml_string(&self) -> String {
        toml::to_string(self).unwrap_or_default()
    }

    /// This scenario with the car's physical constants perturbed by
    /// [`CarParams::perturbed`]`(seed, fraction)`; everything else (effects, arena, noise)
    /// unchanged.
    pub fn perturbed(&self, seed: u64, fraction: f64) -> Result<Self, SimError> {
        let s = Self {
            car: self.car.perturbed(seed, fraction)?,
            ..self.clone()
        };
        s.validate()?;
        Ok(s)
    }

    /// The start state (at rest).
    pub fn start_state(&self) -> CarState {
        CarState {
            x: self.start[0],
            y: self.start[1],
            psi: wrap_angle(self.start[2]),
            ..CarState::default()
        }
    }

    /// Rejects impossible values; the error names the key and what to set.
    pub fn validate(&self) -> Result<(), SimError> {
        finite3("start", self.start)?;
        let c = &self.car;
        positive("car.mass", c.mass)?;
        positive("car.inertia_z", c.inertia_z)?;
        positive("car.lf", c.lf)?;
        positive("car.lr", c.lr)?;
        for (k, t) in [("car.front", &c.front), ("car.rear", &c.rear)] {
            positive(&format!("{k}.b"), t.b)?;
            positive(&format!("{k}.c"), t.c)?;
            positive(&format!("{k}.d"), t.d)?;
        }
        finite("car.cm1", c.cm1)?;
        crate::geometry::non_negative("car.cm2", c.cm2)?;
        crate::geometry::non_negative("car.cr0", c.cr0)?;
        crate::geometry::non_negative("car.cr2", c.cr2)?;
        in_range("car.steering_max", c.steering_max, 0.0, 1.5)?;
        finite("car.throttle_min", c.throttle_min)?;
        finite("car.throttle_max", c.throttle_max)?;
        if c.throttle_min > c.throttle_max {
            return Err(SimError::invalid(
                "car.throttle_max",
                format!(
                    "must be ≥ car.throttle_min ({}), got {}",
                    c.throttle_min, c.throttle_max
                ),
            ));
        }
        positive("car.slip_speed_floor", c.slip_speed_floor)?;
        positive("car.rolling_speed_eps", c.rolling_speed_eps)?;
        positive("car.substep", c.substep)?;
        if c.substep > 0.002 {
            return Err(SimError::invalid(
                "car.substep",
                format!(
                    "must be ≤ 0.002 s for a stable tire model, got {}",
                    c.substep
                ),
            ));
        }
        finite2("arena.min", self.arena.min)?;
        finite2("arena.max", self.arena.max)?;
        if self.arena.min[0] >= self.arena.max[0] || self.arena.min[1] >= self.arena.max[1] {
            return Err(SimError::invalid(
                "arena.max",
                format!(
                    "must be greater than arena.min in x and y, got min {:?} max {:?}",
                    self.arena.min, self.arena.max
                ),
            ));
        }
        let e = &self.effects;
        if let Some(a) = &e.aero_drag {
            crate::geometry::non_negative("effects.aero_drag.c", a.c)?;
        }
        if let Some(m) = &e.motor_lag {
            positive("effects.motor_lag.tau", m.tau)?;
        }
        if let Some(s) = &e.steering_offset {
            in_range("effects.steering_offset.offset", s.offset, -0.5, 0.5)?;
        }
        if let Some(g) = &e.grip_patch {
            crate::geometry::non_negative("effects.grip_patch.scale", g.scale)?;
            g.region.validate("effects.grip_patch.region")?;
        }
        if let Some(g) = &e.steering_gain_speed {
            positive("effects.steering_gain_speed.v0", g.v0)?;
        }
        if let Some(r) = &e.steering_rate_limit {
            positive("effects.steering_rate_limit.rate", r.rate)?;
            crate::geometry::non_negative("effects.steering_rate_limit.tau", r.tau)?;
        }
        if let Some(d) = &e.command_delay {
            in_range("effects.command_delay.delay", d.delay, 0.0, 1.0)?;
        }
        self.noise.validate("noise")
    }
}

/// Car commands: front wheel angle and normalised throttle.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct CarInput {
    /// Steering δ \[rad\] (clamped to ±`steering_max`).
    pub steering: f64,
    /// Throttle d (clamped to `[throttle_min, throttle_max]`).
    pub throttle: f64,
}

impl CarInput {
    /// A command.
    pub fn new(steering: f64, throttle: f64) -> Self {
        Self { steering, throttle }
    }
}

/// Ground-truth car state: pose and body-frame velocities.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct CarState {
    /// x \[m\].
    pub x: f64,
    /// y \[m\].
    pub y: f64,
    /// Heading ψ \[rad\].
    pub psi: f64,
    /// Longitudinal velocity \[m/s\] (body frame).
    pub vx: f64,
    /// Lateral velocity \[m/s\] (body frame, left positive).
    pub vy: f64,
    /// Yaw rate \[rad/s\].
    pub omega: f64,
}

impl CarState {
    /// The pose.
    pub fn pose(&self) -> Pose2 {
        Pose2::new(self.x, self.y, self.psi)
    }

    /// Speed |v| \[m/s\].
    pub fn speed(&self) -> f64 {
        self.vx.hypot(self.vy)
    }

    /// Sideslip angle β = atan2(vy, vx) \[rad\] (0 when at rest).
    pub fn sideslip(&self) -> f64 {
        if self.speed() < 1e-9 {
            0.0
        } else {
            self.vy.atan2(self.vx)
        }
    }

    fn is_finite(&self) -> bool {
        [self.x, self.y, self.psi, self.vx, self.vy, self.omega]
            .iter()
            .all(|v| v.is_finite())
    }
}

/// Integrator state: `[X, Y, ψ, vx, vy, ω, d_actual]`.
type Xs = [f64; 7];

/// The car world. Deterministic: the same scenario and the same calls give bit-identical states.
#[derive(Debug, Clone)]
pub struct CarWorld {
    scenario: CarScenario,
    x: Xs,
    /// Steering servo angle δ_s \[rad\]: the rate-limited command under
    /// `steering_rate_limit`, else the last clamped command.
    servo: f64,
    time: f64,
    /// Under `command_delay`: the commands given (clamped) with the times they were given,
    /// oldest first; the first is the one the car applies now (the neutral command at time −∞
    /// after a reset).
    given: VecDeque<(f64, CarInput)>,
}

impl CarWorld {
    /// Builds the world with the car at rest at the scenario's start.
    pub fn new(scenario: &CarScenario) -> Result<Self, SimError> {
        scenario.validate()?;
        let mut w = Self {
            scenario: scenario.clone(),
            x: [0.0; 7],
            servo: 0.0,
            time: 0.0,
            given: VecDeque::new(),
        };
        w.reset(scenario.start_state())?;
        Ok(w)
    }

    /// The scenario this world was built from.
    pub fn scenario(&self) -> &CarScenario {
        &self.scenario
    }

    /// Puts the car in `state` (the motor lag, if any, starts at zero throttle; the steering
    /// servo at 0, wheels straight).
    pub fn reset(&mut self, state: CarState) -> Result<(), SimError> {
        if !state.is_finite() {
            return Err(SimError::Input {
                what: "CarWorld::reset state",
                message: format!("must be finite, got {state:?}"),
            });
        }
        self.x = [
            state.x,
            state.y,
            wrap_angle(state.psi),
            state.vx,
            state.vy,
            state.omega,
            0.0,
        ];
        self.servo = 0.0;
        self.given.clear();
        self.given
            .push_back((f64::NEG_INFINITY, CarInput::default()));
        Ok(())
    }

    /// Ground truth.
    pub fn state(&self) -> CarState {
        CarState {
            x: self.x[0],
            y: self.x[1],
            psi: self.x[2],
            vx: self.x[3],
            vy: self.x[4],
            omega: self.x[5],
        }
    }

    /// Simulated time since construction \[s\].
    pub fn time(&self) -> f64 {
        self.time
    }

    /// The steering servo angle \[rad\]: under `steering_rate_limit` the rate-limited
    /// (and lagged) servo state, otherwise the last clamped steering command (0 after a reset).
    pub fn servo_angle(&self) -> f64 {
        self.servo
    }

    /// The front wheel angle δ the tires see now \[rad\]: the servo angle times the
    /// `steering_gain_speed` factor at the current `vx`, plus the `steering_offset`.
    pub fn wheel_angle(&self) -> f64 {
        self.wheel_angle_at(self.servo, self.x[3])
    }

    /// δ_wheel from the servo angle and the longitudinal speed (the effects' order: gain, then
    /// offset).
    fn wheel_angle_at(&self, servo: f64, vx: f64) -> f64 {
        let e = &self.scenario.effects;
        let mut delta = servo;
        if let Some(g) = on(&e.steering_gain_speed, |g| g.enabled) {
            delta *= g.gain(vx);
        }
        if let Some(s) = on(&e.steering_offset, |s| s.enabled) {
            delta += s.offset;
        }
        delta
    }

    /// A noisy pose measurement (the scenario's `noise`).
    pub fn measure(&self, rng: &mut SimRng) -> Pose2 {
        self.scenario.noise.measure(self.state().pose(), rng)
    }

    /// The command as the car applies it: clamped to the limits.
    pub fn clamp_input(&self, u: CarInput) -> CarInput {
        let c = &self.scenario.car;
        CarInput {
            steering: u.steering.clamp(-c.steering_max, c.steering_max),
            throttle: u.throttle.clamp(c.throttle_min, c.throttle_max),
        }
    }

    /// Holds `u` for `dt` seconds (split into equal RK4 substeps no longer than `car.substep`)
    /// and returns the new ground-truth state. The one step function for headless runs and a
    /// live node alike.
    pub fn step(&mut self, u: CarInput, dt: f64) -> Result<CarState, SimError> {
        if !(u.steering.is_finite() && u.throttle.is_finite()) {
            return Err(SimError::Input {
                what: "CarInput",
                message: format!("steering and throttle must be finite, got {u:?}"),
            });
        }
        if !(dt.is_finite() && dt > 0.0 && dt <= 10.0) {
            return Err(SimError::Input {
                what: "CarWorld::step dt",
                message: format!("must be within (0, 10] s, got {dt}"),
            });
        }
        let u = self.clamp_input(u);
        let delay = on(&self.scenario.effects.command_delay, |d| d.enabled).map(|d| d.delay);
        if delay.is_some() {
            self.given.push_back((self.time, u));
        }
        let n = (dt / self.scenario.car.substep - 1e-9).ceil().max(1.0) as usize;
        let h = dt / n as f64;
        for i in 0..n {
            let u = match delay {
                Some(d) => self.delayed(self.time + i as f64 * h - d),
                None => u,
            };
            self.servo_substep(u.steering, h);
            let held = CarInput {
                steering: self.servo,
                throttle: u.throttle,
            };
            self.substep(held, h);
        }
        self.time += dt;
        Ok(self.state())
    }

    /// Under `command_delay`: the last command given at or before `t` (drops the older ones).
    fn delayed(&mut self, t: f64) -> CarInput {
        // commands given within a nanosecond of `t` count as given at `t`
        while self.given.len() > 1 && self.given[1].0 <= t + 1e-9 {
            self.given.pop_front();
        }
        self.given.front().map_or_else(CarInput::default, |g| g.1)
    }

    /// Moves the servo angle towards the clamped command over one substep (see
    /// [`SteeringRateLimit`]); without the effect the servo follows the command at once.
    fn servo_substep(&mut self, target: f64, h: f64) {
        match on(&self.scenario.effects.steering_rate_limit, |r| r.enabled) {
            None => self.servo = target,
            Some(r) => {
                let want = if r.tau > 0.0 {
                    (target - self.servo) * -(-h / r.tau).exp_m1()
                } else {
                    target - self.servo
                };
                let max = r.rate * h;
                self.servo += want.clamp(-max, max);
            }
        }
    }

    fn substep(&mut self, u: CarInput, h: f64) {
        // Grip is looked up once per substep, at the axles' positions at its start.
        let grip = self.grip_at(&self.x);
        let x = self.x;
        let k1 = self.deriv(&x, u, grip);
        let k2 = self.deriv(&add(&x, &k1, 0.5 * h), u, grip);
        let k3 = self.deriv(&add(&x, &k2, 0.5 * h), u, grip);
        let k4 = self.deriv(&add(&x, &k3, h), u, grip);
        for i in 0..7 {
            self.x[i] = x[i] + h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
        }
        self.x[2] = wrap_angle(self.x[2]);
    }

    /// Tire peak-force factors `[front, rear]` at the axle positions.
    fn grip_at(&self, x: &Xs) -> [f64; 2] {
        match on(&self.scenario.effects.grip_patch, |e| e.enabled) {
            None => [1.0, 1.0],
            Some(g) => {
                let c = &self.scenario.car;
                let (s, co) = x[2].sin_cos();
                let front = [x[0] + c.lf * co, x[1] + c.lf * s];
                let rear = [x[0] - c.lr * co, x[1] - c.lr * s];
                let f = |p| if g.region.contains(p) { g.scale } else { 1.0 };
                [f(front), f(rear)]
            }
        }
    }

    fn deriv(&self, x: &Xs, u: CarInput, grip: [f64; 2]) -> Xs {
        let c = &self.scenario.car;
        let e = &self.scenario.effects;
        let (psi, vx, vy, w) = (x[2], x[3], x[4], x[5]);
        // `u.steering` is the servo angle; gain and offset act on it at this stage's speed.
        let delta = self.wheel_angle_at(u.steering, vx);
        let (throttle, d_dot) = match on(&e.motor_lag, |m| m.enabled) {
            Some(m) => (x[6], (u.throttle - x[6]) / m.tau),
            None => (u.throttle, 0.0),
        };
        let floor = c.slip_speed_floor;
        // Front wheel: body-frame velocity at the axle, rotated into the wheel frame.
        let (sd, cd) = delta.sin_cos();
        let vfy = vy + c.lf * w;
        let f_long = vx * cd + vfy * sd;
        let f_lat = -vx * sd + vfy * cd;
        let alpha_f = -f_lat.atan2(f_long.abs().max(floor));
        let alpha_r = -(vy - c.lr * w).atan2(vx.abs().max(floor));
        let f_fy = c.front.force(alpha_f, grip[0]);
        let mut f_ry = c.rear.force(alpha_r, grip[1]);
        let mut f_rx = (c.cm1 - c.cm2 * vx) * throttle;
        if c.friction_ellipse {
            let d_r = c.rear.d * grip[1];
            let total = f_rx.hypot(f_ry);
            if total > d_r {
                let s = if total > 0.0 { d_r / total } else { 0.0 };
                f_rx *= s;
                f_ry *= s;
            }
        }
        let roll = c.cr0 * (vx / c.rolling_speed_eps).clamp(-1.0, 1.0);
        let mut fx = f_rx - f_fy * sd - roll - c.cr2 * vx * vx.abs();
        let mut fy = f_ry + f_fy * cd;
        if let Some(a) = on(&e.aero_drag, |a| a.enabled) {
            let v = vx.hypot(vy);
            fx -= a.c * v * vx;
            fy -= a.c * v * vy;
        }
        let (s, co) = psi.sin_cos();
        [
            vx * co - vy * s,
            vx * s + vy * co,
            w,
            fx / c.mass + vy * w,
            fy / c.mass - vx * w,
            (f_fy * c.lf * cd - f_ry * c.lr) / c.inertia_z,
            d_dot,
        ]
    }
}

fn add(x: &Xs, k: &Xs, h: f64) -> Xs {
    let mut y = *x;
    for i in 0..7 {
        y[i] += h * k[i];
    }
    y
}
