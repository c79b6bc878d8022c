#!/usr/bin/env python3
"""The loop a user runs, on pushing data dynlab's simulator did not make (`foreign_push.py`: exact
quasi-static pushing over a dense support grid, other topic names): per block seed a nominal bag
and `dynlab train --kind physics` on it with the block's measured size, then per case a bag of
the same block with hidden effects, `dynlab diagnose` on it. Prints per case and seed what was
named, the held-out error removed, the fitted strengths against the truth and the terms found
beyond the library; then per case how often the named set is exactly the hidden library effects.

    eval_foreign_push.py [--seeds N] [--first-seed N] [--only CASE,CASE] [--jobs N] [--out DIR]
                         [--episodes N] [--perturb F]
"""
import argparse
import json
import math
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from eval_foreign import DYNLAB, HERE, REPO, generated, run
from foreign_push import MU_P, OFFSET, PATCH, TILT, option_error

TOPICS = ["--pose-topic", "/mocap/box/pose", "--cmd-topic", "/pusher/push"]
# case: (generator effects, the library effects that model them; None: outside the library)
CASES = {
    "nominal": ("", ()),
    "com_offset": ("com_offset", ("com_offset",)),
    "table_tilt": ("table_tilt", ("table_tilt",)),
    "friction_patch": ("friction_patch", ("friction_patch",)),
    "pusher_friction": ("pusher_friction", ("pusher_friction",)),
    "com_offset + table_tilt": ("com_offset,table_tilt", ("com_offset", "table_tilt")),
    "com_offset + pusher_friction": ("com_offset,pusher_friction", ("com_offset", "pusher_friction")),
    "table_tilt + friction_patch": ("table_tilt,friction_patch", ("table_tilt", "friction_patch")),
    "friction_patch + pusher_friction": ("friction_patch,pusher_friction", ("friction_patch", "pusher_friction")),
    "anisotropic*": ("anisotropic", None),
    "friction_band*": ("friction_band", None),
    "slippery_band*": ("slippery_band", None),
}
TRUTH = {"com_offset.ox": OFFSET[0], "com_offset.oy": OFFSET[1],
         "table_tilt.gx": TILT[0] * math.cos(TILT[1]), "table_tilt.gy": TILT[0] * math.sin(TILT[1]),
         "friction_patch.cx": PATCH[0][0], "friction_patch.cy": PATCH[0][1], "friction_patch.r": PATCH[1],
         "friction_patch.k": PATCH[2], "pusher_friction.mu": MU_P}
GENERATOR = []  # --episodes, --perturb


def bag(out, block_seed, seed, effects):
    return generated("foreign_push.py", out, "--block-seed", block_seed, "--seed", seed, "--effects", effects,
                     *GENERATOR)


def nominal_model(root, block_seed):
    m = root / f"block{block_seed}" / "model"
    if not m.exists():
        b = bag(root / f"block{block_seed}" / "nominal", block_seed, 1000 * block_seed + 1, "")
        # the block measured to the millimetre
        size = run(sys.executable, HERE / "foreign_push.py", "--block-seed", block_seed, "--print-size",
                   *GENERATOR).split()
        sets = [x for s in size for x in ("--set", s)]
        run(DYNLAB, "train", "--world", "push", "--kind", "physics", "--steps", 3, "--bag", b, "--out", m,
            *sets, *TOPICS)
    return m


def one(root, case, block_seed):
    effects, library = CASES[case]
    model = nominal_model(root, block_seed)
    tag = case.replace(" + ", "+").replace("*", "")
    d = root / f"block{block_seed}"
    b = bag(d / f"bag_{tag}", block_seed, 1000 * block_seed + 2 + list(CASES).index(case), effects)
    out = d / f"diag_{tag}"
    text = run(DYNLAB, "diagnose", "--model", model, "--bag", b, "--out", out, "--seed", block_seed, *TOPICS)
    (out / "diagnose.txt").write_text(text)
    j = json.loads((out / "diagnosis.json").read_text())
    named = tuple(j.get("effects") or ())
    joint = j.get("joint") or {}
    disc = j.get("discovery") or {}
    terms = [t["equation"].split("   [")[0] for t in disc.get("terms", []) if t["significant"]]
    return {
        "case": case, "seed": block_seed, "named": named,
        "right": (named == () if library is None else set(named) == set(library)),
        "removed": joint.get("reduction_vs_model"),
        "params": joint.get("params", {}),
        "terms": terms, "terms_removed": disc.get("error_reduction") if terms else None,
    }


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--first-seed", type=int, default=0)
    ap.add_argument("--only", default="")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--out", default=str(REPO / "out" / "eval_foreign_push"))
    ap.add_argument("--episodes", type=int, default=40, help="episodes of 10 pushes per bag (default 40)")
    ap.add_argument("--perturb", type=float, default=0.1,
                    help="the block's size and the pusher's radius within ±F of the datasheet (default 0.1)")
    a = ap.parse_args()
    if (err := option_error(a.perturb, a.episodes, 10)) is not None:
        ap.error(err)
    GENERATOR.extend(["--episodes", a.episodes, "--perturb", a.perturb])
    cases = [c for c in CASES if not a.only or c in a.only.split(",")]
    if not cases:
        ap.error(f"no case in --only; cases: {', '.join(CASES)}")
    root = Path(a.out)
    root.mkdir(parents=True, exist_ok=True)
    seeds = range(a.first_seed, a.first_seed + a.seeds)
    with ThreadPoolExecutor(a.jobs) as ex:
        list(ex.map(lambda s: nominal_model(root, s), seeds))
        results = []
        for r in ex.map(lambda cs: one(root, *cs), [(c, s) for c in cases for s in seeds]):
            print(f"{r['case']}, seed {r['seed']}: {', '.join(r['named']) or 'none'}; "
                  f"{'; '.join(r['terms']) or 'no term'}", file=sys.stderr, flush=True)
            results.append(r)
    print(f"{'case':34} {'seed':>4}  {'named':32} {'removed':>8}  fitted (truth) / terms beyond the library")
    for r in results:
        fitted = ", ".join(f"{k.split('.')[1]} {v:.4g} ({TRUTH[k]:.4g})" for k, v in r["params"].items()
                           if k in TRUTH)
        terms = "; ".join(r["terms"])
        if terms:
            terms += f" ({100 * r['terms_removed']:.0f} % removed)"
        removed = f"{100 * r['removed']:.0f} %" if r["removed"] is not None else "—"
        print(f"{r['case']:34} {r['seed']:>4}  {','.join(r['named']) or 'none':32} {removed:>8}  "
              f"{' / '.join(x for x in (fitted, terms) if x)}")
    print("\nremoved: of the held-out 3-step error")
    for c in cases:
        rs = [r for r in results if r["case"] == c]
        print(f"{c:34} right {sum(r['right'] for r in rs)}/{len(rs)}")


if __name__ == "__main__":
    main()
