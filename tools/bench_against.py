"""The default fill (``auto``) of this tree against another revision's, on the same takes, in one
run: medians and ratios (not a test). Needs ../shared/data and git.

- markers: the first 2,048 frames of CMU 135_02 (C3D, 41 markers, 30 % of them gone per 60
  frames), knowledge base: the other CMU C3D takes at 120 poses a second;
- armature: CMU 13_18 (Daz-friendly BVH, 3,000 frames) with 10 bone gaps of 30-120 frames,
  knowledge base: every other Daz-friendly subject at 60 poses a second (``bench_bones.py``'s
  case).

Each case runs in a fresh interpreter per revision, the revisions in turn (``--repeat`` rounds),
so both see the same machine; each process builds its knowledge base before the clock starts.
``check`` is the markers' RMSE over the gaps (mm) and, for the armature, the sum of the gap
frames' basis matrices (equal where the two revisions fill alike).

Usage: OMP_NUM_THREADS=1 .venv/bin/python tools/bench_against.py [--base 98446f6] [--repeat 3]
"""

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DATA = Path(os.environ.get("MOCAP_GAPFILL_DATA", ROOT.parent / "shared/data"))

CASE = r'''
import json, sys, time
from pathlib import Path
import numpy as np
DATA = Path(sys.argv[2])
if sys.argv[1] == "markers":
    from mocap_gapfill.core.evaluate import punch_gaps, rmse_mm, with_gaps
    from mocap_gapfill.core.fill import fill
    from mocap_gapfill.core.io import read_motion
    from mocap_gapfill.core.kb import build_kb
    kb = build_kb([DATA / "cmu/c3d"], fps=120.0, exclude=["*135_02*"])
    take = read_motion(DATA / "cmu/c3d/135_02.c3d").frame_range(0, 2048)
    take = take.select([n for n in take.names if n in kb.names])
    miss = punch_gaps(2048, take.n_points, "markers", 0.3, np.random.default_rng(0))
    start = time.perf_counter()
    out = fill(with_gaps(take, miss), "auto", kb=kb)
    seconds = time.perf_counter() - start
    error = rmse_mm(out, take, miss)
else:
    from mocap_gapfill.core.bonefill import fill_bones
    from mocap_gapfill.core.evaluate import gappable_bones
    from mocap_gapfill.core.formats.bvh import read_bvh_rig
    from mocap_gapfill.core.kb import build_kb
    from mocap_gapfill.core.rig import interpolate_channels
    daz = DATA / "cmu/bvh/daz_friendly"
    rig, channels, location, fps = read_bvh_rig(daz / "13/13_18.bvh.gz", skip_frames=1)
    kb = build_kb([daz], fps=60, skip_frames=6, exclude=["*/13/*"])
    rng = np.random.default_rng(0)
    gaps = np.zeros(channels.shape[:2], bool)
    for i, b in enumerate(rng.choice(gappable_bones(rig), 10)):
        gaps[150 + i * 280:150 + i * 280 + rng.integers(30, 121), b] = True
    seen = interpolate_channels(channels, gaps)
    start = time.perf_counter()
    out = fill_bones(rig, seen, location, gaps, fps, kb=kb, method="auto")
    seconds = time.perf_counter() - start
    error = float(np.abs(out[gaps]).sum())  # the same where the two fills are
print(json.dumps({"seconds": seconds, "error": error}))
'''


def worktree(revision, where):
    """A checkout of ``revision`` importable as ``mocap_gapfill`` from ``where``."""
    subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "-f", "--detach",
                    str(where / "mocap_gapfill"), revision], check=True, capture_output=True)
    return where


def timed(case, path, script):
    env = dict(os.environ, PYTHONPATH=str(path))
    out = subprocess.run([sys.executable, script, case, str(DATA)], env=env, cwd=path,
                         capture_output=True, text=True)
    if out.returncode:
        sys.exit(out.stderr)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--base", default="98446f6", help="the revision to compare with")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--cases", nargs="+", default=["markers", "armature"])
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        script = tmp / "case.py"
        script.write_text(CASE)
        here = tmp / "here"
        here.mkdir()
        (here / "mocap_gapfill").symlink_to(ROOT)
        trees = {args.base: worktree(args.base, tmp / "base"), "this tree": here}
        try:
            for case in args.cases:
                runs = {name: [] for name in trees}
                for _ in range(args.repeat):
                    for name, path in trees.items():
                        runs[name].append(timed(case, path, script))
                medians = {name: statistics.median(r["seconds"] for r in runs[name])
                           for name in trees}
                for name in trees:
                    spread = ", ".join(f"{r['seconds']:.2f}" for r in runs[name])
                    print(f"{case:8s} {name:10s} median {medians[name]:6.2f} s ({spread}); "
                          f"check {runs[name][-1]['error']:.6g}")
                print(f"{case:8s} this tree / {args.base}: "
                      f"{medians['this tree'] / medians[args.base]:.2f}x")
        finally:
            subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force",
                            str(tmp / "base" / "mocap_gapfill")], capture_output=True)


if __name__ == "__main__":
    main()
