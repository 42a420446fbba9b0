"""Distances a take keeps exactly, kept by its fill.

A skeleton's joints keep their bones' lengths to the rounding of the file, and the joints on one
segment their distances to each other; so may a rigid cluster of markers that the capture
software solved (:func:`~.baselines.steady_pairs` finds them on the frames where both ends are
seen). A blend of two estimates, a spline, a rigid fill from donors on another segment do not,
and the knowledge base's energy only pulls towards a bone's length. :func:`keep_distances` moves
the filled samples back onto those distances, each pair's correction shared by its two ends by
how uncertain each is (a seen sample does not move), sweeping over the pairs one after the other
(Gauss-Seidel, as position-based dynamics does). A joint between two seen ones keeps only its
turn about their line to be wrong; one on a seen segment, nothing. Markers on one segment keep
their distances only within a few millimetres (skin slides): a pair is then a measurement of its
distance with that spread, weighed against the ends' uncertainties (docs/DESIGN.md); as a body
turns its joints such a distance drifts, so a gap may aim part of the way from the take's mean
distance to the pair's own about the gap.
"""

import numpy as np

def keep_distances(positions, missing, uncertainty, pairs, lengths, spreads=None,
                   sweeps=20, local=0.0, seen=1.0):
    """``positions`` with its ``missing`` samples moved so that the points of each pair of
    ``pairs`` lie ``lengths`` apart, as far as each pair's ``spreads`` lets it.

    Parameters
    ----------
    positions : ndarray, shape (frames, points, 3)
        A fill: NaN where it has none (those samples and their pairs are left alone).
    missing : ndarray, shape (frames, points), bool
        The filled samples: the only ones that move.
    uncertainty : ndarray, shape (frames, points)
        The expected squared error of each filled sample: of a pair's correction, each end takes
        its share of the two ends' sum (0: it keeps its place).
    pairs : ndarray, shape (pairs, 2), int
    lengths : ndarray, shape (pairs,)
    spreads : ndarray, shape (pairs,), optional
        How far each pair's distance strays (SD, metres): a pair is kept as a measurement of
        that variance against the ends' uncertainties (compliant position-based dynamics,
        XPBD); None: every distance exactly.
    local : float
        At each frame where it moves, a pair aims this share of the way from its length to its
        own distance there, interpolated linearly from the frames either side where both its
        ends are seen (held beyond the first and last such frame): 0 the length alone.
    seen : float
        At a frame where one of its ends is seen (not ``missing``), a pair's variance from
        ``spreads`` counts this many times over (1: as it is).

    Returns
    -------
    ndarray, shape (frames, points, 3), float64: a new array.

    >>> pos = np.array([[[0.0, 0, 0], [2.0, 0, 0]]])
    >>> keep_distances(pos, np.array([[False, True]]), np.ones((1, 2)), np.array([[0, 1]]),
    ...                np.array([1.0]))[0, 1].tolist()
    [1.0, 0.0, 0.0]
    >>> keep_distances(pos, np.array([[False, True]]), np.ones((1, 2)), np.array([[0, 1]]),
    ...                np.array([1.0]), spreads=np.array([1.0]))[0, 1].round(6).tolist()
    [1.5, 0.0, 0.0]
    >>> keep_distances(pos, np.array([[False, True]]), np.ones((1, 2)), np.array([[0, 1]]),
    ...                np.array([1.0]), spreads=np.array([1.0]), seen=3.0)[0, 1].round(6).tolist()
    [1.75, 0.0, 0.0]
    """
    out = np.array(positions, dtype=np.float64)
    filled = np.isfinite(out[..., 0])
    share = np.where(missing & filled, uncertainty, 0.0)
    share[~filled] = np.nan
    compliance = np.zeros(len(pairs)) if spreads is None else np.asarray(spreads) ** 2
    steps = []
    for (a, b), length, alpha in zip(pairs, lengths, compliance):
        total = share[:, a] + share[:, b]
        frames = np.flatnonzero(total > 0)  # NaN (a sample without a fill) compares False
        if frames.size:
            if local:  # part of the way to the pair's own distance about the gap
                own = _own_distance(out, missing, a, b, frames, length)
                length = length + local * (own - length)[:, None]
            one_seen = ~(missing[frames, a] & missing[frames, b])
            steps.append((a, b, length, frames, share[frames, a][:, None],
                          share[frames, b][:, None],
                          (alpha * np.where(one_seen, seen, 1.0))[:, None],
                          np.zeros((frames.size, 1))))
    for _ in range(sweeps):
        for a, b, length, frames, share_a, share_b, alpha, pull in steps:
            apart = out[frames, a] - out[frames, b]
            distance = np.linalg.norm(apart, axis=1)[:, None]
            # the pair's pull so far counts against its compliance (XPBD's multiplier)
            more = (length - distance - alpha * pull) / (share_a + share_b + alpha)
            pull += more
            toward = apart / np.maximum(distance, 1e-9)
            out[frames, a] += share_a * more * toward
            out[frames, b] -= share_b * more * toward
    return out


def _own_distance(positions, missing, a, b, frames, length):
    """The distance of points ``a`` and ``b`` at ``frames``, interpolated linearly from the
    frames where both are seen (held beyond the first and last; ``length`` where they are never
    seen together)."""
    distance = np.linalg.norm(positions[:, a] - positions[:, b], axis=1)
    seen = np.flatnonzero(~(missing[:, a] | missing[:, b]) & np.isfinite(distance))
    if not seen.size:
        return np.full(frames.size, float(length))
    return np.interp(frames, seen, distance[seen])
