"""The ``faults`` protocol: swaps, spikes and ghost take-overs injected into complete real marker
takes, found by :func:`~.faults.find_faults`, and the faulted samples after repair and fill.

Per take and kind of fault, one fault every 2.5 s, each on markers of its own
(:class:`FaultProtocol`):

- swap: two markers 50-500 mm apart (median distance) exchange trajectories for 0.1-2 s;
- spike: one marker moves 20-200 mm (a random direction) for 1-10 frames;
- ghost: one marker takes the trajectory of another 50 mm or more away for 0.5-2.5 s.

A fault is found where an event of its kind (a spike or a ghost for either of the two) names
its markers and overlaps its frames. Recall counts the faults the issue's bar names (swaps of
0.25 s or more, spikes of 30 mm or more; every ghost); precision counts every event of the kind
found, on the faulted take, against the faults injected.
"""

from dataclasses import dataclass

import numpy as np

from .faults import find_faults

KINDS = ("swap", "spike", "ghost")


@dataclass(frozen=True)
class FaultProtocol:
    """The faults the protocol injects: one every ``every`` seconds; swaps of ``swap_seconds``,
    spikes of ``spike_frames`` and ``spike_mm``, ghosts of ``ghost_seconds`` (ranges); and
    ``rounds`` seeds per take and kind (a short take holds few faults a round)."""

    every: float = 2.5
    swap_seconds: tuple = (0.1, 2.0)
    spike_frames: tuple = (1, 10)
    spike_mm: tuple = (20, 200)
    ghost_seconds: tuple = (0.5, 2.5)
    rounds: int = 3


@dataclass(frozen=True)
class Injected:
    kind: str
    points: frozenset
    first: int
    last: int
    barred: bool  # within the bar (swap >= 0.25 s, spike >= 30 mm, every ghost)


def inject(motion, kind, rng, protocol=FaultProtocol()):
    """``(faulted motion, [Injected, ...])``: faults of ``kind`` put into a take."""
    pos = motion.positions.copy()
    frames, points = pos.shape[:2]
    every = int(round(protocol.every * motion.fps))
    with np.errstate(invalid="ignore"):
        apart = np.nanmedian(np.linalg.norm(pos[::10, :, None] - pos[::10, None], axis=3), axis=0)
    truths = []
    for start in range(every // 4, frames - every, every):
        i = int(rng.integers(points))
        others = np.flatnonzero((apart[i] >= 0.05) & (apart[i] <= 0.5))
        if kind == "spike":
            length = int(rng.integers(protocol.spike_frames[0], protocol.spike_frames[1] + 1))
            size = rng.uniform(*protocol.spike_mm) / 1000
            way = rng.standard_normal(3)
            j, barred = i, size >= 0.03
        elif len(others):
            j = int(rng.choice(others))
            span = protocol.swap_seconds if kind == "swap" else protocol.ghost_seconds
            length = min(every - 2, int(rng.integers(round(span[0] * motion.fps),
                                                     round(span[1] * motion.fps) + 1)))
            barred = kind == "ghost" or length >= 0.25 * motion.fps
        else:
            continue
        stretch = slice(start, start + length)
        if not np.isfinite(pos[start - 1:start + length + 1, [i, j], 0]).all():
            continue  # the take's own gaps there
        if kind == "spike":
            pos[stretch, i] += size * way / np.linalg.norm(way)
        elif kind == "swap":
            pos[stretch, [i, j]] = pos[stretch, [j, i]]
        else:
            pos[stretch, i] = pos[stretch, j]
        truths.append(Injected(kind, frozenset([i, j] if kind == "swap" else [i]), start,
                               start + length - 1, bool(barred)))
    return motion.replace(positions=pos), truths


def marker_take(motion, seen=0.9):
    """The points of a take seen in at least ``seen`` of its frames (its gaps kept: frames left
    out would make jumps of their own)."""
    kept = [n for n, share in zip(motion.names, (~motion.missing).mean(axis=0)) if share >= seen]
    return motion.select(kept)


def matches(event, truth, names):
    """Whether a found :class:`~.faults.Fault` is the injected fault ``truth``."""
    alike = event.kind == truth.kind or {event.kind, truth.kind} <= {"spike", "ghost"}
    return (alike and {names.index(n) for n in event.points} == set(truth.points)
            and event.first <= truth.last and event.last >= truth.first)


def score(events, truths, names, kind):
    """``(found, barred, right, reported)``: the barred faults found, the barred faults, the
    events of ``kind`` that are an injected fault, the events of ``kind``."""
    mine = [e for e in events if e.kind == kind or (kind != "swap" and e.kind != "swap")]
    found = sum(any(matches(e, t, names) for e in events) for t in truths if t.barred)
    right = sum(any(matches(e, t, names) for t in truths) for e in mine)
    return found, sum(t.barred for t in truths), right, len(mine)


def run_take(motion, kind, seed, config=None, protocol=FaultProtocol()):
    """One take, one kind: the faulted motion, the truths, the :class:`~.faults.Repair` and the
    score (:func:`score`)."""
    faulted, truths = inject(motion, kind, np.random.default_rng([seed, *kind.encode()]),
                             protocol)
    repair = find_faults(faulted, config)
    return faulted, truths, repair, score(repair.faults, truths, motion.names, kind)


def faulted_mask(truths, shape):
    """(frames, points) True on the injected faults' samples."""
    mask = np.zeros(shape, dtype=bool)
    for t in truths:
        mask[t.first:t.last + 1, sorted(t.points)] = True
    return mask


def evaluate_faults(tests, kb, fps=None, seed=0, progress=None, report=None,
                    protocol=FaultProtocol()):
    """The ``faults`` protocol on each test take (read as it is, at ``fps``),
    ``protocol.rounds`` times (seeds ``seed``, ``seed + 1``, ...): per take, kind and round a
    result dict with the counts of :func:`score`, recall and precision, and the RMSE (mm) over
    the faulted samples of doing nothing, of today's jump and limb check (``suspects``: its
    samples cut, then filled) and of the repair then fill, ``auto`` with ``kb`` (the test
    subject left out; None: the take alone)."""
    from pathlib import Path

    from .evaluate import _at_rate, kb_without, rmse_mm, subject_of
    from .fill import fill
    from .io import read_motion
    from .suspect import find_suspects

    results, rounds = [], protocol.rounds
    for n, test in enumerate(tests):
        motion = read_motion(test)
        truth = marker_take(_at_rate(motion, fps or motion.fps))
        mine = None if kb is None else kb_without(kb, subject_of(test))
        if mine is not None:
            truth = truth.select([p for p in truth.names if p in mine.names])
        for kind, round_ in ((k, r) for k in KINDS for r in range(rounds)):
            faulted, truths, repair, counts = run_take(truth, kind, seed + round_, None,
                                                       protocol)
            if not truths:  # shorter than the room a fault needs
                if report and round_ == 0:
                    report(f"{Path(test).name} {kind}: the take is too short for it; skipped")
                continue
            mask = faulted_mask(truths, truth.missing.shape) & ~truth.missing
            suspect = find_suspects(faulted.positions, faulted.fps, faulted.limbs)
            cut = faulted.replace(positions=np.where(suspect[..., None], np.nan,
                                                     faulted.positions))
            fixed = faulted.replace(positions=repair.positions)
            found, barred, right, reported = counts
            results.append({
                "test": Path(test).name, "kind": kind, "seed": seed + round_,
                "faults": len(truths), "barred": barred,
                "found": found, "right": right, "reported": reported,
                "recall": found / max(barred, 1), "precision": right / max(reported, 1),
                "rmse_nothing_mm": rmse_mm(faulted, truth, mask),
                "rmse_suspects_mm": rmse_mm(fill(cut, "auto", kb=mine), truth, mask),
                "rmse_repair_mm": rmse_mm(fill(fixed, "auto", kb=mine), truth, mask)})
            if report:
                r = results[-1]
                report(f"{r['test']} {kind} {r['seed']}: {found}/{barred} found, "
                       f"{right}/{reported} right; "
                       f"RMSE {r['rmse_nothing_mm']:.1f} / {r['rmse_suspects_mm']:.1f} / "
                       f"{r['rmse_repair_mm']:.1f} mm (nothing / suspects cut / repaired)")
            if progress:
                done = KINDS.index(kind) * rounds + round_ + 1
                progress((n + done / (len(KINDS) * rounds)) / len(tests),
                         f"{Path(test).name} {kind}")
    return results


def fault_table(results):
    """Recall, precision and the faulted samples' RMSE per kind, summed over the takes."""
    lines = ["kind      faults  recall  precision   RMSE mm: nothing  suspects cut  repaired"]
    for kind in KINDS:
        rows = [r for r in results if r["kind"] == kind]
        if not rows:
            continue
        found, barred, right, reported = (sum(r[k] for r in rows)
                                          for k in ("found", "barred", "right", "reported"))
        mean = {k: np.mean([r[k] for r in rows])
                for k in ("rmse_nothing_mm", "rmse_suspects_mm", "rmse_repair_mm")}
        lines.append(f"{kind:8s} {barred:7d} {found / max(barred, 1):7.3f} "
                     f"{right / max(reported, 1):10.3f} {mean['rmse_nothing_mm']:17.1f} "
                     f"{mean['rmse_suspects_mm']:13.1f} {mean['rmse_repair_mm']:9.1f}")
    lines.append("recall over the faults within the bar (swaps >= 0.25 s, spikes >= 30 mm, "
                 "every ghost); RMSE over the faulted samples, mean over the takes and rounds")
    return "\n".join(lines)
