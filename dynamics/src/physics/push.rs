//! The nominal pusher–slider: quasi-static pushing with an ellipsoidal limit surface (Goyal,
//! Ruina & Papadopoulos 1991; Lee & Cutkosky 1991; Lynch & Mason 1992), written in the block
//! frame and integrated over one push in normalised time `τ ∈ [0, 1]`.
//!
//! Geometry (the Tu & Lin set-up): a square block of side `a`; the pusher touches the face
//! `x = −a/2` at `(p_x, p_y) = (−a/2, κ·p·a/2)` and moves along `(cos φ, sin φ)` (block frame) by
//! `ℓ·L` over the push, so its velocity is `v_p = ℓ L (cos φ, sin φ)` per unit `τ`.
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
//! The world pose moves with the block-frame twist rotated by θ. Approximations, documented:
//! the contact point and push direction are held in the block frame over the push (the real
//! pusher moves in a straight world line while the block turns a little), no pushing when
//! `v_px ≤ 0`, and `c = 0.383 a` (uniform pressure on a square).

use super::car::{Slot, disc};
use super::{Effect, ParamSpec, ps};
use crate::conventions::PUSH_MAX_LENGTH_M;
use crate::real::Real;

/// Nominal pushing parameters (Tu & Lin's PyBullet block).
pub static PUSH_NOMINAL_PARAMS: [ParamSpec; 4] = [
    ps(
        "a",
        "a",
        "m",
        0.01,
        1.0,
        0.1,
        "block side (Tu & Lin: 0.1 m cube)",
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
];

/// Nominal pushing parameters a fit frees by default: the limit-surface ratio `c` and the usable
/// face fraction `κ`. The block side `a` is measured and the push length `L` is the commanded
/// scale; both stay fixed.
pub static PUSH_FITTED_PARAMS: [&str; 2] = ["c", "kappa"];

/// The pushing vector field with the effects in `slots` whose `active` flag is set.
pub(crate) fn rhs<R: Real>(
    p: &[R],
    slots: &[Slot],
    active: &[bool],
    s: &[R],
    u: &[R],
    out: &mut [R],
) {
    let [a, c, len, kappa] = [0, 1, 2, 3].map(|i| p[i]);
    let (x, y, th) = (s[0], s[1], s[2]);
    let (loc, phi, ell) = (u[0], u[1], u[2]);
    let mut ox = R::cst(0.0);
    let mut oy = R::cst(0.0);
    let mut mu: Option<R> = None;
    for (sl, &on) in slots.iter().zip(active) {
        if !on {
            continue;
        }
        let q = &p[sl.p_off..];
        match sl.effect {
            Effect::ComOffset => {
                ox = q[0];
                oy = q[1];
            }
            Effect::PusherFriction => mu = Some(q[0]),
            _ => {}
        }
    }
    // contact point relative to the centre of mass, block frame
    let px = a * -0.5 - ox;
    let py = kappa * loc * a * 0.5 - oy;
    let vpx = ell * len * phi.cos();
    let vpy = ell * len * phi.sin();
    let c2 = c * c;
    let m11 = py * py / c2 + 1.0;
    let m12 = -(px * py) / c2;
    let m22 = px * px / c2 + 1.0;
    let (fx, fy) = if vpx.value() <= 0.0 {
        (R::cst(0.0), R::cst(0.0))
    } else {
        match mu {
            None => (vpx / m11, R::cst(0.0)),
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
        }
    };
    let om = (px * fy - py * fx) / c2;
    // velocity of the geometric centre: v_com + ω × (centre − com)
    let vx = fx + om * oy;
    let vy = fy - om * ox;
    let (st, ct) = (th.sin(), th.cos());
    let mut wx = ct * vx - st * vy;
    let mut wy = st * vx + ct * vy;
    let mut wom = om;
    for (sl, &on) in slots.iter().zip(active) {
        if !on {
            continue;
        }
        let q = &p[sl.p_off..];
        match sl.effect {
            Effect::FrictionPatch => {
                let g = disc(x, y, q[0], q[1], q[2], q[3]) * q[4] + 1.0;
                wx = wx * g;
                wy = wy * g;
                wom = wom * g;
            }
            Effect::TableTilt => {
                let eps = 1e-6;
                let speed = (wx * wx + wy * wy + eps * eps).sqrt() - eps;
                wx = wx + q[0] * speed;
                wy = wy + q[1] * speed;
            }
            _ => {}
        }
    }
    out[0] = wx;
    out[1] = wy;
    out[2] = wom;
}
