//! Physics sanity of the car world (ORCA 1:43 parameters).

use dynlab_sim::{CarInput, CarScenario, CarState, CarWorld};

fn drive(world: &mut CarWorld, u: CarInput, seconds: f64) -> Vec<CarState> {
    let n = (seconds / 0.01).round() as usize;
    (0..n)
        .map(|_| world.step(u, 0.01).expect("finite input"))
        .collect()
}

#[test]
fn straight_line_top_speed_matches_the_drivetrain_balance() {
    // At full throttle the steady state solves (Cm1 − Cm2 v) − Cr0 − Cr2 v² = 0.
    let s = CarScenario::floor();
    let c = &s.car;
    let (a, b, k) = (c.cr2, c.cm2, c.cm1 - c.cr0);
    let v_top = (-b + (b * b + 4.0 * a * k).sqrt()) / (2.0 * a);
    let mut w = CarWorld::new(&s).unwrap();
    let traj = drive(&mut w, CarInput::new(0.0, 1.0), 20.0);
    let end = traj.last().unwrap();
    assert!(
        (end.vx - v_top).abs() < 0.01 * v_top,
        "vx {} vs {v_top}",
        end.vx
    );
    assert_eq!(end.vy, 0.0);
    assert_eq!(end.omega, 0.0);
    assert_eq!(end.y, 0.0);
}

#[test]
fn grips_at_gentle_input() {
    // δ = 0.1 rad, d = 0.2: about 0.5 m/s on a 0.6 m circle. The sideslip stays small and the
    // yaw rate is the kinematic one, v tan δ / L, within the small understeer of the ORCA tires.
    let s = CarScenario::floor();
    let mut w = CarWorld::new(&s).unwrap();
    drive(&mut w, CarInput::new(0.0, 0.2), 1.0);
    let traj = drive(&mut w, CarInput::new(0.1, 0.2), 8.0);
    for st in &traj {
        assert!(
            st.sideslip().abs() < 5f64.to_radians(),
            "sideslip {} deg",
            st.sideslip().to_degrees()
        );
    }
    let end = traj.last().unwrap();
    let kinematic = end.speed() * 0.1f64.tan() / s.car.wheelbase();
    assert!(end.speed() > 0.3);
    assert!(
        (end.omega - kinematic).abs() < 0.1 * kinematic,
        "yaw rate {} vs kinematic {kinematic}",
        end.omega
    );
}

#[test]
fn drifts_at_high_throttle_and_steering() {
    // Full throttle asks the rear tire for more than its peak force: the friction ellipse
    // leaves little lateral grip at the rear and the car oversteers into a slide.
    let s = CarScenario::floor();
    let mut w = CarWorld::new(&s).unwrap();
    drive(&mut w, CarInput::new(0.0, 0.3), 2.0);
    let traj = drive(&mut w, CarInput::new(0.35, 1.0), 2.0);
    let max_beta = traj
        .iter()
        .filter(|st| st.speed() > 0.3)
        .map(|st| st.sideslip().abs())
        .fold(0.0, f64::max);
    assert!(
        max_beta > 30f64.to_radians(),
        "max sideslip {} deg",
        max_beta.to_degrees()
    );
    // Without the friction ellipse (the published model) the same input is far tamer.
    let mut published = s.clone();
    published.car.friction_ellipse = false;
    let mut w = CarWorld::new(&published).unwrap();
    drive(&mut w, CarInput::new(0.0, 0.3), 2.0);
    let first = drive(&mut w, CarInput::new(0.35, 1.0), 0.5);
    let mut w = CarWorld::new(&s).unwrap();
    drive(&mut w, CarInput::new(0.0, 0.3), 2.0);
    let second = drive(&mut w, CarInput::new(0.35, 1.0), 0.5);
    let beta = |t: &[CarState]| t.iter().map(|s| s.sideslip().abs()).fold(0.0, f64::max);
    assert!(beta(&second) > beta(&first));
}

#[test]
fn car_at_rest_stays_at_rest_and_brakes_to_a_stop() {
    let s = CarScenario::floor();
    let mut w = CarWorld::new(&s).unwrap();
    let traj = drive(&mut w, CarInput::new(0.2, 0.0), 5.0);
    let end = traj.last().unwrap();
    assert!(end.x.abs() < 1e-9 && end.y.abs() < 1e-9);
    // The reverse drive at d = −0.1 is below rolling resistance: at most a slow creep.
    let traj = drive(&mut w, CarInput::new(0.0, -0.1), 5.0);
    assert!(traj.last().unwrap().x.abs() < 5e-3);
    // Rolling at 1 m/s with zero throttle, the car coasts to a stop.
    w.reset(CarState {
        vx: 1.0,
        ..CarState::default()
    })
    .unwrap();
    let traj = drive(&mut w, CarInput::new(0.0, 0.0), 5.0);
    assert!(traj.last().unwrap().vx.abs() < 2e-3, "{:?}", traj.last());
}

#[test]
fn sliding_sideways_at_low_speed_comes_to_rest() {
    // The slip-angle regularisation turns v → 0 into a bounded lateral force, no blow-up.
    let s = CarScenario::floor();
    let mut w = CarWorld::new(&s).unwrap();
    w.reset(CarState {
        vx: 0.01,
        vy: 0.5,
        omega: 3.0,
        ..CarState::default()
    })
    .unwrap();
    let traj = drive(&mut w, CarInput::new(0.0, 0.0), 3.0);
    let end = traj.last().unwrap();
    assert!(
        traj.iter()
            .all(|s| s.speed().is_finite() && s.speed() < 0.6)
    );
    assert!(end.speed() < 0.01 && end.omega.abs() < 0.1, "{end:?}");
}

#[test]
fn inputs_are_clamped_and_bad_inputs_rejected() {
    let s = CarScenario::floor();
    let mut a = CarWorld::new(&s).unwrap();
    let mut b = CarWorld::new(&s).unwrap();
    a.step(CarInput::new(5.0, 7.0), 0.5).unwrap();
    b.step(CarInput::new(0.35, 1.0), 0.5).unwrap();
    assert_eq!(a.state(), b.state());
    assert!(a.step(CarInput::new(f64::NAN, 0.0), 0.01).is_err());
    assert!(a.step(CarInput::new(0.0, 0.0), -0.01).is_err());
    assert!(
        a.reset(CarState {
            vx: f64::NAN,
            ..CarState::default()
        })
        .is_err()
    );
}

#[test]
fn step_splits_into_substeps_consistently() {
    // One 0.1 s step equals ten 0.01 s steps to rounding (same 1 ms substeps).
    let s = CarScenario::floor();
    let mut a = CarWorld::new(&s).unwrap();
    let mut b = CarWorld::new(&s).unwrap();
    a.step(CarInput::new(0.2, 0.5), 0.1).unwrap();
    for _ in 0..10 {
        b.step(CarInput::new(0.2, 0.5), 0.01).unwrap();
    }
    let (x, y) = (a.state(), b.state());
    assert!(
        (x.x - y.x).abs() < 1e-12
            && (x.vx - y.vx).abs() < 1e-12
            && (x.omega - y.omega).abs() < 1e-12
    );
}
