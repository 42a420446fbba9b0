"""Motion matching: stretches of the knowledge base that move like the frames around a gap.

A gap in one bone of an armature take is a stretch of frames where most of the body is known.
Per-frame neighbours (the local models of :mod:`.recover`) see one pose at a time, and what they
predict jitters from frame to frame; what the knowledge base holds is motion. Here a query is a
stretch of frames - the gap and some context either side, where the gapped bones are known too -
and the answer the knowledge-base windows of consecutive poses whose known features move most
like it, played at a few speeds. The mean of the best windows' features is the prediction; it is
smooth because each window is real motion.
"""

import numpy as np

#: playback speeds of the knowledge base tried against the take
SPEEDS = (0.8, 0.9, 1.0, 1.12, 1.25)
#: windows averaged per stretch
TOP = 5


def match_windows(features, weight, kb_features, kb_source, fps, kb_fps, stretches,
                  speeds=SPEEDS, top=TOP):
    """Per stretch ``(lo, hi)`` of take frames: the mean, over the ``top`` best windows of the
    knowledge base, of their features at each frame lo..hi (an array (hi - lo + 1, items, d)),
    or None where the knowledge base has no window that long.

    ``features`` (frames, items, d) of the take, ``weight`` (frames, items) how much each counts
    (0: unknown); ``kb_features`` (poses, items, d) at ``kb_fps``, consecutive poses of one
    ``kb_source`` being consecutive frames. A window's cost is its weighted sum of squared
    feature differences over the stretch, sampled at the knowledge base's rate; windows of one
    source closer than half their width to a better one are left out.
    """
    flat = kb_features.reshape(len(kb_features), -1)
    sq = (kb_features.astype(np.float64) ** 2).sum(axis=2)
    out = []
    for lo, hi in stretches:
        found = []
        for speed in speeds:
            step = speed * fps / kb_fps  # take frames per knowledge-base pose
            times = lo + step * np.arange(int((hi - lo) / step) + 1)
            width = len(times)
            if width > len(flat):
                continue
            q, w = _sample(features, weight, times)
            cost = _window_costs(q, w, flat, sq)
            cost = np.where(kb_source[:len(cost)] == kb_source[width - 1:], cost, np.inf)
            for t in np.argsort(cost)[:top * 4]:
                if np.isfinite(cost[t]):
                    found.append((cost[t], speed, int(t), width))
        found.sort()
        chosen = []
        for c, speed, t, width in found:
            if all(kb_source[t] != kb_source[t2] or abs(t - t2) >= width // 2
                   for _, _, t2, _ in chosen):
                chosen.append((c, speed, t, width))
            if len(chosen) == top:
                break
        if not chosen:
            out.append(None)
            continue
        frames = np.arange(lo, hi + 1)
        mean = np.zeros((len(frames),) + kb_features.shape[1:])
        for _, speed, t, width in chosen:
            mean += at_times(kb_features[t:t + width], (frames - lo) * kb_fps / (speed * fps),
                             width - 1)
        out.append(mean / len(chosen))
    return out


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


def _sample(features, weight, times):
    """Features at fractional frame ``times`` (linear), and their weights (the smaller of the
    two frames')."""
    i0, i1, _ = brackets(times, len(features) - 1)
    return (at_times(np.nan_to_num(features), times, len(features) - 1),
            np.minimum(weight[i0], weight[i1]))


def _window_costs(q, w, flat, sq):
    """Per start pose, the weighted squared distance of the window to ``q``, over ``w``'s sum."""
    n, width = len(flat), len(q)
    qw = (q * w[..., None]).reshape(width, -1)
    d = w @ sq.T - 2.0 * (qw @ flat.T) + (w * (q ** 2).sum(axis=2)).sum(axis=1)[:, None]
    cost = np.zeros(n - width + 1)
    for k in range(width):
        cost += d[k, k:k + n - width + 1]
    return cost / max(w.sum(), 1e-12)
