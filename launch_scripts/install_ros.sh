#!/usr/bin/env bash
# Installs dynlab into a ROS 2 prefix without colcon, so that `ros2 launch` and `ros2 run` find it:
#
#   launch_scripts/install_ros.sh PREFIX [--no-build]
#
# builds the release node binaries (`cargo build --release --locked -p dynlab-nodes --bins`;
# --no-build takes them as they are from $DYNLAB_BIN_DIR, default target/release) and lays out
#
#   PREFIX/lib/dynlab/<node>                                  every nodes/src/bin/*.rs
#   PREFIX/share/dynlab/package.xml
#   PREFIX/share/dynlab/launch/*.launch.xml
#   PREFIX/share/dynlab/{tracks,scenarios}/                   files the launch files name
#   PREFIX/share/ament_index/resource_index/packages/dynlab   the ament index marker (empty)
#   PREFIX/setup.sh                                           adds PREFIX to AMENT_PREFIX_PATH
#
# the same tree `colcon build` installs from package.xml and CMakeLists.txt. Then, in a shell
# with ROS 2 Jazzy sourced:
#
#   source PREFIX/setup.sh
#   ros2 launch dynlab racer.launch.xml model:=out/car_physics bag:=out/race_bag
#
# Installing again over the same PREFIX replaces the files.
set -euo pipefail
here="$(cd "$(dirname "$0")/.." && pwd)"
usage="usage: launch_scripts/install_ros.sh PREFIX [--no-build]"
prefix="${1:?$usage}"
build=1
case "${2:-}" in
  "") ;;
  --no-build) build=0 ;;
  *) echo "install_ros.sh: unknown option '$2'; $usage" >&2; exit 2 ;;
esac
mkdir -p "$prefix"
prefix="$(cd "$prefix" && pwd)"

if (( build )); then
  (cd "$here" && cargo build --release --locked -p dynlab-nodes --bins)
  bin="${CARGO_TARGET_DIR:-$here/target}/release"
else
  bin="${DYNLAB_BIN_DIR:-${CARGO_TARGET_DIR:-$here/target}/release}"
fi

nodes=()
for src in "$here"/nodes/src/bin/*.rs; do
  name="$(basename "$src" .rs)"
  [[ -x "$bin/$name" ]] || {
    echo "install_ros.sh: $bin/$name not found; build it with cargo build --release -p dynlab-nodes --bins (or drop --no-build)" >&2
    exit 2
  }
  nodes+=("$name")
done

share="$prefix/share/dynlab"
mkdir -p "$prefix/lib/dynlab" "$share/launch" "$share/tracks" "$share/scenarios" \
  "$prefix/share/ament_index/resource_index/packages"
for name in "${nodes[@]}"; do
  install -m 755 "$bin/$name" "$prefix/lib/dynlab/$name"
done
install -m 644 "$here/package.xml" "$share/package.xml"
install -m 644 "$here"/launch/*.launch.xml "$share/launch/"
install -m 644 "$here"/launch_scripts/tracks/*.json "$share/tracks/"
install -m 644 "$here"/launch_scripts/scenarios/*.toml "$share/scenarios/"
: > "$prefix/share/ament_index/resource_index/packages/dynlab"
cat > "$prefix/setup.sh" <<SETUP
# dynlab in $prefix: source after ROS 2 (e.g. /opt/ros/jazzy/setup.bash)
case ":\${AMENT_PREFIX_PATH:-}:" in
  *":$prefix:"*) ;;
  *) export AMENT_PREFIX_PATH="$prefix\${AMENT_PREFIX_PATH:+:\$AMENT_PREFIX_PATH}" ;;
esac
SETUP
echo "installed ${#nodes[@]} nodes (${nodes[*]}) and $(ls "$share/launch" | wc -l) launch files into $prefix"
echo "use: source $prefix/setup.sh; ros2 launch dynlab racer.launch.xml model:=DIR bag:=DIR"
