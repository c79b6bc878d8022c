//! Custom effects: named sets of terms `ṡ_i += θ_j · feature_j(s, u)` that the user adds to a
//! physics model from a small TOML file, beside the library [`Effect`](super::Effect)s.
//!
//! ```toml
//! name = "steering_gain_speed"
//! [[term]]
//! state = "omega"         # which state derivative
//! feature = "delta*vx"    # a product of atoms of the feature library
//! coefficient = -3.2      # start value; fitted by train
//! ```
//!
//! **Targets.** Car (time in seconds): `vx`, `vy` (`v̇ₓ`, `v̇_y` in m/s²) and `omega` (`ω̇` in
//! 1/s²); `ax`, `ay` (`ẍ`, `ÿ` in m/s²) add an acceleration in the **world frame**, rotated into
//! the body frame by the heading `ψ`, so `ÿ += 0.23` is a floor that slopes down along `y` (or a
//! steady wind) with one coefficient where the body frame needs a `cos ψ` and a `sin ψ` term on
//! each of `v̇ₓ`, `v̇_y`; the pose kinematics stay as they are. `delta` (`δ` in rad) is not a derivative: it
//! corrects the **effective steering angle** the tires see (after the servo's lag, when the model
//! has one), so one term acts on `v̇_y` and `ω̇` through the tire model the way an input
//! nonlinearity does (a steering gain that changes with speed, `δ += θ·δ·vₓ²`). `grip` (`μ`,
//! dimensionless) is not a derivative either: the tires' peak forces (both axles, and the rear
//! friction ellipse) are scaled by `1 + Σ θ·feature`, so a term on a position feature is a region
//! of other grip (`μ += −0.5·g(cx, cy; r)`: half the grip around `(cx, cy)`). Pushing (time
//! in pushes, one push integrates normalised time over `[0, 1]`): `x`, `y`, `theta` add a rate
//! in the **world (table) frame**, so a term constant over the push moves the block by
//! `θ·feature` per push; `bx`, `by` add it
//! in the **block frame** (rotated by the block's current heading `θ`), for effects that move
//! with the block (an offset load, a skewed contact). A quasi-static block moves only while
//! pushed: multiply pushing features by `l` (`ℓ`) unless the term should act without a push.
//! `friction` (`μ`, dimensionless) scales the table's friction under each of the block's
//! support points by `1 + Σ θ·feature` evaluated at the point's place on the table (features of
//! the position alone): `μ += 1.5·strip(0.4,0.1,0.2)` is a stripe of 2.5 times the friction,
//! which turns a block that straddles its edge. Friction that is the same all over the
//! footprint does not move a quasi-static block.
//!
//! A custom effect is linear in its parameters (one coefficient per term). In a
//! [`PhysicsModel`](super::PhysicsModel) the coefficients are appended to the parameter vector
//! after the library effects' (names `custom.<name>.<j>`), bounded by `±`[`COEFFICIENT_BOUND`]
//! (a grip term on a region by [`GRIP_REGION_BOUNDS`]),
//! always fitted by `train`, and printed by `equations()` as `ω̇ += θ · δ·vₓ [unit of θ]`.

use serde::{Deserialize, Serialize};

use super::Robot;
use super::features::{Atom, Feature, FeatureError, Unit, time_unit};
use crate::real::Real;

/// Bound `|θ| ≤` of a custom term's coefficient (any unit): wide, only to keep a fit finite.
pub const COEFFICIENT_BOUND: f64 = 1e6;

/// The library's steering offset, as a parameter name.
const STEERING_OFFSET: &str = "steering_offset.delta0";

/// Which state derivative a custom term adds to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Target {
    /// Car: `v̇ₓ`.
    Vx,
    /// Car: `v̇_y`.
    Vy,
    /// Car: `ω̇`.
    Omega,
    /// Car: the world-frame `ẍ`, rotated into the body frame by the heading `ψ` (a pull fixed
    /// in the world: a sloping floor, a steady wind, a cable).
    WorldX,
    /// Car: the world-frame `ÿ`, rotated into the body frame by `ψ`.
    WorldY,
    /// Car: the effective steering angle `δ` (an input correction, not a derivative).
    Delta,
    /// Car: the tires' grip `μ`, a scale `1 + μ` of both axles' peak forces (a correction
    /// through the tire model, not a derivative).
    Grip,
    /// Pushing: world `ẋ` (per push).
    X,
    /// Pushing: world `ẏ` (per push).
    Y,
    /// Pushing: `θ̇` (per push).
    Theta,
    /// Pushing: block-frame x rate (per push), rotated into the world by `θ`.
    BlockX,
    /// Pushing: block-frame y rate (per push), rotated into the world by `θ`.
    BlockY,
    /// Pushing: the table's friction `μ`, a scale `1 + μ` of the friction under each of the
    /// block's support points, the feature evaluated at the point's place on the table (a
    /// correction through the friction model, not a derivative).
    Friction,
}

const TARGETS: [(Target, &str, &str, Unit, Robot); 13] = [
    (Target::Vx, "vx", "v̇ₓ", Unit::new(1, -2), Robot::Car),
    (Target::Vy, "vy", "v̇_y", Unit::new(1, -2), Robot::Car),
    (Target::Omega, "omega", "ω̇", Unit::new(0, -2), Robot::Car),
    (Target::WorldX, "ax", "ẍ", Unit::new(1, -2), Robot::Car),
    (Target::WorldY, "ay", "ÿ", Unit::new(1, -2), Robot::Car),
    (Target::Delta, "delta", "δ", Unit::new(0, 0), Robot::Car),
    (Target::Grip, "grip", "μ", Unit::new(0, 0), Robot::Car),
    (Target::X, "x", "ẋ", Unit::new(1, -1), Robot::Pushing),
    (Target::Y, "y", "ẏ", Unit::new(1, -1), Robot::Pushing),
    (
        Target::Theta,
        "theta",
        "θ̇",
        Unit::new(0, -1),
        Robot::Pushing,
    ),
    (
        Target::BlockX,
        "bx",
        "ẋ_b",
        Unit::new(1, -1),
        Robot::Pushing,
    ),
    (
        Target::BlockY,
        "by",
        "ẏ_b",
        Unit::new(1, -1),
        Robot::Pushing,
    ),
    (
        Target::Friction,
        "friction",
        "μ",
        Unit::new(0, 0),
        Robot::Pushing,
    ),
];

impl Target {
    fn entry(self) -> &'static (Target, &'static str, &'static str, Unit, Robot) {
        TARGETS
            .iter()
            .find(|e| e.0 == self)
            .expect("every target is in the table")
    }
    /// Name in files (`omega`, `bx`).
    pub fn name(self) -> &'static str {
        self.entry().1
    }
    /// Symbol of the derivative (`ω̇`, `ẋ_b`), or of the input (`δ`).
    pub fn symbol(self) -> &'static str {
        self.entry().2
    }
    /// Unit of the derivative (of the input for `δ`).
    pub fn unit(self) -> Unit {
        self.entry().3
    }
    /// The robot.
    pub fn robot(self) -> Robot {
        self.entry().4
    }
    /// Targets of a robot.
    pub fn all(robot: Robot) -> Vec<Target> {
        TARGETS
            .iter()
            .filter(|e| e.4 == robot)
            .map(|e| e.0)
            .collect()
    }
    /// The nominal parameter whose own term in this derivative has the shape of `feature`, if
    /// any: a term `ṡ += θ·feature` then changes that parameter (and trades off against it in
    /// a fit) rather than adding an effect. Car `v̇ₓ`, from the drivetrain
    /// `F_x = (C_m1 − C_m2·vₓ)·d − C_r0·tanh(vₓ/v_reg) − C_r2·vₓ|vₓ|` over the mass: `d`
    /// (`Cm1`), `d·vₓ`, `d·|vₓ|` (`Cm2`), `1` (`Cr0`, driving forward), `vₓ²`, `vₓ|vₓ|`
    /// (`Cr2`). The tire forces are nonlinear in their parameters and shared by `v̇_y` and
    /// `ω̇`, so no single term has their shape. Pushing: the block advances along the pushed
    /// face's normal by `ℓ·L·cos φ`, so `ẋ_b` on `ℓ·cos φ` or `ℓ` is a change of the push
    /// length `L` (a block or finger a few per cent off its nominal size); it turns by the
    /// off-centre part of the push over the limit-surface ratio, so `θ̇` on `ℓ·sin φ`, `ℓ·φ`
    /// or `ℓ·p` is a change of `c` (on perturbed nominal worlds such terms passed in 5 of 10
    /// seeds of 1000 pushes). A frictionless pusher moves the block only along the face normal
    /// (and turns it), so `ẏ_b` on `ℓ·sin φ` or `ℓ·φ`, the block following the push's lateral
    /// part, is the shape of the library's `pusher_friction` (on perturbed nominal worlds of
    /// 1000 pushes it passed the search's test in 11 of 20 seeds, and on `ℓ·φ` in 9 of 20 once
    /// `ℓ·sin φ` was left out). `δ` on `1` is the library's
    /// `steering_offset` (`delta0`); `μ` on `1` is a scale of the peak forces `Df`, `Dr`.
    pub fn nominal_parameter(self, feature: &Feature) -> Option<&'static str> {
        match (self, feature.name().as_str()) {
            (Target::Vx, "d") => Some("Cm1"),
            (Target::Vx, "d*vx" | "d*|vx|") => Some("Cm2"),
            (Target::Vx, "1") => Some("Cr0"),
            (Target::Vx, "vx*vx" | "vx*|vx|") => Some("Cr2"),
            (Target::Delta, "1") => Some(STEERING_OFFSET),
            (Target::Grip, "1") => Some("Df"),
            (Target::BlockX, "l" | "l*cos_phi") => Some("L"),
            (Target::Theta, "l*sin_phi" | "l*phi" | "l*p") => Some("c"),
            (Target::BlockY, "l*sin_phi" | "l*phi") => Some("pusher_friction.mu"),
            _ => None,
        }
    }

    /// Whether the term search tries `feature` on this target: every feature on a derivative;
    /// on the steering angle `δ` only features of the commands and the speed (`δ`, `d`, `vₓ`,
    /// `|vₓ|`, `|v|`, `vₓ²/(vₓ² + v₀²)`, the lagged steering command, the steering beyond a
    /// level), the shapes of an input's nonlinearity. A lagged command is tried only through
    /// the input it lags: the steering's on `δ`, the throttle's on `v̇ₓ` (the drive). With a slip
    /// angle, `ω`, `v_y` or a position in it a `δ` term is a change of the tire model (on a car
    /// whose tires were 10 % off the model's, `δ += 0.48·α_r·vₓ` passed the search's test). A
    /// custom effect file may still put any feature on `δ`. On the grip `μ` only features of the position (`x`,
    /// `y`, the bumps and bands): a grip that changes everywhere alike is the tires' own
    /// parameters, a grip that changes with the motion is a tire model's shape. The bands are
    /// tried on `μ` only (a strip of other grip across a floor). On the world-frame `ẍ`, `ÿ`
    /// only the constant and features of the position but the bands: a pull fixed in the world
    /// (a slope, a wind), everywhere or over a region; the heading features on `v̇ₓ`, `v̇_y` give
    /// the same pull one body-frame component at a time. On the table's friction only
    /// regions (bumps, bands, strips): a friction that changes everywhere alike does not move
    /// a quasi-static block at all.
    pub fn searched_with(self, feature: &Feature) -> bool {
        let all = |ok: fn(&Atom) -> bool| feature.factors().iter().all(ok);
        let lagged = |input: usize| {
            feature.factors().iter().all(|a| match a {
                Atom::LaggedInput { input: i, .. } | Atom::InputRate { input: i, .. } => {
                    *i == input
                }
                _ => !a.uses_input_lags(),
            })
        };
        match self {
            Target::Delta => {
                lagged(0)
                    && all(|a| {
                        matches!(
                            a,
                            Atom::Delta
                                | Atom::Throttle
                                | Atom::Vx
                                | Atom::AbsVx
                                | Atom::Speed
                                | Atom::SatVx2 { .. }
                                | Atom::LaggedInput { .. }
                                | Atom::InputRate { .. }
                                | Atom::Beyond { input: 0, .. }
                        )
                    })
            }
            Target::Grip => all(Atom::is_position),
            Target::WorldX | Target::WorldY => all(|a| {
                matches!(a, Atom::One)
                    || a.is_position() && !matches!(a, Atom::Band { .. } | Atom::Strip { .. })
            }),
            Target::Friction => !feature.factors().is_empty() && all(Atom::is_region),
            Target::Vx => {
                lagged(1) && all(|a| !matches!(a, Atom::Band { .. } | Atom::Strip { .. }))
            }
            _ => all(|a| {
                !a.uses_input_lags() && !matches!(a, Atom::Band { .. } | Atom::Strip { .. })
            }),
        }
    }

    /// The parameters a term on the target is fitted with ([`CustomEffect::coupled_nominal`]):
    /// the grip's, the car's friction-ellipse weight; the steering angle's, the library's
    /// steering offset (where the model has it: a `δ` term on an input that is near a constant
    /// while the car drives, the throttle `d` or the speed, otherwise takes the part of the
    /// offset's value the selection got wrong).
    pub fn coupled_nominal(self) -> &'static [&'static str] {
        match self {
            Target::Grip => &["ellipse"],
            Target::Delta => &[STEERING_OFFSET],
            _ => &[],
        }
    }

    /// Whether the coupled parameters are refitted with every term on the target, not only
    /// where that fits better: the steering angle's, an effect's own parameter (the steering
    /// offset) the term stands in for.
    pub fn always_refits(self) -> bool {
        self == Target::Delta
    }

    /// Whether the target corrects an input of the tire or friction model (`δ`, `μ`) rather
    /// than adding to a derivative.
    pub fn is_input(self) -> bool {
        matches!(self, Target::Delta | Target::Grip | Target::Friction)
    }

    /// Whether the target is evaluated at places on the table or floor rather than at the
    /// state: the table's friction, at each support point of the block. Its features are then
    /// of the position alone.
    pub fn is_field(self) -> bool {
        self == Target::Friction
    }

    /// Looks a target up by name.
    pub fn from_name(name: &str) -> Result<Target, CustomError> {
        TARGETS
            .iter()
            .find(|e| e.1 == name.trim())
            .map(|e| e.0)
            .ok_or_else(|| CustomError::UnknownState {
                name: name.to_string(),
                known:
                    "car: vx, vy, omega (body frame), ax, ay (world-frame acceleration), delta (the effective steering angle), grip (a scale of the tires' peak forces); pushing: x, y, theta (world frame), bx, by (block frame), friction (a scale of the table's friction under the block)"
                        .into(),
            })
    }
}

/// Errors reading or adding a custom effect.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CustomError {
    /// Not valid TOML or a key is missing or unknown.
    #[error(
        "custom effect file: {0}; expected `name = \"…\"` and one or more [[term]] tables with \
         `state`, `feature` and `coefficient`"
    )]
    Toml(String),
    /// A name that cannot be part of a parameter name.
    #[error(
        "custom effect name '{0}' must be non-empty letters, digits and '_' (it becomes part of the parameter names custom.<name>.<j>)"
    )]
    BadName(String),
    /// No terms.
    #[error("custom effect '{0}' has no terms; add at least one [[term]] table")]
    NoTerms(String),
    /// Unknown target state.
    #[error("unknown state '{name}' in a custom term; known: {known}")]
    UnknownState {
        /// The name given.
        name: String,
        /// The known targets.
        known: String,
    },
    /// A bad feature.
    #[error("custom effect '{effect}', term {term}: {source}")]
    Feature {
        /// The effect.
        effect: String,
        /// The term index (0-based).
        term: usize,
        /// What is wrong.
        source: FeatureError,
    },
    /// A coefficient that is not finite or outside its bounds ([`CustomTerm::bounds`]).
    #[error(
        "custom effect '{effect}', term {term}: coefficient {value} must be finite within [{lower}, {upper}] (a grip term on a region keeps the grip between 5 % and 4 × the rest's, a table-friction term the friction between 5 % and 10 ×)"
    )]
    BadCoefficient {
        /// The effect.
        effect: String,
        /// The term index.
        term: usize,
        /// The value.
        value: f64,
        /// Its bounds.
        lower: f64,
        /// Its bounds.
        upper: f64,
    },
    /// A table-friction term on a feature that is not of the position alone.
    #[error(
        "custom effect '{effect}', term {term}: the table's friction is a property of the place, so its feature must be of the position alone (x, y, gauss(…), band(…), strip(…)), not '{feature}'"
    )]
    NotAField {
        /// The effect.
        effect: String,
        /// The term index.
        term: usize,
        /// The feature given.
        feature: String,
    },
    /// Terms of both robots.
    #[error(
        "custom effect '{0}' mixes car and pushing terms; a custom effect belongs to one robot"
    )]
    MixedRobots(String),
    /// The effect belongs to the other robot.
    #[error("custom effect '{effect}' is for the {effect_robot:?} model, not the {robot:?} model")]
    WrongRobot {
        /// The effect.
        effect: String,
        /// Its robot.
        effect_robot: Robot,
        /// The model's robot.
        robot: Robot,
    },
    /// Two custom effects with one name.
    #[error("custom effect '{0}' is added twice; give each custom effect its own name")]
    Duplicate(String),
}

/// One term `ṡ_target += θ · feature(s, u)`.
#[derive(Clone, Debug, PartialEq)]
pub struct CustomTerm {
    /// The state derivative it adds to.
    pub target: Target,
    /// The feature.
    pub feature: Feature,
    /// The coefficient `θ` (start value; the model's parameter vector holds the fitted one).
    pub coefficient: f64,
}

/// Bounds of a grip term's coefficient on a region (a feature of bumps and bands, in `(0, 1]`):
/// the grip there stays between 5 % and 4 × the rest's.
pub const GRIP_REGION_BOUNDS: (f64, f64) = (-0.95, 3.0);

/// Bounds of a table-friction term's coefficient on a region: the friction there between 5 %
/// and 10 × the rest's (PTFE on steel against rubber on wood spans more).
pub const FRICTION_REGION_BOUNDS: (f64, f64) = (-0.95, 9.0);

impl CustomTerm {
    /// Unit of the coefficient: the derivative's over the feature's.
    pub fn coefficient_unit(&self) -> Unit {
        self.target.unit() / self.feature.unit()
    }

    /// Bounds of the coefficient: [`GRIP_REGION_BOUNDS`] for a grip term on a region (a
    /// coefficient below −1 would make the tires push, not grip), [`FRICTION_REGION_BOUNDS`]
    /// for a table-friction term on one, else `±`[`COEFFICIENT_BOUND`].
    pub fn bounds(&self) -> (f64, f64) {
        let region = !self.feature.factors().is_empty()
            && self.feature.factors().iter().all(Atom::is_region);
        match self.target {
            Target::Grip if region => GRIP_REGION_BOUNDS,
            Target::Friction if region => FRICTION_REGION_BOUNDS,
            _ => (-COEFFICIENT_BOUND, COEFFICIENT_BOUND),
        }
    }
}

/// A named set of custom terms (see the [module docs](self)). Serialises as the file format.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "CustomEffectSpec", into = "CustomEffectSpec")]
pub struct CustomEffect {
    name: String,
    terms: Vec<CustomTerm>,
    robot: Robot,
}

/// The file format of a custom effect (what TOML and JSON hold).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CustomEffectSpec {
    /// Name (letters, digits, `_`).
    pub name: String,
    /// Terms.
    #[serde(rename = "term")]
    pub terms: Vec<CustomTermSpec>,
}

/// One term in the file format.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CustomTermSpec {
    /// Target state (`vx`, `vy`, `omega`; `x`, `y`, `theta`, `bx`, `by`, `friction`).
    pub state: String,
    /// Feature (`delta*vx`).
    pub feature: String,
    /// Coefficient (start value).
    pub coefficient: f64,
}

impl TryFrom<CustomEffectSpec> for CustomEffect {
    type Error = CustomError;
    fn try_from(spec: CustomEffectSpec) -> Result<Self, CustomError> {
        let name = spec.name.trim().to_string();
        if name.is_empty() || !name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') {
            return Err(CustomError::BadName(spec.name));
        }
        if spec.terms.is_empty() {
            return Err(CustomError::NoTerms(name));
        }
        let mut terms = Vec::new();
        for (j, t) in spec.terms.iter().enumerate() {
            let target = Target::from_name(&t.state)?;
            let feature = Feature::parse(&t.feature).map_err(|source| CustomError::Feature {
                effect: name.clone(),
                term: j,
                source,
            })?;
            feature
                .check_robot(target.robot())
                .map_err(|source| CustomError::Feature {
                    effect: name.clone(),
                    term: j,
                    source,
                })?;
            if target.is_field() && !feature.factors().iter().all(Atom::is_position) {
                return Err(CustomError::NotAField {
                    effect: name,
                    term: j,
                    feature: feature.name(),
                });
            }
            let term = CustomTerm {
                target,
                feature,
                coefficient: t.coefficient,
            };
            let (lower, upper) = term.bounds();
            if !(t.coefficient.is_finite() && (lower..=upper).contains(&t.coefficient)) {
                return Err(CustomError::BadCoefficient {
                    effect: name,
                    term: j,
                    value: t.coefficient,
                    lower,
                    upper,
                });
            }
            terms.push(term);
        }
        let robot = terms[0].target.robot();
        if terms.iter().any(|t| t.target.robot() != robot) {
            return Err(CustomError::MixedRobots(name));
        }
        Ok(Self { name, terms, robot })
    }
}

impl From<CustomEffect> for CustomEffectSpec {
    fn from(c: CustomEffect) -> Self {
        CustomEffectSpec {
            name: c.name,
            terms: c
                .terms
                .iter()
                .map(|t| CustomTermSpec {
                    state: t.target.name().to_string(),
                    feature: t.feature.name(),
                    coefficient: t.coefficient,
                })
                .collect(),
        }
    }
}

impl CustomEffect {
    /// A custom effect from terms (validated as a file would be).
    pub fn new(name: &str, terms: Vec<CustomTerm>) -> Result<Self, CustomError> {
        CustomEffectSpec {
            name: name.to_string(),
            terms: terms
                .iter()
                .map(|t| CustomTermSpec {
                    state: t.target.name().to_string(),
                    feature: t.feature.name(),
                    coefficient: t.coefficient,
                })
                .collect(),
        }
        .try_into()
    }

    /// Parses the TOML file format (see the [module docs](self)).
    pub fn from_toml(text: &str) -> Result<Self, CustomError> {
        let spec: CustomEffectSpec = toml::from_str(text)
            .map_err(|e| CustomError::Toml(e.to_string().trim().to_string()))?;
        spec.try_into()
    }

    /// The TOML text of the effect (what [`CustomEffect::from_toml`] reads back).
    pub fn to_toml(&self) -> String {
        let mut o = format!("name = \"{}\"\n", self.name);
        for t in &self.terms {
            o.push_str(&format!(
                "\n[[term]]\nstate = \"{}\"\nfeature = \"{}\"\ncoefficient = {:e}   # {} · {} [{}]\n",
                t.target.name(),
                t.feature.name(),
                t.coefficient,
                t.target.symbol(),
                t.feature.symbol(),
                t.coefficient_unit().format(time_unit(self.robot)),
            ));
        }
        o
    }

    /// Name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Terms.
    pub fn terms(&self) -> &[CustomTerm] {
        &self.terms
    }

    /// The robot.
    pub fn robot(&self) -> Robot {
        self.robot
    }

    /// Whether a term uses a lagged command (`delta_rate(0.1)`, …): a model with the effect then
    /// carries the lagged commands as effect states.
    pub fn uses_input_lags(&self) -> bool {
        self.terms.iter().any(|t| t.feature.uses_input_lags())
    }

    /// The nominal parameters fitted wherever the effect is fitted, as
    /// [`Effect::coupled_nominal`](super::Effect::coupled_nominal) for the library's: a grip
    /// term takes the car's friction-ellipse weight `ellipse`, as a grip patch does. Nominal
    /// data rarely take the rear tire to its peak and cannot tell the weight; on less grip it
    /// decides how much lateral force the throttle leaves (on a car without an ellipse, fitted
    /// with the full one, the right low-grip strip removed 6.5 % of the held-out error, with the
    /// weight at 0 85 %).
    pub fn coupled_nominal(&self) -> &'static [&'static str] {
        self.coupling_target().map_or(&[], |t| t.coupled_nominal())
    }

    /// Whether [`CustomEffect::coupled_nominal`] is refitted with the terms whatever the gain
    /// ([`Target::always_refits`]).
    pub fn always_refits_coupled(&self) -> bool {
        self.coupling_target().is_some_and(Target::always_refits)
    }

    /// The first term's target with coupled parameters.
    fn coupling_target(&self) -> Option<Target> {
        self.terms
            .iter()
            .map(|t| t.target)
            .find(|t| !t.coupled_nominal().is_empty())
    }

    /// The same effect with new coefficients (one per term; fitted values).
    pub fn with_coefficients(&self, c: &[f64]) -> Self {
        let mut o = self.clone();
        for (t, &v) in o.terms.iter_mut().zip(c) {
            t.coefficient = v;
        }
        o
    }

    /// The equation of term `j` with coefficient `value` (and `± std` when given):
    /// `ω̇ += −3.2 ± 0.1 · δ·vₓ   [θ: 1/(m·s)]`.
    pub fn term_equation(&self, j: usize, value: f64, std: Option<f64>) -> String {
        let t = &self.terms[j];
        let c = match std {
            Some(s) if s.is_finite() && s > 0.0 => {
                format!("{} ± {}", fmt_num(value), fmt_num(s))
            }
            _ => fmt_num(value),
        };
        format!(
            "{} += {} · {}   [θ: {}]",
            t.target.symbol(),
            c,
            t.feature.symbol(),
            t.coefficient_unit().format(time_unit(self.robot))
        )
    }

    /// Whether a term acts on `target`.
    pub fn acts_on(&self, target: Target) -> bool {
        self.terms.iter().any(|t| t.target == target)
    }

    /// The correction of the input `target` (`δ`, `μ`): the sum of its terms with coefficients
    /// `theta` (0 without such terms).
    pub(crate) fn input<R: Real>(
        &self,
        target: Target,
        theta: &[R],
        p: &[R],
        s: &[R],
        u: &[R],
    ) -> R {
        let mut d = R::cst(0.0);
        for (t, &c) in self.terms.iter().zip(theta) {
            if t.target == target {
                d = d + c * t.feature.eval(self.robot, p, s, u);
            }
        }
        d
    }

    /// Adds the terms with coefficients `theta` to the vector field `out` at state `s`, input
    /// `u` (`p`: the model's nominal parameters, for the slip-angle atoms).
    pub(crate) fn add_to<R: Real>(&self, theta: &[R], p: &[R], s: &[R], u: &[R], out: &mut [R]) {
        for (t, &c) in self.terms.iter().zip(theta) {
            let v = c * t.feature.eval(self.robot, p, s, u);
            match t.target {
                // input corrections: `input`
                Target::Delta | Target::Grip | Target::Friction => {}
                Target::Vx => out[3] = out[3] + v,
                Target::Vy => out[4] = out[4] + v,
                Target::Omega => out[5] = out[5] + v,
                Target::WorldX | Target::WorldY => {
                    // the world-frame acceleration in the body frame: `R(ψ)ᵀ·a`
                    let (sp, cp) = (s[2].sin(), s[2].cos());
                    let (ax, ay) = if t.target == Target::WorldX {
                        (cp, -sp)
                    } else {
                        (sp, cp)
                    };
                    out[3] = out[3] + v * ax;
                    out[4] = out[4] + v * ay;
                }
                Target::X => out[0] = out[0] + v,
                Target::Y => out[1] = out[1] + v,
                Target::Theta => out[2] = out[2] + v,
                Target::BlockX | Target::BlockY => {
                    let (st, ct) = (s[2].sin(), s[2].cos());
                    let (bx, by) = if t.target == Target::BlockX {
                        (ct, st)
                    } else {
                        (-st, ct)
                    };
                    out[0] = out[0] + v * bx;
                    out[1] = out[1] + v * by;
                }
            }
        }
    }
}

/// Every atom name, for error messages and docs.
pub fn known_features(robot: Robot) -> String {
    Atom::names(robot).join(", ")
}

/// Compact number formatting: 4 significant digits, scientific outside [1e-4, 1e4), a true
/// minus sign.
pub fn fmt_num(v: f64) -> String {
    let a = v.abs();
    let s = if v == 0.0 {
        "0".into()
    } else if !(1e-4..1e4).contains(&a) {
        format!("{v:.3e}")
    } else {
        let digits = (3 - a.log10().floor() as i32).max(0) as usize;
        format!("{v:.digits$}")
    };
    s.replace('-', "−")
}

#[cfg(test)]
mod tests {
    use super::*;

    const FILE: &str = r#"
name = "steering_gain_speed"
[[term]]
state = "omega"
feature = "delta*vx"
coefficient = -3.2
"#;

    #[test]
    fn nominal_shaped_terms_name_their_parameter() {
        let f = |n: &str| Feature::parse(n).unwrap();
        assert_eq!(Target::Vx.nominal_parameter(&f("vx*vx")), Some("Cr2"));
        assert_eq!(Target::Vx.nominal_parameter(&f("vx*|vx|")), Some("Cr2"));
        assert_eq!(Target::Vx.nominal_parameter(&f("d*vx")), Some("Cm2"));
        assert_eq!(Target::Vx.nominal_parameter(&f("d")), Some("Cm1"));
        assert_eq!(Target::Vx.nominal_parameter(&f("1")), Some("Cr0"));
        // other shapes, or the same shape in another derivative, are candidate effects
        assert_eq!(Target::Vx.nominal_parameter(&f("vx")), None);
        assert_eq!(Target::Omega.nominal_parameter(&f("vx*vx")), None);
        assert_eq!(Target::Vy.nominal_parameter(&f("d")), None);
        // pushing: the push length and the limit-surface ratio
        assert_eq!(Target::BlockX.nominal_parameter(&f("l*cos_phi")), Some("L"));
        assert_eq!(Target::Theta.nominal_parameter(&f("l*sin_phi")), Some("c"));
        assert_eq!(Target::Theta.nominal_parameter(&f("l*p")), Some("c"));
        assert_eq!(Target::BlockY.nominal_parameter(&f("l")), None);
        assert_eq!(
            Target::BlockY.nominal_parameter(&f("l*sin_phi")),
            Some("pusher_friction.mu")
        );
        assert_eq!(
            Target::Delta.nominal_parameter(&f("1")),
            Some("steering_offset.delta0")
        );
        assert!(Target::Delta.searched_with(&f("delta*vx*vx")));
        assert!(!Target::Delta.searched_with(&f("alpha_r*vx")));
        assert_eq!(Target::Grip.nominal_parameter(&f("1")), Some("Df"));
        assert!(Target::Grip.searched_with(&f("gauss(0.5,0.2,0.4)")));
        assert!(Target::Grip.searched_with(&f("x")));
        assert!(!Target::Grip.searched_with(&f("gauss(0.5,0.2,0.4)*sat_alpha_r")));
        assert!(!Target::Grip.searched_with(&f("vx")));
        assert!(Target::Grip.searched_with(&f("band(0.785,0.2,0.3)")));
        assert!(!Target::Vy.searched_with(&f("band(0.785,0.2,0.3)")));
        assert!(Target::Grip.is_input() && Target::Delta.is_input() && !Target::Vy.is_input());
        assert!(Target::Omega.searched_with(&f("alpha_r*vx")));
        assert_eq!(Target::X.nominal_parameter(&f("l*cos_phi")), None);
    }

    #[test]
    fn a_grip_term_on_a_region_keeps_the_grip_positive() {
        let file = |state: &str, feature: &str, c: f64| {
            format!(
                "name = \"g\"\n[[term]]\nstate = \"{state}\"\nfeature = \"{feature}\"\ncoefficient = {c}\n"
            )
        };
        let region = CustomEffect::from_toml(&file("grip", "band(0.5,0.3,0.2)", -0.5)).unwrap();
        assert_eq!(region.terms()[0].bounds(), GRIP_REGION_BOUNDS);
        // `x` is not a region, a derivative's term not a grip term: wide bounds
        for (state, feature) in [("grip", "x"), ("vy", "gauss(0.5,0.2,0.4)")] {
            let c = CustomEffect::from_toml(&file(state, feature, -3.0)).unwrap();
            assert_eq!(
                c.terms()[0].bounds(),
                (-COEFFICIENT_BOUND, COEFFICIENT_BOUND)
            );
        }
        // less than no grip: the error names the bounds
        let e = CustomEffect::from_toml(&file("grip", "gauss(0.5,0.2,0.4)", -1.5)).unwrap_err();
        assert!(
            matches!(e, CustomError::BadCoefficient { lower, .. } if lower == GRIP_REGION_BOUNDS.0),
            "{e}"
        );
        assert!(e.to_string().contains("[-0.95, 3]"), "{e}");
    }

    #[test]
    fn a_world_frame_term_is_the_same_pull_at_every_heading() {
        let c = CustomEffect::from_toml(
            "name = \"slope\"\n[[term]]\nstate = \"ay\"\nfeature = \"1\"\ncoefficient = 0.2\n",
        )
        .unwrap();
        assert_eq!(c.terms()[0].target, Target::WorldY);
        assert_eq!(c.terms()[0].coefficient_unit().format("s"), "m/s²");
        // the constant needs no nominal parameter
        let p: [f64; 0] = [];
        for psi in [0.0, 0.7, 2.0, -2.5] {
            let s = [0.3, -0.1, psi, 1.2, 0.1, 0.5];
            let mut out = [0.0; 6];
            c.add_to(&[0.2], &p, &s, &[0.1, 0.4], &mut out);
            // back in the world frame: 0.2 along y, nothing along x, whatever the heading
            let (sp, cp) = (f64::sin(psi), f64::cos(psi));
            let world = [cp * out[3] - sp * out[4], sp * out[3] + cp * out[4]];
            assert!(
                world[0].abs() < 1e-12 && (world[1] - 0.2).abs() < 1e-12,
                "{psi}: {world:?}"
            );
            assert_eq!([out[0], out[1], out[2], out[5]], [0.0; 4]);
        }
        let f = |n: &str| Feature::parse(n).unwrap();
        assert!(Target::WorldY.searched_with(&f("1")));
        assert!(Target::WorldX.searched_with(&f("gauss(0.5,0.2,0.4)")));
        assert!(!Target::WorldX.searched_with(&f("sin_psi")));
        assert!(!Target::WorldX.searched_with(&f("band(0.785,0.2,0.3)")));
    }

    #[test]
    fn toml_round_trip() {
        let c = CustomEffect::from_toml(FILE).unwrap();
        assert_eq!(c.name(), "steering_gain_speed");
        assert_eq!(c.robot(), Robot::Car);
        assert_eq!(c.terms()[0].target, Target::Omega);
        assert_eq!(c.terms()[0].coefficient, -3.2);
        assert_eq!(c.terms()[0].coefficient_unit().format("s"), "1/(m·s)");
        let back = CustomEffect::from_toml(&c.to_toml()).unwrap();
        assert_eq!(back, c);
        let json = serde_json::to_string(&c).unwrap();
        assert_eq!(serde_json::from_str::<CustomEffect>(&json).unwrap(), c);
        assert_eq!(
            c.term_equation(0, -3.2, Some(0.1)),
            "ω̇ += −3.200 ± 0.1000 · δ·vₓ   [θ: 1/(m·s)]"
        );
    }

    #[test]
    fn bad_files_say_what_is_wrong() {
        let err = |t: &str| CustomEffect::from_toml(t).unwrap_err().to_string();
        let e = err(&FILE.replace("delta*vx", "delta*speed"));
        assert!(e.contains("'speed'") && e.contains("|v|"), "{e}");
        let e = err(&FILE.replace("\"omega\"", "\"yaw\""));
        assert!(e.contains("'yaw'") && e.contains("omega"), "{e}");
        let e = err(&FILE.replace("coefficient = -3.2\n", ""));
        assert!(e.contains("coefficient"), "{e}");
        let e = err(&FILE.replace("-3.2", "nan"));
        assert!(e.contains("finite"), "{e}");
        let e = err(&FILE.replace("\"omega\"", "\"theta\""));
        assert!(e.contains("'delta'"), "{e}");
        let e =
            err("name = \"a b\"\n[[term]]\nstate = \"vx\"\nfeature = \"vx\"\ncoefficient = 1\n");
        assert!(e.contains("letters"), "{e}");
        let e = err("name = \"a\"\nterm = []\n");
        assert!(e.contains("no terms"), "{e}");
        let e = err(&format!("{FILE}colour = 3\n"));
        assert!(e.contains("colour"), "{e}");
    }

    #[test]
    fn model_adds_the_terms_with_exact_jacobians() {
        use crate::ode::Solver;
        use crate::physics::PhysicsModel;
        let mut m = PhysicsModel::car(&[]).unwrap();
        let base = m.clone();
        m.add_custom(CustomEffect::from_toml(FILE).unwrap())
            .unwrap();
        assert_eq!(
            m.param_names().last().unwrap(),
            "custom.steering_gain_speed.0"
        );
        assert!(*m.default_free().last().unwrap());
        let (s, u) = ([0.1, 0.2, 0.3, 1.5, 0.05, 0.4], [0.2, 0.5]);
        let (mut f0, mut f1) = ([0.0; 6], [0.0; 6]);
        base.eval_one(&s, &u, &mut f0);
        m.eval_one(&s, &u, &mut f1);
        for i in 0..6 {
            let want = if i == 5 { -3.2 * 0.2 * 1.5 } else { 0.0 };
            assert!((f1[i] - f0[i] - want).abs() < 1e-12, "{i}");
        }
        let np = m.params().len();
        let nz = 6 + 2 + np;
        let mut j = vec![0.0; 6 * nz];
        let mut f = [0.0; 6];
        m.jacobian_full(&s, &u, &[], true, &mut f, &mut j);
        assert!((j[5 * nz + 8 + np - 1] - 0.2 * 1.5).abs() < 1e-12);
        assert!(
            (j[5 * nz + 6] - (-3.2 * 1.5) - {
                let mut jb = vec![0.0; 6 * (nz - 1)];
                base.jacobian_full(&s, &u, &[], true, &mut f0, &mut jb);
                jb[5 * (nz - 1) + 6]
            })
            .abs()
                < 1e-9
        );
        let eq = m.equations();
        assert!(
            eq.contains("ω̇ += −3.200 · δ·vₓ   [θ: 1/(m·s)]   (custom.steering_gain_speed.0)"),
            "{eq}"
        );
        assert!(
            m.add_custom(CustomEffect::from_toml(FILE).unwrap())
                .is_err()
        );
        // extending keeps the custom coefficient
        let mut m2 = m.clone();
        m2.set_param("custom.steering_gain_speed.0", -1.5).unwrap();
        let m3 = m2
            .with_effects(&[crate::physics::Effect::AeroDrag])
            .unwrap();
        assert_eq!(
            m3.params()[m3.param_index("custom.steering_gain_speed.0").unwrap()],
            -1.5
        );
        // and dropping an effect keeps the others' parameters and the coefficient
        let mut m4 = m3
            .with_effects(&[crate::physics::Effect::MotorLag])
            .unwrap();
        m4.set_param("aero_drag.c", 0.02).unwrap();
        m4.set_param("motor_lag.tau", 0.3).unwrap();
        let m5 = m4
            .without_effects(&[crate::physics::Effect::AeroDrag])
            .unwrap();
        assert_eq!(m5.effects(), vec![crate::physics::Effect::MotorLag]);
        assert!(m5.param_index("aero_drag.c").is_none());
        assert_eq!(m5.params()[m5.param_index("motor_lag.tau").unwrap()], 0.3);
        assert_eq!(
            m5.params()[m5.param_index("custom.steering_gain_speed.0").unwrap()],
            -1.5
        );
        assert_eq!(m5.params().len(), m4.params().len() - 1);
        // pushing, no push (ℓ = 0): a block-frame drift of 5 mm per push, world x then
        let text =
            "name = \"drift\"\n[[term]]\nstate = \"bx\"\nfeature = \"1\"\ncoefficient = 0.005\n";
        let mut p = PhysicsModel::pushing(&[]).unwrap();
        assert!(
            p.add_custom(CustomEffect::from_toml(FILE).unwrap())
                .is_err()
        );
        let pb = p.clone();
        p.add_custom(CustomEffect::from_toml(text).unwrap())
            .unwrap();
        let (s0, a) = ([0.5, 0.0, 0.3], [0.0, 0.2, 0.0]);
        let (mut o0, mut o1) = ([0.0; 3], [0.0; 3]);
        pb.integrate_step(&Solver::rk4(), 1, &s0, &a, 1.0, &mut o0);
        p.integrate_step(&Solver::rk4(), 1, &s0, &a, 1.0, &mut o1);
        assert_eq!(o0, s0);
        assert!((o1[0] - o0[0] - 0.005 * 0.3f64.cos()).abs() < 1e-12);
        assert!((o1[1] - o0[1] - 0.005 * 0.3f64.sin()).abs() < 1e-12);
    }
}
