//! Effects the diagnosis library does not model (`steering_gain_speed`, `steering_rate_limit`,
//! non-disc grip regions, `anisotropic_friction`), the flat pusher (a rigid pad, which the
//! library's `flat_pusher` approximates by a point contact at its leading corner) and the
//! perturbed-parameter helpers: each
//! effect changes the trajectory in its documented direction, runs are deterministic, and bad
//! values are rejected naming the key.

use dynlab_sim::car::{
    AeroDrag, CarParams, CommandDelay, GripPatch, SteeringGainSpeed, SteeringOffset,
    SteeringRateLimit,
};
use dynlab_sim::push::{AnisotropicFriction, FrictionPatch, TableTilt};
use dynlab_sim::{
    CarExplorer, CarInput, CarScenario, CarState, CarWorld, Pose2, PushAction, PushExplorer,
    PushOutcome, PushScenario, PushWorld, Region, RegionShape, SimError, generate_car_episodes,
    generate_push_episodes,
};

fn drive(s: &CarScenario, start: CarState, u: CarInput, seconds: f64) -> Vec<CarState> {
    let mut w = CarWorld::new(s).unwrap();
    w.reset(start).unwrap();
    (0..(seconds * 100.0).round() as usize)
        .map(|_| w.step(u, 0.01).unwrap())
        .collect()
}

fn rolling(vx: f64) -> CarState {
    CarState {
        vx,
        ..CarState::default()
    }
}

fn gain_speed(v0: f64) -> CarScenario {
    let mut s = CarScenario::floor();
    s.effects.steering_gain_speed = Some(SteeringGainSpeed { enabled: true, v0 });
    s
}

fn rate_limited(rate: f64, tau: f64) -> CarScenario {
    let mut s = CarScenario::floor();
    s.effects.steering_rate_limit = Some(SteeringRateLimit {
        enabled: true,
        rate,
        tau,
    });
    s
}

#[test]
fn steering_gain_falls_with_speed_and_lowers_the_yaw_rate_at_speed() {
    let u = CarInput::new(0.08, 0.45);
    // At speed (2 m/s, gain 1/(1 + 0.8²) = 0.61) the same command turns the car less…
    let fast_nominal = drive(&CarScenario::floor(), rolling(2.0), u, 0.5);
    let fast_gain = drive(&gain_speed(2.5), rolling(2.0), u, 0.5);
    let (w0, w1) = (
        fast_nominal.last().unwrap().omega,
        fast_gain.last().unwrap().omega,
    );
    assert!(w0 > 0.5, "nominal yaw rate {w0}");
    assert!(w1 < 0.8 * w0, "yaw rate {w1} with the effect vs {w0}");
    assert!(w1 > 0.0, "the gain never reverses the steering: {w1}");
    // …while at walking pace (0.3 m/s held by throttle 0.2, gain 0.986) it is almost the
    // nominal car.
    let slow_nominal = drive(
        &CarScenario::floor(),
        rolling(0.3),
        CarInput::new(0.2, 0.2),
        0.3,
    );
    let slow_gain = drive(&gain_speed(2.5), rolling(0.3), CarInput::new(0.2, 0.2), 0.3);
    let (s0, s1) = (
        slow_nominal.last().unwrap().omega,
        slow_gain.last().unwrap().omega,
    );
    assert!(s1 < s0 && s1 > 0.95 * s0, "slow: {s1} vs {s0}");
}

#[test]
fn steering_gain_is_the_documented_formula_after_the_limit_and_before_the_offset() {
    let mut s = gain_speed(2.0);
    s.effects.steering_offset = Some(SteeringOffset {
        enabled: true,
        offset: 0.03,
    });
    let mut w = CarWorld::new(&s).unwrap();
    w.reset(rolling(2.0)).unwrap();
    // A command beyond the limit is clamped to 0.35 first, then scaled, then offset.
    w.step(CarInput::new(1.0, 0.4), 0.01).unwrap();
    let vx = w.state().vx;
    assert_eq!(w.servo_angle(), 0.35);
    let expected = 0.35 / (1.0 + (vx / 2.0).powi(2)) + 0.03;
    assert!(
        (w.wheel_angle() - expected).abs() < 1e-12,
        "{} vs {expected}",
        w.wheel_angle()
    );
    let g = SteeringGainSpeed {
        enabled: true,
        v0: 2.0,
    };
    assert_eq!(g.gain(2.0), 0.5);
    assert_eq!(g.gain(-2.0), 0.5);
    assert_eq!(g.gain(0.0), 1.0);
}

#[test]
fn steering_rate_limit_bounds_the_servo_rate_and_delays_the_turn() {
    let rate = 3.0;
    let s = rate_limited(rate, 0.0);
    let mut w = CarWorld::new(&s).unwrap();
    w.reset(rolling(1.0)).unwrap();
    let mut angles = vec![w.servo_angle()];
    // Full left, then full right: steps of 0.35 and 0.7 rad.
    for k in 0..60 {
        let cmd = if k < 30 { 0.35 } else { -0.35 };
        w.step(CarInput::new(cmd, 0.3), 0.01).unwrap();
        angles.push(w.servo_angle());
    }
    for (k, pair) in angles.windows(2).enumerate() {
        assert!(
            (pair[1] - pair[0]).abs() <= rate * 0.01 + 1e-12,
            "step {k}: {} → {}",
            pair[0],
            pair[1]
        );
    }
    // It does reach the command: 0.35 rad at 3 rad/s takes 0.117 s, 0.7 rad 0.233 s.
    assert!((angles[12] - 0.35).abs() < 1e-12, "{}", angles[12]);
    assert!((angles[11] - 0.33).abs() < 1e-9, "{}", angles[11]);
    assert!((angles[60] + 0.35).abs() < 1e-12, "{}", angles[60]);
    assert!(angles[40] > -0.35 + 0.05, "{}", angles[40]);
    // The yaw response lags the nominal car's after a steering step.
    let u = CarInput::new(0.3, 0.3);
    let nominal = drive(&CarScenario::floor(), rolling(1.0), u, 0.1);
    let limited = drive(&s, rolling(1.0), u, 0.1);
    assert!(
        limited[5].psi < 0.7 * nominal[5].psi,
        "{} vs {}",
        limited[5].psi,
        nominal[5].psi
    );
}

#[test]
fn steering_servo_lag_is_first_order_and_resets_with_the_state() {
    // A fast servo (the rate limit never binds) with τ = 0.1 s: after τ it is at 1 − 1/e.
    let s = rate_limited(100.0, 0.1);
    let mut w = CarWorld::new(&s).unwrap();
    w.reset(rolling(1.0)).unwrap();
    for _ in 0..10 {
        w.step(CarInput::new(0.2, 0.3), 0.01).unwrap();
    }
    let expected = 0.2 * (1.0 - (-1.0f64).exp());
    assert!(
        (w.servo_angle() - expected).abs() < 1e-9,
        "{} vs {expected}",
        w.servo_angle()
    );
    // The servo is state: a reset puts it back to straight, and the rerun is bit-identical.
    let before: Vec<_> = {
        w.reset(rolling(1.0)).unwrap();
        assert_eq!(w.servo_angle(), 0.0);
        (0..50)
            .map(|k| {
                w.step(CarInput::new(0.3 * (k as f64 * 0.3).sin(), 0.4), 0.01)
                    .unwrap()
            })
            .collect()
    };
    let mut fresh = CarWorld::new(&s).unwrap();
    fresh.reset(rolling(1.0)).unwrap();
    let again: Vec<_> = (0..50)
        .map(|k| {
            fresh
                .step(CarInput::new(0.3 * (k as f64 * 0.3).sin(), 0.4), 0.01)
                .unwrap()
        })
        .collect();
    assert_eq!(before, again);
}

#[test]
fn band_and_annulus_regions_contain_the_documented_points() {
    let band = Region {
        shape: RegionShape::Band,
        centre: [0.0, 0.5],
        angle: std::f64::consts::FRAC_PI_4,
        width: 0.2,
        ..Region::default()
    };
    // Along the 45° line through (0, 0.5), however far: inside.
    assert!(band.contains([10.0, 10.5]));
    assert!(band.contains([-3.0, -2.5]));
    // 0.09 m off the line (perpendicular): inside; 0.11 m: outside.
    let n = [
        -std::f64::consts::FRAC_1_SQRT_2,
        std::f64::consts::FRAC_1_SQRT_2,
    ];
    assert!(band.contains([0.09 * n[0], 0.5 + 0.09 * n[1]]));
    assert!(!band.contains([0.11 * n[0], 0.5 + 0.11 * n[1]]));
    assert!(!band.contains([0.0, 0.0]));
    let ring = Region {
        shape: RegionShape::Annulus,
        centre: [1.0, 0.0],
        radius: 0.5,
        inner_radius: 0.3,
        ..Region::default()
    };
    assert!(!ring.contains([1.0, 0.0]), "the hole is outside");
    assert!(ring.contains([1.4, 0.0]));
    assert!(ring.contains([1.0, -0.3]));
    assert!(!ring.contains([1.6, 0.0]));
}

#[test]
fn grip_band_lowers_grip_inside_and_changes_nothing_outside() {
    // Steady cornering on a circle of ≈ 0.3 m radius around (0, 0.3).
    let u = CarInput::new(0.25, 0.3);
    let lateral = |t: &[CarState]| t.last().map(|s| s.vx * s.omega).unwrap_or(0.0);
    let band = |centre: [f64; 2]| {
        let mut s = CarScenario::floor();
        s.effects.grip_patch = Some(GripPatch {
            enabled: true,
            scale: 0.5,
            region: Region {
                shape: RegionShape::Band,
                centre,
                angle: 0.4,
                width: 1.5,
                ..Region::default()
            },
        });
        s
    };
    let nominal = drive(&CarScenario::floor(), rolling(1.0), u, 6.0);
    let inside = drive(&band([0.0, 0.3]), rolling(1.0), u, 6.0);
    let outside = drive(&band([0.0, 5.0]), rolling(1.0), u, 6.0);
    assert!(
        lateral(&inside) < 0.85 * lateral(&nominal),
        "{} vs {}",
        lateral(&inside),
        lateral(&nominal)
    );
    assert_eq!(outside, nominal);
}

fn push(s: &PushScenario, start: Pose2, a: PushAction) -> PushOutcome {
    let mut w = PushWorld::new(s).unwrap();
    w.reset(start).unwrap();
    w.apply(a).unwrap()
}

fn grain(ratio: f64, angle: f64) -> PushScenario {
    let mut s = PushScenario::free();
    s.effects.anisotropic_friction = Some(AnisotropicFriction {
        enabled: true,
        ratio,
        angle,
    });
    s
}

#[test]
fn anisotropic_table_holds_across_the_grain_and_slides_along_it() {
    // Tilt 0.15 rad: above the friction angle along the grain (atan 0.1 = 0.0997), below the
    // one across it (atan 0.2 = 0.197). Grain along x (μ_x = 0.1, μ_y = 0.2).
    let tilted = |direction: f64| {
        let mut s = grain(2.0, 0.0);
        s.effects.table_tilt = Some(TableTilt {
            enabled: true,
            direction,
            angle: 0.15,
        });
        s
    };
    let start = Pose2::new(0.5, 0.0, 0.0);
    let settle = |s: &PushScenario| {
        let mut w = PushWorld::new(s).unwrap();
        w.reset(start).unwrap();
        for _ in 0..250 {
            w.step();
        }
        w.block_pose()
    };
    let along = settle(&tilted(0.0));
    let across = settle(&tilted(std::f64::consts::FRAC_PI_2));
    assert!(
        along.x - start.x > 0.01,
        "downhill along the grain: {along:?}"
    );
    assert!(
        across.distance(start) < 1e-6,
        "across the grain: {across:?}"
    );
    // The isotropic table lets both slide (μ = 0.1 either way).
    let mut iso = PushScenario::free();
    iso.effects.table_tilt = tilted(std::f64::consts::FRAC_PI_2).effects.table_tilt;
    assert!(settle(&iso).y - start.y > 0.01);
}

#[test]
fn anisotropic_table_makes_a_push_across_the_grain_veer_towards_it() {
    // The block faces 45° between grain (x, low μ) and cross direction (y, high μ). A
    // frictionless pusher pushes the middle of its back face along its heading: on an
    // isotropic table it goes straight (dx = dy); here the friction force must point back along
    // the heading, which needs a velocity mostly along the grain: dx > dy.
    let start = Pose2::new(0.4, 0.0, std::f64::consts::FRAC_PI_4);
    let a = PushAction::new(0.0, 0.0, 1.0);
    let iso = push(&PushScenario::free(), start, a);
    let dx0 = iso.final_pose.x - start.x;
    let dy0 = iso.final_pose.y - start.y;
    assert!((dx0 - dy0).abs() < 1e-3, "isotropic: {dx0} {dy0}");
    let o = push(&grain(2.0, 0.0), start, a);
    let (dx, dy) = (o.final_pose.x - start.x, o.final_pose.y - start.y);
    assert!(dy < 0.8 * dx, "anisotropic: dx {dx} dy {dy}");
    // A push straight along the grain or across it goes straight (no torque, no veer).
    for theta in [0.0, std::f64::consts::FRAC_PI_2] {
        let s0 = Pose2::new(0.4, 0.0, theta);
        let o = push(&grain(2.0, 0.0), s0, a);
        let moved = [o.final_pose.x - s0.x, o.final_pose.y - s0.y];
        let side = -theta.sin() * moved[0] + theta.cos() * moved[1];
        assert!(side.abs() < 1e-4, "θ {theta}: sideways {side}");
        assert!((o.final_pose.theta - theta).abs() < 1e-3);
    }
}

#[test]
fn ratio_one_is_isotropic_and_the_grain_applies_on_a_patch_too() {
    let start = Pose2::new(0.4, 0.0, 0.3);
    let a = PushAction::new(0.5, 0.4, 0.8);
    let nominal = push(&PushScenario::free(), start, a);
    let one = push(&grain(1.0, 0.7), start, a);
    assert!(
        one.final_pose.distance(nominal.final_pose) < 1e-5,
        "{:?} vs {:?}",
        one.final_pose,
        nominal.final_pose
    );
    assert!((one.final_pose.theta - nominal.final_pose.theta).abs() < 1e-4);
    // On a patch of μ = 0.2 with the grain along x: a tilt of 0.3 rad along y (below
    // atan 0.4 = 0.38) holds, though it would slide on the isotropic patch (atan 0.2 = 0.197).
    let on_patch = |ratio: f64| {
        let mut s = grain(ratio, 0.0);
        s.effects.friction_patch = Some(FrictionPatch {
            enabled: true,
            mu: 0.2,
            region: Region {
                centre: [0.5, 0.0],
                size: [1.0, 1.0],
                ..Region::default()
            },
        });
        s.effects.table_tilt = Some(TableTilt {
            enabled: true,
            direction: std::f64::consts::FRAC_PI_2,
            angle: 0.3,
        });
        let mut w = PushWorld::new(&s).unwrap();
        w.reset(Pose2::new(0.5, 0.0, 0.0)).unwrap();
        for _ in 0..250 {
            w.step();
        }
        w.block_pose().y
    };
    assert!(on_patch(2.0).abs() < 1e-6);
    assert!(on_patch(1.0) > 0.01);
}

fn car_all_new() -> CarScenario {
    let mut s = CarScenario::floor();
    s.effects.steering_gain_speed = Some(SteeringGainSpeed::default());
    s.effects.steering_rate_limit = Some(SteeringRateLimit {
        enabled: true,
        rate: 3.0,
        tau: 0.05,
    });
    s.effects.grip_patch = Some(GripPatch {
        enabled: true,
        scale: 0.6,
        region: Region {
            shape: RegionShape::Annulus,
            centre: [0.0, 0.0],
            radius: 1.2,
            inner_radius: 0.6,
            ..Region::default()
        },
    });
    s.effects.command_delay = Some(CommandDelay::default());
    s
}

#[test]
fn command_delay_applies_every_command_the_delay_later() {
    let mut s = CarScenario::floor();
    s.effects.command_delay = Some(CommandDelay {
        enabled: true,
        delay: 0.06,
    });
    let cmd = |k: usize| {
        CarInput::new(
            0.3 * (k as f64 * 0.13).sin(),
            0.2 + 0.3 * ((k / 17) % 2) as f64,
        )
    };
    let start = rolling(1.0);
    let (mut late, mut now) = (
        CarWorld::new(&s).unwrap(),
        CarWorld::new(&CarScenario::floor()).unwrap(),
    );
    for round in 0..2 {
        // after a reset the car holds the neutral command until the first one arrives
        late.reset(start).unwrap();
        now.reset(start).unwrap();
        for k in 0..200 {
            let a = late.step(cmd(k), 0.01).unwrap();
            let given = if k < 6 {
                CarInput::default()
            } else {
                cmd(k - 6)
            };
            let b = now.step(given, 0.01).unwrap();
            assert!(
                (a.x - b.x).abs() + (a.y - b.y).abs() + (a.omega - b.omega).abs() < 1e-12,
                "round {round} step {k}: {a:?} vs {b:?}"
            );
        }
    }
    // it changes the run: the commands act late
    let plain = drive(&CarScenario::floor(), start, CarInput::new(0.3, 0.5), 0.3);
    let delayed = drive(&s, start, CarInput::new(0.3, 0.5), 0.3);
    assert!(
        delayed[5].omega.abs() < 1e-12 && plain[5].omega > 0.1,
        "{:?} {:?}",
        delayed[5],
        plain[5]
    );
    assert!((delayed.last().unwrap().psi - plain.last().unwrap().psi).abs() > 0.01);
    assert_eq!(s.effects.active(), ["command_delay"]);
}

#[test]
fn new_effects_are_deterministic_for_any_thread_count() {
    let explorer = CarExplorer {
        duration: 5.0,
        ..CarExplorer::default()
    };
    let s = car_all_new();
    let a = generate_car_episodes(&s, &explorer, 11, 3, 1).unwrap();
    let b = generate_car_episodes(&s, &explorer, 11, 3, 2).unwrap();
    assert_eq!(format!("{a:?}"), format!("{b:?}"));
    let nominal = generate_car_episodes(&CarScenario::floor(), &explorer, 11, 3, 1).unwrap();
    assert_ne!(format!("{a:?}"), format!("{nominal:?}"));

    let push_explorer = PushExplorer {
        pushes_per_episode: 3,
        ..PushExplorer::default()
    };
    let p = grain(2.0, 0.5);
    let a = generate_push_episodes(&p, &push_explorer, 5, 2, 1).unwrap();
    let b = generate_push_episodes(&p, &push_explorer, 5, 2, 2).unwrap();
    assert_eq!(format!("{a:?}"), format!("{b:?}"));
    let nominal = generate_push_episodes(&PushScenario::free(), &push_explorer, 5, 2, 1).unwrap();
    assert_ne!(format!("{a:?}"), format!("{nominal:?}"));
}

#[test]
fn switched_off_new_effects_change_no_bit() {
    let explorer = CarExplorer {
        duration: 5.0,
        ..CarExplorer::default()
    };
    let mut off = car_all_new();
    for e in [
        off.effects
            .steering_gain_speed
            .as_mut()
            .map(|e| &mut e.enabled),
        off.effects
            .steering_rate_limit
            .as_mut()
            .map(|e| &mut e.enabled),
        off.effects.grip_patch.as_mut().map(|e| &mut e.enabled),
        off.effects.command_delay.as_mut().map(|e| &mut e.enabled),
    ]
    .into_iter()
    .flatten()
    {
        *e = false;
    }
    assert!(off.effects.active().is_empty());
    let a = generate_car_episodes(&off, &explorer, 3, 2, 1).unwrap();
    let b = generate_car_episodes(&CarScenario::floor(), &explorer, 3, 2, 1).unwrap();
    assert_eq!(format!("{a:?}"), format!("{b:?}"));

    let mut p = grain(2.0, 0.5);
    if let Some(e) = &mut p.effects.anisotropic_friction {
        e.enabled = false;
    }
    let push_explorer = PushExplorer {
        pushes_per_episode: 3,
        ..PushExplorer::default()
    };
    let a = generate_push_episodes(&p, &push_explorer, 5, 1, 1).unwrap();
    let b = generate_push_episodes(&PushScenario::free(), &push_explorer, 5, 1, 1).unwrap();
    assert_eq!(format!("{a:?}"), format!("{b:?}"));
}

#[test]
fn perturbed_car_parameters_are_seeded_and_within_the_fraction() {
    let nominal = CarParams::default();
    let a = nominal.perturbed(7, 0.1).unwrap();
    assert_eq!(a, nominal.perturbed(7, 0.1).unwrap());
    assert_ne!(a, nominal.perturbed(8, 0.1).unwrap());
    let pairs = [
        (a.mass, nominal.mass),
        (a.inertia_z, nominal.inertia_z),
        (a.lf, nominal.lf),
        (a.lr, nominal.lr),
        (a.front.b, nominal.front.b),
        (a.front.c, nominal.front.c),
        (a.front.d, nominal.front.d),
        (a.rear.b, nominal.rear.b),
        (a.rear.c, nominal.rear.c),
        (a.rear.d, nominal.rear.d),
        (a.cm1, nominal.cm1),
        (a.cm2, nominal.cm2),
        (a.cr0, nominal.cr0),
        (a.cr2, nominal.cr2),
    ];
    let factors: Vec<f64> = pairs.iter().map(|(p, n)| p / n).collect();
    for (i, f) in factors.iter().enumerate() {
        assert!((0.9..=1.1).contains(f) && *f != 1.0, "parameter {i}: ×{f}");
    }
    // Independent factors, not one common scale.
    assert!(factors.windows(2).any(|w| (w[0] - w[1]).abs() > 1e-3));
    assert_eq!(a.steering_max, nominal.steering_max);
    assert_eq!(a.substep, nominal.substep);
    assert_eq!(nominal.perturbed(7, 0.0).unwrap(), nominal);
    // The perturbed car drives differently.
    let mut s = CarScenario::floor();
    let u = CarInput::new(0.2, 0.4);
    let base = drive(&s, rolling(1.0), u, 1.0);
    s = s.perturbed(7, 0.1).unwrap();
    assert_ne!(drive(&s, rolling(1.0), u, 1.0), base);
    // A fraction that could make a parameter ≤ 0 is refused.
    for bad in [1.0, -0.1, f64::NAN] {
        let e = nominal.perturbed(7, bad).unwrap_err();
        assert!(matches!(e, SimError::Input { .. }), "{e}");
        assert!(e.to_string().contains("fraction"), "{e}");
    }
}

#[test]
fn perturbed_push_scenarios_are_seeded_and_within_the_fraction() {
    let nominal = PushScenario::free();
    let a = nominal.perturbed(3, 0.1).unwrap();
    assert_eq!(a, nominal.perturbed(3, 0.1).unwrap());
    assert_ne!(a, nominal.perturbed(4, 0.1).unwrap());
    for (p, n) in [
        (a.block.size[0], nominal.block.size[0]),
        (a.block.size[1], nominal.block.size[1]),
        (a.block.mass, nominal.block.mass),
        (a.block.table_friction, nominal.block.table_friction),
        (a.block.obstacle_friction, nominal.block.obstacle_friction),
        (a.pusher.radius, nominal.pusher.radius),
    ] {
        let f = p / n;
        assert!((0.9..=1.1).contains(&f) && f != 1.0, "×{f}");
    }
    assert_eq!(a.pusher.speed, nominal.pusher.speed);
    assert_eq!(a.effects, nominal.effects);
    assert!(nominal.perturbed(3, 1.5).is_err());
}

fn err_key(r: Result<impl std::fmt::Debug, SimError>) -> String {
    let e = r.expect_err("must be rejected");
    e.key().map(str::to_string).unwrap_or_else(|| e.to_string())
}

#[test]
fn bad_values_of_the_new_keys_are_named() {
    let car = CarScenario::from_toml_str;
    assert_eq!(
        err_key(car("[effects.steering_gain_speed]\nv0 = 0.0\n")),
        "effects.steering_gain_speed.v0"
    );
    assert_eq!(
        err_key(car("[effects.steering_rate_limit]\nrate = -3.0\n")),
        "effects.steering_rate_limit.rate"
    );
    assert_eq!(
        err_key(car("[effects.steering_rate_limit]\ntau = -0.1\n")),
        "effects.steering_rate_limit.tau"
    );
    assert_eq!(
        err_key(car(
            "[effects.grip_patch]\nregion = { shape = \"band\", width = 0.0 }\n"
        )),
        "effects.grip_patch.region.width"
    );
    let e = car(
        "[effects.grip_patch]\nregion = { shape = \"annulus\", radius = 0.5, inner_radius = 0.5 }\n",
    )
    .unwrap_err();
    assert_eq!(e.key(), Some("effects.grip_patch.region.inner_radius"));
    assert!(
        e.to_string()
            .contains("must be < effects.grip_patch.region.radius (0.5)"),
        "{e}"
    );
    assert_eq!(
        err_key(car("[effects.command_delay]\ndelay = 1.5\n")),
        "effects.command_delay.delay"
    );
    let e = car("[effects.steering_rate_limit]\nrat = 3.0\n")
        .unwrap_err()
        .to_string();
    assert!(e.contains("effects.steering_rate_limit.rat"), "{e}");
    assert!(e.contains("unknown field"), "{e}");
    let e =
        PushScenario::from_toml_str("[effects.anisotropic_friction]\nratio = 0.0\n").unwrap_err();
    assert_eq!(e.key(), Some("effects.anisotropic_friction.ratio"));
    assert!(e.to_string().contains("got 0"), "{e}");
    assert_eq!(
        err_key(PushScenario::from_toml_str(
            "[effects.anisotropic_friction]\nangle = nan\n"
        )),
        "effects.anisotropic_friction.angle"
    );
    // And good values parse, in any combination.
    let s = car(
        "[effects.steering_gain_speed]\nv0 = 2.0\n[effects.steering_rate_limit]\nrate = 3.0\ntau = 0.05\n\
         [effects.grip_patch]\nregion = { shape = \"band\", centre = [0.0, 0.3], angle = 0.5, width = 0.6 }\n",
    )
    .unwrap();
    assert_eq!(
        s.effects.active(),
        ["grip_patch", "steering_gain_speed", "steering_rate_limit"]
    );
    assert_eq!(CarScenario::from_toml_str(&s.to_toml_string()).unwrap(), s);
}

fn scenarios() -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../launch_scripts/scenarios")
}

#[test]
fn bundled_scenarios_of_the_new_effects_load_with_the_documented_values() {
    let car = |f: &str| CarScenario::from_file(scenarios().join(f)).unwrap();
    let s = car("car_steering_gain.toml");
    assert_eq!(s.effects.active(), ["steering_gain_speed"]);
    let s = car("car_steering_rate.toml");
    assert_eq!(s.effects.active(), ["steering_rate_limit"]);
    let s = car("car_grip_band.toml");
    assert_eq!(s.effects.active(), ["grip_patch"]);
    let g = s.effects.grip_patch.unwrap();
    assert_eq!(g.region.shape, RegionShape::Band);
    let s = car("car_drag_steering.toml");
    assert_eq!(s.effects.active(), ["aero_drag", "steering_offset"]);
    assert_eq!(
        s.effects.aero_drag,
        Some(AeroDrag {
            enabled: true,
            c: 0.01
        })
    );
    assert_eq!(
        s.effects.steering_offset,
        Some(SteeringOffset {
            enabled: true,
            offset: 0.03
        })
    );
    let p = PushScenario::from_file(scenarios().join("push_anisotropic.toml")).unwrap();
    assert_eq!(p.effects.active(), ["anisotropic_friction"]);
    assert_eq!(p.effects.anisotropic_friction.unwrap().ratio, 2.0);
    let p = PushScenario::from_file(scenarios().join("push_flat_pusher.toml")).unwrap();
    assert!(p.effects.active().is_empty());
    assert_eq!((p.pusher.pad_half_width, p.pusher.pad_yaw), (0.012, 0.0));
}

fn flat_pusher(half_width: f64, yaw: f64) -> PushScenario {
    let mut s = PushScenario::free();
    s.pusher.pad_half_width = half_width;
    s.pusher.pad_yaw = yaw;
    s
}

#[test]
fn a_flat_pusher_at_one_world_yaw_turns_the_block_towards_its_face() {
    // A centred straight push: the disc pushes the block straight on; a pad held at world yaw 0
    // touches a block turned by ±0.5 rad with one corner, off the face's middle, and the block
    // turns back towards the pad's yaw.
    let a = PushAction::new(0.0, 0.0, 1.0);
    for theta in [0.5, -0.5] {
        let start = Pose2::new(0.4, 0.0, theta);
        let disc = push(&PushScenario::free(), start, a);
        assert!(disc.contact_made);
        assert!(
            (disc.final_pose.theta - theta).abs() < 0.01,
            "disc: {disc:?}"
        );
        let pad = push(&flat_pusher(0.015, 0.0), start, a);
        assert!(pad.contact_made && !pad.lost_contact, "{pad:?}");
        let turned = pad.final_pose.theta - theta;
        assert!(
            turned * theta.signum() < -0.05,
            "θ {theta}: the pad turned the block by {turned}"
        );
        assert!(pad.final_pose.distance(start) > 0.05, "{pad:?}");
    }
    // aligned with the face, the pad pushes the block straight on like the disc
    let start = Pose2::new(0.4, 0.0, 0.3);
    let pad = push(&flat_pusher(0.015, 0.3), start, a);
    assert!((pad.final_pose.theta - 0.3).abs() < 0.01, "{pad:?}");
    // bad values name the key
    for (w, yaw, key) in [
        (-0.01, 0.0, "pusher.pad_half_width"),
        (0.01, f64::NAN, "pusher.pad_yaw"),
    ] {
        let e = PushWorld::new(&flat_pusher(w, yaw)).expect_err("refused");
        assert!(e.to_string().contains(key), "{e}");
    }
}
