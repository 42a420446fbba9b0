"""Load test: fill a 10-minute 120 fps take (72,000 frames, 41 markers, 20 % missing) with
bounded memory, and check that the result is the same as filling it in pieces.

    python tools/load_test.py [--data ../shared/data] [--minutes 10] [--json OUT]

The take is the CMU C3D files of ../shared/data end to end, repeated until it is long enough
(their 41 common markers); its gaps follow the markers protocol (20 % of the markers hidden,
drawn anew for every 60 frames). The knowledge base is the HDM05 C3D files (other subjects).
Printed: time, peak memory (tracemalloc: every numpy array; and the process's peak RSS), the
RMSE over the hidden samples against linear interpolation, and how the whole fill compares with
each of its pieces filled alone as a take of its own.
"""

import argparse
import json
import platform
import resource
import sys
import time
import tracemalloc
from dataclasses import replace
from pathlib import Path

import numpy as np

from mocap_gapfill.core.evaluate import punch_gaps, rmse_mm, with_gaps
from mocap_gapfill.core.fill import fill
from mocap_gapfill.core.io import read_motion
from mocap_gapfill.core.kb import build_kb
from mocap_gapfill.core.motion import Motion
from mocap_gapfill.core.recover import KnnSettings, fill_knn, pieces

ROOT = Path(__file__).resolve().parent.parent


def long_take(folder, frames):
    """The C3D files of ``folder`` end to end (their common markers), repeated to ``frames``."""
    takes = [read_motion(p) for p in sorted(Path(folder).glob("*.c3d"))]
    names = [n for n in takes[0].names if all(n in t.names for t in takes[1:])]
    parts = [t.select(names).positions for t in takes]
    reps = -(-frames // sum(len(p) for p in parts))
    positions = np.concatenate(parts * reps)[:frames]
    return Motion(positions=positions, names=tuple(names), fps=takes[0].fps,
                  limbs=takes[0].select(names).limbs, source=f"{len(takes)} CMU C3D files x{reps}")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=ROOT.parent / "shared" / "data")
    parser.add_argument("--minutes", type=float, default=10.0)
    parser.add_argument("--rate", type=float, default=0.2)
    parser.add_argument("--json", type=Path)
    args = parser.parse_args()

    kb = build_kb([args.data / "hdm05/c3d"])
    truth = long_take(args.data / "cmu/c3d", int(round(args.minutes * 60 * 120)))
    hidden = punch_gaps(truth.n_frames, truth.n_points, "markers", args.rate,
                        np.random.default_rng(0))
    take = with_gaps(truth, hidden)
    scored = hidden & ~truth.missing  # samples hidden by us whose truth is known
    settings = KnnSettings(device="numpy")
    print(f"take: {truth.n_frames} frames at {truth.fps:g} fps, {truth.n_points} markers, "
          f"{100 * take.missing.mean():.1f} % missing ({truth.source}); KB {kb.size} poses")

    def progress(fraction, message):
        step = int(fraction * 20)
        if step != progress.last:
            progress.last = step
            print(f"  {100 * fraction:5.1f} %  {time.time() - t0:7.1f} s  {message}", flush=True)
    progress.last = -1

    tracemalloc.start()
    t0 = time.time()
    whole = fill_knn(take, kb, settings, progress=progress)
    seconds = time.time() - t0
    peak_mb = tracemalloc.get_traced_memory()[1] / 2**20
    tracemalloc.stop()
    rss_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    linear = fill(take, "linear")
    result = {
        "machine": f"{platform.processor() or platform.machine()}, {platform.system()}, "
                   f"Python {sys.version.split()[0]}, numpy {np.__version__}",
        "frames": truth.n_frames, "points": truth.n_points, "fps": truth.fps,
        "missing_percent": round(100 * float(take.missing.mean()), 2), "kb_poses": kb.size,
        "seconds": round(seconds, 1), "peak_traced_mb": round(peak_mb, 1),
        "peak_rss_mb": round(rss_mb, 1),
        "rmse_missing_mm": {"knn": round(rmse_mm(whole, truth, scored), 2),
                            "linear": round(rmse_mm(linear, truth, scored), 2)},
        "unfilled": int((take.missing & np.isnan(whole.positions[..., 0])).sum()),
        "observed_changed": int((~take.missing
                                 & (whole.positions != take.positions).any(axis=2)).sum()),
    }
    print(json.dumps(result, indent=1))

    # the same take, piece by piece, each piece filled as a take of its own
    ranges = pieces(take.n_frames, settings.segment_frames, settings.segment_overlap)
    alone = replace(settings, segment_frames=take.n_frames)
    own_diff, fade_outside, prev = 0.0, 0, None
    for i, (a, b) in enumerate(ranges):
        part = fill_knn(take.frame_range(a, b), kb, alone).positions
        lo = ranges[i - 1][1] if i else a  # frames before lo are shared with the previous piece
        hi = ranges[i + 1][0] if i + 1 < len(ranges) else b
        own_diff = max(own_diff, float(np.nanmax(np.abs(part[lo - a:hi - a]
                                                        - whole.positions[lo:hi]))))
        if i:  # shared frames: the whole fill lies between the two pieces' fills
            mine, theirs = part[:lo - a], prev[a - ranges[i - 1][0]:]
            got = whole.positions[a:lo]
            low, high = np.fmin(mine, theirs) - 1e-9, np.fmax(mine, theirs) + 1e-9
            fade_outside += int(((got < low) | (got > high)).sum())
        prev = part
        print(f"  piece {i + 1}/{len(ranges)} frames {a}-{b - 1}: max difference so far "
              f"{1000 * own_diff:.6f} mm", flush=True)
    result["pieces"] = {"count": len(ranges), "frames": settings.segment_frames,
                        "overlap": settings.segment_overlap,
                        "max_difference_mm_outside_overlaps": own_diff * 1000,
                        "overlap_values_outside_the_two_fills": fade_outside}
    print(json.dumps(result["pieces"], indent=1))
    if args.json:
        args.json.write_text(json.dumps(result, indent=1) + "\n")


if __name__ == "__main__":
    main()
