#!/usr/bin/env bash
# Trains every model kind for k = 1…5 on Tu & Lin's pushing data (their PyBullet data converted
# to our topic contract), on their split (80/20 overlapping windows, seed 42, their loss) and on a
# split by whole trajectories, and prints our validation losses beside their published table.
#
#   launch_scripts/eval_tu_lin.sh [BAG] [--full] [--epochs N] [--batch B] [--lr LR] [--threads T] [--kinds a,b] [--effects a,b] [--json OUT]
#
# BAG defaults to ../shared/data/tu_lin_pushing.mcap (relative to the repository). The default
# budget (250 epochs at lr 1e-3, hybrid 60, batch 100: 2000 Adam steps) takes ≈ 20 min on 2 cores;
# --full uses theirs (3000 epochs at lr 1e-4, batch 500: 6000 steps, several hours).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bag="$root/../shared/data/tu_lin_pushing.mcap"
if [[ $# -gt 0 && "$1" != --* ]]; then
  bag="$1"
  shift
fi
if [[ ! -e "$bag" ]]; then
  echo "error: $bag not found; pass the path of tu_lin_pushing.mcap (Tu & Lin's data in our topic contract) as the first argument" >&2
  exit 2
fi
cd "$root"
cargo build --release -q -p dynlab-learn --example tu_lin_table
exec "${CARGO_TARGET_DIR:-$root/target}/release/examples/tu_lin_table" "$bag" "$@"
