//! The nominal pusher–slider: quasi-static pushing with an ellipsoidal limit surface (Goyal,
//! Ruina & Papadopoulos 1991; Lee & Cutkosky 1991; Lynch & Mason 1992), written in the block
//! frame and integrated over one push in normalised time `τ ∈ [0, 1]`.
//!
//! Geometry: a rectangular block of depth `a` (along its x axis, the push direction at `φ = 0`)
//! and width `b` (along the pushed face; Tu & Lin's block is a square, `a = b`); the pusher
//! touches the face `x = −a/2` at `(p_x, p_y) = (−a/2, κ·p·b/2)` and moves along
//! `(cos φ, sin φ)` (block frame) by `ℓ·L` over the push, so its velocity is
//! `v_p = ℓ L (cos φ, sin φ)` per unit `τ`.
//!
//! Mechanics: with the limit surface `H(F) = (F_x² + F_y²)/f_max² + M²/m_max²` and
//! `c = m_max/f_max`, a contact force `F` (normalised by `f_max`) applied at `(p_x, p_y)` moves
//! the block with the twist `V = (F_x, F_y, (p_x F_y − p_y F_x)/c²)` (up to a common scale). The
//! contact-point velocity is then `M F` with
//! `M = [[1 + p_y²/c², −p_x p_y/c²], [−p_x p_y/c², 1 + p_x²/c²]]`.
//!
//! * Frictionless pusher (nominal): `F = f (1, 0)` with `f` such that the normal velocities match:
//!   `f = v_px / (1 + p_y²/c²)`; the tangential pusher motion slides along the face.
//! * With pusher friction `μ_p` (effect `pusher_friction`): sticking `F = M⁻¹ v_p` when it lies in
//!   the friction cone `|F_y| ≤ μ_p F_x` (the pusher velocity is inside the motion cone),
//!   otherwise sliding on the cone edge `F = f (1, ±μ_p)` with `f` from the normal velocity.
//!
//! **The pusher moves on a straight world line** (as the simulator's and a robot's pusher do):
//! the push starts at the step's initial pose `(x₀, y₀, θ₀)`, so the pusher centre starts at
//! `q = (x₀, y₀) + R(θ₀)·(−a/2 − r_p, κ·p·b/2)` (a disc of radius `r_p` touching the face) and
//! moves along the world direction `ψ = θ₀ + φ`. These three step constants `(ψ, q)` are held in
//! the world frame over the push (auxiliary states of the step's ODE, see
//! [`PhysicsModel::integrate_step`](super::PhysicsModel::integrate_step)); the model state stays
//! `(x, y, θ)`. At a block pose the pusher's progress `σ` along its line follows from contact
//! (the disc centre stays `r_p` behind the face): `σ = (−a/2 − r_p − n·(q − o))/(n·d)`, so the
//! contact's lateral offset `p_y = t·(q + σ d − o)` (block axes `n`, `t`) and the pusher
//! velocity in the block frame `v_p = ℓ L (cos(ψ − θ), sin(ψ − θ))` are known at every instant:
//! the block may turn under the pusher and the contact slides along the face. The contact is
//! lost when `p_y` leaves the face (`|p_y| > b/2`) or the pusher stops approaching it
//! (`cos(ψ − θ) ≤ 0`).
//!
//! Evaluated at the step's start (the plain [`VectorField`](crate::ode::VectorField) of the
//! model) the constants are those of the start pose, so `f(s, u)` is the instantaneous push
//! rate at the start of a push from `s`.
//!
//! Effects (each a physical term, checked against the simulator in the tests):
//! * `com_offset`: the centre of mass (= centre of friction, the support load's centroid) is at
//!   `(o_x, o_y)` in the block frame; contact arms are taken about it.
//! * `table_tilt`: gravity along the table, normalised by the friction limit
//!   `(g_x, g_y) = tan α / μ · (cos dir, sin dir)` (world frame), acts at the centre of mass:
//!   the table friction balances pusher force plus tilt, so the wrench `W = f·F̂ + g` lies on
//!   the limit surface `(W_x² + W_y²) + W_m²/c² = 1`, which fixes the pusher force `f`; the
//!   twist is `λ (W_x, W_y, W_m/c²)` with `λ` from the contact's normal velocity.
//! * `friction_patch`: a disc of the table where μ is `k` times the table's. The friction is
//!   per support point (a 5 × 5 grid over the footprint, as in the simulator): a block partly on
//!   the patch has its centre of friction moved towards the patch, which turns it. A block fully
//!   on or off the patch moves the same (quasi-static: friction scale does not change motion),
//!   except on a tilted table: the slope's pull is the same everywhere, the friction that holds
//!   it is not, so `table_tilt`'s `g` is divided by the block's friction limit over the table's.
//! * `pusher_friction`: sticking inside the motion cone, sliding on its edge (see above).
//! * `flat_pusher`: the pusher is a flat pad `2·t` thick and `2·w` wide held at the world yaw
//!   `ψ_f` whatever the block's heading (a gripper kept at one orientation). Turned against the
//!   face by `β = ψ_f − θ`, it touches with its leading corner, about `w·cos β` off its
//!   centre's line on the side it leads on (clamped to the face: past its end the block's
//!   corner is on the pad), so a push turns the block until face and pad align; the corner's
//!   side switches smoothly through alignment (see [`FLAT_SWITCH`]).
//!
//! Approximation, documented: `c = 0.383 a` (uniform pressure on a square) by default; the
//! support grid of `com_offset` and `friction_patch` spans the `a × b` footprint.

use super::car::disc;
use super::custom::Target;
use super::{Effect, ParamSpec, PhysicsModel, ps};
use crate::conventions::PUSH_MAX_LENGTH_M;
use crate::real::Real;

/// Nominal pushing parameters (Tu & Lin's PyBullet block). The width `b` comes last so that
/// the indices of the others are those of the square block's model.
pub static PUSH_NOMINAL_PARAMS: [ParamSpec; 5] = [
    ps(
        "a",
        "a",
        "m",
        0.01,
        1.0,
        0.1,
        "block depth, across the pushed face (Tu & Lin: 0.1 m cube)",
    ),
    ps(
        "c",
        "c",
        "m",
        0.001,
        1.0,
        0.0383,
        "limit-surface ratio m_max/f_max (uniform pressure square: 0.383 a)",
    ),
    ps(
        "L",
        "L",
        "m",
        0.001,
        1.0,
        PUSH_MAX_LENGTH_M,
        "push length at ℓ = 1",
    ),
    ps(
        "kappa",
        "κ",
        "-",
        0.0,
        1.0,
        0.95,
        "usable fraction of the half face (Tu & Lin leave a 5 % margin)",
    ),
    ps(
        "b",
        "b",
        "m",
        0.01,
        1.0,
        0.1,
        "block width, along the pushed face (Tu & Lin: 0.1 m cube)",
    ),
];

/// Nominal pushing parameters a fit frees by default: the limit-surface ratio `c` and the usable
/// face fraction `κ`. The block's depth `a` and width `b` are measured (`dynlab train --set
/// a=0.08 --set b=0.12` for a rectangular block) and the push length `L` is the commanded
/// scale; they stay fixed (the diagnosis refits the depth within ±10 % for its baseline;
/// `--free a,c,kappa` fits it in training, to ±8 mm on 100 pushes). `κ` also absorbs what the
/// ellipsoid gets wrong about
/// off-centre pushes (held at the simulator's 0.95 with `b` and `c` free, the term search
/// finds `ẋ_b += ≈0.005·ℓ·p²` m/push on the simulator's nominal block), which is why it is
/// fitted and often ends on its bound 1.
pub static PUSH_FITTED_PARAMS: [&str; 2] = ["c", "kappa"];

/// How the pushing model turns the pusher's force into the block's motion.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LimitSurface {
    /// The ellipsoidal limit surface with ratio `c` (closed form; the default).
    #[default]
    Ellipsoid,
    /// The Coulomb friction of the `5 × 5` support points solved exactly (Newton's method in
    /// every evaluation, started from the ellipsoid's motion, which stays where it finds no
    /// solution; derivatives by the implicit-function theorem), their arms scaled so that their
    /// mean distance from the centre is `c`: off-centre pushes as the points dictate, at
    /// several times the cost.
    SupportPoints,
}

impl LimitSurface {
    /// Every choice.
    pub const ALL: [LimitSurface; 2] = [LimitSurface::Ellipsoid, LimitSurface::SupportPoints];

    /// The name in files and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            LimitSurface::Ellipsoid => "ellipsoid",
            LimitSurface::SupportPoints => "support_points",
        }
    }

    /// The choice of a name, if it is one.
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|l| l.name() == name)
    }
}

impl std::fmt::Display for LimitSurface {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// Pusher disc radius \[m\] (the simulator's default finger tip).
pub const PUSHER_RADIUS_M: f64 = 0.01;

/// Support grid of the `friction_patch` term: `N × N` points over the footprint.
const PATCH_GRID: usize = 5;

/// Least scale of the table's friction under a support point from the custom terms on it
/// (a term on `x` or `y` grows without bound across the table).
const MIN_FRICTION_SCALE: f64 = 0.05;

/// The support points of a block of depth `a` and width `b` (block frame, about its centre):
/// the `N × N` grid of cell centres the friction model places under the footprint, where the
/// table's friction is read.
pub fn support_grid(a: f64, b: f64) -> Vec<[f64; 2]> {
    (0..PATCH_GRID)
        .flat_map(|i| (0..PATCH_GRID).map(move |j| [a * grid_at(i), b * grid_at(j)]))
        .collect()
}

/// The `i`-th cell centre of the support grid across the footprint, in units of its side
/// (−0.5 … 0.5).
fn grid_at(i: usize) -> f64 {
    (i as f64 + 0.5) / PATCH_GRID as f64 - 0.5
}

/// How sharply the flat pusher's touching corner switches sides as its turn against the face
/// passes zero: `sgn(sin β) ≈ tanh(sin β / FLAT_SWITCH)`. Around alignment the pad touches
/// along its whole face, where the contact's centre of pressure lies anywhere on the pad; the
/// smooth switch puts it where the block keeps its heading, which is what a flat contact does.
const FLAT_SWITCH: f64 = 0.02;

/// Over how much of its last overlap with the face \[m\] a flat pusher's push fades out as it
/// slides off the face's end.
const FLAT_RELEASE_M: f64 = 0.002;

/// The share of a flat pusher's motion that reaches the block with `margin` of overlap left:
/// 1 down to [`FLAT_RELEASE_M`], then a smoothstep to 0. A contact dropped at once made the
/// model's step jump with the pad's yaw at the pushes that slide off the face, and one such
/// push held nearly all of a fit's information on the yaw (its σ ±42 rad on Tu & Lin's data).
fn smooth_release<R: Real>(margin: R) -> R {
    if margin.value() >= FLAT_RELEASE_M {
        return R::cst(1.0);
    }
    let s = margin / FLAT_RELEASE_M;
    s * s * (s * -2.0 + 3.0)
}

/// The flat pusher's `[yaw, half width, half thickness]` if `flat_pusher` is on (`active`:
/// the effects' flags, `None` for all on).
pub(crate) fn flat_pusher<R: Real>(
    p: &[R],
    model: &PhysicsModel,
    active: Option<&[bool]>,
) -> Option<[R; 3]> {
    model
        .slots()
        .iter()
        .enumerate()
        .find(|(i, sl)| {
            sl.effect == Effect::FlatPusher && active.is_none_or(|a| a.get(*i) == Some(&true))
        })
        .map(|(_, sl)| [0, 1, 2].map(|k| p[sl.p_off + k]))
}

/// Where a pusher turned by `β` against the face touches it, relative to its centre (block
/// frame): how far it reaches ahead, the touching point's lateral offset and the pusher's
/// lateral half extent. A disc reaches `r_p` straight ahead; a flat pusher (a pad of half
/// width `w` and half thickness `t`) reaches with its leading corner, `t·|cos β| + w·|sin β|`
/// ahead and `t·sin β·sgn(cos β) − w·cos β·sgn(sin β)` to the side, and spans
/// `w·|cos β| + t·|sin β|` to each side.
fn reach<R: Real>(flat: Option<[R; 3]>, th: R) -> [R; 3] {
    match flat {
        None => [R::cst(PUSHER_RADIUS_M), R::cst(0.0), R::cst(0.0)],
        Some([yaw, w, t]) => {
            let beta = yaw - th;
            let (sb, cb) = (beta.sin(), beta.cos());
            let sgn_s = (sb / FLAT_SWITCH).tanh();
            let sgn_c = (cb / FLAT_SWITCH).tanh();
            [
                cb * sgn_c * t + w * sb * sgn_s,
                sb * sgn_c * t - w * cb * sgn_s,
                w * cb.abs() + t * sb.abs(),
            ]
        }
    }
}

/// The step constants `(ψ, q_x, q_y)` of a push from pose `s` under action `u`: the world push
/// direction and the pusher centre's start point (world frame), the pusher touching the face
/// (`flat`: the flat pusher, see [`flat_pusher`]).
pub(crate) fn start_constants<R: Real>(p: &[R], flat: Option<[R; 3]>, s: &[R], u: &[R]) -> [R; 3] {
    let (a, kappa, b) = (p[0], p[3], p[4]);
    let (x, y, th) = (s[0], s[1], s[2]);
    let bx = a * -0.5 - reach(flat, th)[0];
    let by = kappa * u[0] * b * 0.5;
    let (st, ct) = (th.sin(), th.cos());
    [th + u[1], x + ct * bx - st * by, y + st * bx + ct * by]
}

/// The pushing vector field at the start of a push from `s` (step constants from `s`, `u`).
pub(crate) fn rhs<R: Real>(
    p: &[R],
    model: &PhysicsModel,
    active: &[bool],
    s: &[R],
    u: &[R],
    out: &mut [R],
) {
    let line = start_constants(p, flat_pusher(p, model, Some(active)), s, u);
    rhs_line(p, model, active, s, line, u[2], out);
}

/// The pushing vector field at pose `s` during a push along the world line `line = (ψ, q)`
/// with length fraction `ell`.
pub(crate) fn rhs_line<R: Real>(
    p: &[R],
    model: &PhysicsModel,
    active: &[bool],
    s: &[R],
    line: [R; 3],
    ell: R,
    out: &mut [R],
) {
    let [a, c, len, _kappa, b] = [0, 1, 2, 3, 4].map(|i| p[i]);
    let (x, y, th) = (s[0], s[1], s[2]);
    let [psi, qx, qy] = line;
    let zero = R::cst(0.0);
    out[0] = zero;
    out[1] = zero;
    out[2] = zero;
    let mut com: Option<(R, R)> = None;
    let mut patch: Option<&[R]> = None;
    let mut mu: Option<R> = None;
    let mut tilt: Option<(R, R)> = None;
    let mut flat: Option<[R; 3]> = None;
    for (sl, &on) in model.slots().iter().zip(active) {
        if !on {
            continue;
        }
        let q = &p[sl.p_off..];
        match sl.effect {
            Effect::ComOffset => com = Some((q[0], q[1])),
            Effect::PusherFriction => mu = Some(q[0]),
            Effect::TableTilt => tilt = Some((q[0], q[1])),
            Effect::FrictionPatch => patch = Some(q),
            Effect::FlatPusher => flat = Some([q[0], q[1], q[2]]),
            _ => {}
        }
    }
    // the table's friction from the custom terms on it, at a place on the table
    let field = model
        .has_custom_target(Target::Friction)
        .then_some(|wx: R, wy: R| model.custom_input(Target::Friction, p, &[wx, wy, th], &[]));
    let uneven = com.is_some() || patch.is_some() || field.is_some();
    // the support points where the friction model needs them, computed once
    let exact = model.limit_surface() == LimitSurface::SupportPoints;
    let support = (exact || uneven).then(|| {
        let field = field.as_ref().map(|f| f as &dyn Fn(R, R) -> R);
        support_points([a, b], c, [x, y, th], com, patch, field)
    });
    let (pts, friction) = match support {
        Some((pts, k)) => (Some(pts), k),
        None => (None, R::cst(1.0)),
    };
    // centre of friction and limit-surface ratio of the support distribution
    let (ox, oy, c) = match &pts {
        Some(pts) if uneven => support_friction(pts),
        _ => (zero, zero, c),
    };
    let (st, ct) = (th.sin(), th.cos());
    // tilt force in the block frame, normalised by the friction limit: the table's, scaled by
    // the friction the block stands on (on a patch of less friction the same slope pulls harder)
    let tilt = tilt.map(|(gx, gy)| {
        let (gx, gy) = (gx / friction, gy / friction);
        (ct * gx + st * gy, ct * gy - st * gx)
    });
    let rel = psi - th;
    let (nd, td) = (rel.cos(), rel.sin());
    if nd.value() <= 1e-6 {
        return;
    }
    // pusher progress from contact, then the contact's lateral offset (block frame)
    let (rx, ry) = (qx - x, qy - y);
    let n_rel = ct * rx + st * ry;
    let t_rel = ct * ry - st * rx;
    let [ahead, side, extent] = reach(flat, th);
    let sigma = (a * -0.5 - ahead - n_rel) / nd;
    let centre = t_rel + sigma * td;
    let half = b * 0.5;
    // the contact point and how much of the pusher's motion reaches the block
    let (lat, fade) = match flat {
        None if centre.value().abs() > half.value() => return,
        None => (centre, R::cst(1.0)),
        Some(_) => {
            // the pad overlaps the face as long as its centre is within its lateral half
            // extent of it; a corner past the face's end leaves the block's corner on the pad
            let off = if centre.value() < 0.0 {
                -centre
            } else {
                centre
            };
            let margin = half + extent - off;
            if margin.value() <= 0.0 {
                return;
            }
            let lat = centre + side;
            let lat = match lat.value() {
                v if v > half.value() => half,
                v if v < -half.value() => -half,
                _ => lat,
            };
            (lat, smooth_release(margin))
        }
    };
    // contact point relative to the centre of friction, block frame
    let px = a * -0.5 - ox;
    let py = lat - oy;
    let vpx = ell * len * nd * fade;
    let vpy = ell * len * td * fade;
    if vpx.value() <= 0.0 {
        return;
    }
    let c2 = c * c;
    let m11 = py * py / c2 + 1.0;
    let m12 = -(px * py) / c2;
    let m22 = px * px / c2 + 1.0;
    let (mut fx, mut fy) = match mu {
        None => (vpx / m11, zero),
        Some(mu) => {
            let det = m11 * m22 - m12 * m12;
            let sx = (m22 * vpx - m12 * vpy) / det;
            let sy = (m11 * vpy - m12 * vpx) / det;
            if sy.value().abs() <= (mu * sx).value() {
                (sx, sy)
            } else {
                let sign = if sy.value() >= 0.0 { 1.0 } else { -1.0 };
                let dir_y = mu * sign;
                let f = vpx / (m11 + m12 * dir_y);
                (f, f * dir_y)
            }
        }
    };
    let mut mz = px * fy - py * fx;
    if let Some((tx, ty)) = tilt {
        // the wrench f·(F̂, m̂) + (t, 0) on the unit limit surface, then scaled to the contact
        // kinematics
        let qa = fx * fx + fy * fy + mz * mz / c2;
        let qb = fx * tx + fy * ty;
        let qc = tx * tx + ty * ty - 1.0;
        let disc = qb * qb - qa * qc;
        let disc = if disc.value() > 1e-12 {
            disc
        } else {
            R::cst(1e-12)
        };
        let f = (disc.sqrt() - qb) / qa;
        let (wx, wy, wm) = (f * fx + tx, f * fy + ty, f * mz);
        let normal = wx - wm * py / c2;
        if normal.value() <= 1e-9 {
            return;
        }
        let lam = vpx / normal;
        fx = lam * wx;
        fy = lam * wy;
        mz = lam * wm;
    }
    let om = mz / c2;
    // velocity of the geometric centre: v_cof + ω × (centre − cof)
    let vx = fx + om * oy;
    let vy = fy - om * ox;
    let (vx, vy, om) = if let Some(pts) = pts.as_deref().filter(|_| exact) {
        let (cx_, cy_) = com.unwrap_or((zero, zero));
        let tw = match tilt {
            Some((tx, ty)) => [tx, ty, cx_ * ty - cy_ * tx],
            None => [zero; 3],
        };
        let guess = [
            (vy / vpx).value(),
            (om / vpx).value(),
            1.0 / (1.0 + (py * py / c2).value()).sqrt(),
        ];
        // the ellipsoid's motion where Newton finds no pressing solution (it starts from it)
        super::support::pushed_twist(pts, [a * -0.5, lat], [vpx, vpy], tw, mu, guess)
            .map_or((vx, vy, om), |[vx, vy, om]| (vx, vy, om))
    } else {
        (vx, vy, om)
    };
    out[0] = ct * vx - st * vy;
    out[1] = st * vx + ct * vy;
    out[2] = om;
}

/// The support points `[x, y, w]` (block frame, about the centre) of a block of depth `a` and
/// width `b` at pose `(x, y, θ)`: an `N × N` grid of cell centres (as in the simulator) with
/// friction weights `wᵢ ∝ Nᵢ·μᵢ`, `Σ wᵢ = 1` — the normal load varies linearly so that its
/// centroid is the centre of mass (`com_offset`: `Nᵢ ∝ max(0, 1 + o_x xᵢ/⟨x²⟩ + o_y yᵢ/⟨y²⟩)`,
/// the simulator's load model), and `μᵢ/μ = 1 + (k − 1)·σ((r − ‖pᵢ − c‖)/w)` on a disc patch
/// (`friction_patch`), times `1 + field(pᵢ)` (the custom terms on the table's friction, at
/// least [`MIN_FRICTION_SCALE`]), `pᵢ` the point's place on the table. The arms about the
/// weighted centroid are scaled by `c` over the uniform grid's mean distance from the centre,
/// so that `c` is the limit-surface ratio of the uniform support. Also returned: the block's
/// friction limit over the table's, `Σ Nᵢμᵢ / (μ Σ Nᵢ)` (1 off a patch).
fn support_points<R: Real>(
    [a, b]: [R; 2],
    c: R,
    [x, y, th]: [R; 3],
    com: Option<(R, R)>,
    patch: Option<&[R]>,
    field: Option<&dyn Fn(R, R) -> R>,
) -> (Vec<[R; 3]>, R) {
    let (st, ct) = (th.sin(), th.cos());
    // ⟨x²⟩ of the grid in units of a², ⟨y²⟩ in units of b²
    let m2: f64 = (0..PATCH_GRID).map(|i| grid_at(i).powi(2)).sum::<f64>() / PATCH_GRID as f64;
    let mut pts = Vec::with_capacity(PATCH_GRID * PATCH_GRID);
    let mut uniform = R::cst(0.0);
    let mut load = R::cst(0.0);
    for i in 0..PATCH_GRID {
        for j in 0..PATCH_GRID {
            let (fx, fy) = (grid_at(i), grid_at(j));
            let lx = a * fx;
            let ly = b * fy;
            let mut wi = R::cst(1.0);
            if let Some((cx_, cy_)) = com {
                let l = cx_ * fx / (a * m2) + cy_ * fy / (b * m2) + 1.0;
                wi = if l.value() > 0.0 { l } else { R::cst(0.0) };
            }
            load = load + wi;
            let wx = x + ct * lx - st * ly;
            let wy = y + st * lx + ct * ly;
            if let Some(q) = patch {
                wi = wi * (disc(wx, wy, q[0], q[1], q[2], q[3]) * (q[4] - 1.0) + 1.0);
            }
            if let Some(f) = field {
                let k = f(wx, wy) + 1.0;
                wi = wi
                    * if k.value() > MIN_FRICTION_SCALE {
                        k
                    } else {
                        R::cst(MIN_FRICTION_SCALE)
                    };
            }
            // + 1e-12: the distance of the grid's centre point has no derivative at 0
            uniform = uniform + (lx * lx + ly * ly + 1e-12).sqrt();
            pts.push([lx, ly, wi]);
        }
    }
    let scale = c / (uniform / pts.len() as f64);
    let sw = pts.iter().fold(R::cst(0.0), |s, p| s + p[2]);
    let ox = pts.iter().fold(R::cst(0.0), |s, p| s + p[0] * p[2]) / sw;
    let oy = pts.iter().fold(R::cst(0.0), |s, p| s + p[1] * p[2]) / sw;
    for p in &mut pts {
        *p = [
            ox + (p[0] - ox) * scale,
            oy + (p[1] - oy) * scale,
            p[2] / sw,
        ];
    }
    (pts, sw / load)
}

/// Centre of friction `(o_x, o_y)` (block frame) and limit-surface ratio of the
/// [`support_points`]: their weighted centroid and weighted mean distance from it.
fn support_friction<R: Real>(pts: &[[R; 3]]) -> (R, R, R) {
    let zero = R::cst(0.0);
    let ox = pts.iter().fold(zero, |s, p| s + p[0] * p[2]);
    let oy = pts.iter().fold(zero, |s, p| s + p[1] * p[2]);
    let ratio = pts.iter().fold(zero, |s, p| {
        let (dx, dy) = (p[0] - ox, p[1] - oy);
        s + p[2] * (dx * dx + dy * dy + 1e-12).sqrt()
    });
    (ox, oy, ratio)
}
