//! Time of one receding-horizon racing cycle at n = 20 (20 Hz, 5 model steps per control
//! step), per model kind and cycle setting, measured side by side in one run.
//!
//! `cargo bench -p dynlab-control --bench racing_speed` — builds 8 × 64 GELU networks with
//! random weights (the Kohler size; speed does not depend on the weights), the nominal physics
//! model and the simulator itself, races `DYNLAB_RACE_CYCLES` (default 30) control cycles (3 for
//! GD, whose 512-candidate line search is far slower) on an oval from a standing start and
//! prints p50/p99 of the per-cycle time. One model's rows run interleaved, cycle by cycle, so a
//! change in the machine's load hits them alike; compare rows by their ratios (`p50/prev`,
//! `p99/prev`: over the row of the previous path in the same family), not by absolute times.
//! Rows: `sqp 1 it`, `sqp 3 it` (one solve per cycle, recovery off; `prev` = Clarabel's default
//! QP settings with a hard QP first, the path before `SqpSettings::fast_qp`); `race` (the racing
//! defaults: recovery starts when stalled — with random weights the car hardly moves, so nearly
//! every cycle stalls); `stall …` (the racing defaults stalled on every cycle: the warm start and
//! the three recovery starts; `prev` = the previous QPs on one thread, `1 thr` = the new QPs on
//! one thread, plain = two threads, `8ms` = with `solve_budget` 8 ms).
//! `DYNLAB_RACE_MODEL=<dir>` adds a trained model, `DYNLAB_RACE_ONLY=<text>` keeps the rows whose
//! "model cycle" contains the text. Row `node-rk4 fwd-jac` is the node-rk4 model linearised by
//! forward mode through the RK4 stages (`Model::jacobians`) instead of
//! `Model::jacobians_stagewise`: compare it with `node-rk4 8x64`.

use std::time::Instant;

use dynlab_control::racing::{
    CarDynamics, GdSettings, Optimizer, Racer, RacerSettings, RacingError, SimCar, SqpSettings,
    true_car_model,
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
    // the racing settings with a stall on every cycle (recovery_fraction 1: the plan never
    // reaches the whole reference progress), so every cycle solves the warm start and the three
    // recovery starts: the worst case of a racing cycle
    let stalled = RacerSettings {
        recovery_fraction: 1.0,
        ..RacerSettings::default()
    };
    // the previous path: Clarabel's default QP settings, a hard QP first on every iteration,
    // the recovery starts solved one after the other
    let prev_sqp = SqpSettings {
        iterations: 3,
        ..SqpSettings::default()
    };
    let configs: Vec<(&str, RacerSettings)> = vec![
        (
            "sqp 1 it",
            RacerSettings {
                sqp: SqpSettings {
                    iterations: 1,
                    ..RacerSettings::default().sqp
                },
                ..single_solve
            },
        ),
        (
            "sqp 3 it prev",
            RacerSettings {
                sqp: prev_sqp,
                ..single_solve
            },
        ),
        ("sqp 3 it", single_solve),
        ("race", RacerSettings::default()),
        (
            "stall prev",
            RacerSettings {
                recovery_threads: 1,
                sqp: prev_sqp,
                ..stalled
            },
        ),
        (
            "stall 1 thr",
            RacerSettings {
                recovery_threads: 1,
                ..stalled
            },
        ),
        ("stall", stalled),
        (
            "stall 8ms",
            RacerSettings {
                solve_budget: 0.008,
                ..stalled
            },
        ),
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
    let cycles: usize = std::env::var("DYNLAB_RACE_CYCLES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(30);
    println!(
        "one receding-horizon cycle, n = 20, hold 5 (100 model steps); {cycles} cycles per SQP row \
         (DYNLAB_RACE_CYCLES), 3 per GD row; one model's rows interleaved cycle by cycle"
    );
    println!(
        "rows: sqp 1 it / 3 it = one solve per cycle (recovery off); race = the racing defaults \
         (recovery starts when stalled); stall = the racing defaults stalled on every cycle (warm \
         start + 3 recovery starts; 2 threads), on 1 thread, and with an 8 ms solve_budget; \
         prev = the previous path (Clarabel's default QP settings, hard QP first, 1 thread); \
         ratios: this row's p50 and p99 over its prev row's"
    );
    println!(
        "{:<16} {:<14} {:>9} {:>9} {:>11} {:>10} {:>10} {:>8} {:>9}",
        "model",
        "cycle",
        "p50 (ms)",
        "p99 (ms)",
        "p99 / phys",
        "p50/prev",
        "p99/prev",
        "rec cyc",
        "deadline"
    );
    // DYNLAB_RACE_ONLY=<text>: only rows whose "model cycle" contains the text (profiling)
    let only = std::env::var("DYNLAB_RACE_ONLY").ok();
    let mut reference = std::collections::HashMap::new();
    for (mname, model) in &models {
        // the rows that apply to this model, interleaved cycle by cycle so that a change in the
        // machine's load hits every row alike
        let learned =
            mname.starts_with("residual") || mname.starts_with("node-rk4 8") || *mname == "trained";
        let mut rows = Vec::new();
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
            if (cname.starts_with("stall") || *cname == "race") && !learned {
                continue;
            }
            let racer = Racer::new(*model, &track, *cfg).unwrap();
            let p = track.start_pose();
            let s = [p.x, p.y, p.theta, 0.0, 0.0, 0.0];
            let n = if gd { 3 } else { cycles };
            rows.push((*cname, racer, s, n, Vec::with_capacity(n), 0usize, 0usize));
        }
        for c in 0..cycles {
            for (_, racer, s, n, times, rec, dl) in rows.iter_mut() {
                if c >= *n {
                    continue;
                }
                let t0 = Instant::now();
                let r = racer.step(*s).unwrap();
                times.push(t0.elapsed().as_secs_f64() * 1e3);
                *rec += usize::from(r.recovery_solves > 0);
                *dl += usize::from(r.deadline);
                // advance along the prediction (the benchmark measures the solver, not the loop)
                *s = r.predicted[1];
            }
        }
        let mut prev = std::collections::HashMap::new();
        for (cname, _, _, _, mut times, rec, dl) in rows {
            let p50 = quantile(&mut times, 0.5);
            let p99 = quantile(&mut times, 0.99);
            if *mname == "physics" {
                reference.insert(cname, p99);
            }
            let family = if cname.starts_with("stall") {
                "stall"
            } else if cname.starts_with("sqp 3") {
                "sqp 3"
            } else {
                cname
            };
            if cname.ends_with("prev") {
                prev.insert(family, (p50, p99));
            }
            let (r50, r99) = prev
                .get(family)
                .map_or((f64::NAN, f64::NAN), |(a, b)| (p50 / a, p99 / b));
            println!(
                "{:<16} {:<14} {:>9.2} {:>9.2} {:>11.2} {:>10.2} {:>10.2} {:>8} {:>9}",
                mname,
                cname,
                p50,
                p99,
                reference.get(cname).map_or(f64::NAN, |r| p99 / r),
                r50,
                r99,
                rec,
                dl
            );
        }
    }
}
