#!/usr/bin/env bash
# The diagnosis loop on car data that dynlab's simulator did not make (launch_scripts/foreign_car.py:
# a numpy dynamic bicycle, 120 Hz motion capture with dropouts, other topic names, the car's
# parameters 10 % off the datasheet): per car seed a nominal bag and `dynlab train`, per case a bag
# with hidden effects and `dynlab diagnose`; prints what was named, the error removed, the fitted
# strengths against the truth and the terms found beyond the library.
# Usage: launch_scripts/eval_foreign.sh [--seeds N] [--first-seed N] [--only CASE,CASE] [--jobs N]
#        [--out DIR] [--friction-ellipse] [--rate HZ] [--perturb F] [--floor]   (defaults: 3 seeds
#        from 0, every case, 2 jobs, out/eval_foreign; --friction-ellipse: cars whose drive force
#        takes lateral grip; --rate: the motion capture's frequency, 120 Hz; --perturb: the cars'
#        parameters within ±F of the datasheet, 0.1; --floor:
#        each library case diagnosed with the generator's own car too, the error no model goes below)
set -euo pipefail
cd "$(dirname "$0")/.."
bash tests/setup_python.sh
cargo build --release -q -p dynlab --bin dynlab
exec .venv/bin/python launch_scripts/eval_foreign.py "$@"
