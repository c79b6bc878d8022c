#!/usr/bin/env python3
"""The loop a user runs, on car data dynlab's simulator did not make (`foreign_car.py`): per car
seed a nominal bag, `dynlab train --kind physics` on it, then per case a bag of the same car with
hidden effects, `dynlab diagnose` on it. Prints per case and seed what was named, the held-out
error removed, the fitted strengths against the truth, the terms found beyond the library and a
significant drift of the car along the recording; then per case how often the named set is
exactly the hidden library effects, and how often a drift was found.

With `--floor`, each case is diagnosed a second time with the generator's own car as the model
(its parameters, the friction ellipse's weight and `v_reg` as the generator has them, only `C_r0`
refitted on the nominal bag): that model's error after its fitted effects (beyond the library:
its significant terms) is what no model of ours goes below on those held-out windows (pose noise, velocities from poses, the chaos of
open-loop rollouts), and the table gives the share of the error above it that the effects remove.

    eval_foreign.py [--seeds N] [--first-seed N] [--only CASE,CASE] [--jobs N] [--out DIR]
                    [--friction-ellipse] [--rate HZ] [--perturb F] [--floor] [--score poses] [--free P,P]
                    [--model-states S] [--fitted-starts S]

`--rate` and `--perturb` pass to the generator: its motion capture's frequency (default 120 Hz) and
how far each car's parameters are from the datasheet (default ±10 %).
"""
import argparse
import json
import os
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from foreign_car import car_params, option_error

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
DYNLAB = Path(os.environ.get("DYNLAB", REPO / "target" / "release" / "dynlab"))
TOPICS = ["--pose-topic", "/mocap/orca/pose", "--cmd-topic", "/orca/cmd"]
# case: (generator effects, the library effects that model them; None: outside the library)
CASES = {
    "nominal": ("", ()),
    "aero_drag": ("aero_drag", ("aero_drag",)),
    "steering_offset": ("steering_offset", ("steering_offset",)),
    "motor_lag": ("motor_lag", ("motor_lag",)),
    "grip_patch": ("grip_patch", ("grip_patch",)),
    "aero_drag + steering_offset": ("aero_drag,steering_offset", ("aero_drag", "steering_offset")),
    "steering_offset + grip_patch": ("steering_offset,grip_patch", ("steering_offset", "grip_patch")),
    "steering_gain_speed*": ("steering_gain_speed", None),
    "grip_band*": ("grip_band", None),
    "cmd_delay": ("cmd_delay", ("command_delay",)),
    "yaw_damping*": ("yaw_damping", None),
    # (appended: a case's index seeds its drive)
    "servo_rate": ("servo_rate", ("steering_lag",)),
    "floor_tilt*": ("floor_tilt", None),
    "steer_stop*": ("steer_stop", None),
    "traction_limit*": ("traction_limit", None),
    "battery_sag*": ("battery_sag", None),
    "aero_drag + motor_lag": ("aero_drag,motor_lag", ("aero_drag", "motor_lag")),
    "motor_lag + steering_offset": ("motor_lag,steering_offset", ("motor_lag", "steering_offset")),
    "aero_drag + grip_patch": ("aero_drag,grip_patch", ("aero_drag", "grip_patch")),
    "servo_rate + motor_lag": ("servo_rate,motor_lag", ("steering_lag", "motor_lag")),
    "cmd_delay + steering_offset": ("cmd_delay,steering_offset", ("command_delay", "steering_offset")),
}
TRUTH = {"aero_drag.c": 0.01, "steering_offset.delta0": 0.03, "motor_lag.tau": 0.2,
         "steering_lag.tau": 0.025, "steering_lag.rate": 2.5,
         "command_delay.delay": 0.06,
         "grip_patch.k": 0.45, "grip_patch.cx": 0.5, "grip_patch.cy": 0.0, "grip_patch.r": 0.6}


def run(*cmd):
    p = subprocess.run([str(c) for c in cmd], capture_output=True, text=True)
    if p.returncode != 0:
        raise RuntimeError(f"{' '.join(map(str, cmd))} failed:\n{p.stderr[-2000:]}")
    return p.stdout


PERTURB = 0.1  # --perturb: the true model's parameters (--floor) are the generator's
GENERATOR = []  # extra options of foreign_car.py (--friction-ellipse, --rate, --perturb)
SCORE = ["states"]  # --score: what the diagnoses' k-step error compares
NOMINAL_FREE = []  # --free: the nominal models' fitted parameters (empty: train's default)
DIAGNOSE = []  # extra options of dynlab diagnose (--model-states, --fitted-starts)


def generated(script, out, *args):
    """The bag `out` of generator `script` (in this folder) with `args`, made if it is not there."""
    if not out.exists():
        run(sys.executable, HERE / script, out, *args)
    return out


def bag(out, car_seed, seed, effects):
    return generated("foreign_car.py", out, "--car-seed", car_seed, "--seed", seed, "--effects", effects, *GENERATOR)


def nominal_model(root, car_seed):
    m = root / f"car{car_seed}" / "model"
    if not m.exists():
        b = bag(root / f"car{car_seed}" / "nominal", car_seed, 1000 * car_seed + 1, "")
        free = ["--free", ",".join(NOMINAL_FREE)] if NOMINAL_FREE else []
        run(DYNLAB, "train", "--world", "car", "--kind", "physics", "--bag", b, "--out", m, *free, *TOPICS)
    return m


def true_model(root, car_seed):
    m = root / f"car{car_seed}" / "true_model"
    if not m.exists():
        b = bag(root / f"car{car_seed}" / "nominal", car_seed, 1000 * car_seed + 1, "")
        sets = [a for k, v in car_params(car_seed, PERTURB).items() for a in ("--set", f"{k}={v}")]
        sets += ["--set", f"ellipse={int('--friction-ellipse' in GENERATOR)}", "--set", "v_reg=0.02"]
        run(DYNLAB, "train", "--world", "car", "--kind", "physics", "--bag", b, "--out", m, "--free", "Cr0",
            *sets, *TOPICS)
    return m


def diagnose(model, b, out, car_seed):
    text = run(DYNLAB, "diagnose", "--model", model, "--bag", b, "--out", out, "--seed", car_seed,
               "--score", SCORE[0], *DIAGNOSE, *TOPICS)
    (out / "diagnose.txt").write_text(text)
    return json.loads((out / "diagnosis.json").read_text())


def significant_terms(j):
    """The equations of the diagnosis `j`'s significant terms beyond the library."""
    disc = j.get("discovery") or {}
    return [t["equation"].split("   [")[0] for t in disc.get("terms", []) if t["significant"]]


def before_after(j):
    """The held-out error before and after what the diagnosis `j` adds: its library effects'
    joint fit, or else its significant terms beyond the library, on the term search's windows
    (those through a spin left out; after None: nothing added)."""
    if (j.get("joint") or {}).get("error_after") is not None:
        return j["baseline_error"], j["joint"]["error_after"]
    if significant_terms(j):
        return j["discovery"]["baseline_error"], j["discovery"]["error_after"]
    return j["baseline_error"], None


def one(root, case, car_seed, floor):
    effects, library = CASES[case]
    model = nominal_model(root, car_seed)
    idx = list(CASES).index(case)
    tag = case.replace(" + ", "+").replace("*", "")
    b = bag(root / f"car{car_seed}" / f"bag_{tag}", car_seed, 1000 * car_seed + 2 + idx, effects)
    j = diagnose(model, b, root / f"car{car_seed}" / f"diag_{tag}", car_seed)
    best = None
    if floor:
        t = diagnose(true_model(root, car_seed), b, root / f"car{car_seed}" / f"true_diag_{tag}", car_seed)
        best = min(x for x in before_after(t) if x is not None)
    named = tuple(j.get("effects") or ())
    joint = j.get("joint") or {}
    disc = j.get("discovery") or {}
    terms = significant_terms(j)
    drift = j.get("drift") or {}
    return {
        "case": case, "seed": car_seed, "named": named,
        "right": (named == () if library is None else set(named) == set(library)),
        "removed": joint.get("reduction_vs_model"),
        "before": before_after(j)[0], "after": before_after(j)[1],
        "params": joint.get("params", {}),
        "terms": terms, "terms_removed": disc.get("error_reduction") if terms else None,
        "floor": best,
        "noise": (j.get("noise_floor") or {}).get("share"),
        "drift": (f"{drift['quantity']} {100 * drift['change']:+.0f} % ({100 * drift['error_reduction']:.0f} % removed)"
                  if drift.get("significant") else None),
    }


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--first-seed", type=int, default=0)
    ap.add_argument("--only", default="")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--out", default=str(REPO / "out" / "eval_foreign"))
    ap.add_argument("--friction-ellipse", action="store_true",
                    help="cars whose drive force takes the rear tire's lateral grip")
    ap.add_argument("--rate", type=float, default=120.0,
                    help="the generator's motion capture frequency, Hz (default 120)")
    ap.add_argument("--perturb", type=float, default=0.1,
                    help="each car's parameters within ±F of the datasheet (default 0.1)")
    ap.add_argument("--score", choices=("states", "poses"), default="states",
                    help="what the diagnoses' k-step error compares (dynlab diagnose --score)")
    ap.add_argument("--free", default="",
                    help="the nominal models' fitted parameters (dynlab train --free; default: train's); "
                         "a model already in --out is reused, so give another --out")
    ap.add_argument("--model-states", type=float, metavar="S",
                    help="the diagnoses' car states re-estimated with the model over ±S s (dynlab diagnose --model-states)")
    ap.add_argument("--fitted-starts", type=float, metavar="S",
                    help="every model compared starts each window from its own fit to the S s of poses before it (dynlab diagnose --fitted-starts)")
    ap.add_argument("--floor", action="store_true",
                    help="also diagnose with the generator's own car: the share of the removable error")
    a = ap.parse_args()
    if (err := option_error(a.rate, a.perturb)) is not None:
        ap.error(err)
    global PERTURB
    PERTURB = a.perturb
    SCORE[0] = a.score
    NOMINAL_FREE.extend(x for x in a.free.split(",") if x)
    if a.model_states is not None:
        DIAGNOSE.extend(["--model-states", a.model_states])
    if a.fitted_starts is not None:
        DIAGNOSE.extend(["--fitted-starts", a.fitted_starts])
    GENERATOR.extend(["--rate", a.rate, "--perturb", a.perturb])
    if a.friction_ellipse:
        GENERATOR.append("--friction-ellipse")
    cases = [c for c in CASES if not a.only or c in a.only.split(",")]
    if not cases:
        ap.error(f"no case in --only; cases: {', '.join(CASES)}")
    root = Path(a.out)
    root.mkdir(parents=True, exist_ok=True)
    seeds = range(a.first_seed, a.first_seed + a.seeds)
    # the nominal models first (one per car, shared by its cases)
    with ThreadPoolExecutor(a.jobs) as ex:
        list(ex.map(lambda s: nominal_model(root, s), seeds))
        results = []
        for r in ex.map(lambda cs: one(root, *cs, a.floor), [(c, s) for c in cases for s in seeds]):
            print(f"{r['case']}, seed {r['seed']}: {', '.join(r['named']) or 'none'}; "
                  f"{'; '.join(r['terms']) or 'no term'}; drift {r['drift'] or 'none'}",
                  file=sys.stderr, flush=True)
            results.append(r)
    # the nominal model's error on another drive without hidden effects: what no effect removes
    floor = {r["seed"]: r["before"] for r in results if r["case"] == "nominal"}

    def share(r, f):
        if r["after"] is None or f is None or r["before"] <= f:
            return "—"
        return f"{100 * (r['before'] - r['after']) / (r['before'] - f):.0f} %"

    print(f"{'case':30} {'seed':>4}  {'named':32} {'removed':>8} {'excess':>7} {'of true':>7} {'noise':>6}  "
          "fitted (truth) / terms beyond the library")
    for r in results:
        fitted = ", ".join(f"{k.split('.')[1]} {v:.4g} ({TRUTH[k]:g})" for k, v in r["params"].items()
                           if k in TRUTH)
        terms = "; ".join(r["terms"])
        if terms:
            terms += f" ({100 * r['terms_removed']:.0f} % removed)"
        removed = f"{100 * r['removed']:.0f} %" if r["removed"] is not None else "—"
        print(f"{r['case']:30} {r['seed']:>4}  {','.join(r['named']) or 'none':32} {removed:>8} "
              f"{share(r, floor.get(r['seed'])):>7} {share(r, r['floor']):>7} "
              f"{'—' if r['noise'] is None else format(100 * r['noise'], '.0f') + ' %':>6}  "
              f"{' / '.join(x for x in (fitted, terms, r['drift'] and 'drift ' + r['drift']) if x)}")
    print("\nremoved: of the held-out 50-step error; excess: of what the error exceeds the nominal "
          "model's on the nominal drive of the same car (the case nominal; — without it); of true: of what it "
          "exceeds the generator's own car's error with its fitted effects on the same windows (--floor); "
          "noise: the share of the baseline's held-out error the poses' noise alone gives (the diagnosis' estimate)")
    for c in cases:
        rs = [r for r in results if r["case"] == c]
        print(f"{c:30} right {sum(r['right'] for r in rs)}/{len(rs)}, "
              f"drift significant {sum(r['drift'] is not None for r in rs)}/{len(rs)}")


if __name__ == "__main__":
    main()
