//! Speed of the model kinds through the public API of `dynlab-learn` (not the raw network), side
//! by side with PyTorch CPU on the same machine:
//!
//! ```text
//! cargo bench -p dynlab-learn --bench train_speed
//! DYNLAB_TORCH_PYTHON=$HOME/torchvenv/bin/python cargo bench -p dynlab-learn --bench train_speed
//! ```
//!
//! Rows (medians over rounds; with PyTorch each round runs ours, then `benches/torch_reference.py
//! --rounds 1` with 2 threads and with 1 thread, interleaved so all see the same machine load;
//! ratios are how many times faster dynlab is than each):
//!
//! * `train_*`: training samples/s of `dynlab_learn::train` (forward + backward through the
//!   solver + Adam, batch 500, pushing MLP 6 → 100 → 100 → 3 tanh, 2 threads), measured over
//!   whole epochs of exactly one batch (with a 1 % validation pass and the checkpoint copy, which
//!   PyTorch's loop does not do), timed like PyTorch (fastest block of ≥ 3 calls and ≥ 30 ms);
//!   `DYNLAB_BENCH_THREADS=1` measures our side on one thread instead of two (the scaling), and
//!   with `DYNLAB_BENCH_ONLY`, `DYNLAB_BENCH_REPS=n` runs exactly n `train()` calls (fixed work
//!   for `perf stat -e task-clock`);
//! * `mppi_ms`: `Model::rollout_f32` of a node-rk4 pushing model, 1000 samples × 20 steps, 2 threads;
//! * `car_jac_ms`: 20 input Jacobians of the 8 → 8 × 64 GELU → 3 network (the reference's
//!   definition), and of a whole car model step (`Model::jacobians`, residual kind, 5 → 8 × 64 → 3
//!   with the pose kinematics).

use std::hint::black_box;
use std::time::Instant;

use dynlab_learn::dynamics::data::{SplitMix64, StateTrajectory};
use dynlab_learn::{Dataset, Model, ModelKind, RolloutWorkspace, Split, TrainConfig, World, train};
use dynlab_nn::{Activation, Init, Mlp, MlpSpec};

/// Seconds per call, timed as `benches/torch_reference.py` times PyTorch: 2 warm-up calls, then
/// blocks of at least 3 calls and 30 ms for at least `min_secs`; the fastest block counts (other
/// processes on the machine only ever slow a block down).
fn timed(mut f: impl FnMut(), min_secs: f64) -> f64 {
    for _ in 0..2 {
        f();
    }
    let t0 = Instant::now();
    let mut best = f64::INFINITY;
    while t0.elapsed().as_secs_f64() < min_secs || !best.is_finite() {
        let tb = Instant::now();
        let mut n = 0;
        while n < 3 || tb.elapsed().as_secs_f64() < 0.03 {
            f();
            n += 1;
        }
        best = best.min(tb.elapsed().as_secs_f64() / n as f64);
    }
    best
}

fn random_push_data(windows: usize, k: usize) -> Dataset {
    let mut rng = SplitMix64::new(1);
    let mut r = || ((rng.next_u64() >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0;
    let len = windows + k;
    let traj = StateTrajectory {
        s: (0..len * 3).map(|_| r()).collect(),
        u: (0..len * 3).map(|_| r()).collect(),
        dim_s: 3,
        dim_u: 3,
        dt: 1.0,
    };
    Dataset {
        world: World::Push,
        trajectories: vec![traj],
        pose_dt_s: 1.0,
        sources: Vec::new(),
        reports: Vec::new(),
    }
}

/// Training threads: 2, or `DYNLAB_BENCH_THREADS` (to compare the scaling of our side).
fn bench_threads() -> usize {
    std::env::var("DYNLAB_BENCH_THREADS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(2)
}

/// Training samples/s over epochs of one batch of 500.
fn train_rate(kind: ModelKind, k: usize) -> f64 {
    // 505 windows, 1 % validation → 500 training windows = one batch per epoch
    let data = random_push_data(505, k);
    let epochs = 20;
    let cfg = TrainConfig {
        kind,
        steps: k,
        epochs,
        split: Split::OverlappingWindows,
        validation_fraction: 0.01,
        threads: bench_threads(),
        ..Default::default()
    };
    let once = || {
        black_box(train(&data, &cfg, &mut |_| {}).map(|o| o.best_epoch).ok());
    };
    // DYNLAB_BENCH_REPS=n: exactly n calls (fixed work, for `perf stat -e task-clock`)
    if let Some(reps) = std::env::var("DYNLAB_BENCH_REPS")
        .ok()
        .and_then(|v| v.parse::<usize>().ok())
    {
        let t0 = Instant::now();
        for _ in 0..reps {
            once();
        }
        return (500 * epochs * reps) as f64 / t0.elapsed().as_secs_f64();
    }
    let secs = timed(once, 0.5);
    (500 * epochs) as f64 / secs
}

fn push_rk4_model() -> Model {
    let data = random_push_data(600, 1);
    let cfg = TrainConfig {
        kind: ModelKind::NodeRk4,
        epochs: 1,
        split: Split::OverlappingWindows,
        ..Default::default()
    };
    train(&data, &cfg, &mut |_| {})
        .map(|o| o.model)
        .expect("model")
}

fn mppi_ms(model: &Model, threads: usize) -> f64 {
    let (n, horizon) = (1000, 20);
    let mut rng = SplitMix64::new(2);
    let mut r = || ((rng.next_u64() >> 11) as f32 / (1u64 << 53) as f32) * 2.0 - 1.0;
    let s0: Vec<f32> = (0..n * 3).map(|_| r()).collect();
    let acts: Vec<f32> = (0..n * horizon * 3).map(|_| r()).collect();
    let mut out = vec![0.0f32; n * horizon * 3];
    let mut ws = RolloutWorkspace::new(threads);
    1e3 * timed(
        || {
            model.rollout_f32(&s0, &acts, &mut out, &mut ws).ok();
            black_box(&out);
        },
        0.5,
    )
}

fn car_net_jac_ms() -> f64 {
    let spec = MlpSpec::uniform(8, &[64; 8], 3, Activation::Gelu).expect("spec");
    let mlp = Mlp::new(spec, Init::Auto, 3);
    let mut ws = mlp.workspace();
    let mut rng = SplitMix64::new(3);
    let x: Vec<f32> = (0..20 * 8)
        .map(|_| ((rng.next_u64() >> 11) as f32 / (1u64 << 53) as f32) * 2.0 - 1.0)
        .collect();
    1e3 * timed(
        || {
            black_box(mlp.jacobian(&x, &mut ws).map(|j| j[0]).ok());
        },
        0.3,
    )
}

fn car_model_jac_ms() -> f64 {
    let mut rng = SplitMix64::new(4);
    let mut r = || ((rng.next_u64() >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0;
    let len = 400;
    let traj = StateTrajectory {
        s: (0..len * 6).map(|_| r()).collect(),
        u: (0..len * 2).map(|_| r()).collect(),
        dim_s: 6,
        dim_u: 2,
        dt: 0.01,
    };
    let data = Dataset {
        world: World::Car,
        trajectories: vec![traj],
        pose_dt_s: 0.01,
        sources: Vec::new(),
        reports: Vec::new(),
    };
    let cfg = TrainConfig {
        kind: ModelKind::Residual,
        epochs: 1,
        split: Split::OverlappingWindows,
        ..Default::default()
    };
    let model = train(&data, &cfg, &mut |_| {})
        .map(|o| o.model)
        .expect("model");
    let s: Vec<f64> = (0..20 * 6).map(|_| r()).collect();
    let u: Vec<f64> = (0..20 * 2).map(|_| r()).collect();
    1e3 * timed(
        || {
            black_box(model.jacobians(&s, &u).map(|j| j.ds[0]).ok());
        },
        0.3,
    )
}

fn torch_round(python: &str, threads: usize) -> Option<Vec<(String, f64)>> {
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/../benches/torch_reference.py");
    let threads = threads.to_string();
    let out = std::process::Command::new(python)
        .args([script, "--json", "--rounds", "1", "--threads", &threads])
        .stderr(std::process::Stdio::null())
        .output()
        .ok()?;
    if !out.status.success() {
        return None;
    }
    let text = String::from_utf8_lossy(&out.stdout);
    let line = text
        .lines()
        .rev()
        .find(|l| l.trim_start().starts_with('{'))?;
    let v: serde_json::Value = serde_json::from_str(line.trim()).ok()?;
    Some(
        v.as_object()?
            .iter()
            .filter_map(|(k, v)| Some((k.clone(), v.as_f64()?)))
            .collect(),
    )
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() {
    if !std::env::args().any(|a| a == "--bench") {
        println!("train_speed: run with `cargo bench -p dynlab-learn --bench train_speed`");
        return;
    }
    // DYNLAB_BENCH_ONLY=train_rk4_k1 (etc.) runs one row once, for `perf stat`/`perf record`.
    if let Ok(only) = std::env::var("DYNLAB_BENCH_ONLY") {
        let v = match only.as_str() {
            "train_rk4_k1" => train_rate(ModelKind::NodeRk4, 1),
            "train_rk4_k3" => train_rate(ModelKind::NodeRk4, 3),
            "train_residual" => train_rate(ModelKind::Residual, 1),
            "mppi" => mppi_ms(&push_rk4_model(), 2),
            other => {
                eprintln!(
                    "unknown benchmark {other}: train_rk4_k1, train_rk4_k3, train_residual, mppi"
                );
                return;
            }
        };
        println!("{only}: {v:.3}");
        return;
    }
    let rounds: usize = std::env::var("DYNLAB_BENCH_ROUNDS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(5);
    let python = std::env::var("DYNLAB_TORCH_PYTHON").ok();
    let rk4 = push_rk4_model();
    // (name, unit, higher is better, torch key)
    let rows: [(&str, &str, bool, &str); 7] = [
        ("train node-rk4 k=1", "samples/s", true, "train_rk4_k1"),
        ("train node-rk4 k=3", "samples/s", true, "train_rk4_k3"),
        ("train residual k=1", "samples/s", true, "train_residual"),
        ("MPPI 1000×20 node-rk4, 2 threads", "ms", false, "mppi_ms"),
        ("MPPI 1000×20 node-rk4, 1 thread", "ms", false, "mppi_ms"),
        ("20 Jacobians 8→8×64 GELU→3", "ms", false, "car_jac_ms"),
        ("20 car model step Jacobians", "ms", false, "car_jac_ms"),
    ];
    let mut ours: Vec<Vec<f64>> = vec![Vec::new(); rows.len()];
    // PyTorch with 2 threads (the comparison the targets are stated against) and with 1 thread
    // (on a busy machine its OpenMP workers wait for each other and 1 thread is often faster).
    let mut torch: Vec<Vec<f64>> = vec![Vec::new(); rows.len()];
    let mut torch1: Vec<Vec<f64>> = vec![Vec::new(); rows.len()];
    for round in 0..rounds {
        eprintln!("round {}/{rounds}", round + 1);
        let vals = [
            train_rate(ModelKind::NodeRk4, 1),
            train_rate(ModelKind::NodeRk4, 3),
            train_rate(ModelKind::Residual, 1),
            mppi_ms(&rk4, 2),
            mppi_ms(&rk4, 1),
            car_net_jac_ms(),
            car_model_jac_ms(),
        ];
        for (o, v) in ours.iter_mut().zip(vals) {
            o.push(v);
        }
        if let Some(py) = &python {
            for (threads, dst) in [(2, &mut torch), (1, &mut torch1)] {
                if let Some(t) = torch_round(py, threads) {
                    for (i, row) in rows.iter().enumerate() {
                        if let Some((_, v)) = t.iter().find(|(k, _)| k == row.3) {
                            dst[i].push(*v);
                        }
                    }
                }
            }
        }
    }
    println!(
        "{:<36} {:>12} {:>12} {:>9} {:>12} {:>9}  unit",
        "benchmark", "dynlab", "PyTorch 2t", "ratio", "PyTorch 1t", "ratio"
    );
    for (i, (name, unit, higher, _)) in rows.iter().enumerate() {
        let o = median(ours[i].clone());
        let cell = |t: &Vec<f64>| {
            if t.is_empty() {
                ("-".to_string(), "-".to_string())
            } else {
                let t = median(t.clone());
                let r = if *higher { o / t } else { t / o };
                (format!("{t:.3}"), format!("{r:.2}×"))
            }
        };
        let (t2, r2) = cell(&torch[i]);
        let (t1, r1) = cell(&torch1[i]);
        println!("{name:<36} {o:>12.3} {t2:>12} {r2:>9} {t1:>12} {r1:>9}  {unit}");
    }
    if python.is_none() {
        println!("(set DYNLAB_TORCH_PYTHON=/path/to/python-with-torch for the PyTorch column)");
    }
    println!("ratio: how many times faster dynlab is");
}
