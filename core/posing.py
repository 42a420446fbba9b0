"""Bone transforms from joint positions: forward kinematics run backwards, for armatures.

An armature is a tree of bones. Bone ``b`` has a rest matrix ``rest[b]`` (4x4, armature space,
Blender's ``Bone.matrix_local``) and, per frame, a basis matrix (location, rotation, scale keys,
Blender's ``PoseBone.matrix_basis``). Its pose matrix is::

    pose[b] = pose[parent] @ inv(rest[parent]) @ rest[b] @ basis[b]     (root: rest[b] @ basis[b])

and its head (the joint) is ``pose[b][:3, 3]``. :func:`solve_pose` finds basis matrices whose
heads land on given joint positions: the location of bones that may move, and the rotation that
turns each bone's children onto their targets (one child: the smallest such turn from a reference
pose, which keeps the twist the reference had; two or more: the best rigid fit).
"""

import numpy as np

from .errors import GapFillError


def rotation_between(a, b):
    """The smallest rotations taking directions ``a`` to directions ``b``.

    Parameters
    ----------
    a, b : ndarray, shape (..., 3)
        Non-zero vectors (need not be unit length).

    Returns
    -------
    ndarray, shape (..., 3, 3)

    >>> r = rotation_between(np.array([1.0, 0, 0]), np.array([0, 2.0, 0]))
    >>> np.round(r @ [1.0, 0, 0], 6).tolist()
    [0.0, 1.0, 0.0]
    """
    a = a / np.linalg.norm(a, axis=-1, keepdims=True)
    b = b / np.linalg.norm(b, axis=-1, keepdims=True)
    v = np.cross(a, b)
    c = np.sum(a * b, axis=-1)
    k = np.zeros(a.shape[:-1] + (3, 3))
    k[..., 0, 1], k[..., 0, 2], k[..., 1, 2] = -v[..., 2], v[..., 1], -v[..., 0]
    k[..., 1, 0], k[..., 2, 0], k[..., 2, 1] = v[..., 2], -v[..., 1], v[..., 0]
    opposite = c < -1 + 1e-9
    scale = np.where(opposite, 0.0, 1.0 / np.where(opposite, 1.0, 1.0 + c))
    r = np.eye(3) + k + (k @ k) * scale[..., None, None]
    if opposite.any():  # half turn about an axis perpendicular to a
        aa = a[opposite]
        axis = np.cross(aa, np.where(np.abs(aa[:, :1]) < 0.9, [[1.0, 0, 0]], [[0, 1.0, 0]]))
        axis /= np.linalg.norm(axis, axis=-1, keepdims=True)
        r[opposite] = 2 * axis[:, :, None] * axis[:, None, :] - np.eye(3)
    return r


def gram_schmidt(x, y):
    """Rotation matrices (..., 3, 3) whose columns are ``x`` made unit, ``y`` made square to it
    and unit, and their cross product (``x``, ``y``: (..., 3); NaN where they are parallel)."""
    x = x / np.linalg.norm(x, axis=-1, keepdims=True)
    y = y - (x * y).sum(axis=-1, keepdims=True) * x
    y /= np.linalg.norm(y, axis=-1, keepdims=True)
    return np.stack([x, y, np.cross(x, y)], axis=-1)


def best_rotation(a, b, lean=0.0):
    """Rotations ``r`` minimising ``sum_i |r @ a[..., i, :] - b[..., i, :]|^2`` (Kabsch).

    ``a``, ``b``: shape (..., n, 3). Returns shape (..., 3, 3) and, per item, whether the fit is
    determined (False where the ``a`` vectors are collinear, leaving a free turn about them).
    ``lean``: where the fit leaves a turn free, the rounding of the data chooses it; a small
    ``lean`` (1e-9) adds that share of the identity (times the fit's scale) to the problem, so
    the least turn is taken there and a determined fit moves by about that share of a radian.
    """
    cov = np.swapaxes(b, -1, -2) @ a
    if lean:
        scale = np.sqrt((cov ** 2).sum(axis=(-2, -1)))
        cov = cov + lean * scale[..., None, None] * np.eye(3)
    u, s, vt = np.linalg.svd(cov)
    d = np.sign(np.linalg.det(u @ vt))
    fix = np.ones(s.shape)
    fix[..., 2] = np.where(d == 0, 1.0, d)
    determined = s[..., 1] > 1e-6 * np.maximum(s[..., 0], 1e-300)
    return (u * fix[..., None, :]) @ vt, determined


def rigidly_carried(ref, cur, weight, point, lean=0.0):
    """Where the weighted rigid fit of the points ``ref`` onto ``cur`` (n, k, 3; ``weight``
    (n, k, 1), each row summing to 1) carries ``point`` (n, 3): their weighted centroids matched
    and the :func:`best_rotation` of the weighted offsets about them."""
    c_ref = (ref * weight).sum(axis=1)
    c_cur = (cur * weight).sum(axis=1)
    rot, _ = best_rotation((ref - c_ref[:, None]) * np.sqrt(weight),
                           (cur - c_cur[:, None]) * np.sqrt(weight), lean=lean)
    return np.einsum("fij,fj->fi", rot, point - c_ref) + c_cur


def order_bones(parents):
    """An order in which every parent comes before its children; GapFillError on a cycle."""
    parents = [int(p) for p in parents]
    done, order = set(), []
    while len(order) < len(parents):
        ready = [b for b, p in enumerate(parents) if b not in done and (p < 0 or p in done)]
        if not ready:
            raise GapFillError("the bone hierarchy has a cycle or a parent out of range")
        order.extend(ready)
        done.update(ready)
    return order


def forward(rest, parents, basis):
    """Pose matrices (frames, bones, 4, 4) from basis matrices (see the module docstring)."""
    rest = np.asarray(rest, dtype=float)
    local = _local_rest(rest, parents)
    pose = np.empty(basis.shape)
    for b in order_bones(parents):
        p = parents[b]
        above = local[b] if p < 0 else pose[:, p] @ local[b]
        pose[:, b] = above @ basis[:, b]
    return pose


def _local_rest(rest, parents):
    inv = np.linalg.inv(rest)
    return np.stack([rest[b] if p < 0 else inv[p] @ rest[b] for b, p in enumerate(parents)])


def child_handles(rest, parents):
    """Per bone, the points its rotation places when joints are bone heads (a BVH armature):
    ``[(offset in the bone's rest frame, child index), ...]`` for children not at its head."""
    rest = np.asarray(rest, dtype=float)
    local = _local_rest(rest, parents)
    return [[(local[c][:3, 3], c) for c, p in enumerate(parents) if p == b
             and np.linalg.norm(local[c][:3, 3]) > 1e-6 * (1 + np.abs(rest[b][:3, 3]).max())]
            for b in range(len(parents))]


def tail_handles(lengths, parents):
    """Per bone, the point its rotation places when joints are bone tails (one bone per
    segment, as our ASF/AMC import builds): its own tail, ``(0, length, 0)`` in its frame;
    roots place nothing (their joint is their head)."""
    return [[] if p < 0 else [(np.array([0.0, float(length), 0.0]), b)]
            for b, (length, p) in enumerate(zip(lengths, parents))]


def solve_pose(rest, parents, reference, targets, rotate, translate, handles=None):
    """Basis matrices whose bones place their points on ``targets``.

    Parameters
    ----------
    rest : ndarray, shape (bones, 4, 4)
        Rest matrices in armature space.
    parents : sequence of int
        Parent bone index per bone, -1 for a root.
    reference : ndarray, shape (frames, bones, 4, 4)
        Basis matrices to start from: kept where nothing is solved, and the twist reference of
        bones with one child.
    targets : ndarray, shape (frames, bones, 3)
        Wanted head positions, armature space (NaN where there is no target).
    rotate : ndarray, shape (frames, bones), bool
        Solve the rotation of bone ``b`` at frame ``f`` (from its children's targets).
    translate : ndarray, shape (frames, bones), bool
        Solve the location of bone ``b`` at frame ``f`` so its head reaches its own target.
    handles : list, optional
        What each bone's rotation places (:func:`child_handles`, the default: joints are heads;
        or :func:`tail_handles`: joints are tails).

    Returns
    -------
    basis, pose : ndarray, shape (frames, bones, 4, 4)
        The solved basis matrices and the pose matrices they give (heads: ``pose[..., :3, 3]``).
    """
    rest = np.asarray(rest, dtype=float)
    parents = [int(p) for p in parents]
    basis = np.array(reference, dtype=float)
    targets = np.asarray(targets, dtype=float)
    rotate = np.asarray(rotate, dtype=bool) & np.isfinite(targets[..., 0]).any(axis=1)[:, None]
    translate = np.asarray(translate, dtype=bool) & np.isfinite(targets[..., 0])
    local = _local_rest(rest, parents)
    handles = child_handles(rest, parents) if handles is None else handles
    pose = np.empty(basis.shape)
    for b in order_bones(parents):
        p = parents[b]
        above = np.broadcast_to(local[b], basis[:, b].shape) if p < 0 else pose[:, p] @ local[b]
        rot_above = above[:, :3, :3]
        frames = translate[:, b]
        if frames.any():
            offset = targets[frames, b] - above[frames, :3, 3]
            basis[frames, b, :3, 3] = np.linalg.solve(rot_above[frames], offset[..., None])[..., 0]
        head = (above @ basis[:, b])[:, :3, 3]
        kids = [c for _, c in handles[b]]
        frames = rotate[:, b] & np.isfinite(targets[:, kids, 0]).all(axis=1) if kids else None
        if kids and frames.any():
            ref = basis[frames, b, :3, :3]
            # the placed points' offsets under the reference rotation, and where they should
            # point, both in the frame above the bone (rotation part of ``above``)
            now = np.einsum("fij,cj->fci", ref, np.stack([offset for offset, _ in handles[b]]))
            want = np.linalg.solve(rot_above[frames][:, None],
                                   (targets[frames][:, kids] - head[frames][:, None])[..., None])
            want = want[..., 0]
            turn = rotation_between(now[:, 0], want[:, 0])
            if len(kids) > 1:
                fitted, ok = best_rotation(now, want)
                turn = np.where(ok[:, None, None], fitted, turn)
            basis[frames, b, :3, :3] = turn @ ref
        pose[:, b] = above @ basis[:, b]
    return basis, pose


def descendants(parents):
    """For each bone, the boolean mask (bones,) of its strict descendants; shape (bones, bones)."""
    n = len(parents)
    below = np.zeros((n, n), dtype=bool)
    for b in reversed(order_bones(parents)):
        p = parents[b]
        if p >= 0:
            below[p] |= below[b]
            below[p, b] = True
    return below


def points_missing(bone_gaps, parents, moves):
    """Which joint positions a set of bone gaps leaves unknown.

    A bone with no good keys at a frame has an unknown rotation, so every joint below it is
    unknown; its own joint is unknown too where the bone's location is animated (``moves``).

    Parameters
    ----------
    bone_gaps : ndarray, shape (frames, bones), bool
    parents : sequence of int
    moves : ndarray, shape (bones,), bool

    Returns
    -------
    ndarray, shape (frames, bones), bool
    """
    gaps = np.asarray(bone_gaps, dtype=bool)
    missing = (gaps.astype(np.int64) @ descendants(parents).astype(np.int64)) > 0
    return missing | (gaps & np.asarray(moves, dtype=bool))


def bones_to_blame(suspect, parents, moves):
    """Bone gaps that explain suspect joint positions (the inverse of :func:`points_missing`):
    a suspect joint is blamed on its own bone where that bone moves, else on its parent, unless
    the parent's joint is suspect too at that frame (then the fault lies higher up)."""
    suspect = np.asarray(suspect, dtype=bool)
    blame = suspect & np.asarray(moves, dtype=bool)
    for c, p in enumerate(parents):
        if p >= 0:
            blame[:, p] |= suspect[:, c] & ~suspect[:, p]
    return blame
