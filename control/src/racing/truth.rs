//! The simulator's own car model as a `physics` model: the optimiser with perfect knowledge.

use dynlab_learn::dynamics::ode::Solver;
use dynlab_learn::dynamics::physics::PhysicsModel;
use dynlab_learn::{Model, ModelKind, StepJacobians, World};
use dynlab_sim::car::CarParams;
use dynlab_sim::{CarInput, CarScenario, CarState, CarWorld, wrap_angle};

use super::RacingError;
use super::plant::CarDynamics;

/// A `physics` car model with the simulator's parameters (`CarParams`), stepping `dt` seconds
/// with RK4 — the "true model" baseline of `dynlab eval race`.
///
/// It is the simulator's bicycle model, with the simulator's friction ellipse on the rear axle
/// when `params.friction_ellipse` is set; the low-speed regularisation differs below
/// ≈ 0.05 m/s. Hidden effects of a scenario are not included.
pub fn true_car_model(params: &CarParams, dt: f64) -> Result<Model, RacingError> {
    let mut p = PhysicsModel::car(&[]).map_err(|e| {
        RacingError::setting("physics", e.to_string(), "the nominal car model must build")
    })?;
    let values = [
        ("m", params.mass),
        ("Iz", params.inertia_z),
        ("lf", params.lf),
        ("lr", params.lr),
        ("Bf", params.front.b),
        ("Cf", params.front.c),
        ("Df", params.front.d),
        ("Br", params.rear.b),
        ("Cr", params.rear.c),
        ("Dr", params.rear.d),
        ("Cm1", params.cm1),
        ("Cm2", params.cm2),
        ("Cr0", params.cr0),
        ("Cr2", params.cr2),
        ("v_reg", params.slip_speed_floor),
        ("ellipse", if params.friction_ellipse { 1.0 } else { 0.0 }),
    ];
    for (name, v) in values {
        p.set_param(name, v)
            .map_err(|e| RacingError::setting("car", format!("{name} = {v}"), e.to_string()))?;
    }
    Ok(Model::new(
        ModelKind::Physics,
        World::Car,
        dt,
        None,
        None,
        Some(p),
        Solver::rk4(),
    )?)
}

/// The simulator itself as a car model: each step runs [`CarWorld::step`] from the given state
/// (same equations, substeps and hidden effects; a motor lag restarts from zero throttle each
/// step). Jacobians by central differences (one-sided at the input limits) — this is the
/// reference the learned model is measured against, not the exact-gradient path.
#[derive(Debug, Clone)]
pub struct SimCar {
    world: CarWorld,
    dt: f64,
}

impl SimCar {
    /// The simulator of `scenario` stepping `dt` seconds per model step.
    pub fn new(scenario: &CarScenario, dt: f64) -> Result<Self, RacingError> {
        if !(dt.is_finite() && dt > 0.0) {
            return Err(RacingError::setting("dt", dt, "the model step must be > 0"));
        }
        let mut sc = scenario.clone();
        sc.track_data = None;
        sc.arena.track = None;
        Ok(Self {
            world: CarWorld::new(&sc)?,
            dt,
        })
    }

    fn step1(&self, s: &[f64], u: [f64; 2]) -> [f64; 6] {
        let mut w = self.world.clone();
        let st = CarState {
            x: s[0],
            y: s[1],
            psi: s[2],
            vx: s[3],
            vy: s[4],
            omega: s[5],
        };
        if w.reset(st).is_err() {
            return [f64::NAN; 6];
        }
        match w.step(CarInput::new(u[0], u[1]), self.dt) {
            Ok(n) => [
                n.x,
                n.y,
                s[2] + wrap_angle(n.psi - s[2]),
                n.vx,
                n.vy,
                n.omega,
            ],
            Err(_) => [f64::NAN; 6],
        }
    }
}

impl CarDynamics for SimCar {
    fn dt(&self) -> f64 {
        self.dt
    }

    fn rollout(&self, s0: &[f64], actions: &[f64], out: &mut [f64]) -> Result<(), RacingError> {
        let m = s0.len() / 6;
        let k = actions.len() / (2 * m.max(1));
        let mut cur = s0.to_vec();
        for j in 0..k {
            for c in 0..m {
                let u = [actions[(j * m + c) * 2], actions[(j * m + c) * 2 + 1]];
                let n = self.step1(&cur[c * 6..c * 6 + 6], u);
                out[(j * m + c) * 6..(j * m + c) * 6 + 6].copy_from_slice(&n);
            }
            cur.copy_from_slice(&out[j * m * 6..(j + 1) * m * 6]);
        }
        Ok(())
    }

    fn jacobians(&self, s: &[f64], u: &[f64]) -> Result<StepJacobians, RacingError> {
        let m = s.len() / 6;
        let mut next = vec![0.0; m * 6];
        let mut ds = vec![0.0; m * 36];
        let mut du = vec![0.0; m * 12];
        let c = &self.world.scenario().car;
        let (lo, hi) = (
            [-c.steering_max, c.throttle_min],
            [c.steering_max, c.throttle_max],
        );
        for b in 0..m {
            let sb = &s[b * 6..b * 6 + 6];
            let ub = [u[b * 2], u[b * 2 + 1]];
            next[b * 6..b * 6 + 6].copy_from_slice(&self.step1(sb, ub));
            for col in 0..6 {
                let h = 1e-6 * (1.0 + sb[col].abs());
                let (mut p, mut q) = ([0.0; 6], [0.0; 6]);
                p.copy_from_slice(sb);
                q.copy_from_slice(sb);
                p[col] += h;
                q[col] -= h;
                let (fp, fq) = (self.step1(&p, ub), self.step1(&q, ub));
                for r in 0..6 {
                    ds[b * 36 + r * 6 + col] = (fp[r] - fq[r]) / (2.0 * h);
                }
            }
            for col in 0..2 {
                let h = 1e-6;
                let (mut p, mut q) = (ub, ub);
                p[col] = (ub[col] + h).min(hi[col]);
                q[col] = (ub[col] - h).max(lo[col]);
                let span = p[col] - q[col];
                if span <= 0.0 {
                    continue;
                }
                let (fp, fq) = (self.step1(sb, p), self.step1(sb, q));
                for r in 0..6 {
                    du[b * 12 + r * 2 + col] = (fp[r] - fq[r]) / span;
                }
            }
        }
        Ok(StepJacobians { next, ds, du })
    }
}
