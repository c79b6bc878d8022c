//! How well the nominal pusher–slider predicts the simulator's nominal pushes: one-push and
//! k-push errors of the world-line pusher model (`PhysicsModel::integrate_step`, the model's
//! step) and of the older block-frame pusher (the plain vector field integrated directly, which
//! holds contact point and push direction in the block frame), side by side.
//!
//! `cargo run --release -p dynlab-diagnose --example push_nominal -- [--episodes N] [--noise X]
//! [--seed S] [--effect NAME]`

use dynlab_diagnose::diagnosis::push_level_dataset;
use dynlab_diagnose::diagnosis::simdata::{push_dataset, push_scenario};
use dynlab_learn::dynamics::conventions::wrap_angle;
use dynlab_learn::dynamics::ode::{self, Solver};
use dynlab_learn::dynamics::physics::{Effect, PhysicsModel};

fn arg<T: std::str::FromStr>(name: &str, default: T) -> T {
    let a: Vec<String> = std::env::args().collect();
    a.iter()
        .position(|x| x == name)
        .and_then(|i| a.get(i + 1))
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

fn truth(e: Option<Effect>) -> Vec<(&'static str, f64)> {
    match e {
        Some(Effect::ComOffset) => vec![("com_offset.ox", 0.02), ("com_offset.oy", 0.01)],
        Some(Effect::TableTilt) => vec![("table_tilt.gx", 0.02f64.tan() / 0.1)],
        Some(Effect::FrictionPatch) => vec![
            ("friction_patch.cx", 0.5),
            ("friction_patch.cy", 0.1),
            ("friction_patch.r", 0.1),
            ("friction_patch.w", 0.002),
            ("friction_patch.k", 5.0),
        ],
        Some(Effect::PusherFriction) => vec![("pusher_friction.mu", 0.5)],
        _ => vec![],
    }
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let episodes: u64 = arg("--episodes", 20);
    let noise: f64 = arg("--noise", 0.0);
    let seed: u64 = arg("--seed", 7);
    let effect: String = arg("--effect", String::new());
    let eff = Effect::from_name(&effect);
    let data = push_level_dataset(push_dataset(
        &push_scenario(eff, noise),
        episodes,
        10,
        seed,
        2,
    )?);
    let mut model = PhysicsModel::pushing(&[])?;
    model.set_param("c", arg("--c", 0.0383))?;
    println!(
        "nominal pusher–slider on simulator pushes ({}), {episodes} × 10 pushes, noise ×{noise}",
        eff.map_or("nominal".to_string(), |e| e.name().to_string())
    );
    println!(
        "{:<28} {:>6} {:>12} {:>12} {:>10}",
        "model step", "k", "pos RMS/mm", "θ RMS/mrad", "ratio"
    );
    // the effect at the simulator's value (diagnosis::simdata::push_scenario)
    let mut with = PhysicsModel::pushing(&eff.into_iter().collect::<Vec<_>>())?;
    with.set_param("c", arg("--c", 0.0383))?;
    for (name, v) in truth(eff) {
        with.set_param(name, v)?;
    }
    for k in [1usize, 5] {
        let mut base = (0.0, 0.0);
        for (name, world_line, substeps, m) in [
            ("block-frame pusher (old)", false, 2, &model),
            ("world-line pusher, rk4×2", true, 2, &model),
            ("world-line pusher, rk4×8", true, 8, &model),
            ("world-line + effect (truth)", true, 2, &with),
        ] {
            let model = m;
            if eff.is_none() && std::ptr::eq(m, &with) {
                continue;
            }
            let solver = Solver::Rk4 { substeps };
            let (mut ep, mut et, mut cnt) = (0.0, 0.0, 0usize);
            for t in &data.trajectories {
                let n = t.len();
                for a in 0..n.saturating_sub(k) {
                    let mut s = t.s[a * 3..a * 3 + 3].to_vec();
                    for j in 0..k {
                        let u = &t.u[(a + j) * 3..(a + j) * 3 + 3];
                        let mut o = [0.0; 3];
                        if world_line {
                            model.integrate_step(&solver, 1, &s, u, 1.0, &mut o);
                        } else {
                            ode::integrate(model, &solver, 1, &s, u, 1.0, &mut o);
                        }
                        s.copy_from_slice(&o);
                    }
                    let m = &t.s[(a + k) * 3..(a + k) * 3 + 3];
                    if k == 1 && substeps == 8 && std::env::var("VERBOSE").is_ok() {
                        let u = &t.u[a * 3..a * 3 + 3];
                        let s0 = &t.s[a * 3..a * 3 + 3];
                        println!(
                            "u = ({:+.2}, {:+.2}, {:.2})  dθ meas {:+.4} model {:+.4}  dpos meas ({:+.4}, {:+.4}) err ({:+.4}, {:+.4})",
                            u[0],
                            u[1],
                            u[2],
                            wrap_angle(m[2] - s0[2]),
                            wrap_angle(s[2] - s0[2]),
                            m[0] - s0[0],
                            m[1] - s0[1],
                            s[0] - m[0],
                            s[1] - m[1]
                        );
                    }
                    ep += (s[0] - m[0]).powi(2) + (s[1] - m[1]).powi(2);
                    et += wrap_angle(s[2] - m[2]).powi(2);
                    cnt += 1;
                }
            }
            let pos = 1e3 * (ep / cnt.max(1) as f64).sqrt();
            let th = 1e3 * (et / cnt.max(1) as f64).sqrt();
            if !world_line {
                base = (pos, th);
            }
            println!(
                "{name:<28} {k:>6} {pos:>12.3} {th:>12.3} {:>10.3}",
                pos / base.0.max(1e-12)
            );
        }
    }
    Ok(())
}
