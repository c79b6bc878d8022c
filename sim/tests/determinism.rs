//! Determinism contracts: the same seed gives bit-identical episodes, the thread count does
//! not change them, and different seeds differ. Also the shape of generated episodes.

use dynlab_sim::{
    CarExplorer, CarScenario, Episode, PushExplorer, PushScenario, Record, SimRng, Track,
    concatenate, generate_car_episodes, generate_push_episodes,
};

fn bits(e: &[Episode]) -> String {
    format!("{e:?}")
}

fn short_push() -> PushExplorer {
    PushExplorer {
        pushes_per_episode: 3,
        ..PushExplorer::default()
    }
}

fn short_car() -> CarExplorer {
    CarExplorer {
        duration: 5.0,
        ..CarExplorer::default()
    }
}

#[test]
fn push_episodes_same_seed_same_bits_any_thread_count() {
    let s = PushScenario::obstacle();
    let one = generate_push_episodes(&s, &short_push(), 42, 6, 1).unwrap();
    let again = generate_push_episodes(&s, &short_push(), 42, 6, 1).unwrap();
    let four = generate_push_episodes(&s, &short_push(), 42, 6, 4).unwrap();
    assert_eq!(bits(&one), bits(&again));
    assert_eq!(bits(&one), bits(&four));
    let other = generate_push_episodes(&s, &short_push(), 43, 6, 4).unwrap();
    assert_ne!(bits(&one), bits(&other));
    // Episodes differ from one another (per-episode seeds).
    assert_ne!(
        format!("{:?}", one[0].samples),
        format!("{:?}", one[1].samples)
    );
}

#[test]
fn car_episodes_same_seed_same_bits_any_thread_count() {
    let s = CarScenario::floor();
    let one = generate_car_episodes(&s, &short_car(), 9, 5, 1).unwrap();
    let four = generate_car_episodes(&s, &short_car(), 9, 5, 4).unwrap();
    let again = generate_car_episodes(&s, &short_car(), 9, 5, 3).unwrap();
    assert_eq!(bits(&one), bits(&four));
    assert_eq!(bits(&one), bits(&again));
    assert_ne!(
        bits(&one),
        bits(&generate_car_episodes(&s, &short_car(), 10, 5, 1).unwrap())
    );
}

#[test]
fn push_episode_layout() {
    let s = PushScenario::free();
    let ex = PushExplorer::default();
    let eps = generate_push_episodes(&s, &ex, 1, 2, 2).unwrap();
    for e in &eps {
        let actions: Vec<_> = e
            .samples
            .iter()
            .filter(|x| matches!(x.record, Record::PushAction(_)))
            .collect();
        let poses: Vec<_> = e
            .samples
            .iter()
            .filter(|x| matches!(x.record, Record::BlockPose(_)))
            .collect();
        assert_eq!(actions.len(), 10);
        // 10 Hz over 20 s, both ends included.
        assert_eq!(poses.len(), 201);
        for (k, a) in actions.iter().enumerate() {
            assert_eq!(a.t_ns, k as u64 * 2_000_000_000);
            if let Record::PushAction(a) = a.record {
                assert!(a.validate().is_ok());
            }
        }
        for w in e.samples.windows(2) {
            assert!(w[0].t_ns <= w[1].t_ns);
        }
        // At an action's stamp the pose comes first (the state the action was chosen in).
        let i = e
            .samples
            .iter()
            .position(|x| matches!(x.record, Record::PushAction(_)))
            .unwrap();
        assert!(matches!(e.samples[i - 1].record, Record::BlockPose(_)));
        assert_eq!(e.samples[i - 1].t_ns, e.samples[i].t_ns);
    }
}

#[test]
fn car_explorer_stays_on_the_floor_and_drifts_sometimes() {
    let s = CarScenario::floor();
    let eps = generate_car_episodes(&s, &CarExplorer::default(), 3, 6, 2).unwrap();
    let mut states = 0usize;
    let mut drifting = 0usize;
    let mut cmds = 0usize;
    for e in &eps {
        for x in &e.samples {
            match x.record {
                Record::CarOdom(st) => {
                    states += 1;
                    assert!(s.arena.contains([st.x, st.y]), "left the floor: {st:?}");
                    if st.speed() > 0.3 && st.sideslip().abs() > 20f64.to_radians() {
                        drifting += 1;
                    }
                }
                Record::CarCmd(_) => cmds += 1,
                _ => {}
            }
        }
    }
    assert_eq!(states, 6 * 3001);
    assert_eq!(cmds, 6 * 1500);
    assert!(drifting > 20, "only {drifting} drifting samples");
}

#[test]
fn car_explorer_follows_a_track() {
    let track = Track::oval(1.5, 0.8, 0.2, 200).unwrap();
    let s = CarScenario::on_track(track.clone());
    let eps = generate_car_episodes(&s, &CarExplorer::default(), 5, 3, 2).unwrap();
    let (mut on, mut all) = (0usize, 0usize);
    let mut progress = 0.0;
    for e in &eps {
        let mut last = None;
        for x in &e.samples {
            if let Record::CarOdom(st) = x.record {
                all += 1;
                on += usize::from(track.contains([st.x, st.y]));
                if let Some((px, py)) = last {
                    progress += f64::hypot(st.x - px, st.y - py);
                }
                last = Some((st.x, st.y));
            }
        }
    }
    assert!(on as f64 > 0.85 * all as f64, "on track {on}/{all}");
    // It actually drives around (30 s × 3 episodes at about 1 m/s).
    assert!(progress > 40.0, "{progress}");
}

#[test]
fn concatenation_lays_episodes_end_to_end() {
    let s = PushScenario::free();
    let eps = generate_push_episodes(&s, &short_push(), 1, 3, 1).unwrap();
    let all = concatenate(&eps, 1_000, 60_000_000_000);
    assert_eq!(
        all.len(),
        eps.iter().map(|e| e.samples.len()).sum::<usize>()
    );
    assert_eq!(all[0].t_ns, 1_000);
    for w in all.windows(2) {
        assert!(w[0].t_ns <= w[1].t_ns);
    }
    let second = all[eps[0].samples.len()].t_ns;
    assert_eq!(second, 1_000 + eps[0].duration_ns + 60_000_000_000);
}

#[test]
fn a_stream_sought_past_normals_continues_it_bitwise() {
    for start in [0usize, 1, 2, 7] {
        let mut base = SimRng::new(41);
        // A spare normal pending (odd start) or not, and a uniform drawn in between.
        for _ in 0..start {
            base.normal();
        }
        if start == 2 {
            base.uniform();
        }
        let mut seq = base.clone();
        let drawn: Vec<f64> = (0..40).map(|_| seq.normal()).collect();
        for skip in [0usize, 1, 2, 3, 10, 33] {
            let mut ahead = base.after_normals(skip);
            let rest: Vec<f64> = (skip..40).map(|_| ahead.normal()).collect();
            assert!(
                rest.iter()
                    .zip(&drawn[skip..])
                    .all(|(a, b)| a.to_bits() == b.to_bits()),
                "start {start}, skip {skip}"
            );
        }
        // After the seek the stream goes on as the sequential one does.
        let mut ahead = base.after_normals(40);
        assert_eq!(ahead.next_u64(), seq.next_u64(), "start {start}");
    }
}
