#!/usr/bin/env bash
# Creates .venv with the independent peers the interop tests talk to (Cyclone DDS, rosbags,
# mcap-ros2-support), pinned in tests/requirements.txt. Safe to run again: it only installs what is
# missing or changed.
set -euo pipefail
cd "$(dirname "$0")/.."
if [ ! -x .venv/bin/python ]; then
  python3 -m venv .venv
fi
stamp=.venv/.requirements.sha
want=$(sha256sum tests/requirements.txt | cut -d' ' -f1)
if [ "$(cat "$stamp" 2>/dev/null)" != "$want" ]; then
  .venv/bin/python -m pip install --quiet --disable-pip-version-check -r tests/requirements.txt
  echo "$want" > "$stamp"
fi
