#!/usr/bin/env bash
# The whole test suite: formatting and lints, Rust unit and integration tests, then the interop
# tests against independent peers (Cyclone DDS, rosbags, mcap-ros2-support), which drive the
# release binaries.
set -euo pipefail
cd "$(dirname "$0")/.."
bash tests/setup_python.sh
cargo fmt --all --check
cargo clippy --workspace --all-targets --locked -- -D warnings
cargo build --release --workspace --bins --locked
cargo test --release --workspace --locked
export DYNLAB_BIN_DIR="${CARGO_TARGET_DIR:-$PWD/target}/release"
# two workers: the DDS tests on one, one after another, the diagnosis loops beside them
# (tests/interop/conftest.py)
.venv/bin/python -m pytest tests/interop -q -n 2
