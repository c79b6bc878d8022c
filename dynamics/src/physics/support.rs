//! Quasi-static motion of a block on point supports: the twist under which the Coulomb friction
//! of the supports balances a pusher's force (and a table tilt), solved exactly instead of
//! through the ellipsoidal approximation of the limit surface.
//!
//! Support point `i` at `rᵢ = (xᵢ, yᵢ)` (block frame, about the block's centre) carries the
//! friction weight `wᵢ` (load times friction coefficient, `Σ wᵢ = 1`: forces in units of the
//! block's total friction limit). A twist `V = (v_x, v_y, ω)` of the centre moves the point with
//! `vᵢ = (v_x − ω yᵢ, v_y + ω xᵢ)`; its friction opposes that, so the pusher and the tilt must
//! supply `W(V) = Σ wᵢ (v̂ᵢ, xᵢ v̂ᵢ_y − yᵢ v̂ᵢ_x)` (force, moment about the centre), with
//! `v̂ = v/√(|v|² + ε²)` (`ε` a thousandth of the contact's normal speed: smooth where the
//! centre of rotation crosses a support point).
//!
//! * Pushing force along a known direction `D` (a frictionless pusher: the face normal; a
//!   sliding one: the edge of its friction cone) at the contact `(p_x, p_y)`:
//!   `W(V) = f·(D_x, D_y, p_x D_y − p_y D_x) + T` with the contact's normal speed fixed, three
//!   equations in `v_y`, `ω` and the force `f`.
//! * A sticking pusher: the contact moves with the pusher, which leaves `ω`, fixed by the
//!   wrench `W(V) − T` passing through the contact.
//!
//! Newton's method in `f64` (its Jacobian from dual numbers), then one Newton step in the
//! caller's [`Real`] at the solution: the implicit-function theorem's exact derivatives with
//! respect to everything the residual depends on.

use crate::real::{Dual, Real};

/// Smoothing of the supports' velocity directions, relative to the contact's normal speed.
const EPS: f64 = 1e-3;
/// Newton iterations at most.
const MAX_ITER: usize = 40;

/// The friction wrench `W(V)` the supports resist twist `v` with.
fn wrench<T: Real>(pts: &[[T; 3]], v: [T; 3]) -> [T; 3] {
    let zero = T::cst(0.0);
    let (mut fx, mut fy, mut m) = (zero, zero, zero);
    for &[x, y, w] in pts {
        let ux = v[0] - v[2] * y;
        let uy = v[1] + v[2] * x;
        let k = w / (ux * ux + uy * uy + EPS * EPS).sqrt();
        fx = fx + k * ux;
        fy = fy + k * uy;
        m = m + k * (x * uy - y * ux);
    }
    [fx, fy, m]
}

/// What is solved for, with its residual.
#[derive(Clone, Copy)]
enum Mode<T> {
    /// Unknowns `(v_y, ω, f)`, the contact's normal speed 1: force `f` along `d`.
    Directed { d: [T; 2] },
    /// Unknown `ω`: the contact moves with the pusher, whose velocity is `(1, t)`.
    Sticking { t: T },
}

/// Twist of the centre for the unknowns `z` (contact normal speed 1).
fn twist<T: Real>(mode: &Mode<T>, contact: [T; 2], z: &[T]) -> [T; 3] {
    let [px, py] = contact;
    match mode {
        Mode::Directed { .. } => [z[1] * py + 1.0, z[0], z[1]],
        Mode::Sticking { t } => [z[0] * py + 1.0, *t - z[0] * px, z[0]],
    }
}

fn residual<T: Real>(
    pts: &[[T; 3]],
    contact: [T; 2],
    tilt: [T; 3],
    mode: &Mode<T>,
    z: &[T],
    out: &mut [T],
) {
    let [px, py] = contact;
    let w = wrench(pts, twist(mode, contact, z));
    match mode {
        Mode::Directed { d } => {
            let f = z[2];
            let dm = px * d[1] - py * d[0];
            out[0] = w[0] - f * d[0] - tilt[0];
            out[1] = w[1] - f * d[1] - tilt[1];
            out[2] = w[2] - f * dm - tilt[2];
        }
        Mode::Sticking { .. } => {
            let (fx, fy, fm) = (w[0] - tilt[0], w[1] - tilt[1], w[2] - tilt[2]);
            out[0] = fm - (px * fy - py * fx);
        }
    }
}

fn values<R: Real, const K: usize>(x: [R; K]) -> [f64; K] {
    x.map(|v| v.value())
}

/// Solves `J Δ = r` for `K ≤ 3` by Gaussian elimination with partial pivoting.
fn solve_linear<const K: usize>(mut j: [[f64; K]; K], mut r: [f64; K]) -> Option<[f64; K]> {
    for c in 0..K {
        let p = (c..K).max_by(|&a, &b| j[a][c].abs().total_cmp(&j[b][c].abs()))?;
        if j[p][c].abs() < 1e-14 {
            return None;
        }
        j.swap(c, p);
        r.swap(c, p);
        for row in c + 1..K {
            let k = j[row][c] / j[c][c];
            for col in c..K {
                j[row][col] -= k * j[c][col];
            }
            r[row] -= k * r[c];
        }
    }
    let mut x = [0.0; K];
    for c in (0..K).rev() {
        let s: f64 = (c + 1..K).map(|k| j[c][k] * x[k]).sum();
        x[c] = (r[c] - s) / j[c][c];
    }
    Some(x)
}

/// Newton's method on the `f64` values; returns the solution and the residual's Jacobian there.
fn newton<const K: usize>(
    pts: &[[f64; 3]],
    contact: [f64; 2],
    tilt: [f64; 3],
    mode: &Mode<f64>,
    mut z: [f64; K],
) -> Option<([f64; K], [[f64; K]; K])> {
    let dual_mode = match mode {
        Mode::Directed { d } => Mode::Directed {
            d: d.map(Dual::<K>::cst),
        },
        Mode::Sticking { t } => Mode::Sticking {
            t: Dual::<K>::cst(*t),
        },
    };
    let dpts: Vec<[Dual<K>; 3]> = pts.iter().map(|p| p.map(Dual::<K>::cst)).collect();
    let (dc, dt) = (contact.map(Dual::<K>::cst), tilt.map(Dual::<K>::cst));
    let eval = |z: &[f64; K]| {
        let zd: [Dual<K>; K] = std::array::from_fn(|i| Dual::var(z[i], i));
        let mut out = [Dual::<K>::cst(0.0); K];
        residual(&dpts, dc, dt, &dual_mode, &zd, &mut out);
        let r = out.map(|o| o.v);
        let j: [[f64; K]; K] = std::array::from_fn(|i| out[i].d);
        (r, j)
    };
    let norm = |r: &[f64; K]| r.iter().map(|x| x * x).sum::<f64>();
    let (mut r, mut j) = eval(&z);
    for _ in 0..MAX_ITER {
        // the closing step in `lift` squares what is left
        if norm(&r) < 1e-20 {
            return Some((z, j));
        }
        let step = solve_linear(j, r)?;
        // damped: halve the step until the residual falls
        let mut lambda = 1.0;
        loop {
            let trial: [f64; K] = std::array::from_fn(|i| z[i] - lambda * step[i]);
            let (rt, jt) = eval(&trial);
            if norm(&rt) < norm(&r) || lambda < 1e-4 {
                z = trial;
                r = rt;
                j = jt;
                break;
            }
            lambda *= 0.5;
        }
    }
    (norm(&r) < 1e-16).then_some((z, j))
}

/// The unknowns in the caller's `Real`: one Newton step from the `f64` solution `z`, exact in
/// its first derivatives.
fn lift<R: Real, const K: usize>(
    pts: &[[R; 3]],
    contact: [R; 2],
    tilt: [R; 3],
    mode: &Mode<R>,
    z: [f64; K],
    j: [[f64; K]; K],
) -> Option<[R; K]> {
    let zr = z.map(R::cst);
    let mut r = [R::cst(0.0); K];
    residual(pts, contact, tilt, mode, &zr, &mut r);
    // Δ = J⁻¹ r, linear in r: solve for each column of the derivatives through the inverse
    let mut inv = [[0.0; K]; K];
    for c in 0..K {
        let mut e = [0.0; K];
        e[c] = 1.0;
        let col = solve_linear(j, e)?;
        for row in 0..K {
            inv[row][c] = col[row];
        }
    }
    Some(std::array::from_fn(|i| {
        let mut delta = R::cst(0.0);
        for (k, rk) in r.iter().enumerate() {
            delta = delta + *rk * inv[i][k];
        }
        zr[i] - delta
    }))
}

/// The quasi-static twist `(v_x, v_y, ω)` of the block's centre (block frame) pushed at
/// `contact = (p_x, p_y)` with pusher velocity `vp = (v_px, v_py)`, `v_px > 0`, on supports
/// `pts`, with tilt wrench `tilt` (force and moment about the centre, in units of the friction
/// limit) and pusher friction `mu` (`None`: frictionless). `guess`: `(v_y, ω, f)` per unit normal
/// speed to start Newton from. `None` when the pusher does not press on the block (the tilt
/// pulls it away) or Newton fails.
pub(crate) fn pushed_twist<R: Real>(
    pts: &[[R; 3]],
    contact: [R; 2],
    vp: [R; 2],
    tilt: [R; 3],
    mu: Option<R>,
    guess: [f64; 3],
) -> Option<[R; 3]> {
    let fpts: Vec<[f64; 3]> = pts.iter().map(|p| values(*p)).collect();
    let (fc, ft) = (values(contact), values(tilt));
    let scale = |z: [R; 3]| z.map(|x| x * vp[0]);
    let directed = |d: [R; 2]| -> Option<([R; 3], f64)> {
        let fmode = Mode::Directed { d: values(d) };
        let (z, j) = newton::<3>(&fpts, fc, ft, &fmode, guess)?;
        let zr = lift(pts, contact, tilt, &Mode::Directed { d }, z, j)?;
        Some((twist(&Mode::Directed { d }, contact, &zr), z[2]))
    };
    let frictionless = || {
        let (v, f) = directed([R::cst(1.0), R::cst(0.0)])?;
        (f > 0.0).then(|| scale(v))
    };
    let Some(mu) = mu else {
        return frictionless();
    };
    // sticking: the contact moves with the pusher
    let t = vp[1] / vp[0];
    let smode = Mode::Sticking { t: t.value() };
    let (z, j) = newton::<1>(&fpts, fc, ft, &smode, [guess[1]])?;
    let zr = lift(pts, contact, tilt, &Mode::Sticking { t }, z, j)?;
    let v = twist(&Mode::Sticking { t }, contact, &zr);
    let w = wrench(pts, v);
    let (fx, fy) = (w[0] - tilt[0], w[1] - tilt[1]);
    if fx.value() > 0.0 && fy.value().abs() <= (mu * fx).value() {
        return Some(scale(v));
    }
    if fx.value() <= 0.0 {
        return None;
    }
    // sliding on the edge of the friction cone on the side the sticking force leaned to
    let sign = if fy.value() >= 0.0 { 1.0 } else { -1.0 };
    let (v, f) = directed([R::cst(1.0), mu * sign])?;
    (f > 0.0).then(|| scale(v))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A uniform `n × n` grid over a square of side `a`.
    fn grid(n: usize, a: f64) -> Vec<[f64; 3]> {
        let g = |i: usize| a * ((i as f64 + 0.5) / n as f64 - 0.5);
        let w = 1.0 / (n * n) as f64;
        (0..n * n).map(|k| [g(k / n), g(k % n), w]).collect()
    }

    #[test]
    fn a_centred_push_translates_and_an_off_centre_push_turns_away_from_the_contact() {
        let pts = grid(5, 0.1);
        let tw = |py: f64| {
            pushed_twist(&pts, [-0.05, py], [1.0, 0.0], [0.0; 3], None, [0.0; 3]).unwrap()
        };
        let v = tw(0.0);
        assert!(
            (v[0] - 1.0).abs() < 1e-9 && v[1].abs() < 1e-9 && v[2].abs() < 1e-9,
            "{v:?}"
        );
        // pushed left of centre (py > 0): turns clockwise, slower along the push
        let v = tw(0.0475);
        assert!(v[2] < -5.0 && v[0] < 0.6 && v[0] > 0.2, "{v:?}");
        // mirror symmetry
        let m = tw(-0.0475);
        assert!(
            (m[0] - v[0]).abs() < 1e-9 && (m[2] + v[2]).abs() < 1e-9,
            "{m:?} {v:?}"
        );
        // the friction wrench balances the pusher's: no sideways force, moment −p_y f
        let w = wrench(&pts, v);
        assert!(
            w[1].abs() < 1e-9 && (w[2] + 0.0475 * w[0]).abs() < 1e-9,
            "{w:?}"
        );
    }

    #[test]
    fn derivatives_match_finite_differences() {
        // d(twist)/d(contact offset) and d/d(a support weight) through the dual numbers
        let base = grid(4, 0.1);
        let at = |py: f64, dw: f64| {
            let mut p = base.clone();
            p[0][2] += dw;
            pushed_twist(
                &p,
                [-0.05, py],
                [1.0, 0.2],
                [0.01, 0.0, 0.0],
                Some(0.3),
                [0.0; 3],
            )
            .unwrap()
        };
        let py = 0.02;
        let pts: Vec<[Dual<2>; 3]> = base
            .iter()
            .enumerate()
            .map(|(i, p)| {
                let w = if i == 0 {
                    Dual::var(p[2], 1)
                } else {
                    Dual::cst(p[2])
                };
                [Dual::cst(p[0]), Dual::cst(p[1]), w]
            })
            .collect();
        let v = pushed_twist(
            &pts,
            [Dual::cst(-0.05), Dual::var(py, 0)],
            [Dual::cst(1.0), Dual::cst(0.2)],
            [Dual::cst(0.01), Dual::cst(0.0), Dual::cst(0.0)],
            Some(Dual::cst(0.3)),
            [0.0; 3],
        )
        .unwrap();
        let h = 1e-6;
        for k in 0..3 {
            let fd_py = (at(py + h, 0.0)[k] - at(py - h, 0.0)[k]) / (2.0 * h);
            let fd_w = (at(py, h)[k] - at(py, -h)[k]) / (2.0 * h);
            assert!(
                (v[k].d[0] - fd_py).abs() < 1e-4 * fd_py.abs().max(1.0),
                "{k}: {v:?} {fd_py}"
            );
            assert!(
                (v[k].d[1] - fd_w).abs() < 1e-4 * fd_w.abs().max(1.0),
                "{k}: {v:?} {fd_w}"
            );
        }
    }
}
