//! `dynlab diagnose`: which physical effect of the library explains a model's residual on a bag
//! (a thin adapter over `dynlab_diagnose::diagnosis`).

use std::collections::BTreeMap;
use std::path::PathBuf;

use anyhow::Context;
use clap::{Args, Parser};
use dynlab_diagnose::diagnosis::{DiagnoseConfig, Score, diagnose, diagnosis_page};
use dynlab_learn::dynamics::physics::{LimitSurface, PhysicsModel};
use dynlab_learn::{load_bags_with, load_model, pipeline_notes};

/// [`Score`] on the command line.
#[derive(Clone, Copy, Debug, clap::ValueEnum)]
enum ScoreArg {
    /// Every state dimension.
    States,
    /// The measured pose alone.
    Poses,
}

/// `dynlab diagnose …`
#[derive(Debug, Args)]
pub struct DiagnoseArgs {
    /// Model directory (from `dynlab train`; any kind).
    #[arg(long)]
    model: PathBuf,
    /// Bag(s) with the measurements (of the model's robot).
    #[arg(long = "bag", required = true, num_args = 1.., value_name = "BAG")]
    bags: Vec<PathBuf>,
    /// Output directory for diagnosis.json and diagnosis.html.
    #[arg(long, default_value = "out/diagnosis")]
    out: PathBuf,
    /// Open-loop steps k of the scored error (default: car 50, pushing 3).
    #[arg(long)]
    steps: Option<usize>,
    /// Seed of the split, subsamples and bootstrap.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Candidate effects, comma-separated (default: the world's whole library).
    #[arg(long, value_delimiter = ',')]
    effects: Option<Vec<String>>,
    /// Smallest held-out error reduction that counts (fraction).
    #[arg(long, default_value_t = 0.1)]
    min_reduction: f64,
    /// Hold the model's nominal parameters (pushing physics models otherwise refit `c`, `κ`
    /// with every candidate, and the block's measured depth `a` within ±10 % for the baseline).
    #[arg(long)]
    no_refit: bool,
    /// Refit these nominal parameters with every candidate (comma-separated; the car's grip and
    /// drivetrain: `Df,Dr,Cm1,Cm2,Cr0`).
    #[arg(long, value_delimiter = ',')]
    refit: Option<Vec<String>>,
    /// A refitted nominal parameter stays within this fraction of the model's value (e.g. 0.15;
    /// default: within its physical bounds, pushing's measured depth `a` within ±10 %).
    #[arg(long)]
    refit_tolerance: Option<f64>,
    /// Skip the drift check (whether a nominal parameter, e.g. the drive force as a battery
    /// runs down, changes from the bag's first data to its last).
    #[arg(long)]
    no_drift: bool,
    /// What the k-step error compares: `states` (every state dimension, the car's estimated
    /// velocities as well) or `poses` (the measured pose alone; the velocities still start each
    /// window, unless `--fitted-starts`). On noisy motion capture a car's velocity estimates carry errors as large as a
    /// small effect's; see the diagnose README for what each finds.
    #[arg(long, value_enum, default_value_t = ScoreArg::States)]
    score: ScoreArg,
    /// Car, physics model: re-estimate the states with the model before scoring (its motion
    /// fitted to the poses within S seconds of each sample, e.g. 0.1) in place of the
    /// Savitzky–Golay estimates. On noisy motion capture it shows a steady effect (drag, an
    /// offset, a lag) more clearly, and it hides what changes within the span (a grip patch, a
    /// command delay, a servo): see the diagnose README ("States from the model").
    #[arg(long, value_name = "S")]
    model_states: Option<f64>,
    /// Car, physics model: start every model's windows from its own fit to the poses of the S
    /// seconds before each window (e.g. 0.1) in place of the estimated states there; with
    /// `--score poses`, nothing a model is scored on is an estimate. See the diagnose README
    /// ("Fitted starts").
    #[arg(long, value_name = "S")]
    fitted_starts: Option<f64>,
    /// Forward selection adds at most this many effects.
    #[arg(long, default_value_t = 3)]
    max_effects: usize,
    /// Also train the model with the selected effects (and the custom effect of terms found
    /// beyond the library) on the same bags (`dynlab train --kind physics --effects …
    /// [--effects-file …]`), written to `<out>/model`.
    #[arg(long)]
    apply: bool,
    #[command(flatten)]
    source: crate::source_args::SourceArgs,
}

pub fn run(args: DiagnoseArgs) -> anyhow::Result<()> {
    let (model, meta) = load_model(&args.model, None, None)
        .with_context(|| format!("loading the model {}", args.model.display()))?;
    let opts = args.source.options()?;
    let mut data = load_bags_with(
        &args.bags,
        Some(model.world()),
        &opts,
        &args.source.savgol(),
        None,
    )?
    .data;
    // a car model steps a fixed dt: poses at another rate are resampled to it (as compare does)
    if model.world() == dynlab_learn::World::Car
        && (data.pose_dt_s - model.dt()).abs() > 0.01 * model.dt()
    {
        println!(
            "data: poses every {:.2} ms; the model steps {:.2} ms: resampled to the model's step",
            data.pose_dt_s * 1e3,
            model.dt() * 1e3
        );
        data = load_bags_with(
            &args.bags,
            Some(model.world()),
            &opts,
            &args.source.savgol(),
            Some(model.dt()),
        )?
        .data;
    }
    crate::source_args::warn_about_data(&data);
    let effects = match &args.effects {
        Some(names) => {
            let n: Vec<&str> = names.iter().map(|s| s.as_str()).collect();
            Some(PhysicsModel::parse_effects(&n)?)
        }
        None => None,
    };
    let cfg = DiagnoseConfig {
        steps: args.steps,
        seed: args.seed,
        effects,
        min_reduction: args.min_reduction,
        refit_nominal: if args.no_refit {
            Some(false)
        } else if args.refit.is_some() {
            Some(true)
        } else {
            None
        },
        max_effects: args.max_effects,
        refit_params: args.refit.clone(),
        refit_tolerance: args.refit_tolerance,
        drift: !args.no_drift,
        model_states: args.model_states,
        fitted_starts: args.fitted_starts,
        score: match args.score {
            ScoreArg::States => Score::States,
            ScoreArg::Poses => Score::Poses,
        },
        ..DiagnoseConfig::default()
    };
    let d = diagnose(&model, &data, &cfg)?;
    print!("{}", d.table());
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let json = args.out.join("diagnosis.json");
    let mut value = d.to_json();
    if let Some(obj) = value.as_object_mut() {
        // how the data were read: pose source, a damaged bag's recovery, skipped poses
        let notes: Vec<Vec<String>> = data.reports.iter().map(pipeline_notes).collect();
        obj.insert("data_notes".into(), serde_json::to_value(notes)?);
    }
    std::fs::write(&json, serde_json::to_string_pretty(&value)? + "\n")
        .with_context(|| format!("writing {}", json.display()))?;
    let html = args.out.join("diagnosis.html");
    std::fs::write(&html, diagnosis_page(&d))
        .with_context(|| format!("writing {}", html.display()))?;
    println!("report: {} and {}", json.display(), html.display());
    // a significant term beyond the library: its custom effect file, to train with
    let custom = match d.discovery.as_ref().and_then(|x| {
        x.terms
            .iter()
            .any(|t| t.significant)
            .then_some(x.effect_toml.as_ref())
            .flatten()
    }) {
        Some(text) => {
            let f = args.out.join("custom_effect.toml");
            std::fs::write(&f, text).with_context(|| format!("writing {}", f.display()))?;
            println!("custom effect: {}", f.display());
            Some(f)
        }
        None => None,
    };
    if d.effects.is_empty() && custom.is_none() && d.limit_surface.is_none() {
        return Ok(());
    }
    let kind = if model.kind().name() == "hybrid" {
        "hybrid"
    } else {
        "physics"
    };
    let mut train: Vec<String> = vec!["train".into()];
    for b in &args.bags {
        train.extend(["--bag".into(), b.display().to_string()]);
    }
    // the model's world: bags under other topic names do not tell it
    train.extend([
        "--world".into(),
        model.world().name().into(),
        "--kind".into(),
        kind.into(),
    ]);
    // the model's own effects stay, the selected ones follow
    let effects: Vec<&str> = d
        .model_effects
        .iter()
        .chain(&d.effects)
        .map(String::as_str)
        .collect();
    if !effects.is_empty() {
        train.extend(["--effects".into(), effects.join(",")]);
    }
    // what the model carries beyond train's defaults (its measured nominal values, its own
    // effects' values, its limit surface), then the diagnosis's values: the fit starts from
    // them, and from the defaults it may not find them (a patch elsewhere, a servo's rate
    // limit from its no-limit bound), with the nominal parameters refitted with them but not
    // for the baseline (a grip patch's friction-ellipse weight)
    let mut sets: BTreeMap<String, f64> = model.physics().map(carried).unwrap_or_default();
    if let Some(j) = &d.joint {
        let effects = j.params.iter().map(|(k, v)| (k, *v));
        for (name, v) in effects.chain(d.coupled_nominal(&j.nominal_params)) {
            sets.insert(name.clone(), v);
        }
    }
    // the limit surface the diagnosis took, or the model's own
    let surface = match &d.limit_surface {
        Some(s) => Some(s.to.clone()),
        None => model
            .physics()
            .map(|p| p.limit_surface())
            .filter(|s| *s != LimitSurface::default())
            .map(|s| s.name().to_string()),
    };
    if let Some(s) = surface {
        train.extend(["--limit-surface".into(), s]);
    }
    if let Some(free) = model.physics().and_then(|p| d.train_free(p)) {
        train.extend(["--free".into(), free.join(",")]);
    }
    // the model's own custom effects at its coefficients (the fit starts from them), then the
    // discovered one
    for c in model
        .physics()
        .map(|p| p.custom_effects())
        .unwrap_or_default()
    {
        let f = args.out.join(format!("model_effect_{}.toml", c.name()));
        std::fs::write(&f, c.to_toml()).with_context(|| format!("writing {}", f.display()))?;
        train.extend(["--effects-file".into(), f.display().to_string()]);
    }
    if let Some(f) = &custom {
        train.extend(["--effects-file".into(), f.display().to_string()]);
        // from the nominal parameters the term search refitted with its terms (a grip term's
        // friction-ellipse weight)
        for (name, v) in d.discovery.iter().flat_map(|x| &x.nominal) {
            sets.insert(name.clone(), *v);
        }
    }
    for (name, v) in sets {
        train.extend(["--set".into(), format!("{name}={v}")]);
    }
    // trained as the model was (its steps, seed, windows, … where not train's defaults)
    if let Some(t) = &meta.training {
        train.extend(crate::train_cmd::settings_flags(&t.config, model.world()));
    }
    let src = &args.source;
    for (flag, v) in [
        ("--pose-topic", &src.pose_topic),
        ("--pose-tf", &src.pose_tf),
        ("--cmd-topic", &src.cmd_topic),
    ] {
        if let Some(v) = v {
            train.extend([flag.into(), v.clone()]);
        }
    }
    if src.strict {
        train.push("--strict".into());
    }
    train.extend(src.savgol_flags());
    train.extend(["--out".into(), args.out.join("model").display().to_string()]);
    let shown = train.join(" ");
    if !args.apply {
        println!("add them: dynlab {shown}   (or rerun with --apply)");
        return Ok(());
    }
    println!("applying: dynlab {shown}");
    let parsed = ApplyTrain::try_parse_from(std::iter::once("dynlab".to_string()).chain(train))
        .context("building the train command for --apply")?;
    let ApplyCommand::Train(t) = parsed.command;
    crate::train_cmd::run(t)
}

/// The `dynlab train` command line that `--apply` runs.
#[derive(Debug, clap::Parser)]
struct ApplyTrain {
    #[command(subcommand)]
    command: ApplyCommand,
}

#[derive(Debug, clap::Subcommand)]
enum ApplyCommand {
    Train(crate::train_cmd::TrainArgs),
}

/// The values `physics` holds that `dynlab train` would not start from: the nominal parameters
/// a fit holds (measured: a block's size, a car's mass) where they differ from their defaults,
/// and the parameters of its own effects.
fn carried(physics: &PhysicsModel) -> BTreeMap<String, f64> {
    physics
        .param_specs()
        .into_iter()
        .zip(physics.param_names())
        .zip(physics.params().iter().zip(physics.default_free()))
        .filter(|(((owner, spec), _), (v, free))| owner.is_some() || (!free && **v != spec.default))
        .map(|((_, name), (v, _))| (name, *v))
        .collect()
}
