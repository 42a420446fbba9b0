"""Leave-one-subject-out runs for choosing the default fill (issue 15): every candidate method on
the evaluation protocols' gaps and on their copies (``fill.validation_gaps``), on takes that are
NOT test takes of docs/EVALUATION.md, the take's subject out of the KB. Writes one npz per take
and setting (truth, gaps, copies, each candidate's fill of both) for the selection rules to be
compared offline (docs/DESIGN.md).

    python tools/tune_default.py markers OUTDIR
    python tools/tune_default.py joints OUTDIR
    python tools/tune_default.py joints OUTDIR auto    (refill one method into OUTDIR)
"""

import os
import sys
import time
from pathlib import Path

import numpy as np

from mocap_gapfill.core.evaluate import (complete_take, kb_without, punch_gaps, settings_of,
                                         subject_of, with_gaps)
from mocap_gapfill.core.fill import fill, validation_gaps
from mocap_gapfill.core.io import read_motion
from mocap_gapfill.core.kb import build_kb

DATA = Path(os.environ.get("MOCAP_GAPFILL_DATA",
                           Path(__file__).resolve().parents[2] / "shared" / "data"))
CANDIDATES = ("auto", "knn", "rigid", "pattern", "local-spline", "spline", "linear")
TEST_TAKES = ["01_01", "02_02", "05_02", "06_10", "09_12", "10_01", "12_02", "13_30"]
RUNS = {
    "markers": dict(fps=120.0, skip=0, kb=[DATA / "cmu/c3d"], exclude=["*85_02*"],
                    takes=[DATA / "cmu/c3d" / f"{t}.c3d" for t in
                           ("01_01", "02_05", "06_01", "135_02")]),
    "joints": dict(fps=60.0, skip=6, kb=[DATA / "cmu/bvh/daz_friendly"],
                   exclude=[f"*{t}.bvh*" for t in TEST_TAKES],
                   takes=[DATA / "cmu/bvh/daz_friendly" / t for t in
                          ("03/03_02.bvh.gz", "07/07_05.bvh.gz", "08/08_02.bvh.gz",
                           "11/11_01.bvh.gz")]),
}


def main(protocol, out, only=None):
    run = RUNS[protocol]
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    full = build_kb(run["kb"], fps=run["fps"], skip_frames=run["skip"], exclude=run["exclude"])
    for path in run["takes"]:
        truth = complete_take(read_motion(path, skip_frames=run["skip"]), full.names,
                              run["fps"])
        kb = kb_without(full, subject_of(path))
        for label, setting in settings_of(protocol):
            rng = np.random.default_rng([0, *label.encode()])
            miss = punch_gaps(truth.n_frames, truth.n_points, protocol, setting, rng, truth.names)
            probe = validation_gaps(miss)
            name = Path(path).name.split(".")[0]
            saved = {"truth": truth.positions, "miss": miss, "probe": probe}
            if only:  # refill one method into earlier results
                saved = dict(np.load(out / f"{name}_{label}.npz"))
            for method in [only] if only else CANDIDATES:
                for key, mask in (("gap", miss), ("copy", miss | probe))[:1 if method == "auto"
                                                                            else 2]:
                    start = time.perf_counter()
                    saved[f"{key}_{method}"] = fill(with_gaps(truth, mask), method,
                                                    kb=kb).positions
                    saved[f"seconds_{key}_{method}"] = time.perf_counter() - start
            np.savez_compressed(out / f"{name}_{label}.npz", **saved)
            print(name, label, flush=True)


if __name__ == "__main__":
    main(*sys.argv[1:4])
