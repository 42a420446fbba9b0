"""Gap lists of takes and the fill, between the operators / batch command and the bridge.

Everything here runs on the main thread except the ``work`` closures :func:`plan_detect` and
:func:`plan_fill` return, which only see arrays.
"""

import os
import re
from dataclasses import dataclass, field, replace

import numpy as np

from ..core import explain
from ..core.errors import GapFillError
from ..core.fill import DEFAULT_METHOD
from ..core.motion import gap_runs
from ..core.faults import find_faults
from ..core.suspect import find_suspects
from . import bridge, prefs

_KB_CACHE = {}


def takes_in(context, names=None):
    """The takes (armatures and marker sets) named, or else those of the selected objects, or
    else of the active object."""
    scene = context.scene
    if names:
        found = [scene.objects.get(n) for n in names]
        unknown = [n for n, o in zip(names, found) if o is None]
        if unknown:
            raise GapFillError(f"no object named {', '.join(unknown)} in scene '{scene.name}'")
        objects = found
    else:
        objects = list(context.selected_objects) or [context.active_object]
    owners = []
    for obj in objects:
        owner = bridge.take_owner(obj)
        if owner is not None and owner not in owners:
            owners.append(owner)
    return owners


def all_takes(scene):
    return [o for o in scene.objects if bridge.take_owner(o) is o]


def read_original(owner, scene):
    """The take as recorded: read with the original actions playing, whatever is shown."""
    settings = owner.mocap_gapfill
    showing = settings.showing
    if showing != "ORIGINAL":
        bridge.show(owner, "ORIGINAL")
    try:
        return bridge.read_take(owner, scene)
    finally:
        if showing != "ORIGINAL":
            bridge.show(owner, showing)


def detect(owner, scene, suspects=True, jump_factor=8.0):
    """Replace the detected gaps of a take (keeping gaps marked by hand); returns the take."""
    take, work = plan_detect(owner, scene, suspects, jump_factor)
    write_detected(owner, take, work(lambda fraction, message: None, None))
    return take


def plan_detect(owner, scene, suspects=True, jump_factor=8.0):
    """Read a take; returns ``(take, work)``: ``work(progress, should_cancel)`` finds, on plain
    arrays, its gaps, its suspect keys (jumps, stretched limbs) and on a marker set its label
    swaps, spikes and ghosts, for :func:`write_detected`."""
    take = read_original(owner, scene)
    missing = bridge.unkeyed(take)

    def work(progress, should_cancel):
        if not suspects:
            return missing, np.zeros_like(missing), []
        progress(0.0, "looking for keys that jump")
        motion = take.motion(bridge.missing_points(take, missing))
        flagged = find_suspects(motion.positions, motion.fps, motion.limbs,
                                jump_factor=jump_factor)
        problems = []
        if take.kind == "armature":
            flagged = bridge.blame_bones(take, flagged)
        else:  # label swaps, spikes and ghosts: listed as such, not as suspects
            progress(0.2, "looking for label swaps, spikes and ghosts")
            problems = find_faults(motion, should_cancel=should_cancel).faults
            for fault in problems:  # (the jump test flags a jump's neighbours too)
                for name in fault.points:
                    flagged[max(fault.first - 1, 0):fault.last + 2,
                            motion.names.index(name)] = False
        return missing, flagged & ~missing, problems

    return take, work


def write_detected(owner, take, found):
    """The gap list of ``owner`` made anew from what :func:`plan_detect`'s work ``found``."""
    missing, suspect, problems = found
    settings = owner.mocap_gapfill
    marked = [(g.point, g.first, g.last, g.kind, g.filled, g.how, g.estimate, g.expected_mm)
              for g in settings.gaps if g.kind == "MARKED"]
    settings.gaps.clear()
    for kind, mask in (("MISSING", missing), ("SUSPECT", suspect)):
        for j, a, b in gap_runs(mask):
            _add_gap(settings, take.points[j], take.first + a, take.first + b, kind)
    for fault in problems:  # by the listed names (objects), not the labels
        names = [take.points[take.names.index(n)] for n in fault.points]
        gap = _add_gap(settings, names[0], take.first + fault.first, take.first + fault.last,
                       fault.kind.upper())
        gap.other = names[1] if len(names) > 1 else ""
    for point, first, last, kind, filled, how, estimate, expected in marked:
        gap = _add_gap(settings, point, first, last, kind)
        gap.filled, gap.how, gap.estimate, gap.expected_mm = filled, how, estimate, expected
    settings.gap_index = -1 if not len(settings.gaps) else min(settings.gap_index, 0)
    update_stats(owner, take.points, take.first, take.positions.shape[0])


def _add_gap(settings, point, first, last, kind):
    gap = settings.gaps.add()
    gap.point, gap.first, gap.last, gap.kind = point, int(first), int(last), kind
    return gap


def mark(owner, points, first, last):
    """Add hand-marked gaps on ``points`` over ``first..last`` (inclusive)."""
    if last < first:
        raise GapFillError(f"empty frame range {first}..{last}")
    settings = owner.mocap_gapfill
    for point in points:
        _add_gap(settings, point, first, last, "MARKED")
    settings.gap_index = len(settings.gaps) - 1


def update_stats(owner, points, first, frames):
    """Per-point totals (gaps, frames, percentage, longest) of a take's gap list."""
    settings = owner.mocap_gapfill
    mask = gap_mask(settings.gaps, points, first, frames)
    runs = gap_runs(mask)  # point-major
    settings.points.clear()
    settings.frames = frames
    for j in dict.fromkeys(p for p, _, _ in runs):
        lengths = [b - a + 1 for p, a, b in runs if p == j]
        item = settings.points.add()
        item.name = points[j]
        item.gaps = len(lengths)
        item.frames = int(mask[:, j].sum())
        item.percent = 100.0 * item.frames / max(frames, 1)
        item.longest = max(lengths)


def gap_mask(gaps, points, first, frames):
    """(frames, points) mask of the listed gaps inside the take's range (a swap is not a gap:
    Repair exchanges its keys back)."""
    index = {n: j for j, n in enumerate(points)}
    mask = np.zeros((frames, len(points)), dtype=bool)
    for gap in gaps:
        j = index.get(gap.point)
        if j is None or gap.kind == "SWAP":
            continue
        a, b = max(gap.first - first, 0), min(gap.last - first, frames - 1)
        if a <= b:
            mask[a:b + 1, j] = True
    return mask


def take_gaps(owner, take):
    """(frames, points) samples under the take's listed gaps or unkeyed: markers without a
    good key, or bones without good keys (their rotation, and a moving bone's location)."""
    return gap_mask(owner.mocap_gapfill.gaps, take.points, take.first,
                    take.positions.shape[0]) | bridge.unkeyed(take)


def take_missing(owner, take):
    """Point samples a take does not know: those under its listed gaps and its unkeyed ones."""
    return bridge.missing_points(take, take_gaps(owner, take))


def load_kb_cached(path):
    from ..core.kb import load_kb

    path = os.path.abspath(path)
    stamp = os.stat(path).st_mtime_ns if os.path.isfile(path) else None
    cached = _KB_CACHE.get(path)
    if cached is None or cached[0] != stamp:
        _KB_CACHE.clear()
        _KB_CACHE[path] = (stamp, load_kb(path))
    return _KB_CACHE[path][1]


def kb_path(context):
    import bpy

    chosen = context.scene.mocap_gapfill.kb_path
    path = bpy.path.abspath(chosen) if chosen else ""
    if not path:
        p = prefs.get(context)
        path = bpy.path.abspath(p.default_kb) if p and p.default_kb else ""
    return path


@dataclass
class FillPlan:
    owner: str
    take: object
    write: np.ndarray  # (frames, points) samples (markers) or bone frames (armature) to write
    missing: np.ndarray  # (frames, points) point samples unknown to the core
    gap_ids: list  # indices into the owner's gap list that this fill covers
    bone_gaps: np.ndarray = None  # (frames, bones) armatures: frames without good keys
    messages: list = field(default_factory=list)  # what the fill had to say
    kb: object = None  # the knowledge base for this take (a starter one where none was chosen)


def plan_fill(context, owners, only_active=False, method=DEFAULT_METHOD, k=0, max_gap=0, kb=None,
              device="auto"):
    """Read the takes and return ``(plans, work)``: ``work(progress, should_cancel)`` fills them
    on plain arrays and returns per plan the filled positions (None for armatures filled in
    rotation space), for armatures the solved basis matrices, and how each gap was filled:
    for armatures in rotation space its :class:`~..core.bonefill.GapChoice`, for markers
    filled by ``auto`` its :class:`~..core.fill.GapAccount` (else None).

    Armatures with ``knn`` or ``auto`` are filled in the space of their gaps
    (:func:`~..core.bonefill.fill_bones`, method ``auto``): only the gapped bones' rotations
    change, and only on gaps where the fill (from the knowledge base, or the take alone where
    none fits) refills copies of the gap better than Blender's own interpolation; other methods
    fill joint positions and solve the bones.
    Without a knowledge base (``kb`` None), methods that use one take the starter knowledge
    base whose names match the take (:func:`~..core.kb.starter_kb`); where none fits, ``auto``
    fills from the take alone, and the others say why none fits."""
    from ..core import bonefill
    from ..core.fill import TAKE_ALONE, fill, kb_for_take
    from ..core.recover import KnnSettings

    plans = []
    for owner in owners:
        settings = owner.mocap_gapfill
        if not len(settings.gaps):
            continue
        take = with_swaps_repaired(owner, read_original(owner, context.scene))
        frames = take.positions.shape[0]
        if only_active and not 0 <= settings.gap_index < len(settings.gaps):
            raise GapFillError(f"'{owner.name}': select a gap in the list first")
        ids = [settings.gap_index] if only_active else range(len(settings.gaps))
        ids = [i for i in ids if not max_gap
               or settings.gaps[i].last - settings.gaps[i].first + 1 <= max_gap]
        if not ids:
            continue
        chosen = [settings.gaps[i] for i in ids]
        write = gap_mask(chosen, take.points, take.first, frames)
        every = take_gaps(owner, take)
        missing = bridge.missing_points(take, every)
        if take.kind == "markers":
            write &= missing
        alone = bonefill.TAKE_ALONE if take.kind == "armature" else TAKE_ALONE
        try:
            used, note = kb_for_take(take.names, method, kb, alone,
                                     choose="Mocap tab > Knowledge base")
        except GapFillError as exc:
            raise GapFillError(f"'{owner.name}': {exc}") from None
        plan = FillPlan(owner.name, take, write, missing, ids, every, kb=used)
        if note:
            plan.messages.append(("no knowledge base chosen: " if used else "") + note)
        plans.append(plan)
    if not plans:
        raise GapFillError("no gaps to fill: detect or mark gaps first"
                           + (f" (or raise Max gap above {max_gap})" if max_gap else ""))
    knn = KnnSettings(k=k or None, device=device)

    def work(progress, should_cancel):
        results = []
        for i, plan in enumerate(plans):
            def step(fraction, message, i=i):
                progress((i + fraction) / len(plans), f"{plan.owner}: {message}")

            take = plan.take
            if take.kind == "armature" and method in ("knn", "auto"):
                # rotation gaps: Blender's interpolation unless the KB measurably beats it
                results.append((None, *fill_armature(take, plan.bone_gaps, plan.kb, knn, step,
                                                     should_cancel, plan.messages.append)))
                continue
            filled, accounts = fill(take.motion(plan.missing), method, kb=plan.kb, settings=knn,
                                    progress=step, should_cancel=should_cancel,
                                    return_account=True)
            basis = None
            if take.kind == "armature":  # (joint positions: their account says nothing of bones)
                basis, _ = bridge.solve_armature(take, filled.positions, plan.write)
                accounts = None
            elif accounts is not None:  # by the listed names (objects), not the labels
                accounts = [replace(a, point=take.points[take.names.index(a.point)])
                            for a in accounts]
            results.append((filled.positions, basis, accounts))
        progress(1.0, "writing keys")
        return results

    return plans, work


#: what a problem left to repair says in its gap box
PROBLEM_WORDS = {"SWAP": ["the two markers' labels are exchanged here:",
                          "Repair swaps their keys back"],
                 "SPIKE": ["the keys leave the body's rigid structure:",
                           "Repair cuts them, Fill fills them"],
                 "GHOST": ["the label follows another trajectory here:",
                           "Repair cuts it, Fill fills it"]}
#: what a repaired problem says in its gap box
REPAIRED = {"SWAP": "labels exchanged back", "SPIKE": "cut: Fill fills it",
            "GHOST": "cut: Fill fills it"}


def with_swaps_repaired(owner, take):
    """The marker take with the swaps Repair mended exchanged back, as the recovered keys hold
    them (the fill sees the markers where they belong)."""
    for gap in owner.mocap_gapfill.gaps:
        if gap.kind == "SWAP" and gap.repaired and gap.other in take.points:
            i, j = take.points.index(gap.point), take.points.index(gap.other)
            rows = slice(gap.first - take.first, gap.last - take.first + 1)
            take.positions[rows, [i, j]] = take.positions[rows, [j, i]]
    return take


def repair(owner, take, ids):
    """Mend the listed problems ``ids`` of a marker take (read as recorded): a swap's keys
    exchanged back into the recovered actions (typed GENERATED), a spike's or ghost's keys cut
    there for Fill to fill. Returns how many were mended."""
    settings, done = owner.mocap_gapfill, 0
    for i in ids:
        gap = settings.gaps[i]
        if gap.kind not in REPAIRED or gap.repaired:
            continue
        if gap.kind == "SWAP":
            a, b = take.points.index(gap.point), take.points.index(gap.other)
            rows = np.arange(gap.first - take.first, gap.last - take.first + 1)
            exchanged = take.positions * take.metres
            exchanged[rows[:, None], [a, b]] = exchanged[rows[:, None], [b, a]]
            mask = np.zeros(take.keyed.shape, dtype=bool)
            mask[rows[:, None], [a, b]] = True
            bridge.write_markers(take, exchanged, mask & np.isfinite(exchanged[..., 0]))
            gap.filled = True
        else:
            bridge.revert_keys(owner, gap.point, gap.first, gap.last, every=True)
        gap.repaired, gap.how = True, REPAIRED[gap.kind]
        done += 1
    settings.showing = "RECOVERED"
    return done


def fill_armature(take, bone_gaps, kb, settings, progress, should_cancel, report):
    """Basis matrices of an armature take after the rotation fill (world metres for the KB),
    and how each gap was filled."""
    from ..core.bonefill import fill_bones

    to_metres = np.diag([take.metres] * 3 + [1.0]) @ take.world
    return fill_bones(take.extra["rig"], take.extra["channels"], take.extra["location"],
                      bone_gaps, take.fps, kb=kb, method="auto", moves=take.extra["moves"],
                      to_metres=to_metres, settings=settings, progress=progress,
                      should_cancel=should_cancel, report=report, return_choices=True)


def apply_fill(context, plans, results):
    """Write the recovered keys (main thread, one step) and show the recovered actions."""
    import bpy

    written = 0
    for plan, (filled, basis, account) in zip(plans, results):
        owner = bpy.data.objects[plan.owner]
        if plan.take.kind == "markers":
            ok = plan.write & np.isfinite(filled[..., 0])
            written += bridge.write_markers(plan.take, filled, ok)
        else:
            # keys only where the fill changed something: elsewhere the F-curves' own
            # interpolation across the gap is the answer
            changed = np.abs(basis - plan.take.extra["basis"]).max(axis=(2, 3)) > 1e-6
            written += bridge.write_armature(plan.take, basis, plan.write & changed)
        settings = owner.mocap_gapfill
        for i in plan.gap_ids:  # a marker gap nothing could place stays open
            gap = settings.gaps[i]
            if plan.take.kind == "markers":
                j = plan.take.points.index(gap.point)
                rows = slice(gap.first - plan.take.first, gap.last - plan.take.first + 1)
                gap.filled = bool(np.isfinite(filled[rows, j, 0]).all())
            else:
                gap.filled = True
            # how it was filled (rotation fill of an armature, auto on markers; else nothing)
            how = how_filled if plan.take.kind == "armature" else how_carried
            gap.how, gap.estimate, gap.expected_mm = (
                ("", 0.0, 0.0) if account is None or not gap.filled else
                how(account, gap.point, gap.first - plan.take.first, gap.last - plan.take.first))
        settings.showing = "RECOVERED"
    return written


def how_filled(choices, bone, first, last):
    """``(how, estimate, 0)`` of a listed gap of ``bone`` over the take's rows ``first``-``last``
    from the rotation fill's choices of the gaps it overlaps: in words, the fill its rotation
    went to and what that was blended with (:func:`~..core.explain.bone_gap`; Blender's curve
    kept: :data:`~..core.explain.KEPT`), and the copies' estimate of its error as a share of
    the interpolation's (the largest where several, 0 where none judged it). No error in
    millimetres: an armature's copies foretell the share, not the level."""
    parts = [c for c in choices if c.bone == bone and c.first <= last and c.last >= first]
    if not parts:
        return "", 0.0, 0.0
    judged = [c.estimate for c in parts if np.isfinite(c.estimate)]
    return explain.bone_gap(parts), max(judged, default=0.0), 0.0


def how_carried(accounts, point, first, last):
    """``(how, 0, expected_mm)`` of a listed gap of marker ``point`` over the take's rows
    ``first``-``last`` from ``auto``'s accounts of the gaps it overlaps: the estimates it
    blended, in words, by share (:func:`~..core.explain.point_gap`), and the copies' RMS error
    of the fill in millimetres (the largest where several, 0 where none had copies)."""
    parts = [a for a in accounts if a.point == point and a.first <= last and a.last >= first]
    if not parts:
        return "", 0.0, 0.0
    judged = [a.estimate for a in parts if np.isfinite(a.estimate)]
    return explain.point_gap(parts), 0.0, 1000.0 * max(judged, default=0.0)


def describe(gap, armature):
    """How a filled gap was filled, in lines of plain words (the panel and ``blend`` say them;
    the panel is narrow: each source on a line of its own)."""
    if gap.kind in REPAIRED:  # a label problem: what it is, or what Repair did
        return [gap.how] if gap.how else PROBLEM_WORDS[gap.kind]
    if not gap.how:
        return []
    if not armature:  # "from knowledge base 60%", "rigid partners 40%", the expected error
        first, *rest = gap.how.split(", ")
        return [f"from {first}", *rest] + (
            [explain.expected(gap.expected_mm / 1000)] if gap.expected_mm else [])
    if gap.how == explain.KEPT:
        return [explain.KEPT, "(no fill was sure to beat it here)" if gap.estimate else
                "(no fill was judged better here)"]
    first, *blended = gap.how.split(", blended with ")
    sources = re.split(r", | and ", blended[0]) if blended else []
    return [f"from {first}"] + [("blended with " if i == 0 else "and ") + source
                                for i, source in enumerate(sources)] + (
        [explain.bone_estimate(gap.estimate)] if gap.estimate else [])