//! The model file: a directory `MODEL/` with a readable `model.json` (format version, kind,
//! world, solver, network spec, normalisation, physics effects with fitted parameters and
//! standard errors, training bags with SHA-256, seed, k, dt, settings, final metrics) and, for
//! kinds with a network, `weights.safetensors`. Loading validates everything.

use std::path::{Path, PathBuf};

use dynlab_dynamics::data::SavGol;
use dynlab_dynamics::ode::Solver;
use dynlab_dynamics::physics::{CustomEffect, LimitSurface, PhysicsModel};
use dynlab_nn::Mlp;
use serde::{Deserialize, Serialize};

use crate::dataset::BagSource;
use crate::net::{Network, Normalization};
use crate::train::TrainConfig;
use crate::{LearnError, Model, ModelKind, World};

/// The `format` value of every model file.
pub const FORMAT: &str = "dynlab-model";
/// The newest format version this build writes and reads.
pub const FORMAT_VERSION: u32 = 1;
/// Metadata file name.
pub const MODEL_JSON: &str = "model.json";
/// Weights file name.
pub const WEIGHTS: &str = "weights.safetensors";

/// The network part of `model.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct NetworkMeta {
    /// Layer sizes `[n_in, …, n_out]`.
    pub sizes: Vec<usize>,
    /// Hidden activations (`tanh`, `gelu`, …).
    pub activations: Vec<String>,
    /// Number of parameters.
    pub n_params: usize,
    /// Input names (learned state dimensions, then the action).
    pub inputs: Vec<String>,
    /// Output names.
    pub outputs: Vec<String>,
    /// What the output means.
    pub output: String,
}

/// One physical parameter in `model.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ParamEntry {
    /// Qualified name (`m`, `aero_drag.c`).
    pub name: String,
    /// Fitted value.
    pub value: f64,
    /// Standard error of the fit, if known.
    pub std: Option<f64>,
    /// Unit.
    pub unit: String,
}

/// The physics part of `model.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PhysicsMeta {
    /// Effects enabled, in order.
    pub effects: Vec<String>,
    /// Solver of the physics model over one step.
    pub solver: Solver,
    /// Custom effects (terms over named features, see
    /// [`dynlab_dynamics::physics::custom`]) in order, with their fitted coefficients; their
    /// parameters are `custom.<name>.<j>` after the effects'. Absent: none.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub custom_effects: Vec<CustomEffect>,
    /// Pushing: how the pusher's force moves the block (absent: the ellipsoidal limit surface).
    #[serde(default, skip_serializing_if = "is_ellipsoid")]
    pub limit_surface: LimitSurface,
    /// Every parameter (nominal, effects, then custom terms) in vector order.
    pub params: Vec<ParamEntry>,
    /// The model's equations as printed by the physics crate (for reading only).
    pub equations: String,
}

/// How a model was trained.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TrainingMeta {
    /// Bags with their SHA-256.
    pub bags: Vec<BagSource>,
    /// The settings (seed, steps k, γ, epochs, lr, batch, split, …).
    pub config: TrainConfig,
    /// Epoch of the best-validation checkpoint.
    pub best_epoch: usize,
    /// Epochs run.
    pub epochs_run: usize,
    /// Training and validation windows.
    pub windows: (usize, usize),
    /// Car data: the Savitzky–Golay settings each bag's velocities were estimated with (in the
    /// order of `bags`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub savgol: Vec<SavGol>,
}

/// Everything in `model.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ModelFile {
    /// Always `dynlab-model`.
    pub format: String,
    /// Format version (this build: [`FORMAT_VERSION`]).
    pub format_version: u32,
    /// Model kind.
    pub kind: ModelKind,
    /// World.
    pub world: World,
    /// Model step \[s\] (pushing: time between pushes; the dynamics step one push).
    pub dt: f64,
    /// State names.
    pub state: Vec<String>,
    /// Action names.
    pub action: Vec<String>,
    /// Network solver (NeuralODE kinds).
    pub solver: Option<Solver>,
    /// Network spec.
    pub network: Option<NetworkMeta>,
    /// Network normalisation.
    pub normalization: Option<Normalization>,
    /// Physics model.
    pub physics: Option<PhysicsMeta>,
    /// Training record.
    pub training: Option<TrainingMeta>,
    /// Final metrics (validation loss, baseline, …).
    #[serde(default)]
    pub metrics: serde_json::Map<String, serde_json::Value>,
}

impl ModelFile {
    /// The Savitzky–Golay fit a live state estimate for this model should use: the one its
    /// training data's velocities came from (per window, the median over its bags), so the
    /// model sees states as noisy as those it learned from; the default (15 poses) for a model
    /// without that record.
    pub fn state_fit(&self) -> SavGol {
        let fits = self.training.as_ref().map_or(&[][..], |t| &t.savgol[..]);
        if fits.is_empty() {
            return SavGol::default();
        }
        let median = |f: &dyn Fn(&SavGol) -> usize| {
            let mut v: Vec<usize> = fits.iter().map(f).collect();
            v.sort_unstable();
            v[v.len() / 2]
        };
        let window = median(&|s| s.window);
        let yaw = median(&|s| s.yaw_window.unwrap_or(s.window));
        SavGol {
            window,
            order: median(&|s| s.order),
            yaw_window: (yaw != window).then_some(yaw),
            adaptive: false,
        }
    }

    /// The metadata of `model` (training record and metrics empty).
    pub fn describe(model: &Model) -> Self {
        let world = model.world();
        let names = |v: &[&str]| v.iter().map(|s| s.to_string()).collect::<Vec<_>>();
        let lr = world.learned_dims();
        let learned: Vec<String> = world.state_names()[lr]
            .iter()
            .map(|s| s.to_string())
            .collect();
        let network = model.network().map(|n| NetworkMeta {
            sizes: n.mlp.sizes().to_vec(),
            activations: n.mlp.spec().activations().iter().map(|a| a.to_string()).collect(),
            n_params: n.mlp.n_params(),
            inputs: learned
                .iter()
                .cloned()
                .chain(names(world.action_names()))
                .collect(),
            outputs: learned.iter().map(|s| format!("d{s}")).collect(),
            output: match model.kind() {
                ModelKind::Residual => "change of the outputs per step (added to the state)",
                ModelKind::Hybrid => "correction added to the physics model's next state",
                _ => "time derivative of the outputs per unit of normalised step time (integrated over [0, 1])",
            }
            .to_string(),
        });
        let physics = model.physics().map(|p| PhysicsMeta {
            effects: p.effects().iter().map(|e| e.name().to_string()).collect(),
            solver: model.physics_solver(),
            custom_effects: p.custom_effects(),
            limit_surface: p.limit_surface(),
            params: p
                .param_names()
                .into_iter()
                .zip(p.params())
                .zip(p.param_specs())
                .enumerate()
                .map(|(i, ((name, &value), (_, spec)))| ParamEntry {
                    name,
                    value,
                    std: p
                        .std_errors()
                        .and_then(|s| s.get(i).copied())
                        .filter(|v| v.is_finite()),
                    unit: spec.unit.to_string(),
                })
                .collect(),
            equations: p.equations(),
        });
        Self {
            format: FORMAT.to_string(),
            format_version: FORMAT_VERSION,
            kind: model.kind(),
            world,
            dt: model.dt(),
            state: names(world.state_names()),
            action: names(world.action_names()),
            solver: model.solver(),
            network,
            normalization: model.network().map(|n| n.norm.clone()),
            physics,
            training: None,
            metrics: Default::default(),
        }
    }
}

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> LearnError + '_ {
    move |source| LearnError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// Writes `model` to the directory `dir` (created if needed) with its training record and
/// metrics.
pub fn save_model(
    model: &Model,
    dir: &Path,
    training: Option<TrainingMeta>,
    metrics: serde_json::Map<String, serde_json::Value>,
) -> Result<(), LearnError> {
    std::fs::create_dir_all(dir).map_err(io(dir))?;
    let mut meta = ModelFile::describe(model);
    meta.training = training;
    meta.metrics = metrics;
    let json = serde_json::to_string_pretty(&meta).map_err(|e| LearnError::CorruptModel {
        path: dir.to_path_buf(),
        reason: format!("cannot serialise the metadata: {e}"),
    })?;
    let weights = dir.join(WEIGHTS);
    match model.network() {
        Some(n) => {
            // Byte-stable: the same network always gives the same file.
            let bytes = n
                .mlp
                .to_safetensors()
                .map_err(|e| LearnError::CorruptModel {
                    path: weights.clone(),
                    reason: e.to_string(),
                })?;
            std::fs::write(&weights, bytes).map_err(io(&weights))?;
        }
        None => {
            if weights.exists() {
                std::fs::remove_file(&weights).map_err(io(&weights))?;
            }
        }
    }
    let path = dir.join(MODEL_JSON);
    std::fs::write(&path, json + "\n").map_err(io(&path))?;
    Ok(())
}

/// Reads and validates `model.json` only.
pub fn read_meta(dir: &Path) -> Result<ModelFile, LearnError> {
    let path = dir.join(MODEL_JSON);
    if !dir.is_dir() {
        return Err(LearnError::CorruptModel {
            path: dir.to_path_buf(),
            reason: "not a model directory (expected a directory with model.json)".into(),
        });
    }
    let text = std::fs::read_to_string(&path).map_err(io(&path))?;
    let value: serde_json::Value =
        serde_json::from_str(&text).map_err(|e| LearnError::CorruptModel {
            path: path.clone(),
            reason: format!("not valid JSON ({e})"),
        })?;
    if value.get("format").and_then(|v| v.as_str()) != Some(FORMAT) {
        return Err(LearnError::CorruptModel {
            path: path.clone(),
            reason: format!("\"format\" is not \"{FORMAT}\""),
        });
    }
    let version = value
        .get("format_version")
        .and_then(|v| v.as_u64())
        .ok_or_else(|| LearnError::CorruptModel {
            path: path.clone(),
            reason: "\"format_version\" is missing".into(),
        })?;
    if version > u64::from(FORMAT_VERSION) {
        return Err(LearnError::NewerFormat {
            path: dir.to_path_buf(),
            found: u32::try_from(version).unwrap_or(u32::MAX),
            supported: FORMAT_VERSION,
        });
    }
    serde_json::from_value(value).map_err(|e| LearnError::CorruptModel {
        path,
        reason: e.to_string(),
    })
}

fn is_ellipsoid(s: &LimitSurface) -> bool {
    *s == LimitSurface::Ellipsoid
}

/// The physics parameters of a model file written by an earlier dynlab, completed:
/// - a pushing model written before the block was a rectangle (its parameters `a, c, L, kappa,
///   …` without `b`) gets the block width `b` = the side `a` right after `kappa`: such a file
///   describes a square block, and loads as one;
/// - a car model written before the friction ellipse had a weight (its nominal parameters end
///   at `v_reg`) gets `ellipse` = 1 right after `v_reg`: such a model had the full ellipse.
fn upgraded_params(expected: &[String], params: &[ParamEntry]) -> Vec<ParamEntry> {
    let mut params = with_block_width(expected, params);
    let after_v_reg = |at: usize| at > 0 && expected[at - 1] == "v_reg";
    if let Some(at) = expected.iter().position(|n| n == "ellipse")
        && after_v_reg(at)
        && params.len() + 1 == expected.len()
        && params.iter().all(|e| e.name != "ellipse")
        && params.get(at - 1).is_some_and(|e| e.name == "v_reg")
    {
        let full = ParamEntry {
            name: "ellipse".into(),
            value: 1.0,
            std: Some(0.0),
            unit: "-".into(),
        };
        params.insert(at, full);
    }
    params
}

/// [`upgraded_params`]' first part: the block width of a square block's file.
fn with_block_width(expected: &[String], params: &[ParamEntry]) -> Vec<ParamEntry> {
    let mut params = params.to_vec();
    let square = ["a", "c", "L", "kappa"];
    let is_pushing = expected.len() > square.len() && expected[..4] == square && expected[4] == "b";
    if is_pushing
        && params.len() + 1 == expected.len()
        && params.iter().zip(square).all(|(e, n)| e.name == n)
        && params.iter().all(|e| e.name != "b")
    {
        let side = &params[0];
        let width = ParamEntry {
            name: "b".into(),
            value: side.value,
            std: side.std,
            unit: side.unit.clone(),
        };
        params.insert(4, width);
    }
    params
}

/// Loads a model directory, validating every part. `kind` and `world`, when given, must match.
pub fn load_model(
    dir: &Path,
    kind: Option<ModelKind>,
    world: Option<World>,
) -> Result<(Model, ModelFile), LearnError> {
    let meta = read_meta(dir)?;
    let corrupt = |reason: String| LearnError::CorruptModel {
        path: dir.to_path_buf(),
        reason,
    };
    if let Some(k) = kind
        && k != meta.kind
    {
        return Err(LearnError::KindMismatch {
            path: dir.to_path_buf(),
            found: meta.kind.name().into(),
            expected: k.name().into(),
        });
    }
    if let Some(w) = world
        && w != meta.world
    {
        return Err(LearnError::WorldMismatch {
            what: format!("the model {}", dir.display()),
            found: meta.world.name().into(),
            expected: w.name().into(),
            hint: "use a model trained on data of the same robot".into(),
        });
    }
    // the fits live state estimates take from the record (`ModelFile::state_fit`)
    for (i, fit) in meta.training.iter().flat_map(|t| &t.savgol).enumerate() {
        fit.validate()
            .map_err(|e| corrupt(format!("training.savgol[{i}]: {e}")))?;
    }
    let net = match (&meta.network, meta.kind.has_network()) {
        (Some(nm), true) => {
            let wpath: PathBuf = dir.join(WEIGHTS);
            let bytes = std::fs::read(&wpath).map_err(io(&wpath))?;
            let acts = nm
                .activations
                .iter()
                .map(|a| a.parse::<dynlab_nn::Activation>())
                .collect::<Result<Vec<_>, _>>()
                .map_err(|e| corrupt(format!("network.activations: {e}")))?;
            let spec = dynlab_nn::MlpSpec::new(&nm.sizes, &acts)
                .map_err(|e| corrupt(format!("network: {e}")))?;
            let mut mlp = Mlp::zeros(spec);
            mlp.load_safetensors(&bytes)
                .map_err(|e| LearnError::CorruptModel {
                    path: wpath.clone(),
                    reason: format!(
                        "{e} (model.json says the network is {:?} {:?})",
                        nm.sizes, nm.activations
                    ),
                })?;
            let norm = meta
                .normalization
                .clone()
                .ok_or_else(|| corrupt("\"normalization\" is missing".into()))?;
            Some(Network::new(mlp, norm))
        }
        (None, true) => return Err(corrupt(format!("a {} model needs \"network\"", meta.kind))),
        (_, false) => None,
    };
    let (physics, physics_solver) = match (&meta.physics, meta.kind.has_physics()) {
        (Some(pm), true) => {
            let names: Vec<&str> = pm.effects.iter().map(|s| s.as_str()).collect();
            let effects =
                PhysicsModel::parse_effects(&names).map_err(|e| corrupt(e.to_string()))?;
            let mut p = PhysicsModel::new(meta.world.robot(), &effects)
                .map_err(|e| corrupt(e.to_string()))?;
            for c in &pm.custom_effects {
                p.add_custom(c.clone())
                    .map_err(|e| corrupt(format!("physics.custom_effects: {e}")))?;
            }
            p.set_limit_surface(pm.limit_surface)
                .map_err(|e| corrupt(format!("physics.limit_surface: {e}")))?;
            let expected = p.param_names();
            let params = upgraded_params(&expected, &pm.params);
            let got: Vec<String> = params.iter().map(|e| e.name.clone()).collect();
            if expected != got {
                return Err(corrupt(format!(
                    "physics parameters {got:?} do not match the model's {expected:?}"
                )));
            }
            let values: Vec<f64> = params.iter().map(|e| e.value).collect();
            p.set_params(&values).map_err(|e| corrupt(e.to_string()))?;
            let std: Vec<f64> = params.iter().map(|e| e.std.unwrap_or(f64::NAN)).collect();
            p.set_std_errors(Some(std))
                .map_err(|e| corrupt(e.to_string()))?;
            (Some(p), pm.solver)
        }
        (None, true) => return Err(corrupt(format!("a {} model needs \"physics\"", meta.kind))),
        (_, false) => (None, crate::train::default_physics_solver(meta.world)),
    };
    let model = Model::new(
        meta.kind,
        meta.world,
        meta.dt,
        meta.solver,
        net,
        physics,
        physics_solver,
    )
    .map_err(|e| corrupt(e.to_string()))?;
    Ok((model, meta))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn with_fits(fits: &[SavGol]) -> ModelFile {
        let p = crate::train::physics_model(World::Car, &[]).unwrap();
        let model = Model::new(
            ModelKind::Physics,
            World::Car,
            0.01,
            None,
            None,
            Some(p),
            Solver::Rk4 { substeps: 1 },
        )
        .unwrap();
        let mut meta = ModelFile::describe(&model);
        meta.training = Some(TrainingMeta {
            bags: Vec::new(),
            config: TrainConfig::default(),
            best_epoch: 0,
            epochs_run: 0,
            windows: (0, 0),
            savgol: fits.to_vec(),
        });
        meta
    }

    #[test]
    fn the_live_fit_is_the_training_datas_median_window_per_component() {
        let fit = |window, yaw: Option<usize>| SavGol {
            window,
            yaw_window: yaw,
            adaptive: true,
            ..SavGol::default()
        };
        assert_eq!(with_fits(&[]).state_fit(), SavGol::default());
        let mut none = with_fits(&[]);
        none.training = None;
        assert_eq!(none.state_fit(), SavGol::default());
        // three bags: x/y 27, 21, 33 → 27; yaw 15, 21, 15 → 15; recorded as fixed settings
        let three = with_fits(&[fit(27, Some(15)), fit(21, None), fit(33, Some(15))]);
        assert_eq!(
            three.state_fit(),
            SavGol {
                window: 27,
                yaw_window: Some(15),
                ..SavGol::default()
            }
        );
        let same = with_fits(&[fit(21, None), fit(15, Some(21)), fit(21, None)]);
        assert_eq!(
            same.state_fit(),
            SavGol {
                window: 21,
                ..SavGol::default()
            }
        );
    }
}
