#!/usr/bin/env bash
# The test command: set up (idempotent), then run the add-on tests on bpy 4.2 LTS (Python 3.11)
# and the whole suite on bpy 5.2 (Python 3.13, numpy 2; numpy backend) and bpy 5.0 (Python 3.11,
# numpy 1, torch 2.13.0 CPU, ray, dask: the torch backend and the torch/numpy parity tests, the
# batch command's cluster engines).
# Data comes from ../shared/data (MOCAP_GAPFILL_DATA overrides).
set -euo pipefail
cd "$(dirname "$0")/.."
bash tools/setup.sh
export OMP_NUM_THREADS=1 MKL_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1
export MOCAP_GAPFILL_REQUIRE_DATA=1 MOCAP_GAPFILL_REQUIRE_BPY=1
echo "== bpy 4.2 LTS (Python 3.11): add-on tests"
.venv42/bin/python -m pytest -q -p no:cacheprovider tests/addon
echo "== bpy 5.2 (Python 3.13): all tests"
.venv52/bin/python -m pytest -q -p no:cacheprovider tests
echo "== bpy 5.0 (Python 3.11) with torch (CPU): all tests"
MOCAP_GAPFILL_REQUIRE_TORCH=1 MOCAP_GAPFILL_REQUIRE_CLUSTER=1 .venv/bin/python -m pytest -q -p no:cacheprovider tests "$@"
