#!/usr/bin/env bash
# GPU figures in one short run on a machine with a CUDA GPU (docs/BENCHMARKS.md): the torch-cuda
# parity tests, then the engine, armature and per-stage benchmarks with numpy and torch-cpu in
# the same run as the baselines. Every step has its own time limit; logs and JSON go to $OUT.
#   OUT=/tmp/gpu MOCAP_GAPFILL_DATA=../shared/data bash tools/gpu_bench.sh
# The machine needs python3 with numpy, scipy, torch (CUDA) and pytest; the data needs only
# MANIFEST.md and cmu/bvh/daz_friendly. Nothing is installed: the checkout is put on PYTHONPATH.
set -uo pipefail
cd "$(dirname "$0")/.."
: "${OUT:?set OUT to a folder for the logs}" "${MOCAP_GAPFILL_DATA:?set MOCAP_GAPFILL_DATA}"
PY=${PY:-python3}
pkg=$(mktemp -d)
ln -s "$PWD" "$pkg/mocap_gapfill"
export PYTHONPATH=$pkg PYTHONUNBUFFERED=1 MOCAP_GAPFILL_REQUIRE_TORCH=1
step() {  # step SECONDS LOG COMMAND...: run with a limit, keep the log, say how it ended
  local limit=$1 log=$OUT/$2 rc=0 t=$SECONDS
  shift 2
  echo "== $* (limit ${limit} s)" >>"$log"
  timeout "$limit" "$@" >>"$log" 2>&1 || rc=$?
  tail -n 25 "$log"
  echo "-- exit $rc after $((SECONDS - t)) s"
}
nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv | tee "$OUT/machine.txt"
$PY -c "import os, platform, numpy, scipy, torch; print(platform.python_version(), 'numpy', \
numpy.__version__, 'scipy', scipy.__version__, 'torch', torch.__version__, 'cuda', \
torch.cuda.is_available(), 'cores', os.cpu_count())" | tee -a "$OUT/machine.txt"
step 120 tests.log $PY -m pytest -q -p no:cacheprovider tests/test_backend.py -s
for device in cuda cpu; do
  for stage in fill auto; do
    step 90 engine.log $PY tools/bench_engine.py --stage "$stage" --device "$device" --repeat 3
  done
done
# the search benchmark (SEARCH=0 leaves it out where only the fills changed)
if [ "${SEARCH:-1}" = 1 ]; then
  step 240 bench.log $PY -m mocap_gapfill bench --quick --repeat 3 --json "$OUT/bench_quick.json"
fi
for device in cuda cpu; do
  step 120 bones.log $PY tools/bench_bones.py --repeat 2 --device "$device"
done
