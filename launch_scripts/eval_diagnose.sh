#!/usr/bin/env bash
# Recovery rate of `dynlab diagnose` over several seeds with shorter data and more noise than
# the tests: for each world and each effect of the library, simulator data with only that
# effect on (and nominal data), the nominal physics model diagnosed; prints how often the hidden
# effect is named first and significant (nominal: how often nothing is named).
# Usage: launch_scripts/eval_diagnose.sh [--seeds N] [--noise X] [--car-episodes N]
#        [--car-duration S] [--push-episodes N] [--only NAME] [--world car|push] [--steps K]
#        [--fit-baseline] [--no-refit] [--no-bonferroni]
# Defaults: 5 seeds, noise ×2 (1 mm, 0.004 rad), car 4 × 15 s, pushing 20 × 10 pushes.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo run --release -q -p dynlab-diagnose --example recovery -- "$@"
