//! Trains every model kind for k = 1 … 5 on the Tu & Lin pushing bag, on their split (80/20
//! overlapping windows, seed 42) and on a split by whole trajectories, and prints our best
//! validation losses (their loss: MSE(x) + MSE(y) + 0.0408·MSE(θ), discounted by 0.9 over the k
//! steps) beside their published table. Run by `launch_scripts/eval_tu_lin.sh`. `--effects a,b`
//! gives the physics and hybrid models those library effects (`dynlab train --effects`).
//!
//! ```text
//! cargo run --release -p dynlab-learn --example tu_lin_table -- BAG [--full] [--epochs N]
//!     [--hybrid-epochs N] [--lr LR] [--batch B] [--threads T] [--kinds residual,node-rk4,…]
//!     [--effects a,b] [--json OUT]
//! ```

use std::path::PathBuf;
use std::time::Instant;

use dynlab_dynamics::data::SavGol;
use dynlab_learn::{ModelKind, Split, Topics, TrainConfig, World, load_bags, train};

const PUBLISHED: [(&str, [f64; 5]); 4] = [
    ("residual", [1.82e-4, 4.69e-4, 1.45e-3, 3.07e-3, 6.50e-3]),
    ("node-euler", [6.80e-5, 1.22e-4, 2.73e-4, 5.80e-4, 9.71e-4]),
    ("node-rk4", [6.20e-5, 1.14e-4, 2.33e-4, 4.33e-4, 8.01e-4]),
    ("node-dopri5", [6.61e-5, 9.60e-5, 2.67e-4, 3.55e-4, 7.90e-4]),
];

/// kind, split, best validation losses, constant-model losses, seconds.
type Row = (String, String, Vec<f64>, Vec<f64>, f64);

fn main() {
    if let Err(e) = run() {
        eprintln!("error: {e}");
        std::process::exit(1);
    }
}

fn run() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let mut bag: Option<PathBuf> = None;
    let mut full = false;
    let mut epochs: Option<usize> = None;
    let mut hybrid_epochs: Option<usize> = None;
    let mut lr: Option<f64> = None;
    let mut threads = 2;
    let mut batch: Option<usize> = None;
    let mut json: Option<PathBuf> = None;
    let mut kinds: Vec<ModelKind> = ModelKind::ALL.to_vec();
    let mut effects: Vec<String> = Vec::new();
    while let Some(a) = args.next() {
        let mut val = || args.next().ok_or(format!("{a} needs a value"));
        match a.as_str() {
            "--full" => full = true,
            "--epochs" => epochs = Some(val()?.parse()?),
            "--hybrid-epochs" => hybrid_epochs = Some(val()?.parse()?),
            "--lr" => lr = Some(val()?.parse()?),
            "--threads" => threads = val()?.parse()?,
            "--batch" => batch = Some(val()?.parse()?),
            "--json" => json = Some(val()?.into()),
            "--effects" => effects = val()?.split(',').map(String::from).collect(),
            "--kinds" => {
                kinds = val()?
                    .split(',')
                    .map(ModelKind::from_name)
                    .collect::<Result<_, _>>()?
            }
            _ if a.starts_with("--") => return Err(format!("unknown option {a}").into()),
            _ => bag = Some(a.into()),
        }
    }
    let bag = bag.ok_or("give the bag path")?;
    // Their budget: 3000 epochs at lr 1e-4, batch 500 (6000 Adam steps on ≈ 800 training
    // windows). Ours by default: 250 epochs at lr 1e-3 with batch 100 (2000 Adam steps; hybrid
    // 60 epochs), so that the whole table takes ≈ 20 min on 2 shared cores. Batch 500 at our
    // budget is only 500 steps and under-trains at k ≥ 2 (2–6× above their losses); --full runs
    // theirs (batch 500 unless --batch is given).
    let epochs = epochs.unwrap_or(if full { 3000 } else { 250 });
    let hybrid_epochs = hybrid_epochs.unwrap_or(if full { 3000 } else { 60 });
    let lr = lr.unwrap_or(if full { 1e-4 } else { 1e-3 });
    let batch = batch.unwrap_or(if full { 500 } else { 100 });
    // Gradient chunks of half a batch: both threads work, and the result depends on the batch
    // (and chunk) size only, never on the thread count.
    let chunk = batch.div_ceil(2).max(1);
    let data = load_bags(
        std::slice::from_ref(&bag),
        Some(World::Push),
        &Topics::default(),
        &SavGol::default(),
    )?;
    println!(
        "{}: {} trajectories, {} transitions; budget {epochs} epochs (hybrid {hybrid_epochs}) at lr {lr:e}, batch {batch}, seed 42",
        bag.display(),
        data.trajectories.len(),
        data.transitions()
    );
    let mut rows: Vec<Row> = Vec::new();
    let t_all = Instant::now();
    for split in [Split::OverlappingWindows, Split::Trajectories] {
        for &kind in &kinds {
            let t0 = Instant::now();
            let mut losses = Vec::new();
            let mut baselines = Vec::new();
            for k in 1..=5 {
                let cfg = TrainConfig {
                    kind,
                    steps: k,
                    epochs: if kind == ModelKind::Hybrid {
                        hybrid_epochs
                    } else {
                        epochs
                    },
                    lr,
                    batch,
                    chunk,
                    seed: 42,
                    split,
                    threads,
                    effects: match kind {
                        ModelKind::Physics | ModelKind::Hybrid => effects.clone(),
                        _ => Vec::new(),
                    },
                    ..Default::default()
                };
                let out = train(&data, &cfg, &mut |_| {})?;
                losses.push(out.best_validation_loss);
                baselines.push(out.baseline_validation_loss);
            }
            let secs = t0.elapsed().as_secs_f64();
            eprintln!(
                "{kind:>12} {split:?}: {:?} ({secs:.0} s)",
                losses
                    .iter()
                    .map(|x| format!("{x:.3e}"))
                    .collect::<Vec<_>>()
            );
            rows.push((
                kind.name().into(),
                format!("{split:?}"),
                losses,
                baselines,
                secs,
            ));
        }
    }
    println!();
    println!(
        "whole table: {:.1} min on {threads} threads",
        t_all.elapsed().as_secs_f64() / 60.0
    );
    println!(
        "Best validation loss, MSE(x) + MSE(y) + 0.0408·MSE(θ) summed over k steps with γ = 0.9"
    );
    println!("| model | split | k=1 | k=2 | k=3 | k=4 | k=5 |");
    println!("|---|---|---|---|---|---|---|");
    let fmt = |v: &[f64]| {
        v.iter()
            .map(|x| format!("{x:.2e}"))
            .collect::<Vec<_>>()
            .join(" | ")
    };
    for (name, vals) in PUBLISHED {
        println!(
            "| {name} (Tu & Lin, 3000 epochs) | theirs: overlapping 80/20 | {} |",
            fmt(&vals)
        );
    }
    for (name, split, l, _, _) in &rows {
        let split = if split == "OverlappingWindows" {
            "ours: overlapping 80/20"
        } else {
            "ours: by trajectory 80/20"
        };
        let with = match effects.is_empty() {
            true => String::new(),
            false => format!(" with {}", effects.join(", ")),
        };
        let budget = match name.as_str() {
            "physics" => format!("Levenberg–Marquardt fit{with}"),
            "hybrid" => format!("LM fit{with} + {hybrid_epochs} epochs, batch {batch}"),
            _ => format!("{epochs} epochs, batch {batch}"),
        };
        println!("| {name} (dynlab, {budget}) | {split} | {} |", fmt(l));
    }
    if let Some((_, _, _, b, _)) = rows.iter().find(|r| r.1 == "OverlappingWindows") {
        println!(
            "| constant model s⁺ = s | ours: overlapping 80/20 | {} |",
            fmt(b)
        );
    }
    if let Some((_, _, _, b, _)) = rows.iter().find(|r| r.1 == "Trajectories") {
        println!(
            "| constant model s⁺ = s | ours: by trajectory 80/20 | {} |",
            fmt(b)
        );
    }
    if let Some(path) = json {
        let v: Vec<serde_json::Value> = rows
            .iter()
            .map(|(n, s, l, b, t)| serde_json::json!({"kind": n, "split": s, "loss": l, "baseline": b, "seconds": t}))
            .collect();
        std::fs::write(path, serde_json::to_string_pretty(&v)?)?;
    }
    Ok(())
}
