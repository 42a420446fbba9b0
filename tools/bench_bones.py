"""Armature fill benchmark (issue 14): prints medians and a ratio (not a test).

A 3,000-frame take (CMU 13_18 boxing, Daz-friendly BVH, 120 fps, read as Blender's importer
builds it) with 10 bone gaps of 30-120 frames on limb and spine bones; knowledge base: every
other Daz-friendly subject at 60 fps (about 48k poses, with bone rotations). Times the default
fill (``auto``: copies of each gap refilled by ``match``, ``mix`` and ``stack``, then the chosen
one on the gaps), ``match``, ``regress`` and ``knn`` alone, with ``slerp`` in the same run as the
baseline (what interpolating costs) and ``bezier`` (Blender's curves through Bezier keys).

Usage: OMP_NUM_THREADS=2 .venv/bin/python tools/bench_bones.py [--repeat 3]
[--device auto|numpy|cpu|cuda]
"""

import argparse
import os
import statistics
import time
from pathlib import Path

from mocap_gapfill.__main__ import choose_blas_kernel

DATA = Path(os.environ.get("MOCAP_GAPFILL_DATA",
                           Path(__file__).resolve().parents[2] / "shared/data"))
DAZ = DATA / "cmu/bvh/daz_friendly"


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--device", default="auto", help="the search's and local models' "
                        "backend (auto, numpy, cpu, cuda)")
    args = parser.parse_args()
    choose_blas_kernel()
    import numpy as np

    from mocap_gapfill.core.bonefill import fill_bones
    from mocap_gapfill.core.evaluate import gappable_bones
    from mocap_gapfill.core.formats.bvh import read_bvh_rig
    from mocap_gapfill.core.kb import build_kb
    from mocap_gapfill.core.models import KnnSettings
    from mocap_gapfill.core.rig import interpolate_channels

    rig, channels, location, fps = read_bvh_rig(DAZ / "13/13_18.bvh.gz", skip_frames=1)
    kb = build_kb([DAZ], fps=60, skip_frames=6, exclude=["*/13/*"])
    rng = np.random.default_rng(0)
    gaps = np.zeros(channels.shape[:2], bool)
    bones = rng.choice(gappable_bones(rig), 10)
    for i, b in enumerate(bones):
        start = 150 + i * 280
        gaps[start:start + rng.integers(30, 121), b] = True
    seen = interpolate_channels(channels, gaps)
    print(f"take: {len(channels)} frames, {len(rig.names)} bones, {int(gaps.sum())} gap frames "
          f"on {len(bones)} gaps; KB {kb.size} poses; device {args.device}")
    times = {}
    for method in ("slerp", "bezier", "learn", "regress", "match", "knn", "auto"):
        runs = []
        for _ in range(args.repeat):
            start = time.perf_counter()
            fill_bones(rig, seen, location, gaps, fps, kb=kb, method=method,
                       settings=KnnSettings(device=args.device))
            runs.append(time.perf_counter() - start)
        times[method] = statistics.median(runs)
        print(f"{method:6s} median {times[method]:7.3f} s over {args.repeat} runs "
              f"({', '.join(f'{r:.2f}' for r in runs)})")
    print(f"auto / match: {times['auto'] / times['match']:.2f}x; bezier / slerp: "
          f"{times['bezier'] / times['slerp']:.2f}x; target: auto < 10 s")


if __name__ == "__main__":
    main()
