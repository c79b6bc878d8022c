#!/usr/bin/env bash
# Regenerates the checked-in data sets in bags/ with fixed seeds (byte-identical on every run
# and thread count):
#
#   launch_scripts/make_bags.sh [OUT_DIR]      # default: bags/ of this repository
#
# Each bag is `dynlab collect` on a scenario of launch_scripts/scenarios/ (see bags/README.md
# for what each holds). The `dynlab` release binary comes from $DYNLAB_BIN_DIR (default:
# target/release; build it with `cargo build --release -p dynlab`). Existing bags of the same
# name are replaced.
set -euo pipefail
here="$(cd "$(dirname "$0")/.." && pwd)"
bin="${DYNLAB_BIN_DIR:-${CARGO_TARGET_DIR:-$here/target}/release}"
out="${1:-$here/bags}"
scenarios="$here/launch_scripts/scenarios"
[[ -x "$bin/dynlab" ]] || { echo "make_bags.sh: $bin/dynlab not found; run cargo build --release -p dynlab" >&2; exit 2; }
mkdir -p "$out"

# Bags for control (push_wide, car_track, car_race; launch_scripts/control.sh trains on them) take
# extra `collect` arguments (last column; scenario files relative to launch_scripts/scenarios/).
# Set ONLY="name …" to regenerate some of them.
# name        world  scenario                  episodes  seed  extra collect arguments
bags=(
  "push_nominal        push  push_nominal.toml         40  101"
  "push_friction_patch push  push_friction_patch.toml  40  102"
  "push_com_offset     push  push_com_offset.toml      40  103"
  "car_nominal         car   car_nominal.toml           3  201"
  "car_aero_drag       car   car_aero_drag.toml         3  202"
  "car_steering_offset car   car_steering_offset.toml   3  203"
  "car_drag_steering   car   car_drag_steering.toml     3  204"
  "car_steering_gain   car   car_steering_gain.toml     3  205"
  "push_wide           push  push_wide.toml           500    7  --explore push_wide_explore.toml --episode-gap 30"
  "car_track           car   car_track.toml            10  301  --explore car_track_explore.toml"
  "car_race            car   car_track.toml            10  302  --race car_track_race.toml"
)
for line in "${bags[@]}"; do
  read -r name world scenario episodes seed extra <<<"$line"
  if [[ -n "${ONLY:-}" && " $ONLY " != *" $name "* ]]; then continue; fi
  args=()
  for a in $extra; do
    if [[ "$a" == *.toml ]]; then args+=("$scenarios/$a"); else args+=("$a"); fi
  done
  rm -rf "${out:?}/$name"
  echo "== $name"
  "$bin/dynlab" collect "$world" --scenario "$scenarios/$scenario" --episodes "$episodes" \
    --seed "$seed" "${args[@]}" --out "$out/$name"
  [[ -f "$out/$name/metadata.yaml" ]] || { echo "make_bags.sh: $name was not written" >&2; exit 1; }
done
du -sh "$out"/*/ | sed "s|$out/||"
