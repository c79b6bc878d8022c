//! A library of named, unit-carrying features of the state and input of each robot, the
//! building blocks of [custom effects](super::CustomEffect) and of the term search in
//! `dynlab-diagnose` (`discovery`).
//!
//! A [`Feature`] is a product of one or more [`Atom`]s, written in files as the atoms' names
//! joined by `*` (`delta*vx`, `delta*vx*vx`, `vx*|vx|`) and printed with their symbols
//! (`δ·vₓ`, `δ·vₓ²`, `vₓ·|vₓ|`). Every atom is written once, generically over
//! [`Real`], so a model with custom terms keeps exact Jacobians.
//!
//! Atoms of the car (state `(x, y, ψ, vx, vy, ω)`, input `(δ, d)`):
//!
//! | name | symbol | unit | meaning |
//! |---|---|---|---|
//! | `vx`, `vy` | `vₓ`, `v_y` | m/s | body-frame velocity |
//! | `omega` | `ω` | 1/s | yaw rate |
//! | `delta` | `δ` | rad | commanded front wheel angle |
//! | `d` | `d` | - | throttle command |
//! | `\|v\|` | `\|v\|` | m/s | speed `√(vx² + vy²)` |
//! | `\|vx\|` | `\|vₓ\|` | m/s | `\|vx\|` (so `vx*\|vx\|` is `vx\|vx\|`) |
//! | `alpha_f`, `alpha_r` | `α_f`, `α_r` | rad | slip angles exactly as the nominal model computes them (`v_reg`-regularised) |
//! | `sat_alpha_f`, `sat_alpha_r` | `tanh(α_f/α₀)` | - | saturating slip, `α₀` = [`SLIP_SCALE_RAD`] |
//! | `beta` | `β` | rad | sideslip `atan(vy/√(vx² + v_reg²))` |
//! | `sat_vx2(v0)` | `vₓ²/(vₓ² + v₀²)` | - | saturating speed with the scale `v₀` \[m/s\] (> 0): `δ·(1 − vₓ²/(vₓ² + v₀²))` is the steady-state steering gain `1/(1 + vₓ²/v₀²)` of a car that understeers with the characteristic speed `v₀` |
//! | `cos_psi`, `sin_psi` | `cos ψ`, `sin ψ` | - | heading; on a velocity derivative a pull fixed in the world frame (a sloping floor, a steady wind): `v̇ₓ += a·cos(ψ − φ)` for a pull `a` towards `φ` is `a·cos φ·cos ψ + a·sin φ·sin ψ` (the world-frame targets `ax`, `ay` take the whole pull, on both velocities, as `ẍ += a·cos φ`, `ÿ += a·sin φ` on `1`) |
//! | `delta_beyond(l)`, `d_beyond(l)` | `δ_{>l}`, `d_{>l}` | - | the part of a command beyond the level `l` (> 0), with its sign: `sgn(u)·max(\|u\| − l, 0)`, the shape of an actuator's hard limit: `δ += −1·δ_{>l}` is a steering end stop at `l` rad, a negative `v̇ₓ` term on `d_{>l}` a drive force capped by the tyres' traction or the motor's current limit |
//!
//! Atoms of the pusher (state `(x, y, θ)`, action `(p, φ, ℓ)`): `p`, `phi` (`φ`, rad), `l`
//! (`ℓ`), `cos_phi`, `sin_phi`, `theta` (`θ`, rad), `cos_theta`, `sin_theta`, and the doubled
//! heading `cos_2theta`, `sin_2theta` (`cos 2θ`, `sin 2θ`). A frictionless pusher presses along
//! the pushed face's normal, the block's heading `θ` in the world, whatever the push angle `φ`;
//! a table whose friction depends on the direction (a grain, which has no sign) turns the
//! block's motion away from that normal by an amount periodic in `2(θ − γ)` for a grain at `γ`,
//! and `a·sin 2θ + b·cos 2θ` is `A·sin 2(θ − γ)` for any `γ`. The library's
//! `ℓ·cos φ·sin 2θ`, `ℓ·cos φ·cos 2θ` scale it by the pusher's advance along the normal.
//!
//! Both robots: `x`, `y` (m, world/table frame), `1` (a constant) and position basis functions
//! `gauss(cx,cy,r)` = `exp(−((x − cx)² + (y − cy)²)/(2r²))` (a Gaussian bump of width `r` \[m\]
//! centred at `(cx, cy)`, for region-dependent effects; the term search puts them on a coarse
//! grid over the driven area) and `band(a,d,w)` = `exp(−(n·(x, y) − d)²/(2w²))` with `n =
//! (−sin a, cos a)` (a straight band along the direction `a` \[rad\], at the signed distance
//! `d` \[m\] from the origin, of width `w` \[m\]: a strip of other grip across a floor, which
//! one bump covers only in part; the term search puts them at 4 directions × `grid` offsets
//! and tries them on the car's grip). Angles count as dimensionless in units (rad = 1), so
//! `ω̇ += θ·δ·vₓ` has `θ` in `1/(m·s)`.
//!
//! **Lagged inputs** (car): `delta_lag(τ)`, `d_lag(τ)` (`δ_{τ s}`, `d_{τ s}`) are the commands
//! seen through a first-order lag of time constant `τ`, and `delta_rate(τ)`, `d_rate(τ)`
//! (`δ̇_{τ s}`, `ḋ_{τ s}`, 1/s) the commands' rates seen through it, `(δ − δ_τ)/τ`. A command
//! that acts `t_d` late is `δ(t − t_d) ≈ δ − t_d·δ̇`, so `δ += θ·δ̇_{τ s}` is a steering delay of
//! `−θ` seconds (for delays up to about `τ`; `θ = −τ` is the lag `δ_τ` itself). `τ` is one of
//! [`INPUT_LAGS_S`]. They need the command history: a model with a custom term on them carries
//! the lagged commands as effect states ([`INPUT_LAG_STATES`], last in the state), rebuilt from
//! the command history at the start of each window like the library's lags. Their values reach
//! [`Atom::eval`] as the input's entries past the commands: `u = (δ, d, δ_{τ₁}, d_{τ₁}, …)` in
//! the order of [`INPUT_LAGS_S`] ([`input_lag_index`]); without them the atoms are `NaN`.

use std::fmt::Write as _;

use super::Robot;
use crate::real::Real;

/// Scale `α₀` of the saturating slip atoms `tanh(α/α₀)` \[rad\]: about where the small ORCA
/// tires leave their linear range.
pub const SLIP_SCALE_RAD: f64 = 0.1;

/// Most factors in one feature.
pub const MAX_FACTORS: usize = 4;

/// Time constants \[s\] of the car's lagged-input atoms (`delta_lag(τ)`, `d_rate(τ)`, …): a
/// fixed set, so that a model carries one lagged copy of each command per time constant
/// whichever terms use them.
pub const INPUT_LAGS_S: [f64; 3] = [0.03, 0.1, 0.3];

/// Names of the effect states holding the lagged commands, in state order: for each of
/// [`INPUT_LAGS_S`] the lagged steering angle, then the lagged throttle.
pub const INPUT_LAG_STATES: [&str; 6] = [
    "delta_0.03",
    "d_0.03",
    "delta_0.1",
    "d_0.1",
    "delta_0.3",
    "d_0.3",
];

/// The car's commands (`δ`, `d`): the number of entries of an input before its lagged copies.
const CAR_COMMANDS: usize = 2;

/// Where the command `input` (0: `δ`, 1: `d`) lagged by `INPUT_LAGS_S[lag]` sits in an input
/// extended by the lagged commands (`(δ, d, δ_{τ₁}, d_{τ₁}, …)`), and in the block of
/// [`INPUT_LAG_STATES`] after subtracting the commands.
pub fn input_lag_index(input: usize, lag: usize) -> usize {
    CAR_COMMANDS + CAR_COMMANDS * lag + input
}

/// The rates of the lagged commands `lagged` ([`INPUT_LAG_STATES`] order) under the commands
/// `u`: `(u_i − u_{i,τ})/τ` for each time constant.
pub fn input_lag_rates<R: Real>(lagged: &[R], u: &[R], out: &mut [R]) {
    for (lag, &tau) in INPUT_LAGS_S.iter().enumerate() {
        for i in 0..CAR_COMMANDS {
            let j = input_lag_index(i, lag) - CAR_COMMANDS;
            out[j] = (u[i] - lagged[j]) / tau;
        }
    }
}

/// The lagged commands along a car's command sequence `u` (`len × 2`, each held for `dt` until
/// the next): `len × 6` in [`INPUT_LAG_STATES`] order, started settled at the first command,
/// the exact solution of each first-order lag under zero-order hold. Entry `a` is what a
/// model's lagged commands hold at sample `a` (the model rebuilds them with its own integrator,
/// within 10⁻⁶ of these).
pub fn input_lags_along(u: &[f64], dt: f64) -> Vec<f64> {
    let n = INPUT_LAG_STATES.len();
    let len = u.len() / CAR_COMMANDS;
    let mut out = vec![0.0; len * n];
    for (lag, &tau) in INPUT_LAGS_S.iter().enumerate() {
        for i in 0..CAR_COMMANDS {
            let cmd: Vec<f64> = (0..len).map(|a| u[a * CAR_COMMANDS + i]).collect();
            let j = input_lag_index(i, lag) - CAR_COMMANDS;
            let first = cmd.first().copied().unwrap_or(0.0);
            for (a, v) in super::PhysicsModel::motor_lag_filter(&cmd, dt, tau, first)
                .into_iter()
                .enumerate()
            {
                out[a * n + j] = v;
            }
        }
    }
    out
}

/// The lagged commands settled under the held commands `u` (each copy equal to its command).
pub fn input_lags_settled<R: Real>(u: &[R], out: &mut [R]) {
    for lag in 0..INPUT_LAGS_S.len() {
        for i in 0..CAR_COMMANDS {
            out[input_lag_index(i, lag) - CAR_COMMANDS] = u[i];
        }
    }
}

/// A physical unit as powers of metre and of the robot's time unit (seconds for the car, one
/// push for the pusher). Angles are dimensionless.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct Unit {
    /// Power of the metre.
    pub m: i32,
    /// Power of the time unit.
    pub t: i32,
}

impl Unit {
    /// `m^m · t^t`.
    pub const fn new(m: i32, t: i32) -> Self {
        Self { m, t }
    }
    /// Formats the unit with the time unit's symbol (`s`, `push`): `m/s²`, `1/(m·s)`, `-`.
    pub fn format(self, time: &str) -> String {
        fn pow(base: &str, e: i32) -> String {
            match e {
                1 => base.to_string(),
                _ => format!("{base}{}", superscript(e)),
            }
        }
        let mut num = Vec::new();
        let mut den = Vec::new();
        for (b, e) in [("m", self.m), (time, self.t)] {
            match e.cmp(&0) {
                std::cmp::Ordering::Greater => num.push(pow(b, e)),
                std::cmp::Ordering::Less => den.push(pow(b, -e)),
                std::cmp::Ordering::Equal => {}
            }
        }
        match (num.is_empty(), den.len()) {
            (true, 0) => "-".into(),
            (false, 0) => num.join("·"),
            (n, k) => {
                let top = if n { "1".to_string() } else { num.join("·") };
                if k == 1 {
                    format!("{top}/{}", den[0])
                } else {
                    format!("{top}/({})", den.join("·"))
                }
            }
        }
    }
}

impl std::ops::Mul for Unit {
    type Output = Unit;
    /// The product of two units.
    fn mul(self, o: Unit) -> Unit {
        Unit::new(self.m + o.m, self.t + o.t)
    }
}

impl std::ops::Div for Unit {
    type Output = Unit;
    /// The quotient of two units.
    fn div(self, o: Unit) -> Unit {
        Unit::new(self.m - o.m, self.t - o.t)
    }
}

fn superscript(e: i32) -> String {
    const D: [char; 10] = ['⁰', '¹', '²', '³', '⁴', '⁵', '⁶', '⁷', '⁸', '⁹'];
    let mut s = String::new();
    if e < 0 {
        s.push('⁻');
    }
    for c in e.unsigned_abs().to_string().chars() {
        s.push(D[c.to_digit(10).unwrap_or(0) as usize]);
    }
    s
}

/// The time unit's symbol of a robot (`s`, `push`).
pub fn time_unit(robot: Robot) -> &'static str {
    match robot {
        Robot::Car => "s",
        Robot::Pushing => "push",
    }
}

/// One factor of a feature.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Atom {
    /// Car: body-frame longitudinal velocity `vx`.
    Vx,
    /// Car: body-frame lateral velocity `vy`.
    Vy,
    /// Car: yaw rate `ω`.
    Omega,
    /// Car: commanded front wheel angle `δ`.
    Delta,
    /// Car: throttle command `d`.
    Throttle,
    /// Car: speed `|v|`.
    Speed,
    /// Car: `|vx|`.
    AbsVx,
    /// Car: front slip angle `α_f`.
    AlphaF,
    /// Car: rear slip angle `α_r`.
    AlphaR,
    /// Car: `tanh(α_f/α₀)`.
    SatAlphaF,
    /// Car: `tanh(α_r/α₀)`.
    SatAlphaR,
    /// Car: sideslip `β`.
    Beta,
    /// Car: saturating speed `vₓ²/(vₓ² + v₀²)` with the scale `v₀` \[m/s\]: 0 at rest, ½ at
    /// `v₀`, 1 far above it. A steering gain that falls with speed as an understeering car's
    /// steady-state gain `1/(1 + vₓ²/v₀²)` is `δ·(1 − vₓ²/(vₓ² + v₀²))`.
    SatVx2 {
        /// Speed scale \[m/s\].
        v0: f64,
    },
    /// Car: `cos ψ`.
    CosPsi,
    /// Car: `sin ψ`.
    SinPsi,
    /// Pushing: push location `p`.
    PushLocation,
    /// Pushing: push angle `φ`.
    PushAngle,
    /// Pushing: push length `ℓ`.
    PushLength,
    /// Pushing: `cos φ`.
    CosPhi,
    /// Pushing: `sin φ`.
    SinPhi,
    /// Pushing: block heading `θ`.
    Theta,
    /// Pushing: `cos θ`.
    CosTheta,
    /// Pushing: `sin θ`.
    SinTheta,
    /// Pushing: `cos 2θ`, the doubled heading: the pushed face's normal in the world, as an
    /// axis (a table's grain has no sign).
    Cos2Theta,
    /// Pushing: `sin 2θ` (see [`Atom::Cos2Theta`]).
    Sin2Theta,
    /// Position `x` (world/table frame).
    X,
    /// Position `y` (world/table frame).
    Y,
    /// The constant 1.
    One,
    /// Gaussian bump `exp(−‖(x, y) − c‖²/(2r²))` centred at `(cx, cy)` with width `r`.
    Gauss {
        /// Centre x \[m\].
        cx: f64,
        /// Centre y \[m\].
        cy: f64,
        /// Width \[m\].
        r: f64,
    },
    /// Gaussian band `exp(−(n·(x, y) − d)²/(2w²))`, `n = (−sin a, cos a)`: a straight band
    /// along the direction `a` at the signed distance `d` from the origin, of width `w`.
    Band {
        /// Direction of the band \[rad\].
        a: f64,
        /// Signed distance of its centre line from the origin \[m\].
        d: f64,
        /// Width \[m\].
        w: f64,
    },
    /// Car: the command `input` (0: `δ`, 1: `d`) through a first-order lag of time constant
    /// `tau` (one of [`INPUT_LAGS_S`]).
    LaggedInput {
        /// 0: the steering angle `δ`; 1: the throttle `d`.
        input: usize,
        /// Time constant \[s\].
        tau: f64,
    },
    /// Car: the rate of the command `input` through that lag, `(u − u_τ)/τ` \[1/s\].
    InputRate {
        /// 0: the steering angle `δ`; 1: the throttle `d`.
        input: usize,
        /// Time constant \[s\].
        tau: f64,
    },
    /// Car: the part of the command `input` beyond `level`, with the command's sign,
    /// `sgn(u)·max(|u| − level, 0)`: the shape of an actuator's hard limit (a steering end
    /// stop, a drive force capped by traction or by the motor's current limit).
    Beyond {
        /// 0: the steering angle `δ`; 1: the throttle `d`.
        input: usize,
        /// Level (> 0), in the command's unit.
        level: f64,
    },
    /// Flat-topped strip `½·(tanh((e + w/2)/ε) − tanh((e − w/2)/ε))`, `e = n·(x, y) − d` as for
    /// [`Atom::Band`], `ε = w/20`: a straight strip `w` wide with sharp edges (a wet stripe, a
    /// rug, a painted line), 1 inside and 0 outside, which a Gaussian band follows only near
    /// its centre line.
    Strip {
        /// Direction of the strip \[rad\].
        a: f64,
        /// Signed distance of its centre line from the origin \[m\].
        d: f64,
        /// Full width \[m\].
        w: f64,
    },
}

/// Which robots an atom belongs to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Owner {
    Car,
    Pushing,
    Both,
}

/// Name, symbol, unit and owner of every atom but those with parameters (`gauss`, `band`,
/// `sat_vx2`).
const TABLE: [(Atom, &str, &str, Unit, Owner); 27] = [
    (Atom::Vx, "vx", "vₓ", Unit::new(1, -1), Owner::Car),
    (Atom::Vy, "vy", "v_y", Unit::new(1, -1), Owner::Car),
    (Atom::Omega, "omega", "ω", Unit::new(0, -1), Owner::Car),
    (Atom::Delta, "delta", "δ", Unit::new(0, 0), Owner::Car),
    (Atom::Throttle, "d", "d", Unit::new(0, 0), Owner::Car),
    (Atom::Speed, "|v|", "|v|", Unit::new(1, -1), Owner::Car),
    (Atom::AbsVx, "|vx|", "|vₓ|", Unit::new(1, -1), Owner::Car),
    (Atom::AlphaF, "alpha_f", "α_f", Unit::new(0, 0), Owner::Car),
    (Atom::AlphaR, "alpha_r", "α_r", Unit::new(0, 0), Owner::Car),
    (
        Atom::SatAlphaF,
        "sat_alpha_f",
        "tanh(α_f/α₀)",
        Unit::new(0, 0),
        Owner::Car,
    ),
    (
        Atom::SatAlphaR,
        "sat_alpha_r",
        "tanh(α_r/α₀)",
        Unit::new(0, 0),
        Owner::Car,
    ),
    (Atom::Beta, "beta", "β", Unit::new(0, 0), Owner::Car),
    (
        Atom::CosPsi,
        "cos_psi",
        "cos ψ",
        Unit::new(0, 0),
        Owner::Car,
    ),
    (
        Atom::SinPsi,
        "sin_psi",
        "sin ψ",
        Unit::new(0, 0),
        Owner::Car,
    ),
    (
        Atom::PushLocation,
        "p",
        "p",
        Unit::new(0, 0),
        Owner::Pushing,
    ),
    (Atom::PushAngle, "phi", "φ", Unit::new(0, 0), Owner::Pushing),
    (Atom::PushLength, "l", "ℓ", Unit::new(0, 0), Owner::Pushing),
    (
        Atom::CosPhi,
        "cos_phi",
        "cos φ",
        Unit::new(0, 0),
        Owner::Pushing,
    ),
    (
        Atom::SinPhi,
        "sin_phi",
        "sin φ",
        Unit::new(0, 0),
        Owner::Pushing,
    ),
    (Atom::Theta, "theta", "θ", Unit::new(0, 0), Owner::Pushing),
    (
        Atom::CosTheta,
        "cos_theta",
        "cos θ",
        Unit::new(0, 0),
        Owner::Pushing,
    ),
    (
        Atom::SinTheta,
        "sin_theta",
        "sin θ",
        Unit::new(0, 0),
        Owner::Pushing,
    ),
    (
        Atom::Cos2Theta,
        "cos_2theta",
        "cos 2θ",
        Unit::new(0, 0),
        Owner::Pushing,
    ),
    (
        Atom::Sin2Theta,
        "sin_2theta",
        "sin 2θ",
        Unit::new(0, 0),
        Owner::Pushing,
    ),
    (Atom::X, "x", "x", Unit::new(1, 0), Owner::Both),
    (Atom::Y, "y", "y", Unit::new(1, 0), Owner::Both),
    (Atom::One, "1", "1", Unit::new(0, 0), Owner::Both),
];

fn entry(a: &Atom) -> Option<&'static (Atom, &'static str, &'static str, Unit, Owner)> {
    TABLE
        .iter()
        .find(|e| std::mem::discriminant(&e.0) == std::mem::discriminant(a))
}

/// Shortest decimal text of a number that parses back to the same `f64`.
fn short(v: f64) -> String {
    format!("{v}")
}

impl Atom {
    /// Name used in files (`vx`, `alpha_f`, `gauss(0.5,-0.2,0.4)`).
    pub fn name(&self) -> String {
        match self {
            Atom::Gauss { cx, cy, r } => {
                format!("gauss({},{},{})", short(*cx), short(*cy), short(*r))
            }
            Atom::Band { a, d, w } => format!("band({},{},{})", short(*a), short(*d), short(*w)),
            Atom::Strip { a, d, w } => {
                format!("strip({},{},{})", short(*a), short(*d), short(*w))
            }
            Atom::SatVx2 { v0 } => format!("sat_vx2({})", short(*v0)),
            Atom::LaggedInput { input, tau } => {
                format!("{}_lag({})", COMMAND_NAMES[*input], short(*tau))
            }
            Atom::InputRate { input, tau } => {
                format!("{}_rate({})", COMMAND_NAMES[*input], short(*tau))
            }
            Atom::Beyond { input, level } => {
                format!("{}_beyond({})", COMMAND_NAMES[*input], short(*level))
            }
            a => entry(a).map(|e| e.1).unwrap_or("?").to_string(),
        }
    }

    /// Symbol for printed equations (`vₓ`, `α_f`, `g(0.5, −0.2; 0.4)`).
    pub fn symbol(&self) -> String {
        match self {
            Atom::Gauss { cx, cy, r } => format!(
                "g({}, {}; {})",
                short(*cx).replace('-', "−"),
                short(*cy).replace('-', "−"),
                short(*r)
            ),
            Atom::Band { a, d, w } => format!(
                "b({}, {}; {})",
                short(*a).replace('-', "−"),
                short(*d).replace('-', "−"),
                short(*w)
            ),
            Atom::Strip { a, d, w } => format!(
                "s({}, {}; {})",
                short(*a).replace('-', "−"),
                short(*d).replace('-', "−"),
                short(*w)
            ),
            Atom::SatVx2 { v0 } => format!("vₓ²/(vₓ² + {}²)", short(*v0)),
            Atom::LaggedInput { input, tau } => {
                format!("{}_{{{} s}}", COMMAND_SYMBOLS[*input], short(*tau))
            }
            Atom::InputRate { input, tau } => {
                format!("{}_{{{} s}}", COMMAND_RATE_SYMBOLS[*input], short(*tau))
            }
            Atom::Beyond { input, level } => {
                format!("{}_{{>{}}}", COMMAND_SYMBOLS[*input], short(*level))
            }
            a => entry(a).map(|e| e.2).unwrap_or("?").to_string(),
        }
    }

    /// Unit.
    pub fn unit(&self) -> Unit {
        match self {
            Atom::Gauss { .. }
            | Atom::Band { .. }
            | Atom::Strip { .. }
            | Atom::SatVx2 { .. }
            | Atom::LaggedInput { .. }
            | Atom::Beyond { .. } => Unit::default(),
            Atom::InputRate { .. } => Unit::new(0, -1),
            a => entry(a).map(|e| e.3).unwrap_or_default(),
        }
    }

    /// Whether the atom exists for `robot`.
    pub fn belongs_to(&self, robot: Robot) -> bool {
        let owner = match self {
            Atom::Gauss { .. } | Atom::Band { .. } | Atom::Strip { .. } => Owner::Both,
            Atom::SatVx2 { .. }
            | Atom::LaggedInput { .. }
            | Atom::InputRate { .. }
            | Atom::Beyond { .. } => Owner::Car,
            a => entry(a).map(|e| e.4).unwrap_or(Owner::Both),
        };
        match owner {
            Owner::Both => true,
            Owner::Car => robot == Robot::Car,
            Owner::Pushing => robot == Robot::Pushing,
        }
    }

    /// Whether the atom is a function of the position alone (`x`, `y`, a bump, a band, a
    /// strip).
    pub fn is_position(&self) -> bool {
        matches!(self, Atom::X | Atom::Y) || self.is_region()
    }

    /// Whether the atom needs the command history (a lagged command or its rate): a model with
    /// such a term carries the lagged commands as effect states.
    pub fn uses_input_lags(&self) -> bool {
        matches!(self, Atom::LaggedInput { .. } | Atom::InputRate { .. })
    }

    /// Whether the atom is a state, a command, a position or the constant itself rather than a
    /// quantity derived from them (a speed, a slip angle, a saturation, a lagged command, a
    /// region): of two terms the data do not tell apart, the term search keeps the one with
    /// fewer derived atoms.
    pub fn is_elementary(&self) -> bool {
        matches!(
            self,
            Atom::Vx
                | Atom::Vy
                | Atom::Omega
                | Atom::Delta
                | Atom::Throttle
                | Atom::PushLocation
                | Atom::PushAngle
                | Atom::PushLength
                | Atom::Theta
                | Atom::X
                | Atom::Y
                | Atom::One
        )
    }

    /// Whether the atom is a region of the floor or table (a bump, a band, a strip).
    pub fn is_region(&self) -> bool {
        matches!(
            self,
            Atom::Gauss { .. } | Atom::Band { .. } | Atom::Strip { .. }
        )
    }

    /// Names of the atoms of `robot` (those with parameters last: `sat_vx2(v0)`, the lagged
    /// commands and the commands beyond a level of the car, `gauss(cx,cy,r)`, `band(a,d,w)`,
    /// `strip(a,d,w)`).
    pub fn names(robot: Robot) -> Vec<String> {
        let car_only: &[&str] = match robot {
            Robot::Car => &[
                "sat_vx2(v0)",
                "delta_lag(tau)",
                "d_lag(tau)",
                "delta_rate(tau)",
                "d_rate(tau)",
                "delta_beyond(l)",
                "d_beyond(l)",
            ],
            Robot::Pushing => &[],
        };
        TABLE
            .iter()
            .filter(|e| e.0.belongs_to(robot))
            .map(|e| e.1.to_string())
            .chain(car_only.iter().map(|n| n.to_string()))
            .chain(["gauss(cx,cy,r)", "band(a,d,w)", "strip(a,d,w)"].map(String::from))
            .collect()
    }

    /// Parses one atom name (any robot).
    pub fn parse(name: &str) -> Result<Atom, FeatureError> {
        let n = name.trim();
        if let Some(e) = TABLE.iter().find(|e| e.1 == n) {
            return Ok(e.0);
        }
        // three finite numbers, the last (a width) positive
        let args = |prefix: &str| -> Option<Result<[f64; 3], FeatureError>> {
            let inner = n.strip_prefix(prefix)?.strip_suffix(')')?;
            let v: Vec<f64> = inner
                .split(',')
                .map(|a| a.trim().parse::<f64>())
                .collect::<Result<_, _>>()
                .unwrap_or_default();
            Some(match v[..] {
                [a, b, c] if a.is_finite() && b.is_finite() && c.is_finite() && c > 0.0 => {
                    Ok([a, b, c])
                }
                _ => Err(FeatureError::BadRegion(n.to_string())),
            })
        };
        if let Some(v) = args("gauss(") {
            let [cx, cy, r] = v?;
            return Ok(Atom::Gauss { cx, cy, r });
        }
        if let Some(v) = args("band(") {
            let [a, d, w] = v?;
            return Ok(Atom::Band { a, d, w });
        }
        if let Some(v) = args("strip(") {
            let [a, d, w] = v?;
            return Ok(Atom::Strip { a, d, w });
        }
        for (input, command) in COMMAND_NAMES.iter().enumerate() {
            if let Some(inner) = n
                .strip_prefix(command)
                .and_then(|r| r.strip_prefix("_beyond("))
                .and_then(|r| r.strip_suffix(')'))
            {
                return match inner.trim().parse::<f64>() {
                    Ok(level) if level.is_finite() && level > 0.0 => {
                        Ok(Atom::Beyond { input, level })
                    }
                    _ => Err(FeatureError::BadLevel(n.to_string())),
                };
            }
            for (kind, rate) in [("_lag(", false), ("_rate(", true)] {
                let Some(inner) = n
                    .strip_prefix(command)
                    .and_then(|r| r.strip_prefix(kind))
                    .and_then(|r| r.strip_suffix(')'))
                else {
                    continue;
                };
                let tau = inner.trim().parse::<f64>().ok().and_then(|t| {
                    INPUT_LAGS_S
                        .iter()
                        .copied()
                        .find(|&l| (l - t).abs() <= 1e-9 * l)
                });
                return match tau {
                    Some(tau) if rate => Ok(Atom::InputRate { input, tau }),
                    Some(tau) => Ok(Atom::LaggedInput { input, tau }),
                    None => Err(FeatureError::BadInputLag(n.to_string())),
                };
            }
        }
        if let Some(inner) = n.strip_prefix("sat_vx2(").and_then(|r| r.strip_suffix(')')) {
            return match inner.trim().parse::<f64>() {
                Ok(v0) if v0.is_finite() && v0 > 0.0 => Ok(Atom::SatVx2 { v0 }),
                _ => Err(FeatureError::BadSpeedScale(n.to_string())),
            };
        }
        Err(FeatureError::UnknownAtom {
            name: n.to_string(),
            car: Atom::names(Robot::Car).join(", "),
            pushing: Atom::names(Robot::Pushing).join(", "),
        })
    }

    /// The atom's value at state `s`, input `u`, with the nominal parameters `p` of the robot's
    /// model (the car's slip angles use `l_f`, `l_r`, `v_reg`). The lagged commands read the
    /// input's entries past the commands ([`input_lag_index`]), and are `NaN` without them.
    pub fn eval<R: Real>(&self, robot: Robot, p: &[R], s: &[R], u: &[R]) -> R {
        let lagged = |input: usize, tau: f64| {
            let lag = INPUT_LAGS_S.iter().position(|&l| l == tau);
            lag.and_then(|lag| u.get(input_lag_index(input, lag)).copied())
        };
        match (robot, self) {
            (Robot::Car, Atom::LaggedInput { input, tau }) => {
                lagged(*input, *tau).unwrap_or(R::cst(f64::NAN))
            }
            (Robot::Car, Atom::InputRate { input, tau }) => match lagged(*input, *tau) {
                Some(l) => (u[*input] - l) / *tau,
                None => R::cst(f64::NAN),
            },
            (Robot::Car, Atom::Beyond { input, level }) => {
                let c = u[*input];
                if c.value().abs() > *level {
                    (c.abs() - *level) * c.value().signum()
                } else {
                    R::cst(0.0)
                }
            }
            (_, Atom::X) => s[0],
            (_, Atom::Y) => s[1],
            (_, Atom::One) => R::cst(1.0),
            (_, Atom::Gauss { cx, cy, r }) => {
                let dx = s[0] - *cx;
                let dy = s[1] - *cy;
                (-(dx * dx + dy * dy) / (2.0 * r * r)).exp()
            }
            (_, Atom::Band { a, d, w }) => {
                let e = s[1] * a.cos() - s[0] * a.sin() - *d;
                (-(e * e) / (2.0 * w * w)).exp()
            }
            (_, Atom::Strip { a, d, w }) => {
                let e = s[1] * a.cos() - s[0] * a.sin() - *d;
                let eps = 0.05 * *w;
                (((e + 0.5 * *w) / eps).tanh() - ((e - 0.5 * *w) / eps).tanh()) * 0.5
            }
            (Robot::Car, a) => car_atom(a, p, s, u),
            (Robot::Pushing, a) => push_atom(a, s, u),
        }
    }
}

fn car_atom<R: Real>(a: &Atom, p: &[R], s: &[R], u: &[R]) -> R {
    let (lf, lr, vreg) = (p[2], p[3], p[14]);
    let (vx, vy, om) = (s[3], s[4], s[5]);
    let delta = u[0];
    let reg = vreg * vreg;
    let alpha_f = || {
        let (sd, cd) = (delta.sin(), delta.cos());
        let vyf = vy + lf * om;
        let v_long_f = cd * vx + sd * vyf;
        let v_lat_f = cd * vyf - sd * vx;
        -(v_lat_f / (v_long_f * v_long_f + reg).sqrt()).atan()
    };
    let alpha_r = || -((vy - lr * om) / (vx * vx + reg).sqrt()).atan();
    match a {
        Atom::Vx => vx,
        Atom::Vy => vy,
        Atom::Omega => om,
        Atom::Delta => delta,
        Atom::Throttle => u[1],
        Atom::Speed => (vx * vx + vy * vy + 1e-12).sqrt(),
        Atom::AbsVx => vx.abs(),
        Atom::AlphaF => alpha_f(),
        Atom::AlphaR => alpha_r(),
        Atom::SatAlphaF => (alpha_f() / SLIP_SCALE_RAD).tanh(),
        Atom::SatAlphaR => (alpha_r() / SLIP_SCALE_RAD).tanh(),
        Atom::Beta => (vy / (vx * vx + reg).sqrt()).atan(),
        Atom::SatVx2 { v0 } => {
            let v2 = vx * vx;
            v2 / (v2 + *v0 * *v0)
        }
        Atom::CosPsi => s[2].cos(),
        Atom::SinPsi => s[2].sin(),
        _ => R::cst(0.0),
    }
}

fn push_atom<R: Real>(a: &Atom, s: &[R], u: &[R]) -> R {
    match a {
        Atom::PushLocation => u[0],
        Atom::PushAngle => u[1],
        Atom::PushLength => u[2],
        Atom::CosPhi => u[1].cos(),
        Atom::SinPhi => u[1].sin(),
        Atom::Theta => s[2],
        Atom::CosTheta => s[2].cos(),
        Atom::SinTheta => s[2].sin(),
        Atom::Cos2Theta => (s[2] * R::cst(2.0)).cos(),
        Atom::Sin2Theta => (s[2] * R::cst(2.0)).sin(),
        _ => R::cst(0.0),
    }
}

/// File names of the car's commands (`δ`, `d`), as the lagged atoms spell them.
const COMMAND_NAMES: [&str; 2] = ["delta", "d"];
/// Symbols of the car's commands and of their rates.
const COMMAND_SYMBOLS: [&str; 2] = ["δ", "d"];
const COMMAND_RATE_SYMBOLS: [&str; 2] = ["δ̇", "ḋ"];

/// Errors parsing a feature.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FeatureError {
    /// An unknown atom name.
    #[error(
        "unknown feature '{name}'; a feature is a product of atoms joined by '*' (e.g. delta*vx); \
         car atoms: {car}; pushing atoms: {pushing}"
    )]
    UnknownAtom {
        /// The name given.
        name: String,
        /// Atoms of the car.
        car: String,
        /// Atoms of the pusher.
        pushing: String,
    },
    /// A malformed position basis function.
    #[error(
        "bad position basis '{0}'; write gauss(cx,cy,r) or band(a,d,w) with finite numbers and r, w > 0 (metres, a in rad)"
    )]
    BadRegion(String),
    /// A malformed saturating speed.
    #[error("bad saturating speed '{0}'; write sat_vx2(v0) with a finite speed scale v0 > 0 (m/s)")]
    BadSpeedScale(String),
    /// A lagged command with a time constant outside [`INPUT_LAGS_S`].
    #[error(
        "bad lagged command '{0}'; write delta_lag(tau), d_lag(tau), delta_rate(tau) or d_rate(tau) with tau one of 0.03, 0.1, 0.3 (seconds)"
    )]
    BadInputLag(String),
    /// A command beyond a level that is not finite and positive.
    #[error(
        "bad command level '{0}'; write delta_beyond(l) or d_beyond(l) with a finite level l > 0 (rad for the steering, the throttle's unit for d)"
    )]
    BadLevel(String),
    /// No factors or too many.
    #[error("feature '{name}' has {got} factors; use 1 to {max} atoms joined by '*'")]
    FactorCount {
        /// The feature text.
        name: String,
        /// Factors found.
        got: usize,
        /// The limit.
        max: usize,
    },
    /// An atom of the other robot.
    #[error(
        "feature '{feature}' uses '{atom}', which the {robot:?} model does not have; its atoms: {known}"
    )]
    WrongRobot {
        /// The feature.
        feature: String,
        /// The atom.
        atom: String,
        /// The robot.
        robot: Robot,
        /// The robot's atoms.
        known: String,
    },
}

/// A product of atoms: one column of the term search, one term of a custom effect.
#[derive(Clone, Debug, PartialEq)]
pub struct Feature {
    factors: Vec<Atom>,
}

impl Feature {
    /// A feature from its factors (1 to [`MAX_FACTORS`]).
    pub fn new(factors: Vec<Atom>) -> Result<Self, FeatureError> {
        if factors.is_empty() || factors.len() > MAX_FACTORS {
            return Err(FeatureError::FactorCount {
                name: factors
                    .iter()
                    .map(|a| a.name())
                    .collect::<Vec<_>>()
                    .join("*"),
                got: factors.len(),
                max: MAX_FACTORS,
            });
        }
        Ok(Self { factors })
    }

    /// Parses `delta*vx`, `vx*|vx|`, `l*gauss(0.6,0,0.1)` (any robot's atoms; see
    /// [`Feature::check_robot`]).
    pub fn parse(text: &str) -> Result<Self, FeatureError> {
        let factors = text
            .split('*')
            .map(Atom::parse)
            .collect::<Result<Vec<_>, _>>()?;
        Self::new(factors).map_err(|e| match e {
            FeatureError::FactorCount { got, max, .. } => FeatureError::FactorCount {
                name: text.to_string(),
                got,
                max,
            },
            e => e,
        })
    }

    /// Checks that every atom exists for `robot`.
    pub fn check_robot(&self, robot: Robot) -> Result<(), FeatureError> {
        match self.factors.iter().find(|a| !a.belongs_to(robot)) {
            None => Ok(()),
            Some(a) => Err(FeatureError::WrongRobot {
                feature: self.name(),
                atom: a.name(),
                robot,
                known: Atom::names(robot).join(", "),
            }),
        }
    }

    /// The factors.
    pub fn factors(&self) -> &[Atom] {
        &self.factors
    }

    /// Whether the feature needs the command history ([`Atom::uses_input_lags`]).
    pub fn uses_input_lags(&self) -> bool {
        self.factors.iter().any(Atom::uses_input_lags)
    }

    /// Whether the feature depends on where the robot is (`x`, `y`, a Gaussian bump or band):
    /// a region's term, which the term search tries only after the terms that hold everywhere.
    pub fn depends_on_position(&self) -> bool {
        self.factors.iter().any(Atom::is_position)
    }

    /// Whether the feature is a command beyond a level ([`Atom::Beyond`]): 0 wherever the
    /// command stays within it, so its coefficient reaches only the part of the data where
    /// the command goes past.
    pub fn beyond_a_level(&self) -> bool {
        self.factors
            .iter()
            .any(|a| matches!(a, Atom::Beyond { .. }))
    }

    /// Name used in files: the atoms joined by `*`.
    pub fn name(&self) -> String {
        self.factors
            .iter()
            .map(|a| a.name())
            .collect::<Vec<_>>()
            .join("*")
    }

    /// Symbol with repeated neighbours as powers: `δ·vₓ²`.
    pub fn symbol(&self) -> String {
        let mut o = String::new();
        let mut i = 0;
        while i < self.factors.len() {
            let mut j = i + 1;
            while j < self.factors.len() && self.factors[j] == self.factors[i] {
                j += 1;
            }
            if i > 0 {
                o.push('·');
            }
            o.push_str(&self.factors[i].symbol());
            if j - i > 1 {
                let _ = write!(o, "{}", superscript((j - i) as i32));
            }
            i = j;
        }
        o
    }

    /// Unit of the product.
    pub fn unit(&self) -> Unit {
        self.factors
            .iter()
            .fold(Unit::default(), |u, a| u * a.unit())
    }

    /// The feature's value (see [`Atom::eval`]).
    pub fn eval<R: Real>(&self, robot: Robot, p: &[R], s: &[R], u: &[R]) -> R {
        let mut v = self.factors[0].eval(robot, p, s, u);
        for a in &self.factors[1..] {
            v = v * a.eval(robot, p, s, u);
        }
        v
    }
}

impl std::fmt::Display for Feature {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.name())
    }
}

/// The axis-aligned area the data cover, for the position basis functions.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Area {
    /// Lower corner `(x, y)` \[m\].
    pub lo: [f64; 2],
    /// Upper corner `(x, y)` \[m\].
    pub hi: [f64; 2],
}

/// The candidate features of the term search for `robot`: the physics-informed products of
/// states and inputs, slip angles and their saturating functions, the car's lagged command
/// rates (a command that acts late) and heading (a pull fixed in the world), `x`, `y`, and,
/// when `area`
/// is given, Gaussian bumps on a `grid × grid` lattice over it (width: the lattice spacing) and
/// for the car bands at 4 directions and `grid` offsets across it (width: half the spacing).
pub fn library(robot: Robot, area: Option<Area>, grid: usize) -> Vec<Feature> {
    let names: &[&str] = match robot {
        Robot::Car => &[
            "vx",
            "vy",
            "omega",
            "delta",
            "d",
            "|v|",
            "vx*|vx|",
            "vx*vx",
            "delta*vx",
            "delta*vx*vx",
            "delta*|v|",
            "omega*vx",
            "vy*vx",
            "d*vx",
            "d*|vx|",
            "alpha_f",
            "alpha_r",
            "sat_alpha_f",
            "sat_alpha_r",
            "alpha_f*vx",
            "alpha_r*vx",
            "beta",
            "beta*vx",
            "delta_rate(0.03)",
            "delta_rate(0.1)",
            "delta_rate(0.3)",
            "d_rate(0.03)",
            "d_rate(0.1)",
            "d_rate(0.3)",
            "1",
            "cos_psi",
            "sin_psi",
            "x",
            "y",
        ],
        Robot::Pushing => &[
            "l",
            "l*p",
            "l*phi",
            "l*p*phi",
            "l*cos_phi",
            "l*sin_phi",
            "l*p*p",
            "l*cos_theta",
            "l*sin_theta",
            "cos_theta",
            "sin_theta",
            "l*x",
            "l*y",
            "1",
            "l*cos_phi*cos_2theta",
            "l*cos_phi*sin_2theta",
        ],
    };
    let mut v: Vec<Feature> = names
        .iter()
        .map(|n| Feature::parse(n).expect("library feature names parse"))
        .collect();
    if let Some(a) = area
        && grid > 0
    {
        let w = [(a.hi[0] - a.lo[0]).max(1e-3), (a.hi[1] - a.lo[1]).max(1e-3)];
        let r = (w[0].max(w[1]) / grid as f64).max(1e-3);
        let round = |v: f64| (v * 1000.0).round() / 1000.0;
        for i in 0..grid {
            for j in 0..grid {
                let cx = round(a.lo[0] + (i as f64 + 0.5) / grid as f64 * w[0]);
                let cy = round(a.lo[1] + (j as f64 + 0.5) / grid as f64 * w[1]);
                let g = Atom::Gauss {
                    cx,
                    cy,
                    r: round(r),
                };
                match robot {
                    // a quasi-static block moves only while pushed
                    Robot::Pushing => v.push(Feature {
                        factors: vec![Atom::PushLength, g],
                    }),
                    // a region of other grip scales the tire forces there: the bump times the
                    // saturating slip of each axle (the sign of the force goes with the slip)
                    Robot::Car => {
                        for f in [vec![g], vec![g, Atom::SatAlphaF], vec![g, Atom::SatAlphaR]] {
                            v.push(Feature { factors: f });
                        }
                    }
                }
            }
        }
        // the car's straight bands (for its grip): 4 directions, `grid` offsets across the
        // area in each, as wide as half the spacing
        if robot == Robot::Car {
            for k in 0..4 {
                let ang = round(k as f64 * std::f64::consts::FRAC_PI_4);
                let n = [-ang.sin(), ang.cos()];
                let proj: Vec<f64> = [a.lo, [a.lo[0], a.hi[1]], [a.hi[0], a.lo[1]], a.hi]
                    .iter()
                    .map(|c| n[0] * c[0] + n[1] * c[1])
                    .collect();
                let lo = proj.iter().copied().fold(f64::INFINITY, f64::min);
                let span = (proj.iter().copied().fold(f64::NEG_INFINITY, f64::max) - lo).max(1e-3);
                for i in 0..grid {
                    v.push(Feature {
                        factors: vec![Atom::Band {
                            a: ang,
                            d: round(lo + (i as f64 + 0.5) / grid as f64 * span),
                            w: round((0.5 * span / grid as f64).max(1e-3)),
                        }],
                    });
                }
            }
        }
    }
    v
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::real::Dual;

    #[test]
    fn a_strip_is_flat_inside_and_falls_at_its_edges() {
        // a strip 0.8 m wide along 0.5 rad whose centre line passes 0.3 m from the origin
        let f = Feature::parse("strip(0.5,0.3,0.8)").unwrap();
        assert_eq!(f.name(), "strip(0.5,0.3,0.8)");
        assert_eq!(f.symbol(), "s(0.5, 0.3; 0.8)");
        assert!(f.factors()[0].is_position() && f.factors()[0].is_region());
        f.check_robot(Robot::Car).unwrap();
        let (sn, cs) = 0.5f64.sin_cos();
        // the point at distance e across the centre line, 0.7 m along it
        let at = |e: f64| {
            let p = [-sn * (0.3 + e) + cs * 0.7, cs * (0.3 + e) + sn * 0.7];
            f.eval::<f64>(Robot::Car, &[], &[p[0], p[1], 0.0, 0.0, 0.0, 0.0], &[])
        };
        for e in [-0.3, 0.0, 0.3] {
            assert!(at(e) > 0.95, "inside at {e}: {}", at(e));
        }
        for e in [-0.4, 0.4] {
            assert!((at(e) - 0.5).abs() < 1e-3, "edge at {e}: {}", at(e));
        }
        for e in [-0.6, 0.6] {
            assert!(at(e) < 0.02, "outside at {e}: {}", at(e));
        }
        // a Gaussian band of the same direction and offset is 1 only on its centre line
        let band = Feature::parse("band(0.5,0.3,0.34)").unwrap();
        let p = [-sn * 0.6 + cs * 0.7, cs * 0.6 + sn * 0.7];
        let b = band.eval::<f64>(Robot::Car, &[], &[p[0], p[1], 0.0, 0.0, 0.0, 0.0], &[]);
        assert!(b < 0.7 && at(0.3) > 0.95);
        for bad in ["strip(0.5,0.3,0)", "strip(0.5,0.3)", "strip(0.5,nan,0.8)"] {
            assert!(Feature::parse(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn lagged_commands_name_their_time_constant_and_need_the_command_history() {
        let f = Feature::parse("delta_rate(0.1)*vx").unwrap();
        assert_eq!(f.factors()[0], Atom::InputRate { input: 0, tau: 0.1 });
        assert_eq!(Feature::parse(&f.name()).unwrap(), f);
        assert_eq!(f.symbol(), "δ̇_{0.1 s}·vₓ");
        assert_eq!(f.unit(), Unit::new(1, -2));
        assert!(f.uses_input_lags() && !f.depends_on_position());
        let g = Feature::parse("d_lag(0.03)").unwrap();
        assert_eq!(
            (g.name().as_str(), g.symbol().as_str()),
            ("d_lag(0.03)", "d_{0.03 s}")
        );
        assert_eq!(g.unit(), Unit::default());
        assert!(f.check_robot(Robot::Pushing).is_err() && g.check_robot(Robot::Car).is_ok());
        // the state names follow the time constants and the index
        for (lag, tau) in INPUT_LAGS_S.iter().enumerate() {
            for (i, cmd) in COMMAND_NAMES.iter().enumerate() {
                let j = input_lag_index(i, lag) - CAR_COMMANDS;
                assert_eq!(INPUT_LAG_STATES[j], format!("{cmd}_{tau}"));
            }
        }
        // values from the input's entries past the commands; NaN without them
        let u = [0.2, 0.5, 0.1, 0.4, 0.15, 0.3, 0.0, 0.0];
        let s = [0.0, 0.0, 0.0, 2.0, 0.0, 0.0];
        let p = crate::physics::PhysicsModel::car(&[])
            .unwrap()
            .params()
            .to_vec();
        let v = f.eval::<f64>(Robot::Car, &p, &s, &u);
        assert!((v - (0.2 - 0.15) / 0.1 * 2.0).abs() < 1e-12, "{v}");
        assert_eq!(g.eval::<f64>(Robot::Car, &p, &s, &u), 0.4);
        assert!(f.eval::<f64>(Robot::Car, &p, &s, &u[..2]).is_nan());
        // a time constant outside the set says which exist
        let e = Feature::parse("delta_rate(0.05)").unwrap_err().to_string();
        for tau in INPUT_LAGS_S {
            assert!(e.contains(&tau.to_string()), "{e}");
        }
        assert!(Feature::parse("delta_lag()").is_err() && Feature::parse("d_rate(x)").is_err());
        assert!(Atom::names(Robot::Car).contains(&"delta_rate(tau)".to_string()));
    }

    #[test]
    fn names_round_trip_and_units_multiply() {
        for robot in [Robot::Car, Robot::Pushing] {
            let area = Area {
                lo: [-1.0, -0.5],
                hi: [1.0, 0.5],
            };
            for f in library(robot, Some(area), 3) {
                let g = Feature::parse(&f.name()).unwrap();
                assert_eq!(g, f, "{}", f.name());
                f.check_robot(robot).unwrap();
            }
        }
        let f = Feature::parse("delta*vx*vx").unwrap();
        assert_eq!(f.symbol(), "δ·vₓ²");
        assert_eq!(f.unit(), Unit::new(2, -2));
        let omega_dot = Unit::new(0, -2);
        assert_eq!((omega_dot / f.unit()).format("s"), "1/m²");
        assert_eq!(Unit::new(-1, -1).format("s"), "1/(m·s)");
        assert_eq!(Unit::new(1, -2).format("s"), "m/s²");
        assert_eq!(Unit::default().format("s"), "-");
        // the doubled heading: name, symbol and a product with ℓ·cos φ
        let f = Feature::parse("l*cos_phi*sin_2theta").unwrap();
        assert_eq!(
            f.factors(),
            &[Atom::PushLength, Atom::CosPhi, Atom::Sin2Theta]
        );
        assert_eq!(f.name(), "l*cos_phi*sin_2theta");
        assert_eq!(f.symbol(), "ℓ·cos φ·sin 2θ");
        assert_eq!(f.unit(), Unit::default());
        assert_eq!(
            Feature::parse("l*cos_phi*cos_2theta").unwrap().symbol(),
            "ℓ·cos φ·cos 2θ"
        );
        assert!(
            Feature::parse("cos_2theta")
                .unwrap()
                .check_robot(Robot::Car)
                .is_err()
        );
    }

    #[test]
    fn the_saturating_speed_is_an_understeering_cars_steering_gain() {
        let f = Feature::parse("delta*sat_vx2(2.5)").unwrap();
        assert_eq!(f.factors(), &[Atom::Delta, Atom::SatVx2 { v0: 2.5 }]);
        assert_eq!(Feature::parse(&f.name()).unwrap(), f);
        assert_eq!(f.symbol(), "δ·vₓ²/(vₓ² + 2.5²)");
        assert_eq!(f.unit(), Unit::default());
        f.check_robot(Robot::Car).unwrap();
        assert!(f.check_robot(Robot::Pushing).is_err());
        assert!(!f.depends_on_position());
        // δ − 1·δ·vₓ²/(vₓ² + v₀²) = δ/(1 + vₓ²/v₀²): ½ of δ at v₀, ⅕ at 2·v₀
        let p = crate::physics::PhysicsModel::car(&[])
            .unwrap()
            .params()
            .to_vec();
        let u = [0.2, 0.5];
        for (vx, gain) in [(0.0, 1.0), (2.5, 0.5), (5.0, 0.2), (-5.0, 0.2)] {
            let s = [0.0, 0.0, 0.0, vx, 0.0, 0.0];
            let v = f.eval(Robot::Car, &p, &s, &u);
            assert!((u[0] - v - gain * u[0]).abs() < 1e-12, "vx {vx}: {v}");
        }
        for bad in [
            "sat_vx2(0)",
            "sat_vx2(-1)",
            "sat_vx2(nan)",
            "sat_vx2()",
            "sat_vx2(1,2)",
        ] {
            assert!(
                matches!(Atom::parse(bad), Err(FeatureError::BadSpeedScale(_))),
                "{bad}"
            );
        }
        assert!(Atom::names(Robot::Car).contains(&"sat_vx2(v0)".to_string()));
        assert!(!Atom::names(Robot::Pushing).contains(&"sat_vx2(v0)".to_string()));
    }

    #[test]
    fn a_command_beyond_a_level_is_an_actuators_hard_limit() {
        let f = Feature::parse("delta_beyond(0.25)").unwrap();
        assert_eq!(
            f.factors(),
            &[Atom::Beyond {
                input: 0,
                level: 0.25
            }]
        );
        assert_eq!(Feature::parse(&f.name()).unwrap(), f);
        assert_eq!(f.symbol(), "δ_{>0.25}");
        assert_eq!(f.unit(), Unit::default());
        assert!(f.beyond_a_level() && !f.depends_on_position() && !f.uses_input_lags());
        f.check_robot(Robot::Car).unwrap();
        assert!(f.check_robot(Robot::Pushing).is_err());
        let g = Feature::parse("d_beyond(0.3)").unwrap();
        assert_eq!(
            (g.name().as_str(), g.symbol().as_str()),
            ("d_beyond(0.3)", "d_{>0.3}")
        );
        // δ − 1·δ_{>0.25} is the steering held at an end stop of ±0.25 rad
        let p = crate::physics::PhysicsModel::car(&[])
            .unwrap()
            .params()
            .to_vec();
        let s = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0];
        for (delta, seen) in [
            (0.1, 0.1),
            (0.25, 0.25),
            (0.35, 0.25),
            (-0.35, -0.25),
            (-0.2, -0.2),
        ] {
            let v = f.eval(Robot::Car, &p, &s, &[delta, 0.4]);
            assert!((delta - v - seen).abs() < 1e-12, "δ {delta}: {v}");
        }
        for (d, beyond) in [(0.2, 0.0), (0.5, 0.2), (-0.4, -0.1)] {
            let v = g.eval(Robot::Car, &p, &s, &[0.0, d]);
            assert!((v - beyond).abs() < 1e-12, "d {d}: {v}");
        }
        for bad in [
            "delta_beyond(0)",
            "d_beyond(-0.1)",
            "d_beyond(inf)",
            "delta_beyond()",
        ] {
            assert!(
                matches!(Atom::parse(bad), Err(FeatureError::BadLevel(_))),
                "{bad}"
            );
        }
        let names = Atom::names(Robot::Car);
        assert!(names.contains(&"delta_beyond(l)".to_string()));
        assert!(names.contains(&"d_beyond(l)".to_string()));
    }

    #[test]
    fn region_features_are_told_from_global_ones() {
        let area = Area {
            lo: [-1.0, -1.0],
            hi: [1.0, 1.0],
        };
        let lib = library(Robot::Car, Some(area), 3);
        let region: Vec<&Feature> = lib.iter().filter(|f| f.depends_on_position()).collect();
        // x, y, each of the 9 bumps alone and times the slip of each axle, 4 × 3 bands
        assert_eq!(region.len(), 2 + 27 + 12);
        for axle in [Atom::SatAlphaF, Atom::SatAlphaR] {
            let n = region
                .iter()
                .filter(|f| f.factors().contains(&axle))
                .count();
            assert_eq!(n, 9);
        }
        let f = Feature::parse("gauss(0.5,0,0.3)*sat_alpha_f").unwrap();
        assert!(f.depends_on_position());
        assert!(!Feature::parse("delta*vx").unwrap().depends_on_position());
        assert!(!Feature::parse("sat_alpha_r").unwrap().depends_on_position());
    }

    #[test]
    fn doubled_heading_has_no_sign() {
        // a grain has no sign: the heading θ and its reverse θ + π give the same value, and
        // a·sin 2θ + b·cos 2θ is A·sin 2(θ − γ) for the grain angle γ
        let (s, u) = ([0.1, -0.2, 0.7], [0.3, -0.4, 0.8]);
        let s_rev = [s[0], s[1], s[2] + std::f64::consts::PI];
        for a in [Atom::Sin2Theta, Atom::Cos2Theta] {
            let v = a.eval(Robot::Pushing, &[], &s, &u);
            let w = a.eval(Robot::Pushing, &[], &s_rev, &u);
            assert!((v - w).abs() < 1e-12, "{}", a.name());
        }
        let gamma = 0.4;
        let (sin2, cos2) = (
            Atom::Sin2Theta.eval(Robot::Pushing, &[], &s, &u),
            Atom::Cos2Theta.eval(Robot::Pushing, &[], &s, &u),
        );
        let combined = (2.0 * gamma).cos() * sin2 - (2.0 * gamma).sin() * cos2;
        assert!((combined - (2.0 * (s[2] - gamma)).sin()).abs() < 1e-12);
    }

    #[test]
    fn bad_names_say_what_exists() {
        let e = Feature::parse("delta*speed").unwrap_err().to_string();
        assert!(e.contains("'speed'") && e.contains("|v|"), "{e}");
        assert!(Feature::parse("gauss(1,2)").is_err());
        assert!(Feature::parse("band(0.5,0.1,0)").is_err());
        let b = Feature::parse("band(0.5,0.1,0.4)").unwrap();
        assert_eq!(b.name(), "band(0.5,0.1,0.4)");
        assert!(b.depends_on_position());
        // on its centre line (distance 0.1 along the normal) the band is 1, a width off e^(−1/2)
        let n = [-(0.5f64).sin(), (0.5f64).cos()];
        let at = |off: f64| {
            let s = [
                n[0] * off + 3.0 * n[1],
                n[1] * off - 3.0 * n[0],
                0.0,
                1.0,
                0.0,
                0.0,
            ];
            b.eval(Robot::Car, &[], &s, &[0.0, 0.0])
        };
        assert!((at(0.1) - 1.0).abs() < 1e-12);
        assert!((at(0.5) - (-0.5f64).exp()).abs() < 1e-12);
        assert!(Feature::parse("vx*vx*vx*vx*vx").is_err());
        let e = Feature::parse("l*vx")
            .unwrap()
            .check_robot(Robot::Pushing)
            .unwrap_err();
        assert!(e.to_string().contains("'vx'"));
    }

    #[test]
    fn derivatives_match_finite_differences() {
        let p: Vec<f64> = super::super::CAR_NOMINAL_PARAMS
            .iter()
            .map(|s| s.default)
            .collect();
        let s = [0.3, -0.2, 0.4, 1.2, 0.1, 0.8];
        // the commands, then their lagged copies (constants here: a model's effect states)
        let u = [0.15, 0.4, 0.1, 0.3, 0.05, 0.35, 0.0, 0.2];
        // the fitted shapes, a strip's edge passing near the state's position
        // and commands beyond a level, on either side of it
        let fitted = [
            "delta*sat_vx2(0.9)",
            "strip(0.5,0.07,0.8)",
            "delta_beyond(0.1)",
            "d_beyond(0.3)",
            "d_beyond(0.5)",
        ]
        .map(|n| Feature::parse(n).unwrap());
        for f in library(Robot::Car, None, 0).into_iter().chain(fitted) {
            let pd: Vec<Dual<8>> = p.iter().map(|&v| Dual::cst(v)).collect();
            let sd: Vec<Dual<8>> = (0..6).map(|i| Dual::var(s[i], i)).collect();
            let ud: Vec<Dual<8>> = (0..8)
                .map(|i| {
                    if i < 2 {
                        Dual::var(u[i], 6 + i)
                    } else {
                        Dual::cst(u[i])
                    }
                })
                .collect();
            assert!(f.eval(Robot::Car, &p, &s, &u).is_finite(), "{}", f.name());
            let v = f.eval(Robot::Car, &pd, &sd, &ud);
            for k in 0..8 {
                let (mut s2, mut u2) = (s, u);
                let h = 1e-6;
                if k < 6 {
                    s2[k] += h;
                } else {
                    u2[k - 6] += h;
                }
                let fd = (f.eval(Robot::Car, &p, &s2, &u2) - v.v) / h;
                assert!(
                    (fd - v.d[k]).abs() < 1e-4 * (1.0 + fd.abs()),
                    "{} d{k}",
                    f.name()
                );
            }
        }
        // pushing: state (x, y, θ), action (p, φ, ℓ)
        let s = [0.3, -0.1, 0.6];
        let u = [0.2, -0.5, 0.7];
        let area = Area {
            lo: [-0.5, -0.5],
            hi: [0.5, 0.5],
        };
        for f in library(Robot::Pushing, Some(area), 2) {
            let sd: Vec<Dual<6>> = (0..3).map(|i| Dual::var(s[i], i)).collect();
            let ud: Vec<Dual<6>> = (0..3).map(|i| Dual::var(u[i], 3 + i)).collect();
            let v = f.eval(Robot::Pushing, &[], &sd, &ud);
            for k in 0..6 {
                let (mut s2, mut u2) = (s, u);
                let h = 1e-6;
                if k < 3 {
                    s2[k] += h;
                } else {
                    u2[k - 3] += h;
                }
                let fd = (f.eval(Robot::Pushing, &[], &s2, &u2) - v.v) / h;
                assert!(
                    (fd - v.d[k]).abs() < 1e-4 * (1.0 + fd.abs()),
                    "{} d{k}",
                    f.name()
                );
            }
        }
    }
}
