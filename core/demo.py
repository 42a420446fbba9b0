"""``mocap-gapfill demo``: the main job on a built-in default.

1. Fill the real gaps of CMU take 01_01 (C3D, 2.4 % of samples missing) from a knowledge base of
   the other CMU C3D takes, and write the result.
2. Show the accuracy on known truth: punch 20 % gaps (60-frame intervals) into CMU 85_02 (jump
   turn, complete), fill them with every method, print RMSE against the original.
"""

import os
from pathlib import Path

import numpy as np

from .errors import GapFillError
from .evaluate import punch_gaps, rmse_mm, with_gaps
from .fill import fill
from .io import read_motion, write_motion
from .kb import build_kb

DEFAULT_DATA = Path(__file__).resolve().parents[2] / "shared" / "data"


def run_demo(outdir="out", data=None, progress=None, report=print):
    data = Path(data or os.environ.get("MOCAP_GAPFILL_DATA", DEFAULT_DATA))
    c3d = data / "cmu" / "c3d"
    if not (c3d / "01_01.c3d").is_file():
        raise GapFillError(f"the demo reads CMU C3D takes from {c3d}; set MOCAP_GAPFILL_DATA")
    outdir = Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    take = read_motion(c3d / "01_01.c3d")
    kb = build_kb([c3d / "85_02.c3d", c3d / "135_02.c3d"])
    report(f"knowledge base: {kb.size} poses of {len(kb.names)} markers from 85_02 and 135_02")
    report(f"01_01.c3d: {take.n_frames} frames, {100 * take.missing.mean():.2f} % missing "
           f"in {len(take.gap_runs())} gaps")
    filled = fill(take, "knn", kb=kb, progress=progress, report=report)
    out = write_motion(filled, outdir / "01_01_filled.c3d", overwrite=True)
    report(f"filled {int((take.missing & ~filled.missing).sum())} samples -> {out}")

    truth = read_motion(c3d / "85_02.c3d")
    truth = truth.replace(filled=None)
    kb2 = build_kb([c3d / "01_01.c3d", c3d / "135_02.c3d"])
    common = [n for n in truth.names if n in kb2.names]
    truth = truth.select(common)
    miss = punch_gaps(truth.n_frames, truth.n_points, "markers", 0.2, np.random.default_rng(0))
    query = with_gaps(truth, miss)
    report("85_02.c3d with 20 % of the markers removed per 60-frame interval "
           "(knowledge base: 01_01 + 135_02):")
    scores = {}
    for method in ("knn", "linear", "spline", "pca", "intercorrelation"):
        result = fill(query, method, kb=kb2)
        scores[method] = rmse_mm(result, truth, miss)
        report(f"  {method:17s} RMSE over missing markers {scores[method]:7.1f} mm")
        if method == "knn":
            write_motion(result, outdir / "85_02_punched_filled.c3d", overwrite=True)
    return scores
