#!/usr/bin/env bash
# The test command: set up (idempotent), then run the whole suite on bpy 5.0 and the add-on
# tests again on bpy 4.2 LTS. Data comes from ../shared/data (MOCAP_GAPFILL_DATA overrides).
set -euo pipefail
cd "$(dirname "$0")/.."
bash tools/setup.sh
export OMP_NUM_THREADS=1 MKL_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1
export MOCAP_GAPFILL_REQUIRE_DATA=1 MOCAP_GAPFILL_REQUIRE_BPY=1
echo "== bpy 4.2 LTS: add-on tests"
.venv42/bin/python -m pytest -q -p no:cacheprovider tests/addon
echo "== bpy 5.0: all tests"
.venv/bin/python -m pytest -q -p no:cacheprovider tests "$@"
