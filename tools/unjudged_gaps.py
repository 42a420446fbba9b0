"""The armature default on long gaps that no copy judges (docs/DESIGN.md): the bones protocol's
take-settings at l >= 60 frames (seed 0) where no copy of any gap fits the take (``gap_copies``
empty), on every Daz take that is not a test take, or with
``AMC=1`` on the ASF/AMC tuning takes; each subject out of a knowledge base that holds no test
take (60 poses a second). ``auto`` filled with ``BoneConfig.unjudged_consensus`` set to SHARE
(0: ``match`` unjudged, as before; 1: the mean of ``match`` and ``regress_kernel``;
2: ``regress_kernel``); per take-setting the RMSE of ``auto`` and ``interp`` per gap.

    python tools/unjudged_gaps.py OUT.jsonl SHARE     # AMC=1: the ASF/AMC tuning takes
    python tools/unjudged_gaps.py --score BEFORE.jsonl AFTER.jsonl ...
"""

import json
import os
import sys
from collections import defaultdict

import numpy as np

from mocap_gapfill.core import bonefill
from mocap_gapfill.core.evaluate import (PROTOCOLS, bone_errors, kb_without,
                                         punch_bone_gaps, subject_of)
from mocap_gapfill.core.io import read_rig_take
from mocap_gapfill.core.rig import basis_matrices, interpolate_channels
from tune_bones import AMC, AMC_TUNING, DAZ, TEST_TAKES, armature_kb


def run(out, share):
    amc = bool(os.environ.get("AMC"))
    full = armature_kb(amc)
    paths = ([AMC / f"{t}.amc" for t in AMC_TUNING] if amc else
             [p for p in sorted(DAZ.glob("*/*.bvh.gz")) if p.name.split(".")[0] not in TEST_TAKES])
    with open(out, "w") as sink:
        for path in paths:
            rig, channels, location, fps = read_rig_take(path, skip_frames=0 if amc else 6)
            kb = kb_without(full, subject_of(path))
            truth = basis_matrices(rig, channels, location)
            for n, l in PROTOCOLS.bones:
                gaps = punch_bone_gaps(rig, len(channels), (n, l))
                if l < 60 or not gaps.any() or bonefill.gap_copies(
                        gaps, bonefill.BoneConfig.auto_copies, bonefill.BoneConfig.copy_margin):
                    continue
                seen = interpolate_channels(channels, gaps)
                row = {"take": path.name, "setting": f"n={n},l={l}"}
                for method in ("auto", "interp"):
                    basis = bonefill.fill_bones(rig, seen, location, gaps, fps, kb=kb,
                                                method=method, config=bonefill.BoneConfig(
                                                    unjudged_consensus=share))
                    errors = bone_errors(rig, basis, truth, gaps)
                    row[method] = {"mm": errors["rmse_missing_mm"], "gaps_mm": errors["gaps_mm"]}
                sink.write(json.dumps(row) + "\n")
                sink.flush()


def score(before, *afters):
    """Per setting ``auto`` / ``interp`` (ratio of the means over take-settings), new / old per
    take-setting (geometric mean, min-max), gaps better / worse by over 1 %, gaps lost (worse
    than ``interp`` by more than 10 % + 2 mm)."""
    def rows(path):
        return {(r["take"], r["setting"]): r for r in map(json.loads, open(path))}

    old = rows(before)
    for path in afters:
        new = rows(path)
        keys = sorted(set(old) & set(new))
        by, ratio, better, worse, lost = defaultdict(list), [], 0, 0, [0, 0]
        for key in keys:
            o, n, i = old[key]["auto"], new[key]["auto"], old[key]["interp"]
            by[key[1]].append((o["mm"], n["mm"], i["mm"]))
            ratio.append(n["mm"] / o["mm"])
            for a, b, c in zip(o["gaps_mm"], n["gaps_mm"], i["gaps_mm"]):
                better += b < 0.99 * a
                worse += b > 1.01 * a
                lost[0] += a > 1.1 * c + 2
                lost[1] += b > 1.1 * c + 2
        print(f"{path}: {len(keys)} take-settings, new / old {np.exp(np.mean(np.log(ratio))):.3f} "
              f"({min(ratio):.2f}-{max(ratio):.2f}); gaps better {better}, worse {worse}; "
              f"lost {lost[0]} -> {lost[1]}")
        for setting, values in sorted(by.items()):
            o, n, i = np.mean(values, axis=0)
            print(f"  {setting}: auto / interp {o / i:.3f} -> {n / i:.3f}")


if __name__ == "__main__":
    if sys.argv[1] == "--score":
        score(*sys.argv[2:])
    else:
        run(sys.argv[1], float(sys.argv[2]))
