#!/usr/bin/env bash
# The main job on the bundled bags (bags/): the whole loop of finding the missing physics, for
# each bag with hidden effects, in a few minutes on 2 cores:
#   1. baseline: the physics model fitted on the nominal bag (`train`'s default: 50 open-loop steps);
#   2. its error on held-out data with the hidden effects, and where it fails (`dynlab compare`);
#   3. diagnosis (`dynlab diagnose`) on the bag: forward selection over the effect library (every
#      significant effect, one step at a time, with fitted parameters ± std), then, where the
#      residual keeps structure, a search over physics-informed terms beyond the library that
#      writes a custom effect file;
#   4. add what was found (`dynlab train --effects a,b [--effects-file F]`) and refit on that bag;
#   5. the error after, on the same held-out data (`dynlab compare --baseline`: before and after
#      on the same axes); a before/after table and the report paths.
# Car bags: car_drag_steering (drag and a steering offset, both in the library) and
# car_steering_gain (the steering gain falls with speed: not in the library).
# Usage: launch_scripts/main.sh [OUT_DIR]   (default out/main; rewritten on each run)
set -euo pipefail
cd "$(dirname "$0")/.."
out="${1:-out/main}"
cargo build --release -q -p dynlab
dynlab="${CARGO_TARGET_DIR:-$PWD/target}/release/dynlab"
scen=launch_scripts/scenarios
rm -rf "$out"
mkdir -p "$out/test" "$out/models" "$out/eval" "$out/diagnosis" "$out/compare"

step() { printf '\n== %s\n' "$*"; }
effects_of() { python3 -c 'import json,sys; print(",".join(json.load(open(sys.argv[1])).get("effects") or []))' "$1"; }
# the joint fit's effect parameters as `--set name=value` (the training starts there, as in the
# train command the diagnosis prints)
starts_of() { python3 -c 'import json,sys; j=json.load(open(sys.argv[1])).get("joint") or {}; print(" ".join(f"--set {k}={v!r}" for k,v in (j.get("params") or {}).items()))' "$1"; }
custom_name_of() { python3 -c 'import sys,tomllib; print(tomllib.load(open(sys.argv[1],"rb")).get("name","custom"))' "$1"; }

step "Held-out test data (same scenarios, other seeds)"
for name in car_drag_steering car_steering_gain; do
  "$dynlab" collect car --scenario "$scen/$name.toml" --episodes 1 --seed 9002 --out "$out/test/$name" \
    | tail -n 1
done

step "Baseline: the physics model fitted on the nominal bag"
"$dynlab" train --bag bags/car_nominal --kind physics --physics-windows 400 \
  --out "$out/models/car_physics" | tail -n 1

# car_drag_steering: two library effects at once (drag and a steering offset);
# car_steering_gain: an effect outside the library (the steering gain falls with speed)
for effect_bag in car_drag_steering car_steering_gain; do
  step "$effect_bag: baseline error on held-out data"
  "$dynlab" eval-model --model "$out/models/car_physics" --bag "$out/test/$effect_bag" --steps 50 --json \
    > "$out/eval/before@$effect_bag.json"

  step "$effect_bag: where the baseline fails (compare)"
  "$dynlab" compare --steps 50 --model "$out/models/car_physics" --bag "$out/test/$effect_bag" \
    --out "$out/compare/baseline@$effect_bag" | sed -n 1,12p

  step "$effect_bag: diagnosis (forward selection over the library, then terms beyond it)"
  diag="$out/diagnosis/$effect_bag"
  "$dynlab" diagnose --model "$out/models/car_physics" --bag "bags/$effect_bag" --out "$diag"
  effects="$(effects_of "$diag/diagnosis.json")"
  add=()
  [[ -n "$effects" ]] && add+=(--effects "$effects")
  read -r -a sets <<< "$(starts_of "$diag/diagnosis.json")"
  add+=("${sets[@]}")
  [[ -f "$diag/custom_effect.toml" ]] && add+=(--effects-file "$diag/custom_effect.toml")
  if [[ ${#add[@]} -eq 0 ]]; then
    echo "nothing found for $effect_bag; nothing to add"
    cp "$out/eval/before@$effect_bag.json" "$out/eval/after@$effect_bag.json"
    continue
  fi
  label="${effects:-}"
  [[ -f "$diag/custom_effect.toml" ]] && label="${label:+$label+}custom:$(custom_name_of "$diag/custom_effect.toml")"

  step "$effect_bag: add $label and refit"
  "$dynlab" train --bag "bags/$effect_bag" --kind physics --physics-windows 400 \
    "${add[@]}" --out "$out/models/car_physics+$effect_bag" | tail -n 1
  "$dynlab" eval-model --model "$out/models/car_physics+$effect_bag" --bag "$out/test/$effect_bag" --steps 50 \
    --json > "$out/eval/after@$effect_bag.json"
  echo "$label" > "$out/eval/verdict@$effect_bag.txt"

  step "$effect_bag: where the error fell (compare, before and after on the same axes)"
  "$dynlab" compare --steps 50 --model "$out/models/car_physics+$effect_bag" --baseline "$out/models/car_physics" \
    --bag "$out/test/$effect_bag" --out "$out/compare/$effect_bag" | sed -n 1,12p
done

# Pushing: the same loop on the bundled pushing bag with a hidden centre-of-mass offset (one
# transition per push: the loader collapses the 10 Hz block pose to the push starts; k = 3 pushes).
step "Held-out pushing test data (push_com_offset scenario, other seed)"
"$dynlab" collect push --scenario "$scen/push_com_offset.toml" --episodes 10 --seed 9002 \
  --out "$out/test/push_com_offset" | tail -n 1

step "Baseline: the pushing physics model fitted on the nominal bag"
"$dynlab" train --bag bags/push_nominal --kind physics --steps 3 --out "$out/models/push_physics" | tail -n 1

effect_bag=push_com_offset
step "$effect_bag: baseline error on held-out data"
"$dynlab" eval-model --model "$out/models/push_physics" --bag "$out/test/$effect_bag" --steps 3 --json \
  > "$out/eval/before@$effect_bag.json"
step "$effect_bag: diagnosis"
"$dynlab" diagnose --model "$out/models/push_physics" --bag "bags/$effect_bag" --out "$out/diagnosis/$effect_bag"
verdict="$(effects_of "$out/diagnosis/$effect_bag/diagnosis.json")"
if [[ -z "$verdict" ]]; then
  echo "no effect found for $effect_bag; nothing to add"
  cp "$out/eval/before@$effect_bag.json" "$out/eval/after@$effect_bag.json"
else
  step "$effect_bag: add $verdict and refit"
  read -r -a sets <<< "$(starts_of "$out/diagnosis/$effect_bag/diagnosis.json")"
  "$dynlab" train --bag "bags/$effect_bag" --kind physics --steps 3 --effects "$verdict" "${sets[@]}" \
    --out "$out/models/push_physics+$verdict" | grep -E "\($verdict|physics model, best"
  "$dynlab" eval-model --model "$out/models/push_physics+$verdict" --bag "$out/test/$effect_bag" --steps 3 \
    --json > "$out/eval/after@$effect_bag.json"
  echo "$verdict" > "$out/eval/verdict@$effect_bag.txt"
  step "$effect_bag: where the error fell (compare, side by side with the baseline)"
  "$dynlab" compare --steps 3 --model "$out/models/push_physics+$verdict" --baseline "$out/models/push_physics" \
    --bag "$out/test/$effect_bag" --out "$out/compare/$effect_bag"
fi

step "Before / after: held-out error of the physics model (car: 50 steps, pushing: 3 pushes; held-out test data with the hidden effects)"
python3 - "$out/eval" <<'PY'
import json, pathlib, sys
d = pathlib.Path(sys.argv[1])
print(f"{'data':<22} {'effects added':<40} {'loss before':>12} {'loss after':>12} {'change':>8} {'TVE before':>11} {'TVE after':>10}")
for before in sorted(d.glob("before@*.json")):
    name = before.stem.split("@")[1]
    b = json.loads(before.read_text())
    a = json.loads((d / f"after@{name}.json").read_text())
    v = (d / f"verdict@{name}.txt")
    v = v.read_text().strip() if v.exists() else "—"
    tb = (b.get("tve") or {}).get("tve", float("nan"))
    ta = (a.get("tve") or {}).get("tve", float("nan"))
    f = lambda x: f"{x:.3f}" if x == x else "—"
    print(f"{name:<22} {v:<40} {b['loss']:>12.4e} {a['loss']:>12.4e} {100*(a['loss']/b['loss']-1):>7.0f}% {f(tb):>11} {f(ta):>10}")
PY
printf '\nReports: %s/compare/*/index.html (where it fails, before/after), %s/diagnosis/*/diagnosis.html\nModels and errors: %s\n' "$out" "$out" "$out"
