//! Physics models of the two robots with named, pluggable effects.
//!
//! A [`PhysicsModel`] is a nominal model (the car's dynamic bicycle with Pacejka tires and
//! drivetrain, or the quasi-static pusher–slider) plus a list of enabled [`Effect`]s, with one
//! flat parameter vector `θ = [nominal…, effect 1…, effect 2…]`. It implements
//! [`VectorField`](crate::ode::VectorField), so it integrates with the same solvers as a network
//! and has exact Jacobians with respect to state, input and parameters.
//!
//! **The effect interface.** An effect is a named term with physical parameters
//! ([`Effect::params`]: name, symbol, unit, bounds, default), a contribution to the dynamics and
//! its derivatives. The *contribution* of enabled effect `e` is
//! `Δf_e(s, u) = f(s, u) − f_{without e}(s, u)`: exactly additive for additive terms
//! (`aero_drag`), and the induced change for effects that modify an intermediate quantity
//! (`steering_offset` shifts δ, `grip_patch` scales the tire peaks). [`PhysicsModel::effect_term`]
//! gives the contribution with its exact Jacobians wrt state, input and the effect's own
//! parameters; [`Effect::linear_in_params`] says whether the contribution is linear in those
//! parameters (then the diagnosis can fit it by constrained linear least squares).
//!
//! **Custom effects** ([`custom`]): terms `ṡ_i += θ_j · feature_j(s, u)` over the named
//! [`features`] library, read from a small TOML file and added with
//! [`PhysicsModel::add_custom`]; their coefficients follow the library effects' parameters.
//!
//! Derivatives are exact: the models are written once, generically over
//! [`Real`](crate::real::Real), and differentiated by forward-mode dual numbers. There is no
//! second, hand-differentiated copy of the equations to drift out of sync.

mod car;
pub mod custom;
pub mod features;
mod fit;
mod model;
mod push;
mod step;
mod support;

pub use car::{
    CAR_FITTED_PARAMS, CAR_NOMINAL_PARAMS, COMMAND_DELAY_STATES, MOTOR_LAG_STATE,
    STEERING_LAG_STATE,
};
pub use custom::{CustomEffect, CustomError, CustomTerm, Target};
pub use features::{Feature, FeatureError};
pub use fit::{ResidualJacobian, Transition, residuals, residuals_and_jacobian};
pub use model::{EffectTerm, ModelError, PhysicsModel};
pub use push::{
    LimitSurface, PUSH_FITTED_PARAMS, PUSH_NOMINAL_PARAMS, PUSHER_RADIUS_M, support_grid,
};
pub use step::StepTape;

use crate::ode::InputTape;
use std::cell::{Cell, RefCell};

/// Which robot a model or effect belongs to.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Robot {
    /// The RC car: state `(x, y, ψ, vx, vy, ω)` (+ effect states), input `(δ, d)`, time in seconds.
    Car,
    /// The planar pusher: state `(x, y, θ)`, action `(p, φ, ℓ)`, time in pushes (one push = 1).
    Pushing,
}

/// A physical parameter: what it is, its unit, bounds and documented default.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct ParamSpec {
    /// Name used in files and on the command line (`c`, `tau`, `delta0`).
    pub name: &'static str,
    /// Symbol for printed equations (`c`, `τ`, `δ₀`).
    pub symbol: &'static str,
    /// Unit (`1/m`, `s`, `rad`, `-`).
    pub unit: &'static str,
    /// Lower bound.
    pub lower: f64,
    /// Upper bound.
    pub upper: f64,
    /// Default value.
    pub default: f64,
    /// One line: meaning and where the default comes from.
    pub description: &'static str,
}

const fn ps(
    name: &'static str,
    symbol: &'static str,
    unit: &'static str,
    lower: f64,
    upper: f64,
    default: f64,
    description: &'static str,
) -> ParamSpec {
    ParamSpec {
        name,
        symbol,
        unit,
        lower,
        upper,
        default,
        description,
    }
}

/// The library of candidate physical effects (DESIGN.md, "Finding the missing physics").
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Effect {
    /// Car: aerodynamic drag `F = −c·|v|·v` on the body velocity vector `v = (vx, vy)`, so
    /// `v̇x −= c|v|vx/m`, `v̇y −= c|v|vy/m` (the simulator's hidden drag). The nominal
    /// `C_r2·vx|vx|` stays fixed at its published value, so this term is identifiable.
    AeroDrag,
    /// Car: first-order lag of the motor: the drivetrain sees the filtered throttle `d_f`,
    /// `ḋ_f = (d − d_f)/τ`, an extra state (see [`MOTOR_LAG_STATE`]).
    MotorLag,
    /// Car: steering offset, the wheels turn to `δ + δ₀`.
    SteeringOffset,
    /// Car: a circular patch of the floor where both tire peak forces are scaled by `k`.
    GripPatch,
    /// Car: the steering servo: the wheels turn to the wheel angle `δ_w`, an extra state (see
    /// [`STEERING_LAG_STATE`]) that follows the commanded angle (plus `δ₀` with
    /// `steering_offset`) as a first-order lag with a smooth rate limit,
    /// `δ̇_w = r·tanh((δ − δ_w)/(r·τ_s))`: a lag of time constant `τ_s` for small steps, the
    /// rate `r` at most for large ones (differentiable everywhere; `r` at its upper bound is a
    /// plain first-order lag).
    SteeringLag,
    /// Car: a transport delay of both commands (radio link, bus, servo electronics): the car
    /// acts on the commands sent `t_d` earlier. Modelled per command by the [1/2] Padé
    /// approximant of the delay, `(1 − s·t_d/3)/(1 + 2s·t_d/3 + s²·t_d²/6)` (exact to third
    /// order in frequency, strictly proper: nothing of a command step reaches the car at once),
    /// four extra states (see [`COMMAND_DELAY_STATES`]); `steering_lag` and `motor_lag` act on
    /// the delayed commands.
    CommandDelay,
    /// Pushing: the block's centre of mass (centre of friction) is offset from its geometric
    /// centre by `(o_x, o_y)` in the block frame.
    ComOffset,
    /// Pushing: a tilted table; gravity along the table, `(g_x, g_y) = tan α/μ·(cos, sin)` of
    /// the downhill direction (world frame, normalised by the friction limit), acts at the
    /// centre of mass and shares the friction limit with the pusher force.
    TableTilt,
    /// Pushing: a circular patch of the table where the block–table μ is `k` times the table's,
    /// per support point: a block partly on the patch has its centre of friction moved towards
    /// the patch (and turns); fully on or off, quasi-static motion is unchanged.
    FrictionPatch,
    /// Pushing: Coulomb friction `μ_p` between pusher and block (the nominal pusher is
    /// frictionless): sticking inside the motion cone, sliding on its edge.
    PusherFriction,
    /// Pushing: a flat pusher, a pad of half width `w` and half thickness `t` held at the world
    /// yaw `ψ_f` whatever the block's heading (a gripper kept at one orientation): turned
    /// against the face, it touches with its leading corner, off the commanded point, and the
    /// block turns towards the pad's yaw.
    FlatPusher,
}

static AERO_DRAG: [ParamSpec; 1] = [ps(
    "c",
    "c",
    "N·s²/m²",
    0.0,
    1.0,
    0.0,
    "drag coefficient ½ρC_dA on top of the nominal C_r2 (the simulator's default: 0.01)",
)];
static MOTOR_LAG: [ParamSpec; 1] = [ps(
    "tau",
    "τ",
    "s",
    1e-3,
    1.0,
    0.05,
    "time constant of the throttle-to-drive lag",
)];
static STEERING_OFFSET: [ParamSpec; 1] = [ps(
    "delta0",
    "δ₀",
    "rad",
    -0.2,
    0.2,
    0.0,
    "constant offset added to the commanded front wheel angle",
)];
static STEERING_LAG: [ParamSpec; 2] = [
    ps(
        "tau",
        "τ_s",
        "s",
        0.01,
        1.0,
        0.05,
        "time constant of the steering servo (≥ 10 ms: a faster servo is not identifiable at \
         100 Hz, and the model step's RK4 stays stable)",
    ),
    ps(
        "rate",
        "r",
        "rad/s",
        0.05,
        50.0,
        50.0,
        "largest wheel-angle rate of the servo (default: the upper bound, no effective limit)",
    ),
];
static COMMAND_DELAY: [ParamSpec; 1] = [ps(
    "delay",
    "t_d",
    "s",
    0.02,
    0.5,
    0.05,
    "transport delay of both commands (a second-order Padé filter; ≥ 20 ms: its poles, \
     √6/t_d from the origin, keep the model step's RK4 stable)",
)];
static GRIP_PATCH: [ParamSpec; 5] = [
    ps(
        "cx",
        "c_x",
        "m",
        -100.0,
        100.0,
        0.0,
        "patch centre x (world)",
    ),
    ps(
        "cy",
        "c_y",
        "m",
        -100.0,
        100.0,
        0.0,
        "patch centre y (world)",
    ),
    ps("r", "r", "m", 0.01, 100.0, 0.5, "patch radius"),
    ps(
        "w",
        "w",
        "m",
        0.005,
        10.0,
        0.05,
        "width of the smooth patch edge (logistic)",
    ),
    ps(
        "k",
        "k",
        "-",
        0.0,
        3.0,
        1.0,
        "tire peak force scale inside the patch (1: no change)",
    ),
];
static COM_OFFSET: [ParamSpec; 2] = [
    ps(
        "ox",
        "o_x",
        "m",
        -0.05,
        0.05,
        0.0,
        "centre-of-mass offset along the block x axis",
    ),
    ps(
        "oy",
        "o_y",
        "m",
        -0.05,
        0.05,
        0.0,
        "centre-of-mass offset along the block y axis",
    ),
];
static TABLE_TILT: [ParamSpec; 2] = [
    ps(
        "gx",
        "g_x",
        "m/m",
        -1.0,
        1.0,
        0.0,
        "tilt force along world x over the friction limit (tan α·cos dir/μ)",
    ),
    ps(
        "gy",
        "g_y",
        "m/m",
        -1.0,
        1.0,
        0.0,
        "tilt force along world y over the friction limit (tan α·sin dir/μ)",
    ),
];
static FRICTION_PATCH: [ParamSpec; 5] = [
    ps(
        "cx",
        "c_x",
        "m",
        -10.0,
        10.0,
        0.6,
        "patch centre x (table frame)",
    ),
    ps(
        "cy",
        "c_y",
        "m",
        -10.0,
        10.0,
        0.0,
        "patch centre y (table frame)",
    ),
    ps("r", "r", "m", 0.005, 10.0, 0.1, "patch radius"),
    ps(
        "w",
        "w",
        "m",
        0.001,
        1.0,
        0.01,
        "width of the smooth patch edge (logistic)",
    ),
    ps(
        "k",
        "k",
        "-",
        0.05,
        20.0,
        1.0,
        "block–table friction inside the patch over the table's, μ_patch/μ (1: no change)",
    ),
];
static FLAT_PUSHER: [ParamSpec; 3] = [
    ps(
        "yaw",
        "ψ_f",
        "rad",
        -std::f64::consts::PI,
        std::f64::consts::PI,
        0.0,
        "world yaw of the pad's face normal (a pad turned by π is the same pad)",
    ),
    ps(
        "half_width",
        "w",
        "m",
        0.0,
        0.1,
        0.02,
        "half width of the pad along its face",
    ),
    ps(
        "half_thickness",
        "t",
        "m",
        0.001,
        0.1,
        push::PUSHER_RADIUS_M,
        "half thickness of the pad, along its face normal (a pad turned a quarter with width and \
         thickness swapped is the same pad; ≥ 1 mm: a fit that wants no thickness at all is not \
         a pad, as on a table with a grain, which it otherwise took for one)",
    ),
];
static PUSHER_FRICTION: [ParamSpec; 1] = [ps(
    "mu",
    "μ_p",
    "-",
    0.0,
    2.0,
    0.0,
    "Coulomb friction coefficient between pusher and block",
)];

/// The centres of the cells of an `n × n` lattice over the rectangle `lo`–`hi`.
pub fn lattice(lo: [f64; 2], hi: [f64; 2], n: usize) -> Vec<[f64; 2]> {
    let f = |i: usize| (i as f64 + 0.5) / n as f64;
    (0..n)
        .flat_map(|a| {
            (0..n).map(move |b| {
                [
                    lo[0] + f(a) * (hi[0] - lo[0]),
                    lo[1] + f(b) * (hi[1] - lo[1]),
                ]
            })
        })
        .collect()
}

/// Patch starts: discs of radius `r` and edge width `w` centred on an `n × n` lattice over
/// `lo`–`hi`, each with every factor of `ks`.
fn discs(
    lo: [f64; 2],
    hi: [f64; 2],
    n: usize,
    r: f64,
    w: f64,
    ks: [f64; 2],
) -> Vec<Vec<(&'static str, f64)>> {
    lattice(lo, hi, n)
        .into_iter()
        .flat_map(|[x, y]| ks.map(|k| vec![("cx", x), ("cy", y), ("r", r), ("w", w), ("k", k)]))
        .collect()
}

impl Effect {
    /// Every effect in the library.
    pub const ALL: [Effect; 11] = [
        Effect::AeroDrag,
        Effect::MotorLag,
        Effect::SteeringOffset,
        Effect::GripPatch,
        Effect::SteeringLag,
        Effect::CommandDelay,
        Effect::ComOffset,
        Effect::TableTilt,
        Effect::FrictionPatch,
        Effect::PusherFriction,
        Effect::FlatPusher,
    ];

    /// The nominal parameters fitted wherever the effect is fitted (training and diagnosis): a
    /// grip patch takes the car's friction-ellipse weight `ellipse`. Nominal data rarely take the
    /// rear tire to its peak, so a nominal fit cannot tell the weight; under throttle on low grip
    /// it decides how much lateral force is left, and a patch fitted with the wrong weight is
    /// the wrong patch (found on 2 of 5 cars without an ellipse, diagnosed with the full one).
    pub fn coupled_nominal(self) -> &'static [&'static str] {
        match self {
            Effect::GripPatch => &["ellipse"],
            _ => &[],
        }
    }

    /// Whether the effect acts on a region of the floor or table only (the patches): its
    /// parameters do not reach motion that never crosses the region.
    pub fn is_regional(self) -> bool {
        matches!(self, Effect::GripPatch | Effect::FrictionPatch)
    }

    /// The name used in files and on the command line (`aero_drag`, …).
    pub fn name(self) -> &'static str {
        match self {
            Effect::AeroDrag => "aero_drag",
            Effect::MotorLag => "motor_lag",
            Effect::SteeringOffset => "steering_offset",
            Effect::SteeringLag => "steering_lag",
            Effect::CommandDelay => "command_delay",
            Effect::GripPatch => "grip_patch",
            Effect::ComOffset => "com_offset",
            Effect::TableTilt => "table_tilt",
            Effect::FrictionPatch => "friction_patch",
            Effect::PusherFriction => "pusher_friction",
            Effect::FlatPusher => "flat_pusher",
        }
    }

    /// Looks an effect up by name.
    pub fn from_name(name: &str) -> Option<Effect> {
        Effect::ALL.into_iter().find(|e| e.name() == name)
    }

    /// The robot the effect applies to.
    pub fn robot(self) -> Robot {
        match self {
            Effect::AeroDrag
            | Effect::MotorLag
            | Effect::SteeringOffset
            | Effect::SteeringLag
            | Effect::CommandDelay
            | Effect::GripPatch => Robot::Car,
            _ => Robot::Pushing,
        }
    }

    /// One-line physical description.
    pub fn description(self) -> &'static str {
        match self {
            Effect::AeroDrag => "aerodynamic drag, quadratic in speed",
            Effect::MotorLag => "first-order lag between throttle command and drive force",
            Effect::SteeringOffset => "constant steering offset (miscalibrated servo trim)",
            Effect::SteeringLag => {
                "steering servo lag and rate limit (wheel angle behind the command)"
            }
            Effect::CommandDelay => "transport delay of both commands (the car acts late)",
            Effect::GripPatch => "floor patch with different tire grip",
            Effect::ComOffset => {
                "centre of mass away from the geometric centre (to a point pusher, o_y is nearly the same as the contact sitting −o_y off its commanded point along the face: a pusher's calibration, a finger's corner)"
            }
            Effect::TableTilt => "tilted table: downhill drift while sliding",
            Effect::FrictionPatch => "table patch with different friction",
            Effect::PusherFriction => "friction at the pusher contact (sticking/sliding)",
            Effect::FlatPusher => {
                "flat pusher held at one world yaw: touches with a corner and turns the block towards its face"
            }
        }
    }

    /// The effect's parameters, in the order they appear in the model's parameter vector.
    pub fn params(self) -> &'static [ParamSpec] {
        match self {
            Effect::AeroDrag => &AERO_DRAG,
            Effect::MotorLag => &MOTOR_LAG,
            Effect::SteeringOffset => &STEERING_OFFSET,
            Effect::SteeringLag => &STEERING_LAG,
            Effect::CommandDelay => &COMMAND_DELAY,
            Effect::GripPatch => &GRIP_PATCH,
            Effect::ComOffset => &COM_OFFSET,
            Effect::TableTilt => &TABLE_TILT,
            Effect::FrictionPatch => &FRICTION_PATCH,
            Effect::PusherFriction => &PUSHER_FRICTION,
            Effect::FlatPusher => &FLAT_PUSHER,
        }
    }

    /// Starting points of a fit of the effect's parameters (each a list of `(name, value)`, the
    /// rest at their defaults), the patches' over the rectangle `lo`–`hi` that the data's
    /// positions span. From its defaults alone a fit seldom finds the effect: a patch away
    /// from the default disc has no gradient, and a servo's rate limit has next to none at its
    /// no-limit default (the rate's upper bound).
    pub fn starts(self, lo: [f64; 2], hi: [f64; 2]) -> Vec<Vec<(&'static str, f64)>> {
        let extent = (hi[0] - lo[0]).max(hi[1] - lo[1]);
        let one = |name: &'static str, values: &[f64]| -> Vec<Vec<(&'static str, f64)>> {
            values.iter().map(|&v| vec![(name, v)]).collect()
        };
        match self {
            Effect::AeroDrag => one("c", &[0.0, 0.003, 0.01, 0.03, 0.1]),
            Effect::MotorLag => one("tau", &[0.02, 0.05, 0.1, 0.2, 0.35, 0.6]),
            // a plain lag (the rate at its bound) and two rate limits
            Effect::SteeringLag => [0.02, 0.05, 0.1, 0.2]
                .into_iter()
                .flat_map(|t| [50.0, 6.0, 2.0].map(|r| vec![("tau", t), ("rate", r)]))
                .collect(),
            Effect::CommandDelay => one("delay", &[0.03, 0.06, 0.12, 0.25]),
            Effect::SteeringOffset => one("delta0", &[-0.05, -0.01, 0.0, 0.01, 0.05]),
            Effect::GripPatch => discs(lo, hi, 3, 0.3 * extent.max(0.1), 0.05, [0.5, 1.5]),
            Effect::ComOffset => vec![vec![("ox", 0.0), ("oy", 0.0)]],
            Effect::TableTilt => vec![vec![("gx", 0.0), ("gy", 0.0)]],
            Effect::FrictionPatch => discs(lo, hi, 3, 0.25 * extent.max(0.02), 0.01, [0.3, 3.0]),
            Effect::PusherFriction => one("mu", &[0.1, 0.4, 1.0]),
            // the pad is the same turned by π: yaws over half a turn, a narrow and a wide pad
            Effect::FlatPusher => [-1.2, -0.6, 0.0, 0.6, 1.2]
                .into_iter()
                .flat_map(|y| [0.012, 0.025].map(|w| vec![("yaw", y), ("half_width", w)]))
                .collect(),
        }
    }

    /// More starting points for a fit with no screen of its own (`train`; the diagnosis adds
    /// discs from a one-step screen of the residual instead): the patches' discs, half the
    /// radius, on a 5 × 5 lattice. On 12 × 6 m of driving the 3 × 3 lattice's discs (3.5 m)
    /// each covered more normal floor than patch, and none beat the defaults.
    pub fn fine_starts(self, lo: [f64; 2], hi: [f64; 2]) -> Vec<Vec<(&'static str, f64)>> {
        let extent = (hi[0] - lo[0]).max(hi[1] - lo[1]);
        match self {
            Effect::GripPatch => discs(lo, hi, 5, 0.15 * extent.max(0.1), 0.05, [0.5, 1.5]),
            Effect::FrictionPatch => discs(lo, hi, 5, 0.125 * extent.max(0.02), 0.01, [0.3, 3.0]),
            _ => Vec::new(),
        }
    }

    /// Writes the effect's parameters `v` (and their standard errors `std`, same length or
    /// empty) in one form of the ones that give the same model: a flat pusher is the same pad
    /// turned by π, and with width and thickness swapped turned a quarter, so its half width
    /// is the larger and its yaw lies in (−π/2, π/2]. Every other effect has one form.
    pub fn canonical(self, v: &mut [f64], std: &mut [f64]) {
        if self != Effect::FlatPusher || v.len() != 3 {
            return;
        }
        if v[2] > v[1] {
            v.swap(1, 2);
            if std.len() == 3 {
                std.swap(1, 2);
            }
            v[0] += std::f64::consts::FRAC_PI_2;
        }
        let pi = std::f64::consts::PI;
        v[0] -= pi * ((v[0] - 0.5 * pi) / pi).ceil();
    }

    /// Whether the contribution is linear in the effect's parameters (for all states and
    /// inputs), so that it can be fitted by linear least squares. `aero_drag` is; the others
    /// enter through nonlinear functions (`table_tilt` shares the friction limit with the
    /// pusher force, the patches saturate).
    pub fn linear_in_params(self) -> bool {
        matches!(self, Effect::AeroDrag)
    }

    /// Names of the states the effect adds to the model state (appended in effect order).
    /// An effect state's rate depends only on the effect states, the input and the parameters,
    /// never on the robot's state, so it can be rebuilt from the command history alone
    /// ([`PhysicsModel::effect_states_along`]).
    pub fn extra_states(self) -> &'static [&'static str] {
        match self {
            Effect::MotorLag => &[MOTOR_LAG_STATE],
            Effect::SteeringLag => &[STEERING_LAG_STATE],
            Effect::CommandDelay => &COMMAND_DELAY_STATES,
            _ => &[],
        }
    }

    /// The shortest time constant of the effect's states that its parameters' bounds allow
    /// (`None` without states): the effect-state integration's substeps follow from it.
    pub fn shortest_time_constant(self) -> Option<f64> {
        match self {
            Effect::MotorLag | Effect::SteeringLag => Some(self.params()[0].lower),
            // the Padé filter's poles lie √6/t_d from the origin
            Effect::CommandDelay => Some(self.params()[0].lower / 6f64.sqrt()),
            _ => None,
        }
    }
}

impl std::fmt::Display for Effect {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// Writes one forward-mode pass: the values of `out` to `f` and their derivatives along the
/// pass's directions to columns `base..base + N` of the dense row-major Jacobian `j` (`nz`
/// columns; directions past `nz` are padding and dropped).
fn scatter_duals<const N: usize>(
    out: &[crate::real::Dual<N>],
    base: usize,
    nz: usize,
    f: &mut [f64],
    j: &mut [f64],
) {
    for (r, o) in out.iter().enumerate() {
        f[r] = o.v;
        for k in 0..N.min(nz.saturating_sub(base)) {
            j[r * nz + base + k] = o.d[k];
        }
    }
}

/// One row of a vector–Jacobian product from a dense Jacobian `j` (`ȳ.len()` rows; columns: the
/// state, then the input, then the parameters if any): sets `s̄ = ȳᵀ ∂f/∂s`, `ū = ȳᵀ ∂f/∂u` and
/// adds `ȳᵀ ∂f/∂p` to `p̄` (parameters only when `p̄` is not empty).
fn vjp_row(ybar: &[f64], j: &[f64], sbar: &mut [f64], ubar: &mut [f64], pbar: &mut [f64]) {
    let (ds, du) = (sbar.len(), ubar.len());
    let nz = j.len() / ybar.len().max(1);
    let cols = if pbar.is_empty() { ds + du } else { nz };
    for c in 0..cols {
        let g: f64 = (0..ybar.len()).map(|r| ybar[r] * j[r * nz + c]).sum();
        if c < ds {
            sbar[c] = g;
        } else if c < ds + du {
            ubar[c - ds] = g;
        } else {
            pbar[c - ds - du] += g;
        }
    }
}

/// What a physics field keeps for its reverse pass: the call's inputs and, once a reverse pass
/// has needed them, each sample's Jacobian `∂f/∂[s, u, θ]`. A step's Jacobian takes one reverse
/// pass per state row through the same taped stages; the field's derivatives are evaluated on
/// the first and reused by the others.
#[derive(Debug, Default)]
pub struct JacobianTape {
    inputs: InputTape<f64>,
    /// Whether `jac` holds the Jacobians at the recorded inputs, and with the θ columns: `None`
    /// until a reverse pass after the last record
    with_p: Cell<Option<bool>>,
    /// `n × dim_s × nz`, the buffer reused from record to record
    jac: RefCell<Vec<f64>>,
}

impl JacobianTape {
    fn record(&mut self, n: usize, s: &[f64], u: &[f64]) {
        self.inputs.record(n, s, u);
        self.with_p.set(None);
    }

    /// The reverse pass of [`VectorField::vjp`](crate::ode::VectorField::vjp) over the recorded
    /// samples, with `jac(s, u, with_θ, f, J)` writing one sample's value and Jacobian
    /// (`dim_s × nz`, `nz = dim_s + dim_u (+ n_params)`).
    fn vjp(
        &self,
        (ds, du, np): (usize, usize, usize),
        jac: impl Fn(&[f64], &[f64], bool, &mut [f64], &mut [f64]),
        ybar: &[f64],
        sbar: &mut [f64],
        ubar: &mut [f64],
        pbar: &mut [f64],
    ) {
        let n = self.inputs.n;
        let want_p = !pbar.is_empty();
        let has_p = match self.with_p.get() {
            Some(has_p) if has_p || !want_p => has_p,
            _ => {
                let nz = ds + du + if want_p { np } else { 0 };
                let mut js = self.jac.borrow_mut();
                js.clear();
                js.resize(n * ds * nz, 0.0);
                let mut f = vec![0.0; ds];
                for (i, j) in js.chunks_exact_mut(ds * nz).enumerate() {
                    let s = &self.inputs.s[i * ds..(i + 1) * ds];
                    let u = &self.inputs.u[i * du..(i + 1) * du];
                    jac(s, u, want_p, &mut f, j);
                }
                self.with_p.set(Some(want_p));
                want_p
            }
        };
        let per = ds * (ds + du + if has_p { np } else { 0 });
        let js = self.jac.borrow();
        for i in 0..n {
            vjp_row(
                &ybar[i * ds..(i + 1) * ds],
                &js[i * per..(i + 1) * per],
                &mut sbar[i * ds..(i + 1) * ds],
                &mut ubar[i * du..(i + 1) * du],
                pbar,
            );
        }
    }
}
