#!/usr/bin/env bash
# The control demo in one command: trains the models from the bundled bags with `dynlab train`'s
# defaults, then runs every controller as separate processes over DDS, records bags and prints one
# table.
#
#   launch_scripts/control.sh [OUT]          # default out/control
#
# 1. trains (skipped when OUT/models/NAME/model.json exists): a pushing node-rk4 model on
#    bags/push_wide, car node-rk4 and residual models on bags/car_nominal, bags/car_track and
#    bags/car_race (the defaults: pushing k = 1, 300 epochs; car k = 5, 40 epochs);
# 2. pushing: launch_scripts/push_mppi.sh (sim_node at $PUSH_RATE × real time, default 5,
#    mppi_pusher, recorder) in Tu & Lin's free and obstacle scenes, one episode each, stopped at
#    the goal or after 20 pushes, judged from the bag (launch_scripts/push_check.py);
# 3. racing: launch_scripts/race.sh (sim_node at $SIM_RATE × real time, default 1, racer,
#    recorder) for $RACE_SECONDS wall seconds (default 30) with each car model on the default
#    track and on the hairpin track (launch_scripts/tracks/hairpin.json with hairpin_racer.toml),
#    judged from the bag and the racer's log (launch_scripts/race_check.py); the lap time of the
#    true model (the simulator's own car inside the same racer, `dynlab eval race`, headless, the
#    second of two laps) is beside it;
# 4. prints the table (also OUT/table.md).
#
# Environment: SIM_RATE, PUSH_RATE, RACE_SECONDS, THREADS (training threads, default 2),
# ROS_DOMAIN_ID (default 0; use another one when others run DDS nodes on the machine).
# Binaries from $DYNLAB_BIN_DIR (default: target/release, built here). Takes ≈ 10 min on 2 cores
# (training ≈ 4 min, racing 4 × RACE_SECONDS, the rest seconds).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
out="${1:-$root/out/control}"
SIM_RATE="${SIM_RATE:-1.0}"
PUSH_RATE="${PUSH_RATE:-5.0}"
RACE_SECONDS="${RACE_SECONDS:-30}"
THREADS="${THREADS:-2}"
export ROS_DOMAIN_ID="${ROS_DOMAIN_ID:-0}"
cd "$root"
if [[ -z "${DYNLAB_BIN_DIR:-}" ]]; then
  cargo build --release -q -p dynlab -p dynlab-nodes --bins
fi
export DYNLAB_BIN_DIR="${DYNLAB_BIN_DIR:-${CARGO_TARGET_DIR:-$root/target}/release}"
dl="$DYNLAB_BIN_DIR/dynlab"
for b in dynlab sim_node racer recorder mppi_pusher; do
  [[ -x "$DYNLAB_BIN_DIR/$b" ]] || { echo "control.sh: $DYNLAB_BIN_DIR/$b not found; run cargo build --release -p dynlab -p dynlab-nodes --bins" >&2; exit 2; }
done
for b in push_wide car_nominal car_track car_race; do
  [[ -f "$root/bags/$b/metadata.yaml" ]] || { echo "control.sh: bags/$b missing; launch_scripts/make_bags.sh regenerates it" >&2; exit 2; }
done
mkdir -p "$out/models" "$out/runs"

# 1. models, with the training defaults
train() {
  local name="$1" kind="$2"; shift 2
  [[ -f "$out/models/$name/model.json" ]] && return 0
  echo "== train $name"
  "$dl" train --bag "$@" --kind "$kind" --threads "$THREADS" --quiet --out "$out/models/$name"
}
train push_node-rk4 node-rk4 bags/push_wide
for kind in node-rk4 residual; do
  train "car_$kind" "$kind" bags/car_nominal bags/car_track bags/car_race
done

# 2. pushing over DDS
for scene in free obstacle; do
  echo "== push $scene"
  rm -rf "$out/runs/push_$scene"
  RATE="$PUSH_RATE" MAX_PUSHES=20 CHECK_ARGS=--json bash "$root/launch_scripts/push_mppi.sh" \
    "$out/models/push_node-rk4" "$scene" "$out/runs/push_$scene" \
    > "$out/runs/push_$scene.check" 2> "$out/runs/push_$scene.err" \
    || echo "control.sh: push $scene failed (see $out/runs/push_$scene.err)" >&2
done

# 3. racing over DDS, with the true model's lap time from the headless evaluation
tracks=(
  "default:launch_scripts/tracks/default.json:launch_scripts/scenarios/car_track.toml:"
  "hairpin:launch_scripts/tracks/hairpin.json:launch_scripts/scenarios/car_hairpin.toml:launch_scripts/tracks/hairpin_racer.toml"
)
for t in "${tracks[@]}"; do
  IFS=: read -r name track scenario settings <<<"$t"
  set_eval=(); set_racer=()
  if [[ -n "$settings" ]]; then
    set_eval=(--settings "$root/$settings"); set_racer=(-p "settings:=$root/$settings")
  fi
  if [[ ! -f "$out/runs/true_$name/report.json" ]]; then
    echo "== true model laps, $name track"
    "$dl" eval race --model "$out/models/car_node-rk4" --laps 2 --track "$root/$track" \
      "${set_eval[@]}" --out "$out/runs/true_$name" > "$out/runs/true_$name.txt" \
      || echo "control.sh: the true model's laps on $name failed (see $out/runs/true_$name.txt)" >&2
  fi
  for kind in node-rk4 residual; do
    echo "== race $kind, $name track, ${RACE_SECONDS} s at ${SIM_RATE} × real time"
    bag="$out/runs/race_${name}_$kind"
    rm -rf "$bag"
    SIM_RATE="$SIM_RATE" SCENARIO="$root/$scenario" TRACK="$root/$track" CHECK_ARGS=--json \
      bash "$root/launch_scripts/race.sh" "$out/models/car_$kind" "$RACE_SECONDS" "$bag" \
      "${set_racer[@]}" > "$bag.check" 2> "$bag.err" \
      || echo "control.sh: race $kind on $name failed (see $bag.err)" >&2
  done
done

# 4. the table
python3 - "$out" "$SIM_RATE" "$PUSH_RATE" <<'EOF' | tee "$out/table.md"
import json, sys, os
out, sim_rate, push_rate = sys.argv[1], sys.argv[2], sys.argv[3]

def last_json(path):
    try:
        lines = [l for l in open(path) if l.strip().startswith("{")]
        return json.loads(lines[-1]) if lines else None
    except OSError:
        return None

print(f"Pushing (node-rk4 on bags/push_wide; sim_node at {push_rate} × real time, one episode per scene):\n")
print("| scene | success | strict | pushes | final distance (m) | collision |")
print("|---|---|---|---|---|---|")
for scene in ("free", "obstacle"):
    r = last_json(f"{out}/runs/push_{scene}.check")
    if r is None:
        print(f"| {scene} | failed | | | | |")
        continue
    d = r.get("final_distance_m")
    print(f"| {scene} | {'yes' if r['success'] else 'no'} | {'yes' if r['strict'] else 'no'} | {r['pushes']} | "
          f"{'' if d is None else f'{d:.3f}'} | {'yes' if r['collision'] else 'no'} |")
print(f"\nRacing (sim_node at {sim_rate} × real time over DDS; true model: the simulator's car in the same racer, headless):\n")
print("| track | model | laps | lap times (s) | true model lap (s) | excursions | late commands | solve p50 / p99 / worst (ms) | stopped at the budget |")
print("|---|---|---|---|---|---|---|---|---|")
for name in ("default", "hairpin"):
    true_lap = ""
    try:
        rep = json.load(open(f"{out}/runs/true_{name}/report.json"))
        laps = [r for r in rep["runs"] if r["model"] == "true"][0]["lap_times"]
        true_lap = f"{laps[-1]:.2f}" if laps else "no lap"
    except (OSError, IndexError, KeyError, ValueError):
        pass
    for kind in ("node-rk4", "residual"):
        r = last_json(f"{out}/runs/race_{name}_{kind}.check")
        if r is None:
            print(f"| {name} | {kind} | failed | | {true_lap} | | | | |")
            continue
        laps = ", ".join(f"{x:.2f}" for x in r["lap_times_s"])
        late = f"{r['late_commands']} of {r['solves_logged']}" if "late_commands" in r else "not logged"
        p50 = r.get("solve_p50_ms", r.get("solve_sampled_p50_ms"))
        p99 = r.get("solve_p99_ms", r.get("solve_sampled_p99_ms"))
        solve = f"{p50:.1f} / {p99:.1f} / {r['solve_worst_ms']:.1f}" if "solve_worst_ms" in r else ""
        stops = r.get("budget_stops", "")
        print(f"| {name} | {kind} | {r['laps']} | {laps} | {true_lap} | {r['excursions']} | {late} | {solve} | {stops} |")
print("\nSolve p50 / p99 / worst are over every solve (the racer's summary at shutdown; from its")
print("progress lines, every 100th solve, when a run has no summary); stopped at the budget: solves cut")
print("off at the racer's solve_budget (15 ms) with the best plan so far;")
print("late commands: published after their apply time (the solve took longer than the 30 ms delay).")
EOF
