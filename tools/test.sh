#!/usr/bin/env bash
# The test command: set up (idempotent), then run the add-on tests on bpy 4.2 LTS (Python 3.11)
# and the whole suite on bpy 5.2 (Python 3.13, numpy 2; numpy backend) and bpy 5.0 (Python 3.11,
# numpy 1, torch 2.13.0 CPU, ray, dask: the torch backend and the torch/numpy parity tests, the
# batch command's cluster engines).
# Two lanes run side by side, one per core (every test pins its threads to one): bpy 4.2 then
# bpy 5.2 in one (lane_a), bpy 5.0 in the other (lane_b); their output is printed at the end.
# Data comes from ../shared/data (MOCAP_GAPFILL_DATA overrides).
set -euo pipefail
cd "$(dirname "$0")/.."
bash tools/setup.sh
export OMP_NUM_THREADS=1 MKL_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1
export MOCAP_GAPFILL_REQUIRE_DATA=1 MOCAP_GAPFILL_REQUIRE_BPY=1
logs=$(mktemp -d)
trap 'rm -rf "$logs"' EXIT

lane_a() {
  echo "== bpy 4.2 LTS (Python 3.11): add-on tests"
  .venv42/bin/python -m pytest -q -p no:cacheprovider tests/addon || return
  echo "== bpy 5.2 (Python 3.13): all tests"
  .venv52/bin/python -m pytest -q -p no:cacheprovider tests
}

lane_b() {
  echo "== bpy 5.0 (Python 3.11) with torch (CPU): all tests"
  MOCAP_GAPFILL_REQUIRE_TORCH=1 MOCAP_GAPFILL_REQUIRE_CLUSTER=1 \
    .venv/bin/python -m pytest -q -p no:cacheprovider tests "$@"
}

timed() {  # run a lane; its last line says how long it took
  local rc=0
  "$@" || rc=$?
  echo "-- $1 ended after $((SECONDS - start)) s, exit $rc"
  return "$rc"
}

start=$SECONDS
timed lane_a >"$logs/a" 2>&1 &
a=$!
timed lane_b "$@" >"$logs/b" 2>&1 &
b=$!
rc_a=0 rc_b=0
wait "$a" || rc_a=$?
cat "$logs/a"
wait "$b" || rc_b=$?
cat "$logs/b"
[ "$rc_a" = 0 ] && [ "$rc_b" = 0 ]
