//! `dynlab train`: trains a dynamics model of any kind from bags and writes the model directory
//! (`model.json`, `weights.safetensors`), the training curve `curve.csv` and `curve.png`.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, bail};
use clap::{Args, ValueEnum};
use dynlab_learn::dynamics::conventions::LossNorm;
use dynlab_learn::dynamics::ode::Solver;
use dynlab_learn::dynamics::physics::LimitSurface;
use dynlab_learn::file::TrainingMeta;
use dynlab_learn::{
    KindDefaults, Loss, ModelKind, Progress, Split, TrainConfig, World, load_bags_with, save_model,
    train,
};
use indicatif::{ProgressBar, ProgressStyle};

/// `dynlab train …`
#[derive(Debug, Args)]
pub struct TrainArgs {
    /// Bag(s) to train on (directories or .mcap files), all of the same robot.
    #[arg(long = "bag", required = true, num_args = 1.., value_name = "BAG")]
    bags: Vec<PathBuf>,
    /// Model kind: residual, node-euler, node-rk4, node-dopri5, physics, hybrid.
    #[arg(long)]
    kind: String,
    /// push or car (default: inferred from the bag's topics).
    #[arg(long)]
    world: Option<String>,
    /// Rollout steps k of the discounted multi-step loss (default: per world and kind, car
    /// residual and node-* 5, otherwise 1; the command prints what it chose).
    #[arg(long)]
    steps: Option<usize>,
    /// Discount γ in (0, 1] of the multi-step loss: step j weighs γ^(j−1) (default: per world
    /// and kind, car physics 1, otherwise 0.9; the command prints what it chose).
    #[arg(long)]
    gamma: Option<f64>,
    /// Physics effects, comma-separated (physics and hybrid only), e.g. aero_drag,steering_offset.
    #[arg(long, value_delimiter = ',')]
    effects: Vec<String>,
    /// Custom effect files (TOML: `name`, `[[term]]` tables with `state`, `feature`,
    /// `coefficient`; see learn/README.md), repeatable or comma-separated; the coefficients are
    /// fitted (physics and hybrid only; together with --effects).
    #[arg(long = "effects-file", value_delimiter = ',', value_name = "FILE")]
    effects_files: Vec<PathBuf>,
    /// Nominal physics parameters to fit, comma-separated (default: the identifiable ones; the
    /// measured mass, inertia and geometry stay fixed), e.g. Df,Dr,Cm1.
    #[arg(long, value_delimiter = ',', value_name = "NAMES")]
    free: Option<Vec<String>>,
    /// Physics fit: windows used at most (seeded subsample).
    #[arg(long, default_value_t = TrainConfig::default().physics_max_windows, value_name = "N")]
    physics_windows: usize,
    /// A physics parameter value set before the fit (repeatable), e.g. --set m=0.045 (kg).
    #[arg(long = "set", value_name = "NAME=VALUE")]
    set: Vec<String>,
    /// Pushing physics: how the pusher's force moves the block, `ellipsoid` (the ellipsoidal
    /// limit surface, closed form) or `support_points` (the support points' Coulomb friction
    /// solved exactly: off-centre pushes as the points dictate, several times slower).
    #[arg(long, value_name = "NAME", default_value = "ellipsoid")]
    limit_surface: String,
    /// Epochs (default: per world and kind, car residual and node-* 40, otherwise 300).
    #[arg(long)]
    epochs: Option<usize>,
    /// Stop after this many training windows in total.
    #[arg(long)]
    max_samples: Option<u64>,
    /// Seed of the split, shuffles and initial weights.
    #[arg(long, default_value_t = TrainConfig::default().seed)]
    seed: u64,
    /// Adam learning rate (default 1e-3).
    #[arg(long)]
    lr: Option<f64>,
    /// Batch size (default 500).
    #[arg(long)]
    batch: Option<usize>,
    /// Validation split.
    #[arg(long, value_enum, default_value_t = SplitArg::Trajectories)]
    split: SplitArg,
    /// Pushing: add N rigidly moved and turned copies of every training trajectory (pushing on a
    /// homogeneous table does not depend on the block's pose; validation data stay as recorded).
    #[arg(long, default_value_t = TrainConfig::default().augment_se2, value_name = "N")]
    augment_se2: usize,
    /// Threads (results do not depend on it).
    #[arg(long, default_value_t = 2)]
    threads: usize,
    /// Car loss norm of L_rel.
    #[arg(long, value_enum)]
    loss_norm: Option<NormArg>,
    /// Dopri5 relative tolerance (node-dopri5).
    #[arg(long)]
    rtol: Option<f64>,
    /// Dopri5 absolute tolerance (node-dopri5).
    #[arg(long)]
    atol: Option<f64>,
    #[command(flatten)]
    source: crate::source_args::SourceArgs,
    /// Output model directory.
    #[arg(long)]
    out: PathBuf,
    /// No progress bar.
    #[arg(long)]
    quiet: bool,
}

/// The `dynlab train` flags that reproduce `cfg`'s settings where they differ from what the
/// command chooses without them on `world` (what `diagnose` carries from a model's training
/// record into the command it prints). The effects, the fitted and set parameters and the
/// limit surface are the caller's; `--threads` does not change the result.
pub(crate) fn settings_flags(cfg: &TrainConfig, world: World) -> Vec<String> {
    let defaults = KindDefaults::for_kind(world, cfg.kind);
    let base = TrainConfig::default();
    let mut flags: Vec<(&str, String)> = Vec::new();
    if cfg.steps != defaults.steps {
        flags.push(("--steps", cfg.steps.to_string()));
    }
    if cfg.steps > 1 && cfg.gamma != defaults.gamma {
        flags.push(("--gamma", cfg.gamma.to_string()));
    }
    if cfg.kind.has_network() && cfg.epochs != defaults.epochs {
        flags.push(("--epochs", cfg.epochs.to_string()));
    }
    if let Some(n) = cfg.max_samples {
        flags.push(("--max-samples", n.to_string()));
    }
    if cfg.seed != base.seed {
        flags.push(("--seed", cfg.seed.to_string()));
    }
    if cfg.lr != base.lr {
        flags.push(("--lr", cfg.lr.to_string()));
    }
    if cfg.batch != base.batch {
        flags.push(("--batch", cfg.batch.to_string()));
    }
    if cfg.split == Split::OverlappingWindows {
        flags.push(("--split", "overlapping".into()));
    }
    if cfg.augment_se2 != base.augment_se2 {
        flags.push(("--augment-se2", cfg.augment_se2.to_string()));
    }
    if cfg.physics_max_windows != base.physics_max_windows {
        flags.push(("--physics-windows", cfg.physics_max_windows.to_string()));
    }
    if let Some(Loss::LRel { norm, .. }) = &cfg.loss {
        let name = match norm {
            LossNorm::L1 => "l1",
            LossNorm::L2 => "l2",
        };
        flags.push(("--loss-norm", name.into()));
    }
    flags
        .into_iter()
        .flat_map(|(f, v)| [f.to_string(), v])
        .collect()
}

#[derive(Debug, Clone, Copy, ValueEnum)]
enum SplitArg {
    /// By whole trajectories (car: 3 s segments).
    Trajectories,
    /// Tu & Lin's overlapping windows (leaks; for comparison only).
    Overlapping,
}

#[derive(Debug, Clone, Copy, ValueEnum)]
enum NormArg {
    L1,
    L2,
}

pub fn run(args: TrainArgs) -> anyhow::Result<()> {
    let kind = ModelKind::from_name(&args.kind)?;
    let world = args.world.as_deref().map(World::from_name).transpose()?;
    // read the custom effect files first: a bad file fails before the bags load
    let custom_effects = args
        .effects_files
        .iter()
        .map(|f| dynlab_learn::train::read_custom_effect(f))
        .collect::<Result<Vec<_>, _>>()?;
    let opts = args.source.options()?;
    let data = load_bags_with(&args.bags, world, &opts, &args.source.savgol(), None)?.data;
    crate::source_args::warn_about_data(&data);
    if data.transitions() < 10 {
        bail!(
            "too little data: {} transitions in {} trajectories; record more (at least 10 transitions, better thousands)",
            data.transitions(),
            data.trajectories.len()
        );
    }
    let defaults = KindDefaults::for_kind(data.world, kind);
    let mut chosen = Vec::new();
    if args.steps.is_none() {
        chosen.push(format!("--steps {}", defaults.steps));
    }
    // the discount matters only over several steps
    if args.gamma.is_none() && args.steps.unwrap_or(defaults.steps) > 1 {
        chosen.push(format!("--gamma {}", defaults.gamma));
    }
    if args.epochs.is_none() && kind.has_network() {
        chosen.push(format!("--epochs {}", defaults.epochs));
    }
    if !chosen.is_empty() {
        eprintln!(
            "defaults for a {} {kind} model: {} (pass the flag to override)",
            data.world,
            chosen.join(" ")
        );
    }
    let mut cfg = TrainConfig {
        kind,
        steps: args.steps.unwrap_or(defaults.steps),
        gamma: args.gamma.unwrap_or(defaults.gamma),
        epochs: args.epochs.unwrap_or(defaults.epochs),
        seed: args.seed,
        effects: args.effects.clone(),
        custom_effects,
        threads: args.threads.max(1),
        max_samples: args.max_samples,
        augment_se2: args.augment_se2,
        split: match args.split {
            SplitArg::Trajectories => Split::Trajectories,
            SplitArg::Overlapping => Split::OverlappingWindows,
        },
        ..Default::default()
    };
    cfg.physics_free = args.free.clone();
    cfg.limit_surface = LimitSurface::from_name(&args.limit_surface).ok_or_else(|| {
        anyhow::anyhow!(
            "--limit-surface {}: choose ellipsoid or support_points",
            args.limit_surface
        )
    })?;
    if cfg.limit_surface != LimitSurface::default() && data.world != World::Push {
        bail!("--limit-surface applies to the pushing physics model; the car has none");
    }
    cfg.physics_max_windows = args.physics_windows.max(1);
    for kv in &args.set {
        let (k, v) = kv
            .split_once('=')
            .ok_or_else(|| anyhow::anyhow!("--set {kv}: write NAME=VALUE, e.g. --set m=0.045"))?;
        let v: f64 = v
            .trim()
            .parse()
            .map_err(|_| anyhow::anyhow!("--set {kv}: the value must be a number"))?;
        cfg.physics_values.insert(k.trim().to_string(), v);
    }
    if let Some(lr) = args.lr {
        cfg.lr = lr;
    }
    if let Some(b) = args.batch {
        cfg.batch = b;
    }
    if let Some(n) = args.loss_norm {
        if data.world != World::Car {
            bail!(
                "--loss-norm applies to the car's L_rel loss; the pushing loss is Tu & Lin's weighted pose MSE"
            );
        }
        cfg.loss = Some(Loss::LRel {
            norm: match n {
                NormArg::L1 => LossNorm::L1,
                NormArg::L2 => LossNorm::L2,
            },
            eps: 0.1,
        });
    }
    if args.rtol.is_some() || args.atol.is_some() {
        if kind != ModelKind::NodeDopri5 {
            bail!("--rtol/--atol set the Dopri5 tolerances; use them with --kind node-dopri5");
        }
        let d = match kind.default_solver() {
            Some(Solver::Dopri5(o)) => o,
            _ => Default::default(),
        };
        cfg.solver = Some(Solver::dopri5(
            args.rtol.unwrap_or(d.rtol),
            args.atol.unwrap_or(d.atol),
        ));
    }
    eprintln!(
        "training a {kind} {} model on {} trajectories ({} transitions, step {:.4} s) from {} bag(s)",
        data.world,
        data.trajectories.len(),
        data.transitions(),
        data.pose_dt_s,
        data.sources.len()
    );
    let bar = if args.quiet || !kind.has_network() {
        ProgressBar::hidden()
    } else {
        ProgressBar::new(cfg.epochs as u64)
    };
    bar.set_style(
        ProgressStyle::with_template("{bar:30} epoch {pos}/{len} {msg} [{elapsed} < {eta}]")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let start = Instant::now();
    let mut on_progress = |p: &Progress| {
        let rate = p.samples as f64 / start.elapsed().as_secs_f64().max(1e-9);
        bar.set_position(p.epoch as u64);
        bar.set_message(format!(
            "train {:.3e} val {:.3e} best {:.3e} {:.0} samples/s",
            p.train_loss, p.validation_loss, p.best_validation_loss, rate
        ));
    };
    let out = train(&data, &cfg, &mut on_progress)?;
    bar.finish_and_clear();
    let mut metrics = serde_json::Map::new();
    metrics.insert(
        "best_validation_loss".into(),
        out.best_validation_loss.into(),
    );
    metrics.insert("final_train_loss".into(), out.final_train_loss.into());
    metrics.insert(
        "baseline_validation_loss".into(),
        out.baseline_validation_loss.into(),
    );
    if let Some(f) = &out.physics_fit {
        for s in &f.started {
            eprintln!("physics fit: started {s}");
        }
        metrics.insert("physics_fit".into(), serde_json::to_value(f)?);
    }
    let training = TrainingMeta {
        bags: data.sources.clone(),
        config: cfg.clone(),
        best_epoch: out.best_epoch,
        epochs_run: out.curve.len(),
        windows: out.windows,
        savgol: data.reports.iter().filter_map(|r| r.savgol).collect(),
    };
    save_model(&out.model, &args.out, Some(training), metrics)?;
    write_curve_csv(&args.out.join("curve.csv"), &out.curve)?;
    if let Err(e) = plot_curve(&args.out.join("curve.png"), &out.curve) {
        eprintln!("warning: no curve.png ({e:#})");
    }
    if let Some(p) = out.model.physics() {
        eprintln!("{p}");
    }
    println!(
        "{}: {kind} model, best validation loss {:.4e} at epoch {} (constant model {:.4e}), {} train / {} validation windows, {:.1} s",
        args.out.display(),
        out.best_validation_loss,
        out.best_epoch,
        out.baseline_validation_loss,
        out.windows.0,
        out.windows.1,
        start.elapsed().as_secs_f64()
    );
    Ok(())
}

fn write_curve_csv(path: &Path, curve: &[Progress]) -> anyhow::Result<()> {
    let mut f = std::io::BufWriter::new(
        std::fs::File::create(path).with_context(|| format!("creating {}", path.display()))?,
    );
    writeln!(
        f,
        "epoch,samples,train_loss,validation_loss,best_validation_loss"
    )?;
    for p in curve {
        writeln!(
            f,
            "{},{},{:e},{:e},{:e}",
            p.epoch, p.samples, p.train_loss, p.validation_loss, p.best_validation_loss
        )?;
    }
    f.flush()?;
    Ok(())
}

fn plot_curve(path: &Path, curve: &[Progress]) -> anyhow::Result<()> {
    use plotters::prelude::*;
    if curve.is_empty() {
        bail!("empty curve");
    }
    let vals = curve
        .iter()
        .flat_map(|p| [p.train_loss, p.validation_loss])
        .filter(|v| v.is_finite() && *v > 0.0);
    let (lo, hi) = vals.fold((f64::MAX, f64::MIN), |(a, b), v| (a.min(v), b.max(v)));
    if lo > hi {
        bail!("no positive losses to plot");
    }
    // log10 of the losses on a linear axis: readable tick labels over any range
    let (lo, hi) = (lo.log10(), hi.log10());
    let pad = ((hi - lo) * 0.1).max(0.05);
    let l10 = |v: f64| v.max(10f64.powf(lo)).log10();
    let root = BitMapBackend::new(path, (800, 500)).into_drawing_area();
    root.fill(&WHITE)?;
    let n = curve.len() as f64;
    let mut chart = ChartBuilder::on(&root)
        .caption("training curve", ("sans-serif", 22))
        .margin(10)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(1.0..n.max(2.0), (lo - pad)..(hi + pad))?;
    chart
        .configure_mesh()
        .x_desc("epoch")
        .y_desc("log10 loss")
        .y_label_formatter(&|v| format!("{v:.2}"))
        .draw()?;
    chart
        .draw_series(LineSeries::new(
            curve.iter().map(|p| (p.epoch as f64, l10(p.train_loss))),
            &BLUE,
        ))?
        .label("train")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLUE));
    chart
        .draw_series(LineSeries::new(
            curve
                .iter()
                .map(|p| (p.epoch as f64, l10(p.validation_loss))),
            &RED,
        ))?
        .label("validation")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], RED));
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()?;
    root.present()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Debug, clap::Parser)]
    struct Train {
        #[command(flatten)]
        args: TrainArgs,
    }

    fn parsed(flags: Vec<String>) -> TrainArgs {
        let required = ["train", "--bag", "b", "--kind", "hybrid", "--out", "m"];
        Train::try_parse_from(required.into_iter().map(String::from).chain(flags))
            .unwrap()
            .args
    }

    #[test]
    fn settings_flags_parse_back_to_the_settings_they_carry() {
        let cfg = TrainConfig {
            kind: ModelKind::Hybrid,
            steps: 3,
            gamma: 0.8,
            epochs: 7,
            max_samples: Some(900),
            seed: 4,
            lr: 2e-3,
            batch: 64,
            split: Split::OverlappingWindows,
            augment_se2: 2,
            physics_max_windows: 500,
            loss: Some(Loss::LRel {
                norm: LossNorm::L2,
                eps: 0.1,
            }),
            ..TrainConfig::default()
        };
        let a = parsed(settings_flags(&cfg, World::Car));
        assert_eq!(
            (a.steps, a.gamma, a.epochs, a.max_samples),
            (Some(3), Some(0.8), Some(7), Some(900))
        );
        assert_eq!((a.seed, a.lr, a.batch), (4, Some(2e-3), Some(64)));
        assert!(matches!(a.split, SplitArg::Overlapping));
        assert_eq!((a.augment_se2, a.physics_windows), (2, 500));
        assert!(matches!(a.loss_norm, Some(NormArg::L2)));
        // what train chooses by itself is not repeated
        for (world, kind) in [
            (World::Car, ModelKind::Physics),
            (World::Push, ModelKind::Physics),
            (World::Car, ModelKind::Hybrid),
        ] {
            let d = KindDefaults::for_kind(world, kind);
            let cfg = TrainConfig {
                kind,
                steps: d.steps,
                gamma: d.gamma,
                epochs: d.epochs,
                ..TrainConfig::default()
            };
            assert_eq!(settings_flags(&cfg, world), Vec::<String>::new());
        }
    }
}
