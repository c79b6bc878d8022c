#!/usr/bin/env bash
# The pushing simulator and the MPPI pusher as separate processes over DDS (+ a recorder):
#
#   launch_scripts/push_mppi.sh MODEL [free|obstacle] [BAG_OUT]
#
# sim_node runs Tu & Lin's scene (free: start (0.4, 0, 0.2π), goal (0.8, 0, 0); obstacle: a
# 0.1 × 0.5 m box at (0.6, 0.2), start (0.4, 0, −0.2π), goal (0.8, −0.1, 0)) at $RATE × real time
# (default 5); mppi_pusher gets the scene's goal (publish another PoseStamped on /push/goal to move
# it); the recorder writes /push/block_pose, /push/action and /push/goal to BAG_OUT, the pusher's
# log goes to BAG_OUT.pusher.log as well. Ctrl-C stops all.
#
# One episode, judged: with MAX_PUSHES=N the script stops everything when the pusher reports the
# goal reached or N pushes have run (or after TIMEOUT wall seconds, default 300), then checks the
# bag (launch_scripts/push_check.py: success and strict as `dynlab eval push` judges them, pushes,
# final distance, collision; with --json in CHECK_ARGS one JSON line). Without MAX_PUSHES it runs
# until Ctrl-C. Binaries from $DYNLAB_BIN_DIR (default: target/release, built here).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
model="${1:?usage: push_mppi.sh MODEL [free|obstacle] [BAG_OUT]}"
scene="${2:-free}"
bag="${3:-$root/out/push_mppi_$(date +%Y%m%d_%H%M%S)}"
cd "$root"
if [[ -z "${DYNLAB_BIN_DIR:-}" ]]; then
  cargo build --release -q -p dynlab-nodes --bin sim_node --bin mppi_pusher --bin recorder
fi
bin="${DYNLAB_BIN_DIR:-${CARGO_TARGET_DIR:-$root/target}/release}"
rate="${RATE:-5.0}"
scen_file="$(mktemp --suffix .toml)"
case "$scene" in
  free)
    printf 'name = "free"\nstart = [0.4, 0.0, 0.6283185307179586]\ngoal = [0.8, 0.0, 0.0]\n' > "$scen_file"
    goal="0.8,0.0,0.0"; obstacle="" ;;
  obstacle)
    printf 'name = "obstacle"\nstart = [0.4, 0.0, -0.6283185307179586]\ngoal = [0.8, -0.1, 0.0]\n[[obstacles]]\ncentre = [0.6, 0.2]\nsize = [0.1, 0.5]\n' > "$scen_file"
    goal="0.8,-0.1,0.0"; obstacle="0.6,0.2,0.1,0.5" ;;
  *) echo "error: scene must be free or obstacle, got $scene" >&2; exit 2 ;;
esac
log="$bag.pusher.log"
pids=()
cleanup() { for p in "${pids[@]}"; do kill -INT "$p" 2>/dev/null || true; wait "$p" 2>/dev/null || true; done; rm -f "$scen_file"; }
trap cleanup EXIT INT TERM
"$bin/recorder" -o "$bag" /push/block_pose /push/action /push/goal & pids+=($!)
args=(-p model:="$model" -p goal:="$goal")
[[ -n "$obstacle" ]] && args+=(-p obstacle:="$obstacle")
"$bin/mppi_pusher" --ros-args "${args[@]}" 2> >(tee "$log" >&2) & pids+=($!)
# the simulator last, once the recorder has had time to discover the pusher (at 5 × real time
# the first push goes out 0.2 s after the simulator starts)
sleep "${START_DELAY:-1.5}"
"$bin/sim_node" --ros-args -p world:=push -p scenario:="$scen_file" -p rate:="$rate" -p pose_rate:=10.0 & pids+=($!)
if [[ -z "${MAX_PUSHES:-}" ]]; then
  wait
  exit 0
fi
# one judged episode: stop at the goal, after MAX_PUSHES pushes (once the last has settled) or
# at the timeout
start=$SECONDS
while (( SECONDS - start < ${TIMEOUT:-300} )); do
  sleep 0.2
  grep -q "goal reached" "$log" 2>/dev/null && break
  n=$(grep -c "push [0-9]* from" "$log" 2>/dev/null) || n=0
  if (( n >= MAX_PUSHES )); then
    sleep "$(python3 -c "print(2.5 / $rate)")"
    break
  fi
done
# recorder first so the bag ends cleanly, then the others
for p in "${pids[@]}"; do kill -INT "$p" 2>/dev/null || true; wait "$p" 2>/dev/null || true; done
pids=()
check=(--goal "$goal" --max-pushes "$MAX_PUSHES" --log "$log")
[[ -n "$obstacle" ]] && check+=(--obstacle "${obstacle}")
if [[ -x "$bin/dynlab" ]]; then
  "$bin/dynlab" bag export "$bag" > "$bag.jsonl"
  python3 "$root/launch_scripts/push_check.py" "$bag.jsonl" "${check[@]}" ${CHECK_ARGS:-}
fi
