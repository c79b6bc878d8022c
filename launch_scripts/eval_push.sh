#!/usr/bin/env bash
# Closed-loop MPPI pushing evaluation (Tu & Lin, Table I): trains every model kind for k = 1…5 on
# our simulator's data and on Tu & Lin's data, then runs `dynlab eval push` in free space and in
# the obstacle scene for every model and writes one table.
#
#   launch_scripts/eval_push.sh [OUT] [--train-only|--eval-only]
#
# Environment: EPISODES (default 50), SEED (default 1), EPOCHS (default 300), KINDS (default
# "residual node-euler node-rk4 node-dopri5 physics hybrid"), STEPS (default "1 2 3 4 5"),
# TU_LIN (default ../shared/data/tu_lin_pushing.mcap; skipped when missing), THREADS (default 2).
# Our data: 500 episodes × 10 pushes from starts spread over x ± 5 cm, y ± 10 cm, θ ± π/2
# around (0.4, 0, 0), one pose per push (as Tu & Lin record), so that both scenes' starts
# (θ = ±0.2π) are inside the training distribution.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
out="${1:-$root/out/eval_push}"
mode="${2:-all}"
EPISODES="${EPISODES:-50}"
SEED="${SEED:-1}"
EPOCHS="${EPOCHS:-300}"
KINDS="${KINDS:-residual node-euler node-rk4 node-dopri5 physics hybrid}"
STEPS="${STEPS:-1 2 3 4 5}"
THREADS="${THREADS:-2}"
TU_LIN="${TU_LIN:-$root/../shared/data/tu_lin_pushing.mcap}"
cd "$root"
cargo build --release -q -p dynlab
bin="${CARGO_TARGET_DIR:-$root/target}/release/dynlab"
mkdir -p "$out/models"

datasets=(sim)
if [[ -e "$TU_LIN" ]]; then datasets+=(tulin); else echo "note: $TU_LIN not found; Tu & Lin's data skipped" >&2; fi

if [[ "$mode" != "--eval-only" ]]; then
  if [[ ! -e "$out/sim_bag/metadata.yaml" ]]; then
    printf 'name = "push_wide"\nstart = [0.4, 0.0, 0.0]\ngoal = [0.8, 0.0, 0.0]\n[noise]\nposition_std = 0.0005\nyaw_std = 0.002\n' > "$out/sim_scenario.toml"
    printf 'start_jitter = [0.05, 0.1, 1.5707963267948966]\npose_rate = 0.5\n' > "$out/sim_explore.toml"
    rm -rf "$out/sim_bag"
    "$bin" collect push --scenario "$out/sim_scenario.toml" --explore "$out/sim_explore.toml" \
      --episodes 500 --seed 7 --episode-gap 30 --out "$out/sim_bag"
  fi
  for ds in "${datasets[@]}"; do
    bag="$out/sim_bag"; [[ "$ds" == tulin ]] && bag="$TU_LIN"
    for kind in $KINDS; do
      for k in $STEPS; do
        m="$out/models/$ds-$kind-k$k"
        [[ -e "$m/model.json" ]] && continue
        extra=()
        [[ "$kind" == hybrid ]] && extra=(--epochs $(( EPOCHS / 3 > 0 ? EPOCHS / 3 : 1 )))
        [[ "$kind" != hybrid && "$kind" != physics ]] && extra=(--epochs "$EPOCHS")
        echo "== train $ds $kind k=$k"
        "$bin" train --bag "$bag" --kind "$kind" --steps "$k" "${extra[@]}" --threads "$THREADS" \
          --out "$m" --quiet 2>&1 | tail -1
      done
    done
  done
fi
[[ "$mode" == "--train-only" ]] && exit 0

for scene in free obstacle; do
  for ds in "${datasets[@]}"; do
    for kind in $KINDS; do
      for k in $STEPS; do
        m="$out/models/$ds-$kind-k$k"
        [[ -e "$m/model.json" ]] || continue
        csv="$out/episodes/$scene-$ds-$kind-k$k.csv"
        [[ -e "$csv" ]] && continue
        mkdir -p "$out/episodes"
        "$bin" eval push --model "$m" --scenario "$scene" --episodes "$EPISODES" --seed "$SEED" \
          --label "$ds/$kind/k$k" --csv "$csv.tmp" --quiet && mv "$csv.tmp" "$csv"
      done
    done
  done
done
"$bin" eval push-table --out "$out/table.md" --plot "$out/success.png" "$out"/episodes/*.csv
cat "$out/table.md"
