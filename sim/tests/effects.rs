//! Each hidden effect changes the trajectory measurably and in the expected direction, and
//! an effect that is configured but switched off changes not a single bit.

use dynlab_sim::car::{AeroDrag, GripPatch, MotorLag, SteeringOffset};
use dynlab_sim::push::{ComOffset, FrictionPatch, PusherFriction, TableTilt};
use dynlab_sim::{
    CarExplorer, CarInput, CarScenario, CarState, CarWorld, Pose2, PushAction, PushExplorer,
    PushOutcome, PushScenario, PushWorld, Region, car_episode, push_episode,
};

fn push(s: &PushScenario, start: Pose2, a: PushAction) -> PushOutcome {
    let mut w = PushWorld::new(s).unwrap();
    w.reset(start).unwrap();
    w.apply(a).unwrap()
}

fn drive(s: &CarScenario, start: CarState, u: CarInput, seconds: f64) -> Vec<CarState> {
    let mut w = CarWorld::new(s).unwrap();
    w.reset(start).unwrap();
    (0..(seconds * 100.0).round() as usize)
        .map(|_| w.step(u, 0.01).unwrap())
        .collect()
}

const START: Pose2 = Pose2 {
    x: 0.4,
    y: 0.0,
    theta: 0.0,
};
const CENTRE_PUSH: PushAction = PushAction {
    location: 0.0,
    angle: 0.0,
    length: 1.0,
};

#[test]
fn com_offset_rotates_a_centre_push() {
    // The table's friction resultant sits under the centre of mass, at +y. The pusher's force
    // (F, 0) acts on the line y = 0, i.e. at −c_y from it: torque −(−c_y)F > 0, so the block
    // turns counter-clockwise (θ increases).
    let mut s = PushScenario::free();
    s.effects.com_offset = Some(ComOffset {
        enabled: true,
        offset: [0.0, 0.02],
    });
    let o = push(&s, START, CENTRE_PUSH);
    let nominal = push(&PushScenario::free(), START, CENTRE_PUSH);
    assert!(nominal.final_pose.theta.abs() < 1e-3);
    assert!(o.final_pose.theta > 0.05, "θ {}", o.final_pose.theta);
}

#[test]
fn table_tilt_drifts_downhill_and_holds_below_the_friction_angle() {
    let downhill_y = |angle: f64| {
        let mut s = PushScenario::free();
        s.effects.table_tilt = Some(TableTilt {
            enabled: true,
            direction: std::f64::consts::FRAC_PI_2,
            angle,
        });
        s
    };
    // Below the friction angle (atan 0.1 ≈ 0.0997 rad) a resting block sticks exactly…
    let s = downhill_y(0.05);
    let mut w = PushWorld::new(&s).unwrap();
    w.reset(START).unwrap();
    for _ in 0..500 {
        w.step();
    }
    assert!(
        w.block_pose().distance(START) < 1e-6,
        "{:?}",
        w.block_pose()
    );
    // …but while pushed (sliding) it drifts downhill (+y).
    let o = push(&s, START, CENTRE_PUSH);
    assert!(o.final_pose.y > 0.01, "y {}", o.final_pose.y);
    // Above the friction angle it slides on its own.
    let mut w = PushWorld::new(&downhill_y(0.15)).unwrap();
    w.reset(START).unwrap();
    for _ in 0..250 {
        w.step();
    }
    assert!(w.block_pose().y > 0.01);
}

#[test]
fn friction_patch_under_half_the_block_turns_it() {
    // Higher μ on the +y half moves the friction resultant to +y: as for the com offset the
    // block turns counter-clockwise. The patch also slows nothing else: x still advances.
    let mut s = PushScenario::free();
    s.effects.friction_patch = Some(FrictionPatch {
        enabled: true,
        mu: 0.3,
        region: Region {
            centre: [0.5, 0.25],
            size: [1.0, 0.5],
            ..Region::default()
        },
    });
    let o = push(&s, START, CENTRE_PUSH);
    assert!(o.final_pose.theta > 0.05, "θ {}", o.final_pose.theta);
    // A patch the block never touches changes nothing.
    if let Some(p) = &mut s.effects.friction_patch {
        p.region.centre = [0.9, 0.4];
        p.region.size = [0.05, 0.05];
    }
    let far = push(&s, START, CENTRE_PUSH);
    let nominal = push(&PushScenario::free(), START, CENTRE_PUSH);
    assert_eq!(far.final_pose, nominal.final_pose);
}

#[test]
fn pusher_friction_drags_the_block_sideways() {
    // An oblique push (φ = 0.8 rad towards +y): a frictionless pusher slides along the face,
    // a frictional one drags the block towards +y.
    let a = PushAction::new(0.3, 0.8, 1.0);
    let nominal = push(&PushScenario::free(), START, a);
    let mut s = PushScenario::free();
    s.effects.pusher_friction = Some(PusherFriction {
        enabled: true,
        mu: 0.5,
    });
    let o = push(&s, START, a);
    assert!(
        o.final_pose.y > nominal.final_pose.y + 0.003,
        "{} vs {}",
        o.final_pose.y,
        nominal.final_pose.y
    );
}

#[test]
fn aero_drag_lowers_top_speed() {
    let mut s = CarScenario::floor();
    let nominal = drive(&s, CarState::default(), CarInput::new(0.0, 1.0), 15.0);
    s.effects.aero_drag = Some(AeroDrag {
        enabled: true,
        c: 0.01,
    });
    let dragged = drive(&s, CarState::default(), CarInput::new(0.0, 1.0), 15.0);
    let (v0, v1) = (nominal.last().unwrap().vx, dragged.last().unwrap().vx);
    assert!(v1 < v0 - 0.5, "top speed {v1} with drag vs {v0}");
}

#[test]
fn steering_offset_turns_straight_driving() {
    let mut s = CarScenario::floor();
    let nominal = drive(&s, CarState::default(), CarInput::new(0.0, 0.2), 4.0);
    s.effects.steering_offset = Some(SteeringOffset {
        enabled: true,
        offset: 0.03,
    });
    let offset = drive(&s, CarState::default(), CarInput::new(0.0, 0.2), 4.0);
    assert_eq!(nominal.last().unwrap().psi, 0.0);
    // A positive offset steers left: heading and y increase.
    assert!(offset.last().unwrap().psi > 0.05);
    assert!(offset.last().unwrap().y > 0.02);
}

#[test]
fn motor_lag_delays_acceleration_but_not_top_speed() {
    let mut s = CarScenario::floor();
    let nominal = drive(&s, CarState::default(), CarInput::new(0.0, 0.5), 10.0);
    s.effects.motor_lag = Some(MotorLag {
        enabled: true,
        tau: 0.2,
    });
    let lagged = drive(&s, CarState::default(), CarInput::new(0.0, 0.5), 10.0);
    assert!(
        lagged[19].vx < 0.8 * nominal[19].vx,
        "{} vs {}",
        lagged[19].vx,
        nominal[19].vx
    );
    let (a, b) = (nominal.last().unwrap().vx, lagged.last().unwrap().vx);
    assert!((a - b).abs() < 0.01 * a);
}

#[test]
fn grip_patch_lowers_cornering_acceleration() {
    let mut s = CarScenario::floor();
    let u = CarInput::new(0.25, 0.3);
    let rolling = CarState {
        vx: 1.0,
        ..CarState::default()
    };
    let lateral = |t: &[CarState]| t.last().map(|s| s.vx * s.omega).unwrap_or(0.0);
    let nominal = drive(&s, rolling, u, 6.0);
    s.effects.grip_patch = Some(GripPatch {
        enabled: true,
        scale: 0.5,
        region: Region {
            centre: [0.0, 0.0],
            size: [100.0, 100.0],
            ..Region::default()
        },
    });
    let slippery = drive(&s, rolling, u, 6.0);
    assert!(
        lateral(&slippery) < 0.85 * lateral(&nominal),
        "{} vs {}",
        lateral(&slippery),
        lateral(&nominal)
    );
}

fn bits_push(s: &PushScenario) -> String {
    let e = push_episode(
        s,
        &PushExplorer {
            pushes_per_episode: 4,
            ..PushExplorer::default()
        },
        7,
        0,
    )
    .unwrap();
    format!("{:?}", e.samples)
}

fn bits_car(s: &CarScenario) -> String {
    let e = car_episode(
        s,
        &CarExplorer {
            duration: 8.0,
            ..CarExplorer::default()
        },
        7,
        0,
    )
    .unwrap();
    format!("{:?}", e.samples)
}

#[test]
fn switched_off_effects_leave_the_nominal_push_world_bit_identical() {
    let nominal = PushScenario::free();
    let mut off = nominal.clone();
    off.effects.com_offset = Some(ComOffset {
        enabled: false,
        ..ComOffset::default()
    });
    off.effects.table_tilt = Some(TableTilt {
        enabled: false,
        ..TableTilt::default()
    });
    off.effects.friction_patch = Some(FrictionPatch {
        enabled: false,
        region: Region {
            centre: [0.4, 0.0],
            ..Region::default()
        },
        ..FrictionPatch::default()
    });
    off.effects.pusher_friction = Some(PusherFriction {
        enabled: false,
        mu: 0.9,
    });
    assert!(off.effects.active().is_empty());
    assert_eq!(bits_push(&nominal), bits_push(&off));
    // And switching one on does change the data (the comparison can fail).
    let mut on = off.clone();
    if let Some(e) = &mut on.effects.com_offset {
        e.enabled = true;
    }
    assert_ne!(bits_push(&nominal), bits_push(&on));
}

#[test]
fn switched_off_effects_leave_the_nominal_car_world_bit_identical() {
    let nominal = CarScenario::floor();
    let mut off = nominal.clone();
    off.effects.aero_drag = Some(AeroDrag {
        enabled: false,
        c: 0.05,
    });
    off.effects.motor_lag = Some(MotorLag {
        enabled: false,
        tau: 0.3,
    });
    off.effects.steering_offset = Some(SteeringOffset {
        enabled: false,
        offset: 0.1,
    });
    off.effects.grip_patch = Some(GripPatch {
        enabled: false,
        region: Region {
            centre: [0.0, 0.0],
            size: [10.0, 10.0],
            ..Region::default()
        },
        ..GripPatch::default()
    });
    assert!(off.effects.active().is_empty());
    assert_eq!(bits_car(&nominal), bits_car(&off));
    let mut on = off.clone();
    if let Some(e) = &mut on.effects.steering_offset {
        e.enabled = true;
    }
    assert_ne!(bits_car(&nominal), bits_car(&on));
}
