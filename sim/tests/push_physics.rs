//! Physics sanity of the pushing world (Tu & Lin's action convention).

use dynlab_sim::{Pose2, PushAction, PushScenario, PushWorld, SupportLayout, wrap_angle};

fn push_from(scenario: &PushScenario, start: Pose2, action: PushAction) -> dynlab_sim::PushOutcome {
    let mut w = PushWorld::new(scenario).expect("valid scenario");
    w.reset(start).expect("finite pose");
    w.apply(action).expect("valid action")
}

#[test]
fn centre_push_translates_along_the_heading() {
    let s = PushScenario::free();
    let o = push_from(
        &s,
        Pose2::new(0.4, 0.0, 0.0),
        PushAction::new(0.0, 0.0, 1.0),
    );
    assert!(o.contact_made && !o.lost_contact);
    assert!((o.final_pose.x - 0.5).abs() < 2e-3, "x {}", o.final_pose.x);
    assert!(o.final_pose.y.abs() < 1e-4, "y {}", o.final_pose.y);
    assert!(
        o.final_pose.theta.abs() < 1e-3,
        "theta {}",
        o.final_pose.theta
    );
}

#[test]
fn centre_push_follows_a_rotated_block() {
    // The push direction is relative to the block heading: a block facing +y moves along +y.
    let s = PushScenario::free();
    let start = Pose2::new(0.4, 0.0, std::f64::consts::FRAC_PI_2);
    let o = push_from(&s, start, PushAction::new(0.0, 0.0, 0.5));
    assert!((o.final_pose.y - 0.05).abs() < 2e-3, "{:?}", o.final_pose);
    assert!((o.final_pose.x - 0.4).abs() < 1e-3, "{:?}", o.final_pose);
}

#[test]
fn off_centre_push_rotates_the_right_way() {
    // The pusher sits on the block's −x face at y = +p·b/2 and pushes along +x. Its force
    // (F, 0) acts at r = (−a/2, y_p) from the centre: torque r × F = −y_p F < 0, so a push left of
    // the centre line (p > 0) turns the block clockwise (θ decreases), and p < 0 the other way.
    let s = PushScenario::free();
    let start = Pose2::new(0.4, 0.0, 0.0);
    let left = push_from(&s, start, PushAction::new(0.8, 0.0, 1.0));
    let right = push_from(&s, start, PushAction::new(-0.8, 0.0, 1.0));
    assert!(
        left.final_pose.theta < -0.1,
        "p=+0.8 gives θ {}",
        left.final_pose.theta
    );
    assert!(
        right.final_pose.theta > 0.1,
        "p=−0.8 gives θ {}",
        right.final_pose.theta
    );
    // Mirror symmetry of the set-up.
    assert!((left.final_pose.theta + right.final_pose.theta).abs() < 1e-3);
    assert!((left.final_pose.y + right.final_pose.y).abs() < 1e-4);
    assert!((left.final_pose.x - right.final_pose.x).abs() < 1e-4);
    // The block still moves forward.
    assert!(left.final_pose.x > 0.42);
}

#[test]
fn block_on_its_corners_turns_less_than_on_a_grid() {
    // The frictional torque about the centre grows with the support points' distance from it:
    // on its four corners (c ≈ 0.71 a) the block resists turning more than on the uniform grid
    // (c ≈ 0.38 a), so the same off-centre push turns it less and moves it further.
    let start = Pose2::new(0.4, 0.0, 0.0);
    let push = PushAction::new(0.8, 0.0, 1.0);
    let grid = push_from(&PushScenario::free(), start, push);
    let mut corners = PushScenario::free();
    corners.block.support = SupportLayout::Corners;
    let on_corners = push_from(&corners, start, push);
    let (tg, tc) = (grid.final_pose.theta, on_corners.final_pose.theta);
    assert!(tc < -0.05 && tg < tc, "θ grid {tg}, corners {tc}");
    assert!(
        tc / tg < 0.8,
        "corners turn {:.2}× as much as the grid",
        tc / tg
    );
    assert!(on_corners.final_pose.x > grid.final_pose.x);
}

#[test]
fn push_length_sets_the_displacement() {
    let s = PushScenario::free();
    for l in [0.2, 0.5, 0.8, 1.0] {
        let o = push_from(&s, Pose2::new(0.3, 0.1, 0.0), PushAction::new(0.0, 0.0, l));
        let moved = o.final_pose.distance(o.start_pose);
        assert!(
            (moved - 0.1 * l).abs() < 2e-3,
            "ℓ = {l}: moved {moved} m, expected {} m",
            0.1 * l
        );
    }
    let o = push_from(
        &s,
        Pose2::new(0.3, 0.1, 0.0),
        PushAction::new(0.3, 0.4, 0.0),
    );
    assert!(
        o.final_pose.distance(o.start_pose) < 1e-4,
        "ℓ = 0 must not move the block"
    );
}

#[test]
fn block_stops_when_the_pusher_stops() {
    let s = PushScenario::free();
    let action = PushAction::new(0.4, -0.5, 1.0);
    let o = push_from(&s, Pose2::new(0.4, 0.0, 0.3), action);
    let motion = s.push_motion_time(&action);
    let after: Vec<_> = o
        .trajectory
        .iter()
        .filter(|p| p.t > motion + 0.02)
        .collect();
    assert!(after.len() >= 10, "settling must be sampled");
    for p in after {
        let drift = p.pose.distance(o.final_pose);
        let turn = wrap_angle(p.pose.theta - o.final_pose.theta).abs();
        assert!(
            drift < 1e-4 && turn < 1e-3,
            "still moving at t = {}: {drift} m, {turn} rad",
            p.t
        );
    }
    // And it was moving during the push.
    let mid = o
        .trajectory
        .iter()
        .find(|p| p.t > 0.5 * motion)
        .expect("sampled");
    assert!(mid.pose.distance(o.start_pose) > 0.02);
}

#[test]
fn block_at_rest_stays_at_rest() {
    let s = PushScenario::free();
    let mut w = PushWorld::new(&s).unwrap();
    let start = Pose2::new(0.45, -0.05, 1.0);
    w.reset(start).unwrap();
    for _ in 0..500 {
        w.step();
    }
    assert_eq!(
        w.block_pose().to_array(),
        Pose2::new(0.45, -0.05, 1.0)
            .to_array()
            .map(|v| v as f32 as f64)
    );
}

#[test]
fn pusher_sliding_off_the_edge_reports_lost_contact() {
    let s = PushScenario::free();
    let o = push_from(
        &s,
        Pose2::new(0.4, 0.0, 0.0),
        PushAction::new(1.0, 1.5, 1.0),
    );
    assert!(o.contact_made);
    assert!(
        o.lost_contact,
        "a nearly tangential push at the corner must slide off"
    );
    let o = push_from(
        &s,
        Pose2::new(0.4, 0.0, 0.0),
        PushAction::new(0.0, 0.0, 1.0),
    );
    assert!(!o.lost_contact);
}

#[test]
fn obstacle_stops_the_block_and_is_reported() {
    // The obstacle of the paper spans x ∈ [0.55, 0.65], y ∈ [−0.05, 0.45].
    let s = PushScenario::obstacle();
    let o = push_from(
        &s,
        Pose2::new(0.48, 0.2, 0.0),
        PushAction::new(0.0, 0.0, 1.0),
    );
    assert!(o.obstacle_collision);
    assert!(
        o.final_pose.x < 0.5 + 1e-3,
        "block went into the obstacle: {:?}",
        o.final_pose
    );
    let free = push_from(
        &PushScenario::free(),
        Pose2::new(0.48, 0.2, 0.0),
        PushAction::new(0.0, 0.0, 1.0),
    );
    assert!(!free.obstacle_collision);
    assert!(free.final_pose.x > 0.57);
}

#[test]
fn trajectory_is_sampled_at_the_configured_rate() {
    let mut s = PushScenario::free();
    s.sim.sample_rate = 50.0;
    let o = push_from(
        &s,
        Pose2::new(0.4, 0.0, 0.0),
        PushAction::new(0.0, 0.0, 1.0),
    );
    assert_eq!(o.trajectory[0].t, 0.0);
    for w in o.trajectory.windows(2) {
        assert!(w[1].t > w[0].t && w[1].t - w[0].t <= 0.02 + 1e-9);
    }
    assert!((o.trajectory.last().unwrap().t - o.duration).abs() < 1e-9);
    assert_eq!(o.trajectory.last().unwrap().pose, o.final_pose);
}

#[test]
fn bad_actions_and_poses_are_errors_not_panics() {
    let mut w = PushWorld::new(&PushScenario::free()).unwrap();
    assert!(w.apply(PushAction::new(f64::NAN, 0.0, 0.5)).is_err());
    assert!(w.apply(PushAction::new(0.0, 2.0, 0.5)).is_err());
    assert!(w.apply(PushAction::new(0.0, 0.0, 1.5)).is_err());
    assert!(w.reset(Pose2::new(f64::INFINITY, 0.0, 0.0)).is_err());
    assert_eq!(
        PushAction::new(3.0, -9.0, 2.0).clamped(),
        PushAction::new(1.0, -std::f64::consts::FRAC_PI_2, 1.0)
    );
}
