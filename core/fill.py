"""One entry point for every gap-filling method: :func:`fill`."""

import numpy as np

from . import baselines
from .errors import GapFillError
from .kb import match_names

METHODS = ("knn", "linear", "spline", "svt", "pca", "intercorrelation")
NEEDS_KB = ("knn", "pca")


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
    out[:, index] = np.where(np.isnan(out[:, index]), done, out[:, index])
    filled = motion.missing & ~np.isnan(out[..., 0])
    if motion.filled is not None:
        filled |= motion.filled
    return motion.replace(positions=out, filled=filled)
