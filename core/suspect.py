"""Broken data that is present but wrong: sudden jumps and limb-length violations.

Optical systems swap or ghost markers and solvers flip joints; such samples are worse than gaps,
because interpolation and retrieval trust them. :func:`find_suspects` flags them so they can be
treated as gaps.
"""

import numpy as np

from .errors import GapFillError


def find_suspects(positions, fps, limbs=(), jump_factor=8.0, min_jump_speed=5.0,
                  limb_tolerance=0.1, min_limb_error=0.02):
    """Samples that jump or stretch a limb.

    Parameters
    ----------
    positions : ndarray, shape (frames, points, 3)
        Metres, NaN where missing.
    fps : float
    limbs : array-like, shape (limbs, 2)
        Point pairs whose distance should stay constant.
    jump_factor, min_jump_speed : float
        A step between two frames is a jump when its speed exceeds both ``min_jump_speed`` (m/s)
        and ``jump_factor`` times the point's median speed.
    limb_tolerance, min_limb_error : float
        A limb is violated when its length differs from its median by more than
        ``limb_tolerance`` of that median and by more than ``min_limb_error`` metres.

    Returns
    -------
    ndarray, shape (frames, points), bool
        True for suspect samples (both ends of a jump; both points of a violated limb).

    Examples
    --------
    >>> p = np.zeros((8, 1, 3)); p[:, 0, 0] = np.arange(8) * 0.01   # 1 m/s at 100 fps
    >>> p[4, 0, 0] = 0.5                                             # one frame 46 cm off
    >>> np.flatnonzero(find_suspects(p, 100.0)[:, 0]).tolist()
    [3, 4, 5]
    """
    pos = np.asarray(positions, dtype=float)
    if pos.ndim != 3 or pos.shape[2] != 3:
        raise GapFillError(f"positions must have shape (frames, points, 3), got {pos.shape}")
    if not np.isfinite(fps) or fps <= 0:
        raise GapFillError(f"fps must be positive, got {fps}")
    suspect = np.zeros(pos.shape[:2], dtype=bool)
    if pos.shape[0] >= 2:
        speed = np.linalg.norm(np.diff(pos, axis=0), axis=2) * fps  # NaN across gaps
        with np.errstate(all="ignore"):
            typical = np.nanmedian(np.where(np.isfinite(speed), speed, np.nan), axis=0)
        typical = np.nan_to_num(typical)
        jump = speed > np.maximum(min_jump_speed, jump_factor * typical)
        suspect[1:] |= jump
        suspect[:-1] |= jump
    for a, b in np.asarray(limbs, dtype=np.int64).reshape(-1, 2):
        length = np.linalg.norm(pos[:, a] - pos[:, b], axis=1)
        ok = np.isfinite(length)
        if ok.sum() < 3:
            continue
        error = np.abs(length - np.median(length[ok]))
        bad = ok & (error > limb_tolerance * np.median(length[ok])) & (error > min_limb_error)
        suspect[bad, a] = suspect[bad, b] = True
    return suspect
