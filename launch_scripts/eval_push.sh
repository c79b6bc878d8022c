#!/usr/bin/env bash
# Closed-loop MPPI pushing evaluation (Tu & Lin, Table I): trains every model kind for k = 1…5 on
# our simulator's data and on Tu & Lin's data, then runs `dynlab eval push` in free space and in
# the obstacle scene for every model and writes one table.
#
#   launch_scripts/eval_push.sh [OUT] [--train-only|--eval-only]
#
# Environment: EPISODES (default 50), SEED (default 1), EPOCHS (default 300), KINDS (default
# "residual node-euler node-rk4 node-dopri5 physics hybrid"), STEPS (default "1 2 3 4 5"),
# TU_LIN (default ../shared/data/tu_lin_pushing.mcap; skipped when missing), THREADS (default 2),
# PLANTS (default: every "data:support" pair, e.g. "sim:grid tulin:corners"), VARIANTS and
# VARIANT_MODELS (controller variants, see below).
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

# Data sets: "sim" = our simulator's data; "tulin" = Tu & Lin's PyBullet data, trained with the
# budget of their comparison table (batch 100, 250 epochs: ≈ 2000 Adam steps on 800 windows);
# "tulin_se2" = the same data with 10 rigidly moved and turned copies of every training trajectory
# (`train --augment-se2 10`, batch 100, 23 epochs: the same ≈ 2000 Adam steps), network kinds only
# (the physics model is pose-invariant by construction).
datasets=(sim)
if [[ -e "$TU_LIN" ]]; then datasets+=(tulin tulin_se2); else echo "note: $TU_LIN not found; Tu & Lin's data skipped" >&2; fi

if [[ "$mode" != "--eval-only" ]]; then
  if [[ ! -e "$out/sim_bag/metadata.yaml" ]]; then
    printf 'name = "push_wide"\nstart = [0.4, 0.0, 0.0]\ngoal = [0.8, 0.0, 0.0]\n[noise]\nposition_std = 0.0005\nyaw_std = 0.002\n' > "$out/sim_scenario.toml"
    printf 'start_jitter = [0.05, 0.1, 1.5707963267948966]\npose_rate = 0.5\n' > "$out/sim_explore.toml"
    rm -rf "$out/sim_bag"
    "$bin" collect push --scenario "$out/sim_scenario.toml" --explore "$out/sim_explore.toml" \
      --episodes 500 --seed 7 --episode-gap 30 --out "$out/sim_bag"
  fi
  for ds in "${datasets[@]}"; do
    bag="$out/sim_bag"; [[ "$ds" == tulin* ]] && bag="$TU_LIN"
    for kind in $KINDS; do
      [[ "$ds" == tulin_se2 && "$kind" == physics ]] && continue
      for k in $STEPS; do
        m="$out/models/$ds-$kind-k$k"
        [[ -e "$m/model.json" ]] && continue
        extra=()
        case "$ds:$kind" in
          *:physics) ;;
          tulin:*) extra=(--batch 100 --epochs 250) ;;
          tulin_se2:*) extra=(--augment-se2 10 --batch 100 --epochs 23) ;;
          sim:hybrid) extra=(--epochs $(( EPOCHS / 3 > 0 ? EPOCHS / 3 : 1 ))) ;;
          *) extra=(--epochs "$EPOCHS") ;;
        esac
        echo "== train $ds $kind k=$k"
        "$bin" train --bag "$bag" --kind "$kind" --steps "$k" "${extra[@]}" --threads "$THREADS" \
          --out "$m" --quiet 2>&1 | tail -1
      done
    done
  done
fi
[[ "$mode" == "--train-only" ]] && exit 0

mkdir -p "$out/episodes" "$out/plots"
summary="$out/summary.csv"
# Plants: our simulator's default block (support grid) for every model; Tu & Lin's models also
# on the block resting on its four corners (PyBullet's box-on-plane contact, which their data
# come from: the matched plant), row label "<data>@corners".
plants=(sim:grid)
for support in corners grid; do
  for ds in "${datasets[@]}"; do [[ "$ds" == tulin* ]] && plants+=("$ds:$support"); done
done
[[ -n "${PLANTS:-}" ]] && read -r -a plants <<< "$PLANTS"
for plant in "${plants[@]}"; do
  ds="${plant%%:*}"; support="${plant#*:}"
  row="$ds"; [[ "$support" == corners ]] && row="$ds@corners"
  for kind in $KINDS; do
    for k in $STEPS; do
      m="$out/models/$ds-$kind-k$k"
      [[ -e "$m/model.json" ]] || continue
      for scene in free obstacle; do
        arg="$scene"
        [[ "$support" == corners ]] && arg="$root/launch_scripts/scenarios/push_${scene}_corners.toml"
        csv="$out/episodes/$scene-$row-$kind-k$k.csv"
        [[ -e "$csv" ]] && continue
        "$bin" eval push --model "$m" --scenario "$arg" --episodes "$EPISODES" --seed "$SEED" \
          --label "$row-$kind-k$k" --csv "$csv.tmp" --summary "$summary" \
          --plot "$out/plots/$scene-$row-$kind-k$k.png" --quiet > /dev/null && mv "$csv.tmp" "$csv"
        tail -1 "$summary"
      done
    done
  done
done
# Controller variants on a few of our simulator's models (row "sim+<variant>"): Tu & Lin's own
# MPPI settings and SMPPI-style smoothed sampling noise (launch_scripts/mppi/*.toml).
for variant in ${VARIANTS:-tu_lin smooth}; do
  for name in ${VARIANT_MODELS:-node-rk4-k1 node-rk4-k3 residual-k2 node-dopri5-k3}; do
    m="$out/models/sim-$name"
    [[ -e "$m/model.json" ]] || continue
    for scene in free obstacle; do
      csv="$out/episodes/$scene-sim+$variant-$name.csv"
      [[ -e "$csv" ]] && continue
      "$bin" eval push --model "$m" --scenario "$scene" --episodes "$EPISODES" --seed "$SEED" \
        --mppi "$root/launch_scripts/mppi/$variant.toml" --label "sim+$variant-$name" \
        --csv "$csv.tmp" --summary "$summary" --quiet > /dev/null && mv "$csv.tmp" "$csv"
      tail -1 "$summary"
    done
  done
done
# the table: one row per model (data set @ plant, kind, k), free and obstacle side by side
awk -F, 'NR > 1 { key = $1; kind[key] = $2; k[key] = $3
  split(key, a, "-"); data[key] = a[1]
  cell = sprintf("%.0f %% / %.0f %% / %.1f / %d (n=%d)", 100 * $7, 100 * $9, $12, $10, $5)
  if ($4 == "free") free[key] = cell; else obst[key] = cell }
  END {
    rank["residual"] = 1; rank["node-euler"] = 2; rank["node-rk4"] = 3; rank["node-dopri5"] = 4
    rank["physics"] = 5; rank["hybrid"] = 6
    print "| data | kind | k | free: success / strict / steps to success / collisions | obstacle: success / strict / steps to success / collisions |"
    print "|---|---|---|---|---|"
    n = 0; for (key in kind) { keys[++n] = key; sk[key] = sprintf("%d|%s|%d|%d", index(data[key], "+") > 0, data[key], rank[kind[key]], k[key]) }
    for (i = 1; i <= n; i++) for (j = i + 1; j <= n; j++) if (sk[keys[j]] < sk[keys[i]]) { t = keys[i]; keys[i] = keys[j]; keys[j] = t }
    for (i = 1; i <= n; i++) { key = keys[i]
      printf "| %s | %s | %s | %s | %s |\n", data[key], kind[key], k[key], free[key], obst[key] }
  }' "$summary" > "$out/table.md"
cat "$out/table.md"
