//! Symmetry augmentation of pushing data.
//!
//! Quasi-static pushing on a homogeneous table does not depend on where the block is or which way
//! it faces: the push (p, φ, ℓ) is given in the block's frame, so a recorded push trajectory moved
//! and turned rigidly in the plane is an equally valid trajectory. A network that takes the world
//! pose as input (Tu & Lin's 6 → 100 → 100 → 3) cannot know this and extrapolates badly outside the
//! poses it was trained on — their data all start at one pose. [`augment_se2`] adds rigidly moved
//! copies of the training trajectories so the network learns the symmetry from data.
//!
//! Each copy of a trajectory is turned about its first pose by an angle that puts its start heading
//! uniformly in the data's start-heading range widened by π/2 on each side, then moved so that its
//! start lies uniformly in the bounding box of all positions widened by half its size on each side
//! (at least 0.05 m). Headings stay continuous (not wrapped), as recorded.

use dynlab_dynamics::data::{SplitMix64, StateTrajectory};

/// Rigidly moved copies of pushing trajectories (states `(x, y, θ)`): `copies` per trajectory,
/// drawn from `seed` (see the module documentation for the ranges). The originals are not
/// included. Trajectories with another state dimension or no states are skipped.
pub fn augment_se2(trajs: &[StateTrajectory], copies: usize, seed: u64) -> Vec<StateTrajectory> {
    let push: Vec<&StateTrajectory> = trajs
        .iter()
        .filter(|t| t.dim_s == 3 && !t.is_empty())
        .collect();
    if push.is_empty() || copies == 0 {
        return Vec::new();
    }
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    let (mut th_lo, mut th_hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for t in &push {
        for s in t.s.chunks_exact(3) {
            for d in 0..2 {
                lo[d] = lo[d].min(s[d]);
                hi[d] = hi[d].max(s[d]);
            }
        }
        th_lo = th_lo.min(t.s[2]);
        th_hi = th_hi.max(t.s[2]);
    }
    for d in 0..2 {
        let grow = (0.5 * (hi[d] - lo[d])).max(0.05);
        lo[d] -= grow;
        hi[d] += grow;
    }
    let half_pi = std::f64::consts::FRAC_PI_2;
    let (th_lo, th_hi) = (th_lo - half_pi, th_hi + half_pi);
    let mut rng = SplitMix64::new(seed ^ 0x5e2a_0c0f_fee1_900d);
    let mut uniform =
        |a: f64, b: f64| a + (b - a) * ((rng.next_u64() >> 11) as f64 / (1u64 << 53) as f64);
    let mut out = Vec::with_capacity(push.len() * copies);
    for t in &push {
        let (x0, y0, th0) = (t.s[0], t.s[1], t.s[2]);
        for _ in 0..copies {
            let heading = uniform(th_lo, th_hi);
            let start = [uniform(lo[0], hi[0]), uniform(lo[1], hi[1])];
            let turn = heading - th0;
            let (sn, cs) = turn.sin_cos();
            let mut s = Vec::with_capacity(t.s.len());
            for p in t.s.chunks_exact(3) {
                let (dx, dy) = (p[0] - x0, p[1] - y0);
                s.extend([
                    start[0] + cs * dx - sn * dy,
                    start[1] + sn * dx + cs * dy,
                    p[2] + turn,
                ]);
            }
            out.push(StateTrajectory { s, ..(*t).clone() });
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn traj(poses: &[[f64; 3]]) -> StateTrajectory {
        StateTrajectory {
            s: poses.iter().flatten().copied().collect(),
            u: [0.3, 0.1, 0.5].repeat(poses.len()),
            dim_s: 3,
            dim_u: 3,
            dt: 1.0,
        }
    }

    /// Displacement of pose `b` seen from pose `a` (block frame) and the turn.
    fn local(a: &[f64], b: &[f64]) -> [f64; 3] {
        let (sn, cs) = a[2].sin_cos();
        let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
        [cs * dx + sn * dy, -sn * dx + cs * dy, b[2] - a[2]]
    }

    #[test]
    fn copies_keep_every_push_in_the_block_frame() {
        let t = traj(&[[0.4, 0.0, 0.6], [0.47, 0.03, 0.75], [0.52, 0.09, 0.5]]);
        let aug = augment_se2(std::slice::from_ref(&t), 5, 3);
        assert_eq!(aug.len(), 5);
        for a in &aug {
            assert_eq!(a.u, t.u);
            for i in 0..2 {
                let want = local(&t.s[3 * i..3 * i + 3], &t.s[3 * i + 3..3 * i + 6]);
                let got = local(&a.s[3 * i..3 * i + 3], &a.s[3 * i + 3..3 * i + 6]);
                for d in 0..3 {
                    assert!((want[d] - got[d]).abs() < 1e-12, "{want:?} vs {got:?}");
                }
            }
        }
        // The copies really move: starts differ from the original and from each other.
        assert!(
            aug.iter()
                .all(|a| (a.s[0] - 0.4).abs() + (a.s[2] - 0.6).abs() > 1e-6)
        );
        assert!((aug[0].s[0] - aug[1].s[0]).abs() > 1e-9);
    }

    #[test]
    fn starts_stay_in_the_widened_ranges_and_the_seed_decides() {
        let t = traj(&[[0.4, 0.0, 0.6], [0.5, 0.1, 0.7]]);
        let a = augment_se2(std::slice::from_ref(&t), 200, 9);
        for c in &a {
            assert!((0.35..=0.55).contains(&c.s[0]), "x {}", c.s[0]);
            assert!((-0.05..=0.15).contains(&c.s[1]), "y {}", c.s[1]);
            let lim = std::f64::consts::FRAC_PI_2;
            assert!((0.6 - lim..=0.6 + lim).contains(&c.s[2]), "θ {}", c.s[2]);
        }
        assert_eq!(a, augment_se2(std::slice::from_ref(&t), 200, 9));
        assert_ne!(a, augment_se2(std::slice::from_ref(&t), 200, 10));
    }
}
