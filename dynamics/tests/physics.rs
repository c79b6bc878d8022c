//! Physics models: exact Jacobians against finite differences, physical sanity, effects,
//! residuals for fitting, printing and errors.
#![allow(clippy::needless_range_loop)] // index loops mirror the math

mod common;
use common::max_rel_diff;
use dynlab_dynamics::ode::{Solver, VectorField, integrate, step_jacobians};
use dynlab_dynamics::physics::*;

fn car_all() -> PhysicsModel {
    let mut m = PhysicsModel::car(&[
        Effect::AeroDrag,
        Effect::MotorLag,
        Effect::SteeringOffset,
        Effect::GripPatch,
    ])
    .unwrap();
    m.set_param("aero_drag.c", 0.08).unwrap();
    m.set_param("motor_lag.tau", 0.07).unwrap();
    m.set_param("steering_offset.delta0", 0.03).unwrap();
    m.set_param("grip_patch.cx", 1.0).unwrap();
    m.set_param("grip_patch.cy", 0.4).unwrap();
    m.set_param("grip_patch.r", 0.5).unwrap();
    m.set_param("grip_patch.w", 0.1).unwrap();
    m.set_param("grip_patch.k", 0.6).unwrap();
    m
}

fn push_all(mu: f64) -> PhysicsModel {
    let mut m = PhysicsModel::pushing(&[
        Effect::ComOffset,
        Effect::TableTilt,
        Effect::FrictionPatch,
        Effect::PusherFriction,
    ])
    .unwrap();
    m.set_param("com_offset.ox", 0.01).unwrap();
    m.set_param("com_offset.oy", -0.005).unwrap();
    m.set_param("table_tilt.gx", 0.05).unwrap();
    m.set_param("table_tilt.gy", -0.02).unwrap();
    m.set_param("friction_patch.cx", 0.45).unwrap();
    m.set_param("friction_patch.cy", 0.02).unwrap();
    m.set_param("friction_patch.r", 0.05).unwrap();
    m.set_param("friction_patch.w", 0.02).unwrap();
    m.set_param("friction_patch.k", 1.4).unwrap();
    m.set_param("pusher_friction.mu", mu).unwrap();
    m
}

/// A pushing model with a flat pusher `[yaw, half width, half thickness]`.
fn flat(pad: [f64; 3]) -> PhysicsModel {
    let mut m = PhysicsModel::pushing(&[Effect::FlatPusher]).unwrap();
    for (name, v) in ["yaw", "half_width", "half_thickness"].iter().zip(pad) {
        m.set_param(&format!("flat_pusher.{name}"), v).unwrap();
    }
    m
}

// a cornering car: 1.2 m/s, some slip, inside the grip patch edge, filtered throttle ≠ command
const CAR_S: [f64; 7] = [0.9, 0.1, 0.4, 1.2, 0.15, 2.0, 0.3];
const CAR_U: [f64; 2] = [0.2, 0.5];
// pushes: sliding (μ small), sticking (μ large)
const PUSH_S: [f64; 3] = [0.42, 0.01, 0.6];
const PUSH_U: [f64; 3] = [0.4, 0.5, 0.6];

/// Central-difference Jacobian of `g` at `z`.
fn fd_jac(g: impl Fn(&[f64]) -> Vec<f64>, z: &[f64], h: f64) -> Vec<Vec<f64>> {
    (0..z.len())
        .map(|k| {
            // relative steps: parameters span 1e-5 (I_z) to 1e2
            let hk = h * z[k].abs().max(1e-2);
            let mut p = z.to_vec();
            let mut m = z.to_vec();
            p[k] += hk;
            m[k] -= hk;
            let (gp, gm) = (g(&p), g(&m));
            gp.iter()
                .zip(&gm)
                .map(|(a, b)| (a - b) / (2.0 * hk))
                .collect()
        })
        .collect()
}

fn check_field_jacobians(model: &PhysicsModel, s: &[f64], u: &[f64]) {
    // the ellipse's weight inside its range [0, 1], so that central differences stay in it
    let mut model = model.clone();
    if model.param_index("ellipse").is_some() {
        model.set_param("ellipse", 0.8).unwrap();
    }
    let model = &model;
    let (ds, du, np) = (model.dim_s(), model.dim_u(), model.n_params());
    let nz = ds + du + np;
    let mut f = vec![0.0; ds];
    let mut j = vec![0.0; ds * nz];
    model.jacobian_full(
        s,
        u,
        &vec![true; model.effects().len()],
        true,
        &mut f,
        &mut j,
    );
    let z: Vec<f64> = s.iter().chain(u).chain(model.params()).copied().collect();
    let fd = fd_jac(
        |z| {
            let mut m = model.clone();
            // bounds are not the point here: set directly through a fresh vector
            m.set_params(&z[ds + du..]).unwrap();
            let mut out = vec![0.0; ds];
            m.eval_one(&z[..ds], &z[ds..ds + du], &mut out);
            out
        },
        &z,
        1e-6,
    );
    let names = model.param_names();
    for c in 0..nz {
        for r in 0..ds {
            let got = j[r * nz + c];
            let want = fd[c][r];
            let scale = want.abs().max(1.0);
            let what = if c < ds {
                format!("s{c}")
            } else if c < ds + du {
                format!("u{}", c - ds)
            } else {
                names[c - ds - du].clone()
            };
            assert!(
                (got - want).abs() < 1e-5 * scale,
                "{:?} ∂f{r}/∂{what}: exact {got} vs FD {want}",
                model.robot()
            );
        }
    }
    // the VectorField forms agree with the full Jacobian
    let ybar: Vec<f64> = (0..ds).map(|i| 0.3 + 0.1 * i as f64).collect();
    let mut tape = Default::default();
    let mut out = vec![0.0; ds];
    model.eval_taped(1, s, u, &mut out, &mut tape);
    let (mut sb, mut ub, mut pb) = (vec![0.0; ds], vec![0.0; du], vec![0.0; np]);
    model.vjp(&tape, &ybar, &mut sb, &mut ub, &mut pb);
    for c in 0..nz {
        let want: f64 = (0..ds).map(|r| ybar[r] * j[r * nz + c]).sum();
        let got = if c < ds {
            sb[c]
        } else if c < ds + du {
            ub[c - ds]
        } else {
            pb[c - ds - du]
        };
        assert!((got - want).abs() < 1e-12 * want.abs().max(1.0));
    }
    let sdot: Vec<f64> = (0..ds).map(|i| 1.0 - 0.2 * i as f64).collect();
    let udot: Vec<f64> = (0..du).map(|i| 0.5 + i as f64).collect();
    let mut od = vec![0.0; ds];
    model.jvp(1, s, u, &sdot, &udot, &mut out, &mut od);
    for r in 0..ds {
        let want: f64 = (0..ds).map(|c| j[r * nz + c] * sdot[c]).sum::<f64>()
            + (0..du).map(|c| j[r * nz + ds + c] * udot[c]).sum::<f64>();
        assert!((od[r] - want).abs() < 1e-12 * want.abs().max(1.0));
        assert_eq!(out[r], f[r]);
    }
}

#[test]
fn car_jacobians_wrt_state_input_and_parameters_match_finite_differences() {
    check_field_jacobians(&car_all(), &CAR_S, &CAR_U);
    // reversing, slow, and the nominal model alone
    check_field_jacobians(
        &car_all(),
        &[0.0, 0.0, -2.0, -0.4, 0.05, -0.3, -0.2],
        &[-0.1, -0.1],
    );
    check_field_jacobians(&PhysicsModel::car(&[]).unwrap(), &CAR_S[..6], &CAR_U);
}

#[test]
fn pushing_jacobians_match_finite_differences_sliding_and_sticking() {
    for m in [
        push_all(0.2),
        push_all(1.5),
        PhysicsModel::pushing(&[]).unwrap(),
    ] {
        // sliding on the cone edge, sticking, frictionless; both limit surfaces
        check_field_jacobians(&m, &PUSH_S, &PUSH_U);
        check_field_jacobians(&support_points(m), &PUSH_S, &PUSH_U);
    }
}

/// The model with the support points' limit surface.
fn support_points(mut m: PhysicsModel) -> PhysicsModel {
    m.set_limit_surface(LimitSurface::SupportPoints).unwrap();
    m
}

#[test]
fn effect_terms_and_their_jacobians_match_finite_differences() {
    for (model, s, u) in [
        (car_all(), CAR_S.to_vec(), CAR_U.to_vec()),
        (push_all(0.2), PUSH_S.to_vec(), PUSH_U.to_vec()),
        (push_all(1.5), PUSH_S.to_vec(), PUSH_U.to_vec()),
    ] {
        let (ds, du) = (model.dim_state(), model.dim_input());
        for e in model.effects() {
            let t = model.effect_term(e, &s, &u).unwrap();
            let range = model.effect_param_range(e).unwrap();
            let ne = range.len();
            let contrib = |s: &[f64], u: &[f64], q: &[f64]| {
                let mut m = model.clone();
                let mut p = m.params().to_vec();
                p[range.clone()].copy_from_slice(q);
                m.set_params(&p).unwrap();
                m.effect_term(e, s, u).unwrap().contribution
            };
            let q0 = model.params()[range.clone()].to_vec();
            let z: Vec<f64> = s.iter().chain(&u).chain(&q0).copied().collect();
            let fd = fd_jac(
                |z| contrib(&z[..ds], &z[ds..ds + du], &z[ds + du..]),
                &z,
                1e-7,
            );
            for r in 0..ds {
                for c in 0..ds + du + ne {
                    let got = if c < ds {
                        t.d_state[r * ds + c]
                    } else if c < ds + du {
                        t.d_input[r * du + c - ds]
                    } else {
                        t.d_params[r * ne + c - ds - du]
                    };
                    let want = fd[c][r];
                    assert!(
                        (got - want).abs() < 1e-5 * want.abs().max(1.0),
                        "{e}: ∂Δf{r}/∂z{c}: {got} vs {want}"
                    );
                }
            }
        }
    }
}

#[test]
fn aero_drag_is_minus_c_speed_times_body_velocity_over_mass_and_linear_in_c() {
    let mut m = PhysicsModel::car(&[Effect::AeroDrag]).unwrap();
    m.set_param("aero_drag.c", 0.01).unwrap();
    let s = [0.0, 0.0, 0.3, -1.5, 0.2, 0.4];
    let t = m.effect_term(Effect::AeroDrag, &s, &[0.1, 0.3]).unwrap();
    let mass = 0.041;
    let v = (1.5f64 * 1.5 + 0.2 * 0.2).sqrt();
    let want = [
        0.0,
        0.0,
        0.0,
        -0.01 * v * -1.5 / mass,
        -0.01 * v * 0.2 / mass,
        0.0,
    ];
    assert!(
        max_rel_diff(&t.contribution, &want) < 1e-9,
        "{:?}",
        t.contribution
    );
    assert!(Effect::AeroDrag.linear_in_params());
    m.set_param("aero_drag.c", 0.02).unwrap();
    let t2 = m.effect_term(Effect::AeroDrag, &s, &[0.1, 0.3]).unwrap();
    assert!((t2.contribution[3] - 2.0 * t.contribution[3]).abs() < 1e-12);
    assert!((t.d_params[3] - (-v * -1.5 / mass)).abs() < 1e-9);
}

/// Regression: `aero_drag` was `c·vx|vx|`, the same function as the nominal `C_r2·vx|vx|`, so a
/// fit that freed `C_r2` absorbed it and adding the effect changed nothing. `C_r2` is now fixed
/// by default and the effect acts on the whole body velocity, as the simulator's drag does.
#[test]
fn aero_drag_duplicated_nominal_drag() {
    let m = PhysicsModel::car(&[Effect::AeroDrag]).unwrap();
    let free = m.default_free();
    let names = m.param_names();
    let free_names: Vec<&str> = names
        .iter()
        .zip(&free)
        .filter(|(_, f)| **f)
        .map(|(n, _)| n.as_str())
        .collect();
    assert!(!free_names.contains(&"Cr2"), "{free_names:?}");
    assert!(free_names.contains(&"aero_drag.c"), "{free_names:?}");
    // the effect moves vy too, which no nominal drag term does
    let mut m = m;
    m.set_param("aero_drag.c", 0.01).unwrap();
    let t = m
        .effect_term(
            Effect::AeroDrag,
            &[0.0, 0.0, 0.0, 1.0, 0.3, 0.0],
            &[0.0, 0.2],
        )
        .unwrap();
    assert!(t.contribution[4] < -1e-3, "{:?}", t.contribution);
}

/// Regression: the car fit freed every nominal parameter, and the mass (which scales every
/// force) came out as 0.040 ± 0.28 kg. Measured quantities stay fixed by default.
#[test]
fn car_fit_freed_non_identifiable_mass() {
    let m = PhysicsModel::car(&[]).unwrap();
    let free = m.default_free();
    for (name, f) in m.param_names().iter().zip(&free) {
        let held = ["m", "Iz", "lf", "lr", "Cr2", "v_reg", "Cf", "Cr", "ellipse"];
        assert_eq!(*f, !held.contains(&name.as_str()), "{name}");
    }
    // the friction ellipse's weight is fitted with a grip patch, which it shapes
    let patch = PhysicsModel::car(&[Effect::GripPatch]).unwrap();
    let i = patch.param_index("ellipse").unwrap();
    assert!(patch.default_free()[i]);
    // and with a custom effect's grip term (a low-grip strip), not with another term
    let custom = |state: &str, feature: &str| {
        let mut m = PhysicsModel::car(&[]).unwrap();
        let toml = format!(
            "name = \"c\"\n[[term]]\nstate = \"{state}\"\nfeature = \"{feature}\"\ncoefficient = -0.5\n"
        );
        m.add_custom(CustomEffect::from_toml(&toml).unwrap())
            .unwrap();
        m.default_free()[i]
    };
    assert!(custom("grip", "strip(0.5,0.26,0.8)"));
    assert!(!custom("omega", "delta*vx"));
    let p = PhysicsModel::pushing(&[]).unwrap();
    let pf = p.default_free();
    // a, c, L, kappa, b: the geometry and the push length are measured, c and κ fitted
    assert_eq!(pf, vec![false, true, false, true, false]);
}

/// The rear axle saturates on the friction circle like the simulator's: at full throttle the
/// drive force is capped at the rear peak force `D_r`.
#[test]
fn rear_friction_ellipse_caps_the_drive_force() {
    let m = PhysicsModel::car(&[]).unwrap();
    let mut f = [0.0; 6];
    // standing start at full throttle: C_m1 = 0.287 N asked, D_r = 0.1737 N available
    m.eval_one(&[0.0, 0.0, 0.0, 0.0, 0.0, 0.0], &[0.0, 1.0], &mut f);
    let a = f[3] * 0.041;
    assert!((a - 0.1737).abs() < 2e-3, "drive force {a}");
    // gentle throttle is unchanged: 0.1·C_m1
    m.eval_one(&[0.0, 0.0, 0.0, 0.0, 0.0, 0.0], &[0.0, 0.1], &mut f);
    assert!((f[3] * 0.041 - 0.0287).abs() < 1e-4, "{}", f[3] * 0.041);
}

/// The ellipse's weight: 0 leaves the drive force and the rear lateral force independent
/// (Liniger's model), ½ takes half of what the full ellipse takes; inside the circle it changes
/// nothing.
#[test]
fn the_friction_ellipse_weight_blends_the_coupling() {
    let mut m = PhysicsModel::car(&[]).unwrap();
    // sliding sideways at full throttle: both rear forces near their peaks
    let (s, u) = ([0.0, 0.0, 0.0, 1.0, -0.3, 0.0], [0.0, 1.0]);
    let mut rates = Vec::new();
    for e in [1.0, 0.5, 0.0] {
        m.set_param("ellipse", e).unwrap();
        let mut f = [0.0; 6];
        m.eval_one(&s, &u, &mut f);
        rates.push(f);
    }
    let [full, half, none] = [rates[0], rates[1], rates[2]];
    // without the ellipse the drive force is (C_m1 − C_m2·vx)·1 − C_r0 − C_r2 (vy·ω = 0)
    let drive = 0.287 - 0.0545 - 0.0518 * (1.0f64 / 0.05).tanh() - 0.00035;
    assert!(
        (none[3] * 0.041 - drive).abs() < 1e-9,
        "{}",
        none[3] * 0.041
    );
    assert!(
        full[3] < half[3] && half[3] < none[3],
        "{full:?} {half:?} {none:?}"
    );
    for i in [3, 4, 5] {
        assert!(
            ((full[i] + none[i]) / 2.0 - half[i]).abs() < 1e-10,
            "row {i}"
        );
    }
    // gentle throttle, no slip: inside the circle the weight does not matter
    let mut f = [[0.0; 6]; 2];
    for (e, out) in [1.0, 0.0].into_iter().zip(&mut f) {
        m.set_param("ellipse", e).unwrap();
        m.eval_one(&[0.0, 0.0, 0.0, 1.0, 0.0, 0.0], &[0.0, 0.1], out);
    }
    assert!((f[0][3] - f[1][3]).abs() < 1e-5 * f[1][3].abs(), "{f:?}");
    assert!(m.set_param("ellipse", 1.5).is_err());
}

#[test]
fn table_tilt_deflects_a_push_downhill_and_holds_a_block_at_rest() {
    // a central push along +x at θ = 0 on a table tilted towards ±y
    let s = [0.5, 0.0, 0.0];
    let u = [0.0, 0.0, 0.5];
    let mut f = [0.0; 3];
    let nominal = PhysicsModel::pushing(&[]).unwrap();
    nominal.eval_one(&s, &u, &mut f);
    let vx = f[0];
    assert!(vx > 0.0 && f[1].abs() < 1e-15 && f[2].abs() < 1e-15);
    let mut m = PhysicsModel::pushing(&[Effect::TableTilt]).unwrap();
    for gy in [0.2, -0.2] {
        m.set_param("table_tilt.gy", gy).unwrap();
        m.eval_one(&s, &u, &mut f);
        // the pusher sets the normal velocity; the tilt adds a downhill drift
        assert!((f[0] - vx).abs() < 1e-9, "{f:?}");
        assert!(f[1] * gy > 0.0 && f[1].abs() > 0.1 * vx, "{f:?}");
    }
    // no push: the tilt (below the friction angle) does not move the block
    m.eval_one(&s, &[0.0, 0.0, 0.0], &mut f);
    assert_eq!(f, [0.0; 3]);
}

/// The slope's pull is the same all over a tilted table, the friction that holds a block is not:
/// a block wholly on a patch of half the friction drifts as on a table twice as steep (off a
/// tilt the patch changes nothing).
#[test]
fn a_block_on_a_patch_of_less_friction_drifts_further_down_a_tilted_table() {
    let s = [0.5, 0.0, 0.3];
    let u = [0.2, 0.1, 0.5];
    let mut on_patch = PhysicsModel::pushing(&[Effect::TableTilt, Effect::FrictionPatch]).unwrap();
    for (k, v) in [
        ("cx", 0.5),
        ("cy", 0.0),
        ("r", 0.3),
        ("w", 0.005),
        ("k", 0.5),
    ] {
        on_patch
            .set_param(&format!("friction_patch.{k}"), v)
            .unwrap();
    }
    let mut steep = PhysicsModel::pushing(&[Effect::TableTilt]).unwrap();
    let mut level = [0.0; 3];
    PhysicsModel::pushing(&[])
        .unwrap()
        .eval_one(&s, &u, &mut level);
    for (gx, gy) in [(0.0, 0.1), (-0.08, 0.05)] {
        on_patch.set_param("table_tilt.gx", gx).unwrap();
        on_patch.set_param("table_tilt.gy", gy).unwrap();
        steep.set_param("table_tilt.gx", 2.0 * gx).unwrap();
        steep.set_param("table_tilt.gy", 2.0 * gy).unwrap();
        let (mut f, mut g) = ([0.0; 3], [0.0; 3]);
        on_patch.eval_one(&s, &u, &mut f);
        steep.eval_one(&s, &u, &mut g);
        for i in 0..3 {
            assert!(
                (f[i] - g[i]).abs() < 1e-6 * (1.0 + g[i].abs()),
                "{f:?} {g:?}"
            );
            assert!((f[i] - level[i]).abs() > 1e-4 || i == 0, "{f:?} {level:?}");
        }
    }
    on_patch.set_param("table_tilt.gx", 0.0).unwrap();
    on_patch.set_param("table_tilt.gy", 0.0).unwrap();
    let mut f = [0.0; 3];
    on_patch.eval_one(&s, &u, &mut f);
    for i in 0..3 {
        assert!((f[i] - level[i]).abs() < 1e-6, "{f:?} {level:?}");
    }
}

#[test]
fn a_flat_pusher_is_the_same_pad_turned_by_pi_or_a_quarter_with_its_sides_swapped() {
    let solver = Solver::Rk4 { substeps: 4 };
    let step = |m: &PhysicsModel, s: &[f64], u: &[f64]| {
        let mut o = [0.0; 3];
        m.integrate_step(&solver, 1, s, u, 1.0, &mut o);
        o
    };
    let pad = [-0.2, 0.015, 0.008];
    let (pi, half) = (std::f64::consts::PI, std::f64::consts::FRAC_PI_2);
    let same = [
        flat([pad[0] + pi, pad[1], pad[2]]),
        flat([pad[0] - half, pad[2], pad[1]]),
        flat([pad[0] + half, pad[2], pad[1]]),
    ];
    let disc = PhysicsModel::pushing(&[]).unwrap();
    let mut turned = 0.0f64;
    // on both sides of alignment (θ = −0.2) too
    for th in [-0.6, -0.21, -0.19, 0.1, 0.5, 1.2] {
        for u in [[0.0, 0.0, 0.8], [0.6, 0.3, 0.5], [-0.7, -0.4, 1.0]] {
            let s = [0.4, 0.02, th];
            let want = step(&flat(pad), &s, &u);
            for m in &same {
                let got = step(m, &s, &u);
                for k in 0..3 {
                    assert!(
                        (got[k] - want[k]).abs() < 1e-9,
                        "θ {th}, u {u:?}: {got:?} vs {want:?}"
                    );
                }
            }
            turned = turned.max((want[2] - step(&disc, &s, &u)[2]).abs());
        }
    }
    // and not the disc: the corner turns the block
    assert!(
        turned > 0.02,
        "largest heading difference to the disc {turned}"
    );
    // the canonical form: the larger side is the width, the yaw in (−π/2, π/2]
    let (mut v, mut sd) = ([pad[0] - half + 2.0 * pi, pad[2], pad[1]], [0.1, 0.2, 0.3]);
    Effect::FlatPusher.canonical(&mut v, &mut sd);
    assert!((v[0] - pad[0]).abs() < 1e-12 && v[1..] == pad[1..], "{v:?}");
    assert_eq!(sd, [0.1, 0.3, 0.2]);
    let mut m = flat([pad[0] + pi, pad[2], pad[1]]);
    let mut p = m.params().to_vec();
    m.canonical(&mut p, &mut []);
    m.set_params(&p).unwrap();
    let get = |name: &str| m.params()[m.param_index(name).unwrap()];
    assert!((get("flat_pusher.yaw") - (pad[0] + half)).abs() < 1e-12);
    assert_eq!(get("flat_pusher.half_width"), pad[1]);
}

#[test]
fn push_step_derivatives_match_finite_differences() {
    use dynlab_dynamics::physics::StepTape;
    let solver = Solver::Rk4 { substeps: 2 };
    for m in [
        PhysicsModel::pushing(&[]).unwrap(),
        push_all(0.2),
        push_all(1.5),
        support_points(push_all(0.2)),
        support_points(push_all(1.5)),
        // the pad turned 0.3 rad against the face
        flat([0.3, 0.015, 0.01]),
    ] {
        let np = m.params().len();
        let step = |m: &PhysicsModel, s: &[f64], u: &[f64]| {
            let mut o = [0.0; 3];
            m.integrate_step(&solver, 1, s, u, 1.0, &mut o);
            o.to_vec()
        };
        let z: Vec<f64> = PUSH_S.iter().chain(&PUSH_U).copied().collect();
        let fd = fd_jac(|z| step(&m, &z[..3], &z[3..]), &z, 1e-7);
        let (mut out, mut js, mut ju) = ([0.0; 3], [0.0; 9], [0.0; 9]);
        m.step_jacobians(
            &solver, 1, &PUSH_S, &PUSH_U, 1.0, &mut out, &mut js, &mut ju,
        );
        assert_eq!(out.to_vec(), step(&m, &PUSH_S, &PUSH_U));
        // reverse mode, one output at a time
        let mut tape = StepTape::default();
        let mut o = [0.0; 3];
        m.integrate_step_taped(&solver, 1, &PUSH_S, &PUSH_U, 1.0, &mut o, &mut tape);
        let theta = m.params().to_vec();
        let fdp = fd_jac(
            |q| {
                let mut mm = m.clone();
                mm.set_params(q).unwrap();
                step(&mm, &PUSH_S, &PUSH_U)
            },
            &theta,
            1e-7,
        );
        for r in 0..3 {
            let mut ybar = [0.0; 3];
            ybar[r] = 1.0;
            let (mut sb, mut ub, mut pb) = ([0.0; 3], [0.0; 3], vec![0.0; np]);
            m.integrate_step_vjp(&tape, &ybar, &mut sb, &mut ub, &mut pb);
            for c in 0..6 {
                let want = fd[c][r];
                let fwd = if c < 3 {
                    js[r * 3 + c]
                } else {
                    ju[r * 3 + c - 3]
                };
                let rev = if c < 3 { sb[c] } else { ub[c - 3] };
                let tol = 1e-5 * want.abs().max(1.0);
                assert!((fwd - want).abs() < tol, "d{r}/dz{c}: {fwd} vs {want}");
                assert!((rev - want).abs() < tol, "d{r}/dz{c}: {rev} vs {want}");
            }
            for c in 0..np {
                let want = fdp[c][r];
                let tol = 1e-5 * want.abs().max(1.0);
                assert!(
                    (pb[c] - want).abs() < tol,
                    "d{r}/dθ{c}: {} vs {want}",
                    pb[c]
                );
            }
        }
    }
}

#[test]
fn steering_offset_is_the_same_as_turning_the_wheels_further() {
    let mut m = PhysicsModel::car(&[Effect::SteeringOffset]).unwrap();
    m.set_param("steering_offset.delta0", 0.05).unwrap();
    let nominal = PhysicsModel::car(&[]).unwrap();
    let s = &CAR_S[..6];
    let (mut a, mut b) = ([0.0; 6], [0.0; 6]);
    m.eval_one(s, &[0.1, 0.4], &mut a);
    nominal.eval_one(s, &[0.15, 0.4], &mut b);
    assert!(max_rel_diff(&a, &b) < 1e-14);
}

#[test]
fn car_drives_straight_accelerates_and_stands_still_sensibly() {
    let car = PhysicsModel::car(&[]).unwrap();
    let mut f = [0.0; 6];
    // straight at 1 m/s with throttle: no lateral motion, forward acceleration = F_rx/m
    car.eval_one(&[0.0, 0.0, 0.0, 1.0, 0.0, 0.0], &[0.0, 0.5], &mut f);
    let frx = (0.287 - 0.0545) * 0.5 - 0.0518 * (1.0f64 / 0.05).tanh() - 0.00035;
    // (the smooth friction ellipse is 1 − 10⁻⁶ inside the circle)
    assert!((f[3] - frx / 0.041).abs() < 1e-5 * (frx / 0.041).abs());
    assert_eq!((f[4], f[5]), (0.0, 0.0));
    // a standing car with the wheels turned and no throttle does not move
    car.eval_one(&[0.0, 0.0, 0.7, 0.0, 0.0, 0.0], &[0.3, 0.0], &mut f);
    assert!(f.iter().all(|v| v.abs() < 1e-15), "{f:?}");
    // steering left at speed turns left (positive yaw acceleration)
    car.eval_one(&[0.0, 0.0, 0.0, 1.5, 0.0, 0.0], &[0.2, 0.0], &mut f);
    assert!(f[5] > 0.0 && f[4] > 0.0);
    // far above v_reg the slip angles are Liniger's: compare the front lateral force
    let (vx, vy, om, delta) = (2.0, 0.1, 0.5, 0.1);
    car.eval_one(&[0.0, 0.0, 0.0, vx, vy, om], &[delta, 0.0], &mut f);
    let af = delta - ((om * 0.029 + vy) / vx).atan();
    let ar = ((om * 0.033 - vy) / vx).atan();
    let ffy = 0.192 * (1.2 * (2.579 * af).atan()).sin();
    let fry = 0.1737 * (1.2691 * (3.3852 * ar).atan()).sin();
    let omd = (ffy * 0.029 * delta.cos() - fry * 0.033) / 27.8e-6;
    assert!(
        (f[5] - omd).abs() < 2e-3 * omd.abs(),
        "{} vs Liniger {omd}",
        f[5]
    );
}

#[test]
fn a_central_frictionless_push_translates_the_block_by_the_push_length() {
    let m = PhysicsModel::pushing(&[]).unwrap();
    let th = 0.3;
    let mut out = [0.0; 3];
    let rep = integrate(
        &m,
        &Solver::rk4(),
        1,
        &[0.4, 0.0, th],
        &[0.0, 0.0, 0.7],
        1.0,
        &mut out,
    );
    assert!(rep.is_success());
    let d = 0.7 * 0.1;
    assert!((out[0] - (0.4 + d * th.cos())).abs() < 1e-12);
    assert!((out[1] - d * th.sin()).abs() < 1e-12);
    assert!((out[2] - th).abs() < 1e-12);
    // off-centre towards +y along the pushed face turns the block clockwise; no push no motion
    let mut f = [0.0; 3];
    m.eval_one(&[0.0, 0.0, 0.0], &[0.8, 0.0, 0.5], &mut f);
    assert!(f[2] < 0.0);
    m.eval_one(&[0.0, 0.0, 0.0], &[0.8, 0.3, 0.0], &mut f);
    assert_eq!(f, [0.0; 3]);
}

#[test]
fn a_sticking_pusher_moves_the_contact_point_with_the_pusher() {
    // with high friction, the block's contact point velocity equals the pusher velocity
    let mut m = PhysicsModel::pushing(&[Effect::PusherFriction]).unwrap();
    m.set_param("pusher_friction.mu", 2.0).unwrap();
    let (p, phi, ell) = (0.3, 0.25, 0.5);
    let mut f = [0.0; 3];
    m.eval_one(&[0.0, 0.0, 0.0], &[p, phi, ell], &mut f);
    let (px, py) = (-0.05, 0.95 * p * 0.05);
    let vc = [f[0] - f[2] * py, f[1] + f[2] * px];
    let vp = [ell * 0.1 * phi.cos(), ell * 0.1 * phi.sin()];
    assert!(max_rel_diff(&vc, &vp) < 1e-12, "{vc:?} vs {vp:?}");
    // without friction the same push only transmits its normal component
    let m0 = PhysicsModel::pushing(&[]).unwrap();
    m0.eval_one(&[0.0, 0.0, 0.0], &[p, phi, ell], &mut f);
    let vc0 = f[0] - f[2] * py;
    assert!((vc0 - vp[0]).abs() < 1e-12);
}

#[test]
fn motor_lag_filter_matches_the_integrated_extra_state() {
    let mut m = PhysicsModel::car(&[Effect::MotorLag]).unwrap();
    m.set_param("motor_lag.tau", 0.08).unwrap();
    let dt = 0.02;
    let throttle = [0.2, 0.9, 0.9, -0.1, 0.4];
    let filt = PhysicsModel::motor_lag_filter(&throttle, dt, 0.08, 0.0);
    let mut s = vec![0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0];
    for (k, &d) in throttle.iter().enumerate() {
        assert!(
            (s[6] - filt[k]).abs() < 1e-9,
            "step {k}: {} vs {}",
            s[6],
            filt[k]
        );
        let mut next = vec![0.0; 7];
        integrate(
            &m,
            &Solver::dopri5(1e-11, 1e-13),
            1,
            &s,
            &[0.0, d],
            dt,
            &mut next,
        );
        s = next;
    }
}

#[test]
fn step_jacobians_of_the_car_match_finite_differences() {
    let m = car_all();
    let solver = Solver::Rk4 { substeps: 2 };
    let (mut out, mut js, mut ju) = (vec![0.0; 7], vec![0.0; 49], vec![0.0; 14]);
    step_jacobians(
        &m, &solver, 1, &CAR_S, &CAR_U, 0.02, &mut out, &mut js, &mut ju,
    );
    let z: Vec<f64> = CAR_S.iter().chain(&CAR_U).copied().collect();
    let fd = fd_jac(
        |z| {
            let mut o = vec![0.0; 7];
            integrate(&m, &solver, 1, &z[..7], &z[7..], 0.02, &mut o);
            o
        },
        &z,
        1e-7,
    );
    for r in 0..7 {
        for c in 0..9 {
            let got = if c < 7 {
                js[r * 7 + c]
            } else {
                ju[r * 2 + c - 7]
            };
            assert!(
                (got - fd[c][r]).abs() < 1e-6 * fd[c][r].abs().max(1.0),
                "∂s{r}/∂z{c}: {got} vs {}",
                fd[c][r]
            );
        }
    }
}

#[test]
fn reverse_passes_through_one_tape_equal_those_through_a_fresh_tape() {
    // a taped step keeps the field's Jacobians from its first reverse pass for the next ones:
    // every pass (with or without θ, in either order, and after the tape records a new point)
    // gives bit for bit what a pass through a tape of its own gives
    let solver = Solver::Rk4 { substeps: 2 };
    for m in [car_all(), push_all(0.2)] {
        let (ds, du, np) = (m.dim_state(), m.dim_input(), m.params().len());
        let points: Vec<(Vec<f64>, Vec<f64>)> = if ds == 3 {
            let s2 = [PUSH_S[0] - 0.05, PUSH_S[1] + 0.02, PUSH_S[2] - 0.3];
            vec![
                (PUSH_S.to_vec(), PUSH_U.to_vec()),
                (s2.to_vec(), PUSH_U.to_vec()),
            ]
        } else {
            let mut s2 = CAR_S.to_vec();
            s2[3] = 0.6;
            s2[5] = -1.0;
            vec![(CAR_S.to_vec(), CAR_U.to_vec()), (s2, vec![-0.1, 0.3])]
        };
        let dt = if ds == 3 { 1.0 } else { 0.02 };
        let pass = |tape: &StepTape, r: usize, with_p: bool| {
            let mut ybar = vec![0.0; ds];
            ybar[r] = 1.0;
            let (mut sb, mut ub) = (vec![0.0; ds], vec![0.0; du]);
            let mut pb = vec![0.0; if with_p { np } else { 0 }];
            m.integrate_step_vjp(tape, &ybar, &mut sb, &mut ub, &mut pb);
            [sb, ub, pb].concat()
        };
        let mut reused = StepTape::default();
        let mut out = vec![0.0; ds];
        for (s, u) in &points {
            m.integrate_step_taped(&solver, 1, s, u, dt, &mut out, &mut reused);
            for (r, with_p) in [(0, false), (1, true), (2, false), (0, true), (1, false)] {
                let mut fresh = StepTape::default();
                m.integrate_step_taped(&solver, 1, s, u, dt, &mut out, &mut fresh);
                assert_eq!(
                    pass(&reused, r, with_p),
                    pass(&fresh, r, with_p),
                    "row {r}, θ {with_p}"
                );
            }
        }
    }
}

#[test]
fn residual_jacobian_matches_finite_differences_and_vanishes_at_the_truth() {
    let mut truth = PhysicsModel::car(&[Effect::AeroDrag, Effect::SteeringOffset]).unwrap();
    truth.set_param("aero_drag.c", 0.1).unwrap();
    truth.set_param("steering_offset.delta0", 0.02).unwrap();
    let solver = Solver::Rk4 { substeps: 2 };
    let mut transitions = Vec::new();
    for k in 0..4 {
        let s0 = vec![
            0.1 * k as f64,
            -0.2,
            3.0 + 0.3 * k as f64,
            1.0 + 0.2 * k as f64,
            0.05,
            0.5 - 0.2 * k as f64,
        ];
        let u = vec![0.1 - 0.05 * k as f64, 0.4];
        let mut s1 = vec![0.0; 6];
        integrate(&truth, &solver, 1, &s0, &u, 0.02, &mut s1);
        transitions.push(Transition {
            s0,
            u,
            s1,
            dt: 0.02,
        });
    }
    let w = [1.0, 1.0, 0.5, 0.2, 0.2, 0.1];
    let rj = residuals_and_jacobian(&truth, &solver, &transitions, &w).unwrap();
    assert!(rj.residuals.iter().all(|r| r.abs() < 1e-15));
    assert!(rj.failed.is_empty());
    let mut model = PhysicsModel::car(&[Effect::AeroDrag, Effect::SteeringOffset]).unwrap();
    model.set_param("aero_drag.c", 0.03).unwrap();
    model.set_param("ellipse", 0.8).unwrap();
    let rj = residuals_and_jacobian(&model, &solver, &transitions, &w).unwrap();
    let np = rj.cols;
    assert_eq!(np, model.params().len());
    assert!(rj.residuals.iter().any(|r| r.abs() > 1e-6));
    let fd = fd_jac(
        |p| {
            let mut m = model.clone();
            m.set_params(p).unwrap();
            residuals(&m, &solver, &transitions, &w).unwrap().0
        },
        model.params(),
        1e-6,
    );
    for r in 0..rj.residuals.len() {
        for c in 0..np {
            let got = rj.jacobian[r * np + c];
            assert!(
                (got - fd[c][r]).abs() < 1e-5 * fd[c][r].abs().max(1e-3) + 1e-7,
                "row {r} col {c}: {got} vs {}",
                fd[c][r]
            );
        }
    }
    // one Gauss–Newton step on c and δ₀ alone lands near the truth
    let cols = [
        model.param_index("aero_drag.c").unwrap(),
        model.param_index("steering_offset.delta0").unwrap(),
    ];
    let (mut a, mut b) = ([[0.0; 2]; 2], [0.0; 2]);
    for r in 0..rj.residuals.len() {
        for i in 0..2 {
            b[i] -= rj.jacobian[r * np + cols[i]] * rj.residuals[r];
            for j in 0..2 {
                a[i][j] += rj.jacobian[r * np + cols[i]] * rj.jacobian[r * np + cols[j]];
            }
        }
    }
    let det = a[0][0] * a[1][1] - a[0][1] * a[1][0];
    let dc = (b[0] * a[1][1] - a[0][1] * b[1]) / det;
    let dd = (a[0][0] * b[1] - a[1][0] * b[0]) / det;
    assert!((0.03 + dc - 0.1).abs() < 5e-3, "c → {}", 0.03 + dc);
    assert!((0.0 + dd - 0.02).abs() < 1e-3, "δ₀ → {}", dd);
}

#[test]
fn equations_print_fitted_effects_with_uncertainty() {
    let mut m = PhysicsModel::car(&[Effect::AeroDrag, Effect::MotorLag]).unwrap();
    m.set_param("aero_drag.c", 0.0123).unwrap();
    let mut se = vec![0.0; m.params().len()];
    se[m.param_index("aero_drag.c").unwrap()] = 0.0008;
    m.set_std_errors(Some(se)).unwrap();
    let text = m.to_string();
    assert!(text.contains("− 0.01230·|v|·vx/m"), "{text}");
    assert!(
        text.contains("(aero_drag c = 0.01230 ± 0.0008000 N·s²/m²)"),
        "{text}"
    );
    assert!(text.contains("ḋ_f = (d − d_f)/0.05000"), "{text}");
    assert!(text.contains("m = 0.04100 kg"), "{text}");
    let p = push_all(0.3).to_string();
    assert!(p.contains("pusher_friction μ_p = 0.3000 -"), "{p}");
}

#[test]
fn bad_model_configurations_get_clear_errors() {
    let e = PhysicsModel::car(&[Effect::ComOffset]).unwrap_err();
    assert!(
        e.to_string()
            .contains("aero_drag, motor_lag, steering_offset, grip_patch"),
        "{e}"
    );
    let e = PhysicsModel::car(&[Effect::AeroDrag, Effect::AeroDrag]).unwrap_err();
    assert_eq!(e, ModelError::DuplicateEffect(Effect::AeroDrag));
    let e = PhysicsModel::parse_effects(&["aero_dreg"]).unwrap_err();
    assert!(e.to_string().contains("unknown effect 'aero_dreg'"), "{e}");
    let mut m = PhysicsModel::car(&[Effect::AeroDrag]).unwrap();
    let e = m.set_param("steering_lag.rate", 3.0).unwrap_err();
    let msg = e.to_string();
    assert!(
        msg.starts_with("unknown parameter 'steering_lag.rate'"),
        "{e}"
    );
    assert!(
        msg.contains("aero_drag.c") && msg.contains("effect added"),
        "{e}"
    );
    let e = m.set_param("aero_drag.c", f64::NAN).unwrap_err();
    assert!(matches!(e, ModelError::ParamOutOfBounds { .. }), "{e}");
    let e = m.set_params(&[1.0]).unwrap_err();
    assert!(e.to_string().contains("expected 17 parameters"), "{e}");
    let e = m
        .effect_term(Effect::MotorLag, &CAR_S[..6], &CAR_U)
        .unwrap_err();
    assert_eq!(e, ModelError::NotEnabled(Effect::MotorLag));
    let e = m.effect_term(Effect::AeroDrag, &CAR_S, &CAR_U).unwrap_err();
    assert!(matches!(
        e,
        ModelError::Dimension {
            what: "state",
            expected: 6,
            got: 7
        }
    ));
}

/// A custom term on the steering angle `δ` acts where the steering does: `δ += c·δ·vₓ²` on the
/// car gives the field of the model without it at the steering command `(1 + c·vₓ²)·δ`, through
/// the servo's lag when the model has one; its Jacobians (the coefficient's included) match
/// finite differences.
#[test]
fn a_steering_angle_term_is_a_change_of_the_steering_the_tires_see() {
    let c = -0.16;
    let term = CustomEffect::from_toml(&format!(
        "name = \"gain\"\n[[term]]\nstate = \"delta\"\nfeature = \"delta*vx*vx\"\ncoefficient = {c}\n"
    ))
    .unwrap();
    let plain = PhysicsModel::car(&[]).unwrap();
    let mut with = plain.clone();
    with.add_custom(term.clone()).unwrap();
    let (s, u) = (&CAR_S[..6], CAR_U);
    let mut want = vec![0.0; 6];
    plain.eval_one(s, &[(1.0 + c * s[3] * s[3]) * u[0], u[1]], &mut want);
    let mut got = vec![0.0; 6];
    with.eval_one(s, &u, &mut got);
    assert!(max_rel_diff(&got, &want) < 1e-12, "{got:?} vs {want:?}");
    assert!(
        (got[5] - {
            let mut f = vec![0.0; 6];
            plain.eval_one(s, &u, &mut f);
            f[5]
        })
        .abs()
            > 1e-3,
        "the term changes ω̇"
    );
    check_field_jacobians(&with, s, &u);
    // with the servo's lag the term corrects the servo's output (an effect state)
    let mut lagged = PhysicsModel::car(&[Effect::SteeringLag]).unwrap();
    lagged.set_param("steering_lag.rate", 5.0).unwrap();
    lagged.add_custom(term).unwrap();
    let mut sl = s.to_vec();
    sl.resize(lagged.dim_state(), 0.1);
    check_field_jacobians(&lagged, &sl, &u);
}

#[test]
fn a_grip_term_scales_the_tires_peak_forces() {
    // on `1`: both axles' peak forces scaled by 1 + θ, everywhere
    let c = -0.3;
    let global = CustomEffect::from_toml(&format!(
        "name = \"grip\"\n[[term]]\nstate = \"grip\"\nfeature = \"1\"\ncoefficient = {c}\n"
    ))
    .unwrap();
    let plain = PhysicsModel::car(&[]).unwrap();
    let mut with = plain.clone();
    with.add_custom(global).unwrap();
    let mut scaled = plain.clone();
    for name in ["Df", "Dr"] {
        let v = scaled.params()[scaled.param_index(name).unwrap()];
        scaled.set_param(name, (1.0 + c) * v).unwrap();
    }
    let (s, u) = (&CAR_S[..6], CAR_U);
    let (mut got, mut want, mut before) = (vec![0.0; 6], vec![0.0; 6], vec![0.0; 6]);
    with.eval_one(s, &u, &mut got);
    scaled.eval_one(s, &u, &mut want);
    plain.eval_one(s, &u, &mut before);
    assert!(max_rel_diff(&got, &want) < 1e-12, "{got:?} vs {want:?}");
    assert!((got[4] - before[4]).abs() > 1e-3, "the term changes v̇_y");
    check_field_jacobians(&with, s, &u);
    // on a bump: the full change at its centre, none far from it
    let bump = CustomEffect::from_toml(&format!(
        "name = \"region\"\n[[term]]\nstate = \"grip\"\nfeature = \"gauss({},{},0.3)\"\ncoefficient = {c}\n",
        s[0], s[1]
    ))
    .unwrap();
    let mut region = plain.clone();
    region.add_custom(bump).unwrap();
    region.eval_one(s, &u, &mut got);
    assert!(
        max_rel_diff(&got, &want) < 1e-12,
        "at the centre: {got:?} vs {want:?}"
    );
    let mut far = s.to_vec();
    far[0] += 5.0;
    region.eval_one(&far, &u, &mut got);
    plain.eval_one(&far, &u, &mut want);
    assert!(
        max_rel_diff(&got, &want) < 1e-9,
        "far away: {got:?} vs {want:?}"
    );
    check_field_jacobians(&region, s, &u);
}

#[test]
fn a_table_friction_term_turns_a_block_that_straddles_its_edge_and_no_other() {
    let strip = |d: f64, w: f64, c: f64| {
        CustomEffect::from_toml(&format!(
            "name = \"stripe\"\n[[term]]\nstate = \"friction\"\nfeature = \"strip(0,{d},{w})\"\ncoefficient = {c}\n"
        ))
        .unwrap()
    };
    // a central push along the block's x at heading 0: no turn on a uniform table
    let (s, u) = ([0.3, 0.1, 0.0], [0.0, 0.0, 0.7]);
    for surface in [LimitSurface::Ellipsoid, LimitSurface::SupportPoints] {
        let mut plain = PhysicsModel::pushing(&[]).unwrap();
        plain.set_limit_surface(surface).unwrap();
        let (mut f0, mut f) = ([0.0; 3], [0.0; 3]);
        plain.eval_one(&s, &u, &mut f0);
        assert!(f0[2].abs() < 1e-9, "{surface}: {f0:?}");
        // 2.5 times the friction over the block's +y half (the stripe y ∈ [0.1, 1.1]): the
        // centre of friction moves to +y, the push passes on its −y side, the block turns
        // towards +y (counter-clockwise)
        let mut half = plain.clone();
        half.add_custom(strip(0.6, 1.0, 1.5)).unwrap();
        half.eval_one(&s, &u, &mut f);
        assert!(f[2] > 0.05, "{surface}: θ̇ {} on the stripe's edge", f[2]);
        check_field_jacobians(&half, &s, &u);
        // all of the footprint on the stripe, or none of it: the motion of the uniform table
        for d in [0.1, 3.0] {
            let mut on = plain.clone();
            on.add_custom(strip(d, 1.0, 1.5)).unwrap();
            on.eval_one(&s, &u, &mut f);
            assert!(
                max_rel_diff(&f, &f0) < 1e-9,
                "{surface} d {d}: {f:?} vs {f0:?}"
            );
        }
    }
    // the friction is a property of the place: features of the motion are refused, and a
    // region's coefficient keeps the friction positive
    let file = |feature: &str, c: f64| {
        format!(
            "name = \"t\"\n[[term]]\nstate = \"friction\"\nfeature = \"{feature}\"\ncoefficient = {c}\n"
        )
    };
    let e = CustomEffect::from_toml(&file("l*x", 0.5)).unwrap_err();
    assert!(matches!(e, CustomError::NotAField { .. }), "{e}");
    assert!(e.to_string().contains("position alone"), "{e}");
    assert!(CustomEffect::from_toml(&file("strip(0,0.1,0.2)", -1.2)).is_err());
    let ok = CustomEffect::from_toml(&file("x", -3.0)).unwrap();
    assert_eq!(ok.terms()[0].target, Target::Friction);
    assert!(Target::Friction.searched_with(&Feature::parse("strip(0,0.1,0.2)").unwrap()));
    assert!(!Target::Friction.searched_with(&Feature::parse("x").unwrap()));
    assert!(!Target::Friction.searched_with(&Feature::parse("1").unwrap()));
}
