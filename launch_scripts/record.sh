#!/usr/bin/env bash
# Records the dynlab topics into a rosbag2-compatible bag directory until Ctrl-C.
#   launch_scripts/record.sh bags/run1                   # /car/* and /push/* topics and /clock
#   launch_scripts/record.sh bags/run1 --all             # everything discovered
#   ROS_DOMAIN_ID=7 launch_scripts/record.sh bags/run1 /car/pose --ros-args -r /car/pose:=/mocap/pose
set -euo pipefail
cd "$(dirname "$0")/.."
out="${1:?usage: launch_scripts/record.sh OUTPUT_DIR [TOPIC… | --all] [--ros-args …]}"
shift
cargo build --release -q -p dynlab-nodes --bin recorder
bin="${CARGO_TARGET_DIR:-$PWD/target}/release/recorder"
if [ "$#" -eq 0 ]; then
  set -- /car/pose /car/cmd /push/block_pose /push/action /clock
fi
exec "$bin" -o "$out" "$@"
