"""Accuracy evaluation on real data (METHOD.md section 4), every method on identical gaps.

Protocols:
- ``joints``: in each interval of ``l`` frames, ``m`` random points are removed for the whole
  interval (m in {3, 6}, l in {15, 30, 60, 90, 120} at the evaluation frame rate);
- ``markers``: in each 60-frame interval a fraction (10, 20, 30 %) of the points is removed;
- ``bodyparts``: a whole limb or half of the body is removed for the middle half of the clip;
- ``shortgaps``: the dropouts of a few frames that most real captures have: random points lose
  ``l`` frames at random places (l in {3, 6, 12, 24} at the evaluation frame rate) until 5 % of
  the samples are gone;
- ``endgaps``: the gaps takes start and end with (a marker not yet seen, or lost before the end):
  a random share (``GapProtocols.end_gaps_rate``) of the points lose their first ``l`` frames
  and as many others their last ``l`` (l in {3, 12, 30, 60, 120} at the evaluation frame rate);
- ``realgaps``: the gaps a real capture has (``gap_sources``: takes with gaps of their own, e.g.
  CMU 01_01.c3d), transplanted by point name onto the complete test take, the source's mask
  repeated in time where the test take is longer, so gap lengths and co-occurrence are real;
- ``bursts``: occlusions that take most of the body at once (a subject half out of the volume,
  a prop or another actor in the way, a dropped camera frame): in each 120-frame interval a
  random ``l`` frames (l in {3, 12, 30, 60} at the evaluation frame rate) lose a random 50-100 %
  of the points together, so a fill has few or no partners seen to carry them.

The knowledge base is built from the sources without any file of the test trial's subject.
Errors are RMSE in millimetres over the missing entries and over all entries (the paper's).
"""

import re
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .errors import GapFillError
from .fill import METHODS, fill
from .formats.asfamc import find_asf
from .kb import build_kb, load_kb, resample
from .motion import gap_runs
from .io import read_motion, read_rig_take
from .recover import KnnSettings



@dataclass(frozen=True)
class GapProtocols:
    """The gaps each protocol punches (docs/EVALUATION.md): its settings and rates."""

    #: ``joints``: (joints gone, frames) per setting
    joints: tuple = tuple((m, l) for m in (3, 6) for l in (15, 30, 60, 90, 120))
    #: ``markers``: the share of the markers gone per interval
    marker_rates: tuple = (0.1, 0.2, 0.3)
    #: ``shortgaps``: dropout lengths (frames), and the share of the samples they take
    short_gaps: tuple = (3, 6, 12, 24)
    short_gaps_rate: float = 0.05
    #: ``endgaps``: lengths at the clip's ends, and the share of the points that lose them
    end_gaps: tuple = (3, 12, 30, 60, 120)
    end_gaps_rate: float = 0.15
    #: ``bursts``: lengths, frames per burst interval, and the least and most share of the points
    #: a burst takes
    bursts: tuple = (3, 12, 30, 60)
    burst_every: int = 120
    burst_share: tuple = (0.5, 1.0)
    #: ``bones``: (bones gapped, frames) per setting
    bones: tuple = tuple((n, l) for n in (1, 3) for l in (15, 30, 60, 120, 240))


PROTOCOLS = GapProtocols()
BODY_PARTS = ("left_arm", "right_arm", "left_leg", "right_leg", "upper_body", "lower_body",
              "left_side", "right_side")
_ARM = re.compile(r"(arm|hand|wrist|elbow|shoulder|sho|collar|clavicle|humerus|radius|finger|"
                  r"thumb|index|mid|ring|pinky|wr[ab]|elb|frm|upa|fin|wri)", re.I)
_LEG = re.compile(r"(leg|thigh|shin|foot|toe|femur|tibia|knee|kne|ankle|ank|heel|hee|tib|thi|"
                  r"buttock|hipjoint|mt5|upleg)", re.I)


def subject_of(path):
    """Subject id from a file name: CMU ``07_05`` -> ``07``, HDM05 ``HDM_dg_...`` -> ``HDM_dg``;
    an AMC beside its ASF is its skeleton's subject (``charleston1.amc`` and ``charleston2.amc``
    of ``charleston.asf`` are one performer)."""
    path = Path(path)
    if path.suffix.lower() == ".amc" and path.is_file():
        try:
            path = find_asf(path)
        except GapFillError:
            pass
    name = path.name.split(".")[0]
    if name.upper().startswith("HDM_"):
        return "_".join(name.split("_")[:2])
    return name.split("_")[0]


def side_of(name):
    low = name.lower()
    if low.startswith(("l", "left")) and not low.startswith(("lower",)):
        return "left"
    if low.startswith(("r", "right")) and not low.startswith(("root", "ring")):
        return "right"
    return None


def body_part_points(names, part):
    """Indices of the points in a body part, found by name."""
    sides = [side_of(n) for n in names]
    arm = [bool(_ARM.search(n)) and s is not None for n, s in zip(names, sides)]
    leg = [bool(_LEG.search(n)) and s is not None and not a for n, s, a in zip(names, sides, arm)]
    pick = {
        "left_arm": [a and s == "left" for a, s in zip(arm, sides)],
        "right_arm": [a and s == "right" for a, s in zip(arm, sides)],
        "left_leg": [g and s == "left" for g, s in zip(leg, sides)],
        "right_leg": [g and s == "right" for g, s in zip(leg, sides)],
        "upper_body": [not g for g in leg],
        "lower_body": leg,
        "left_side": [s == "left" for s in sides],
        "right_side": [s == "right" for s in sides],
    }[part]
    return [i for i, p in enumerate(pick) if p]


def punch_gaps(n_frames, n_points, protocol, setting, rng, names=None):
    """Boolean mask (frames, points) of the samples to remove."""
    miss = np.zeros((n_frames, n_points), dtype=bool)
    if protocol == "joints":
        m, l = setting
        for s in range(0, n_frames, l):
            miss[s:s + l, rng.choice(n_points, m, replace=False)] = True
    elif protocol == "markers":
        count = max(1, int(round(setting * n_points)))
        for s in range(0, n_frames, 60):
            miss[s:s + 60, rng.choice(n_points, count, replace=False)] = True
    elif protocol == "bodyparts":
        pts = body_part_points(names, setting)
        if not pts:
            raise GapFillError(f"no points of {setting} found by name")
        miss[n_frames // 4: 3 * n_frames // 4, pts] = True
    elif protocol == "shortgaps":
        share = PROTOCOLS.short_gaps_rate
        for _ in range(max(1, int(round(share * n_frames * n_points / setting)))):
            s = rng.integers(1, n_frames - setting - 1)
            miss[s:s + setting, rng.integers(n_points)] = True
    elif protocol == "endgaps":
        count = max(1, int(round(PROTOCOLS.end_gaps_rate * n_points)))
        points = rng.permutation(n_points)
        miss[:setting, points[:count]] = True
        miss[n_frames - setting:, points[count:2 * count]] = True
    elif protocol == "realgaps":
        miss = real_gaps(setting, names, n_frames)
    elif protocol == "bursts":
        for s in range(0, n_frames - setting + 1, PROTOCOLS.burst_every):
            start = s + rng.integers(min(PROTOCOLS.burst_every, n_frames - s) - setting + 1)
            count = int(round(rng.uniform(*PROTOCOLS.burst_share) * n_points))
            miss[start:start + setting, rng.choice(n_points, count, replace=False)] = True
    else:
        raise GapFillError(f"unknown protocol {protocol!r}")
    return miss


def real_gaps(source, names, n_frames):
    """The gap mask of the motion ``source`` (at the take's rate) for the points ``names`` (by
    name) over ``n_frames`` frames: the source repeated in time over a longer take, folded onto
    a shorter one (source frame ``t`` lands on ``t % n_frames``), so every real gap is there."""
    shared = [n for n in names if n in source.names]
    miss = np.zeros((n_frames, len(names)), dtype=bool)
    t = np.arange(max(n_frames, source.n_frames))
    for name in shared:
        np.logical_or.at(miss[:, names.index(name)], t % n_frames,
                         source.missing[t % source.n_frames, source.names.index(name)])
    if not miss.any():
        raise GapFillError(f"{Path(source.source).name} has no gaps on the points it shares "
                           f"with the take ({len(shared)} of {len(names)} names shared)")
    return miss


def settings_of(protocol, gap_sources=()):
    if protocol == "joints":
        return [(f"m={m},l={l}", (m, l)) for m, l in PROTOCOLS.joints]
    if protocol == "markers":
        return [(f"rate={r}", r) for r in PROTOCOLS.marker_rates]
    if protocol == "bodyparts":
        return [(f"part={p}", p) for p in BODY_PARTS]
    if protocol == "shortgaps":
        return [(f"l={l}", l) for l in PROTOCOLS.short_gaps]
    if protocol == "endgaps":
        return [(f"l={l}", l) for l in PROTOCOLS.end_gaps]
    if protocol == "bursts":
        return [(f"l={l}", l) for l in PROTOCOLS.bursts]
    if protocol == "realgaps":
        if not gap_sources:
            raise GapFillError("protocol realgaps needs takes with real gaps (--gap-sources)")
        return [(f"gaps={Path(g).name.split('.')[0]}", g) for g in gap_sources]
    raise GapFillError(f"unknown protocol {protocol!r}")


def with_gaps(motion, miss):
    """The motion with the samples of the mask ``miss`` (frames, points) removed."""
    return motion.replace(positions=np.where(miss[..., None], np.nan, motion.positions))


def rmse_mm(filled, truth, mask=None):
    """RMSE in millimetres between two motions over the samples of ``mask`` (all if None);
    a sample left unfilled counts as infinitely wrong."""
    err = np.linalg.norm(filled.positions - truth.positions, axis=2)
    err = np.where(np.isnan(err), np.inf, err)
    if mask is not None:
        err = err[mask]
    return float(1000 * np.sqrt((err ** 2).mean()))


def kb_without(kb, subject):
    """The knowledge base minus every pose from a file of ``subject``."""
    keep_sources = np.array([subject_of(s) != subject for s in kb.sources])
    keep = keep_sources[kb.source_index]
    if not keep.any():
        raise GapFillError(f"the knowledge base holds only subject {subject}")
    return kb.subset(keep)


def evaluate(protocol, tests, kb_sources, methods=METHODS, fps=60.0, seed=0, k=None,
             skip_frames=0, settings=None, exclude=(), gap_sources=(), kb_file=None,
             progress=None, report=None):
    """Run a protocol; a list of result dicts (method, setting, test, rmse_missing_mm, ...).
    Where a method cannot fill a take-setting (a :class:`GapFillError`: e.g. the root gone from
    every frame of a short take) it is reported, scored as filling nothing (inf) with the
    message under ``error``, and the run goes on. A setting whose gaps a take is too short for
    is reported and left out for that take. Neither ``kb_sources`` nor ``kb_file``: no
    knowledge base (what ``auto`` does with the take alone; the methods that need one score
    inf)."""
    report = report or (lambda message: None)
    chosen = [s for s in settings_of(protocol, gap_sources)
              if settings is None or s[0] in settings]
    if protocol == "realgaps":  # the gap sources' masks, read once
        chosen = [(label, _at_rate(read_motion(path, skip_frames=skip_frames), fps))
                  for label, path in chosen]
    full_kb = _full_kb(kb_sources, kb_file, fps, skip_frames, exclude, report)
    results = []
    total = len(tests) * len(chosen) * len(methods)
    done = 0
    for test in tests:
        truth = complete_take(read_motion(test, skip_frames=skip_frames),
                              None if full_kb is None else full_kb.names, fps)
        kb = None if full_kb is None else kb_without(full_kb, subject_of(test))
        for label, setting in chosen:
            rng = np.random.default_rng([seed, *label.encode()])
            miss = punch_gaps(truth.n_frames, truth.n_points, protocol, setting, rng, truth.names)
            if not miss.any():  # a take too short for the setting: nothing to score
                report(f"{Path(test).name} {label}: the take is too short for it (no gaps); "
                       "skipped")
                done += len(methods)
                continue
            query = with_gaps(truth, miss)
            for method in methods:
                start = time.perf_counter()
                try:
                    out, failed = fill(query, method, kb=kb, settings=KnnSettings(
                        k=None if k is None or kb is None else min(k, kb.size))), {}
                except GapFillError as error:  # e.g. a short take whose root is gone throughout:
                    # nothing filled (every missing sample infinitely wrong), the run goes on
                    report(f"{Path(test).name} {label} {method}: {error}")
                    out, failed = query, {"error": str(error)}
                seconds = time.perf_counter() - start
                results.append({"method": method, "setting": label, "test": Path(test).name,
                                "rmse_missing_mm": rmse_mm(out, truth, miss),
                                "rmse_all_mm": rmse_mm(out, truth), "seconds": seconds,
                                **failed})
                done += 1
                if progress:
                    progress(done / total, f"{Path(test).name} {label} {method}")
    return results


def _full_kb(kb_sources, kb_file, fps, skip_frames, exclude, report):
    """The protocols' knowledge base: the file, else one built from the sources; None without
    either."""
    if kb_file:
        return load_kb(kb_file)
    if not kb_sources:
        return None
    return build_kb(kb_sources, fps=fps, skip_frames=skip_frames, exclude=exclude, report=report)


def _at_rate(motion, fps):
    return motion.replace(positions=resample(motion.positions, motion.fps, fps), fps=fps,
                          filled=None)


def complete_take(motion, names, fps=None):
    """The truth a protocol punches gaps into: the motion at ``fps`` (default: its own rate),
    its points that ``names`` (a knowledge base's; None: all) has, its complete frames only."""
    motion = _at_rate(motion, fps or motion.fps)
    motion = motion.select([n for n in motion.names if names is None or n in names])
    return motion.replace(positions=motion.positions[~motion.missing.any(axis=1)])


def table(results):
    """Mean RMSE over missing entries (all entries) per setting and method, as text."""
    methods = list(dict.fromkeys(r["method"] for r in results))
    settings = list(dict.fromkeys(r["setting"] for r in results))
    lines = ["setting".ljust(18) + "".join(m.rjust(18) for m in methods)]
    for s in settings:
        row = s.ljust(18)
        for m in methods:
            sel = [r for r in results if r["setting"] == s and r["method"] == m]
            miss = np.mean([r["rmse_missing_mm"] for r in sel])
            second = np.mean([r.get("angle_deg", r.get("rmse_all_mm")) for r in sel])
            row += f"{miss:9.1f} ({second:5.1f})".rjust(18)
        lines.append(row)
    if "angle_deg" in results[0]:
        lines.append("mm, RMSE of the joints the gapped bones move (mean angle error of the gapped "
                     "bones, degrees), mean over test takes")
    else:
        lines.append("mm, RMSE over missing entries (over all entries), mean over test trials")
    return "\n".join(lines)


# ---- armatures: rotation gaps (protocol "bones") ------------------------------------------------
#: bones whose rotation places only small end joints are not gapped by the protocol
_SMALL = re.compile(r"(thumb|index|mid|ring|pinky|finger|eye|toe|carpal|hand$|^[lr]hand)", re.I)


def gappable_bones(rig):
    """Limb and spine bones: not a root, placing at least one joint, not a finger, eye or toe."""
    below = rig.placed_by()
    return [b for b, (name, p) in enumerate(zip(rig.names, rig.parents))
            if p >= 0 and below[b].any() and not _SMALL.search(name)]


def punch_bone_gaps(rig, n_frames, setting, seed=0, ends=False):
    """(frames, bones) bool: the bones protocol's gaps for ``setting`` ``(n, l)`` on a take of
    ``rig``: every other stretch of ``l`` frames (the first one keyed) loses the keys of ``n``
    random bones of :func:`gappable_bones`, drawn from ``seed`` and the setting's label (the
    same gaps for every method and every run). ``ends`` (protocol ``bone-ends``): instead, ``n``
    random bones lose their first ``l`` frames and ``n`` others their last ``l``: a take that
    starts or stops with a broken bone, where Blender holds the one key. No gaps where the take
    is too short for the setting (at the ends: ``l`` frames or fewer, which would leave a bone
    no key at all)."""
    n, l = setting
    label = f"{'ends,' if ends else ''}n={n},l={l}"
    rng = np.random.default_rng([seed, *label.encode()])
    candidates = gappable_bones(rig)
    gaps = np.zeros((n_frames, len(rig.names)), dtype=bool)
    if ends and l >= n_frames:
        return gaps
    if ends:
        bones = rng.choice(candidates, 2 * n, replace=False)
        gaps[:l, bones[:n]] = True
        gaps[n_frames - l:, bones[n:]] = True
        return gaps
    for s in range(l, n_frames - 1, 2 * l):
        gaps[s:min(s + l, n_frames - 1), rng.choice(candidates, n, replace=False)] = True
    return gaps


def evaluate_bones(tests, kb_sources, methods, kb_fps=60.0, seed=0, k=None, skip_frames=0,
                   settings=None, exclude=(), kb_file=None, progress=None, report=None,
                   ends=False):
    """Protocol ``bones`` (``ends``: ``bone-ends``, gaps at the clip's ends,
    :func:`punch_bone_gaps`): rotation gaps on armature takes at their own frame rate, every
    method of :data:`~.bonefill.BONE_METHODS` on identical gaps, the test subject out of the KB.

    Scores: :func:`bone_errors`. A method that cannot fill a take-setting (a
    :class:`GapFillError`) is reported and scored inf, with the message under ``error``, as in
    :func:`evaluate`; the run goes on; a setting the take is too short for is reported and left
    out for it. Neither ``kb_sources`` nor ``kb_file``: no knowledge
    base, as in :func:`evaluate`.
    """
    from .bonefill import fill_bones
    from .rig import basis_matrices, interpolate_channels

    report = report or (lambda message: None)
    full_kb = _full_kb(kb_sources, kb_file, kb_fps, skip_frames, exclude, report)
    chosen = [(f"n={n},l={l}", (n, l)) for n, l in PROTOCOLS.bones
              if settings is None or f"n={n},l={l}" in settings]
    results = []
    total = len(tests) * len(chosen) * len(methods)
    done = 0
    for test in tests:
        rig, channels, location, fps = read_rig_take(test, skip_frames)
        kb = None if full_kb is None else kb_without(full_kb, subject_of(test))
        knn = KnnSettings(k=None if k is None or kb is None else min(k, kb.size))
        truth = basis_matrices(rig, channels, location)
        for label, setting in chosen:
            gaps = punch_bone_gaps(rig, len(channels), setting, seed, ends)
            if not gaps.any():  # a take too short for the setting: nothing to score
                report(f"{Path(test).name} {label}: the take is too short for it (no gaps); "
                       "skipped")
                done += len(methods)
                continue
            seen = interpolate_channels(channels, gaps)
            for method in methods:
                start = time.perf_counter()
                try:
                    basis = fill_bones(rig, seen, location, gaps, fps, kb=kb, method=method,
                                       settings=knn)
                    failed = None
                except GapFillError as error:  # nothing filled: infinitely wrong; go on
                    report(f"{Path(test).name} {label} {method}: {error}")
                    basis, failed = None, str(error)
                seconds = time.perf_counter() - start
                scores = bone_errors(rig, basis, truth, gaps) if failed is None else {
                    "rmse_missing_mm": np.inf, "angle_deg": np.inf,
                    "gaps_mm": [np.inf] * len(gap_runs(gaps)), "error": failed}
                results.append({"method": method, "setting": label, "test": Path(test).name,
                                **scores, "seconds": seconds,
                                "gap_bones": int(gaps.any(axis=0).sum())})
                done += 1
                if progress:
                    progress(done / total, f"{Path(test).name} {label} {method}")
    return results


def bone_errors(rig, basis, truth, gaps):
    """How far a fill of an armature's rotation gaps is from the truth (basis matrices, both
    (frames, bones, 4, 4); ``gaps``: (frames, bones) bool): ``rmse_missing_mm``, the RMSE in mm
    of the joints the gapped bones move, over the gap frames; ``gaps_mm``, the same per gap
    (:func:`gap_runs` order) over the joints below its bone; ``angle_deg``, the mean angle in
    degrees between each gapped bone's filled and true rotation."""
    dist = np.linalg.norm(rig.joints(basis) - rig.joints(truth), axis=2)
    below = rig.placed_by()
    rel = np.einsum("fbji,fbjk->fbik", basis[..., :3, :3], truth[..., :3, :3])[gaps]
    angle = np.degrees(np.arccos(np.clip((np.trace(rel, axis1=1, axis2=2) - 1) / 2, -1, 1)))
    return {"rmse_missing_mm": float(1000 * np.sqrt((dist[rig.moved(gaps)] ** 2).mean())),
            "gaps_mm": [float(1000 * np.sqrt((dist[a:e + 1, below[b]] ** 2).mean()))
                        for b, a, e in gap_runs(gaps)],
            "angle_deg": float(angle.mean())}
