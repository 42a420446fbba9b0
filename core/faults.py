"""Label swaps, spikes and ghosts in marker data, found and repaired before the gaps are filled.

A marker's place is held by its rigid partners: the markers whose distance to it stays the
steadiest over the take. At each frame the marker is refitted to those distances from its
partners' positions (:func:`displacement`); how far it must move is its displacement. A marker
that leaves the body's rigid structure moves far, and so does its label:

- a **swap**: two markers off over the same stretch, each of which sits where the other
  belongs (refitted from the other's partners, it hardly moves): the labels are exchanged back;
- a **spike**: off for at most ``max_spike`` frames (10): cut, then filled like any gap;
- a **ghost**: off for longer (a lost label picked up by another trajectory): cut.

The thresholds (how far is off) are fitted by leave-one-subject-out on takes that are not test
takes (``tools/fit_faults.py``) and shipped in ``faults.json`` beside this file; see
docs/DESIGN.md, "Clean before fill".
"""

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .posing import rigidly_carried

FITTED = Path(__file__).with_name("faults.json")


@dataclass(frozen=True)
class FaultConfig:
    """What :func:`find_faults` goes by. ``floor`` (metres) and ``factor`` (of the marker's
    median jump) make a jump an edge: it exceeds both; ``ghost_floor``: how far a ghost at least
    stays away. ``partners``: how
    many of the steadiest partners hold a marker. ``stats_frames``: at most this many frames
    (evenly spread) give the partners' distances and spreads."""

    floor: float = 0.03
    factor: float = 8.0
    ghost_floor: float = 0.03
    max_spike: int = 10  # frames: a spike is at most this long (a ghost longer)
    partners: int = 6
    stats_frames: int = 2000

    @classmethod
    def fitted(cls):
        """The config with the thresholds of ``faults.json`` (:data:`FITTED`)."""
        chosen = json.loads(FITTED.read_text())["chosen"]
        return cls(**chosen)


@dataclass(frozen=True)
class Fault:
    """One problem found: ``kind`` "swap", "spike" or "ghost", the ``points`` (names) it
    concerns and its frames ``first``..``last`` (rows of the take, inclusive)."""

    kind: str
    points: tuple
    first: int
    last: int

    def as_dict(self, offset=0):
        return {"kind": self.kind, "points": list(self.points), "first": self.first + offset,
                "last": self.last + offset}

    def summary(self, offset=1):
        """``swap LFHD / RFHD 120-180``: frames counted from ``offset``."""
        return (f"{self.kind} {' / '.join(self.points)} "
                f"{self.first + offset}-{self.last + offset}")


@dataclass(frozen=True)
class Repair:
    """The repaired positions, the samples changed (True where swapped back or cut) and the
    :class:`Fault` list."""

    positions: np.ndarray
    changed: np.ndarray
    faults: list = field(default_factory=list)


def rigid_partners(positions, config=FaultConfig()):
    """Per marker its ``config.partners`` steadiest partners: ``(index (P, k), distance (P, k),
    spread (P, k))``, the distance its median and the spread the median absolute deviation of
    the distance over the frames both are seen (metres)."""
    pos = np.asarray(positions, dtype=np.float64)
    step = max(1, len(pos) // config.stats_frames)
    sample = pos[::step]
    dist = np.linalg.norm(sample[:, :, None] - sample[:, None], axis=3)  # (t, P, P), NaN unseen
    with np.errstate(invalid="ignore"):
        median = _nanmedian0(dist)
        spread = _nanmedian0(np.abs(dist - median))
        seen = np.isfinite(dist).sum(axis=0)
    n = pos.shape[1]
    rank = np.where((seen >= 10) & ~np.eye(n, dtype=bool), spread, np.inf)
    rank = np.nan_to_num(rank, nan=np.inf)
    k = min(config.partners, n - 1)
    index = np.argsort(rank, axis=1, kind="stable")[:, :k]
    rows = np.arange(n)[:, None]
    return index, median[rows, index], spread[rows, index]


def carried(pos, points, src, dst, partners, spread, leave_out=None, by=None):
    """Where the rigid partners carry ``points`` seen at frames ``src`` to frames ``dst`` (all
    arrays of one length n): the weighted Kabsch fit of the partners (of ``by``, default the
    points themselves) seen at both frames (weights 1 / (spread + 2 mm)^2, ``leave_out`` a
    partner slot given no weight), applied to the point. NaN where fewer than three partners
    are seen at both frames."""
    by = points if by is None else by
    anchors = partners[by]  # (n, k)
    weight = 1.0 / (spread[by] + 0.002) ** 2
    if leave_out is not None:
        weight[:, leave_out] = 0.0
    a, b = pos[src[:, None], anchors], pos[dst[:, None], anchors]  # (n, k, 3)
    both = np.isfinite(a[..., 0]) & np.isfinite(b[..., 0]) & (weight > 0)
    weight = np.where(both, weight, 0.0)
    weight /= np.maximum(weight.sum(axis=1), 1e-300)[:, None]
    out = rigidly_carried(np.nan_to_num(a), np.nan_to_num(b), weight[..., None],
                          pos[src, points])
    return np.where((both.sum(axis=1) >= 3)[:, None], out, np.nan)


def find_faults(motion, config=None, should_cancel=None):
    """The swaps, spikes and ghosts of a marker take (:class:`Fault` list, by first frame) and
    the take repaired: :class:`Repair` (swaps exchanged back, spikes and ghosts cut).
    ``should_cancel`` is asked between its stages (KeyboardInterrupt once it says so)."""
    config = config or FaultConfig.fitted()

    def check():
        if should_cancel and should_cancel():
            raise KeyboardInterrupt

    pos = np.array(motion.positions, dtype=np.float64)
    changed = np.zeros(pos.shape[:2], dtype=bool)
    if motion.parents is not None or pos.shape[1] < 4 or len(pos) < 3:
        return Repair(pos, changed, [])  # a skeleton's joints cannot swap labels
    take = _Take(pos, config)
    check()
    faults = []
    for i, j, a, b in take.swaps():
        pos[a:b + 1, [i, j]] = pos[a:b + 1, [j, i]]
        changed[a:b + 1, [i, j]] = True
        faults.append(Fault("swap", (motion.names[i], motion.names[j]), a, b))
    if faults:
        check()
        take = _Take(pos, config, take.partners)
    check()
    for p, a, b in take.departures():
        kind = "spike" if b - a + 1 <= config.max_spike else "ghost"
        pos[a:b + 1, p] = np.nan
        changed[a:b + 1, p] = True
        faults.append(Fault(kind, (motion.names[p],), a, b))
    faults.sort(key=lambda f: (f.first, f.points))
    return Repair(pos, changed, faults)


def repaired(motion, config=None):
    """``(motion, faults)``: a marker take with its swaps exchanged back (flagged as filled, as
    a C3D writes them with residual 0) and its spikes and ghosts cut (gaps for the fill), and
    the :class:`Fault` list; a skeleton's take as it is."""
    repair = find_faults(motion, config)
    if not repair.faults:
        return motion, []
    filled = repair.changed & np.isfinite(repair.positions[..., 0])
    if motion.filled is not None:
        filled |= motion.filled & np.isfinite(repair.positions[..., 0])
    return motion.replace(positions=repair.positions, filled=filled), repair.faults


def said(fault):
    """One line for the user: ``swap LFHD / RFHD frames 121-181: labels exchanged back``."""
    done = "labels exchanged back" if fault.kind == "swap" else "cut, then filled as a gap"
    return (f"{fault.kind} {' / '.join(fault.points)} frames {fault.first + 1}-"
            f"{fault.last + 1}: {done}")


class _Take:
    """A marker take's rigid partners (:func:`rigid_partners`), each sample's jump (how far it
    lies from where its partners carry the frame before; the smallest with each partner left
    out in turn, so one faulty partner does not move a good marker) and the edges: jumps over
    the marker's limit, ``config.factor`` times its median jump and at least
    ``config.floor``."""

    def __init__(self, pos, config, partners=None):
        self.pos, self.config = pos, config
        self.partners = partners or rigid_partners(pos, config)
        self._homes = {}  # per marker: a reference frame and its usual place there
        frames, points = pos.shape[:2]
        t, p = np.meshgrid(np.arange(1, frames), np.arange(points), indexing="ij")
        t, p = t.ravel(), p.ravel()
        self.jump = np.full((frames, points), np.nan)
        self.jump[t, p] = self.miss(p, t - 1, t)
        typical = _nanmedian0(self.jump)  # the median: a long fault of a short take does not
        # raise it
        self.limit = np.maximum(config.floor, config.factor * np.nan_to_num(typical))
        with np.errstate(invalid="ignore"):
            t, p = np.nonzero(self.jump > config.floor)
        # a faulty partner: not this marker's jump
        self.jump[t, p] = self.miss(p, t - 1, t, robust=True)
        with np.errstate(invalid="ignore"):
            self.jumps = self.jump > config.floor
            self.edges = self.jump > self.limit

    def miss(self, points, src, dst, at=None, robust=False, by=None):
        """How far ``points`` at ``dst`` (or the positions ``at``) lie from where partners (of
        ``by``, default their own) carry them from ``src``; ``robust``: the least over each
        partner left out in turn."""
        index, _, spread = self.partners
        at = self.pos[dst, points] if at is None else at
        outs = [None] + (list(range(index.shape[1])) if robust else [])
        misses = [np.linalg.norm(at - carried(self.pos, points, src, dst, index, spread, out,
                                              by), axis=1) for out in outs]
        with _quiet():
            return np.nanmin(misses, axis=0) if robust else misses[0]

    def crossed(self, i, j, t, back=False):
        """Whether markers ``i`` and ``j`` each sit at ``t`` where the other is carried to from
        the frame before (their labels exchanged there; ``back``: exchanged before, so each
        label's place at ``t - 1`` is carried by the other's partners)."""
        src, dst, pair = np.array([t - 1, t - 1]), np.array([t, t]), np.array([i, j])
        # the exchange must fit within the limit and halve how far each is from its own place
        near = np.minimum(self.limit[[j, i]], 0.5 * self.jump[t, [j, i]])
        with np.errstate(invalid="ignore"):
            return bool((self.miss(pair, src, dst, self.pos[t, [j, i]], robust=True,
                                   by=pair[::-1] if back else pair) <= near).all())

    def swaps(self):
        """``(i, j, first, last)``: pairs of markers whose labels cross where both jump by more
        than ``config.floor`` and cross back at a later such frame (or stay crossed to the end
        of the stretch both are seen)."""
        found, jumps = [], self.jumps
        busy = np.zeros_like(jumps)
        for t, i in zip(*np.nonzero(jumps & (jumps.sum(axis=1) >= 2)[:, None])):
            if busy[t, i]:
                continue
            for j in np.flatnonzero(jumps[t] & ~busy[t]):
                if j == i or not self.crossed(i, j, t):
                    continue
                seen = np.isfinite(self.pos[t:, [i, j], 0]).all(axis=1)
                end = t + (int(np.argmin(seen)) if not seen.all() else len(seen))
                back = [u for u in range(t + 1, end)
                        if jumps[u, i] and jumps[u, j] and self.crossed(i, j, u, True)]
                last = (back[0] if back else end) - 1
                busy[t:last + 2, [i, j]] = True
                found.append((int(i), int(j), int(t), int(last)))
                break
        return found

    def departures(self):
        """``(p, first, last)``: a marker jumps by more than ``config.floor`` and comes back
        within ``config.max_spike`` frames to where its partners carry it from before (off all the
        while by at least half of its jump; a spike), or leaves at an edge and stays away
        (:meth:`_stepped`; a ghost: to where it comes back, or to the end of the stretch it is
        seen)."""
        found = []
        for p in range(self.pos.shape[1]):
            done = -1
            for t in np.flatnonzero(self.jumps[:, p]):
                if t <= done or not np.isfinite(self.pos[t - 1, p, 0]):
                    continue
                seen = np.isfinite(self.pos[t:, p, 0])
                end = t + (int(np.argmin(seen)) if not seen.all() else len(seen))  # exclusive
                last = self._spike(p, t, end)
                if last is None and self.edges[t, p] and self._stepped(p, t, end):
                    back = self._back(p, t, t + 1, end)
                    last = (back[0] if len(back) else end) - 1
                if last is None:
                    continue
                found.append((p, int(t), int(last)))
                done = last + 1  # its jump back
        return found

    def _spike(self, p, t, end):
        """The last frame of a spike of marker ``p`` from ``t`` (None where it is none)."""
        later = np.arange(t, min(end, t + self.config.max_spike + 1))
        away = self.miss(np.full(len(later), p), np.full(len(later), t - 1), later)
        size = self.jump[t, p]
        with np.errstate(invalid="ignore"):
            back = np.flatnonzero(away <= min(self.limit[p], 0.5 * size))
            if not len(back) or back[0] == 0 or (away[:back[0]] < 0.5 * size).any():
                return None
        return int(later[back[0]]) - 1

    def _stepped(self, p, t, end):
        """Whether marker ``p`` steps away at ``t`` and stays there: carried by its partners to
        frame ``t - 1``, its places over the ``config.max_spike`` frames before ``t`` gather at
        ``t - 1``'s and those from ``t`` on (to ``end``) gather away from it, by more than its
        limit, each within half of it (a drift of the partners' carry grows instead)."""
        span = self.config.max_spike
        frames = np.arange(max(0, t - span), min(end, t + span))
        frames = frames[np.isfinite(self.pos[frames, p, 0])]
        before, after = frames[frames < t], frames[frames >= t]
        if len(before) < span // 2 or len(after) < span // 2:
            return False
        places = carried(self.pos, np.full(len(frames), p), frames, np.full(len(frames), t - 1),
                         *self.partners[::2])
        off = np.linalg.norm(places - self.pos[t - 1, p], axis=1)
        half, away = 0.5 * self.limit[p], max(self.limit[p], self.config.ghost_floor)
        # and away from where it was before those frames too (not the end of a spike)
        early = t - span - 1
        if early >= 0 and np.isfinite(self.pos[early, p, 0]):
            from_early = self.miss(np.full(len(after), p), np.full(len(after), early), after)
        else:
            from_early = np.full(len(after), np.inf)
        with np.errstate(invalid="ignore"):
            return bool(np.nanmedian(off[frames < t]) < half
                        and np.nanmedian(off[frames >= t]) > away
                        and np.nanmedian(from_early) > away
                        and np.nanmedian(self._from_home(p, after))
                        > np.nanmedian(self._from_home(p, before)))

    def _from_home(self, p, frames):
        """How far marker ``p`` lies at ``frames`` from its usual place among its partners:
        each frame carried to one reference frame, against the median of every tenth frame."""
        if p not in self._homes:
            seen = np.flatnonzero(np.isfinite(self.pos[:, p, 0]))
            sample = seen[::10]
            ref = seen[len(seen) // 2]
            places = carried(self.pos, np.full(len(sample), p), sample,
                             np.full(len(sample), ref), *self.partners[::2])
            with _quiet():
                self._homes[p] = (ref, np.nanmedian(places, axis=0))
        ref, home = self._homes[p]
        places = carried(self.pos, np.full(len(frames), p), frames, np.full(len(frames), ref),
                         *self.partners[::2])
        return np.linalg.norm(places - home, axis=1)

    def _back(self, p, t, first, stop):
        """Frames ``first``..``stop - 1`` where marker ``p``, which left at ``t``, is back within
        its limit of where its partners carry it from ``t - 1``, and stays there over the next
        ``config.max_spike`` frames (in the median: another trajectory may pass by its place)."""
        later = np.arange(first, stop)
        away = self.miss(np.full(len(later), p), np.full(len(later), t - 1), later)
        with np.errstate(invalid="ignore"), _quiet():
            back = away <= self.limit[p]
            return [u for u, k in zip(later[back], np.flatnonzero(back))
                    if np.nanmedian(away[k:k + self.config.max_spike]) <= self.limit[p]]


def _nanmedian0(values):
    """``np.nanmedian(values, axis=0)`` by one sort (NaN last) instead of a loop over columns."""
    ordered = np.sort(values, axis=0)
    count = np.isfinite(values).sum(axis=0)
    low = np.take_along_axis(ordered, np.maximum((count - 1) // 2, 0)[None], axis=0)[0]
    high = np.take_along_axis(ordered, np.maximum(count // 2, 0)[None], axis=0)[0]
    return np.where(count > 0, 0.5 * (low + high), np.nan)


class _quiet(np.errstate):
    """numpy's warnings of all-NaN slices, silenced (a marker never seen has no statistics)."""

    def __init__(self):
        super().__init__(invalid="ignore")

    def __enter__(self):
        import warnings

        self._warnings = warnings.catch_warnings()
        self._warnings.__enter__()
        warnings.simplefilter("ignore", RuntimeWarning)
        return super().__enter__()

    def __exit__(self, *exc):
        super().__exit__(*exc)
        return self._warnings.__exit__(*exc)
