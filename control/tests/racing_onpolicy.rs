//! On-policy racing episodes: the records, their rates and stamps, determinism in the seed, and
//! that the racer actually races (the data is from the racing regime).

use dynlab_control::racing::{OnPolicySettings, racing_episode, true_car_model};
use dynlab_sim::{CarScenario, Record, Track};

fn setup() -> (CarScenario, Track) {
    let track = Track::oval(1.0, 0.5, 0.2, 120).unwrap();
    (CarScenario::on_track(track.clone()), track)
}

fn short() -> OnPolicySettings {
    OnPolicySettings {
        duration: 2.0,
        ..OnPolicySettings::default()
    }
}

#[test]
fn an_on_policy_episode_records_poses_odometry_and_commands_at_their_rates() {
    let (scenario, track) = setup();
    let model = true_car_model(&scenario.car, 0.01).unwrap();
    let e = racing_episode(&model, &scenario, &track, &short(), 11, 3).unwrap();
    assert_eq!((e.index, e.seed), (3, 11));
    let count = |f: fn(&Record) -> bool| e.samples.iter().filter(|s| f(&s.record)).count();
    // 2 s: 201 poses and odometry messages at 100 Hz, 40 commands at 20 Hz
    assert_eq!(count(|r| matches!(r, Record::CarPose(_))), 201);
    assert_eq!(count(|r| matches!(r, Record::CarOdom(_))), 201);
    assert_eq!(count(|r| matches!(r, Record::CarCmd(_))), 40);
    assert_eq!(e.duration_ns, 2_000_000_000);
    assert!(e.samples.windows(2).all(|w| w[0].t_ns <= w[1].t_ns));
    let cmds: Vec<_> = e
        .samples
        .iter()
        .filter_map(|s| match s.record {
            Record::CarCmd(u) => Some((s.t_ns, u)),
            _ => None,
        })
        .collect();
    assert!(cmds.iter().all(|(t, _)| t % 50_000_000 == 0));
    let lim = &scenario.car;
    assert!(
        cmds.iter()
            .all(|(_, u)| u.steering.abs() <= lim.steering_max
                && (lim.throttle_min..=lim.throttle_max).contains(&u.throttle))
    );
    // the racer races: the car is at speed on the track after 2 s
    let last = e
        .samples
        .iter()
        .rev()
        .find_map(|s| match s.record {
            Record::CarOdom(c) => Some(c),
            _ => None,
        })
        .unwrap();
    assert!(last.speed() > 1.0, "only {} m/s after 2 s", last.speed());
    assert!(track.contains([last.x, last.y]), "{last:?} left the track");
}

#[test]
fn on_policy_episodes_are_deterministic_in_the_seed_and_the_noise_perturbs_the_commands() {
    let (scenario, track) = setup();
    let model = true_car_model(&scenario.car, 0.01).unwrap();
    let s = OnPolicySettings {
        duration: 0.5,
        ..OnPolicySettings::default()
    };
    let a = racing_episode(&model, &scenario, &track, &s, 5, 0).unwrap();
    let b = racing_episode(&model, &scenario, &track, &s, 5, 0).unwrap();
    let c = racing_episode(&model, &scenario, &track, &s, 6, 0).unwrap();
    assert_eq!(a, b);
    assert_ne!(a, c);
    let quiet = OnPolicySettings {
        steering_noise: 0.0,
        throttle_noise: 0.0,
        ..s
    };
    let q = racing_episode(&model, &scenario, &track, &quiet, 5, 0).unwrap();
    let cmds = |e: &dynlab_sim::Episode| -> Vec<[f64; 2]> {
        e.samples
            .iter()
            .filter_map(|x| match x.record {
                Record::CarCmd(u) => Some([u.steering, u.throttle]),
                _ => None,
            })
            .collect()
    };
    // same start and reference speed (same seed), different commands only through the noise
    let (ca, cq) = (cmds(&a), cmds(&q));
    assert_eq!(ca.len(), cq.len());
    let diff: f64 = ca
        .iter()
        .zip(&cq)
        .map(|(x, y)| (x[0] - y[0]).abs() + (x[1] - y[1]).abs())
        .sum::<f64>()
        / ca.len() as f64;
    assert!(diff > 0.02, "noise changed the commands by only {diff}");
}

#[test]
fn bad_on_policy_settings_name_the_key() {
    let (scenario, track) = setup();
    let model = true_car_model(&scenario.car, 0.01).unwrap();
    for (s, key) in [
        (
            OnPolicySettings {
                speed_range: [2.0, 1.0],
                ..short()
            },
            "speed_range",
        ),
        (
            OnPolicySettings {
                steering_noise: -0.1,
                ..short()
            },
            "steering_noise",
        ),
        (
            OnPolicySettings {
                duration: 0.0,
                ..short()
            },
            "duration",
        ),
    ] {
        let err = racing_episode(&model, &scenario, &track, &s, 1, 0).unwrap_err();
        assert!(err.to_string().contains(key), "{err}");
    }
}
