"""Pose normalisation: root at the origin, hips facing a fixed direction (METHOD.md step 1).

Every pose is translated so its root is at the origin and turned about the vertical (Z) axis so
that the hip line (left hip minus right hip) points along +X. Which points are "root", "left hip"
and "right hip" is found by name for the point sets we know (CMU/HDM05 ASF skeletons, the CMU
MotionBuilder BVH and the 43-joint Daz BVH skeletons, the CMU/HDM05 41-marker set, Plug-in Gait
markers); shoulders stand in for hips when no hip pair is present.

Robust to gaps: per frame, the root is the mean of its reference points where all are present;
where only some are, the take's own pelvis (their median normalised positions) is fitted to
those present; with fewer than two it is carried from the frames around (see :func:`frames_of`).
A clip in which no frame shows the reference points raises :class:`GapFillError`.
"""

from dataclasses import dataclass

import numpy as np

from .errors import GapFillError
from .motion import interpolate_rows

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
    #: other left/right point pairs that can stand in for the hips' facing (see frames_of)
    pairs: tuple = ()

    def to_dict(self, names):
        return {k: [names[i] for i in getattr(self, k)] for k in ("root", "left", "right")}


def mirror_pairs(names):
    """(left, right) index pairs of points named alike but for a side prefix
    (``lButtock``/``rButtock``, ``LSHO``/``RSHO``, ``LeftArm``/``RightArm``)."""
    index = {n: i for i, n in enumerate(names)}
    pairs = []
    for name, i in index.items():
        for left, right in (("Left", "Right"), ("left", "right"), ("L", "R"), ("l", "r")):
            if name.startswith(left) and len(name) > len(left):
                other = right + name[len(left):]
                if other in index:
                    pairs.append((i, index[other]))
                break
    return pairs


def find_reference(names):
    """The :class:`Reference` for a point set, or a clear :class:`GapFillError`."""
    lower = {n.lower(): i for i, n in enumerate(names)}

    def idx(group):
        return tuple(lower[g] for g in group) if all(g in lower for g in group) else None

    for root, left, right in _REFERENCES:
        r, l, rr = idx(root), idx(left), idx(right)
        if r and not (l and rr):  # a root without hips: try the shoulders for the facing
            for sl, sr in _SHOULDERS:
                if idx(sl) and idx(sr):
                    l, rr = idx(sl), idx(sr)
                    break
        if r and l and rr:
            used = {*r, *l, *rr}
            pairs = tuple(p for p in mirror_pairs(names) if not used & set(p))
            return Reference(r, l, rr, pairs)
    raise GapFillError(
        "cannot orient this point set: no known root and left/right hip (or shoulder) points "
        f"among {', '.join(names[:12])}{'...' if len(names) > 12 else ''}")


def frames_of(positions, reference, template=None, own_frames=5):
    """Per-frame root (frames, 3) and facing angle (frames,) of a motion, robust to gaps.

    Where some reference points are missing, a template of them (their median normalised
    positions over the frames that show them all, or, in fewer than
    ``own_frames`` frames, ``template``: e.g. a knowledge base's median pose) is
    fitted rigidly (turn about Z, shift) to those present in each frame that shows at least two.
    Where fewer are seen, the root is carried rigidly from the nearest frames on either side that
    have it (a 2-D Kabsch fit of the points present in both), and the facing follows the present
    mirror pair (e.g. the buttocks or the shoulders) whose line keeps the steadiest angle to the
    hip line, with that angle's offset interpolated across the run. With no usable points both
    are interpolated in time (held at clip ends).
    """
    pos = np.asarray(positions, dtype=np.float64)
    root = pos[:, list(reference.root)].mean(axis=1)
    angle = _line_angle(pos, reference.left, reference.right)
    known = np.isfinite(root).all(axis=1) & np.isfinite(angle)
    if known.sum() >= own_frames:  # the take's own: its markers sit where they sit
        template = reference_template(normalize(pos[known], root[known], angle[known]),
                                      reference)
    if template is not None:  # frames that show some of the reference points
        fit_root, fit_angle, fitted = _fit_template(pos, reference, template)
        fitted &= ~known
        root[fitted], angle[fitted] = fit_root[fitted], fit_angle[fitted]
        known |= fitted
    if not known.any():
        raise GapFillError("the root and hip points are missing in every frame: cannot normalise")
    unwrapped = np.zeros(len(angle))
    unwrapped[known] = np.unwrap(angle[known])
    root = interpolate_rows(root, known)
    angle = interpolate_rows(unwrapped[:, None], known)[:, 0]
    edges = np.flatnonzero(np.diff(np.concatenate([[0], (~known).astype(np.int8), [0]])))
    # steadiness of each mirror pair's angle against the hip line, over the known frames
    offsets, spread = [], []
    for left, right in reference.pairs:
        off = angle - _line_angle(pos, (left,), (right,))
        ok = known & np.isfinite(off)
        off = np.where(ok, np.angle(np.exp(1j * off)), np.nan)
        offsets.append(off)
        spread.append(np.nanstd(off) if ok.sum() > 1 else np.inf)
    for a, b in zip(edges[::2], edges[1::2]):  # runs [a, b) without the reference points
        estimates = [e for e in (_carry(pos, root, a - 1, a, b), _carry(pos, root, b, a, b))
                     if e is not None]
        if len(estimates) == 2:
            w = ((np.arange(a, b) - (a - 1)) / (b - a + 1))[:, None]
            root[a:b] = estimates[0] * (1 - w) + estimates[1] * w
        elif estimates:
            root[a:b] = estimates[0]
        for k in np.argsort(spread):
            left, right = reference.pairs[k]
            anchors = [t for t in (a - 1, b) if 0 <= t < len(pos) and np.isfinite(offsets[k][t])]
            pair = _line_angle(pos[a:b], (left,), (right,))
            if not anchors or not np.isfinite(pair).all() or not np.isfinite(spread[k]):
                continue
            off = np.interp(np.arange(a, b), anchors, [offsets[k][t] for t in anchors])
            estimate = np.unwrap(pair + off)
            # continue the unwrapped angle of the frame before (or after) the run
            start = angle[a - 1] if a > 0 else angle[b]
            angle[a:b] = estimate + 2 * np.pi * np.round((start - estimate[0]) / (2 * np.pi))
            # the root keeps its offset from the pair's midpoint in the body frame
            mid = (pos[:, left] + pos[:, right]) / 2
            body = [rotation_z(-angle[t]) @ (root[t] - mid[t]) for t in anchors]
            body = np.stack([np.interp(np.arange(a, b), anchors, [o[i] for o in body])
                             for i in range(3)], axis=1)
            root[a:b] = mid[a:b] + np.einsum("fij,fj->fi", rotation_z(angle[a:b]), body)
            break
    return root, angle


def reference_points(reference):
    """The indices of the root, left and right points, each once, sorted."""
    return sorted({*reference.root, *reference.left, *reference.right})


def reference_template(poses, reference):
    """The median normalised positions of :func:`reference_points` over (knowledge-base) poses:
    the ``template`` of :func:`frames_of`."""
    return np.median(np.asarray(poses)[:, reference_points(reference)], axis=0)


def _fit_template(pos, reference, template):
    """Root and angle of each frame from a rigid fit (turn about Z, shift) of the template
    (normalised positions of :func:`reference_points`) to those of them present; frames with
    fewer than two present stay unknown (NaN)."""
    pts = reference_points(reference)
    p = pos[:, pts]
    seen = np.isfinite(p[..., 0])
    known = seen.sum(axis=1) >= 2
    w = seen[..., None].astype(float)
    count = np.maximum(w.sum(axis=1), 1)
    cp = np.nansum(p * w, axis=1) / count  # centroids of the present points, frame and template
    co = (template[None] * w).sum(axis=1) / count
    u = (template[None] - co[:, None])[..., :2]
    v = np.nan_to_num(p - cp[:, None])[..., :2]
    angle = np.arctan2((w[..., 0] * (u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0])).sum(axis=1),
                       (w * u * v).sum(axis=(1, 2)))
    root = cp - np.einsum("fij,fj->fi", rotation_z(angle), co)
    root[~known], angle[~known] = np.nan, np.nan
    return root, angle, known


def _line_angle(pos, left, right):
    """Angle about Z of the line from the right points' mean to the left points' mean."""
    line = pos[:, list(left)].mean(axis=1) - pos[:, list(right)].mean(axis=1)
    return np.arctan2(line[:, 1], line[:, 0])


def _carry(pos, root, anchor, a, b):
    """Root of frames a..b-1 carried rigidly from the known frame ``anchor`` (2-D Kabsch)."""
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
    return c + np.einsum("fij,j->fi", rotation_z(turn), root[anchor] - c0)


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
