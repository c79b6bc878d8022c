#!/usr/bin/env bash
# The whole test suite: Rust unit and integration tests, then the interop tests against
# independent peers (Cyclone DDS, rosbags, mcap-ros2-support), which drive the release binaries.
set -euo pipefail
cd "$(dirname "$0")/.."
bash tests/setup_python.sh
cargo build --release --workspace --bins --locked
cargo test --release --workspace --locked
export DYNLAB_BIN_DIR="${CARGO_TARGET_DIR:-$PWD/target}/release"
.venv/bin/python -m pytest tests/interop -q
