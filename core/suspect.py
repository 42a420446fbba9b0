"""Broken data that is present but wrong: sudden jumps and limb-length violations.

Optical systems swap or ghost markers and solvers flip joints; such samples are worse than gaps,
because interpolation and retrieval trust them. :func:`find_suspects` flags them so they can be
treated as gaps.
"""

import numpy as np

from .errors import GapFillError


def find_suspects(positions, fps, limbs=(), jump_factor=8.0, min_jump=0.03,
                  limb_tolerance=0.1, min_limb_error=0.02):
    """Samples that jump or stretch a limb.

    Parameters
    ----------
    positions : ndarray, shape (frames, points, 3)
        Metres, NaN where missing.
    fps : float
        Frame rate (kept for the API; the jump test is per frame).
    limbs : array-like, shape (limbs, 2)
        Point pairs whose distance should stay constant.
    jump_factor, min_jump : float
        A sample jumps when it lies further than both ``min_jump`` metres and ``jump_factor``
        times the point's median from the midpoint of its two neighbouring frames. Smooth fast
        motion stays close to that midpoint (100 m/s^2 at 60 fps: 7 mm); a ghost frame or a
        label swap does not.
    limb_tolerance, min_limb_error : float
        A limb is violated when its length differs from its median by more than
        ``limb_tolerance`` of that median and by more than ``min_limb_error`` metres.

    Returns
    -------
    ndarray, shape (frames, points), bool
        True for suspect samples (a ghost frame and its neighbours; both points of a violated
        limb).

    Examples
    --------
    >>> p = np.zeros((30, 1, 3)); p[:, 0, 0] = np.arange(30) * 0.01  # 1 m/s at 100 fps
    >>> p[14, 0, 0] = 0.5                                             # one frame 36 cm off
    >>> np.flatnonzero(find_suspects(p, 100.0)[:, 0]).tolist()
    [13, 14, 15]
    """
    pos = np.asarray(positions, dtype=float)
    if pos.ndim != 3 or pos.shape[2] != 3:
        raise GapFillError(f"positions must have shape (frames, points, 3), got {pos.shape}")
    if not np.isfinite(fps) or fps <= 0:
        raise GapFillError(f"fps must be positive, got {fps}")
    suspect = np.zeros(pos.shape[:2], dtype=bool)
    if pos.shape[0] >= 3:
        deviation = np.linalg.norm(pos[1:-1] - 0.5 * (pos[:-2] + pos[2:]), axis=2)  # NaN at gaps
        seen = np.isfinite(deviation)
        typical = np.array([np.median(d[ok]) if ok.any() else 0.0
                            for d, ok in zip(deviation.T, seen.T)])
        with np.errstate(invalid="ignore"):
            suspect[1:-1] = deviation > np.maximum(min_jump, jump_factor * typical)
    for a, b in np.asarray(limbs, dtype=np.int64).reshape(-1, 2):
        length = np.linalg.norm(pos[:, a] - pos[:, b], axis=1)
        ok = np.isfinite(length)
        if ok.sum() < 3:
            continue
        error = np.abs(length - np.median(length[ok]))
        bad = ok & (error > limb_tolerance * np.median(length[ok])) & (error > min_limb_error)
        suspect[bad, a] = suspect[bad, b] = True
    return suspect
