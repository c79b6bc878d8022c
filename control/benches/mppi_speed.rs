//! One MPPI step over a pushing NeuralODE (Tu & Lin's network: 6 → 100 → 100 → 3 tanh, RK4),
//! for K = 1000, T = 20 and the paper's K = 100, T = 10, on 1 and 2 threads, beside an
//! equivalent PyTorch MPPI (`benches/torch_mppi.py`, run when `DYNLAB_TORCH_PYTHON` names a
//! Python with torch). Prints a table with the ratios, a row for `MppiConfig::default()` (what
//! `dynlab eval push` and `mppi_pusher` run), and a second table with the batched rollout timed
//! on its own beside the whole step.
//!
//! ```sh
//! DYNLAB_TORCH_PYTHON=/path/to/python cargo bench -p dynlab-control --bench mppi_speed
//! ```

use std::path::Path;
use std::process::Command;
use std::time::Instant;

use dynlab_control::mppi::{Mppi, MppiConfig, PushTask};
use dynlab_learn::dynamics::ode::Solver;
use dynlab_learn::train::default_physics_solver;
use dynlab_learn::{Model, ModelKind, Network, Normalization, RolloutWorkspace, World};
use dynlab_nn::{Activation, Init, Mlp, MlpSpec};
use dynlab_sim::{PushScenario, SimRng};

fn model(kind: ModelKind) -> Model {
    let spec = MlpSpec::uniform(6, &[100, 100], 3, Activation::Tanh).expect("spec");
    let mlp = Mlp::new(spec, Init::Auto, 1);
    let mut norm = Normalization::identity(6, 3);
    norm.output_std = vec![0.02, 0.02, 0.1];
    let solver = match kind {
        ModelKind::NodeRk4 => Some(Solver::rk4()),
        ModelKind::NodeEuler => Some(Solver::euler()),
        ModelKind::NodeDopri5 => Some(Solver::dopri5(1e-3, 1e-4)),
        _ => None,
    };
    Model::new(
        kind,
        World::Push,
        2.0,
        solver,
        Some(Network::new(mlp, norm)),
        None,
        default_physics_solver(World::Push),
    )
    .expect("model")
}

/// Median milliseconds of one MPPI step.
fn time_step(model: &Model, k: usize, t: usize, threads: usize, obstacle: bool) -> f64 {
    let cfg = MppiConfig {
        samples: k,
        horizon: t,
        threads,
        ..MppiConfig::default()
    };
    let scene = if obstacle {
        PushScenario::obstacle()
    } else {
        PushScenario::free()
    };
    let task = PushTask::from_scenario(&scene, cfg.obstacle_margin);
    let mut m = Mppi::new(cfg, task).expect("mppi");
    let s = scene.start;
    for _ in 0..3 {
        m.step(model, s).expect("step");
    }
    let reps = if k * t >= 10_000 { 41 } else { 401 };
    let mut times: Vec<f64> = (0..reps)
        .map(|_| {
            let t0 = Instant::now();
            m.step(model, s).expect("step");
            t0.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    times.sort_by(f64::total_cmp);
    times[times.len() / 2]
}

/// Median milliseconds of `f` over `reps` calls (after 3 warm-up calls).
fn median_ms(reps: usize, mut f: impl FnMut()) -> f64 {
    for _ in 0..3 {
        f();
    }
    let mut times: Vec<f64> = (0..reps)
        .map(|_| {
            let t0 = Instant::now();
            f();
            t0.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    times.sort_by(f64::total_cmp);
    times[times.len() / 2]
}

/// One MPPI step (obstacle scene) and its batched rollout timed on its own; the rest of the
/// step (noise, clamping and costs, split over the same worker threads, then the weighted
/// average and the shift) is the difference.
fn phases(model: &Model, k: usize, t: usize, threads: usize) -> [f64; 3] {
    let scene = PushScenario::obstacle();
    let reps = if k * t >= 10_000 { 41 } else { 401 };
    let mut rng = SimRng::new(1);
    let actions: Vec<f32> = (0..k * t * 3)
        .map(|_| (0.3 * rng.normal()).clamp(-1.0, 1.0) as f32)
        .collect();
    let s0: Vec<f32> = (0..k).flat_map(|_| scene.start.map(|v| v as f32)).collect();
    let mut traj = vec![0.0f32; k * t * 3];
    let mut ws = RolloutWorkspace::new(threads);
    let rollout = median_ms(reps, || {
        model
            .rollout_f32(&s0, &actions, &mut traj, &mut ws)
            .expect("rollout");
    });
    let whole = time_step(model, k, t, threads, true);
    [whole, rollout, whole - rollout]
}

fn torch_times() -> Option<Vec<(usize, usize, f64)>> {
    let py = std::env::var("DYNLAB_TORCH_PYTHON").ok()?;
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../benches/torch_mppi.py");
    let out = Command::new(py).arg(script).output().ok()?;
    if !out.status.success() {
        eprintln!(
            "torch_mppi.py failed: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        return None;
    }
    let text = String::from_utf8_lossy(&out.stdout);
    Some(
        text.lines()
            .filter_map(|l| {
                let mut f = l.split_whitespace();
                let k = f.next()?.parse().ok()?;
                let t = f.next()?.parse().ok()?;
                let ms = f.next()?.parse().ok()?;
                Some((k, t, ms))
            })
            .collect(),
    )
}

fn main() {
    let rk4 = model(ModelKind::NodeRk4);
    let torch = torch_times();
    println!(
        "| case | K | T | dynlab 1 thread (ms) | dynlab 2 threads (ms) | PyTorch (ms) | PyTorch / dynlab 2 threads | target (ms) |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    for (k, t, target) in [(1000, 20, 20.0), (100, 10, 1.0)] {
        for obstacle in [false, true] {
            let t1 = time_step(&rk4, k, t, 1, obstacle);
            let t2 = time_step(&rk4, k, t, 2, obstacle);
            let pt = torch
                .as_ref()
                .and_then(|v| v.iter().find(|(a, b, _)| *a == k && *b == t).map(|x| x.2));
            let (pts, ratio) = match pt {
                Some(p) => (format!("{p:.2}"), format!("{:.1}×", p / t2)),
                None => ("–".into(), "–".into()),
            };
            println!(
                "| node-rk4{} | {k} | {t} | {t1:.2} | {t2:.2} | {pts} | {ratio} | {target} |",
                if obstacle { " + obstacle" } else { "" }
            );
        }
    }
    for kind in [
        ModelKind::Residual,
        ModelKind::NodeEuler,
        ModelKind::NodeDopri5,
    ] {
        let m = model(kind);
        let t2 = time_step(&m, 1000, 20, 2, false);
        println!("| {} | 1000 | 20 | – | {t2:.2} | – | – | – |", kind.name());
    }
    // What `dynlab eval push` and `mppi_pusher` run by default (MppiConfig::default()).
    let d = MppiConfig::default();
    let t2 = time_step(&rk4, d.samples, d.horizon, d.threads, true);
    println!(
        "| node-rk4 + obstacle, MppiConfig::default() (eval push, mppi_pusher) | {} | {} | – | {t2:.2} | – | – | – |",
        d.samples, d.horizon
    );
    println!();
    println!(
        "Phases of one step (node-rk4 + obstacle; milliseconds, medians; \"rest\" = noise, clamping, costs, averaging):"
    );
    println!("| K | T | threads | whole step | rollout_f32 | rest |");
    println!("|---|---|---|---|---|---|");
    for (k, t) in [(1000, 20), (100, 10)] {
        for threads in [1, 2] {
            let [whole, rollout, rest] = phases(&rk4, k, t, threads);
            println!("| {k} | {t} | {threads} | {whole:.3} | {rollout:.3} | {rest:.3} |");
        }
    }
    if torch.is_none() {
        println!("(set DYNLAB_TORCH_PYTHON to a Python with torch for the PyTorch column)");
    }
}
