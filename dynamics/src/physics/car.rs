//! The nominal car: a dynamic bicycle model with Pacejka "magic formula" lateral tire forces
//! and a DC-motor drivetrain, in the form of Liniger, Domahidi & Morari (2015, "Optimization-based
//! autonomous racing of 1:43 scale RC cars"), written here from the equations:
//!
//! ```text
//! ẋ  = vx cos ψ − vy sin ψ          ẏ = vx sin ψ + vy cos ψ          ψ̇ = ω
//! v̇x = (F_rx − F_fy sin δ)/m + vy ω
//! v̇y = (F_ry + F_fy cos δ)/m − vx ω
//! ω̇  = (F_fy l_f cos δ − F_ry l_r)/I_z
//! F_fy = D_f sin(C_f atan(B_f α_f))     F_ry = D_r sin(C_r atan(B_r α_r))
//! F_rx = (C_m1 − C_m2 vx) d − C_r0 tanh(vx/v_reg) − C_r2 vx|vx|
//! ```
//!
//! **Low-speed regularisation.** Liniger's slip angles `α_f = δ − atan2(ω l_f + vy, vx)`,
//! `α_r = atan2(ω l_r − vy, vx)` are singular at `vx = 0` and a standing car with the wheels
//! turned would feel a lateral force. Here the slip angle of each axle is computed from the
//! velocity of that wheel in its own frame, `α = −atan(v_lat / √(v_long² + v_reg²))`: identical
//! to Liniger's for `v_long ≫ v_reg` (forward driving), zero for a standing car, smooth through
//! `vx = 0` and opposing lateral sliding when reversing. Rolling resistance `C_r0` acts through
//! `tanh(vx/v_reg)` so it never pushes a standing car backwards, and drag is `C_r2 vx|vx|`.
//! `v_reg` defaults to 0.05 m/s (the ORCA car races at 1–3 m/s).
//!
//! **Friction ellipse on the driven rear axle** (as the simulator, `dynlab-sim`'s
//! `friction_ellipse`): the rear tire's combined force `(F_rx, F_ry)` is scaled back onto the
//! circle of radius `D_r` when it exceeds it, with a smooth maximum
//! `s = D_r / smax(‖F_r‖, D_r)`, `smax(a, b) = ½(a + b + √((a − b)² + ε²))`, `ε = 10⁻³ D_r`, so
//! that full throttle eats lateral grip (power oversteer) and the derivatives stay continuous.
//! Rolling resistance and drag act outside the ellipse, as in the simulator. How much of it a
//! car has is the weight `e` (`ellipse`): both forces are scaled by `1 − e·(1 − s)`, so `e = 1`
//! is the full ellipse (the default, and the simulator) and `e = 0` Liniger's model, whose drive
//! force never takes lateral grip. Cars differ here (tires, differential, how the motor is
//! limited), and a model with the wrong coupling mistakes a low-grip region under throttle. On
//! nominal data the rear tire rarely reaches its peak, and a free weight wandered there (0 to 1
//! on five cars of one kind; on 2 × 12 s of a car with the ellipse its fitted model had a false
//! steering term): it is fitted with a grip patch
//! ([`Effect::coupled_nominal`](super::Effect::coupled_nominal)), or when asked for.
//!
//! **Measured and fitted parameters.** Mass, yaw inertia, axle distances, the quadratic drag
//! `C_r2`, the tire shape factors and `v_reg` are measured or published values and stay fixed in a
//! fit (see [`CAR_FITTED_PARAMS`]); the mass is not identifiable from poses anyway (every force
//! term scales with it). Keeping `C_r2` fixed is what lets the `aero_drag` effect be identified:
//! a free `C_r2` would absorb it.

use super::{Effect, ParamSpec, ps};
use crate::real::Real;

/// Name of the extra state added by [`Effect::MotorLag`]: the filtered throttle `d_f`.
pub const MOTOR_LAG_STATE: &str = "d_f";

/// Name of the extra state added by [`Effect::SteeringLag`]: the wheel angle `δ_w` \[rad\].
pub const STEERING_LAG_STATE: &str = "delta_w";

/// Names of the extra states added by [`Effect::CommandDelay`]: per command (the steering's
/// \[rad\], then the throttle's) the filtered command `c` and its rate `ċ` of the delay's
/// second-order Padé filter; the car sees `c − (t_d/3)·ċ`.
pub const COMMAND_DELAY_STATES: [&str; 4] = ["delta_c", "delta_c_dot", "d_c", "d_c_dot"];

/// Nominal car parameters, defaults from the ORCA 1:43 car (Liniger et al., MPCC project).
pub static CAR_NOMINAL_PARAMS: [ParamSpec; 16] = [
    ps("m", "m", "kg", 0.01, 10.0, 0.041, "mass (ORCA 1:43)"),
    ps(
        "Iz",
        "I_z",
        "kg·m²",
        1e-6,
        1.0,
        27.8e-6,
        "yaw inertia (ORCA 1:43)",
    ),
    ps(
        "lf",
        "l_f",
        "m",
        0.005,
        1.0,
        0.029,
        "centre of mass to front axle",
    ),
    ps(
        "lr",
        "l_r",
        "m",
        0.005,
        1.0,
        0.033,
        "centre of mass to rear axle",
    ),
    ps(
        "Bf",
        "B_f",
        "-",
        0.1,
        50.0,
        2.579,
        "front Pacejka stiffness factor",
    ),
    ps(
        "Cf",
        "C_f",
        "-",
        0.1,
        3.0,
        1.2,
        "front Pacejka shape factor",
    ),
    ps(
        "Df",
        "D_f",
        "N",
        0.0,
        100.0,
        0.192,
        "front Pacejka peak force",
    ),
    ps(
        "Br",
        "B_r",
        "-",
        0.1,
        50.0,
        3.3852,
        "rear Pacejka stiffness factor",
    ),
    ps(
        "Cr",
        "C_r",
        "-",
        0.1,
        3.0,
        1.2691,
        "rear Pacejka shape factor",
    ),
    ps(
        "Dr",
        "D_r",
        "N",
        0.0,
        100.0,
        0.1737,
        "rear Pacejka peak force",
    ),
    ps(
        "Cm1",
        "C_m1",
        "N",
        0.0,
        100.0,
        0.287,
        "motor force per unit throttle",
    ),
    ps(
        "Cm2",
        "C_m2",
        "kg/s",
        0.0,
        100.0,
        0.0545,
        "motor back-EMF loss per unit throttle and speed",
    ),
    ps("Cr0", "C_r0", "N", 0.0, 10.0, 0.0518, "rolling resistance"),
    ps("Cr2", "C_r2", "kg/m", 0.0, 10.0, 0.00035, "quadratic drag"),
    ps(
        "v_reg",
        "v_reg",
        "m/s",
        1e-3,
        1.0,
        0.05,
        "low-speed regularisation of slip angles and rolling resistance",
    ),
    ps(
        "ellipse",
        "e",
        "-",
        0.0,
        1.0,
        1.0,
        "weight of the rear friction ellipse (1: throttle takes lateral grip; 0: it does not)",
    ),
];

/// Nominal car parameters a fit frees by default: tire stiffness and peak forces and the
/// drivetrain. The rest are measured (mass, inertia, geometry) or published (shape factors,
/// quadratic drag) and held at their values; the friction ellipse's weight is fitted with a
/// grip patch.
pub static CAR_FITTED_PARAMS: [&str; 7] = ["Bf", "Df", "Br", "Dr", "Cm1", "Cm2", "Cr0"];

/// Where an enabled effect's parameters and extra states live.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Slot {
    pub effect: Effect,
    pub p_off: usize,
    pub s_off: usize,
}

/// Smooth indicator of a disc: `σ((r − ‖p − c‖)/w)`.
pub(crate) fn disc<R: Real>(x: R, y: R, cx: R, cy: R, r: R, w: R) -> R {
    let dx = x - cx;
    let dy = y - cy;
    let dist = (dx * dx + dy * dy + 1e-12).sqrt();
    ((r - dist) / w).sigmoid()
}

/// The custom terms' corrections of the tire model's inputs.
#[derive(Clone, Copy)]
pub(crate) struct Inputs<R> {
    /// Added to the steering angle the tires see (`δ` terms).
    pub steer: R,
    /// The tires' peak forces are scaled by `1 + grip` (`μ` terms).
    pub grip: R,
}

/// The car vector field with the effects in `slots` whose `active` flag is set and the custom
/// terms' input corrections `inputs`.
pub(crate) fn rhs<R: Real>(
    p: &[R],
    slots: &[Slot],
    active: &[bool],
    s: &[R],
    u: &[R],
    inputs: Inputs<R>,
    out: &mut [R],
) {
    let [
        m,
        iz,
        lf,
        lr,
        bf,
        cf,
        df,
        br,
        cr,
        dr,
        cm1,
        cm2,
        cr0,
        cr2,
        vreg,
        ellipse,
    ] = [0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15].map(|i| p[i]);
    let (x, y, psi, vx, vy, om) = (s[0], s[1], s[2], s[3], s[4], s[5]);
    let commands = commands_at_car(p, slots, active, s, u);
    let (mut delta, mut d) = commands;
    let mut grip = R::cst(1.0);
    for (sl, &on) in slots.iter().zip(active) {
        if !on {
            continue;
        }
        let q = &p[sl.p_off..];
        match sl.effect {
            Effect::SteeringLag => delta = s[sl.s_off],
            Effect::MotorLag => d = s[sl.s_off],
            Effect::GripPatch => {
                let sig = disc(x, y, q[0], q[1], q[2], q[3]);
                grip = grip * ((q[4] - 1.0) * sig + 1.0);
            }
            _ => {}
        }
    }
    // custom `δ` terms correct the angle the tires see, `μ` terms the grip
    let delta = delta + inputs.steer;
    let grip = grip * (inputs.grip + 1.0);
    let (sd, cd) = (delta.sin(), delta.cos());
    let vyf = vy + lf * om;
    let v_long_f = cd * vx + sd * vyf;
    let v_lat_f = cd * vyf - sd * vx;
    let reg = vreg * vreg;
    let alpha_f = -(v_lat_f / (v_long_f * v_long_f + reg).sqrt()).atan();
    let alpha_r = -((vy - lr * om) / (vx * vx + reg).sqrt()).atan();
    let ffy = grip * df * (cf * (bf * alpha_f).atan()).sin();
    let mut fry = grip * dr * (cr * (br * alpha_r).atan()).sin();
    // friction ellipse on the driven rear axle (smooth saturation at the peak force), weighted
    let mut drive = (cm1 - cm2 * vx) * d;
    let dr_eff = grip * dr;
    let total = (drive * drive + fry * fry + 1e-12).sqrt();
    let eps = dr_eff * 1e-3 + 1e-9;
    let diff = total - dr_eff;
    let smax = (total + dr_eff + (diff * diff + eps * eps).sqrt()) * 0.5;
    let scale = R::cst(1.0) - ellipse * (R::cst(1.0) - dr_eff / smax);
    drive = drive * scale;
    fry = fry * scale;
    let frx = drive - cr0 * (vx / vreg).tanh() - cr2 * vx.mul_abs();
    let (sp, cp) = (psi.sin(), psi.cos());
    out[0] = vx * cp - vy * sp;
    out[1] = vx * sp + vy * cp;
    out[2] = om;
    out[3] = (frx - ffy * sd) / m + vy * om;
    out[4] = (fry + ffy * cd) / m - vx * om;
    out[5] = (ffy * lf * cd - fry * lr) / iz;
    for (sl, &on) in slots.iter().zip(active) {
        if on && sl.effect == Effect::AeroDrag {
            // F = −c·|v|·v on the body velocity vector (as the simulator), over the mass
            let c = p[sl.p_off];
            let speed = (vx * vx + vy * vy + 1e-12).sqrt();
            out[3] = out[3] - c * speed * vx / m;
            out[4] = out[4] - c * speed * vy / m;
        }
    }
    effect_state_rates_at(p, slots, active, s, u, commands, out);
}

/// The commanded front wheel angle: `δ`, plus `δ₀` with an active `steering_offset`.
fn steering_target<R: Real>(p: &[R], slots: &[Slot], active: &[bool], u: &[R]) -> R {
    let mut delta = u[0];
    for (sl, &on) in slots.iter().zip(active) {
        if on && sl.effect == Effect::SteeringOffset {
            delta = delta + p[sl.p_off];
        }
    }
    delta
}

/// The commands as they reach the car: the steering target ([`steering_target`]) and the
/// throttle, each through its `command_delay` filter when that is active.
fn commands_at_car<R: Real>(p: &[R], slots: &[Slot], active: &[bool], s: &[R], u: &[R]) -> (R, R) {
    for (sl, &on) in slots.iter().zip(active) {
        if on && sl.effect == Effect::CommandDelay {
            let (o, third) = (sl.s_off, p[sl.p_off] * (1.0 / 3.0));
            return (s[o] - third * s[o + 1], s[o + 2] - third * s[o + 3]);
        }
    }
    (steering_target(p, slots, active, u), u[1])
}

/// The rates of the effect states (rows `6..` of `out`; 0 for inactive effects). They read only
/// the effect states of `s` (rows `6..`), the input and the parameters — never the car's state —
/// which is what lets [`PhysicsModel::effect_states_along`](super::PhysicsModel::effect_states_along)
/// rebuild them from the command history alone.
pub(crate) fn effect_state_rates<R: Real>(
    p: &[R],
    slots: &[Slot],
    active: &[bool],
    s: &[R],
    u: &[R],
    out: &mut [R],
) {
    let commands = commands_at_car(p, slots, active, s, u);
    effect_state_rates_at(p, slots, active, s, u, commands, out);
}

/// [`effect_state_rates`] with the commands as they reach the car, `(target, throttle)`
/// ([`commands_at_car`]), which the lags act on.
fn effect_state_rates_at<R: Real>(
    p: &[R],
    slots: &[Slot],
    active: &[bool],
    s: &[R],
    u: &[R],
    (target, throttle): (R, R),
    out: &mut [R],
) {
    for o in out.iter_mut().skip(6) {
        *o = R::cst(0.0);
    }
    for (sl, &on) in slots.iter().zip(active) {
        if !on {
            continue;
        }
        let q = &p[sl.p_off..];
        let o = sl.s_off;
        match sl.effect {
            Effect::MotorLag => out[o] = (throttle - s[o]) / q[0],
            Effect::SteeringLag => {
                // δ̇_w = r·tanh((δ − δ_w)/(r·τ_s)): slope 1/τ_s at 0, |δ̇_w| < r
                let rate = q[1];
                out[o] = rate * ((target - s[o]) / (rate * q[0])).tanh();
            }
            Effect::CommandDelay => {
                // the [1/2] Padé approximant of e^(−s·t_d), (1 − s·t_d/3)/(1 + 2s·t_d/3 + s²·t_d²/6):
                // c̈ = 6(u − c − (2t_d/3)·ċ)/t_d², seen: c − (t_d/3)·ċ
                let td = q[0];
                let k = R::cst(6.0) / (td * td);
                let target = steering_target(p, slots, active, u);
                for (i, command) in [(0, target), (2, u[1])] {
                    out[o + i] = s[o + i + 1];
                    out[o + i + 1] = (command - s[o + i] - td * (2.0 / 3.0) * s[o + i + 1]) * k;
                }
            }
            _ => {}
        }
    }
}

/// The effect states of a car model at rest under a held input (every lag settled):
/// `d_f = d`, `δ_w = δ (+ δ₀)`, the delay's filters at `δ (+ δ₀)` and `d` with no rate.
pub(crate) fn settled_effect_states<R: Real>(p: &[R], slots: &[Slot], u: &[R], out: &mut [R]) {
    let active = vec![true; slots.len()];
    let target = steering_target(p, slots, &active, u);
    for sl in slots {
        let o = sl.s_off;
        match sl.effect {
            Effect::MotorLag => out[o] = u[1],
            Effect::SteeringLag => out[o] = target,
            Effect::CommandDelay => {
                out[o] = target;
                out[o + 1] = R::cst(0.0);
                out[o + 2] = u[1];
                out[o + 3] = R::cst(0.0);
            }
            _ => {}
        }
    }
}
