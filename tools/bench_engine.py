"""Engine benchmark: prints medians and ratios (not a test). Needs ../shared/data.

1. Exact masked search: 2,048 query frames, 65,536-pose knowledge base, K = 256, our blocked
   GEMM search beside scipy's cKDTree on the same data (one mask for all queries, so cKDTree gets
   one tree over the present coordinates; its build time is reported apart).
2. Fill (knn, and the default auto) of a 2,048-frame clip (6 joints missing in every 120-frame interval) against a knowledge
   base of all Daz-friendly BVH motion (120 fps, the test take 13_30 left out): seconds and peak
   memory (max RSS of a fresh process for the stage).
3. Markers: ``auto`` on the first 2,048 frames of CMU 135_02 (C3D, 41 markers, 30 % of them gone
   per 60 frames) against the other CMU C3D takes, with the default marker settings (the
   rigid estimate reaching past the gap ends, partners alone within 20 mm) and the rigid estimate from
   the ends only, within 5 mm, in the same process.
4. Smooth track: ``auto`` on the same frames with bursts of 30 frames (50-100 % of the markers
   gone at once, once per 120 frames) and with dropouts of 6 frames (5 % of the samples), its
   smooth track the spline alone (``AutoConfig.learned`` = 0) and half of the way
   on to the take's own interpolator (the default), in the same process.

Usage: OMP_NUM_THREADS=2 .venv/bin/python tools/bench_engine.py [--repeat 3] [--json OUT]
[--device auto|numpy|cpu|cuda] [--skip-search]
"""

import argparse
import json
import os
import platform
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

from mocap_gapfill.__main__ import choose_blas_kernel

DATA = Path(os.environ.get("MOCAP_GAPFILL_DATA", Path(__file__).resolve().parents[2] / "shared/data"))
DAZ = DATA / "cmu/bvh/daz_friendly"


def stage_search(repeat):
    import numpy as np
    from scipy.spatial import cKDTree

    from mocap_gapfill.core.kb import build_kb
    from mocap_gapfill.core.search import KBIndex

    kb = build_kb([DAZ], skip_frames=6, exclude=["13_30.bvh.gz"])
    rng = np.random.default_rng(0)
    poses = kb.poses[rng.choice(kb.size, 65536, replace=False)]
    take = build_kb([DAZ / "13/13_30.bvh.gz"], skip_frames=6)  # normalised test poses
    queries = take.poses[:2048].astype(np.float64)
    present = np.ones((2048, poses.shape[1]), bool)
    present[:, rng.choice(poses.shape[1], 6, replace=False)] = False
    index = KBIndex(poses)
    ours = []
    for _ in range(repeat):
        t = time.perf_counter()
        index.search(queries, present, 256)
        ours.append(time.perf_counter() - t)
    cols = np.repeat(present[0], 3)
    data = poses.reshape(len(poses), -1)[:, cols].astype(np.float64)
    t = time.perf_counter()
    tree = cKDTree(data)
    build = time.perf_counter() - t
    kd = []
    for _ in range(max(1, repeat // 2)):
        t = time.perf_counter()
        tree.query(queries.reshape(2048, -1)[:, cols], k=256, workers=-1)
        kd.append(time.perf_counter() - t)
    return {"kb_size": len(poses), "queries": 2048, "k": 256, "dims": int(cols.sum()),
            "ours_median_s": statistics.median(ours), "ckdtree_query_median_s": statistics.median(kd),
            "ckdtree_build_s": build,
            "speedup_vs_ckdtree": statistics.median(kd) / statistics.median(ours)}


def stage_fill(repeat, k=None, device="auto", method="knn"):
    import numpy as np

    from mocap_gapfill.core.evaluate import punch_gaps, rmse_mm, with_gaps
    from mocap_gapfill.core.fill import fill
    from mocap_gapfill.core.io import read_motion
    from mocap_gapfill.core.kb import build_kb
    from mocap_gapfill.core.models import KnnSettings

    t = time.perf_counter()
    kb = build_kb([DAZ], skip_frames=6, exclude=["13_30.bvh.gz"])
    build = time.perf_counter() - t
    take = read_motion(DAZ / "13/13_30.bvh.gz", skip_frames=6).frame_range(0, 2048)
    miss = punch_gaps(2048, take.n_points, "joints", (6, 120), np.random.default_rng(0))
    query = with_gaps(take, miss)
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        out = fill(query, method, kb=kb, settings=KnnSettings(k=k, device=device))
        times.append(time.perf_counter() - t)
    return {"kb_size": kb.size, "frames": 2048, "fps": take.fps, "k": k or f"default ({KnnSettings.default_k})",
            "device": device, "method": method,
            "kb_build_s": build, "fill_median_s": statistics.median(times),
            "rmse_missing_mm": rmse_mm(out, take, miss)}


def _marker_case():
    """The marker stages' knowledge base (the CMU C3D takes but 135_02), take (135_02's first
    2,048 frames, the markers the knowledge base has) and the facts their results start with."""
    from mocap_gapfill.core.io import read_motion
    from mocap_gapfill.core.kb import build_kb

    kb = build_kb([DATA / "cmu/c3d"], fps=120.0, exclude=["*135_02*"])
    take = read_motion(DATA / "cmu/c3d/135_02.c3d").frame_range(0, 2048)
    take = take.select([n for n in take.names if n in kb.names])
    return kb, take, {"frames": 2048, "points": take.n_points, "kb_size": kb.size}


def _timed_auto(result, label, take, miss, kb, config=None):
    """``auto`` on ``take`` with ``miss`` gone (``config``: its AutoConfig): its seconds appended
    to ``result[label_s]``, its RMSE over the gaps in ``result[label_rmse_missing_mm]``."""
    from mocap_gapfill.core.evaluate import rmse_mm, with_gaps
    from mocap_gapfill.core.fill import fill

    t = time.perf_counter()
    out = fill(with_gaps(take, miss), "auto", kb=kb, config=config)
    result.setdefault(f"{label}_s", []).append(time.perf_counter() - t)
    result[f"{label}_rmse_missing_mm"] = rmse_mm(out, take, miss)


def _medians(result, labels):
    """Each ``label_s`` list of ``result`` as its median, ``label_median_s``."""
    for label in labels:
        result[f"{label}_median_s"] = statistics.median(result.pop(f"{label}_s"))


def stage_markers(repeat):
    import numpy as np

    from mocap_gapfill.core import fill as fills
    from mocap_gapfill.core.evaluate import punch_gaps

    kb, take, result = _marker_case()
    miss = punch_gaps(2048, take.n_points, "markers", 0.3, np.random.default_rng(0))
    # from the gap ends, partners alone within 5 mm; and the default
    then = fills.AutoConfig(reach=None, rigid_first_markers=fills.AutoConfig.rigid_first)
    for label, config in (("ends", then), ("reach", fills.AutoConfig())) * repeat:
        _timed_auto(result, label, take, miss, kb, config)
    _medians(result, ("ends", "reach"))
    return result


def stage_smooth(repeat):
    import numpy as np

    from mocap_gapfill.core import fill as fills
    from mocap_gapfill.core.evaluate import punch_gaps

    kb, take, result = _marker_case()
    for protocol, length in (("bursts", 30), ("shortgaps", 6)):
        miss = punch_gaps(2048, take.n_points, protocol, length, np.random.default_rng(0))
        for label, config in (("spline", fills.AutoConfig(learned=0.0)),
                              ("learned", fills.AutoConfig())) * repeat:
            _timed_auto(result, f"{protocol}_{label}", take, miss, kb, config)
        _medians(result, (f"{protocol}_spline", f"{protocol}_learned"))
    return result


def run_stage(name, repeat, device="auto"):
    """Run one stage in a fresh interpreter; its result plus that process's peak RSS."""
    proc = subprocess.run([sys.executable, __file__, "--stage", name, "--repeat", str(repeat),
                           "--device", device], capture_output=True, text=True)
    if proc.returncode:
        sys.exit(proc.stderr)
    return json.loads(proc.stdout.strip().splitlines()[-1])


def main():
    choose_blas_kernel()  # as the command line does; the stages inherit it
    parser = argparse.ArgumentParser()
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--stage", choices=["search", "fill", "fill256", "auto", "markers",
                                                 "smooth"])
    parser.add_argument("--json")
    parser.add_argument("--device", default="auto", help="the fill's (auto, numpy, cpu, cuda)")
    parser.add_argument("--skip-search", action="store_true")
    args = parser.parse_args()
    if args.stage:
        result = {"search": stage_search,
                  "fill": lambda r: stage_fill(r, device=args.device),
                  "fill256": lambda r: stage_fill(r, k=256, device=args.device),
                  "auto": lambda r: stage_fill(r, device=args.device, method="auto"),
                  "markers": stage_markers,
                  "smooth": stage_smooth,
                  }[args.stage](args.repeat)
        result["peak_rss_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
        print(json.dumps(result))
        return
    machine = {"cpu": platform.processor() or platform.machine(), "cores": os.cpu_count(),
               "threads": os.environ.get("OMP_NUM_THREADS"), "python": platform.python_version(),
               "openblas_coretype": os.environ.get("OPENBLAS_CORETYPE")}
    search = None
    if not args.skip_search:
        search = run_stage("search", args.repeat)
        print(f"search: {search['queries']} queries x {search['kb_size']} poses, K={search['k']}, "
              f"{search['dims']} dims")
        print(f"  ours (exact, blocked GEMM)  median {1000 * search['ours_median_s']:8.0f} ms")
        print(f"  scipy cKDTree query         median {1000 * search['ckdtree_query_median_s']:8.0f}"
              f" ms  (+ build {1000 * search['ckdtree_build_s']:.0f} ms)")
        print(f"  speed-up over cKDTree       {search['speedup_vs_ckdtree']:8.1f} x")
    fills = [run_stage("fill", args.repeat, args.device),
             run_stage("fill256", args.repeat, args.device),
             run_stage("auto", args.repeat, args.device)]
    print(f"fill: {fills[0]['frames']} frames at {fills[0]['fps']:g} fps, 6 joints missing per "
          f"120-frame interval, KB {fills[0]['kb_size']} poses (built in "
          f"{fills[0]['kb_build_s']:.1f} s; other takes of the test subject are in it)")
    for fill in fills:
        print(f"  {fill['method']} fill ({fill['device']}), K {fill['k']!s:14s} median {fill['fill_median_s']:6.2f} s, "
              f"peak RSS {fill['peak_rss_mb']:.0f} MB, RMSE missing {fill['rmse_missing_mm']:.1f} mm")
    markers = run_stage("markers", args.repeat)
    print(f"markers: auto on {markers['frames']} frames of 135_02, {markers['points']} markers, "
          f"30 % gone per 60 frames, KB {markers['kb_size']} poses")
    for label, what in (("ends", "rigid from the gap ends only"),
                        ("reach", "default (rigid past the ends)")):
        print(f"  {what:34s} median {markers[label + '_median_s']:6.2f} s, RMSE missing "
              f"{markers[label + '_rmse_missing_mm']:.1f} mm")
    print(f"  ratio {markers['reach_median_s'] / markers['ends_median_s']:.2f}")
    smooth = run_stage("smooth", args.repeat)
    print(f"smooth track: auto on the same {smooth['frames']} frames")
    for protocol, what in (("bursts", "bursts of 30 frames"),
                           ("shortgaps", "dropouts of 6 frames")):
        times = [smooth[f"{protocol}_{label}_median_s"] for label in ("spline", "learned")]
        errors = [smooth[f"{protocol}_{label}_rmse_missing_mm"] for label in ("spline", "learned")]
        print(f"  {what:21s} the spline alone {times[0]:6.2f} s ({errors[0]:.1f} mm), half on to "
              f"the learned one {times[1]:6.2f} s ({errors[1]:.1f} mm), ratio "
              f"{times[1] / times[0]:.2f}")
    if args.json:
        Path(args.json).write_text(json.dumps({"machine": machine, "search": search,
                                               "fill": fills, "markers": markers,
                                               "smooth": smooth}, indent=1))


if __name__ == "__main__":
    main()
