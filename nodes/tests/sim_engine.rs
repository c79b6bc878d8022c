//! The simulator node's engine against the simulator library used directly, and the bag layout
//! of simulated data against what the recorder stores.

use dynlab_nodes::record::offered_qos;
use dynlab_ros::qos;
use dynlab_sim::{
    CarInput, CarScenario, CarWorld, MeasurementNoise, Pose2, PushAction, PushScenario, PushWorld,
    Record, Sample,
};
use dynlab_simbridge::engine::{Emit, EngineConfig, EngineError, Mode, SimEngine};
use dynlab_simbridge::messages::{OfferedQos, SimBagWriter, SimWorld, sim_topics};

fn poses(emits: &[Emit]) -> Vec<(u64, Pose2)> {
    emits
        .iter()
        .filter_map(|e| match e {
            Emit::Pose { t_ns, pose } => Some((*t_ns, *pose)),
            _ => None,
        })
        .collect()
}

fn lockstep(pose_rate: f64) -> EngineConfig {
    EngineConfig {
        mode: Mode::LockStep,
        pose_rate,
        ..EngineConfig::default()
    }
}

#[test]
fn lockstep_pushes_equal_push_world_apply_bit_for_bit() {
    let mut scenario = PushScenario::free();
    scenario.noise = MeasurementNoise::none();
    let actions = [
        PushAction::new(0.0, 0.0, 0.5),
        PushAction::new(0.8, -0.5, 1.0),
        PushAction::new(-0.6, 0.9, 0.2),
    ];
    let mut engine = SimEngine::push(&scenario, lockstep(scenario.sim.sample_rate)).unwrap();
    let mut emits = Vec::new();
    engine.start(&mut emits);
    assert!(!engine.has_work());
    assert!(
        !engine.advance(&mut emits).unwrap(),
        "lock-step must wait for an action"
    );
    let mut got = poses(&emits);
    emits.clear();
    for a in actions {
        engine.push_action(a, &mut emits);
        engine.run_until_idle(&mut emits).unwrap();
    }
    got.extend(poses(&emits));

    // The same pushes with the library's whole-push call.
    let mut world = PushWorld::new(&scenario).unwrap();
    let mut expected = vec![(0u64, world.block_pose())];
    let mut t0 = 0u64;
    for a in actions {
        let outcome = world.apply(a).unwrap();
        for tp in &outcome.trajectory[1..] {
            expected.push((t0 + (tp.t * 1e9).round() as u64, tp.pose));
        }
        t0 += (outcome.duration * 1e9).round() as u64;
    }
    assert_eq!(got.len(), expected.len());
    for (g, e) in got.iter().zip(&expected) {
        assert_eq!(g, e);
    }
    assert_eq!(engine.time_ns(), t0);
    // the pushes moved the block
    assert!(got.last().unwrap().1.distance(expected[0].1) > 0.03);
    let starts = emits
        .iter()
        .filter(|e| matches!(e, Emit::PushStarted { .. }))
        .count();
    let dones = emits
        .iter()
        .filter(|e| matches!(e, Emit::PushDone { .. }))
        .count();
    assert_eq!((starts, dones), (3, 3));
}

#[test]
fn lockstep_car_holds_each_command_for_its_period() {
    let mut scenario = CarScenario::floor();
    scenario.noise = MeasurementNoise::none();
    let cfg = EngineConfig {
        lockstep_period: 0.05,
        ..lockstep(100.0)
    };
    let mut engine = SimEngine::car(&scenario, cfg).unwrap();
    let commands = [
        CarInput::new(0.1, 0.4),
        CarInput::new(-0.2, 0.8),
        CarInput::new(0.0, 0.0),
    ];
    let mut emits = Vec::new();
    for u in commands {
        engine.car_command(u, &mut emits);
    }
    let steps = engine.run_until_idle(&mut emits).unwrap();
    assert_eq!(steps, 15);
    let got = poses(&emits);

    let mut world = CarWorld::new(&scenario).unwrap();
    let mut expected = Vec::new();
    for (i, u) in commands.iter().enumerate() {
        for k in 0..5u64 {
            world.step(*u, 0.01).unwrap();
            expected.push(((i as u64 * 5 + k + 1) * 10_000_000, world.state().pose()));
        }
    }
    assert_eq!(got, expected);
    let odom = emits
        .iter()
        .filter(|e| matches!(e, Emit::Odom { .. }))
        .count();
    assert_eq!(odom, 15);
}

#[test]
fn real_time_car_holds_the_zero_command_after_the_timeout() {
    let mut scenario = CarScenario::floor();
    scenario.noise = MeasurementNoise::none();
    let cfg = EngineConfig {
        cmd_timeout: 0.2,
        ..EngineConfig::default()
    };
    let mut engine = SimEngine::car(&scenario, cfg).unwrap();
    let mut emits = Vec::new();
    let u = CarInput::new(0.1, 0.6);
    engine.car_command(u, &mut emits);
    for _ in 0..100 {
        assert!(engine.advance(&mut emits).unwrap());
    }
    // The same with the library: the command while at most 0.2 s old (checked at the start of
    // each 10 ms tick: ticks 0 … 20), then zero.
    let mut world = CarWorld::new(&scenario).unwrap();
    for i in 0..100 {
        let held = if i <= 20 { u } else { CarInput::default() };
        world.step(held, 0.01).unwrap();
    }
    assert_eq!(poses(&emits).last().unwrap().1, world.state().pose());
    let timeouts: Vec<u64> = emits
        .iter()
        .filter_map(|e| match e {
            Emit::CommandTimedOut { t_ns } => Some(*t_ns),
            _ => None,
        })
        .collect();
    assert_eq!(timeouts, [210_000_000]);
    // a new command ends the zero hold
    engine.car_command(u, &mut emits);
    let before = world.state().speed();
    for _ in 0..20 {
        engine.advance(&mut emits).unwrap();
    }
    let Some(Emit::Odom { state, .. }) =
        emits.iter().rev().find(|e| matches!(e, Emit::Odom { .. }))
    else {
        panic!("no odometry")
    };
    assert!(state.speed() > before, "{} vs {before}", state.speed());
}

#[test]
fn real_time_pushes_queue_and_poses_follow_the_rate() {
    let scenario = PushScenario::free();
    let mut engine = SimEngine::push(&scenario, EngineConfig::default()).unwrap();
    let mut emits = Vec::new();
    engine.push_action(PushAction::new(0.0, 0.0, 0.3), &mut emits);
    engine.push_action(PushAction::new(0.0, 0.0, 0.3), &mut emits);
    for _ in 0..2_500 {
        engine.advance(&mut emits).unwrap();
    }
    let p = poses(&emits);
    assert_eq!(p.len(), 2_500 / 5, "100 Hz poses at a 2 ms step");
    assert!(p.iter().all(|(t, _)| t % 10_000_000 == 0));
    let starts: Vec<u64> = emits
        .iter()
        .filter_map(|e| match e {
            Emit::PushStarted { t_ns, .. } => Some(*t_ns),
            _ => None,
        })
        .collect();
    let done: Vec<u64> = emits
        .iter()
        .filter_map(|e| match e {
            Emit::PushDone { t_ns, .. } => Some(*t_ns),
            _ => None,
        })
        .collect();
    assert_eq!(starts.len(), 2);
    assert_eq!(
        starts[1], done[0],
        "the queued push starts when the first has settled"
    );
}

#[test]
fn bad_rates_are_refused_naming_the_parameter() {
    let err = SimEngine::push(&PushScenario::free(), lockstep(300.0))
        .err()
        .unwrap();
    assert!(
        matches!(
            err,
            EngineError::Param {
                name: "pose_rate",
                ..
            }
        ),
        "{err}"
    );
    assert!(err.to_string().contains("whole steps"), "{err}");
    let err = SimEngine::push(&PushScenario::free(), lockstep(f64::NAN))
        .err()
        .unwrap();
    assert!(err.to_string().starts_with("parameter pose_rate"), "{err}");
    let cfg = EngineConfig {
        lockstep_period: 0.015,
        ..lockstep(100.0)
    };
    let err = SimEngine::car(&CarScenario::floor(), cfg).err().unwrap();
    assert!(
        err.to_string().starts_with("parameter lockstep_period"),
        "{err}"
    );
    let cfg = EngineConfig {
        cmd_timeout: 0.0,
        ..EngineConfig::default()
    };
    let err = SimEngine::car(&CarScenario::floor(), cfg).err().unwrap();
    assert!(
        err.to_string().starts_with("parameter cmd_timeout"),
        "{err}"
    );
}

#[test]
fn collected_bags_offer_the_qos_the_recorder_stores_for_the_live_nodes() {
    assert_eq!(
        OfferedQos::SensorData.recorded_profile(),
        offered_qos(&qos::sensor_data())
    );
    assert_eq!(
        OfferedQos::Reliable.recorded_profile(),
        offered_qos(&qos::default_profile())
    );
    assert_eq!(
        OfferedQos::Clock.recorded_profile(),
        offered_qos(&qos::clock())
    );
    let names: Vec<_> = sim_topics(SimWorld::Car, true)
        .iter()
        .map(|t| t.name)
        .collect();
    assert_eq!(names, ["/car/pose", "/car/cmd", "/car/odom", "/clock"]);
}

#[test]
fn sim_bag_writer_refuses_records_of_the_other_world() {
    let dir = tempfile::tempdir().unwrap();
    let mut w = SimBagWriter::create(
        &dir.path().join("b"),
        SimWorld::Push,
        false,
        Default::default(),
    )
    .unwrap();
    w.write(&Sample {
        t_ns: 0,
        record: Record::BlockPose(Pose2::new(0.4, 0.0, 0.1)),
    })
    .unwrap();
    let err = w
        .write(&Sample {
            t_ns: 1,
            record: Record::CarCmd(CarInput::new(0.0, 0.1)),
        })
        .unwrap_err();
    assert!(
        err.to_string()
            .contains("CarCmd record cannot go into a push bag"),
        "{err}"
    );
    let summary = w.finish().unwrap();
    assert_eq!(summary.message_count, 1);
}
