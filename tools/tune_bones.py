"""Leave-one-subject-out runs for choosing the armature fill's default (issue 14): every
candidate of ``bonefill.CANDIDATES`` on the bones protocol's gaps and on the gaps' copies (what
``auto`` sees), on Daz-friendly takes that are NOT test takes of docs/EVALUATION.md, the take's
subject out of the knowledge base (which holds no test take either). Writes one npz per take
and setting (squared joint errors per gap and per copy, per candidate, and each candidate's squared
deviation from ``interp``, ``*_dev``) for the selection rules
to be compared offline (docs/DESIGN.md). Where ``match`` and ``hermite`` are among the
candidates, blends of ``interp`` and ``hermite`` towards ``match`` are saved too
(``interp_m0.25`` ... ``hermite_m1.0``: that share of the way to ``match``), and how far
``match`` and ``hermite`` disagree (``*_match_hermite_dev``, squared joint distance).

    python tools/tune_bones.py OUTDIR [candidate ...]
    MOCAP_GAPFILL_TUNE_TAKES=01_08,02_05,... python tools/tune_bones.py OUTDIR [candidate ...]
    MOCAP_GAPFILL_TUNE_AMC=1 python tools/tune_bones.py OUTDIR [candidate ...]

The last: the CMU ASF/AMC takes that are not test takes (07_05, 09_06 and four of the
unverified ones), against a KB of cmu/asfamc without the test takes (a second skeleton).

(01_08, 02_05, 03_02, 05_10, 06_03, 07_05, 08_02, 09_05, 10_03, 11_01, 12_03, 13_10
with the candidates interp hermite match.)
"""

import os
import sys
from pathlib import Path

import numpy as np

from mocap_gapfill.core.bonefill import CANDIDATES, BoneConfig, _Job, gap_copies, halfway
from mocap_gapfill.core.evaluate import (PROTOCOLS, kb_without, punch_bone_gaps,
                                         subject_of)
from mocap_gapfill.core.io import read_rig_take
from mocap_gapfill.core.kb import build_kb, load_kb
from mocap_gapfill.core.motion import gap_runs
from mocap_gapfill.core.rig import basis_matrices, interpolate_channels

DATA = Path(os.environ.get("MOCAP_GAPFILL_DATA",
                           Path(__file__).resolve().parents[2] / "shared" / "data"))
DAZ = DATA / "cmu/bvh/daz_friendly"
TEST_TAKES = ["01_01", "02_02", "05_02", "06_10", "09_12", "10_01", "12_02", "13_30"]
TUNING = ["03/03_02", "07/07_05", "08/08_02", "11/11_01"]
AMC = DATA / "cmu/asfamc"
AMC_TEST_TAKES = ["01_01", "11_01", "131_04", "135_06", "02_01"]  # 02_01: no ASF of its own
AMC_TUNING = ["07/07_05", "09/09_06", "_unverified/charleston/charleston1",
              "_unverified/lambada/lambada", "_unverified/pirouette/pirouette",
              "_unverified/zombie/zombie"]
SHARES = (0.25, 0.5, 0.75, 1.0)


def quiet_job(rig, fps, kb):
    """A fill job as ``fill_bones`` makes one, that reports nothing: for the candidates only
    ``auto`` makes (``_Job.candidates``)."""
    return _Job(rig, fps, kb, rig.roots, np.eye(4), None, lambda fraction, message: None, None,
                lambda message: None)


def armature_kb(amc):
    """The knowledge base the armature tuning tools fill from: every CMU ASF/AMC take
    (``amc``) or every Daz-friendly take at 60 poses a second, the test takes out."""
    if amc:
        return build_kb([AMC], fps=60.0, exclude=[f"*{t}.amc" for t in AMC_TEST_TAKES])
    return build_kb([DAZ], fps=60.0, skip_frames=6, exclude=[f"*{t}.bvh*" for t in TEST_TAKES])


def main(out, names=CANDIDATES):
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    amc = bool(os.environ.get("MOCAP_GAPFILL_TUNE_AMC"))
    cache = out / ("kb_amc.npz" if amc else "kb.npz")  # one OUTDIR may hold runs of both
    skip = 0 if amc else 6
    if cache.is_file():
        full = load_kb(cache)
    else:
        full = armature_kb(amc)
        full.save(cache)
    takes = os.environ.get("MOCAP_GAPFILL_TUNE_TAKES")
    takes = [f"{t[:2]}/{t}" for t in takes.split(",")] if takes else AMC_TUNING if amc else TUNING
    for take in takes:
        path = AMC / f"{take}.amc" if amc else DAZ / f"{take}.bvh.gz"
        rig, channels, location, fps = read_rig_take(path, skip_frames=skip)
        kb = kb_without(full, subject_of(path))
        if "charleston" in take:  # the two charleston takes are one (unknown) subject
            kb = kb.subset(np.array(["charleston" not in s for s in kb.sources])[kb.source_index])
        truth = rig.joints(basis_matrices(rig, channels, location))
        for n, l in PROTOCOLS.bones:
            label = f"n={n},l={l}"
            gaps = punch_bone_gaps(rig, len(channels), (n, l))
            seen = interpolate_channels(channels, gaps)
            job = quiet_job(rig, fps, kb)
            copies = gap_copies(gaps, BoneConfig.auto_copies, BoneConfig.copy_margin)
            probe = np.zeros_like(gaps)
            for _, b, start, length in copies:
                probe[start:start + length, b] = True
            runs = gap_runs(gaps)
            saved = {"owner": np.array([c[0] for c in copies], int),
                     "copy_len": np.array([c[3] for c in copies], int),
                     "copy_joints": np.array([job.below[c[1]].sum() for c in copies], int),
                     "gap_len": np.array([e - a + 1 for _, a, e in runs], int),
                     "gap_joints": np.array([job.below[b].sum() for b, _, _ in runs], int)}
            base = basis_matrices(rig, seen, location)
            on_copies = job.candidates(interpolate_channels(seen, probe), location,
                                       gaps | probe, names, base)
            on_gaps = job.candidates(seen, location, gaps, names, base)
            listed = [(i, b, a, e - a + 1) for i, (b, a, e) in enumerate(runs)]
            for where, made, mask, where_copies in (("copy", on_copies, gaps | probe, copies),
                                                    ("gap", on_gaps, gaps, listed)):
                shown = job.world(made["interp"])
                for name in names:
                    saved[f"{where}_{name}"] = job._errors(made[name], truth, where_copies)
                    # how far the candidate moves the joints from what Blender shows: known
                    # when filling, unlike the error
                    saved[f"{where}_{name}_dev"] = job._errors(made[name], shown, where_copies)
                if {"match", "hermite"} <= set(made):
                    # how far the two candidates disagree (known when filling)
                    saved[f"{where}_match_hermite_dev"] = job._errors(
                        made["match"], job.world(made["hermite"]), where_copies)
                    for base in ("interp", "hermite"):
                        for share in SHARES:
                            saved[f"{where}_{base}_m{share}"] = job._errors(
                                halfway(made[base], made["match"], mask, share), truth,
                                where_copies)
            np.savez(out / f"{Path(take).name}_{label}.npz", **saved)
            print(take, label, {k: round(float(np.sqrt(v.sum() / max(1, (saved["gap_len"] * saved["gap_joints"]).sum())) * 1000), 1)
                                for k, v in saved.items() if k.startswith("gap_") and k not in ("gap_len", "gap_joints")},
                  flush=True)


if __name__ == "__main__":
    main(sys.argv[1], tuple(sys.argv[2:]) or CANDIDATES)
