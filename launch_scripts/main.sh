#!/usr/bin/env bash
# The main job on the bundled bags (bags/), start to finish, in a few minutes on 2 cores:
#   1. held-out test data: `dynlab collect` from the same scenario files with other seeds;
#   2. models learned on the nominal bags: a NeuralODE (RK4, k = 3) and the fitted physics model,
#      for the pushing block and for the car;
#   3. each model evaluated (`dynlab eval-model`) on held-out nominal data and on the bags with a
#      hidden physical effect, so the table shows how much worse each model gets where the world
#      holds physics it never saw.
# Usage: launch_scripts/main.sh [OUT_DIR]   (default out/main; rewritten on each run)
set -euo pipefail
cd "$(dirname "$0")/.."
out="${1:-out/main}"
cargo build --release -q -p dynlab
dynlab="${CARGO_TARGET_DIR:-$PWD/target}/release/dynlab"
scen=launch_scripts/scenarios
rm -rf "$out"
mkdir -p "$out/test" "$out/models" "$out/eval"

step() { printf '\n== %s\n' "$*"; }

step "Bundled bags (bags/README.md describes all six)"
"$dynlab" bag info bags/push_com_offset
"$dynlab" bag info bags/car_aero_drag

step "Held-out test data (same scenarios, other seeds)"
for name in push_nominal push_friction_patch push_com_offset; do
  "$dynlab" collect push --scenario "$scen/$name.toml" --episodes 10 --seed 9001 --out "$out/test/$name" \
    | tail -n 1
done
for name in car_nominal car_aero_drag car_steering_offset; do
  "$dynlab" collect car --scenario "$scen/$name.toml" --episodes 1 --seed 9002 --out "$out/test/$name" \
    | tail -n 1
done

step "Training on the nominal bags"
"$dynlab" train --bag bags/push_nominal --kind node-rk4 --steps 3 --epochs 150 --out "$out/models/push_node_rk4"
"$dynlab" train --bag bags/push_nominal --kind physics --steps 3 --out "$out/models/push_physics"
"$dynlab" train --bag bags/car_nominal --kind node-rk4 --epochs 40 --out "$out/models/car_node_rk4"
"$dynlab" train --bag bags/car_nominal --kind physics --out "$out/models/car_physics"

step "Evaluating on held-out data"
for model in push_node_rk4 push_physics; do
  for data in push_nominal push_friction_patch push_com_offset; do
    "$dynlab" eval-model --model "$out/models/$model" --bag "$out/test/$data" --steps 5 --json \
      > "$out/eval/$model@$data.json"
  done
done
for model in car_node_rk4 car_physics; do
  for data in car_nominal car_aero_drag car_steering_offset; do
    "$dynlab" eval-model --model "$out/models/$model" --bag "$out/test/$data" --steps 5 --json \
      > "$out/eval/$model@$data.json"
  done
done

step "Error of each model: nominal test data vs data with a hidden effect (5-step loss; car also TVE)"
python3 - "$out/eval" <<'PY'
import json, pathlib, sys
rows = {}
for f in sorted(pathlib.Path(sys.argv[1]).glob("*.json")):
    model, data = f.stem.split("@")
    rows.setdefault(model, {})[data] = json.loads(f.read_text())
print(f"{'model':<15} {'test data':<22} {'5-step loss':>12} {'× nominal':>10} {'TVE':>8}")
for model, by_data in rows.items():
    nominal = next(v for k, v in by_data.items() if k.endswith("_nominal"))
    for data in sorted(by_data, key=lambda d: (not d.endswith("_nominal"), d)):
        r = by_data[data]
        tve = r.get("tve") or {}
        tve = f"{tve['tve']:.3f}" if tve else "—"
        print(f"{model:<15} {data:<22} {r['loss']:>12.3e} {r['loss'] / nominal['loss']:>10.2f} {tve:>8}")
PY
printf '\nModels, curves and per-dimension errors: %s\n' "$out"
