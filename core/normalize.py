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
    """Per-frame root (frames, 3) and facing angle (frames,) of a motion, robust to gaps.

    Where the reference points are missing, the root and facing are carried rigidly from the
    nearest frames on either side that have them, using the points present in both (a 2-D
    Kabsch fit of the turn about Z), and the two estimates are blended across the run; with no
    usable points they are interpolated in time (held at clip ends).
    """
    pos = np.asarray(positions, dtype=np.float64)
    root = pos[:, list(reference.root)].mean(axis=1)
    hips = pos[:, list(reference.left)].mean(axis=1) - pos[:, list(reference.right)].mean(axis=1)
    angle = np.arctan2(hips[:, 1], hips[:, 0])
    known = np.isfinite(root).all(axis=1) & np.isfinite(angle)
    if not known.any():
        raise GapFillError("the root and hip points are missing in every frame: cannot normalise")
    unwrapped = np.zeros((len(angle), 1))
    unwrapped[known, 0] = np.unwrap(angle[known])
    root = _interpolate_missing(root, known)
    angle = _interpolate_missing(unwrapped, known)[:, 0]
    edges = np.flatnonzero(np.diff(np.concatenate([[0], (~known).astype(np.int8), [0]])))
    for a, b in zip(edges[::2], edges[1::2]):  # runs [a, b) without the reference points
        estimates = [e for e in (_carry(pos, root, angle, a - 1, a, b),
                                 _carry(pos, root, angle, b, a, b)) if e is not None]
        if len(estimates) == 2:
            w = ((np.arange(a, b) - (a - 1)) / (b - a + 1))[:, None]
            (r0, g0), (r1, g1) = estimates
            root[a:b] = r0 * (1 - w) + r1 * w
            angle[a:b] = g0 * (1 - w[:, 0]) + g1 * w[:, 0]
        elif estimates:
            root[a:b], angle[a:b] = estimates[0]
    return root, angle


def _carry(pos, root, angle, anchor, a, b):
    """Root and angle of frames a..b-1 carried rigidly from the known frame ``anchor``."""
    if anchor < 0 or anchor >= len(pos):
        return None
    seen = np.isfinite(pos[anchor, :, 0]) & np.isfinite(pos[a:b, :, 0]).all(axis=0)
    if seen.sum() < 2:
        return None
    ref = pos[anchor, seen]
    cur = pos[a:b][:, seen]
    c0, c = ref.mean(axis=0), cur.mean(axis=1)
    u = (ref - c0)[:, :2]
    v = cur[..., :2] - c[:, None, :2]
    turn = np.arctan2((u[:, 0] * v[..., 1] - u[:, 1] * v[..., 0]).sum(axis=1),
                      (u * v).sum(axis=2).sum(axis=1))
    offset = np.einsum("fij,j->fi", rotation_z(turn), root[anchor] - c0)
    return c + offset, angle[anchor] + turn


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
