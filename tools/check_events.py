"""Every event ``check`` reports on the real marker takes of ../shared/data as they are, with
what it is (docs/EVALUATION.md, "Label swaps, spikes and ghosts").

An event is called **real** where, during it, the marker's distance to its steadiest partner
(the marker on its own segment whose distance to it varies least over the take) leaves that
distance's usual range - its median +- 4 times its median absolute deviation and at least 10 mm
- on at least half of the event's frames, and the frames just around the event sit inside it;
else a **false alarm** (the partners' carry, not the marker, moved: a fast turn of a limb whose
partners sit across a joint). A swap is real where both of its markers leave their range.
Prints a Markdown table and the false alarms per 10,000 marker-frames.

Usage: OMP_NUM_THREADS=2 .venv/bin/python tools/check_events.py
"""

import os
from pathlib import Path

import numpy as np

from mocap_gapfill.core.faults import FaultConfig, find_faults, rigid_partners
from mocap_gapfill.core.io import read_motion

DATA = Path(os.environ.get("MOCAP_GAPFILL_DATA",
                           Path(__file__).resolve().parents[2] / "shared/data"))
TAKES = sorted((DATA / "cmu/c3d").glob("*.c3d")) + sorted((DATA / "hdm05/c3d").glob("*.c3d"))


def left_range(motion, partners, name, first, last):
    """Whether marker ``name`` leaves the usual range of its distance to its steadiest partner
    over ``first..last`` and is inside it just around."""
    p = motion.names.index(name)
    q = partners[0][p, 0]
    dist = np.linalg.norm(motion.positions[:, p] - motion.positions[:, q], axis=1)
    usual = np.nanmedian(dist)
    spread = max(4 * np.nanmedian(np.abs(dist - usual)), 0.01)
    with np.errstate(invalid="ignore"):
        out = np.abs(dist - usual) > spread
    around = np.r_[max(first - 3, 0):first, last + 1:min(last + 4, len(dist))]
    return bool(np.nanmean(out[first:last + 1]) >= 0.5 and not out[around].any())


def main():
    config = FaultConfig.fitted()
    rows, samples, false = [], 0, 0
    for path in TAKES:
        motion = read_motion(path)
        kept = [n for n, s in zip(motion.names, (~motion.missing).mean(axis=0)) if s > 0.5]
        motion = motion.select(kept)  # HDM05's unlabelled points are seen in a few frames
        samples += int((~motion.missing).sum())
        partners = rigid_partners(motion.positions, config)
        for fault in find_faults(motion, config).faults:
            real = all(left_range(motion, partners, n, fault.first, fault.last)
                       for n in fault.points)
            false += not real
            rows.append(f"| {path.name} | {fault.kind} | {' / '.join(fault.points)} | "
                        f"{fault.first}-{fault.last} | {'real' if real else 'false alarm'} |")
    print("| take | kind | markers | frames (from 0) | what it is |\n|---|---|---|---|---|")
    print("\n".join(rows))
    print(f"\n{len(rows)} events, {false} false alarms over {samples:,} marker-frames seen: "
          f"{1e4 * false / max(samples, 1):.2f} per 10,000")


if __name__ == "__main__":
    main()
