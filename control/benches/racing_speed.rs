//! Solve time of one receding-horizon racing step at n = 20 (20 Hz, 5 model steps per control
//! step), per model kind and optimiser, measured side by side in one run.
//!
//! `cargo bench -p dynlab-control --bench racing_speed` — builds 8 × 64 GELU networks with
//! random weights (the Kohler size; speed does not depend on the weights), the nominal physics
//! model and the simulator itself, races 30 control cycles (3 for GD, whose 512-candidate line search is far slower) on an oval from a standing start and
//! prints p50/p99 of the per-cycle solve time. `DYNLAB_RACE_MODEL=<dir>` adds a trained model.
//! Row `node-rk4 fwd-jac` is the node-rk4 model linearised by forward mode through the RK4 stages
//! (`Model::jacobians`) instead of `Model::jacobians_stagewise`: compare it with `node-rk4 8x64`.

use std::time::Instant;

use dynlab_control::racing::{
    CarDynamics, GdSettings, Optimizer, Racer, RacerSettings, RacingError, SimCar, true_car_model,
};
use dynlab_learn::dynamics::ode::Solver;
use dynlab_learn::{Model, ModelKind, Network, Normalization, StepJacobians, World, load_model};
use dynlab_nn::{Activation, Init, Mlp, MlpSpec};
use dynlab_sim::{CarScenario, Track};

fn net_model(kind: ModelKind) -> Model {
    let spec = MlpSpec::uniform(5, &[64; 8], 3, Activation::Gelu).unwrap();
    let mlp = Mlp::new(spec, Init::Auto, 1);
    let mut norm = Normalization::identity(5, 3);
    norm.output_std = vec![1e-3; 3];
    Model::new(
        kind,
        World::Car,
        0.01,
        None,
        Some(Network::new(mlp, norm)),
        None,
        Solver::rk4(),
    )
    .unwrap()
}

/// The node-rk4 model linearised by [`Model::jacobians`] (forward mode through the RK4 stages,
/// one pass per input direction) instead of the plant's stage-wise Jacobians: the previous
/// linearisation, side by side.
#[derive(Debug)]
struct ForwardModeJacobians<'a>(&'a Model);

impl CarDynamics for ForwardModeJacobians<'_> {
    fn dt(&self) -> f64 {
        CarDynamics::dt(self.0)
    }
    fn check(&self) -> Result<(), RacingError> {
        CarDynamics::check(self.0)
    }
    fn rollout(&self, s0: &[f64], actions: &[f64], out: &mut [f64]) -> Result<(), RacingError> {
        CarDynamics::rollout(self.0, s0, actions, out)
    }
    fn jacobians(&self, s: &[f64], u: &[f64]) -> Result<StepJacobians, RacingError> {
        Ok(Model::jacobians(self.0, s, u)?)
    }
}

fn quantile(v: &mut [f64], q: f64) -> f64 {
    v.sort_by(f64::total_cmp);
    v[((q * v.len() as f64).ceil() as usize).clamp(1, v.len()) - 1]
}

fn main() {
    let track = Track::oval(1.5, 0.6, 0.2, 200).unwrap();
    let scenario = CarScenario::on_track(track.clone());
    let physics = true_car_model(&scenario.car, 0.01).unwrap();
    let sim = SimCar::new(&scenario, 0.01).unwrap();
    let residual = net_model(ModelKind::Residual);
    let rk4 = net_model(ModelKind::NodeRk4);
    let rk4_forward = ForwardModeJacobians(&rk4);
    let trained = std::env::var("DYNLAB_RACE_MODEL")
        .ok()
        .map(|p| load_model(std::path::Path::new(&p), None, None).unwrap().0);
    let mut models: Vec<(&str, &dyn CarDynamics)> = vec![
        ("physics", &physics),
        ("residual 8x64", &residual),
        ("node-rk4 8x64", &rk4),
        ("node-rk4 fwd-jac", &rk4_forward),
        ("simulator (FD)", &sim),
    ];
    if let Some(m) = &trained {
        models.push(("trained", m));
    }
    // recovery starts off: every cycle is exactly one solve from the warm start (with random
    // weights, whether the car "stalls" depends on rounding, and a recovery cycle solves 4×)
    let single_solve = RacerSettings {
        recovery_fraction: 0.0,
        ..RacerSettings::default()
    };
    let configs: Vec<(&str, RacerSettings)> = vec![
        (
            "sqp 1 it",
            RacerSettings {
                sqp: dynlab_control::racing::SqpSettings {
                    iterations: 1,
                    ..RacerSettings::default().sqp
                },
                ..single_solve
            },
        ),
        ("sqp 3 it", single_solve),
        (
            "gd 5 it × 512",
            RacerSettings {
                optimizer: Optimizer::Gd,
                gd: GdSettings {
                    iterations: 5,
                    ..GdSettings::default()
                },
                ..single_solve
            },
        ),
    ];
    println!(
        "one receding-horizon solve, n = 20, hold 5 (100 model steps); 30 cycles per SQP row, 3 per GD row; recovery starts off"
    );
    println!(
        "{:<16} {:<14} {:>10} {:>10} {:>12}",
        "model", "optimiser", "p50 (ms)", "p99 (ms)", "p99 / phys"
    );
    // DYNLAB_RACE_ONLY=<text>: only rows whose "model optimiser" contains the text (profiling)
    let only = std::env::var("DYNLAB_RACE_ONLY").ok();
    let mut reference = std::collections::HashMap::new();
    for (mname, model) in &models {
        for (cname, cfg) in &configs {
            if let Some(o) = &only
                && !format!("{mname} {cname}").contains(o.as_str())
            {
                continue;
            }
            let gd = cfg.optimizer == Optimizer::Gd;
            if gd && *mname == "simulator (FD)" {
                continue;
            }
            let cycles = if gd { 3 } else { 30 };
            let mut racer = Racer::new(*model, &track, *cfg).unwrap();
            let p = track.start_pose();
            let mut s = [p.x, p.y, p.theta, 0.0, 0.0, 0.0];
            let mut times = Vec::with_capacity(cycles);
            for _ in 0..cycles {
                let t0 = Instant::now();
                let r = racer.step(s).unwrap();
                times.push(t0.elapsed().as_secs_f64() * 1e3);
                // advance along the prediction (the benchmark measures the solver, not the loop)
                s = r.predicted[1];
            }
            let p50 = quantile(&mut times, 0.5);
            let p99 = quantile(&mut times, 0.99);
            if *mname == "physics" {
                reference.insert(*cname, p99);
            }
            println!(
                "{:<16} {:<14} {:>10.2} {:>10.2} {:>12.2}",
                mname,
                cname,
                p50,
                p99,
                reference.get(cname).map_or(f64::NAN, |r| p99 / r)
            );
        }
    }
}
