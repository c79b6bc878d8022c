//! Anisotropic table friction, a pushing effect outside the diagnosis library, on simulator
//! data: the library names nothing and the term search beyond it finds the grain's sideways
//! drift on the doubled heading, `ẏ_b += a·ℓ·cos φ·sin 2θ + b·ℓ·cos φ·cos 2θ`, with the signs
//! the grain's angle gives; on nominal data of the same kind no grain term is found.
//!
//! The data: the simulator's pushing world (`[effects.anisotropic_friction]`, ratio 2, grain at
//! 30°), 100 explorer episodes of 10 pushes starting at headings all round (a grain has no sign
//! and a table tilt has one: with the explorer's ±45° the library's `table_tilt` takes most of
//! the error), noise ×2; the model is the nominal pushing physics model, whose `c` and `κ` the
//! diagnosis refits. Everything is seeded.

use dynlab_diagnose::diagnosis::simdata::{nominal_model, push_dataset_with, push_scenario};
use dynlab_diagnose::diagnosis::{DiagnoseConfig, Diagnosis, diagnose};
use dynlab_learn::dynamics::physics::CustomEffect;
use dynlab_learn::{Dataset, World};
use dynlab_sim::PushExplorer;
use dynlab_sim::push::AnisotropicFriction;

/// The grain's features.
///
/// Over seeds 0–9 of this set-up (measured once, printed by the test with `--nocapture`): a
/// significant grain term in 10/10, first on `ℓ·cos φ·cos 2θ`, the `sin 2θ` one second in 8,
/// every sign the truth's, 43–78 % of the held-out 3-step error removed; the library named
/// `friction_patch` (a disc of higher friction) beside it in 1/10 (seed 3) until a patch had to
/// remove more than the best sideways-drift term (the grain's). The test runs two, seed 3
/// among them.
const GRAIN: [&str; 2] = ["l*cos_phi*sin_2theta", "l*cos_phi*cos_2theta"];

fn data(grain: Option<f64>, seed: u64) -> Dataset {
    data_of(grain, 100, seed)
}

fn data_of(grain: Option<f64>, episodes: u64, seed: u64) -> Dataset {
    let mut s = push_scenario(None, 2.0);
    s.effects.anisotropic_friction = grain.map(|angle| AnisotropicFriction {
        enabled: true,
        ratio: 2.0,
        angle,
    });
    let explorer = PushExplorer {
        start_jitter: [0.05, 0.05, std::f64::consts::PI],
        ..PushExplorer::default()
    };
    push_dataset_with(&s, &explorer, episodes, 4100 + seed, 2).unwrap()
}

fn diagnosed(data: &Dataset, seed: u64) -> Diagnosis {
    let model = nominal_model(World::Push, data.pose_dt_s).unwrap();
    let cfg = DiagnoseConfig {
        seed,
        ..DiagnoseConfig::default()
    };
    diagnose(&model, data, &cfg).unwrap()
}

#[test]
fn anisotropic_friction_is_found_beyond_the_library() {
    let gamma = 30f64.to_radians();
    for seed in [1u64, 3] {
        let d = diagnosed(&data(Some(gamma), seed), seed);
        let table = d.table();
        println!("seed {seed}\n{table}");
        // no library effect stands in for the grain
        assert!(d.effects.is_empty(), "{table}");
        let disc = d.discovery.as_ref().expect("the term search runs");
        let found: Vec<_> = disc.terms.iter().filter(|t| t.significant).collect();
        assert!(!found.is_empty(), "{table}");
        // the first term is the grain's drift in the block frame
        assert_eq!(found[0].state, "by", "{table}");
        assert!(GRAIN.contains(&found[0].feature.as_str()), "{table}");
        // signs: ẏ_b = A·ℓ·cos φ·sin 2(θ − γ) with A < 0 (towards the grain), so the sin 2θ
        // coefficient is A·cos 2γ < 0 and the cos 2θ one −A·sin 2γ > 0 for γ = 30°
        for t in found.iter().filter(|t| t.state == "by") {
            match t.feature.as_str() {
                "l*cos_phi*sin_2theta" => assert!(t.coefficient < 0.0, "{table}"),
                "l*cos_phi*cos_2theta" => assert!(t.coefficient > 0.0, "{table}"),
                _ => {}
            }
        }
        assert!(disc.error_reduction >= 0.4, "{table}");
        // the custom effect file holds the term and reads back as the same effect (what
        // `dynlab train --effects-file` reads)
        let toml = disc.effect_toml.as_ref().expect("an effect file");
        assert!(toml.contains(&found[0].feature), "{toml}");
        assert_eq!(
            CustomEffect::from_toml(toml).unwrap(),
            *disc.effect.as_ref().unwrap()
        );
    }
}

/// Nominal data of the same kind: nothing named, and no term on the grain's features. (With
/// 1000 pushes the nominal model's own structural error can show as a term on other features —
/// `ẏ_b` on `ℓ·sin φ`, the block sliding sideways under an angled push more than the model
/// predicts; that is the model, not a grain.)
#[test]
fn nominal_pushing_data_have_no_grain_term() {
    let seed = 2;
    let d = diagnosed(&data(None, seed), seed);
    let table = d.table();
    println!("nominal seed {seed}\n{table}");
    assert!(d.effects.is_empty(), "{table}");
    let disc = d.discovery.as_ref().expect("the term search runs");
    assert!(
        disc.terms
            .iter()
            .all(|t| !(t.significant && GRAIN.contains(&t.feature.as_str()))),
        "{table}"
    );
}

/// 30 episodes: 15 held-out segments, where the held-out half alone does not bound the grain
/// term's reduction; the second look (the term fitted on the held-out half, both halves scored)
/// does. The same set-up without the grain: no significant term.
#[test]
fn the_term_search_second_look_finds_the_grain_on_fewer_pushes() {
    let seed = 5;
    let d = diagnosed(&data_of(Some(30f64.to_radians()), 30, seed), seed);
    let table = d.table();
    let disc = d.discovery.as_ref().expect("the term search runs");
    let t = &disc.terms[0];
    assert_eq!(
        (t.state.as_str(), t.feature.as_str()),
        ("by", "l*cos_phi*cos_2theta"),
        "{table}"
    );
    assert!(t.error_reduction >= 0.1 && t.ci_lower <= 0.0, "{table}");
    let look = t.cross_fit.as_ref().expect("a second look");
    assert!(look.counts(0.1), "{table}");
    assert!(t.significant && t.coefficient > 0.0, "{table}");
    // the held-out half's own fit has the truth's sign
    assert!(look.params["coefficient"] > 0.0, "{table}");
    assert!(table.contains("both halves:"), "{table}");
    let nominal = diagnosed(&data_of(None, 30, seed), seed);
    let disc = nominal.discovery.as_ref().expect("the term search runs");
    assert!(
        disc.terms.iter().all(|t| !t.significant),
        "{}",
        nominal.table()
    );
}
