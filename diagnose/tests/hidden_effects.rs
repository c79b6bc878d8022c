//! Diagnosis on simulator data with one hidden effect (issue 5, "Tests on data with a hidden
//! effect"): for each car effect of the library, data with only that effect on and mocap-like
//! noise → `diagnose` puts it first and significant, and adding it cuts the held-out k-step error
//! by at least half; nominal data → no significant effect. The model under diagnosis is the
//! nominal physics model at its documented values (the simulator's nominal car).
//!
//! Data are generated in process (seeded), small but sufficient: 3 episodes of 15 s at 100 Hz
//! (4 × 30 s for the regional effects). One seed per case: the spread over seeds is measured by
//! `launch_scripts/eval_diagnose.sh` (our simulator) and `eval_foreign.sh` (an independent
//! generator), and for the term search by `discovery.rs`.

use dynlab_diagnose::diagnosis::simdata::{
    car_dataset, car_scenario, low_grip_band, nominal_model, over_low_grip_band,
};
use dynlab_diagnose::diagnosis::{DiagnoseConfig, Diagnosis, diagnose, diagnosis_html};
use dynlab_learn::World;
use dynlab_learn::dynamics::physics::Effect;

fn run_car(effect: Option<Effect>, seed: u64) -> Diagnosis {
    run_car_with(effect, seed, None)
}

fn run_car_with(effect: Option<Effect>, seed: u64, effects: Option<Vec<Effect>>) -> Diagnosis {
    run_scenario(&car_scenario(effect, 1.0), 300 + seed, seed, effects)
}

/// The nominal physics model at its documented values diagnosed on 3 × 15 s of `scenario`.
fn run_scenario(
    scenario: &dynlab_sim::CarScenario,
    data_seed: u64,
    seed: u64,
    effects: Option<Vec<Effect>>,
) -> Diagnosis {
    run_episodes(scenario, [3.0, 15.0], data_seed, seed, effects)
}

/// … on `episodes[0]` × `episodes[1]` s of `scenario`.
fn run_episodes(
    scenario: &dynlab_sim::CarScenario,
    episodes: [f64; 2],
    data_seed: u64,
    seed: u64,
    effects: Option<Vec<Effect>>,
) -> Diagnosis {
    let data = car_dataset(scenario, episodes[0] as u64, episodes[1], data_seed, 2).unwrap();
    let model = nominal_model(World::Car, data.pose_dt_s).unwrap();
    // fewer windows than the defaults, for time; more on 4 × 30 s (with 250 fit and 1000 scored
    // windows a grip patch's joint fit removed 44 % of the held-out error)
    let [fit_windows, score_windows] = match episodes[0] * episodes[1] > 60.0 {
        true => [400, 1500],
        false => [250, 1000],
    };
    let cfg = DiagnoseConfig {
        seed,
        fit_windows,
        score_windows,
        bootstrap: 500,
        effects,
        ..DiagnoseConfig::default()
    };
    diagnose(&model, &data, &cfg).unwrap()
}

fn assert_found(d: &Diagnosis, e: Effect, param: &str, truth: f64, tol: f64) {
    let table = d.table();
    assert_eq!(d.verdict.as_deref(), Some(e.name()), "{table}");
    let first = &d.candidates[0];
    assert_eq!(first.effect, e.name(), "{table}");
    assert!(first.significant, "{table}");
    let got = first.params[param];
    assert!(
        (got - truth).abs() <= tol,
        "{param} = {got}, truth {truth}\n{table}"
    );
    assert!(first.param_std[param] > 0.0, "{table}");
    // the forward selection adds this effect alone, and it removes at least half of the
    // held-out error of the model as given
    assert_eq!(d.effects, [e.name()], "{table}");
    let joint = d.joint.as_ref().expect("a joint fit");
    assert!(joint.reduction_vs_model >= 0.5, "{table}");
}

#[test]
fn car_nominal_data_has_no_significant_effect() {
    let d = run_car(None, 1);
    assert_eq!(d.verdict, None, "{}", d.table());
    assert!(d.candidates.iter().all(|c| !c.significant), "{}", d.table());
    assert!(d.summary.contains("no effect in the library explains"));
    assert!(!d.correlations.is_empty());
    // the car stayed the same while it was recorded
    let drift = d.drift.as_ref().expect("the drift is checked");
    assert!(!drift.significant, "{}", d.table());
    assert!(!d.summary.contains("drift:"), "{}", d.summary);
}

#[test]
fn car_aero_drag_is_found_and_its_coefficient_recovered() {
    // the simulator's F = −c|v|v with c = 0.01 N s²/m²
    let d = run_car(Some(Effect::AeroDrag), 2);
    assert_found(&d, Effect::AeroDrag, "c", 0.01, 0.001);
}

#[test]
fn car_motor_lag_is_found_and_its_time_constant_recovered() {
    let d = run_car(Some(Effect::MotorLag), 3);
    assert_found(&d, Effect::MotorLag, "tau", 0.2, 0.03);
}

#[test]
fn car_steering_offset_is_found_and_recovered() {
    let d = run_car(Some(Effect::SteeringOffset), 4);
    assert_found(&d, Effect::SteeringOffset, "delta0", 0.03, 0.003);
}

#[test]
fn car_steering_servo_rate_limit_is_found() {
    // a 50 ms lag with a hard 3 rad/s clamp, the library's servo a smooth one
    let d = run_car(Some(Effect::SteeringLag), 8);
    assert_found(&d, Effect::SteeringLag, "rate", 3.0, 1.0);
}

#[test]
fn car_command_delay_is_found_and_its_delay_recovered() {
    // both commands applied 60 ms late (exact); the library's delay a Padé filter
    let d = run_car(Some(Effect::CommandDelay), 9);
    assert_found(&d, Effect::CommandDelay, "delay", 0.06, 0.015);
}

/// A disc of radius 0.6 m at (0.5, 0) with half the tire peak force, 4 × 30 s. On
/// 3 × 15 s (8 held-out segments) the fitted disc was right (k 0.455 and 0.486, r 0.61) and
/// removed 86 and 95 % of the held-out error, but only the one or two segments that cross the
/// patch gained and the bootstrap bound was −52 % and −125 %. (Beside the patch, for time, the
/// effects without states of their own and the motor's lag: the servo's and the delay's fits on
/// 2 min of data took most of this test's time, and they have tests of their own above.)
#[test]
fn car_grip_patch_is_found() {
    let effects = vec![
        Effect::GripPatch,
        Effect::AeroDrag,
        Effect::SteeringOffset,
        Effect::MotorLag,
    ];
    let seed = 6;
    let scenario = car_scenario(Some(Effect::GripPatch), 1.0);
    let d = run_episodes(&scenario, [4.0, 30.0], 300 + seed, seed, Some(effects));
    assert_found(&d, Effect::GripPatch, "k", 0.5, 0.15);
    let p = &d.candidates[0].params;
    // the centre within a third of the radius
    let off = (p["cx"] - 0.5).hypot(p["cy"]);
    assert!(off < 0.2 && (p["r"] - 0.6).abs() < 0.1, "{}", d.table());
    // the car has the full friction ellipse: its weight is held at the model's 1 or
    // refitted near it, never wandered off where the data hardly tell it
    let ellipse = d.candidates[0].nominal_params.get("ellipse");
    assert!(ellipse.is_none_or(|w| *w > 0.8), "{}", d.table());
    // held in the joint fit, training is told to hold it too
    let model = nominal_model(World::Car, 0.01).unwrap();
    let free = d.train_free(model.physics().unwrap());
    let joint = d.joint.as_ref().unwrap();
    match joint.nominal_params.contains_key("ellipse") {
        true => assert!(free.is_none(), "{free:?}"),
        false => {
            let free = free.unwrap();
            assert!(free.iter().any(|n| n == "Df") && !free.iter().any(|n| n == "ellipse"));
        }
    }
}

/// A car whose drive force never takes lateral grip (no friction ellipse) diagnosed with a model
/// that has the full ellipse (its weight at the default 1, which nominal data rarely correct):
/// the patch is fitted with the weight, which comes out near the car's 0. Held at 1, the
/// model's rear axle saturates under throttle on the patch where the car's does not, and on
/// such cars the patch was found on 2 of 5.
#[test]
fn a_grip_patch_is_found_with_the_ellipse_weight_the_car_has() {
    let mut scenario = car_scenario(Some(Effect::GripPatch), 1.0);
    scenario.car.friction_ellipse = false;
    let d = run_episodes(
        &scenario,
        [4.0, 30.0],
        305,
        5,
        Some(vec![Effect::GripPatch]),
    );
    assert_found(&d, Effect::GripPatch, "k", 0.5, 0.15);
    let first = &d.candidates[0];
    assert!(first.nominal_params["ellipse"] < 0.3, "{}", d.table());
    let joint = d.joint.as_ref().unwrap();
    assert!(joint.nominal_params["ellipse"] < 0.3, "{}", d.table());
    // the weight is shown with the patch, in the candidate's row and in the joint fit
    let table = d.table();
    assert!(
        table.matches("nominal ellipse = 0.").count() >= 2 && table.contains("refitted with it"),
        "{table}"
    );
    assert!(diagnosis_html(&d).contains("ellipse (nominal, refitted with the effects)"));
}

#[test]
fn a_pair_of_library_effects_is_named_by_forward_selection() {
    // drag and a steering offset at once: both added, one step each, both recovered
    let mut scenario = car_scenario(Some(Effect::AeroDrag), 1.0);
    scenario.effects.steering_offset = Some(dynlab_sim::car::SteeringOffset::default());
    let d = run_scenario(&scenario, 310, 7, None);
    let table = d.table();
    let mut named = d.effects.clone();
    named.sort();
    assert_eq!(named, ["aero_drag", "steering_offset"], "{table}");
    assert_eq!(
        d.selection.len(),
        3,
        "two effects added, then none: {table}"
    );
    let joint = d.joint.as_ref().expect("a joint fit");
    assert!(joint.reduction_vs_model >= 0.5, "{table}");
    assert!(
        (joint.params["aero_drag.c"] - 0.01).abs() <= 0.002,
        "{table}"
    );
    assert!(
        (joint.params["steering_offset.delta0"] - 0.03).abs() <= 0.005,
        "{table}"
    );
    let back: Diagnosis = serde_json::from_value(d.to_json()).unwrap();
    assert_eq!(back.effects, d.effects);
    assert_eq!(back.selection.len(), d.selection.len());
}

#[test]
fn a_steering_gain_falling_with_speed_gets_no_library_name_and_a_steering_term() {
    // outside the library: the simulator's steering angle times 1/(1 + (vₓ/v₀)²), v₀ = 2 m/s
    let seed = 9;
    let mut scenario = car_scenario(None, 1.0);
    scenario.effects.steering_gain_speed = Some(dynlab_sim::car::SteeringGainSpeed {
        enabled: true,
        v0: 2.0,
    });
    let d = run_scenario(&scenario, 320 + seed, seed, None);
    let table = d.table();
    assert!(d.effects.is_empty(), "no library effect: {table}");
    let disc = d.discovery.as_ref().expect("the term search ran");
    let found: Vec<_> = disc.terms.iter().filter(|t| t.significant).collect();
    assert!(!found.is_empty(), "{table}");
    // the steering the tires see shrinks with speed: δ += c·δ·vₓ² (or |v|, vₓ) with c < 0
    let t = found[0];
    assert_eq!(t.state, "delta", "{table}");
    assert!(
        t.feature.starts_with("delta*") && t.feature.contains('v'),
        "{table}"
    );
    assert!(t.coefficient < 0.0, "{table}");
    assert!(disc.error_reduction >= 0.4, "{table}");
}

/// Outside the library: half the grip within 0.4 m of a line at 0.5 rad through (0, 0.3)
/// (launch_scripts/scenarios/car_grip_band.toml), 4 × 30 s. The library's disc fits only the
/// part of the band the data cross most; the term search's grip term on the band fitted to the
/// residual removes far more, and when the disc would count on its numbers it is set against
/// that term and not counted. (Where the data cross the band in one place only, a disc there is
/// as good, and the diagnosis names `grip_patch` over the band: seed 9 of this test, and 3 × 15 s
/// of data.)
#[test]
fn a_low_grip_band_is_not_a_disc_but_a_grip_term() {
    let mut scenario = car_scenario(None, 1.0);
    scenario.effects.grip_patch = Some(low_grip_band());
    let d = run_episodes(&scenario, [4.0, 30.0], 348, 8, None);
    let table = d.table();
    assert!(d.effects.is_empty(), "no library effect: {table}");
    let patch = d
        .candidates
        .iter()
        .find(|c| c.effect == "grip_patch")
        .unwrap();
    // the grip term: less grip where the band is, significant, more than the disc removes
    let disc = d.discovery.as_ref().expect("the term search ran");
    let t = disc
        .terms
        .iter()
        .find(|t| t.state == "grip" && t.significant)
        .unwrap_or_else(|| panic!("no significant grip term: {table}"));
    assert!(t.coefficient < 0.0, "{table}");
    assert!(t.error_reduction >= 0.4, "{table}");
    assert!(t.error_reduction > patch.error_reduction, "{table}");
    assert!(over_low_grip_band(&t.feature), "{table}");
    // a disc that would count on its numbers is set against the term: its note names it
    if patch.error_reduction >= 0.1 && patch.ci_lower > 0.0 {
        let note = patch.note.as_deref().unwrap_or_default();
        assert!(
            note.contains("μ +=") && note.contains(&t.equation),
            "{table}"
        );
    }
}

#[test]
fn diagnosis_is_deterministic_and_json_has_the_contract_keys() {
    let few = Some(vec![Effect::SteeringOffset, Effect::AeroDrag]);
    let a = run_car_with(Some(Effect::SteeringOffset), 6, few.clone());
    let b = run_car_with(Some(Effect::SteeringOffset), 6, few);
    assert_eq!(a, b);
    let j = a.to_json();
    assert!(j["verdict"].is_string());
    let c = &j["candidates"][0];
    for key in [
        "effect",
        "error_reduction",
        "significant",
        "params",
        "param_std",
    ] {
        assert!(!c[key].is_null(), "missing {key}: {c}");
    }
    let r = c["error_reduction"].as_f64().unwrap();
    assert!((0.0..=1.0).contains(&r));
    let html = dynlab_diagnose::diagnosis::diagnosis_html(&a);
    assert!(html.starts_with("<section") && html.contains("steering_offset"));
}
