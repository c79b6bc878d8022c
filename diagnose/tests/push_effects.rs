//! The pushing world (issue 5): the nominal pusher–slider against the simulator, each pushing
//! effect term against its simulator counterpart, and the diagnosis on simulator data with one
//! hidden effect (mocap-like noise): nominal data → nothing significant; each effect → first,
//! significant, ≥ 50 % of the held-out k-step error removed, parameter near the truth.
//!
//! Data are generated in process (seeded, the simulator's scenarios of
//! `diagnosis::simdata::push_scenario`): 20 episodes × 10 pushes, a few seconds per test.

use dynlab_diagnose::diagnosis::simdata::{
    nominal_model, push_dataset, push_dataset_with, push_scenario,
};
use dynlab_diagnose::diagnosis::{Candidate, DiagnoseConfig, Diagnosis, diagnose};
use dynlab_learn::dynamics::conventions::wrap_angle;
use dynlab_learn::dynamics::ode;
use dynlab_learn::dynamics::physics::{Effect, LimitSurface, PhysicsModel};
use dynlab_learn::train::default_physics_solver;
use dynlab_learn::{Dataset, Model, ModelKind, World};
use dynlab_sim::PushExplorer;

/// The simulator's value of each effect (`push_scenario`), as model parameters.
fn truth(e: Effect) -> Vec<(&'static str, f64)> {
    match e {
        Effect::ComOffset => vec![("com_offset.ox", 0.02), ("com_offset.oy", 0.01)],
        // tilt 0.02 rad along +x, table μ = 0.1
        Effect::TableTilt => vec![("table_tilt.gx", 0.02f64.tan() / 0.1)],
        // μ = 0.5 on a disc of radius 0.1 m at (0.5, 0.1), table μ = 0.1
        Effect::FrictionPatch => vec![
            ("friction_patch.cx", 0.5),
            ("friction_patch.cy", 0.1),
            ("friction_patch.r", 0.1),
            ("friction_patch.w", 0.002),
            ("friction_patch.k", 5.0),
        ],
        Effect::PusherFriction => vec![("pusher_friction.mu", 0.5)],
        // a pad 2.4 cm wide and 2 cm thick whose face looks along world x
        Effect::FlatPusher => vec![
            ("flat_pusher.yaw", 0.0),
            ("flat_pusher.half_width", 0.012),
            ("flat_pusher.half_thickness", 0.01),
        ],
        _ => vec![],
    }
}

fn data(effect: Option<Effect>, noise: f64, episodes: u64, seed: u64) -> Dataset {
    push_dataset(&push_scenario(effect, noise), episodes, 10, seed, 2).unwrap()
}

/// RMS one-push error (position \[m\], angle \[rad\]) of a model on noiseless data; `world_line`
/// false integrates the plain vector field (pusher held in the block frame).
fn one_push_error(m: &PhysicsModel, d: &Dataset, world_line: bool) -> (f64, f64) {
    let solver = default_physics_solver(World::Push);
    let (mut ep, mut et, mut n) = (0.0, 0.0, 0usize);
    for t in &d.trajectories {
        for a in 0..t.len() - 1 {
            let s = &t.s[a * 3..a * 3 + 3];
            let u = &t.u[a * 3..a * 3 + 3];
            let mut o = [0.0; 3];
            if world_line {
                m.integrate_step(&solver, 1, s, u, 1.0, &mut o);
            } else {
                ode::integrate(m, &solver, 1, s, u, 1.0, &mut o);
            }
            let meas = &t.s[(a + 1) * 3..(a + 2) * 3];
            ep += (o[0] - meas[0]).powi(2) + (o[1] - meas[1]).powi(2);
            et += wrap_angle(o[2] - meas[2]).powi(2);
            n += 1;
        }
    }
    ((ep / n as f64).sqrt(), (et / n as f64).sqrt())
}

#[test]
fn world_line_pusher_matches_the_simulator_far_better_than_a_block_frame_pusher() {
    let d = data(None, 0.0, 8, 11);
    // one state per push (the loader collapses pushes)
    assert!(d.trajectories.iter().all(|t| t.len() <= 11));
    let m = PhysicsModel::pushing(&[]).unwrap();
    let (p_old, t_old) = one_push_error(&m, &d, false);
    let (p_new, t_new) = one_push_error(&m, &d, true);
    assert!(p_new < 0.3 * p_old, "position {p_new} vs {p_old}");
    assert!(t_new < 0.5 * t_old, "angle {t_new} vs {t_old}");
    assert!(p_new < 0.003, "one-push position error {p_new} m");
}

/// Limit-surface ratio `c` of a uniformly loaded `a × b` rectangle: the mean distance of its
/// area from the centre (`m_max/f_max`; 0.383 a for a square).
fn uniform_c(a: f64, b: f64) -> f64 {
    let n = 200;
    let mut sum = 0.0;
    for i in 0..n {
        for j in 0..n {
            let x = a * ((i as f64 + 0.5) / n as f64 - 0.5);
            let y = b * ((j as f64 + 0.5) / n as f64 - 0.5);
            sum += (x * x + y * y).sqrt();
        }
    }
    sum / (n * n) as f64
}

#[test]
fn a_rectangular_block_needs_its_depth_and_its_width() {
    // the simulator's block 8 cm deep and 12 cm wide, pushed on its long face
    let mut s = push_scenario(None, 0.0);
    s.block.size = [0.08, 0.12];
    let d = push_dataset(&s, 8, 10, 31, 2).unwrap();
    let error = |a: f64, b: f64| {
        let mut m = PhysicsModel::pushing(&[]).unwrap();
        m.set_param("a", a).unwrap();
        m.set_param("b", b).unwrap();
        m.set_param("c", uniform_c(a, b)).unwrap();
        let (p, t) = one_push_error(&m, &d, true);
        (p / 0.1 + t, format!("a {a}, b {b}: {p:.4} m, {t:.4} rad"))
    };
    let (right, msg) = error(0.08, 0.12);
    for (a, b) in [(0.1, 0.1), (0.08, 0.08), (0.12, 0.12), (0.12, 0.08)] {
        let (wrong, wmsg) = error(a, b);
        assert!(right < 0.7 * wrong, "{msg}; {wmsg}");
    }
    // as good on the rectangle as the square's model on the square's pushes
    let square = data(None, 0.0, 8, 31);
    let (p, t) = one_push_error(&PhysicsModel::pushing(&[]).unwrap(), &square, true);
    assert!(
        right < 1.5 * (p / 0.1 + t),
        "{msg}; the square: {p:.4} m, {t:.4} rad"
    );
}

/// Each effect term at the simulator's value explains the simulator's pushes with that effect
/// much better than the nominal model: signs, frames and units agree.
fn effect_term_matches_simulator(e: Effect, seed: u64) {
    let d = data(Some(e), 0.0, 8, seed);
    let nominal = PhysicsModel::pushing(&[]).unwrap();
    let mut with = PhysicsModel::pushing(&[e]).unwrap();
    for (name, v) in truth(e) {
        with.set_param(name, v).unwrap();
    }
    let (p0, t0) = one_push_error(&nominal, &d, true);
    let (p1, t1) = one_push_error(&with, &d, true);
    // the combined error in block lengths (a = 0.1 m) and radians drops, and the error the
    // effect mainly acts on (position or angle) drops by at least 40 %
    let (c0, c1) = (p0 / 0.1 + t0, p1 / 0.1 + t1);
    let msg =
        format!("{e}: with the effect {p1:.4} m, {t1:.4} rad; nominal {p0:.4} m, {t0:.4} rad");
    assert!(c1 < 0.8 * c0, "{msg}");
    assert!((p1 / p0).min(t1 / t0) < 0.6, "{msg}");
    // the wrong sign is worse than the right one
    let mut flipped = with.clone();
    for (name, v) in truth(e) {
        if ![".cx", ".cy", ".r", ".w"].iter().any(|x| name.ends_with(x)) {
            let neg = match e {
                Effect::FrictionPatch => 1.0 / v,
                Effect::PusherFriction => 0.0,
                // the pad half a radian off: the block turned towards the wrong yaw
                Effect::FlatPusher if name.ends_with(".yaw") => 0.5,
                Effect::FlatPusher => v,
                _ => -v,
            };
            flipped.set_param(name, neg).unwrap();
        }
    }
    let (p2, t2) = one_push_error(&flipped, &d, true);
    assert!(c1 < p2 / 0.1 + t2, "{e}: flipped effect fits better");
}

#[test]
fn com_offset_term_matches_the_simulator() {
    effect_term_matches_simulator(Effect::ComOffset, 21);
}

#[test]
fn table_tilt_term_matches_the_simulator() {
    effect_term_matches_simulator(Effect::TableTilt, 22);
}

#[test]
fn friction_patch_term_matches_the_simulator() {
    effect_term_matches_simulator(Effect::FrictionPatch, 23);
}

#[test]
fn pusher_friction_term_matches_the_simulator() {
    effect_term_matches_simulator(Effect::PusherFriction, 24);
}

#[test]
fn flat_pusher_term_matches_the_simulator() {
    effect_term_matches_simulator(Effect::FlatPusher, 25);
}

/// A pushing physics model with the default solver.
fn physics_model(physics: PhysicsModel, dt: f64) -> Model {
    Model::new(
        ModelKind::Physics,
        World::Push,
        dt,
        None,
        None,
        Some(physics),
        default_physics_solver(World::Push),
    )
    .unwrap()
}

fn run(effect: Option<Effect>, seed: u64) -> Diagnosis {
    let d = data(effect, 1.0, 20, 400 + seed);
    let model = nominal_model(World::Push, d.pose_dt_s).unwrap();
    let cfg = DiagnoseConfig {
        seed,
        ..DiagnoseConfig::default()
    };
    diagnose(&model, &d, &cfg).unwrap()
}

fn assert_found(d: &Diagnosis, e: Effect, param: &str, truth: f64, tol: f64) {
    assert_found_min(d, e, param, truth, tol, 0.5);
}

fn assert_found_min(d: &Diagnosis, e: Effect, param: &str, truth: f64, tol: f64, min: f64) {
    let table = d.table();
    assert_eq!(d.verdict.as_deref(), Some(e.name()), "{table}");
    let first = &d.candidates[0];
    assert_eq!(first.effect, e.name(), "{table}");
    assert!(first.significant, "{table}");
    assert!(first.error_reduction >= min, "{table}");
    let got = first.params[param];
    assert!(
        (got - truth).abs() <= tol,
        "{param} = {got}, truth {truth}\n{table}"
    );
    assert!(first.param_std[param] > 0.0, "{table}");
}

#[test]
fn push_nominal_data_has_no_significant_effect() {
    let d = run(None, 1);
    assert_eq!(d.verdict, None, "{}", d.table());
    assert!(d.candidates.iter().all(|c| !c.significant), "{}", d.table());
}

#[test]
fn push_com_offset_is_found() {
    // offset (0.02, 0.01) m: the lateral part is well determined, the part along the push
    // direction is weakly identifiable from a frictionless pusher (it only moves the
    // turning centre)
    let d = run(Some(Effect::ComOffset), 2);
    assert_found(&d, Effect::ComOffset, "oy", 0.01, 0.002);
    assert!(d.candidates[0].params["ox"] > 0.005, "{}", d.table());
}

#[test]
fn push_table_tilt_is_found() {
    // a weak effect (1.1° slope): it removes at least half of the held-out error now that the
    // nominal model has the support grid's limit surface and refits c, κ with the effect
    let d = run(Some(Effect::TableTilt), 3);
    assert_found(&d, Effect::TableTilt, "gx", 0.2, 0.08);
}

#[test]
fn push_friction_patch_is_found() {
    // how much of the held-out error the patch explains depends on how many held-out pushes
    // cross its edge
    let d = run(Some(Effect::FrictionPatch), 4);
    assert_found(&d, Effect::FrictionPatch, "cx", 0.5, 0.02);
    let p = &d.candidates[0].params;
    assert!((p["cy"] - 0.1).abs() < 0.02, "{}", d.table());
    assert!((p["r"] - 0.1).abs() < 0.02, "{}", d.table());
    assert!(p["k"] > 2.5, "{}", d.table());
}

#[test]
fn push_pusher_friction_is_found_and_recovered() {
    let d = run(Some(Effect::PusherFriction), 5);
    assert_found(&d, Effect::PusherFriction, "mu", 0.5, 0.05);
}

#[test]
fn push_flat_pusher_is_found_with_its_yaw_and_width() {
    let d = run(Some(Effect::FlatPusher), 6);
    assert_found(&d, Effect::FlatPusher, "half_width", 0.012, 0.003);
    // the canonical form: the yaw within a quarter turn of 0, the width the larger side
    let p = &d.candidates[0].params;
    assert!(p["yaw"].abs() < 0.06, "{}", d.table());
    assert!((p["half_thickness"] - 0.01).abs() < 0.003, "{}", d.table());
}

#[test]
fn refit_tolerance_keeps_the_nominal_parameters_near_the_models_values() {
    let d = data(Some(Effect::TableTilt), 1.0, 20, 403);
    let physics = PhysicsModel::pushing(&[]).unwrap();
    let given: Vec<(String, f64)> = physics
        .param_names()
        .into_iter()
        .zip(physics.params().iter().copied())
        .collect();
    let model = physics_model(physics, d.pose_dt_s);
    let tol = 0.02;
    let cfg = DiagnoseConfig {
        seed: 3,
        refit_tolerance: Some(tol),
        discover: false,
        ..DiagnoseConfig::default()
    };
    let diag = diagnose(&model, &d, &cfg).unwrap();
    assert!(!diag.nominal_refit.is_empty(), "{}", diag.table());
    let fitted = diag
        .nominal_refit
        .iter()
        .chain(diag.candidates.iter().flat_map(|c| c.nominal_params.iter()));
    let mut moved = false;
    for (name, v) in fitted {
        let g = given.iter().find(|(n, _)| n == name).unwrap().1;
        assert!(
            (v - g).abs() <= tol * g.abs() * (1.0 + 1e-9),
            "{name} = {v}, model {g}, tolerance ±{tol}\n{}",
            diag.table()
        );
        moved |= (v - g).abs() > 1e-3 * tol * g.abs();
    }
    assert!(moved, "no nominal parameter was refitted\n{}", diag.table());
    for bad in [0.0, -0.1, f64::NAN] {
        let cfg = DiagnoseConfig {
            refit_tolerance: Some(bad),
            ..DiagnoseConfig::default()
        };
        let err = diagnose(&model, &d, &cfg).unwrap_err().to_string();
        assert!(err.contains("refit_tolerance"), "{err}");
    }
}

#[test]
fn the_support_points_limit_surface_predicts_quasi_static_pushes_better_than_the_ellipsoid() {
    // a slow pusher (0.02 m/s): the simulator's pushes are quasi-static, as the model assumes
    let mut s = push_scenario(None, 0.0);
    s.pusher.speed = 0.02;
    s.pusher.acceleration = 0.08;
    let explorer = PushExplorer {
        pushes_per_episode: 10,
        push_period: s.max_push_time().ceil(),
        ..PushExplorer::default()
    };
    let d = push_dataset_with(&s, &explorer, 8, 11, 2).unwrap();
    let error = |surface: LimitSurface| {
        let mut m = PhysicsModel::pushing(&[]).unwrap();
        m.set_limit_surface(surface).unwrap();
        one_push_error(&m, &d, true)
    };
    let (pe, te) = error(LimitSurface::Ellipsoid);
    let (ps, ts) = error(LimitSurface::SupportPoints);
    let msg = format!("ellipsoid {pe:.5} m, {te:.4} rad; support points {ps:.5} m, {ts:.4} rad");
    assert!(ps < 0.75 * pe && ts < 0.5 * te, "{msg}");
    // the car has no limit surface
    let mut car = PhysicsModel::car(&[]).unwrap();
    let e = car
        .set_limit_surface(LimitSurface::SupportPoints)
        .unwrap_err();
    assert!(e.to_string().contains("car model has none"), "{e}");
}

#[test]
fn a_block_depth_off_its_measure_is_refitted_not_named_a_com_offset() {
    // the simulator's block is 0.1 m deep, the model's 8 % less: the pusher works one face, so
    // a centre of mass moved along the push moves the contact's arm as the depth does
    let d = data(None, 1.0, 20, 407);
    let mut physics = PhysicsModel::pushing(&[]).unwrap();
    physics.set_param("a", 0.092).unwrap();
    let model = physics_model(physics, d.pose_dt_s);
    let cfg = DiagnoseConfig {
        seed: 7,
        discover: false,
        ..DiagnoseConfig::default()
    };
    // the depth refitted within ±10 % of the model's: nothing named, the depth moves towards
    // the block's
    let diag = diagnose(&model, &d, &cfg).unwrap();
    assert_eq!(diag.verdict, None, "{}", diag.table());
    let a = diag.nominal_refit["a"];
    assert!(
        a > 0.096 && a <= 0.092 * 1.1 + 1e-12,
        "a = {a}\n{}",
        diag.table()
    );
    // … for the baseline alone: the candidates hold it
    assert_eq!(diag.nominal_measured.get("a"), Some(&0.1));
    assert!(
        diag.table()
            .contains("the measured a (±10 %) for the baseline alone")
    );
    for c in &diag.candidates {
        assert!(c.nominal_params.contains_key("c"), "{}", diag.table());
        assert!(!c.nominal_params.contains_key("a"), "{}", diag.table());
    }
    // held as given, the depth's error is named an offset along the push of about half of it
    let held = DiagnoseConfig {
        refit_params: Some(vec!["c".into(), "kappa".into()]),
        ..cfg.clone()
    };
    let diag = diagnose(&model, &d, &held).unwrap();
    assert_eq!(
        diag.verdict.as_deref(),
        Some("com_offset"),
        "{}",
        diag.table()
    );
    let ox = diag.candidates[0].params["ox"];
    assert!(ox > 0.002 && ox < 0.006, "ox = {ox}\n{}", diag.table());
    // 10 % short, the block's depth just beyond the tolerance: the depth ends on its bound and
    // the offset the candidate finds lies along the push within the tolerance's half depth, so
    // it is not counted
    let mut short = model.physics().unwrap().clone();
    short.set_param("a", 0.09).unwrap();
    let model = physics_model(short, d.pose_dt_s);
    let diag = diagnose(&model, &d, &cfg).unwrap();
    assert_eq!(diag.verdict, None, "{}", diag.table());
    assert!(
        (diag.nominal_refit["a"] - 0.099).abs() < 1e-6,
        "{}",
        diag.table()
    );
    let com = diag
        .candidates
        .iter()
        .find(|c| c.effect == "com_offset")
        .unwrap();
    let note = com.note.as_deref().unwrap_or_default();
    assert!(note.contains("lies along the push"), "{}", diag.table());
    assert!(
        com.params["ox"] > 0.0 && com.params["ox"] <= 0.5 * 0.1 * 0.09,
        "{}",
        diag.table()
    );
}

/// The diagnosis (without the term search) of `episodes` × 10 pushes with `effect` hidden
/// (noise ×1), split with `seed`.
fn diagnose_pushes(effect: Option<Effect>, episodes: u64, seed: u64) -> Diagnosis {
    let d = push_dataset(&push_scenario(effect, 1.0), episodes, 10, 900 + seed, 2).unwrap();
    let model = nominal_model(World::Push, d.pose_dt_s).unwrap();
    let cfg = DiagnoseConfig {
        seed,
        discover: false,
        ..DiagnoseConfig::default()
    };
    diagnose(&model, &d, &cfg).unwrap()
}

/// Every step's candidates.
fn candidates(d: &Diagnosis) -> impl Iterator<Item = &Candidate> {
    d.selection.iter().flat_map(|s| &s.candidates)
}

#[test]
fn the_second_look_counts_an_effect_the_held_out_half_cannot_bound_and_not_a_nominal_fit() {
    // 6 episodes: 3 held-out segments, too few for the held-out half alone to bound a
    // reduction; the second look fits on the held-out half and scores both
    let diag = |effect: Option<Effect>, seed: u64| diagnose_pushes(effect, 6, seed);
    let tilted = diag(Some(Effect::TableTilt), 4);
    let first = &tilted.selection[0].candidates;
    let tilt = first.iter().find(|c| c.effect == "table_tilt").unwrap();
    assert!(
        tilt.error_reduction >= 0.1 && tilt.ci_lower <= 0.0,
        "{}",
        tilted.table()
    );
    let look = tilt.cross_fit.as_ref().expect("a second look");
    assert!(look.counts(0.1), "{}", tilted.table());
    assert_eq!(look.segments, 6, "{}", tilted.table());
    assert!(tilt.significant, "{}", tilted.table());
    assert_eq!(
        tilted.verdict.as_deref(),
        Some("table_tilt"),
        "{}",
        tilted.table()
    );
    // the slope from the fit half, downhill along +x from the held-out half's three episodes
    let truth = 0.02f64.tan() / 0.1;
    assert!(
        (tilt.params["gx"] - truth).abs() < 0.05,
        "{}",
        tilted.table()
    );
    assert!(look.params["gx"] > 0.05, "{}", tilted.table());
    // nominal data: a candidate that removes enough on the held-out half but is not bounded
    // there gains nothing from the other half
    let nominal = diag(None, 2);
    let looked: Vec<_> = candidates(&nominal)
        .filter(|c| c.cross_fit.is_some())
        .collect();
    assert!(!looked.is_empty(), "{}", nominal.table());
    for c in looked {
        assert!(
            c.error_reduction >= 0.1 && c.ci_lower <= 0.0,
            "{}",
            nominal.table()
        );
        assert!(
            !c.cross_fit.as_ref().unwrap().counts(0.1),
            "{}",
            nominal.table()
        );
    }
    assert_eq!(nominal.verdict, None, "{}", nominal.table());
}

#[test]
fn the_folds_look_counts_a_tilt_neither_half_bounds_and_not_a_nominal_fit() {
    // 8 episodes: the halves' 4 + 4 segments do not bound the tilt, the folds' fits on 6
    // segments each do
    let tilted = diagnose_pushes(Some(Effect::TableTilt), 8, 5);
    let tilt = tilted.selection[0]
        .candidates
        .iter()
        .find(|c| c.effect == "table_tilt")
        .unwrap();
    let table = tilted.table();
    assert!(
        tilt.error_reduction >= 0.1 && tilt.ci_lower <= 0.0,
        "{table}"
    );
    let halves = tilt.cross_fit.as_ref().expect("a second look");
    assert!(
        halves.reduction >= 0.1 && !halves.counts(0.1),
        "the halves alone would count it: {table}"
    );
    let folds = tilt.fold_fit.as_ref().expect("a folds' look");
    assert_eq!((folds.folds, folds.segments), (4, 8), "{table}");
    assert!(folds.counts(0.1) && tilt.significant, "{table}");
    assert_eq!(tilted.verdict.as_deref(), Some("table_tilt"), "{table}");
    let truth = 0.02f64.tan() / 0.1;
    assert!((folds.params["gx"] - truth).abs() < 0.05, "{table}");
    // nominal data: candidates that remove enough on both halves without a bound gain
    // nothing from the folds
    for seed in [2, 7] {
        let nominal = diagnose_pushes(None, 10, seed);
        let looked: Vec<_> = candidates(&nominal)
            .filter_map(|c| c.fold_fit.as_ref())
            .collect();
        assert!(!looked.is_empty(), "{}", nominal.table());
        assert!(looked.iter().all(|f| !f.counts(0.1)), "{}", nominal.table());
        assert_eq!(nominal.verdict, None, "{}", nominal.table());
    }
}

/// A perturbed world of `push_open_world` (`world_seed`: the block, pusher and table each
/// scaled by a seeded factor within ±10 %), its physics model fitted on its nominal pushes, and
/// the diagnosis (no term search) of its pushes with the `hidden` effects.
fn perturbed_world_diagnosis(world_seed: u64, hidden: &[Effect]) -> Diagnosis {
    use dynlab_diagnose::diagnosis::push_level_dataset;
    use dynlab_diagnose::diagnosis::simdata::add_push_effect;
    use dynlab_learn::train::{TrainConfig, train};
    let (seed, threads) = (world_seed, 2);
    let world = push_scenario(None, 2.0)
        .perturbed(7000 + seed, 0.1)
        .unwrap();
    let explorer = PushExplorer {
        pushes_per_episode: 10,
        start_jitter: [0.05, 0.05, std::f64::consts::PI],
        ..PushExplorer::default()
    };
    let pushes = |s, data_seed| {
        push_level_dataset(push_dataset_with(s, &explorer, 100, data_seed, threads).unwrap())
    };
    let tc = TrainConfig {
        kind: ModelKind::Physics,
        seed,
        ..TrainConfig::default()
    };
    let model = train(&pushes(&world, 5000 + seed), &tc, &mut |_| {})
        .unwrap()
        .model;
    let mut with = world.clone();
    for &e in hidden {
        add_push_effect(&mut with, e);
    }
    let cfg = DiagnoseConfig {
        seed,
        discover: false,
        ..DiagnoseConfig::default()
    };
    diagnose(&model, &pushes(&with, 8000 + seed), &cfg).unwrap()
}

/// A perturbed world (`push_open_world`'s seed 1: the block 8 % shallower and 8 % wider, the
/// pusher's radius 9 % smaller, table friction −5 %), its model fitted on its nominal pushes,
/// pusher friction hidden. After the friction a pad 1.4 × 2 mm removed 11 % more (bound 0.6 %)
/// and was named: a pad within half the pusher's radius both ways hardly turns its reach with
/// the block and stands for a pusher or a block of another size. Now the friction alone.
#[test]
fn a_pad_smaller_than_half_the_pusher_is_not_named_in_a_perturbed_world() {
    let d = perturbed_world_diagnosis(1, &[Effect::PusherFriction]);
    let table = d.table();
    assert_eq!(d.effects, vec!["pusher_friction".to_string()], "{table}");
    // the pad was fitted after the friction and is refused for its size
    let pad = candidates(&d)
        .find(|c| c.effect == "flat_pusher" && c.error_reduction >= 0.1)
        .unwrap_or_else(|| panic!("the pad is fitted and removes 10 %\n{table}"));
    assert!(
        pad.note
            .as_deref()
            .is_some_and(|n| n.contains("within half the pusher's radius")),
        "{table}"
    );
    assert!(
        pad.params["half_width"].max(pad.params["half_thickness"]) < 0.005,
        "{table}"
    );
}

/// A perturbed world (`push_open_world`'s seed 0: the block 9.5 % deeper than its datasheet)
/// with a shifted centre of mass and a flat pusher. Alone the offset removed 70 % with `ox` on
/// its bound 0.05 m, the pad alone nothing, and nothing was named. The offset's partner, fitted
/// on top of it, is the pad; refitted together they remove 83 %, the offset off its bound.
#[test]
fn an_effect_on_its_bound_is_named_with_the_partner_it_shares_the_error_with() {
    let d = perturbed_world_diagnosis(0, &[Effect::ComOffset, Effect::FlatPusher]);
    let table = d.table();
    assert_eq!(
        d.effects,
        vec!["com_offset".to_string(), "flat_pusher".to_string()],
        "{table}"
    );
    // the offset alone is on its bound, not significant, and added with the pad
    let first = &d.selection[0];
    let alone = first
        .candidates
        .iter()
        .find(|c| c.effect == "com_offset")
        .unwrap();
    assert!(!alone.significant && !alone.on_bound.is_empty(), "{table}");
    assert!(
        alone
            .paired
            .as_deref()
            .is_some_and(|n| n.contains("with flat_pusher")),
        "{table}"
    );
    assert!(first.candidates.iter().all(|c| !c.significant), "{table}");
    let j = d.joint.as_ref().unwrap();
    assert!(j.on_bound.is_empty(), "{table}");
    assert!(j.error_reduction >= 0.5 && j.ci_lower > 0.0, "{table}");
    let ox = j.params["com_offset.ox"];
    assert!(ox > 0.0 && ox < 0.049, "{table}");
    let yaw = j.params["flat_pusher.yaw"];
    assert!(yaw.abs() < 0.1, "{table}");
}

/// A perturbed world (`push_open_world`'s seed 3: the block 1.7 % deeper and 1.3 % narrower,
/// the pusher's radius 3.7 % larger) with a tilted table and a friction patch. After the two a
/// centre of mass (2.4, 0.7) mm off the block's centre removed 15.9 % more (bound 5.5 %) and
/// was named: an offset within half the measured depth's tolerance both ways is what a block or
/// a pusher a little off its datasheet leaves. Now the tilt and the patch alone. (Since the
/// slope's pull is divided by the friction under the block, the offset after the two removes
/// 9.5 % (bound 4.8 %) and is not significant on its own numbers, the lateral part within its
/// σ; where it clears the bar, the rule must keep it out.)
#[test]
fn an_offset_within_the_blocks_tolerance_both_ways_is_not_named_a_third_effect() {
    let d = perturbed_world_diagnosis(3, &[Effect::TableTilt, Effect::FrictionPatch]);
    let table = d.table();
    let mut named = d.effects.clone();
    named.sort();
    assert_eq!(named, vec!["friction_patch", "table_tilt"], "{table}");
    let last = d.selection.last().unwrap();
    assert_eq!(last.added, None, "{table}");
    let offset = last
        .candidates
        .iter()
        .find(|c| c.effect == "com_offset")
        .unwrap();
    assert!(!offset.significant, "{table}");
    let clears_the_bar = offset.error_reduction >= 0.1 && offset.ci_lower > 0.0;
    assert!(
        !clears_the_bar
            || offset
                .note
                .as_deref()
                .is_some_and(|n| n.contains("both ways")),
        "{table}"
    );
    assert!(
        offset.params["ox"].abs().max(offset.params["oy"].abs()) < 0.005,
        "{table}"
    );
}

/// A perturbed world (`push_open_world`'s seed 4: the block 7 % deeper, table friction +6 %)
/// with a patch of 4.7 times the table's friction and a flat pusher. The patch's starts ranked
/// by their cost put the true disc's basin 5th or lower, and the two refined ended on a large
/// disc of a fifth of the table's friction elsewhere (37 % removed with the pad). Each start
/// fitted a few iterations first, the best two then refined, the patch is the small
/// high-friction disc, and the two remove most of the error.
#[test]
fn a_friction_patch_is_fitted_from_its_starts_probed_not_ranked_where_they_begin() {
    let d = perturbed_world_diagnosis(4, &[Effect::FrictionPatch, Effect::FlatPusher]);
    let table = d.table();
    let mut named = d.effects.clone();
    named.sort();
    assert_eq!(named, vec!["flat_pusher", "friction_patch"], "{table}");
    let step_patch = d.selection[0]
        .candidates
        .iter()
        .find(|c| c.effect == "friction_patch")
        .unwrap();
    // more friction on a disc about the block's size, where the ranked starts found less on a
    // disc twice as large
    assert!(step_patch.params["k"] > 2.0, "{table}");
    assert!(step_patch.params["r"] < 0.15, "{table}");
    let j = d.joint.as_ref().unwrap();
    assert!(j.error_reduction >= 0.6 && j.ci_lower > 0.0, "{table}");
    assert!(j.params["friction_patch.k"] > 2.0, "{table}");
}
