"""Which way is up, from the data rather than the file's word for it.

A C3D says which axis is up (``POINT:Y_SCREEN``) and many files lie: a take whose data is Y-up
but whose header says nothing is read lying on its side, and every method that normalises poses
(the knowledge base's, ``local-spline``) then fills it several times worse without a word. People
in motion capture stand: the head is above the feet. :func:`standing_axis` finds that direction
(by point names: head, neck or C7 against toes, ankles, heels or feet; without such names, the
axis along which the body's extent is largest), :func:`upright_warning` says when it is not the
Z-up the file was read as, :func:`turn_up` reads the take again as the user says and
:func:`stand_up` as the data says.
"""

import re
import warnings

import numpy as np

from .motion import y_up_to_z_up, z_up_to_y_up

_HEAD = re.compile(r"(head|^[lr][fb]hd$|^c7$|neck)", re.I)
_FEET = re.compile(r"(toe|foot|feet|ank|heel|^[lr]hee$|mt5)", re.I)
#: how clearly the data must point along another axis before a warning (cosine)
CLEAR = 0.8
AXES = "xyz"


def standing_axis(positions, names):
    """``(axis, sign, clarity)`` of the direction the body stands along in ``positions`` (frames,
    points, 3): from the feet to the head when the names show both (sign +1 or -1), else the
    axis of the body's largest median extent (sign 0: unknown). ``clarity``: that axis's share
    of the direction (cosine), 0 when nothing can be said.

    >>> pos = np.zeros((2, 2, 3)); pos[:, 0, 1] = 1.7  # the head 1.7 along +Y above the toe
    >>> standing_axis(pos, ["head", "toe"])
    (1, 1, 1.0)
    """
    pos = np.asarray(positions, dtype=np.float64)
    head = [i for i, n in enumerate(names) if _HEAD.search(n)]
    feet = [i for i, n in enumerate(names) if _FEET.search(n)]
    with np.errstate(invalid="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN frames simply do not count
        if head and feet:
            up = np.nanmedian(np.nanmean(pos[:, head], axis=1) - np.nanmean(pos[:, feet], axis=1),
                              axis=0)
            signed = True
        else:
            up = np.nanmedian(np.nanmax(pos, axis=1) - np.nanmin(pos, axis=1), axis=0)
            signed = False
    if not np.isfinite(up).all() or not np.linalg.norm(up) > 0:
        return 2, 0, 0.0
    axis = int(np.argmax(np.abs(up)))
    clarity = float(abs(up[axis]) / np.linalg.norm(up))
    return axis, int(np.sign(up[axis])) if signed else 0, clarity


def upright_warning(motion):
    """A one-line warning when the motion's data stands along another axis than the Z up it was
    read as (the file's ``up_axis`` said so), naming the ``--up`` that reads it standing; None
    when it stands up or nothing clear can be said."""
    axis, sign, clarity = standing_axis(motion.positions, motion.names)
    if clarity < CLEAR or (axis == 2 and sign >= 0):
        return None
    # the direction in the file's own axes, before the reader turned a Y-up file
    direction = np.zeros(3)
    direction[axis] = sign or 1
    in_file = z_up_to_y_up(direction) if motion.up_axis == "y" else direction
    file_axis = int(np.argmax(np.abs(in_file)))
    file_sign = int(np.sign(in_file[file_axis])) if sign else 0
    name = AXES[file_axis]
    where = f"{'-' if file_sign < 0 else '+' if file_sign > 0 else ''}{name.upper()}"
    if name == motion.up_axis:  # upside down along the axis the file names: nothing to offer
        return (f"the take stands along {where} of the file, upside down for its "
                f"{motion.up_axis.upper()}-up header: check the export")
    hint = f"; read it with --up {name}" if name in ("y", "z") and file_sign >= 0 else ""
    return (f"the data stands along {where} of the file, but it was read as "
            f"{motion.up_axis.upper()}-up (the file's header): the take lies on its side and "
            f"fills badly{hint}")


def turn_up(motion, up):
    """The motion read as if its file said ``up`` (``"y"`` or ``"z"``) is the up axis."""
    if up == motion.up_axis:
        return motion
    if up not in ("y", "z"):
        raise ValueError(f"up must be 'y' or 'z', not {up!r}")
    def turned(points):
        raw = z_up_to_y_up(points) if motion.up_axis == "y" else points
        return y_up_to_z_up(raw) if up == "y" else raw

    rest = None if motion.rest is None else turned(motion.rest)
    return motion.replace(positions=turned(motion.positions), up_axis=up, rest=rest)


def stand_up(motion):
    """``(motion, message)``: the motion turned to the up axis that makes it stand, where the
    file's header has it lying on its side (message says so), else unchanged with
    :func:`upright_warning`'s message (None when it stands)."""
    warning = upright_warning(motion)
    if warning is None:
        return motion, None
    up = "z" if motion.up_axis == "y" else "y"
    turned = turn_up(motion, up)
    axis, sign, clarity = standing_axis(turned.positions, turned.names)
    if axis == 2 and sign >= 0 and clarity >= CLEAR:
        return turned, f"{warning.split(';')[0]}: turned to {up.upper()}-up"
    return motion, warning
