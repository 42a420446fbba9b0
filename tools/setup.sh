#!/usr/bin/env bash
# Set up everything on a fresh machine: a Python 3.11 virtual environment per Blender API line
# (.venv: bpy 5.0, .venv42: bpy 4.2 LTS), the package in editable mode (mocap-gapfill command),
# and the wheels the extension bundles (./wheels). Safe to run again.
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3.11}
export PIP_DISABLE_PIP_VERSION_CHECK=1

make_venv() {
  local dir=$1 bpy=$2
  [ -x "$dir/bin/python" ] || "$PY" -m venv "$dir"
  # bpy 4.2-5.0 are built against numpy 1.x
  "$dir/bin/pip" install -q "numpy<2" "scipy==1.16.3" "ezc3d==1.7.2" pytest "bpy==$bpy"
  "$dir/bin/pip" install -q --no-deps -e .
}

make_venv .venv 5.0.1
if [ "${MOCAP_GAPFILL_SKIP_BPY42:-0}" != 1 ]; then
  make_venv .venv42 4.2.23
fi
.venv/bin/python tools/fetch_wheels.py
echo "setup done: .venv/bin/mocap-gapfill --help"
