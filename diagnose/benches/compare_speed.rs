//! Speed of `compare` on one hour of 100 Hz car data (360 000 states), generated here from the
//! car's physics model with smooth random commands, for the two model kinds that bound the
//! cost: the physics model and a NeuralODE (RK4, 8 × 64 GELU, the main job's network).
//!
//! ```text
//! cargo bench -p dynlab-diagnose --bench compare_speed
//! ```
//!
//! Columns: `evaluate` is `dynlab_learn::evaluate` alone (one-step and k-step errors, TVE: what
//! `dynlab eval-model` costs); `compare` is the whole `compare` (it runs `evaluate` and its own
//! pass over every window: bins, map, correlations at 41 lags, worst segments); `report` is
//! building the HTML page with its SVG figures and the JSON; `ratio` is compare / evaluate, and
//! `of target` is (compare + report) / 30 s. Times are single runs, measured side by side.

use std::time::Instant;

use dynlab_diagnose::compare::{CompareConfig, compare, html};
use dynlab_learn::dynamics::data::{SplitMix64, StateTrajectory};
use dynlab_learn::dynamics::ode::Solver;
use dynlab_learn::train::{default_physics_solver, physics_model};
use dynlab_learn::{
    Dataset, Model, ModelKind, Network, Normalization, Stamps, TimedDataset, World, evaluate,
};
use dynlab_nn::{Activation, Init, Mlp, MlpSpec};

const DT: f64 = 0.01;

fn physics() -> Model {
    Model::new(
        ModelKind::Physics,
        World::Car,
        DT,
        None,
        None,
        Some(physics_model(World::Car, &[]).expect("physics")),
        default_physics_solver(World::Car),
    )
    .expect("model")
}

fn node_rk4() -> Model {
    let spec = MlpSpec::uniform(5, &[64; 8], 3, Activation::Gelu).expect("spec");
    let net = Network::new(Mlp::new(spec, Init::Auto, 1), Normalization::identity(5, 3));
    Model::new(
        ModelKind::NodeRk4,
        World::Car,
        DT,
        Some(Solver::rk4()),
        Some(net),
        None,
        default_physics_solver(World::Car),
    )
    .expect("model")
}

/// `trajs` trajectories of `len` states driven by smooth random steering and throttle.
fn hour_of_car_data(trajs: usize, len: usize) -> TimedDataset {
    let model = physics();
    let mut rng = SplitMix64::new(7);
    let mut r = move || ((rng.next_u64() >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0;
    let mut s = vec![0.0; trajs * 6];
    for i in 0..trajs {
        s[i * 6] = r();
        s[i * 6 + 1] = r();
        s[i * 6 + 2] = 3.0 * r();
        s[i * 6 + 3] = 0.5;
    }
    let mut u = vec![0.0; trajs * 2];
    let mut states = vec![Vec::with_capacity(len * 6); trajs];
    let mut inputs = vec![Vec::with_capacity(len * 2); trajs];
    let mut next = vec![0.0; trajs * 6];
    for _ in 0..len {
        for i in 0..trajs {
            // Ornstein–Uhlenbeck-like commands
            u[i * 2] = (0.98 * u[i * 2] + 0.02 * 0.35 * r()).clamp(-0.35, 0.35);
            u[i * 2 + 1] = (0.98 * u[i * 2 + 1] + 0.02 * (0.4 + 0.6 * r())).clamp(-1.0, 1.0);
            states[i].extend_from_slice(&s[i * 6..i * 6 + 6]);
            inputs[i].extend_from_slice(&u[i * 2..i * 2 + 2]);
        }
        model.step(&s, &u, &mut next).expect("step");
        s.copy_from_slice(&next);
    }
    let trajectories = states
        .into_iter()
        .zip(inputs)
        .map(|(s, u)| StateTrajectory {
            s,
            u,
            dim_s: 6,
            dim_u: 2,
            dt: DT,
        })
        .collect();
    let t_ns = (0..trajs)
        .map(|i| {
            let t0 = (i * (len + 100)) as i64 * 10_000_000;
            (0..len as i64).map(|j| t0 + j * 10_000_000).collect()
        })
        .collect();
    TimedDataset {
        data: Dataset {
            world: World::Car,
            trajectories,
            pose_dt_s: DT,
            sources: Vec::new(),
            reports: Vec::new(),
        },
        stamps: Stamps {
            t_ns,
            bag: vec![0; trajs],
            bag_start_ns: vec![0],
        },
    }
}

fn main() {
    let (trajs, len) = (60, 6000);
    let t0 = Instant::now();
    let data = hour_of_car_data(trajs, len);
    println!(
        "data: {} trajectories × {} states at 100 Hz = {:.2} h ({:.1} s to generate)",
        trajs,
        len,
        (trajs * len) as f64 * DT / 3600.0,
        t0.elapsed().as_secs_f64()
    );
    println!(
        "{:<10} {:>9} {:>12} {:>12} {:>10} {:>7} {:>10}",
        "model", "windows", "evaluate s", "compare s", "report s", "ratio", "of target"
    );
    let cfg = CompareConfig::default();
    for (name, model) in [("physics", physics()), ("node-rk4", node_rk4())] {
        let t = Instant::now();
        let ev = evaluate(&model, &data.data, cfg.steps, cfg.segment_s).expect("evaluate");
        let t_eval = t.elapsed().as_secs_f64();
        let t = Instant::now();
        let rep = compare(name, &model, &data, &cfg).expect("compare");
        let t_cmp = t.elapsed().as_secs_f64();
        let t = Instant::now();
        let page = html::report(&rep).to_html();
        let json = serde_json::to_string(&rep).expect("json");
        let t_rep = t.elapsed().as_secs_f64();
        std::hint::black_box((page.len(), json.len()));
        println!(
            "{:<10} {:>9} {:>12.2} {:>12.2} {:>10.2} {:>7.2} {:>9.0} %",
            name,
            ev.windows,
            t_eval,
            t_cmp,
            t_rep,
            t_cmp / t_eval,
            100.0 * (t_cmp + t_rep) / 30.0
        );
    }
}
