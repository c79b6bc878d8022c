#!/usr/bin/env bash
# Records simulated data over DDS, the way data from a real robot is recorded:
#
#   launch_scripts/record_sim.sh push|car OUT_BAG [SECONDS] [sim_node ROS args …]
#
# starts three separate processes on the ROS_DOMAIN_ID domain (default 0) —
#   sim_node  (world push|car, real time; scenario from $SCENARIO if set),
#   explorer  (the exploration driver: /push/action or /car/cmd, following /clock),
#   recorder  (the world's topics and /clock into OUT_BAG, log time = simulation time) —
# lets them run for SECONDS of wall time (default 5), then stops them with SIGINT (recorder
# first, so the bag ends cleanly) and prints the recorder's summary. Extra arguments go to
# sim_node's --ros-args, e.g. `-p rate:=5.0` for five times real time.
#
# The release binaries are taken from $DYNLAB_BIN_DIR (default: target/release of this
# repository; build them with `cargo build --release -p dynlab-nodes --bins`).
# `dynlab collect` writes the same topics headless and far faster (see bags/README.md).
set -euo pipefail
here="$(cd "$(dirname "$0")/.." && pwd)"
bin="${DYNLAB_BIN_DIR:-${CARGO_TARGET_DIR:-$here/target}/release}"
world="${1:?usage: record_sim.sh push|car OUT_BAG [SECONDS] [sim_node ROS args …]}"
out="${2:?usage: record_sim.sh push|car OUT_BAG [SECONDS] [sim_node ROS args …]}"
seconds="${3:-5}"
shift $(( $# < 3 ? $# : 3 ))
case "$world" in
  push) topics=(/push/block_pose /push/action /clock) ;;
  car) topics=(/car/pose /car/cmd /car/odom /clock) ;;
  *) echo "record_sim.sh: world must be push or car, got '$world'" >&2; exit 2 ;;
esac
for b in sim_node explorer recorder; do
  [[ -x "$bin/$b" ]] || { echo "record_sim.sh: $bin/$b not found; run cargo build --release -p dynlab-nodes --bins" >&2; exit 2; }
done
scenario_args=()
[[ -n "${SCENARIO:-}" ]] && scenario_args=(-p "scenario:=$SCENARIO")

pids=()
cleanup() { for p in "${pids[@]}"; do kill -INT "$p" 2>/dev/null || true; done; }
trap cleanup EXIT

"$bin/recorder" -o "$out" "${topics[@]}" --ros-args -p use_sim_time:=true &
rec=$!; pids+=("$rec")
"$bin/sim_node" --ros-args -p "world:=$world" "${scenario_args[@]}" "$@" &
sim=$!; pids+=("$sim")
# the explorer sends its first command once sim_node and the recorder have both subscribed
"$bin/explorer" --ros-args -p "world:=$world" "${scenario_args[@]}" -p use_sim_time:=true \
  -p subscribers:=2 &
exp=$!; pids+=("$exp")

sleep "$seconds"
status=0
kill -INT "$rec"; wait "$rec" || status=$?
kill -INT "$exp" "$sim" 2>/dev/null || true
wait "$exp" || true
wait "$sim" || true
trap - EXIT
exit "$status"
