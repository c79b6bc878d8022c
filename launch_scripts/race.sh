#!/usr/bin/env bash
# Races the simulated car with the receding-horizon racer over DDS:
#
#   launch_scripts/race.sh MODEL_DIR [SECONDS] [OUT_BAG] [racer ROS args …]
#
# starts separate processes on the ROS_DOMAIN_ID domain (default 0) —
#   sim_node  (world car, real time, the car on a track: $SCENARIO, default
#              launch_scripts/scenarios/car_track.toml),
#   racer     (model MODEL_DIR, the scenario's track file $TRACK, default
#              launch_scripts/tracks/default.json; /car/pose in, /car/cmd out, following /clock),
#   recorder  (only if OUT_BAG is given: /car/pose /car/cmd /car/odom /clock) —
# lets them run for SECONDS of wall time (default 20), then stops them with SIGINT.
# Extra arguments go to the racer's --ros-args, e.g. `-p optimizer:=gd` or `-p delay:=0.05`.
# The racer publishes each command 30 ms (its `delay`) of simulation time after the pose it was
# computed from and plans from the state predicted at that time, so every solve must finish
# within 30 ms of simulation time: the racer stops each solve at its `solve_budget` (15 ms of
# wall clock) and sends the best plan found, so the simulation runs at real time ($SIM_RATE,
# default 1; lower it to give the optimiser more simulated time per solve). The racer logs late
# commands and the solves stopped at the budget every 100 solves.
# With OUT_BAG and the `dynlab` binary present, the bag is checked at the end
# (launch_scripts/race_check.py: laps, lap times, excursions, border distance, command rate, and
# from the racer's log, which goes to OUT_BAG.racer.log too, solves and late commands; with
# CHECK_ARGS=--json one JSON line).
#
# Binaries from $DYNLAB_BIN_DIR (default: target/release; build them with
# `cargo build --release -p dynlab-nodes --bins`).
set -euo pipefail
here="$(cd "$(dirname "$0")/.." && pwd)"
bin="${DYNLAB_BIN_DIR:-${CARGO_TARGET_DIR:-$here/target}/release}"
model="${1:?usage: race.sh MODEL_DIR [SECONDS] [OUT_BAG] [racer ROS args …]}"
seconds="${2:-20}"
out="${3:-}"
shift $(( $# < 3 ? $# : 3 ))
scenario="${SCENARIO:-$here/launch_scripts/scenarios/car_track.toml}"
track="${TRACK:-$here/launch_scripts/tracks/default.json}"
for b in sim_node racer recorder; do
  [[ -x "$bin/$b" ]] || { echo "race.sh: $bin/$b not found; run cargo build --release -p dynlab-nodes --bins" >&2; exit 2; }
done

pids=()
cleanup() { for p in "${pids[@]}"; do kill -INT "$p" 2>/dev/null || true; done; }
trap cleanup EXIT

if [[ -n "$out" ]]; then
  "$bin/recorder" -o "$out" /car/pose /car/cmd /car/odom /clock --ros-args -p use_sim_time:=true &
  pids+=("$!")
fi
"$bin/sim_node" --ros-args -p world:=car -p "scenario:=$scenario" -p "rate:=${SIM_RATE:-1.0}" &
pids+=("$!")
if [[ -n "$out" ]]; then
  # the racer's log also to OUT_BAG.racer.log (race_check.py reads its solve and late-command counts)
  "$bin/racer" --ros-args -p "model:=$model" -p "track:=$track" -p use_sim_time:=true "$@" \
    2> >(tee "$out.racer.log" >&2) &
else
  "$bin/racer" --ros-args -p "model:=$model" -p "track:=$track" -p use_sim_time:=true "$@" &
fi
pids+=("$!")

sleep "$seconds"
trap - EXIT
# recorder first so the bag ends cleanly
for p in "${pids[@]}"; do kill -INT "$p" 2>/dev/null || true; wait "$p" || true; done
if [[ -n "$out" && -x "$bin/dynlab" ]]; then
  "$bin/dynlab" bag export "$out" > "$out.jsonl"
  python3 "$here/launch_scripts/race_check.py" "$out.jsonl" "$track" --racer-log "$out.racer.log" ${CHECK_ARGS:-}
fi
