//! The racer on stale poses, without DDS: the hold (zero throttle, last steering) on the node's
//! steady clock, and a state estimate that starts over cleanly after a gap or a clock restart.

use std::path::PathBuf;

use dynlab_control::racing::{Racer, RacerSettings, true_car_model};
use dynlab_nodes::racer::{HoldEvent, RaceClock, StaleHold, held_input};
use dynlab_sim::{CarScenario, Track};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn physics() -> dynlab_learn::Model {
    let s = CarScenario::from_file(root().join("launch_scripts/scenarios/car_track.toml")).unwrap();
    true_car_model(&s.car, 0.01).unwrap()
}

fn track() -> Track {
    Track::from_file(root().join("launch_scripts/tracks/default.json")).unwrap()
}

/// Poses of a car driving straight along x at `v` m/s from `x0`, 100 Hz from stamp `t0`.
fn straight(t0: f64, x0: f64, v: f64, n: usize) -> Vec<(f64, [f64; 3])> {
    (0..n)
        .map(|k| {
            let dt = 0.01 * k as f64;
            (t0 + dt, [x0 + v * dt, 0.5, 0.0])
        })
        .collect()
}

#[test]
fn after_a_gap_the_estimate_restarts_without_a_velocity_spike() {
    let model = physics();
    let t = track();
    let racer = Racer::new(&model, &t, RacerSettings::default()).unwrap();
    let mut clock = RaceClock::new(racer, &model, 3).unwrap();
    for (s, p) in straight(0.0, 0.0, 2.0, 30) {
        clock.on_pose(s, p);
    }
    let (_, before) = clock.estimate().unwrap();
    assert!((before[3] - 2.0).abs() < 1e-6, "vx {}", before[3]);
    // the poses stop for 1 s; meanwhile the car coasted 1.2 m and stopped
    let after = straight(1.29, 1.78, 0.0, 15);
    // the estimator left alone fits one polynomial across the gap: while its window holds poses
    // from both sides it reads the gap as motion (the car stands still after it)
    let worst = {
        let racer = Racer::new(&model, &t, RacerSettings::default()).unwrap();
        let mut naive = RaceClock::new(racer, &model, 3).unwrap();
        for (s, p) in straight(0.0, 0.0, 2.0, 30) {
            naive.on_pose(s, p);
        }
        let mut worst = 0.0f64;
        for (s, p) in &after[..14] {
            naive.on_pose(*s, *p);
            let v = naive.estimate().unwrap().1;
            worst = worst.max(v[3].abs());
        }
        worst
    };
    // (measured: 0.26 m/s at the first fresh pose, for a car standing still)
    assert!(
        worst > 0.2,
        "the spliced window should misread the gap; |vx| ≤ {worst}"
    );
    // restarted: no estimate until a full window of fresh poses, then the true speed
    clock.restart();
    assert!(clock.estimate().is_none());
    assert!(clock.plan(1.29).unwrap().is_none(), "nothing to plan from");
    for (k, (s, p)) in after.iter().enumerate() {
        clock.on_pose(*s, *p);
        assert_eq!(clock.estimate().is_some(), k == 14, "pose {k}");
    }
    let (stamp, s) = clock.estimate().unwrap();
    assert!((stamp - 1.43).abs() < 1e-9);
    assert!(
        s[3].abs() < 1e-6 && s[4].abs() < 1e-6 && s[5].abs() < 1e-6,
        "{s:?}"
    );
    assert!((s[0] - 1.78).abs() < 1e-6, "{s:?}");
    // and the racer plans at once from the fresh estimate (the solve schedule was reset too)
    let planned = clock.plan(stamp).unwrap().expect("a plan from fresh poses");
    assert!((planned.apply_at - (stamp + 0.03)).abs() < 1e-9);
}

#[test]
fn a_restarted_simulator_clock_is_followed_after_restart() {
    let model = physics();
    let t = track();
    let racer = Racer::new(&model, &t, RacerSettings::default()).unwrap();
    let mut clock = RaceClock::new(racer, &model, 3).unwrap();
    for (s, p) in straight(40.0, 0.0, 1.0, 20) {
        clock.on_pose(s, p);
    }
    assert!(clock.plan(40.19).unwrap().is_some());
    // a new simulator run: stamps from 0 again. Without a restart every pose is dropped as
    // older than the window ...
    let fresh = straight(0.0, 0.0, 0.0, 15);
    let mut stuck = clock.estimate().unwrap().0;
    for (s, p) in &fresh {
        clock.on_pose(*s, *p);
        stuck = clock.estimate().unwrap().0;
    }
    assert!((stuck - 40.19).abs() < 1e-9, "old stamps kept: {stuck}");
    // ... with it the new clock is followed
    clock.restart();
    for (s, p) in &fresh {
        clock.on_pose(*s, *p);
    }
    let (stamp, s) = clock.estimate().unwrap();
    assert!((stamp - 0.14).abs() < 1e-9);
    assert!(s[3].abs() < 1e-6);
    let planned = clock.plan(stamp).unwrap().expect("a plan on the new clock");
    assert!(
        planned.step.input[1] > 0.0,
        "races again from rest: {:?}",
        planned.step.input
    );
}

#[test]
fn the_hold_is_zero_throttle_with_the_last_steering_said_once_and_repeated_each_period() {
    assert_eq!(held_input(None), [0.0, 0.0]);
    assert_eq!(held_input(Some([0.2, 0.8])), [0.2, 0.0]);
    let mut h = StaleHold::new(0.2, 0.05).unwrap();
    assert_eq!(h.check(10.0), None, "no pose yet: nothing to hold");
    assert_eq!(h.due(10.0), None);
    for k in 0..10 {
        assert_eq!(h.on_pose(0.01 * k as f64, 5.0 + 0.01 * k as f64), None);
    }
    h.published([0.25, 0.9]);
    assert!(!h.holding());
    assert_eq!(h.check(0.2), None);
    assert_eq!(h.due(0.2), None, "no hold while poses are fresh");
    let e = h.check(0.30).expect("stale after 0.21 s");
    assert!(matches!(e, HoldEvent::Stale { silent } if (silent - 0.21).abs() < 1e-9));
    assert!(h.holding());
    assert_eq!(h.due(0.30), Some([0.25, 0.0]), "held at once");
    assert_eq!(h.due(0.33), None);
    assert_eq!(h.due(0.35), Some([0.25, 0.0]), "and every period");
    for k in 0..50 {
        assert_eq!(h.check(0.36 + 0.01 * k as f64), None, "said once");
    }
    // poses come back from a restarted simulator
    let e = h.on_pose(2.0, 0.01).expect("resumption reported");
    assert_eq!(
        e,
        HoldEvent::Resumed {
            gap: 2.0 - 0.09,
            restarted: true
        }
    );
    assert_eq!(h.on_pose(2.01, 0.02), None, "said once");
    assert!(
        h.holding(),
        "still holding until a fresh solve is published"
    );
    assert_eq!(h.due(2.01), Some([0.25, 0.0]));
    h.published([0.1, 0.7]);
    assert!(!h.holding());
    assert_eq!(h.due(3.0), None);
    // a looped bag: stamps back without a gap
    assert_eq!(
        h.on_pose(2.02, 0.0),
        Some(HoldEvent::Restarted {
            from: 0.02,
            to: 0.0
        })
    );
    assert!(
        !h.holding(),
        "a clock restart without a gap is no reason to hold"
    );
    assert!(StaleHold::new(0.0, 0.05).is_err());
}
