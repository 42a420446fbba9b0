"""Motion matching: stretches of the knowledge base that move like the frames around a gap.

A gap in one bone of an armature take is a stretch of frames where most of the body is known.
Per-frame neighbours (the local models of :mod:`.recover`) see one pose at a time, and what they
predict jitters from frame to frame; what the knowledge base holds is motion. Here a query is a
stretch of frames - the gap and some context either side, where the gapped bones are known too -
and the answer the knowledge-base windows of consecutive poses whose known features move most
like it, played at a few speeds. The mean of the best windows' features is the prediction; it is
smooth because each window is real motion. The armature fill matches bone rotations
(:mod:`.bonefill`); :func:`fill_match` matches normalised joint or marker positions, for
``auto``'s points with long gaps (:mod:`.fill`).
"""

from dataclasses import dataclass

import numpy as np

from .kb import match_names
from .motion import blend_into_gaps, gap_runs, interpolate_rows, widened
from .normalize import denormalize, frames_of, normalize, reference_template


@dataclass(frozen=True)
class MatchSettings:
    """Motion matching's settings (tuned on non-test takes, docs/DESIGN.md)."""

    #: playback speeds of the knowledge base tried against the take
    speeds: tuple = (0.8, 0.9, 1.0, 1.12, 1.25)
    #: windows averaged per stretch
    top: int = 5
    #: ``lean``: the best windows, near copies of each other included, whose distinct ones make
    #: the second set
    lean: int = 10
    #: :func:`fill_match`: seconds of context either side of a gap, of the pieces matched, and
    #: of the chunks a long stretch is matched in (overlapping by a piece, cross-faded: memory
    #: stays bounded)
    context: float = 0.5
    piece: float = 1.0
    chunk: float = 4.0
    #: the knowledge base's poses are matched at most this many a second (a second of motion is
    #: seen well at 30 poses; the cost grows with the square of the rate)
    fps: float = 30.0
    #: the take itself is searched beside the knowledge base wherever it shows the points a
    #: stretch lacks (the same subject and style; the armatures' ``BoneConfig.match_own``)
    own: bool = True


def match_windows(features, weight, kb_features, kb_source, fps, kb_fps, stretches,
                  speeds=MatchSettings.speeds, top=MatchSettings.top, width=None, on_stretch=None,
                  kb_hidden=None,
                  needs=None, table=None, lean=False):
    """Per stretch ``(lo, hi)`` of take frames: the mean, over the ``top`` best windows of the
    knowledge base, of their features at each frame lo..hi (an array (hi - lo + 1, items, d)),
    or None where the knowledge base has no window that long.

    ``features`` (frames, items, d) of the take, ``weight`` (frames, items) how much each counts
    (0: unknown); ``kb_features`` (poses, items, d) at ``kb_fps``, consecutive poses of one
    ``kb_source`` being consecutive frames. A window's cost is its weighted sum of squared
    feature differences over the stretch, sampled at the knowledge base's rate; windows of one
    source closer than half their width to a better one are left out, and so are windows with a
    pose where ``kb_hidden`` (poses, items) marks an item the stretch needs (``needs``: per
    stretch, (items,) bool) as unknown: the take itself can be a source. ``width`` (seconds):
    match pieces of the stretch this long, a quarter of it apart, instead of the whole stretch,
    and blend their means with overlapping triangles (the first and last piece reach the
    stretch's ends in full). ``on_stretch(done)`` is called before each stretch (progress;
    it may raise to stop). ``table``: :func:`pose_table` of ``kb_features``, where the caller
    keeps it between calls. ``lean``: per piece, the mean of the ``top`` best windows is
    averaged, in equal parts, with the mean of the distinct ones among the
    ``MatchSettings.lean`` best, near copies of each other included (a window one pose or one
    speed off the best costs little more where the motion is smooth): where one window stands
    out, its near copies crowd the others out of the second set, and the mean leans to it.
    """
    if not stretches:  # the table below costs a pass over the whole knowledge base
        return []
    if table is None:
        table = pose_table(kb_features)
    features = np.nan_to_num(features)
    size = len(kb_features)
    out = []
    for done, (lo, hi) in enumerate(stretches):
        if on_stretch:
            on_stretch(done)
        hidden = None  # how many poses up to each one lack an item the stretch needs
        if kb_hidden is not None:
            hidden = np.concatenate([[0], np.cumsum(kb_hidden[:, needs[done]].any(axis=1))])
        frames = np.arange(lo, hi + 1)
        half = (hi - lo) / 2 if width is None else min(width * fps, hi - lo) / 2
        count = 1 if width is None else int(np.ceil((hi - lo - 2 * half) / (half / 2) - 1e-9)) + 1
        centres = np.linspace(lo + half, hi - half, count)
        found = [[] for _ in centres]
        for speed in speeds:
            step = speed * fps / kb_fps  # take frames per knowledge-base pose
            times = lo + step * np.arange(int((hi - lo) / step) + 1)
            if len(times) > size:
                continue
            pieces = []  # (piece, first row, last row) of the query
            for piece, centre in enumerate(centres):
                first = int(np.ceil((centre - half - lo) / step - 1e-9))
                last = min(int((centre + half - lo) / step + 1e-9), len(times) - 1)
                if last - first >= 1:
                    pieces.append((piece, first, last))
            if not pieces:
                continue
            q, w = _sample(features, weight, times)
            sums = _diagonal_sums(q, w, table, {r for _, first, last in pieces
                                                for r in (first - 1, last) if r >= 0})
            for piece, first, last in pieces:
                span = last - first + 1
                cost = sums[last][span - 1:].copy()
                if first:
                    cost[1:] -= sums[first - 1][:size - span]
                cost = cost / max(w[first:last + 1].sum(), 1e-12)
                cost = np.where(kb_source[:len(cost)] == kb_source[span - 1:], cost, np.inf)
                if hidden is not None:
                    cost[hidden[span:] > hidden[:len(cost)]] = np.inf
                best = np.argpartition(cost, min(top * 4, len(cost)) - 1)[:top * 4]
                for t in best[np.argsort(cost[best])]:
                    if np.isfinite(cost[t]):
                        found[piece].append((cost[t], speed, int(t), span, times[first]))
        total = np.zeros((len(frames),) + kb_features.shape[1:])
        share = np.zeros(len(frames))
        for piece, (centre, candidates) in enumerate(zip(centres, found)):
            candidates = sorted(candidates)
            sets = [_distinct(candidates, top, kb_source)]
            if not sets[0]:
                continue
            if lean:
                sets.append(_distinct(candidates[:MatchSettings.lean], top, kb_source))
            taper = np.clip(1 - np.abs(frames - centre) / max(half, 1e-9), 0, 1)
            taper[(frames < centre) & (piece == 0)] = 1.0
            taper[(frames > centre) & (piece == len(centres) - 1)] = 1.0
            near = taper > 0
            shares = {}  # each window's share of the mean (one in both sets: both shares)
            for chosen in sets:
                for window in chosen:
                    shares[window] = shares.get(window, 0.0) + 1 / (len(chosen) * len(sets))
            mean = 0.0
            for (_, speed, t, span, start), part in shares.items():  # pose t: frame ``start``
                poses = np.clip((frames[near] - start) * kb_fps / (speed * fps), 0, span - 1)
                mean = mean + part * at_times(kb_features[t:t + span], poses, span - 1)
            total[near] += taper[near, None, None] * mean
            share[near] += taper[near]
        out.append(total / share[:, None, None] if share.all() else None)
    return out


def _distinct(candidates, count, kb_source):
    """The first ``count`` of ``candidates`` (cost, speed, pose, span, start; best first) that
    are not within half their span of an earlier one chosen in the same source."""
    chosen = []
    for candidate in candidates:
        if all(kb_source[candidate[2]] != kb_source[c[2]] or
               abs(candidate[2] - c[2]) >= candidate[3] // 2 for c in chosen):
            chosen.append(candidate)
            if len(chosen) == count:
                break
    return chosen


def brackets(times, last):
    """The frames either side of fractional frame ``times`` (none past ``last``) and the share
    of the later one."""
    i0 = np.minimum(np.floor(times).astype(int), last)
    return i0, np.minimum(i0 + 1, last), times - i0


def at_times(values, times, last):
    """``values`` (frames, ...) at fractional frame ``times``, linearly (frames past ``last``
    held at it)."""
    i0, i1, part = brackets(times, last)
    part = part.reshape((-1,) + (1,) * (values.ndim - 1))
    return values[i0] * (1 - part) + values[i1] * part


def take_as_source(features, gaps, fps, kb_fps, kb_source):
    """The take's ``features`` (frames, items, d; no NaN) at the knowledge base's pose rate, as
    one more source after the knowledge base's (``kb_source``, per pose): its poses (float32),
    the source index of every pose and, per pose, the items ``gaps`` (frames, items) says are
    gapped there (:func:`match_windows`' ``kb_hidden``: a window of the take counts only where
    it shows what the stretch lacks)."""
    frames = len(features)
    times = np.arange(0, frames - 1 + 1e-9, fps / kb_fps)
    own = at_times(features, times, frames - 1).astype(np.float32)
    source = np.concatenate([kb_source, np.full(len(times), kb_source.max() + 1)])
    hidden = np.concatenate([np.zeros((len(kb_source), gaps.shape[1]), bool),
                             at_times(gaps.astype(float), times, frames - 1) > 0])
    return own, source, hidden


def pose_table(kb_features):
    """Each pose's features and their squares per item, float32 like the poses: one product per
    stretch and speed with it gives every term of the distances that involves the poses. Row by
    row, so the table of poses put together is the tables put together."""
    flat = kb_features.reshape(len(kb_features), -1)
    return np.concatenate([flat, (kb_features.astype(np.float64) ** 2).sum(axis=2)],
                          axis=1).astype(np.float32)


def _sample(features, weight, times):
    """Features (no NaN) at fractional frame ``times`` (linear), and their weights (the smaller
    of the two frames')."""
    i0, i1, _ = brackets(times, len(features) - 1)
    return at_times(features, times, len(features) - 1), np.minimum(weight[i0], weight[i1])


def _diagonal_sums(q, w, table, rows):
    """Per query row ``k`` of ``rows``: (poses,), entry ``j`` the weighted squared distance of
    query rows ..k to knowledge-base poses ..j laid along one diagonal (row k against pose j,
    row k - 1 against pose j - 1, ...), so a window of rows a..b starting at pose t costs
    ``[b][t + b - a] - [a - 1][t - 1]`` (the second term 0 where a or t is 0). ``table``: each
    pose's features and, per item, their sum of squares (:func:`pose_table`). The product with
    them is float32, like the poses (features of unit size: errors far below the costs that rank
    windows); the sums along the diagonals float64, carried one row at a time."""
    lhs = np.concatenate([(-2.0 * q * w[..., None]).reshape(len(q), -1), w], axis=1)
    product = lhs.astype(np.float32) @ table.T
    constant = (w * (q ** 2).sum(axis=2)).sum(axis=1)
    out, row, before = {}, np.empty(len(table)), np.empty(len(table))
    for k in range(max(rows) + 1):
        np.add(product[k], constant[k], out=row, dtype=np.float64)
        if k:
            row[1:] += before[:-1]
        if k in rows:
            out[k] = row.copy()
        row, before = before, row
    return out


def fill_match(motion, kb, points=None, should_cancel=None, settings=MatchSettings()):
    """Motion matching in position space: each stretch of frames with ``points`` missing
    ((points,) bool, default all; the other gaps stay as they are) and
    ``settings.context`` either side) takes the mean of the knowledge-base windows whose poses,
    normalised as the knowledge base's are, move most like the take's present points
    (:func:`match_windows`, pieces of ``settings.piece``; the take's own windows too wherever
    they show the points the stretch lacks: ``settings.own``), each gap offset to meet the
    observations at its ends. A whole limb gone for seconds takes real motion of a body that
    moved like this one; where few points are missing the per-frame models of ``knn`` fit the
    pose better. The motion with those gaps filled (NaN where no window matched).
    """
    common, _ = match_names(kb, motion.names)
    q = [motion.names.index(n) for n in common]
    stride = max(1, int(round(kb.fps / settings.fps)))
    kb_poses = kb.poses[::stride, [kb.names.index(n) for n in common]]
    reference = kb.reference_for(common)
    pos = motion.positions[:, q]
    missing = np.isnan(pos[..., 0])
    wanted = missing if points is None else missing & np.asarray(points)[q]
    root, angle = frames_of(pos, reference, reference_template(kb_poses, reference))
    features = np.nan_to_num(normalize(pos, root, angle))
    fps, frames = motion.fps, len(pos)
    margin, chunk, over = (int(round(s * fps)) for s in (settings.context, settings.chunk,
                                                           settings.piece))
    stretches, joins, needs = [], [], []
    for _, a, e in gap_runs(wanted.any(axis=1)[:, None]):
        lo, hi = max(0, a - margin), min(frames - 1, e + margin)
        while True:
            last = min(hi, lo + chunk - 1)
            stretches.append((lo, last))
            joins.append((lo > max(0, a - margin), last < hi))
            # the points gapped in the stretch's own gap frames (not its context)
            needs.append(wanted[max(lo, a):min(last, e) + 1].any(axis=0))
            if last >= hi:
                break
            lo = last - over + 1
    source, hidden = kb.source_index[::stride], None
    if settings.own:
        # the take at the knowledge base's pose rate, its other gaps interpolated; a window
        # of it counts only where it shows every point the stretch lacks
        seen = np.stack([interpolate_rows(features[:, i], ~missing[:, i])
                         for i in range(len(q))], axis=1)
        own, source, hidden = take_as_source(seen, missing, fps, kb.fps / stride, source)
        kb_poses = np.concatenate([kb_poses, own])
    found = match_windows(features, (~missing).astype(float), kb_poses, source, fps,
                          kb.fps / stride, stretches, width=settings.piece,
                          on_stretch=_cancel_check(should_cancel), kb_hidden=hidden,
                          needs=needs)
    total, share = np.zeros(pos.shape), np.zeros(frames)
    for (lo, hi), (after, before), mean in zip(stretches, joins, found):
        if mean is None:
            continue
        w = np.ones(hi - lo + 1)
        ramp = (np.arange(min(over, len(w))) + 1) / (over + 1)
        if after:  # cross-faded with the chunk before
            w[:len(ramp)] = ramp
        if before:
            w[len(w) - len(ramp):] = ramp[::-1]
        total[lo:hi + 1] += w[:, None, None] * mean
        share[lo:hi + 1] += w
    with np.errstate(invalid="ignore", divide="ignore"):
        pred = denormalize(total / share[:, None, None], root, angle)
    out = motion.positions.copy()
    out[:, q] = blend_into_gaps(pos, pred, wanted, widened(wanted))
    return motion.replace(positions=out)


def _cancel_check(should_cancel):
    def check(done):
        if should_cancel and should_cancel():
            raise KeyboardInterrupt
    return check
