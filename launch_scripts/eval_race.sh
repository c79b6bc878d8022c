#!/usr/bin/env bash
# Reproduces the racing numbers of the closing note (results in $OUT, default race_eval/):
#
#   launch_scripts/eval_race.sh [OUT]
#
# 1. collects data on the default track: 10 × 30 s aggressive explorer (seed 301) and
#    20 × 30 s on-policy racing (the racer over the simulator's bicycle model, reference speed
#    1.5–2.5 m/s, command noise; launch_scripts/scenarios/car_track_race.toml, seed 302);
# 2. trains node-rk4 and residual car models (Kohler: 8 × 64 GELU, L_rel, k = 5, 60 epochs) on
#    them and the bundled floor bag bags/car_nominal (the ORCA track stays held out);
# 3. offline manoeuvres (Table I) with GD and SQP on each model;
# 4. laps with each model beside the simulator as the true model, on the default track and,
#    when present, the ORCA track ($ORCA_TRACK, default ../shared/data/orca_track.json; with the
#    curvature-aware reference speed of launch_scripts/tracks/orca_racer.toml): SQP with the
#    pose-noise seeds $SEEDS (default 0 1 2 3), GD with seed 0.
#
# Uses the release `dynlab` from $DYNLAB_BIN_DIR (default target/release; build it with
# `cargo build --release -p dynlab`). Takes ≈ 45–60 min on 2 cores (the data collection, the
# training and the laps with the simulator inside the optimiser dominate).
set -euo pipefail
here="$(cd "$(dirname "$0")/.." && pwd)"
bin="${DYNLAB_BIN_DIR:-${CARGO_TARGET_DIR:-$here/target}/release}"
out="${1:-race_eval}"
orca="${ORCA_TRACK:-$here/../shared/data/orca_track.json}"
mkdir -p "$out"
dl="$bin/dynlab"
[[ -x "$dl" ]] || { echo "eval_race.sh: $dl not found; run cargo build --release -p dynlab" >&2; exit 2; }

if [[ ! -d "$out/car_track_bag" ]]; then
  "$dl" collect car --scenario "$here/launch_scripts/scenarios/car_track.toml" \
    --explore "$here/launch_scripts/scenarios/car_track_explore.toml" \
    --episodes 10 --seed 301 --out "$out/car_track_bag"
fi
if [[ ! -d "$out/car_race_bag" ]]; then
  "$dl" collect car --scenario "$here/launch_scripts/scenarios/car_track.toml" \
    --race "$here/launch_scripts/scenarios/car_track_race.toml" \
    --episodes 20 --seed 302 --out "$out/car_race_bag"
fi
for kind in node-rk4 residual; do
  if [[ ! -f "$out/car_$kind/model.json" && ! -d "$out/car_$kind" ]]; then
    "$dl" train --bag "$here/bags/car_nominal" "$out/car_track_bag" "$out/car_race_bag" \
      --kind "$kind" --steps 5 --epochs 60 --threads 2 --quiet --out "$out/car_$kind"
  fi
done
for kind in node-rk4 residual; do
  echo "== offline manoeuvres, $kind"
  "$dl" eval race --model "$out/car_$kind" --offline --out "$out/offline_$kind"
done
tracks=("default:$here/launch_scripts/tracks/default.json")
[[ -f "$orca" ]] && tracks+=("orca:$orca")
for t in "${tracks[@]}"; do
  name="${t%%:*}"; file="${t#*:}"
  settings=()
  [[ "$name" == orca ]] && settings=(--settings "$here/launch_scripts/tracks/orca_racer.toml")
  for kind in residual node-rk4; do
    for seed in ${SEEDS:-0 1 2 3}; do
      echo "== laps: $name track, $kind, sqp, seed $seed"
      "$dl" eval race --model "$out/car_$kind" --optimizer sqp --laps 2 --track "$file" \
        "${settings[@]}" --seed "$seed" --out "$out/laps_${name}_${kind}_sqp_s$seed"
    done
    echo "== laps: $name track, $kind, gd, seed 0"
    "$dl" eval race --model "$out/car_$kind" --optimizer gd --laps 2 --track "$file" \
      "${settings[@]}" --no-true-model --out "$out/laps_${name}_${kind}_gd"
  done
done
