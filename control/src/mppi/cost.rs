//! The pushing task's cost: per-sample quadratic goal cost with a wrapped angle error, a
//! terminal cost, and a collision cost from a separating-axis test between the block and
//! obstacle rectangles.

use dynlab_sim::{OrientedBox, PushScenario, wrap_angle};

/// A rectangle for the separating-axis test, with its axes precomputed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rect {
    /// Centre `[x, y]` \[m\].
    pub centre: [f64; 2],
    /// Half side lengths \[m\].
    pub half: [f64; 2],
    /// Unit axes (the rectangle's x and y directions).
    axes: [[f64; 2]; 2],
}

impl Rect {
    /// A rectangle centred at `centre`, rotated by `angle` \[rad\], with half sides `half`.
    pub fn new(centre: [f64; 2], angle: f64, half: [f64; 2]) -> Self {
        let (s, c) = angle.sin_cos();
        Self {
            centre,
            half,
            axes: [[c, s], [-s, c]],
        }
    }

    /// From the simulator's oriented box, grown by `margin` on every side.
    pub fn from_box(b: &OrientedBox, margin: f64) -> Self {
        Self::new(
            [b.pose.x, b.pose.y],
            b.pose.theta,
            [b.half[0] + margin, b.half[1] + margin],
        )
    }

    fn radius_on(&self, a: [f64; 2]) -> f64 {
        self.half[0] * (self.axes[0][0] * a[0] + self.axes[0][1] * a[1]).abs()
            + self.half[1] * (self.axes[1][0] * a[0] + self.axes[1][1] * a[1]).abs()
    }

    /// Separating-axis test: whether the two rectangles overlap (touching counts).
    pub fn overlaps(&self, other: &Rect) -> bool {
        let d = [
            other.centre[0] - self.centre[0],
            other.centre[1] - self.centre[1],
        ];
        for a in self.axes.iter().chain(other.axes.iter()) {
            let dist = (d[0] * a[0] + d[1] * a[1]).abs();
            if dist > self.radius_on(*a) + other.radius_on(*a) {
                return false;
            }
        }
        true
    }
}

/// What MPPI drives towards and what it avoids.
#[derive(Debug, Clone, PartialEq)]
pub struct PushTask {
    /// Goal pose `[x, y, θ]`.
    pub goal: [f64; 3],
    /// Half side lengths of the block \[m\].
    pub block_half: [f64; 2],
    /// Obstacles (already inflated by any margin).
    pub obstacles: Vec<Rect>,
}

impl PushTask {
    /// A task without obstacles for a block of half sides `block_half`.
    pub fn free(goal: [f64; 3], block_half: [f64; 2]) -> Self {
        Self {
            goal,
            block_half,
            obstacles: Vec::new(),
        }
    }

    /// The scenario's goal, block and obstacles, the obstacles grown by `margin` \[m\].
    pub fn from_scenario(scenario: &PushScenario, margin: f64) -> Self {
        Self {
            goal: scenario.goal,
            block_half: [0.5 * scenario.block.size[0], 0.5 * scenario.block.size[1]],
            obstacles: scenario
                .obstacles
                .iter()
                .map(|o| Rect::from_box(&o.footprint(), margin))
                .collect(),
        }
    }

    /// Whether the block at pose `s = [x, y, θ]` overlaps an obstacle.
    pub fn in_collision(&self, s: [f64; 3]) -> bool {
        if self.obstacles.is_empty() {
            return false;
        }
        let b = Rect::new([s[0], s[1]], s[2], self.block_half);
        self.obstacles.iter().any(|o| o.overlaps(&b))
    }
}

/// The goal error `s − goal` with the angle error wrapped to (−π, π].
pub fn goal_error(s: [f64; 3], goal: [f64; 3]) -> [f64; 3] {
    [s[0] - goal[0], s[1] - goal[1], wrap_angle(s[2] - goal[2])]
}

/// `eᵀ diag(q) e` of one state, with `e` from [`goal_error`].
pub fn quadratic(s: [f64; 3], goal: [f64; 3], q: [f64; 3]) -> f64 {
    let e = goal_error(s, goal);
    q[0] * e[0] * e[0] + q[1] * e[1] * e[1] + q[2] * e[2] * e[2]
}

/// Weights of a trajectory cost.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CostWeights {
    /// Per-step goal weights.
    pub q: [f64; 3],
    /// Terminal goal weights.
    pub q_terminal: [f64; 3],
    /// Cost per predicted state in collision.
    pub collision: f64,
    /// Also test the midpoint of consecutive poses.
    pub swept: bool,
}

/// The cost of one predicted trajectory `x₁ … x_T` (`traj` is `T × 3`, row-major) starting from
/// `x0`: `Σ_t (x_t − g)ᵀQ(x_t − g) + c·in_collision(x_t)` plus `(x_T − g)ᵀQ_f(x_T − g)`.
/// A trajectory with a non-finite state costs `f64::INFINITY`.
pub fn trajectory_cost(task: &PushTask, w: &CostWeights, x0: [f64; 3], traj: &[f32]) -> f64 {
    let mut cost = 0.0;
    let mut prev = x0;
    let mut last = x0;
    for x in traj.chunks_exact(3) {
        let s = [f64::from(x[0]), f64::from(x[1]), f64::from(x[2])];
        if !(s[0].is_finite() && s[1].is_finite() && s[2].is_finite()) {
            return f64::INFINITY;
        }
        cost += quadratic(s, task.goal, w.q);
        if w.collision > 0.0 && !task.obstacles.is_empty() {
            let mut hit = task.in_collision(s);
            if !hit && w.swept {
                let mid = [
                    0.5 * (prev[0] + s[0]),
                    0.5 * (prev[1] + s[1]),
                    prev[2] + 0.5 * wrap_angle(s[2] - prev[2]),
                ];
                hit = task.in_collision(mid);
            }
            if hit {
                cost += w.collision;
            }
        }
        prev = s;
        last = s;
    }
    cost + quadratic(last, task.goal, w.q_terminal)
}
