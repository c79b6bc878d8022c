//! The term search beyond the effect library on a bag: prints the table (terms, error removed,
//! significance, the custom effect file) and writes `discovery.json`, `discovery.html` and the
//! effect file `<name>.toml` when a term is found. Without `--model` the documented nominal
//! physics model of the bag's robot is searched.
//!
//! `cargo run --release -p dynlab-diagnose --example discover -- --bag BAG [--model DIR]
//! [--out DIR] [--seed S] [--steps K]`

use std::path::PathBuf;

use dynlab_diagnose::discovery::{DiscoveryConfig, discover_terms, discovery_page};
use dynlab_learn::dynamics::data::SavGol;
use dynlab_learn::dynamics::physics::PhysicsModel;
use dynlab_learn::train::default_physics_solver;
use dynlab_learn::{Model, ModelKind, Topics, load_bags, load_model};

fn arg(name: &str) -> Option<String> {
    let a: Vec<String> = std::env::args().collect();
    a.iter()
        .position(|x| x == name)
        .and_then(|i| a.get(i + 1))
        .cloned()
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let bag = PathBuf::from(arg("--bag").ok_or("give --bag BAG")?);
    let data = load_bags(&[bag], None, &Topics::default(), &SavGol::default())?;
    let model = match arg("--model") {
        Some(dir) => load_model(&PathBuf::from(dir), None, Some(data.world))?.0,
        None => Model::new(
            ModelKind::Physics,
            data.world,
            data.pose_dt_s,
            None,
            None,
            Some(PhysicsModel::new(data.world.robot(), &[])?),
            default_physics_solver(data.world),
        )?,
    };
    let cfg = DiscoveryConfig {
        seed: arg("--seed").and_then(|s| s.parse().ok()).unwrap_or(0),
        steps: arg("--steps").and_then(|s| s.parse().ok()),
        ..DiscoveryConfig::default()
    };
    let d = discover_terms(&model, &data, &cfg)?;
    print!("{}", d.table());
    if let Some(out) = arg("--out").map(PathBuf::from) {
        std::fs::create_dir_all(&out)?;
        std::fs::write(out.join("discovery.json"), d.to_json() + "\n")?;
        std::fs::write(out.join("discovery.html"), discovery_page(&d))?;
        if let Some(t) = &d.effect_toml {
            std::fs::write(out.join(format!("{}.toml", cfg.name)), t)?;
        }
        eprintln!("wrote {}", out.display());
    }
    Ok(())
}
