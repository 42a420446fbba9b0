"""What a whole limb gone for half the take gets from each fill `auto` weighs (issue 15's body
parts; docs/DESIGN.md): the `bodyparts` protocol on the twelve Daz tuning takes
of ``tools/lost_gaps.py`` (never a test take; each subject out of a knowledge base that holds no
test take), filled by `auto`, `knn`, the studio fills `rigid` and `pattern`, and alone by the
take's own regression (`regression.regress_points`) and the knowledge base's windows of motion
(`matching.fill_match`), with their even blends; RMSE over the missing samples, one line per
take-part.

    python tools/part_fills.py OUT.jsonl [TAKES]   # run (TAKES: 01_08,02_05 - only those)
    python tools/part_fills.py --score OUT.jsonl   # each fill against `auto` and the best
                                                   # studio fill, and per part as EVALUATION.md
"""

import json
import sys
from collections import defaultdict

import numpy as np

from lost_gaps import DAZ_TUNING
from mocap_gapfill.core.evaluate import (complete_take, kb_without, punch_gaps, rmse_mm,
                                         settings_of, subject_of, with_gaps)
from mocap_gapfill.core.fill import fill
from mocap_gapfill.core.io import read_motion
from mocap_gapfill.core.kb import build_kb
from mocap_gapfill.core.matching import fill_match
from mocap_gapfill.core.regression import regress_points
from tune_bones import DAZ
from tune_default import TEST_TAKES

FILLS = ("auto", "knn", "rigid", "pattern")
BLENDS = {"knn+regress": ("knn", "regress"), "knn+match": ("knn", "match"),
          "regress+match": ("regress", "match"), "knn+regress+match": ("knn", "regress", "match"),
          "auto+regress+match": ("auto", "regress", "match"),
          "auto+auto+regress+match": ("auto", "auto", "regress", "match")}


def run(out, takes=None):
    full = build_kb([DAZ], fps=60.0, skip_frames=6, exclude=[f"*{t}.bvh*" for t in TEST_TAKES])
    with open(out, "w") as sink:
        for take in takes.split(",") if takes else DAZ_TUNING:
            path = DAZ / take[:2] / f"{take}.bvh.gz"
            truth = complete_take(read_motion(path, skip_frames=6), full.names, 60.0)
            kb = kb_without(full, subject_of(path))
            for label, part in settings_of("bodyparts"):
                rng = np.random.default_rng([0, *label.encode()])
                miss = punch_gaps(truth.n_frames, truth.n_points, "bodyparts", part, rng,
                                  truth.names)
                query = with_gaps(truth, miss)
                fills = {name: fill(query, name, kb=kb).positions for name in FILLS}
                fills["regress"] = regress_points(query.positions, query.names)
                fills["match"] = fill_match(query, kb, miss.any(axis=0)).positions
                # where the take's own fills leave a gap open, the knowledge base's models
                fills = {name: np.where(np.isnan(f), fills["knn"], f) for name, f in fills.items()}
                fills.update({name: np.mean([fills[f] for f in parts], axis=0)
                              for name, parts in BLENDS.items()})
                mm = {name: rmse_mm(truth.replace(positions=f), truth, miss)
                      for name, f in fills.items()}
                sink.write(json.dumps({"take": take, "part": label, **mm}) + "\n")
                print(take, label, f"auto {mm['auto']:.1f} mm", flush=True)


def score(path):
    rows = [json.loads(line) for line in open(path)]
    best = np.array([min(r["rigid"], r["pattern"]) for r in rows])
    print(f"{len(rows)} take-parts; geometric means")
    for name in ("auto", "knn", "regress", "match", *BLENDS):
        of_auto = np.log([r[name] / r["auto"] for r in rows])
        print(f"{name:18s} / auto {np.exp(of_auto.mean()):.3f} (worst {np.exp(of_auto.max()):.2f}, "
              f"{int((of_auto > np.log(1.02)).sum())} worse by 2 %), / best studio fill "
              f"{np.exp(np.mean(np.log([r[name] for r in rows] / best))):.3f}")
    by_part = defaultdict(list)
    for r in rows:
        by_part[r["part"]].append(r)
    print("per part, mean over takes / the best studio fill's mean (as docs/EVALUATION.md):")
    for part, group in sorted(by_part.items()):
        def mean(name):
            return np.mean([r[name] for r in group])
        each = [r["auto"] / min(r["rigid"], r["pattern"]) for r in group]
        print(f"  {part:16s} auto {mean('auto') / min(mean('rigid'), mean('pattern')):.2f} "
              f"(per take {min(each):.2f}-{max(each):.2f}), regress+match "
              f"{mean('regress+match') / min(mean('rigid'), mean('pattern')):.2f}")


if __name__ == "__main__":
    if sys.argv[1] == "--score":
        score(sys.argv[2])
    else:
        run(*sys.argv[1:3])
