"""Rotation helpers shared by the skeletal readers (vectorised over frames)."""

import numpy as np


def axis_rotation(axis, angles):
    """Rotation matrices about one of ``x``, ``y``, ``z`` for an array of angles in radians.

    Returns shape ``angles.shape + (3, 3)``.
    """
    angles = np.asarray(angles, dtype=float)
    c, s = np.cos(angles), np.sin(angles)
    one, zero = np.ones_like(c), np.zeros_like(c)
    if axis == "x":
        rows = [[one, zero, zero], [zero, c, -s], [zero, s, c]]
    elif axis == "y":
        rows = [[c, zero, s], [zero, one, zero], [-s, zero, c]]
    elif axis == "z":
        rows = [[c, -s, zero], [s, c, zero], [zero, zero, one]]
    else:
        raise ValueError(f"unknown rotation axis {axis!r}")
    return np.stack([np.stack(r, axis=-1) for r in rows], axis=-2)


def compose(axes, angles):
    """Matrix of rotations applied in the listed order as intrinsic rotations.

    ``compose("zyx", [a, b, c])`` is ``Rz(a) @ Ry(b) @ Rx(c)``: the convention of BVH channel
    lists. ``angles`` is a sequence of arrays of equal shape (radians).
    """
    result = None
    for axis, angle in zip(axes, angles):
        r = axis_rotation(axis, angle)
        result = r if result is None else result @ r
    if result is None:
        return np.broadcast_to(np.eye(3), (1, 3, 3)).copy()
    return result
