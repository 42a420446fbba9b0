"""Build the starter knowledge bases shipped with the extension (sample_scenes/*_kb.npz).

CMU motion only (free to redistribute; HDM05 is CC BY-SA and stays out of the product):
- cmu_daz43_kb.npz: every Daz-friendly BVH take of ../shared/data at 15 fps (43 joints), with
  each bone's rotation (the armature fill's ``match``);
- cmu_markers41_kb.npz: the CMU C3D takes at 30 fps (the 41-marker set);
- cmu_asf31_kb.npz: the CMU ASF/AMC takes at 30 fps (the CMU ASF skeleton, 31 joints), with
  each bone's rotation (armatures rest in the ASF's zero pose); not 02_01, which has no ASF of
  its own.
Poses (and rotations) are stored as float16, compressed (``KnowledgeBase.save(compact=True)``).

    python tools/build_starter_kbs.py [NAME ...]
"""

import os
import sys
from pathlib import Path

from mocap_gapfill.core.kb import STARTER_DIR, build_kb

DATA = Path(os.environ.get("MOCAP_GAPFILL_DATA",
                           Path(__file__).resolve().parents[2] / "shared" / "data"))
STARTERS = {"cmu_daz43_kb.npz": dict(sources=[DATA / "cmu/bvh/daz_friendly"], fps=15.0,
                                     skip_frames=6),
            "cmu_markers41_kb.npz": dict(sources=[DATA / "cmu/c3d"], fps=30.0, skip_frames=0),
            "cmu_asf31_kb.npz": dict(sources=[DATA / "cmu/asfamc"], fps=30.0, skip_frames=0,
                                     exclude=["*02_01.amc"])}


def main(names=()):
    for name, spec in STARTERS.items():
        if names and name not in names:
            continue
        kb = build_kb(spec["sources"], fps=spec["fps"], skip_frames=spec["skip_frames"],
                      exclude=spec.get("exclude", ()), report=print)
        path = kb.save(STARTER_DIR / name, overwrite=True, compact=True)
        print(f"{path}: {kb.size} poses of {len(kb.names)} points at {kb.fps:g} fps, "
              f"{path.stat().st_size / 1e6:.1f} MB")


if __name__ == "__main__":
    main(sys.argv[1:])
