#!/usr/bin/env bash
# Reproduces the racing numbers of the closing note (results in $OUT, default race_eval/):
#
#   launch_scripts/eval_race.sh [OUT]
#
# 1. collects racing data on the default track (10 × 30 s, aggressive explorer, seed 301);
# 2. trains node-rk4 and residual car models (Kohler: 8 × 64 GELU, L_rel, k = 5) on it and the
#    bundled floor bag bags/car_nominal;
# 3. offline manoeuvres (Table I) with GD and SQP on each model;
# 4. laps with each model (SQP and GD) beside the simulator as the true model, on the default
#    track and, when present, the ORCA track ($ORCA_TRACK, default ../shared/data/orca_track.json;
#    with the curvature-aware reference speed of launch_scripts/tracks/orca_racer.toml).
#
# Uses the release `dynlab` from $DYNLAB_BIN_DIR (default target/release; build it with
# `cargo build --release -p dynlab`). Takes ≈ 30–60 min on 2 cores (training dominates).
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
for kind in node-rk4 residual; do
  if [[ ! -f "$out/car_$kind/model.json" && ! -d "$out/car_$kind" ]]; then
    "$dl" train --bag "$here/bags/car_nominal" "$out/car_track_bag" --kind "$kind" --steps 5 \
      --epochs 30 --threads 2 --quiet --out "$out/car_$kind"
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
    for opt in sqp gd; do
      echo "== laps: $name track, $kind, $opt"
      "$dl" eval race --model "$out/car_$kind" --optimizer "$opt" --laps 2 --track "$file" \
        "${settings[@]}" --out "$out/laps_${name}_${kind}_${opt}"
    done
  done
done
