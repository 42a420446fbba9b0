#!/usr/bin/env bash
# Set up everything on a fresh machine: a virtual environment per Blender API line, the package
# in editable mode (mocap-gapfill command), and the wheels the extension bundles (./wheels):
#   .venv    Python 3.11, bpy 5.0, torch 2.13.0 CPU, ray, dask (the whole suite, the command line)
#   .venv42  Python 3.11, bpy 4.2 LTS (add-on tests)
#   .venv52  Python 3.13, bpy 5.2  (add-on tests; Blender 5.1+ runs Python 3.13)
# Safe to run again.
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3.11}
export PIP_DISABLE_PIP_VERSION_CHECK=1

find_python313() {
  if [ -n "${PYTHON313:-}" ]; then echo "$PYTHON313"; return; fi
  if python3.13 --version >/dev/null 2>&1; then command -v python3.13; return; fi
  local root
  root=$(pyenv root 2>/dev/null || echo "$HOME/.pyenv")
  ls -d "$root"/versions/3.13*/bin/python3.13 2>/dev/null | sort -V | tail -1
}

make_venv() {
  local dir=$1 python=$2
  shift 2
  [ -x "$dir/bin/python" ] || "$python" -m venv "$dir"
  "$dir/bin/pip" install -q "$@" "ezc3d==1.7.2" "threadpoolctl==3.7.0" pytest
  "$dir/bin/pip" install -q --no-deps -e .
}

# bpy 4.2-5.0 are built against numpy 1.x
# torch is optional for users; pinned here (2.13.0 is the CPU build these machines keep)
# ray and dask: the batch command's cluster engines (optional extras for users)
make_venv .venv "$PY" "numpy<2" "scipy==1.16.3" "bpy==5.0.1" "torch==2.13.0" "ray==2.60.0" \
  "dask[distributed]==2026.8.0"
if [ "${MOCAP_GAPFILL_SKIP_BPY42:-0}" != 1 ]; then
  make_venv .venv42 "$PY" "numpy<2" "scipy==1.16.3" "bpy==4.2.23"
fi
if [ "${MOCAP_GAPFILL_SKIP_BPY52:-0}" != 1 ]; then
  PY313=$(find_python313)
  [ -n "$PY313" ] || { echo "Python 3.13 not found (set PYTHON313)"; exit 1; }
  make_venv .venv52 "$PY313" "scipy==1.17.1" "bpy==5.2.3"
fi
.venv/bin/python tools/fetch_wheels.py
echo "setup done: .venv/bin/mocap-gapfill --help"
