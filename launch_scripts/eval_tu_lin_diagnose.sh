#!/usr/bin/env bash
# The diagnosis on Tu & Lin's pushing data (their PyBullet data converted to our topic contract):
# the physics model trained on the bag, then `dynlab diagnose` on it with several seeds (each
# seed another fit/held-out split), one line per seed with what was named, what it removes and
# its fitted parameters, the term search's result and the caution about the data's starts.
#
#   launch_scripts/eval_tu_lin_diagnose.sh [BAG] [OUT] [SEEDS]
#
# BAG defaults to ../shared/data/tu_lin_pushing.mcap (relative to the repository), OUT to
# out/tu_lin_diagnose, SEEDS to 4 (seeds 0 … SEEDS−1). About 15 s a seed on 2 cores.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bag="${1:-$root/../shared/data/tu_lin_pushing.mcap}"
out="${2:-$root/out/tu_lin_diagnose}"
seeds="${3:-4}"
if [[ ! -e "$bag" ]]; then
  echo "error: $bag not found; pass the path of tu_lin_pushing.mcap (Tu & Lin's data in our topic contract) as the first argument" >&2
  exit 2
fi
if ! [[ "$seeds" =~ ^[1-9][0-9]*$ ]]; then
  echo "error: SEEDS must be a positive whole number, got '$seeds'" >&2
  exit 2
fi
cd "$root"
cargo build --release -q -p dynlab
dynlab="${CARGO_TARGET_DIR:-$root/target}/release/dynlab"
mkdir -p "$out"
"$dynlab" train --kind physics --bag "$bag" --out "$out/model" > "$out/train.txt"
for ((s = 0; s < seeds; s++)); do
  "$dynlab" diagnose --model "$out/model" --bag "$bag" --out "$out/seed$s" --seed "$s" > "$out/seed$s.txt"
  python3 - "$out/seed$s/diagnosis.json" "$s" <<'PY'
import json, sys
d = json.load(open(sys.argv[1]))
j = d.get("joint") or {}
named = ", ".join(d["effects"]) or "none"
params = ", ".join(f"{k} {v:.4g}" for k, v in (j.get("params") or {}).items())
removed = f"{100 * j['error_reduction']:.0f} %" if j else "—"
x = d.get("discovery") or {}
terms = "; ".join(f"{t['equation']} ({100 * t['error_reduction']:.0f} %)"
                  for t in x.get("terms", []) if t.get("significant")) or "no term"
print(f"seed {sys.argv[2]}: named {named} ({removed}{'; ' + params if params else ''}); {terms}"
      f"{'; one start: ' + str(d['one_start']['trajectories']) + ' trajectories' if d.get('one_start') else ''}")
PY
done
