"""Several fills of one gap weighed together frame by frame, by how far the frame lies from a key.

Fills of a gap err in different ways: a curve carried on from the keys (``hermite``) is right
next to them and drifts with every frame away from them; a fill shaped by other motion
(``match``: the knowledge base; ``regress``: the rest of the body) is roughly as good all through
the gap and meets the keys only through an offset. Where several fills were made for copies of
a take's gaps (placed where the truth is known), the weights that refill those copies best,
frame by frame, are a least-squares problem per distance to the nearest key (and per gap
length): weights summing to one, minimising the copies' squared error given the covariance of
the fills' errors there (ridge-regularised towards equal weights). Errors that go together
(two fills that miss the same way) share a weight; an error another fill cancels gets a
negative one.

Arrays in, arrays out: a fill's error on a copy is any (frames, d) array (d: e.g. the joints it
moves, flattened); the table is ``(distances, lengths, fills)``.
"""

import numpy as np

#: distance of a frame from the nearest key, in seconds (the edges of the classes; 1, 2, 3, 5,
#: 8, 12, 18, 27, 40, 60, 90 frames at 120 fps)
DISTANCES = np.array([1, 2, 3, 5, 8, 12, 18, 27, 40, 60, 90]) / 120.0
#: gap lengths, in seconds (edges: 0, 20, 45, 90, 180 frames at 120 fps)
LENGTHS = np.array([0, 20, 45, 90, 180]) / 120.0


def keys_of(first, last, frames):
    """Where the keys of a gap over frames ``first``-``last`` of a take of ``frames`` frames
    are: ``"both"`` ends, or only ``"after"`` it (a gap at the clip's start) or ``"before"`` it
    (at its end). A gap over the whole take counts as ``"both"``."""
    at_start, at_end = first == 0, last == frames - 1
    return "both" if at_start == at_end else "after" if at_start else "before"


def from_keys(length, key="both"):
    """``(length,)`` int: each frame's distance in frames to the nearest key of a gap of
    ``length`` frames whose keys are where ``key`` says (:func:`keys_of`)."""
    t = np.arange(length)
    return {"both": np.minimum(t + 1, length - t), "before": t + 1, "after": length - t}[key]


def classes(length, fps, key="both"):
    """Per frame of a gap of ``length`` frames: its distance class (``(length,)`` int) and the
    gap's length class (int). ``key`` (:func:`keys_of`): at a clip end a frame's distance is to
    the one key, and the gap's length class that of a gap with keys at both ends and as far
    from them (twice as long)."""
    away = from_keys(length, key)
    near = np.clip(np.searchsorted(DISTANCES, away / fps + 1e-9, side="right") - 1, 0, None)
    span = length if key == "both" else 2 * length
    return near, int(np.searchsorted(LENGTHS, span / fps + 1e-9, side="right") - 1)


def moments(errors, fps):
    """The second moments of the fills' errors on one copy by class: ``(sums, counts)`` with
    sums ``(distances, lengths, fills, fills)`` (the summed products of the fills' errors,
    frame by frame) and counts ``(distances, lengths)`` (frames). ``errors``: (fills, frames,
    d), the fills' minus the truth."""
    errors = np.asarray(errors, dtype=float)
    fills, length = errors.shape[:2]
    near, size = classes(length, fps)
    sums = np.zeros((len(DISTANCES), len(LENGTHS), fills, fills))
    counts = np.zeros((len(DISTANCES), len(LENGTHS)))
    flat = errors.reshape(fills, length, -1)
    for k in np.unique(near):
        part = flat[:, near == k].reshape(fills, -1)
        sums[k, size] = part @ part.T
        counts[k, size] = (near == k).sum()
    return sums, counts


def weights(sums, counts, ridge):
    """Weights ``(distances, lengths, fills)`` summing to one per class: the least-squares
    combination given the error moments (plus ``ridge`` times their mean variance on the
    diagonal). Classes without copies take the nearest distance class of their length class,
    else the nearest length class; with no copies at all, equal weights."""
    n_near, n_size, fills = sums.shape[:3]
    table = np.full((n_near, n_size, fills), np.nan)
    for k in range(n_near):
        for j in range(n_size):
            if counts[k, j] == 0:
                continue
            moment = sums[k, j]
            moment = moment + (ridge * np.trace(moment) / fills + 1e-12) * np.eye(fills)
            w = np.linalg.solve(moment, np.ones(fills))
            table[k, j] = w / w.sum()
    seen = ~np.isnan(table[..., 0])
    for j in range(n_size):
        have = np.flatnonzero(seen[:, j])
        for k in np.flatnonzero(~seen[:, j]) if len(have) else ():
            table[k, j] = table[have[np.argmin(np.abs(have - k))], j]
    sizes = np.flatnonzero(seen.any(axis=0))
    for j in range(n_size):
        if not seen[:, j].any():
            table[:, j] = (table[:, sizes[np.argmin(np.abs(sizes - j))]] if len(sizes)
                           else 1.0 / fills)
    return table


def frame_weights(table, length, fps, key="both"):
    """(length, fills): the table's weights for each frame of a gap of ``length`` frames
    (``key``: as in :func:`classes`)."""
    near, size = classes(length, fps, key)
    return table[near, size]
