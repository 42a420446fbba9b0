"""Batch throughput benchmark (issue 17): prints takes per minute and ratios (not a test).

Library: 48 C3D takes of 240 frames cut from Daz-friendly BVH takes of subject 02 (joint
positions written as C3D points), 3 joints missing per 30 frames; knowledge base: every other
Daz-friendly subject at 120 fps (91k poses), resampled to the rate that makes at least
``--kb-poses`` (100k: 132 fps). Run with ``OMP_NUM_THREADS=1`` to compare
processes (by default each of N workers gets cores / N BLAS threads, so one worker already uses
every core for its products). The default method (``auto``) fills
the same library with ``--jobs 1`` and ``--jobs 2`` (local process pool), then through Ray and
Dask local clusters of 2 workers; each run writes into a fresh folder. Peak memory per worker
is the largest ``peak_mb`` of the run's report.

Usage: OMP_NUM_THREADS=1 .venv/bin/python tools/bench_batch.py [--takes 48] [--json OUT]
"""

import argparse
import json
import os
import tempfile
import time
from pathlib import Path

DATA = Path(os.environ.get("MOCAP_GAPFILL_DATA",
                           Path(__file__).resolve().parents[2] / "shared/data"))
DAZ = DATA / "cmu/bvh/daz_friendly"


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--takes", type=int, default=48)
    parser.add_argument("--json", help="write the figures as JSON")
    parser.add_argument("--kb-poses", type=int, default=100_000,
                        help="at least this many KB poses (the KB is resampled up to it)")
    parser.add_argument("--engines", nargs="+", default=["local", "ray", "dask"])
    args = parser.parse_args()
    from mocap_gapfill.__main__ import choose_blas_kernel

    choose_blas_kernel()
    import numpy as np

    from mocap_gapfill.core.batch import Options, run_batch
    from mocap_gapfill.core.evaluate import punch_gaps
    from mocap_gapfill.core.io import read_motion, write_motion
    from mocap_gapfill.core.kb import build_kb

    work = Path(tempfile.mkdtemp(prefix="bench_batch_"))
    (work / "library").mkdir()
    rng = np.random.default_rng(0)
    sources = sorted((DAZ / "02").glob("*.bvh.gz"))
    made = 0
    for path in sources:
        take = read_motion(path, skip_frames=6)
        for start in range(0, take.n_frames - 240, 240):
            part = take.frame_range(start, start + 240)
            miss = punch_gaps(240, part.n_points, "joints", (3, 30), rng)
            write_motion(part.replace(positions=np.where(miss[..., None], np.nan,
                                                         part.positions), filled=None),
                         work / "library" / f"{path.name[:5]}_{start:05d}.c3d")
            made += 1
            if made == args.takes:
                break
        if made == args.takes:
            break
    kb = build_kb([DAZ], fps=120, skip_frames=6, exclude=["*/02/*"])
    if kb.size < args.kb_poses:  # the memory bar is set at 100k poses: resampled up to it
        kb = build_kb([DAZ], fps=np.ceil(120 * args.kb_poses / kb.size), skip_frames=6,
                      exclude=["*/02/*"])
    kb.save(work / "kb.npz")
    print(f"library: {made} takes of 240 frames ({len(kb.names)} joints), KB {kb.size} poses "
          f"at {kb.fps:g} fps")
    options = Options(kb=str(work / "kb.npz"))
    runs = [(e, j) for e, j in [("local", 1), ("local", 2), ("ray", 2), ("dask", 2)]
            if e in args.engines]
    out = {"takes": made, "kb_poses": kb.size, "cores": os.cpu_count(),
           "omp_threads": os.environ.get("OMP_NUM_THREADS"), "runs": {}}
    for engine, jobs in runs:
        start = time.perf_counter()
        rows = run_batch([work / "library"], work / f"out_{engine}_{jobs}", options,
                         engine=engine, jobs=jobs)
        seconds = time.perf_counter() - start
        failed = [r for r in rows if r["status"] != "filled"]
        peak = max(float(r["peak_mb"]) for r in rows if r["peak_mb"] != "")
        label = f"{engine} --jobs {jobs}"
        out["runs"][label] = {"seconds": seconds, "takes_per_minute": 60 * made / seconds,
                              "peak_mb_per_worker": peak, "failed": len(failed)}
        print(f"{label:16s} {seconds:7.1f} s  {60 * made / seconds:6.1f} takes/min  "
              f"peak {peak:6.0f} MB per worker  {len(failed)} failed")
    rate = {k: v["takes_per_minute"] for k, v in out["runs"].items()}
    base = rate["local --jobs 2"]
    print(f"jobs 2 / jobs 1: {base / rate['local --jobs 1']:.2f}x (target >= 1.7x); "
          + ", ".join(f"{e} / local: {rate[f'{e} --jobs 2'] / base:.2f}" for e in ("ray", "dask")
                      if f"{e} --jobs 2" in rate) + " (target within 20 %)")
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
