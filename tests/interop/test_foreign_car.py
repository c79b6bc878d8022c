"""The diagnosis loop on car data dynlab's simulator did not make: `launch_scripts/foreign_car.py`
(a numpy dynamic bicycle without a friction ellipse, RK4 at 1 kHz, a 120 Hz motion capture with
jitter, noise and dropouts, written by `rosbags` under other topic names) makes a nominal bag and a
bag of the same car, its parameters 10 % off the datasheet, with aero drag and a steering offset.
`dynlab train` on the first, `dynlab diagnose --apply` on the second: only hidden effects named,
with their strengths, nothing beyond the library, and the applied model predicts the bag better.
Bags with an effect outside the library (a yaw damper, a steering gain falling with speed, a sloping
floor, a drive force capped by traction) get no library name and the term that models it.
(The evaluation's own cars, `eval_foreign.py`'s seeds 0 and 5: `test_foreign_car_eval.py`.)
"""
import json
import subprocess
import sys

import pytest

from conftest import REPO, run

TOPICS = ["--pose-topic", "/mocap/orca/pose", "--cmd-topic", "/orca/cmd"]


def generate(out, seed, effects="", episodes=3, duration=12, car_seed=1):
    subprocess.run([sys.executable, str(REPO / "launch_scripts" / "foreign_car.py"), str(out),
                    "--car-seed", str(car_seed), "--seed", str(seed), "--effects", effects,
                    "--episodes", str(episodes), "--duration", str(duration)],
                   check=True, capture_output=True, timeout=120)
    return out


def diagnose(model, bag, out, *args):
    """`dynlab diagnose` of `bag` with `model` into `out` (more options in `args`): its output and
    `diagnosis.json`."""
    proc = run("dynlab", "diagnose", "--model", model, "--bag", bag, "--out", out, *args, *TOPICS, timeout=900)
    return proc, json.loads((out / "diagnosis.json").read_text())


def assert_no_drift(j):
    """The car stayed the same while it was recorded: the drift check finds nothing."""
    assert j["drift"] is not None and not j["drift"]["significant"], j["drift"]


def eval_car(d, car, case_index, effects, *train_args):
    """`eval_foreign.py`'s car `car` on its case `case_index` with the generator's `effects`:
    the nominal drive, `dynlab train` on it (more options in `train_args`), and the case's bag,
    all under `d`; returns the model and the bag. The evaluation's seeds: 1000·car + 1 for the
    nominal drive, 1000·car + 2 + the case's index for the case."""
    gen = [sys.executable, str(REPO / "launch_scripts" / "foreign_car.py"), "--car-seed", str(car)]
    nominal, bag, model = d / "nominal", d / "case", d / "model"
    subprocess.run([*gen, str(nominal), "--seed", str(1000 * car + 1)], check=True,
                   capture_output=True, timeout=300)
    subprocess.run([*gen, str(bag), "--seed", str(1000 * car + 2 + case_index), "--effects", effects],
                   check=True, capture_output=True, timeout=300)
    run("dynlab", "train", "--world", "car", "--kind", "physics", "--bag", nominal, "--out", model,
        *train_args, *TOPICS, timeout=600)
    return model, bag


def first_term_found(d, car, case_index, effects):
    """`eval_car`'s car and case diagnosed (seeded by the car) with the drag alone among the
    candidates, for time (with the whole library none is named on these cases): no library
    effect named, and the output, `diagnosis.json` and the first significant term found."""
    model, bag = eval_car(d, car, case_index, effects)
    proc, j = diagnose(model, bag, d / "diagnosis", "--seed", str(car), "--effects", "aero_drag")
    assert j["effects"] == [], proc.stdout
    terms = [t for t in j["discovery"]["terms"] if t["significant"]]
    assert terms, j["discovery"]["summary"]
    return proc, j, terms[0]


@pytest.fixture(scope="module")
def foreign(tmp_path_factory):
    d = tmp_path_factory.mktemp("foreign")
    nominal = generate(d / "nominal", 11)
    effects = generate(d / "drag_offset", 12, "aero_drag,steering_offset")
    model = d / "model"
    run("dynlab", "train", "--world", "car", "--kind", "physics", "--bag", nominal, "--out", model,
        *TOPICS, timeout=300)
    return d, model, effects


def test_the_generator_rejects_an_unknown_effect(tmp_path):
    p = subprocess.run([sys.executable, str(REPO / "launch_scripts" / "foreign_car.py"), str(tmp_path / "b"),
                        "--effects", "aero_drag,wind"], capture_output=True, text=True, timeout=60)
    assert p.returncode != 0 and "wind" in p.stderr, p.stderr


def test_the_generators_delay_servo_yaw_damping_slope_and_limits_act_as_documented():
    sys.path.insert(0, str(REPO / "launch_scripts"))
    import numpy as np
    import foreign_car as fc

    p = dict(fc.car_params(1, 0.1), friction_ellipse=False)
    s = np.array([0.1, 0.2, 0.3, 1.2, 0.1, 2.5, 0.2, 0.05])
    plain = fc.deriv(p, set(), s, 0.2, 0.3)
    damped = fc.deriv(p, {"yaw_damping"}, s, 0.2, 0.3)
    assert damped[5] - plain[5] == pytest.approx(-4.0 * 2.5)
    assert np.array_equal(np.delete(damped, 5), np.delete(plain, 5))
    # the servo: the wheels at the servo's angle, turning at most 2.5 rad/s towards the command
    servo = fc.deriv(p, {"servo_rate"}, s, 0.2, 0.3)
    assert servo[7] == pytest.approx(2.5)
    assert fc.deriv(p, {"servo_rate"}, s, 0.052, 0.3)[7] == pytest.approx(0.002 / 0.025)
    assert np.allclose(servo[:7], fc.deriv(p, set(), s, 0.05, 0.3)[:7])
    # the delayed car's first 60 ms see no command: it coasts as a car sent zeros
    delayed, _ = fc.episode(p, {"cmd_delay"}, np.random.default_rng(3), 0.2)
    coast = delayed[0][1]
    for _ in range(60):
        coast = fc.rk4(p, set(), coast, 0.0, 0.0, 0.001)
    assert np.allclose(delayed[60][1], coast)
    undelayed, _ = fc.episode(p, set(), np.random.default_rng(3), 0.2)
    assert not np.allclose(undelayed[60][1], coast)
    # the sloping floor: gravity's pull along the slope, turned into the body frame
    tilted = fc.deriv(p, {"floor_tilt"}, s, 0.2, 0.3)
    a, psi = fc.TILT_ACC, s[2] - fc.TILT_DIR
    assert a == pytest.approx(9.81 * np.sin(np.radians(1.5)))
    assert tilted[3] - plain[3] == pytest.approx(a * np.cos(psi))
    assert tilted[4] - plain[4] == pytest.approx(-a * np.sin(psi))
    assert np.array_equal(np.delete(tilted, [3, 4]), np.delete(plain, [3, 4]))
    # the steering's end stop: a command past it turns the wheels no further
    assert np.array_equal(fc.deriv(p, {"steer_stop"}, s, 0.35, 0.3), fc.deriv(p, set(), s, fc.STOP, 0.3))
    assert np.array_equal(fc.deriv(p, {"steer_stop"}, s, -0.2, 0.3), fc.deriv(p, set(), s, -0.2, 0.3))
    # the traction limit: the drive force no larger than the cap, the same below it
    capped = fc.deriv(p, {"traction_limit"}, s, 0.2, 0.9)
    uncapped = fc.deriv(p, set(), s, 0.2, 0.9)
    drive = (p["Cm1"] - p["Cm2"] * s[3]) * 0.9
    assert drive > fc.TRACTION
    assert capped[3] - uncapped[3] == pytest.approx((fc.TRACTION - drive) / p["m"])
    assert np.array_equal(fc.deriv(p, {"traction_limit"}, s, 0.2, 0.1), fc.deriv(p, set(), s, 0.2, 0.1))
    # the battery's sag: the drive force scaled by the charge left
    sagged = fc.deriv(dict(p, charge=0.7), set(), s, 0.2, 0.3)
    assert sagged[3] - plain[3] == pytest.approx(-0.3 * (p["Cm1"] - p["Cm2"] * s[3]) * 0.3 / p["m"])


def test_diagnose_names_both_hidden_effects_and_applies_them(foreign):
    d, model, bag = foreign
    out = d / "diagnosis"
    proc, j = diagnose(model, bag, out, "--effects", "aero_drag,steering_offset,grip_patch", "--apply")
    # what is named is hidden (on this short drive of a car whose geometry is off the datasheet
    # the nominal fit's C_m2 takes much of the drag: the evaluation, launch_scripts/eval_foreign.sh,
    # reports over seeds how often both are named)
    named = set(j["effects"])
    assert named and named <= {"aero_drag", "steering_offset"}, proc.stdout
    params = j["joint"]["params"]
    if "aero_drag" in named:
        assert abs(params["aero_drag.c"] - 0.01) < 0.004, params
    if "steering_offset" in named:
        assert abs(params["steering_offset.delta0"] - 0.03) < 0.02, params
    assert j["joint"]["reduction_vs_model"] > 0.1, j["joint"]
    # every strength with a standard error that says something: from the fit windows calm at
    # the fitted parameters (with the windows the fit carried into a spin, this drive's joint
    # fit gave c ± 480 % and δ₀ ± 150 %, the offset's step ± 420 %)
    for name, v in params.items():
        s = j["joint"]["param_std"][name]
        assert 1e-3 < s / abs(v) < 0.5, (name, v, s)
    assert_no_drift(j)
    assert not any(t["significant"] for t in j["discovery"]["terms"]), j["discovery"]["summary"]
    # the train command it ran names the world (the topics do not tell it)
    assert "applying: dynlab train" in proc.stdout and "--world car" in proc.stdout, proc.stdout
    applied = out / "model"
    before = json.loads(run("dynlab", "eval-model", "--model", model, "--bag", bag, *TOPICS, "--json",
                            timeout=300).stdout)
    after = json.loads(run("dynlab", "eval-model", "--model", applied, "--bag", bag, *TOPICS, "--json",
                           timeout=300).stdout)
    # the trajectory validation error (open-loop position error over 3 s segments) falls
    assert after["tve"]["tve"] < 0.5 * before["tve"]["tve"], (before["tve"], after["tve"])


def test_the_nominal_fit_s_standard_errors_leave_out_windows_that_spin_at_the_fitted_parameters(foreign):
    """On this car's drive a fit window calm at the datasheet rolls out through a spin at the
    parameters the 50-step fit reaches; its Jacobian dwarfed the rest and shrank the standard
    errors to 10⁻¹¹ of the values. They come from the windows calm at the result: every fitted
    parameter has a standard error that says something."""
    _, model, _ = foreign
    m = json.loads((model / "model.json").read_text())
    fitted = {p["name"]: p for p in m["physics"]["params"] if p["std"] > 0}
    assert {"Bf", "Df", "Br", "Dr", "Cm1"} <= set(fitted), fitted
    for name, p in fitted.items():
        assert 1e-4 < p["std"] / abs(p["value"]) < 0.5, (name, p)


def test_a_yaw_damper_is_a_yaw_term_and_the_drag_it_passed_as_is_dropped(tmp_path):
    """Car seed 2 of `eval_foreign.py`'s `yaw_damping*` case, outside the library: a yaw moment
    −4·ω·I_z. The nominal model is fitted on 20 steps discounted by 0.9 (`train`'s car physics
    default before undiscounted 50-step rollouts): its misfit lets `aero_drag` pass the
    selection's first step on this drive (a small drag takes up part of the damping; on the
    default fit no drag passes on cars 0–4). The term search then finds a yaw term, and the
    backward check scores the drag again against it: the drag no longer counts and is dropped.
    No library name is left, and a yaw term that damps ω is."""
    model, bag = eval_car(tmp_path, 2, 10, "yaw_damping", "--steps", 20, "--gamma", 0.9)
    out = tmp_path / "diagnosis"
    # (the drag alone among the candidates, for time: with the whole library it is the same)
    proc, j = diagnose(model, bag, out, "--seed", "2", "--effects", "aero_drag")
    assert j["effects"] == [] and j["joint"] is None, proc.stdout
    assert_no_drift(j)
    first = j["selection"][0]
    assert first["added"] == "aero_drag", proc.stdout
    dropped = j.get("dropped") or []
    assert [c["effect"] for c in dropped] == ["aero_drag"], proc.stdout
    assert dropped[0]["note"].startswith("against the term found after the selection (ω̇ += "), dropped[0]
    assert not dropped[0]["significant"], dropped[0]
    assert "backward check" in proc.stdout and "dropped by the backward check: aero_drag" in proc.stdout
    terms = [t for t in j["discovery"]["terms"] if t["significant"]]
    assert terms and all(t["state"] == "omega" and t["coefficient"] < 0 for t in terms), j["discovery"]["summary"]
    assert j["discovery"]["error_reduction"] >= 0.4, j["discovery"]["summary"]


def test_a_yaw_damper_is_a_yaw_term_the_data_do_not_tell_from_a_steering_term(tmp_path):
    """Car seed 5 of `eval_foreign.py`'s `yaw_damping*` case: a yaw moment −4·ω·I_z. On this
    drive `ω̇` on `δ`, on `tanh(α_f/α₀)`, on `δ·vₓ` and on `ω` fit the fit half within 3 % of
    each other. With 15-pose velocity fits `δ` was best by a hair and `ω`, fitted beside it, was
    kept as the simplest; with the fits the poses' noise asks for (33 poses), `δ` fits both halves
    2.5 % better than `ω`, which ranks fifth and is not among the round's three rivals. What the
    data say either way: a yaw term that opposes the turn, removing at least 40 % of the
    held-out error, listed with the rivals the fit half does not tell from it (the damper itself
    with the coefficient of the truth's order where it is the one kept)."""
    proc, j, damper = first_term_found(tmp_path, 5, 10, "yaw_damping")
    assert damper["state"] == "omega", damper["equation"]
    assert damper["feature"] in ("omega", "delta", "sat_alpha_f"), damper["equation"]
    assert damper["coefficient"] < 0, damper["equation"]
    if damper["feature"] == "omega":
        assert -6.0 < damper["coefficient"] < -3.0, damper["equation"]
    others = {(a["state"], a["feature"]): a for a in damper["alternatives"]}
    assert others and all(s == "omega" and a["coefficient"] < 0 for (s, _), a in others.items()), damper
    assert all(abs(a["fit_error_change"]) < 0.05 for a in others.values()), damper["alternatives"]
    assert "the fit half does not tell it from ω̇ += " in proc.stdout, proc.stdout
    assert j["discovery"]["error_reduction"] >= 0.4, j["discovery"]["summary"]


def test_a_steering_gain_that_acts_at_speed_is_fitted_on_the_windows_it_acts_on(tmp_path):
    """Car seed 7 of `eval_foreign.py`'s `steering_gain_speed*` case, outside the library: the
    wheels turn `δ/(1 + vₓ²/4)`. The term search's best term, a gain falling with speed, acts
    on the fast windows alone, a small share of the fit half; against 100 times the median
    window's sensitivity those were taken for spins and dropped fit after fit, and what was
    left could not fix the coefficient (σ 65 % of it, not significant although it removed 44 %
    of the held-out error). Fitted on the fit half without its spins, at the effect fits'
    limit, the term is significant, with a tight σ, and removes more than 40 %."""
    _, j, gain = first_term_found(tmp_path, 7, 7, "steering_gain_speed")
    assert gain["state"] == "delta" and gain["feature"].startswith("delta*"), gain["equation"]
    assert gain["coefficient"] < 0 and gain["std"] < 0.1 * abs(gain["coefficient"]), gain["equation"]
    assert j["discovery"]["error_reduction"] >= 0.4, j["discovery"]["summary"]


def test_a_sloping_floor_is_a_heading_term(foreign):
    """Outside the library: the floor slopes 1.5° down towards the heading 2 rad, a pull fixed in
    the world frame (`v̇ₓ += a·cos(ψ − 2)`, `v̇_y −= a·sin(ψ − 2)`, a = 0.257 m/s²). No library
    effect takes it; the term search finds the pull with the slope's strength: in the world frame
    (`ẍ`, `ÿ` on the constant) or one body-frame component (`v̇ₓ`, `v̇_y` on the heading).
    (`eval_foreign.py`'s `floor_tilt*` on 4 × 15 s drives finds `ÿ += θ` on 5 of 5 cars; on
    drives as short as this one's, 3 × 12 s, a term on 2 of 4: this is one of them.)"""
    sys.path.insert(0, str(REPO / "launch_scripts"))
    import math
    import foreign_car as fc

    d, model, _ = foreign
    bag = generate(d / "tilt", 14, "floor_tilt")
    out = d / "tilt_diagnosis"
    # (the drag alone among the candidates, for time)
    proc, j = diagnose(model, bag, out, "--effects", "aero_drag")
    assert j["effects"] == [], proc.stdout
    assert_no_drift(j)
    terms = [t for t in j["discovery"]["terms"] if t["significant"]]
    assert terms, j["discovery"]["summary"]
    # the slope's pull on each velocity per unit of each heading feature
    a, phi = fc.TILT_ACC, fc.TILT_DIR
    truth = {("vx", "cos_psi"): a * math.cos(phi), ("vx", "sin_psi"): a * math.sin(phi),
             ("vy", "cos_psi"): a * math.sin(phi), ("vy", "sin_psi"): -a * math.cos(phi),
             ("ax", "1"): a * math.cos(phi), ("ay", "1"): a * math.sin(phi)}
    first = terms[0]
    key = (first["state"], first["feature"])
    assert key in truth, j["discovery"]["summary"]
    assert abs(first["coefficient"] - truth[key]) < 0.3 * a, (first["coefficient"], truth[key])
    assert j["discovery"]["error_reduction"] >= 0.15, j["discovery"]["summary"]
    assert any(s in proc.stdout for s in ("sin ψ", "cos ψ", "ẍ +=", "ÿ +=")), proc.stdout
    # a pull in the world frame is a constant: its plot is the residual against the heading
    assert first["plot"]["constant"] == (first["feature"] == "1"), first["plot"]["x_label"]


def test_a_drive_force_capped_by_traction_is_a_throttle_limit_term_not_a_drag(foreign):
    """Outside the library: the rear tyres pass at most 0.06 N of drive force before they spin.
    A drag (at several times a real one's coefficient) and a slow motor each follow part of it;
    the term search's throttle beyond a level on `v̇ₓ`, `d_{>l}`, follows all of it, so neither
    library effect is named and the term is, with the level where the cap starts and the
    acceleration the car loses per unit of throttle beyond it. (`eval_foreign.py`'s
    `traction_limit*`: before the term existed, `aero_drag` was named on 3 of 3 cars.)"""
    sys.path.insert(0, str(REPO / "launch_scripts"))
    import foreign_car as fc

    d, model, _ = foreign
    bag = generate(d / "traction", 15, "traction_limit")
    out = d / "traction_diagnosis"
    # (the two effects that take part of it among the candidates, for time)
    proc, j = diagnose(model, bag, out, "--effects", "aero_drag,motor_lag", "--apply")
    assert j["effects"] == [], proc.stdout
    assert_no_drift(j)
    terms = [t for t in j["discovery"]["terms"] if t["significant"]]
    assert terms, j["discovery"]["summary"]
    first = terms[0]
    assert first["state"] == "vx" and first["feature"].startswith("d_beyond("), j["discovery"]["summary"]
    # the cap starts at the throttle whose drive force at rest is the limit, and the car then
    # loses (C_m1 − C_m2·vₓ)/m of acceleration per unit of throttle (vₓ up to about 1.5 m/s)
    p = fc.car_params(1, 0.1)
    level = float(first["feature"][len("d_beyond("):-1])
    assert 0.6 < level / (fc.TRACTION / p["Cm1"]) < 1.6, (level, fc.TRACTION / p["Cm1"])
    slope = -first["coefficient"] * p["m"]
    assert p["Cm1"] - 1.5 * p["Cm2"] - 0.1 < slope < p["Cm1"] + 0.1, (slope, p["Cm1"])
    assert j["discovery"]["error_reduction"] >= 0.4, j["discovery"]["summary"]
    assert "d_{>" in proc.stdout, proc.stdout
    # the model trained with the term predicts another drive of the car far better
    other = generate(d / "traction_other", 16, "traction_limit")
    before, after = (json.loads(run("dynlab", "eval-model", "--model", m, "--bag", other, *TOPICS, "--json",
                                    timeout=300).stdout)["tve"]["tve"] for m in (model, out / "model"))
    assert after < 0.5 * before, (before, after)


def test_a_battery_running_down_is_a_drift_of_the_drive_force_not_an_effect(foreign):
    """The drive force falls with the battery's charge, by 30 % from the first drive of the bag to
    the last (`battery_sag`, 4 × 15 s). No effect of the library and no term follows the
    recording's time; the drift check fits the drive force (`C_m1`, `C_m2` scaled together) on
    each sixth of the recording alone and finds it falling drive by drive. (`eval_foreign.py`'s
    `battery_sag*`: before the check nothing was reported, though the error was 2–5 × the
    nominal drive's.) A rolling resistance rising over the recording slows the car nearly
    alike on these drives (the throttle stays within 0.1–0.45); where its line removes as much
    the check names either and says the data hardly tell the two apart, and the drive force's
    own line is what is checked."""
    d, model, _ = foreign
    bag = generate(d / "battery", 17, "battery_sag", episodes=4, duration=15)
    out = d / "battery_diagnosis"
    # (the drag, which a weaker drive resembles, alone among the candidates, for time)
    proc, j = diagnose(model, bag, out, "--effects", "aero_drag")
    assert j["effects"] == [], proc.stdout
    dr = j["drift"]
    assert dr["significant"], proc.stdout
    tried = dr["tried"]
    # the drive force removes the most, or within a point of the named rival, which then says so
    assert tried["the drive force"] >= max(tried.values()) - 0.01, tried
    assert tried["the drive force"] >= 0.15 and tried["the tyres' grip"] < 0.05, tried
    # the charge is 1, 0.9, 0.8, 0.7 at the drives' centres, which lie 3/4 of the recording
    # apart: a line that falls by 40 % from the recording's start to its end
    if dr["quantity"] == "the drive force":
        assert dr["params"] == ["Cm1", "Cm2"], dr
        change = dr["change"]
        scales = [b[1] for b in dr["blocks"]]
        assert scales[0] > 0.9 and scales[-1] < 0.8, scales
        assert "drift: the drive force (Cm1, Cm2)" in proc.stdout, proc.stdout
    else:
        assert dr["quantity"] == "the rolling resistance" and dr["change"] > 0, dr
        change = dr["alike"]["the drive force"]
        assert "the drive force changing by" in proc.stdout and "hardly tell the two apart" in proc.stdout
    assert -0.65 < change < -0.25, proc.stdout
    html = (out / "diagnosis.html").read_text()
    assert "Did the robot change while it was recorded?" in html and "the line through them" in html
