"""``mocap-gapfill bench``: where the time goes, per stage and backend (medians and ratios).

Stages (``--json`` rows: stage, backend, kb_size, queries, k, median_s, peak_mb):

- ``search``: exact masked K-NN of ``queries`` frames (6 of the points hidden per frame) in a
  knowledge base of ``kb_size`` poses: numpy blocked GEMM, torch (CPU, CUDA), and scipy's
  cKDTree (given one mask for all queries, so one tree serves; its build time is not counted;
  knowledge bases up to 65,536 poses);
- ``model``: the local PCA of every frame's K neighbours and the closed-form fit;
- ``fill``: the whole knn fill of a ``queries``-frame clip, 6 joints missing per 120 frames.

Poses are real (the Daz-friendly BVH of ../shared/data, every subject but 13, whose take 13_30
gives the queries); sizes beyond what the data holds are drawn with replacement plus 1 mm of
noise. Without the data the synthetic walker stands in. Peak memory: the tracemalloc peak of
the case (numpy and scipy buffers; torch's own CPU allocations are not seen, CUDA's are).
The GEMM line gives the machine's float32 matrix-multiply speed and the time the search's FLOP
count predicts at it.
"""

import os
import platform
import statistics
import time
import tracemalloc
from pathlib import Path

import numpy as np

from .backend import resolve


SEARCH_SIZES = (16384, 65536, 262144)
QUERY_SIZES = (1024, 2048, 4096)
KS = (64, 256)
HIDDEN = 6


def machine():
    info = {"cpu": platform.processor() or platform.machine(), "cores": os.cpu_count(),
            "threads": os.environ.get("OMP_NUM_THREADS"), "python": platform.python_version(),
            "numpy": np.__version__, "openblas_coretype": os.environ.get("OPENBLAS_CORETYPE")}
    try:
        import torch

        info["torch"] = torch.__version__
        info["torch_threads"] = torch.get_num_threads()
        if torch.cuda.is_available():
            info["gpu"] = torch.cuda.get_device_name(0)
    except ImportError:
        info["torch"] = None
    return info


def backends():
    names = ["numpy"]
    try:
        import torch

        names.append("cpu")
        if torch.cuda.is_available():
            names.append("cuda")
    except ImportError:
        pass
    return names


def load_poses(data, report):
    """(kb poses, query take) normalised; real Daz poses when the data is there."""
    from .kb import build_kb, kb_from_motions

    daz = Path(data) / "cmu" / "bvh" / "daz_friendly"
    if daz.is_dir():
        kb = build_kb([daz], skip_frames=6, exclude=["*/13/*"])
        take = build_kb([daz / "13" / "13_30.bvh.gz"], skip_frames=6)
        report(f"poses: {kb.size} Daz-friendly BVH poses ({len(kb.names)} joints, 120 fps), "
               f"queries from 13_30")
        return kb.poses, take.poses, kb.names
    from . import synth

    motions = [synth.take(g, frames=4000, fps=120.0, phase=i)[0]
               for i, g in enumerate(synth.KB_GAITS)]
    report("poses: synthetic walker (../shared/data not found)")
    kb = kb_from_motions(motions)
    return kb.poses, kb_from_motions([synth.take(frames=4096, fps=120.0)[0]]).poses, kb.names


def sized(poses, n, rng):
    if n <= len(poses):
        return poses[rng.choice(len(poses), n, replace=False)]
    pick = poses[rng.choice(len(poses), n, replace=True)]
    return (pick + rng.normal(scale=0.001, size=pick.shape)).astype(np.float32)


def timed(func, repeat):
    times, peaks = [], []
    for _ in range(repeat):
        tracemalloc.start()
        start = time.perf_counter()
        func()
        times.append(time.perf_counter() - start)
        peaks.append(tracemalloc.get_traced_memory()[1] / 2**20)
        tracemalloc.stop()
    return statistics.median(times), max(peaks)


def gemm_gflops(device, inner, repeat=3):
    """float32 GEMM speed of a backend on the search's shape (2048 x inner x 65536)."""
    a = np.random.default_rng(0).standard_normal((2048, inner)).astype(np.float32)
    b = np.random.default_rng(1).standard_normal((inner, 65536)).astype(np.float32)
    if device == "numpy":
        seconds, _ = timed(lambda: a @ b, repeat)
    else:
        import torch

        ta, tb = torch.as_tensor(a, device=device), torch.as_tensor(b, device=device)

        def product():
            ta @ tb
            if device == "cuda":
                torch.cuda.synchronize()

        product()
        seconds, _ = timed(product, repeat)
    return 2 * a.shape[0] * a.shape[1] * b.shape[1] / seconds / 1e9


def run(quick=False, repeat=3, data=None, report=print, progress=None):
    """Run the suite; returns ``{"machine": ..., "results": [...]}``."""
    from .search import KBIndex

    data = data or os.environ.get("MOCAP_GAPFILL_DATA",
                                  Path(__file__).resolve().parents[2] / "shared" / "data")
    rng = np.random.default_rng(0)
    base, take, names = load_poses(data, report)
    points = base.shape[1]
    sizes = (65536,) if quick else SEARCH_SIZES
    queries_list = (2048,) if quick else QUERY_SIZES
    results = []
    inner = 4 * points  # [-2q, mask] x [k, |k_i|^2]
    gflops = {}
    for device in backends():
        name = resolve(device).name
        gflops[name] = gemm_gflops(device, inner)
        report(f"float32 GEMM {name} (2048 x {inner} x 65536): {gflops[name]:.0f} GFLOP/s")

    def add(stage, backend, kb_size, queries, k, median, peak):
        results.append({"stage": stage, "backend": backend, "kb_size": kb_size,
                        "queries": queries, "k": k, "median_s": median, "peak_mb": peak})
        report(f"  {stage:6s} {backend:10s} kb {kb_size:6d}  q {queries:4d}  K {k:3d}  "
               f"{1000 * median:9.1f} ms  peak {peak:7.1f} MB")

    for size in sizes:
        poses = sized(base, size, rng)
        indexes = {name: KBIndex(poses, name) for name in backends()}
        for nq in queries_list:
            q = take[rng.choice(len(take), nq, replace=nq > len(take))].astype(np.float64)
            present = np.ones((nq, points), bool)
            present[:, rng.choice(points, HIDDEN, replace=False)] = False  # one mask: cKDTree
            flops = 2 * nq * inner * size
            report(f"search: {nq} queries x {size} poses; GEMM {flops / 1e9:.1f} GFLOP = "
                   + ", ".join(f"{1000 * flops / g / 1e9:.0f} ms {n}" for n, g in gflops.items())
                   + " at the measured speeds")
            for k in KS:
                for name, index in indexes.items():
                    median, peak = timed(lambda: index.search(q, present, k, ordered=False),
                                         repeat)
                    add("search", index.backend.name, size, nq, k, median, peak)
                if size <= 65536:  # beyond, one case takes minutes
                    median, peak = _ckdtree(poses, q, present, k, repeat)
                    add("search", "ckdtree", size, nq, k, median, peak)
    _model_and_fill(base, take, names, rng, quick, repeat, add)
    _summary(results, report, gflops, inner)
    return {"machine": {**machine(), "gemm_gflops": gflops}, "results": results}


def _ckdtree(poses, q, present, k, repeat):
    from scipy.spatial import cKDTree

    cols = np.repeat(present[0], 3)
    tree = cKDTree(poses.reshape(len(poses), -1)[:, cols].astype(np.float64))
    flat = q.reshape(len(q), -1)[:, cols]
    return timed(lambda: tree.query(flat, k=k, workers=-1), max(1, repeat // 2))


def _model_and_fill(base, take, names, rng, quick, repeat, add):
    from .evaluate import punch_gaps
    from .fill import fill
    from .kb import KnowledgeBase
    from .motion import Motion
    from .energy import closed_form, normal_equations
    from .models import KnnSettings, local_pca
    from .search import KBIndex

    frames_list = (2048,) if quick else (512, 2048)
    sizes = (65536,) if quick else (16384, 65536)
    q = take[:2048].astype(np.float64)
    present = np.ones(q.shape[:2], bool)
    present[:, :HIDDEN] = False
    for size in sizes:
        poses = sized(base, size, rng)
        kb = KnowledgeBase(poses, names, 120.0, np.zeros((0, 2), int), ("bench",),
                           np.zeros(size, np.int32))
        for device in backends():
            index = KBIndex(poses, device)
            for k in KS:
                idx, _ = index.search(q, present, k, ordered=False)
                settings = KnnSettings(k=k)

                def model():  # gathers the neighbours as a fill does (centred in place)
                    neighbours = poses.reshape(size, -1)[idx]
                    mean, comps, lams, noise = local_pca(neighbours, settings, rng,
                                                          index.backend)
                    closed_form(normal_equations(~present, q, mean, comps), lams, noise,
                                 settings)

                median, peak = timed(model, repeat)
                add("model", index.backend.name, size, len(q), k, median, peak)
            for frames in frames_list:
                clip = take[np.arange(frames) % len(take)].astype(np.float64)
                miss = punch_gaps(frames, clip.shape[1], "joints", (HIDDEN, 120),
                                  np.random.default_rng(0))
                motion = Motion(np.where(miss[..., None], np.nan, clip), names, 120.0)
                for k in KS:
                    settings = KnnSettings(k=k, device=device)
                    median, peak = timed(lambda: fill(motion, "knn", kb=kb, settings=settings),
                                         max(1, repeat // 2))
                    add("fill", index.backend.name, size, frames, k, median, peak)


def _summary(results, report, gflops, inner):
    """Ratios: each backend's search against numpy's, and against its GEMM-predicted time."""
    by = {(r["stage"], r["backend"], r["kb_size"], r["queries"], r["k"]): r["median_s"]
          for r in results}
    report("ratios (search): numpy time / this backend's; this backend's time / the time its "
           "GEMM speed predicts")
    for (stage, backend, size, nq, k), median in sorted(by.items()):
        if stage != "search":
            continue
        vs = by.get((stage, "numpy", size, nq, k), np.nan) / median
        line = f"  {backend:10s} kb {size:6d} q {nq:4d} K {k:3d}: {vs:6.2f} x numpy"
        if backend in gflops:
            line += f", {median / (2 * nq * inner * size / gflops[backend] / 1e9):5.2f} x GEMM"
        report(line)
