//! Open-world recovery on the pushing world: anisotropic table friction, an effect outside the
//! diagnosis library, found by the term search beyond it; and nominal pushing data, where
//! nothing may be found.
//!
//! For every seed: a pushing world whose parameters are perturbed from the nominal ones
//! (`PushScenario::perturbed`: block size, mass, table and obstacle friction and pusher radius
//! each scaled by its own seeded factor in [1 − f, 1 + f]; `--perturb 0` for the nominal
//! world), `--episodes` × 10 explorer pushes of it (noise ×2: 1 mm, 4 mrad; every episode
//! starts at a heading drawn within ±`--jitter-deg` of the scenario's), the physics model
//! fitted on those (`dynlab train --kind physics` with its defaults), then data of the same
//! world on a table with a grain (`[effects.anisotropic_friction]`: μ₂ = ratio·μ₁ across the
//! grain at angle γ), diagnosed (`diagnose`, which runs the term search after the library's
//! forward selection). Per seed: the library effects named, the significant terms beyond the
//! library (target, feature, coefficient ± σ, the held-out 3-step error each removes), the
//! grain angle the `ẏ_b` terms on `ℓ·cos φ·sin 2θ`, `ℓ·cos φ·cos 2θ` imply, and the proof that
//! the term is worth having: the physics model trained on the same anisotropic data with the discovered
//! custom effect (`TrainConfig::custom_effects`, the `dynlab train --effects-file` path) against
//! without, both evaluated on fresh held-out episodes of that world (3-step loss and position
//! and heading RMSE). Then the library's own effects in the same perturbed worlds (`--only
//! library`; `--cases a,b+c`, default every pushing effect alone and in pairs): each hidden at
//! the recovery's strength (`simdata::add_push_effect`), diagnosed with the model fitted on the
//! world's nominal pushes; per seed what was named (✗: not exactly the hidden set), the held-out
//! error the selection removes and the strengths against the truth. Then the nominal case: data
//! of the fitted world without any effect, diagnosed: nothing named, no significant term.
//!
//! The expected signature: a frictionless pusher presses along the pushed face's normal, the
//! block heading `θ`, and advances along it by `ℓ·L·cos φ`; on the anisotropic table the block's
//! velocity turns from that normal towards the grain (maximum dissipation on the friction
//! ellipse: for a force at `α = θ − γ` to the grain, `tan β = tan α/ratio²`), a sideways drift
//! in the block frame whose first harmonic is
//! `ẏ_b ≈ A·ℓ·cos φ·sin 2(θ−γ) = A cos 2γ·ℓ·cos φ·sin 2θ − A sin 2γ·ℓ·cos φ·cos 2θ`, `A < 0`
//! (towards the grain).
//!
//! Why the defaults are 100 episodes and headings all round: a grain has no sign (axial,
//! period π in θ), a table tilt has one (polar, period 2π). With the explorer's own ±45° the
//! block's headings stay within about a quarter turn, where the drift towards a grain at γ and
//! the drift down a slope along γ look alike, and the library's `table_tilt` took 66–94 % of
//! the error (tilt along the grain); with headings all round they differ. With 200 pushes the
//! term was the first one tried but its bootstrap bound (at `0.05/M` over 10 held-out
//! segments) stayed below 0.
//!
//! `cargo run --release -p dynlab-diagnose --example push_open_world -- [--seeds N]
//! [--first-seed N] [--nominal-seeds N] [--perturb F] [--episodes N] [--noise X] [--ratio R]
//! [--angle-deg G | --random-angle] [--jitter-deg D] [--no-library] [--only aniso|library|nominal]
//! [--cases a,b+c]
//! [--refit a,c,kappa] [--pusher-speed V] [--pusher-acceleration A]
//! [--limit-surface support_points]` (`--refit`: the nominal parameters the fit of the world's
//! model frees and the diagnosis refits, default `c`, `kappa`; `--limit-surface`: the pushing
//! model's, default `ellipsoid`; the pusher's cruise speed \[m/s\] and acceleration \[m/s²\], default the
//! simulator's 0.1 and 0.4)
//! (defaults 5 seeds from 0, 10 nominal seeds, f = 0.1, 100 × 10 pushes, noise ×2, ratio 2,
//! γ = 30°, start headings within ±180°; `--random-angle` draws γ per seed, uniform in
//! [0°, 180°), from the seed; `--jitter-deg 45` is the explorer's default; `--no-library` runs
//! the term search on the fitted model without the library's selection); `VERBOSE=1` prints
//! every diagnosis.

use std::time::Instant;

use dynlab_diagnose::diagnosis::simdata::{add_push_effect, push_dataset_with, push_scenario};
use dynlab_diagnose::diagnosis::{DiagnoseConfig, Diagnosis, diagnose, push_level_dataset};
use dynlab_learn::dynamics::data::SplitMix64;
use dynlab_learn::dynamics::physics::{Effect, LimitSurface, Robot, Target};
use dynlab_learn::eval::evaluate;
use dynlab_learn::train::{TrainConfig, train};
use dynlab_learn::{Dataset, Model, ModelKind};
use dynlab_sim::push::AnisotropicFriction;
use dynlab_sim::{PushExplorer, PushScenario};

fn opt<T: std::str::FromStr>(name: &str) -> Option<T> {
    let a: Vec<String> = std::env::args().collect();
    a.iter()
        .position(|x| x == name)
        .and_then(|i| a.get(i + 1))
        .and_then(|v| v.parse().ok())
}

fn arg<T: std::str::FromStr>(name: &str, default: T) -> T {
    opt(name).unwrap_or(default)
}

/// The held-out error of a model on fresh data: 3-step loss, position RMSE \[mm\] and heading
/// RMSE \[mrad\] after 3 pushes.
struct Held {
    loss: f64,
    pos_mm: f64,
    yaw_mrad: f64,
}

fn held_out(model: &Model, data: &Dataset) -> Result<Held, Box<dyn std::error::Error>> {
    let r = evaluate(model, data, 3, 3.0)?;
    let rm = |i: usize| r.k_step.get(i).map_or(f64::NAN, |d| d.rmse);
    Ok(Held {
        loss: r.loss,
        pos_mm: 1e3 * (rm(0).powi(2) + rm(1).powi(2)).sqrt(),
        yaw_mrad: 1e3 * rm(2),
    })
}

/// The grain angle \[deg, in [0, 180)\] that `by += a·ℓ·cos φ·sin 2θ + b·ℓ·cos φ·cos 2θ`
/// implies (`A sin 2(θ−γ)` with `A < 0`: `a = A cos 2γ`, `b = −A sin 2γ`), with the strength
/// `|A|`.
fn implied_grain(a: f64, b: f64) -> (f64, f64) {
    let g = 0.5 * b.atan2(-a).to_degrees();
    (g.rem_euclid(180.0), a.hypot(b))
}

/// The significant terms beyond the library: (target, feature, coefficient, σ, reduction).
fn terms_of(d: &Diagnosis) -> Vec<(String, String, f64, f64, f64)> {
    d.discovery
        .as_ref()
        .map(|disc| {
            disc.terms
                .iter()
                .filter(|t| t.significant)
                .map(|t| {
                    (
                        t.state.clone(),
                        t.feature.clone(),
                        t.coefficient,
                        t.std,
                        t.error_reduction,
                    )
                })
                .collect()
        })
        .unwrap_or_default()
}

type Res<T> = Result<T, Box<dyn std::error::Error>>;

/// The fitted strength of effect `e` against the truth the simulator hides it with
/// ([`add_push_effect`]) in world `s`: (parameter, fitted, truth). A tilt and a patch are
/// fitted relative to the table's friction, which the perturbation scales.
fn strength(e: Effect, s: &PushScenario, d: &Diagnosis) -> Option<(String, f64, f64)> {
    let mu = s.block.table_friction;
    let (key, truth) = match e {
        Effect::ComOffset => ("ox", 0.02),
        Effect::TableTilt => ("gx", 0.02_f64.tan() / mu),
        Effect::FrictionPatch => ("k", 0.5 / mu),
        Effect::PusherFriction => ("mu", 0.5),
        Effect::FlatPusher => ("half_width", 0.012),
        _ => return None,
    };
    let name = format!("{}.{key}", e.name());
    let v = *d.joint.as_ref()?.params.get(&name)?;
    Some((name, v, truth))
}

/// Every library case (one pushing effect or several) in the perturbed worlds of the seeds:
/// the world's model fitted on its nominal pushes, data with the case's effects hidden,
/// diagnosed; per seed what was named, the held-out error the selection removes and the
/// strengths against the truth; per case how often the named set is exactly the hidden one.
fn library_cases(
    first_seed: u64,
    seeds: u64,
    cases: &[Vec<Effect>],
    world: &dyn Fn(u64) -> Res<(PushScenario, Model)>,
    pushes: &dyn Fn(&PushScenario, u64) -> Res<Dataset>,
    diag_cfg: &dyn Fn(u64) -> DiagnoseConfig,
) -> Res<()> {
    let verbose = std::env::var("VERBOSE").is_ok();
    println!(
        "\n{:<34} {:<5} {:<34} {:>8} {:>8} {:<60} {:>6}",
        "hidden (library)", "seed", "named", "removed", "vs given", "fitted (truth)", "time/s"
    );
    let mut summary = Vec::new();
    let worlds: Vec<(PushScenario, Model)> = (first_seed..first_seed + seeds)
        .map(world)
        .collect::<Result<_, _>>()?;
    for case in cases {
        let label = case
            .iter()
            .map(|e| e.name())
            .collect::<Vec<_>>()
            .join(" + ");
        let (mut exact, mut removed, mut vs_given) = (0, Vec::new(), Vec::new());
        for (seed, (scenario, model)) in (first_seed..).zip(&worlds) {
            let t0 = Instant::now();
            let mut hidden = scenario.clone();
            for &e in case {
                add_push_effect(&mut hidden, e);
            }
            let data = pushes(&hidden, 8000 + seed)?;
            let d = diagnose(model, &data, &diag_cfg(seed))?;
            if verbose {
                let b = &scenario.block;
                println!(
                    "--- {label}, seed {seed} (block {:.1} × {:.1} mm, {:.3} kg, table μ {:.4}, pusher radius {:.2} mm)\n{}",
                    1e3 * b.size[0],
                    1e3 * b.size[1],
                    b.mass,
                    b.table_friction,
                    1e3 * scenario.pusher.radius,
                    d.table()
                );
            }
            let mut named: Vec<&str> = d.effects.iter().map(String::as_str).collect();
            named.sort_unstable();
            let mut truth: Vec<&str> = case.iter().map(|e| e.name()).collect();
            truth.sort_unstable();
            let hit = named == truth;
            exact += usize::from(hit);
            let red = d.joint.as_ref().map_or(0.0, |j| j.error_reduction);
            let given = d.joint.as_ref().map_or(0.0, |j| j.reduction_vs_model);
            removed.push(red);
            vs_given.push(given);
            let fitted: Vec<String> = case
                .iter()
                .filter_map(|&e| strength(e, scenario, &d))
                .map(|(n, v, t)| format!("{n} {v:.4} ({t:.4})"))
                .collect();
            println!(
                "{:<34} {:<5} {:<34} {:>7.1}% {:>7.1}% {:<60} {:>6.1}",
                label,
                seed,
                if named.is_empty() {
                    "—".to_string()
                } else {
                    d.effects.join(", ")
                } + if hit { "" } else { " ✗" },
                100.0 * red,
                100.0 * given,
                fitted.join(", "),
                t0.elapsed().as_secs_f64()
            );
        }
        summary.push((label, exact, removed, vs_given));
    }
    println!(
        "\nlibrary cases in perturbed worlds over {seeds} seeds: exactly the hidden set named; the held-out error the selection removes, min / mean / max, from the baseline (the nominal parameters refitted) and from the model as given"
    );
    for (label, exact, removed, vs_given) in summary {
        println!(
            "{label:<34} {exact}/{seeds}   {}   (as given: {})",
            span(&removed),
            span(&vs_given)
        );
    }
    Ok(())
}

/// Min / mean / max of fractions `v`, in per cent.
fn span(v: &[f64]) -> String {
    let lo = v.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let m = v.iter().sum::<f64>() / v.len().max(1) as f64;
    format!("{:.0} / {:.0} / {:.0} %", 100.0 * lo, 100.0 * m, 100.0 * hi)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let seeds: u64 = arg("--seeds", 5);
    let first_seed: u64 = arg("--first-seed", 0);
    let nominal_seeds: u64 = arg("--nominal-seeds", 10);
    let perturb: f64 = arg("--perturb", 0.1);
    let episodes: u64 = arg("--episodes", 100);
    let noise: f64 = arg("--noise", 2.0);
    let ratio: f64 = arg("--ratio", 2.0);
    let angle_deg: f64 = arg("--angle-deg", 30.0);
    let random_angle = std::env::args().any(|a| a == "--random-angle");
    let only: String = arg("--only", String::new());
    let jitter_deg: f64 = arg("--jitter-deg", 180.0);
    let no_library = std::env::args().any(|a| a == "--no-library");
    let refit: String = arg("--refit", String::new());
    let refit: Option<Vec<String>> =
        (!refit.is_empty()).then(|| refit.split(',').map(String::from).collect());
    let defaults = PushScenario::default().pusher;
    let pusher_speed: f64 = arg("--pusher-speed", defaults.speed);
    let pusher_acceleration: f64 = arg("--pusher-acceleration", defaults.acceleration);
    let surface: String = arg(
        "--limit-surface",
        LimitSurface::default().name().to_string(),
    );
    let limit_surface = LimitSurface::from_name(&surface)
        .ok_or_else(|| format!("--limit-surface {surface}: choose ellipsoid or support_points"))?;
    let verbose = std::env::var("VERBOSE").is_ok();
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    println!(
        "pushing open world: {episodes} × 10 pushes, noise ×{noise}, parameters perturbed ±{:.0} %; anisotropic table friction ratio {ratio} (outside the library)",
        100.0 * perturb
    );
    let explorer = PushExplorer {
        pushes_per_episode: 10,
        start_jitter: [0.05, 0.05, jitter_deg.to_radians()],
        ..PushExplorer::default()
    };
    let pushes = |s: &PushScenario, seed: u64| -> Result<Dataset, Box<dyn std::error::Error>> {
        // a slower pusher needs longer between pushes
        let explorer = PushExplorer {
            push_period: explorer.push_period.max(s.max_push_time().ceil()),
            ..explorer.clone()
        };
        Ok(push_level_dataset(push_dataset_with(
            s, &explorer, episodes, seed, threads,
        )?))
    };
    let diag_cfg = |seed: u64| DiagnoseConfig {
        seed,
        effects: no_library.then(Vec::new),
        refit_params: refit.clone(),
        ..DiagnoseConfig::default()
    };
    // the fitted model of a seed's world, and that world
    let world = |seed: u64| -> Result<(PushScenario, Model), Box<dyn std::error::Error>> {
        let mut s = push_scenario(None, noise);
        s.pusher.speed = pusher_speed;
        s.pusher.acceleration = pusher_acceleration;
        if perturb > 0.0 {
            s = s.perturbed(7000 + seed, perturb)?;
        }
        let nominal = pushes(&s, 5000 + seed)?;
        let tc = TrainConfig {
            kind: ModelKind::Physics,
            seed,
            physics_free: refit.clone(),
            limit_surface,
            ..TrainConfig::default()
        };
        Ok((s, train(&nominal, &tc, &mut |_| {})?.model))
    };
    let name = |t: &str| Target::from_name(t).map_or(t.to_string(), |x| x.symbol().to_string());
    // the library's cases: `--cases a+b,c` (default every pushing effect alone and in pairs)
    let cases: Vec<Vec<Effect>> = match opt::<String>("--cases") {
        Some(list) => list
            .split(',')
            .map(|case| {
                case.split('+')
                    .map(|n| {
                        Effect::from_name(n.trim())
                            .filter(|e| e.robot() == Robot::Pushing)
                            .ok_or_else(|| {
                                format!("--cases: '{n}' is not a pushing effect of the library")
                            })
                    })
                    .collect::<Result<Vec<_>, _>>()
            })
            .collect::<Result<_, _>>()?,
        None => {
            let push: Vec<Effect> = Effect::ALL
                .into_iter()
                .filter(|e| e.robot() == Robot::Pushing)
                .collect();
            let mut cases: Vec<Vec<Effect>> = push.iter().map(|&e| vec![e]).collect();
            for (i, &a) in push.iter().enumerate() {
                cases.extend(push[i + 1..].iter().map(|&b| vec![a, b]));
            }
            cases
        }
    };

    if only.is_empty() || only == "aniso" {
        println!(
            "\n{:<5} {:>6} {:<16} {:<62} {:>8} {:>24} {:>24} {:>6}",
            "seed",
            "γ/deg",
            "library named",
            "terms beyond the library (held-out 3-step error removed)",
            "removed",
            "trained without: loss/mm/mrad",
            "with the term: loss/mm/mrad",
            "time/s"
        );
        let mut named = 0;
        let (mut on_grain, mut right_sign) = (0, 0);
        let (mut found, mut removed, mut better) = (0, Vec::new(), 0);
        let mut gains = Vec::new();
        for seed in first_seed..first_seed + seeds {
            let t0 = Instant::now();
            let gamma = if random_angle {
                let u = (SplitMix64::new(0xA115_0000 ^ seed).next_u64() >> 11) as f64
                    / (1u64 << 53) as f64;
                std::f64::consts::PI * u
            } else {
                angle_deg.to_radians()
            };
            let (scenario, model) = world(seed)?;
            let mut hidden = scenario.clone();
            hidden.effects.anisotropic_friction = Some(AnisotropicFriction {
                enabled: true,
                ratio,
                angle: gamma,
            });
            let data = pushes(&hidden, 1000 + seed)?;
            let test = pushes(&hidden, 3000 + seed)?;
            let d = diagnose(&model, &data, &diag_cfg(seed))?;
            if verbose {
                println!("--- anisotropic, seed {seed}\n{}", d.table());
            }
            named += usize::from(!d.effects.is_empty());
            let terms = terms_of(&d);
            let mut text: Vec<String> = terms
                .iter()
                .map(|(s, f, c, sd, r)| {
                    let sym = dynlab_learn::dynamics::physics::features::Feature::parse(f)
                        .map_or(f.clone(), |x| x.symbol());
                    format!("{} += {c:+.4}±{sd:.1e}·{sym} ({:.0} %)", name(s), 100.0 * r)
                })
                .collect();
            let coef = |feature: &str| {
                terms
                    .iter()
                    .find(|t| t.0 == "by" && t.1 == feature)
                    .map_or(0.0, |t| t.2)
            };
            let (a, b) = (coef("l*cos_phi*sin_2theta"), coef("l*cos_phi*cos_2theta"));
            // the grain's terms with the sign the truth gives (A < 0: a = A cos 2γ,
            // b = −A sin 2γ; a component under 0.2 |A| has no sign to check)
            let grain_terms = usize::from(a != 0.0) + usize::from(b != 0.0);
            let signed = |v: f64, truth: f64| truth.abs() < 0.2 || v * truth > 0.0;
            let right = grain_terms > 0
                && (a == 0.0 || signed(a, -(2.0 * gamma).cos()))
                && (b == 0.0 || signed(b, (2.0 * gamma).sin()));
            right_sign += usize::from(right);
            on_grain += usize::from(grain_terms > 0);
            if a != 0.0 && b != 0.0 {
                let (g, amp) = implied_grain(a, b);
                text.push(format!("grain {g:.0}°, |A| {amp:.4}"));
            }
            let disc = d.discovery.as_ref();
            let red = disc.map_or(0.0, |x| x.error_reduction);
            let (before, after) = match disc.and_then(|x| x.effect.clone()) {
                Some(effect) => {
                    found += 1;
                    removed.push(red);
                    let tc = TrainConfig {
                        kind: ModelKind::Physics,
                        seed,
                        physics_free: refit.clone(),
                        limit_surface,
                        ..TrainConfig::default()
                    };
                    let without = train(&data, &tc, &mut |_| {})?.model;
                    let with = train(
                        &data,
                        &TrainConfig {
                            custom_effects: vec![effect],
                            ..tc
                        },
                        &mut |_| {},
                    )?
                    .model;
                    if verbose && let Some(p) = with.physics() {
                        println!("trained with the term:\n{}", p.equations());
                    }
                    let (b, a) = (held_out(&without, &test)?, held_out(&with, &test)?);
                    better += usize::from(a.loss < b.loss);
                    gains.push(1.0 - a.loss / b.loss);
                    (
                        format!("{:.5}/{:.2}/{:.1}", b.loss, b.pos_mm, b.yaw_mrad),
                        format!("{:.5}/{:.2}/{:.1}", a.loss, a.pos_mm, a.yaw_mrad),
                    )
                }
                None => ("—".into(), "—".into()),
            };
            println!(
                "{:<5} {:>6.1} {:<16} {:<62} {:>7.1}% {:>24} {:>24} {:>6.1}",
                seed,
                gamma.to_degrees(),
                if d.effects.is_empty() {
                    "—".to_string()
                } else {
                    d.effects.join(",")
                },
                if text.is_empty() {
                    "no significant term".to_string()
                } else {
                    text.join("; ")
                },
                100.0 * red,
                before,
                after,
                t0.elapsed().as_secs_f64()
            );
        }
        println!(
            "anisotropic friction over {seeds} seeds: a library effect named in {named}/{seeds}; a term beyond the library in {found}/{seeds} (on ẏ_b with ℓ·cos φ·sin 2θ or ℓ·cos φ·cos 2θ in {on_grain}, with the truth's sign in {right_sign}), held-out error removed min/mean/max {}; training with it lowered the held-out loss in {better}/{found} (by {})",
            span(&removed),
            span(&gains)
        );
    }

    if only.is_empty() || only == "library" {
        library_cases(first_seed, seeds, &cases, &world, &pushes, &diag_cfg)?;
    }

    if only.is_empty() || only == "nominal" {
        println!(
            "\n{:<5} {:>13} {:<40} {:<70} {:>6}",
            "seed", "block/mm", "library named", "term search", "time/s"
        );
        let (mut clean, mut sig, mut bound, mut named_on_bound) = (0, 0, 0, 0);
        for seed in first_seed..first_seed + nominal_seeds {
            let t0 = Instant::now();
            let (scenario, model) = world(100 + seed)?;
            let data = pushes(&scenario, 1500 + seed)?;
            let d = diagnose(&model, &data, &diag_cfg(seed))?;
            if verbose {
                println!("--- nominal, seed {seed}\n{}", d.table());
            }
            let terms = terms_of(&d);
            clean += usize::from(d.effects.is_empty());
            sig += usize::from(!terms.is_empty());
            let on_bound = !d.nominal_on_bound.is_empty();
            bound += usize::from(on_bound);
            named_on_bound += usize::from(on_bound && !d.effects.is_empty());
            let [bx, by] = scenario.block.size;
            println!(
                "{:<5} {:>6.1}×{:<6.1} {:<40} {:<70} {:>6.1}",
                seed,
                1e3 * bx,
                1e3 * by,
                if d.effects.is_empty() {
                    if on_bound {
                        "— (a nominal parameter on its bound)"
                    } else {
                        "—"
                    }
                    .to_string()
                } else {
                    d.selection
                        .iter()
                        .filter_map(|s| {
                            let c = s
                                .candidates
                                .iter()
                                .find(|c| Some(&c.effect) == s.added.as_ref())?;
                            let p: Vec<String> = c
                                .params
                                .iter()
                                .map(|(k, v)| format!("{k} {v:.4}"))
                                .collect();
                            Some(format!("{} ({})", c.effect, p.join(", ")))
                        })
                        .collect::<Vec<_>>()
                        .join(", ")
                        + if on_bound {
                            " (a nominal parameter on its bound)"
                        } else {
                            ""
                        }
                },
                d.discovery
                    .as_ref()
                    .map_or("not searched".to_string(), |x| x.summary.clone()),
                t0.elapsed().as_secs_f64()
            );
        }
        println!(
            "nominal over {nominal_seeds} seeds: nothing named in {clean}/{nominal_seeds}; a significant term in {sig}/{nominal_seeds}; a refitted nominal parameter on its bound in {bound} (of those, named: {named_on_bound})"
        );
    }
    Ok(())
}
