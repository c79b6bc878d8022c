#!/usr/bin/env bash
# The diagnosis loop on pushing data that dynlab's simulator did not make
# (launch_scripts/foreign_push.py: exact quasi-static pushing over a 15 × 15 Coulomb support grid,
# other topic names, the block's size and the pusher's radius 10 % off the datasheet): per block
# seed a nominal bag and `dynlab train` with the block's measured size, per case a bag with hidden
# effects and `dynlab diagnose`; prints what was named, the error removed, the fitted strengths
# against the truth and the terms found beyond the library.
# Usage: launch_scripts/eval_foreign_push.sh [--seeds N] [--first-seed N] [--only CASE,CASE]
#        [--jobs N] [--out DIR] [--episodes N] [--perturb F]   (defaults: 3 seeds from 0, every
#        case, 2 jobs, out/eval_foreign_push, 40 episodes of 10 pushes a bag, ±10 %)
set -euo pipefail
cd "$(dirname "$0")/.."
bash tests/setup_python.sh
cargo build --release -q -p dynlab --bin dynlab
exec .venv/bin/python launch_scripts/eval_foreign_push.py "$@"
