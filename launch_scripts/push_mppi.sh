#!/usr/bin/env bash
# The pushing simulator and the MPPI pusher as separate processes over DDS (+ a recorder):
#
#   launch_scripts/push_mppi.sh MODEL [free|obstacle] [BAG_OUT]
#
# sim_node runs Tu & Lin's scene (free: start (0.4, 0, 0.2π), goal (0.8, 0, 0); obstacle: a
# 0.1 × 0.5 m box at (0.6, 0.2), start (0.4, 0, −0.2π), goal (0.8, −0.1, 0)) at 5 × real time;
# mppi_pusher gets the scene's goal (publish another PoseStamped on /push/goal to move it);
# the recorder writes /push/block_pose, /push/action and /push/goal to BAG_OUT. Ctrl-C stops all.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
model="${1:?usage: push_mppi.sh MODEL [free|obstacle] [BAG_OUT]}"
scene="${2:-free}"
bag="${3:-$root/out/push_mppi_$(date +%Y%m%d_%H%M%S)}"
cd "$root"
cargo build --release -q -p dynlab-nodes --bin sim_node --bin mppi_pusher --bin recorder
bin="${CARGO_TARGET_DIR:-$root/target}/release"
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
pids=()
cleanup() { for p in "${pids[@]}"; do kill -INT "$p" 2>/dev/null || true; done; wait; rm -f "$scen_file"; }
trap cleanup EXIT INT TERM
"$bin/recorder" -o "$bag" /push/block_pose /push/action /push/goal & pids+=($!)
"$bin/sim_node" --ros-args -p world:=push -p scenario:="$scen_file" -p rate:=5.0 -p pose_rate:=10.0 & pids+=($!)
args=(-p model:="$model" -p goal:="$goal")
[[ -n "$obstacle" ]] && args+=(-p obstacle:="$obstacle")
"$bin/mppi_pusher" --ros-args "${args[@]}" & pids+=($!)
wait
