"""Can copies of an armature's clip-end gaps choose their fill? (docs/DESIGN.md)

``auto`` judges a gap by copies of it placed where the bone is keyed, with keys at both ends.
A gap at a clip end has one key (Blender holds it), so those copies judge its fills against an
interpolation far stronger than the held key. Here each clip-end gap gets one-sided copies: the
take is cropped by ``k * (l + 10)`` frames (k = 1, 2, 3) on the gap's side, and the gap's bones
lose as many frames at the crop's end; every fill then fills the crop as it would the take. Per
gap, the errors of ``auto``, the held key (``interp``), ``match``, ``regress``, ``regress_kernel``
and their consensus (``cons``: the mean of ``match`` and ``regress_kernel``) on the real gap and
on each copy. The protocol is ``bone-ends`` on the tuning takes of ``tools/tune_bones.py``
(never a test take), each subject out of its knowledge base.

    python tools/end_copies.py OUT.jsonl            # run (Daz tuning takes; AMC=1: ASF/AMC;
                                                    # TAKES=07_05,...: only those)
    python tools/end_copies.py --score A.jsonl,B.jsonl
        # rule: a gap takes the fill with the least mean log ratio of its copies' squared
        # error to auto's, where that is below log(p), it has at least c copies and (guard q)
        # the fill beat the held key on every copy by q; grid and leave-one-subject-out
"""

import itertools
import json
import os
import sys
from collections import defaultdict

import numpy as np

from mocap_gapfill.core.bonefill import fill_bones, halfway
from mocap_gapfill.core.evaluate import (PROTOCOLS, bone_errors, kb_without, punch_bone_gaps,
                                         subject_of)
from mocap_gapfill.core.io import read_rig_take
from mocap_gapfill.core.motion import gap_runs
from mocap_gapfill.core.rig import basis_matrices, interpolate_channels
from lost_gaps import DAZ_TUNING
from tune_bones import AMC, AMC_TUNING, DAZ, armature_kb, quiet_job

FILLS = ("auto", "interp", "match", "regress", "regress_kernel", "cons")
COPIES, MARGIN = 3, 10
FLOOR = 1.0  # mm^2 added to each squared error before a ratio


def fills_of(rig, channels, location, gaps, fps, kb):
    """Basis matrices of each of :data:`FILLS` for the gaps (the truth in ``channels``)."""
    seen = interpolate_channels(channels, gaps)
    out = {m: fill_bones(rig, seen, location, gaps, fps, kb=kb, method=m)
           for m in ("auto", "interp", "match", "regress")}
    out.update(quiet_job(rig, fps, kb).candidates(seen, location, gaps, ("regress_kernel",),
                                                  basis_matrices(rig, seen, location)))
    out["cons"] = halfway(out["match"], out["regress_kernel"], gaps)
    return out


def gap_errors(rig, fills, truth, gaps):
    """Per gap (:func:`gap_runs` order), each fill's RMS joint error (mm) over the joints its
    bone moves (:func:`~mocap_gapfill.core.evaluate.bone_errors`, ``truth`` basis matrices);
    None for a bone that moves none."""
    per_fill = {name: bone_errors(rig, basis, truth, gaps)["gaps_mm"]
                for name, basis in fills.items()}
    below = rig.placed_by()
    return [{name: errors[i] for name, errors in per_fill.items()} if below[b].any() else None
            for i, (b, _, _) in enumerate(gap_runs(gaps))]


def run(out):
    amc = bool(os.environ.get("AMC"))
    full = armature_kb(amc)
    only = os.environ.get("TAKES")
    takes = [t for t in (AMC_TUNING if amc else DAZ_TUNING)
             if not only or any(x in t for x in only.split(","))]
    with open(out, "w") as sink:
        for take in takes:
            path = AMC / f"{take}.amc" if amc else DAZ / take[:2] / f"{take}.bvh.gz"
            rig, channels, location, fps = read_rig_take(path, skip_frames=0 if amc else 6)
            kb = kb_without(full, subject_of(path))
            truth = basis_matrices(rig, channels, location)
            below = rig.placed_by()
            frames = len(channels)
            for n, l in PROTOCOLS.bones:
                gaps = punch_bone_gaps(rig, frames, (n, l), ends=True)
                runs = gap_runs(gaps)
                real = gap_errors(rig, fills_of(rig, channels, location, gaps, fps, kb), truth,
                                  gaps)
                copies = [[] for _ in runs]
                for start in (True, False):  # the gaps at the clip's start, then its end
                    for k in range(1, COPIES + 1):
                        cut = k * (l + MARGIN)
                        if frames - cut < 3 * l:
                            break
                        rows = slice(cut, frames) if start else slice(0, frames - cut)
                        crop = gaps[rows].copy()
                        for b, a, e in runs:
                            if (a == 0) == start:  # moved to the crop's end on that side
                                crop[:, b] = False
                                if start:
                                    crop[:e - a + 1, b] = True
                                else:
                                    crop[len(crop) - (e - a + 1):, b] = True
                        errors = gap_errors(rig, fills_of(rig, channels[rows], location[rows],
                                                          crop, fps, kb), truth[rows], crop)
                        by_bone = {(b, a == 0): err for (b, a, _), err in zip(gap_runs(crop),
                                                                               errors)}
                        for i, (b, a, _) in enumerate(runs):
                            if (a == 0) == start and by_bone.get((b, start)) is not None:
                                copies[i].append(by_bone[b, start])
                for (b, a, e), err, own in zip(runs, real, copies):
                    if err is None:
                        continue
                    sink.write(json.dumps({
                        "take": path.name, "subject": subject_of(path), "setting": f"n={n},l={l}",
                        "bone": rig.names[b], "start": bool(a == 0),
                        "weight": int((e - a + 1) * below[b].sum()),
                        "real": err, "copies": own}) + "\n")
                print(take, n, l, flush=True)


def choose(row, fills, p, least, guard):
    """The fill a gap takes by the rule (module docstring); ``auto`` where none qualifies."""
    copies = row["copies"]
    if len(copies) < least:
        return "auto"
    score = {f: np.mean([np.log((c[f] ** 2 + FLOOR) / (c["auto"] ** 2 + FLOOR)) for c in copies])
             for f in fills if guard is None
             or all(c[f] ** 2 + FLOOR < guard ** 2 * (c["interp"] ** 2 + FLOOR) for c in copies)}
    best = min(score, key=score.get, default=None)
    return best if best is not None and score[best] < np.log(p) else "auto"


def judged(rows, rule):
    """Geometric mean over take-settings of the rule's RMSE over auto's, the gaps the rule and
    auto lose (worse than the held key by 10 % + 2 mm)."""
    settings = defaultdict(list)
    for row in rows:
        settings[row["take"], row["setting"]].append(row)
    logs, lost, lost_auto = [], 0, 0
    for group in settings.values():
        weights = np.array([r["weight"] for r in group])
        picked = [rule(r) for r in group]

        def rmse(names):
            return np.sqrt(np.sum(weights * [r["real"][n] ** 2 for r, n in zip(group, names)])
                           / weights.sum())

        auto = rmse(["auto"] * len(group))
        if auto > 1e-6:
            logs.append(np.log((rmse(picked) + 1e-3) / (auto + 1e-3)))
        held = [1.1 * r["real"]["interp"] + 2 for r in group]
        lost += sum(r["real"][n] > h for r, n, h in zip(group, picked, held))
        lost_auto += sum(r["real"]["auto"] > h for r, h in zip(group, held))
    return float(np.exp(np.mean(logs))), lost, lost_auto


def score(paths):
    rows = [json.loads(line) for path in paths.split(",") for line in open(path)]
    others = FILLS[1:]
    grid = [(fills, p, least, guard)
            for k in range(1, len(others) + 1) for fills in itertools.combinations(others, k)
            for p in (1.0, 0.9, 0.8, 0.7, 0.5) for least in (1, 2, 3)
            for guard in (None, 1.0)]

    def of(g, subset):
        return judged(subset, lambda r: choose(r, *g))

    every = {g: of(g, rows) for g in grid}
    for g in sorted(every, key=lambda g: every[g][0])[:10]:
        print(g, "%.3f of auto, lost %d (auto %d)" % every[g])
    for name in FILLS:
        print(name, "alone: %.3f of auto, lost %d (auto %d)" % judged(rows, lambda r: name))
    print("best fill per gap: %.3f of auto" % judged(
        rows, lambda r: min(FILLS, key=lambda f: r["real"][f]))[0])
    held, lost = [], np.zeros(2, int)
    for subject in sorted({r["subject"] for r in rows}):
        train = [r for r in rows if r["subject"] != subject]
        test = [r for r in rows if r["subject"] == subject]
        base = judged(train, lambda r: "auto")[2]
        fits = {g: of(g, train) for g in grid}
        g = min((g for g in grid if fits[g][1] <= 1.1 * base + 1), key=lambda g: fits[g][0])
        ratio, new, old = of(g, test)
        held.append(ratio)
        lost += (new, old)
        print("left out", subject, g, "%.3f, lost %d (auto %d)" % (ratio, new, old))
    print("leave-one-subject-out: held-out %.3f (%.2f-%.2f), lost %d (auto %d)"
          % (np.exp(np.mean(np.log(held))), min(held), max(held), *lost))


if __name__ == "__main__":
    if sys.argv[1] == "--score":
        score(sys.argv[2])
    else:
        run(sys.argv[1])
