"""One entry point for every gap-filling method: :func:`fill`."""

import numpy as np

from . import baselines
from .errors import GapFillError
from .kb import match_names
from .motion import gap_runs

METHODS = ("knn", "auto", "linear", "spline", "svt", "pca", "intercorrelation")
NEEDS_KB = ("knn", "auto", "pca")
#: what ``auto`` chooses between, per point
AUTO_CANDIDATES = ("knn", "spline")
#: validation gaps per point for ``auto``
AUTO_PROBES = 3
#: ``auto`` leaves a point to knn unless another candidate's error on its copies is below this
#: share of knn's (a copy is a small sample; the KB method is the better bet when close)
AUTO_MARGIN = 0.5


def fill(motion, method="knn", kb=None, settings=None, progress=None, should_cancel=None,
         report=None):
    """Fill the gaps of a motion with the named method.

    Parameters
    ----------
    motion : Motion
    method : str
        One of :data:`METHODS`; ``knn`` (the knowledge-base method) is the default.
    kb : KnowledgeBase, optional
        Needed by ``knn`` and ``pca``.
    settings : KnnSettings, optional
        ``knn`` settings (K, weights, ...).

    Returns
    -------
    Motion
        Observed samples unchanged, missing ones filled and flagged in ``filled``.
    """
    if method not in METHODS:
        raise GapFillError(f"unknown method {method!r}; choose from {', '.join(METHODS)}")
    if method in NEEDS_KB and kb is None:
        raise GapFillError(f"method {method!r} needs a knowledge base (-k KB.npz)")
    if not motion.missing.any():
        return motion
    if method == "knn":
        from .recover import KnnSettings, fill_knn  # scipy.optimize only when needed

        return fill_knn(motion, kb, settings or KnnSettings(), progress=progress,
                        should_cancel=should_cancel, report=report)
    if method == "auto":
        return _fill_auto(motion, kb, settings, progress, should_cancel, report)
    if method == "pca":
        common, _ = match_names(kb, motion.names)
        sub = motion.select(common)
        kb_cols = [kb.names.index(n) for n in common]
        done = baselines.fill_global_pca(sub.positions, kb.poses[:, kb_cols],
                                         kb.reference_for(common))
        index = [motion.names.index(n) for n in common]
    else:
        func = {"linear": baselines.fill_linear, "spline": baselines.fill_spline,
                "svt": baselines.fill_svt, "intercorrelation": baselines.fill_intercorrelation}
        done = func[method](motion.positions)
        index = list(range(motion.n_points))
    out = motion.positions.copy()
    out[:, index] = done
    return _with_fill(motion, out)


def _with_fill(motion, out):
    """``motion`` with its missing samples taken from ``out`` and flagged as filled."""
    missing = motion.missing
    out = np.where(missing[..., None], out, motion.positions)
    filled = missing & ~np.isnan(out[..., 0])
    if motion.filled is not None:
        filled |= motion.filled
    return motion.replace(positions=out, filled=filled)


def _fill_auto(motion, kb, settings, progress, should_cancel, report):
    """Per point, the better of the knowledge-base fill and spline interpolation on this take.

    Each gap is copied (same points, same length) to nearby frames where its point is observed;
    both candidates fill those copies, and a point's gaps go to interpolation only where its
    error on the copies is below :data:`AUTO_MARGIN` of the knowledge base's (the knowledge base
    where a point has no copy; interpolation for points the knowledge base lacks). The KB method
    wins where the motion is fast or the gap long, interpolation where the motion is slow and the
    KB holds no similar poses.
    """
    report = report or (lambda message: None)
    progress = progress or (lambda fraction, message: None)
    missing = motion.missing
    probe = validation_gaps(missing, AUTO_PROBES)

    def run(name, target, p0, p1):
        def step(fraction, message):
            progress(p0 + (p1 - p0) * fraction, message)

        return fill(target, name, kb=kb, settings=settings, progress=step,
                    should_cancel=should_cancel).positions

    choice = np.zeros(motion.n_points, dtype=int)  # index into AUTO_CANDIDATES
    if probe.any():
        hidden = motion.replace(positions=np.where(probe[..., None], np.nan, motion.positions))
        errors = []
        for i, name in enumerate(AUTO_CANDIDATES):
            out = run(name, hidden, 0.5 * i / len(AUTO_CANDIDATES),
                      0.5 * (i + 1) / len(AUTO_CANDIDATES))
            sq = np.sum((out - motion.positions) ** 2, axis=2)
            # a candidate that leaves a copy unfilled (a point the KB lacks) cannot win there
            errors.append(np.where(probe, np.nan_to_num(sq, nan=np.inf), 0.0).sum(axis=0))
        errors = np.array(errors)
        errors[1:] /= AUTO_MARGIN  # knn (index 0) keeps a point unless clearly beaten
        seen = probe.any(axis=0)
        choice[seen] = np.argmin(errors[:, seen], axis=0)
    out = None
    for i, name in enumerate(AUTO_CANDIDATES):  # the first (knn) fills every point
        chosen = choice == i
        if out is not None and not chosen.any():
            continue
        result = run(name, motion, 0.5 + 0.5 * i / len(AUTO_CANDIDATES),
                     0.5 + 0.5 * (i + 1) / len(AUTO_CANDIDATES))
        out = result if out is None else np.where(chosen[None, :, None], result, out)
    gappy = missing.any(axis=0)
    for i, name in enumerate(AUTO_CANDIDATES):
        points = [motion.names[p] for p in np.flatnonzero(gappy & (choice == i))]
        if points:
            report(f"auto: {name} for {len(points)} points ({', '.join(points[:8])}"
                   f"{'...' if len(points) > 8 else ''})")
    return _with_fill(motion, out)


def validation_gaps(missing, per_point=3, margin=10):
    """Copies of the gaps where their points are observed: for each gap of each point, the
    nearest shift (by at least the gap's length plus ``margin``) that lands on observed frames
    with an observed frame on either side, at most ``per_point`` per point. A gap of several
    points at the same frames lands at the same shift for all of them when it can."""
    frames, points = missing.shape
    probe = np.zeros_like(missing)
    runs = sorted(gap_runs(missing), key=lambda r: (r[1], r[2], r[0]))
    count = np.zeros(points, dtype=int)
    for p, a, b in runs:
        if count[p] >= per_point:
            continue
        length = b - a + 1
        step = length + margin
        for k in range(1, frames // max(step, 1) + 2):
            for start in (a + k * step, a - k * step):
                lo, hi = start - 1, start + length + 1
                if lo < 0 or hi > frames:
                    continue
                if missing[lo:hi, p].any() or probe[lo:hi, p].any():
                    continue
                probe[start:start + length, p] = True
                count[p] += 1
                break
            else:
                continue
            break
    return probe
