"""Pose normalisation: root at the origin, hips facing a fixed direction (METHOD.md step 1).

Every pose is translated so its root is at the origin and turned about the vertical (Z) axis so
that the hip line (left hip minus right hip) points along +X. Which points are "root", "left hip"
and "right hip" is found by name for the point sets we know (CMU/HDM05 ASF skeletons, the CMU
MotionBuilder BVH and the 43-joint Daz BVH skeletons, the CMU/HDM05 41-marker set, Plug-in Gait
markers); shoulders stand in for hips when no hip pair is present.

Robust to gaps: per frame, the root is the mean of its reference points where all are present;
where they are missing it is interpolated in time from the frames that have them (held constant
before the first and after the last), and likewise the facing angle (unwrapped). A clip in which
no frame shows the reference points raises :class:`GapFillError`.
"""

from dataclasses import dataclass

import numpy as np

from .errors import GapFillError

# (root point names, left-side names, right-side names): the first whose names are all present
# in a point set is used. Case-insensitive. Lists mean "the mean of these points".
_REFERENCES = [
    (["root"], ["lhipjoint"], ["rhipjoint"]),  # CMU / HDM05 ASF (bone tips = hip joints)
    (["hips"], ["leftupleg"], ["rightupleg"]),  # CMU MotionBuilder-friendly BVH, Mixamo-like
    (["hip"], ["lthigh"], ["rthigh"]),  # Daz-friendly BVH (43 joints)
    (["lfwt", "rfwt", "lbwt", "rbwt"], ["lfwt", "lbwt"], ["rfwt", "rbwt"]),  # CMU/HDM05 markers
    (["lasi", "rasi", "lpsi", "rpsi"], ["lasi", "lpsi"], ["rasi", "rpsi"]),  # Plug-in Gait
    (["pelvis"], ["l_hip"], ["r_hip"]),
]
_SHOULDERS = [(["lclavicle"], ["rclavicle"]), (["leftshoulder"], ["rightshoulder"]),
              (["lcollar"], ["rcollar"]), (["lsho"], ["rsho"])]


@dataclass(frozen=True)
class Reference:
    """Indices of the points that define a pose's root and facing."""

    root: tuple
    left: tuple
    right: tuple

    def to_dict(self, names):
        return {k: [names[i] for i in getattr(self, k)] for k in ("root", "left", "right")}


def find_reference(names):
    """The :class:`Reference` for a point set, or a clear :class:`GapFillError`."""
    lower = {n.lower(): i for i, n in enumerate(names)}

    def idx(group):
        return tuple(lower[g] for g in group) if all(g in lower for g in group) else None

    for root, left, right in _REFERENCES:
        r, l, rr = idx(root), idx(left), idx(right)
        if r and l and rr:
            return Reference(r, l, rr)
        if r:  # a root without hips: try the shoulders for the facing
            for sl, sr in _SHOULDERS:
                if idx(sl) and idx(sr):
                    return Reference(r, idx(sl), idx(sr))
    raise GapFillError(
        "cannot orient this point set: no known root and left/right hip (or shoulder) points "
        f"among {', '.join(names[:12])}{'...' if len(names) > 12 else ''}")


def _interpolate_missing(values, valid):
    """Fill rows of ``values`` (frames, k) where ``valid`` is False by linear interpolation."""
    if valid.all():
        return values
    frames = np.arange(len(values))
    out = values.copy()
    for k in range(values.shape[1]):
        out[~valid, k] = np.interp(frames[~valid], frames[valid], values[valid, k])
    return out


def frames_of(positions, reference):
    """Per-frame root (frames, 3) and facing angle (frames,) of a motion, gaps bridged in time."""
    pos = np.asarray(positions, dtype=np.float64)
    root = pos[:, list(reference.root)].mean(axis=1)
    hips = pos[:, list(reference.left)].mean(axis=1) - pos[:, list(reference.right)].mean(axis=1)
    angle = np.arctan2(hips[:, 1], hips[:, 0])
    ok_root = np.isfinite(root).all(axis=1)
    ok_angle = np.isfinite(angle)
    if not ok_root.any() or not ok_angle.any():
        raise GapFillError("the root and hip points are missing in every frame: cannot normalise")
    unwrapped = np.zeros((len(angle), 1))
    unwrapped[ok_angle, 0] = np.unwrap(angle[ok_angle])
    return _interpolate_missing(root, ok_root), _interpolate_missing(unwrapped, ok_angle)[:, 0]


def rotation_z(angle):
    """Rotation matrices about Z, shape angle.shape + (3, 3)."""
    c, s = np.cos(angle), np.sin(angle)
    z, o = np.zeros_like(c), np.ones_like(c)
    return np.stack([np.stack([c, -s, z], -1), np.stack([s, c, z], -1), np.stack([z, z, o], -1)], -2)


def normalize(positions, root, angle):
    """Poses in the normalised frame: ``R_z(-angle) (p - root)``; NaN stays NaN."""
    rot = rotation_z(-np.asarray(angle))
    return np.einsum("fij,fnj->fni", rot, np.asarray(positions) - root[:, None, :])


def denormalize(normalised, root, angle):
    """Inverse of :func:`normalize`."""
    rot = rotation_z(np.asarray(angle))
    return np.einsum("fij,fnj->fni", rot, np.asarray(normalised)) + root[:, None, :]
