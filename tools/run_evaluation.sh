#!/usr/bin/env bash
# The documented accuracy runs (docs/EVALUATION.md). Needs ../shared/data; takes tens of minutes
# on 2 cores. Writes docs/results/*.json and prints the tables.
set -euo pipefail
cd "$(dirname "$0")/.."
export MOCAP_GAPFILL_DATA=${MOCAP_GAPFILL_DATA:-../shared/data}  # the JSON names takes from here on
D=$MOCAP_GAPFILL_DATA
MG=".venv/bin/mocap-gapfill"
mkdir -p docs/results
export OMP_NUM_THREADS=2
DAZ="$D/cmu/bvh/daz_friendly"
# the Daz-friendly BVH test takes: eight takes of eight subjects
BVH43=("$DAZ"/01/01_01.bvh.gz "$DAZ"/05/05_02.bvh.gz "$DAZ"/06/06_10.bvh.gz
       "$DAZ"/09/09_12.bvh.gz "$DAZ"/10/10_01.bvh.gz "$DAZ"/12/12_02.bvh.gz
       "$DAZ"/13/13_30.bvh.gz "$DAZ"/02/02_02.bvh.gz)
$MG evaluate --protocol joints --quiet --skip-frames 6 --kb-sources "$DAZ" \
  --test "${BVH43[@]}" \
  --json docs/results/joints_bvh43.json
AMC="$D/cmu/asfamc"
AMC31=("$AMC"/01/01_01.amc "$AMC"/131/131_04.amc "$AMC"/135/135_06.amc "$AMC"/11/11_01.amc)
# three subjects of another lab (HDM05), each against a KB of the other two
HDM05=("$D"/hdm05/c3d/HDM_bd_05-01_01_120.c3d "$D"/hdm05/c3d/HDM_dg_06-03_03_120.c3d
       "$D"/hdm05/c3d/HDM_mm_01-02_03_120.c3d)
$MG evaluate --protocol joints --quiet --kb-sources "$AMC" --exclude-kb '*02_01.amc' \
  --test "${AMC31[@]}" \
  --json docs/results/joints_amc31.json
$MG evaluate --protocol markers --quiet --fps 120 --kb-sources "$D/cmu/c3d" \
  --test "$D/cmu/c3d/85_02.c3d" --json docs/results/markers_cmu_kb.json
# the gaps real captures have (01_01: RBAC's last 30 frames; 02_05: RSHN, 3 frames) on 85_02
$MG evaluate --protocol realgaps --quiet --fps 120 --kb-sources "$D/cmu/c3d" \
  --gap-sources "$D/cmu/c3d/01_01.c3d" "$D/cmu/c3d/02_05.c3d" \
  --test "$D/cmu/c3d/85_02.c3d" --json docs/results/realgaps_cmu_kb.json
# dropouts of 3-24 frames (the commonest gaps of real captures) on the same take and on the
# joints of the Daz test takes
$MG evaluate --protocol shortgaps --quiet --fps 120 --kb-sources "$D/cmu/c3d" \
  --test "$D/cmu/c3d/85_02.c3d" --json docs/results/shortgaps_cmu_kb.json
$MG evaluate --protocol shortgaps --quiet --skip-frames 6 --kb-sources "$DAZ" \
  --methods auto knn rigid pattern local-spline spline linear \
  --test "${BVH43[@]}" \
  --json docs/results/shortgaps_bvh43.json
# label swaps, spikes and ghosts injected into the marker test takes, found, repaired and filled
# (thresholds fitted on the tuning takes: tools/fit_faults.py)
$MG evaluate --protocol faults --quiet --fps 120 --kb-sources "$D/cmu/c3d" \
  --test "$D/cmu/c3d/85_02.c3d" --json docs/results/faults_cmu_kb.json
$MG evaluate --protocol faults --quiet --fps 120 --kb-sources "$D/hdm05/c3d" \
  --test "${HDM05[@]}" --json docs/results/faults_hdm05_subjects.json
# HDM05-derived numbers (CC BY-SA 3.0 data in the knowledge base)
$MG evaluate --protocol markers --quiet --fps 120 --kb-sources "$D/hdm05/c3d" \
  --test "$D/cmu/c3d/85_02.c3d" --json docs/results/markers_hdm05_kb.json
# other subjects of another lab: each HDM05 take against a KB of the other two (markers)
$MG evaluate --protocol markers --quiet --fps 120 --kb-sources "$D/hdm05/c3d" \
  --methods auto rigid pattern local-spline spline linear \
  --test "${HDM05[@]}" --json docs/results/markers_hdm05_subjects.json
$MG evaluate --protocol shortgaps --quiet --fps 120 --kb-sources "$D/hdm05/c3d" \
  --methods auto rigid pattern local-spline spline linear \
  --test "${HDM05[@]}" --json docs/results/shortgaps_hdm05_subjects.json
$MG evaluate --protocol bodyparts --quiet --skip-frames 6 --kb-sources "$DAZ" \
  --test "$DAZ"/05/05_02.bvh.gz "$DAZ"/13/13_30.bvh.gz "$DAZ"/09/09_12.bvh.gz \
  --json docs/results/bodyparts_bvh43.json
# armature rotation gaps at the takes' own rate (120 fps), KB at 60 fps
$MG evaluate --protocol bones --quiet --skip-frames 6 --kb-sources "$DAZ" \
  --test "${BVH43[@]}" \
  --json docs/results/bones_bvh43.json
$MG evaluate --protocol bones --quiet --kb-sources "$AMC" --exclude-kb '*02_01.amc' \
  --test "${AMC31[@]}" \
  --json docs/results/bones_amc31.json
# gaps at the clip's ends (a take that starts or stops with a broken bone or a marker not yet
# seen), where Blender and the interpolations hold the one key
$MG evaluate --protocol bone-ends --quiet --skip-frames 6 --kb-sources "$DAZ" \
  --methods auto interp regress match \
  --test "${BVH43[@]}" \
  --json docs/results/bone_ends_bvh43.json
$MG evaluate --protocol bone-ends --quiet --kb-sources "$AMC" --exclude-kb '*02_01.amc' \
  --methods auto interp regress match \
  --test "${AMC31[@]}" \
  --json docs/results/bone_ends_amc31.json
# an armature of another lab: HDM05's one ASF/AMC take (actor dg, 202 frames, a subject nothing
# was ever chosen on; CC BY-SA 3.0, evaluation only) against the CMU ASF/AMC knowledge base
HDM05_AMC="$D/hdm05/asfamc/HDM_dg_06-03_03_120.amc"
$MG evaluate --protocol bones --quiet --kb-sources "$AMC" --exclude-kb '*02_01.amc' \
  --methods auto interp bezier hermite slerp match regress learn \
  --test "$HDM05_AMC" --json docs/results/bones_hdm05.json
$MG evaluate --protocol bone-ends --quiet --kb-sources "$AMC" --exclude-kb '*02_01.amc' \
  --methods auto interp regress match \
  --test "$HDM05_AMC" --json docs/results/bone_ends_hdm05.json
$MG evaluate --protocol endgaps --quiet --fps 120 --kb-sources "$D/cmu/c3d" \
  --methods auto knn rigid pattern local-spline spline linear \
  --test "$D/cmu/c3d/85_02.c3d" --json docs/results/endgaps_cmu_kb.json
$MG evaluate --protocol endgaps --quiet --skip-frames 6 --kb-sources "$DAZ" \
  --methods auto knn rigid pattern local-spline spline linear \
  --test "${BVH43[@]}" \
  --json docs/results/endgaps_bvh43.json
# occlusions that take most of the body at once (50-100 % of the points for 3-60 frames per 120
# frames) on 85_02, on the HDM05 subjects (each against a KB of the other two), and without a KB
$MG evaluate --protocol bursts --quiet --fps 120 --kb-sources "$D/cmu/c3d" \
  --methods auto knn rigid pattern local-spline spline linear \
  --test "$D/cmu/c3d/85_02.c3d" --json docs/results/bursts_cmu_kb.json
$MG evaluate --protocol bursts --quiet --fps 120 --kb-sources "$D/hdm05/c3d" \
  --methods auto rigid pattern local-spline spline linear \
  --test "${HDM05[@]}" --json docs/results/bursts_hdm05_subjects.json
$MG evaluate --protocol bursts --quiet --fps 120 --no-kb --methods auto rigid pattern spline \
  --test "$D/cmu/c3d/85_02.c3d" "${HDM05[@]}" --json docs/results/bursts_no_kb.json
# the same gaps without a knowledge base (a rig no starter one fits): auto from the take alone
$MG evaluate --protocol bones --quiet --skip-frames 6 --no-kb --methods interp bezier auto \
  --test "${BVH43[@]}" \
  --json docs/results/bones_bvh43_no_kb.json
$MG evaluate --protocol bones --quiet --no-kb --methods interp bezier auto \
  --test "${AMC31[@]}" \
  --json docs/results/bones_amc31_no_kb.json
$MG evaluate --protocol joints --quiet --skip-frames 6 --no-kb --methods auto rigid pattern spline \
  --test "${BVH43[@]}" --json docs/results/joints_bvh43_no_kb.json
$MG evaluate --protocol joints --quiet --no-kb --methods auto rigid pattern spline \
  --test "${AMC31[@]}" --json docs/results/joints_amc31_no_kb.json
$MG evaluate --protocol markers --quiet --fps 120 --no-kb --methods auto rigid pattern \
  --test "$D"/cmu/c3d/85_02.c3d --json docs/results/markers_cmu_no_kb.json
$MG evaluate --protocol markers --quiet --fps 120 --no-kb --methods auto rigid pattern \
  --test "${HDM05[@]}" --json docs/results/markers_hdm05_no_kb.json
