"""Armatures as the core sees them: bones, their rotation channels per frame, and FK.

An armature (:class:`Rig`) is a tree of bones with rest matrices in armature space (Blender's
``Bone.matrix_local``) and one rotation mode per bone (an Euler order such as ``"ZXY"``,
``"QUATERNION"`` or ``"AXIS_ANGLE"``). A pose over a take is what the animator keys:

- ``channels`` (frames, bones, 4): each bone's rotation channels in its own mode (Euler: the
  angles about X, Y, Z in radians, 4th value unused; quaternion: w, x, y, z; axis-angle: angle,
  x, y, z), as Blender's F-curves give them;
- ``location`` (frames, bones, 3): each bone's location channels (bone space).

``basis = T(location) R(channels)`` (Blender's ``PoseBone.matrix_basis`` without scale), and
:func:`~.posing.forward` turns basis matrices into pose matrices. The joints of a rig are the
bone heads (a BVH armature), or for rigs with ``lengths`` (our ASF/AMC import: one bone per
segment) the bone tails and the root's head.

Rotations go through ``scipy.spatial.transform.Rotation``. Rest matrices of bones made from a
head and a tail follow Blender's rule for a bone with zero roll (:func:`bone_matrix`), so a rig
built here from a BVH file has the rest matrices and the Euler channel values Blender's own BVH
importer gives the same file (checked against the bpy module in tests/addon).
"""

from dataclasses import dataclass

import numpy as np
from scipy.linalg import solve_banded
from scipy.spatial.transform import Rotation

from .errors import GapFillError
from .posing import forward
from .regression import kernel_ridge, within_fitted

EULER_ORDERS = ("XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX")
ROTATION_MODES = EULER_ORDERS + ("QUATERNION", "AXIS_ANGLE")


@dataclass(frozen=True, eq=False)
class Rig:
    """Bones of an armature.

    Parameters
    ----------
    names : tuple of str
    parents : tuple of int
        Parent bone per bone, -1 for a root.
    rest : ndarray, shape (bones, 4, 4)
        Rest matrices in armature space.
    modes : tuple of str
        Rotation mode per bone (:data:`ROTATION_MODES`).
    lengths : ndarray, shape (bones,), or None
        Bone lengths where joints are bone tails; None where joints are bone heads.
    """

    names: tuple
    parents: tuple
    rest: np.ndarray
    modes: tuple
    lengths: np.ndarray = None

    def __post_init__(self):
        n = len(self.names)
        rest = np.asarray(self.rest, dtype=float)
        if rest.shape != (n, 4, 4) or len(self.parents) != n or len(self.modes) != n:
            raise GapFillError(f"a rig of {n} bones needs {n} parents, rest matrices and modes")
        unknown = sorted(set(self.modes) - set(ROTATION_MODES))
        if unknown:
            raise GapFillError(f"unknown rotation modes: {', '.join(unknown)}")
        object.__setattr__(self, "rest", rest)
        object.__setattr__(self, "parents", tuple(int(p) for p in self.parents))

    @property
    def roots(self):
        """(bones,) bool: the bones without a parent."""
        return np.array([p < 0 for p in self.parents])

    def joints(self, basis):
        """Joint positions (frames, bones, 3) in armature space for basis matrices."""
        pose = forward(self.rest, self.parents, basis)
        if self.lengths is None:
            return pose[..., :3, 3].copy()
        tip = pose[..., :3, 3] + pose[..., :3, 1] * np.asarray(self.lengths)[:, None]
        tip[:, self.roots] = pose[..., :3, 3][:, self.roots]
        return tip

    def placed_by(self):
        """(bones, bones) bool: ``[b, j]`` where bone ``b``'s rotation moves joint ``j`` (its
        descendants' joints, and its own tail where joints are tails)."""
        n = len(self.parents)
        below = np.zeros((n, n), bool)
        for b in range(n):  # walk up from each bone
            p = self.parents[b]
            while p >= 0:
                below[p, b] = True
                p = self.parents[p]
        if self.lengths is not None:
            below |= np.eye(n, dtype=bool) & ~self.roots[:, None]
        return below

    def near(self, hops):
        """Per bone, the sorted bones within ``hops`` steps of it (to a parent or a child each
        step), roots and the bone itself left out."""
        out = []
        for b in range(len(self.parents)):
            found = {b}
            for _ in range(hops):
                found |= {c for c, p in enumerate(self.parents) if p in found}
                found |= {self.parents[c] for c in found if self.parents[c] >= 0}
            out.append([c for c in sorted(found - {b}) if self.parents[c] >= 0])
        return out

    def levers(self):
        """(bones, 3, 3): per bone ``M`` with ``w @ M @ w`` the mean squared move of the joints
        it places (in the rest pose; zeros where it places none) when its basis rotation is off
        by a small rotation vector ``w``: how a bone's turn shows in the joints."""
        n = len(self.names)
        rest_joints = self.joints(np.tile(np.eye(4), (1, n, 1, 1)))[0]
        out = np.zeros((n, 3, 3))
        for b, placed in enumerate(self.placed_by()):
            z = (rest_joints[placed] - self.rest[b, :3, 3]) @ self.rest[b, :3, :3]
            if len(z):
                out[b] = (np.sum(z * z) * np.eye(3) - z.T @ z) / len(z)
        return out

    def moved(self, gaps):
        """(frames, joints) bool: the joints that the bones gapped in ``gaps`` (frames, bones)
        move at each frame."""
        return (gaps.astype(np.int64) @ self.placed_by().astype(np.int64)) > 0


def rotations(channels, modes):
    """Rotation matrices (frames, bones, 3, 3) of rotation channels (frames, bones, 4)."""
    channels = np.asarray(channels, dtype=float)
    out = np.empty(channels.shape[:2] + (3, 3))
    for b, mode in enumerate(modes):
        out[:, b] = _rotation(channels[:, b], mode).as_matrix()
    return out


def _rotation(values, mode):
    if mode == "QUATERNION":
        q = values[:, :4]
        norm = np.linalg.norm(q, axis=1, keepdims=True)
        q = np.where(norm > 0, q / np.where(norm > 0, norm, 1), [1.0, 0, 0, 0])
        return Rotation.from_quat(q, scalar_first=True)
    if mode == "AXIS_ANGLE":
        axis = values[:, 1:4]
        norm = np.linalg.norm(axis, axis=1, keepdims=True)
        axis = np.where(norm > 0, axis / np.where(norm > 0, norm, 1), [0.0, 1.0, 0.0])
        return Rotation.from_rotvec(axis * values[:, :1])
    # Blender's order "ZXY" turns about Z first: scipy's extrinsic "zxy"
    order = [("XYZ".index(a)) for a in mode]
    return Rotation.from_euler(mode.lower(), values[:, order])


def channels_of(matrices, modes, previous=None):
    """Rotation channels (frames, bones, 4) of rotation matrices (frames, bones, 3, 3), each
    frame's values chosen closest to the frame before (``previous``, (bones, 4), before the
    first): Euler angles of the two equivalent solutions the one nearer after unwrapping by
    whole turns (Blender's compatible Euler), quaternions in the same hemisphere."""
    frames, bones = matrices.shape[:2]
    out = np.zeros((frames, bones, 4))
    for b, mode in enumerate(modes):
        rot = Rotation.from_matrix(matrices[:, b])
        prev = None if previous is None else np.asarray(previous, dtype=float)[b]
        if mode == "QUATERNION":
            q = rot.as_quat(scalar_first=True)
            flip = np.ones(frames)
            flip[1:] = np.sign(np.sum(q[1:] * q[:-1], axis=1) + 1e-300)
            flip = np.cumprod(flip)
            if prev is not None and np.dot(q[0], prev) * flip[0] < 0:
                flip = -flip
            out[:, b] = q * flip[:, None]
        elif mode == "AXIS_ANGLE":
            v = rot.as_rotvec()
            angle = np.linalg.norm(v, axis=1)
            axis = np.where(angle[:, None] > 1e-12, v / np.maximum(angle, 1e-300)[:, None],
                            [0.0, 1.0, 0.0])
            out[:, b] = np.concatenate([angle[:, None], axis], axis=1)
        else:
            out[:, b, :3] = _compatible_euler(rot, mode, prev)
    return out


def _compatible_euler(rot, mode, prev):
    """Each frame's Euler angles: of the two solutions, unwrapped by whole turns onto the frame
    before, the nearer (L1). Unwrapped, the step from one frame's pick to the next is the
    wrapped difference of the two solutions picked, whatever the turns before: so the pick
    depends only on the pick before (a map of {first, second} onto itself per frame), and the
    turns add up. Both are scans over the frames, done with cumulative sums."""
    order = [("XYZ".index(a)) for a in mode]
    first = rot.as_euler(mode.lower())  # in the order of ``mode``
    second = first + np.pi
    second[:, 1] = np.pi - first[:, 1]
    if not len(first):
        return first
    both = np.stack([first, second], axis=1)  # (frames, 2, 3)
    turn = 2 * np.pi
    if prev is None:
        start, turns0 = 0, 0.0
    else:
        lead = both[0] - np.asarray(prev, dtype=float)[order]
        turns = np.round(lead / turn)
        dist = np.abs(lead - turns * turn).sum(axis=1)
        start = int(dist[1] < dist[0])
        turns0 = turns[start]
    step = both[1:, None, :, :] - both[:-1, :, None, :]  # [f, from, to]
    step_turns = np.round(step / turn)
    dist = np.abs(step - step_turns * turn).sum(axis=3)
    to = (dist[:, :, 1] < dist[:, :, 0]).astype(np.int64)  # the pick after each pick
    # each frame's map: keep (0), swap (1), or a fixed pick whatever came before (2 + pick)
    kind = np.where(to[:, 0] == to[:, 1], 2 + to[:, 0], to[:, 0])
    kind = np.concatenate([[2 + start], kind])
    frames = np.arange(len(kind))
    fixed = np.maximum.accumulate(np.where(kind >= 2, frames, 0))
    swaps = np.cumsum(kind == 1)
    pick = (kind[fixed] - 2) ^ ((swaps - swaps[fixed]) & 1)
    turns = np.cumsum(np.concatenate([turns0 * np.ones((1, 3)),
                                      step_turns[frames[1:] - 1, pick[:-1], pick[1:]]]), axis=0)
    result = both[frames, pick] - turns * turn
    xyz = np.empty_like(result)
    xyz[:, order] = result
    return xyz


def basis_matrices(rig, channels, location, base=None, bones=None):
    """Basis matrices (frames, bones, 4, 4) from rotation and location channels. With ``base``
    (basis matrices of channels that differ only on ``bones``, (bones,) bool) only those bones
    are computed, the others copied from it."""
    if base is None:
        basis = np.zeros((channels.shape[0], len(rig.names), 4, 4))
        basis[..., 3, 3] = 1.0
        cols = np.arange(len(rig.names))
    else:
        basis = np.array(base, dtype=float)
        cols = np.flatnonzero(bones)
    basis[:, cols, :3, :3] = rotations(channels[:, cols], [rig.modes[c] for c in cols])
    basis[:, cols, :3, 3:] = location[:, cols, :, None]
    return basis


def aligned_turns(rig, basis):
    """Each bone's rotation (frames, bones, 3, 3) in its parent's frame with the rest axes taken
    out, ``R_rest basis R_rest^T``: a BVH file's own joint rotations. The same for any two rigs
    whose rest poses point their bones the same way, whatever their bones' roll or lengths."""
    rest = rig.rest[:, :3, :3]
    return rest @ np.asarray(basis)[..., :3, :3] @ np.swapaxes(rest, -1, -2)


def basis_turns(rig, turns, bones=None):
    """The inverse of :func:`aligned_turns` for ``bones`` (default all): basis rotations."""
    rest = rig.rest[:, :3, :3] if bones is None else rig.rest[bones, :3, :3]
    return np.swapaxes(rest, -1, -2) @ turns @ rest


def interpolate_channels(values, gaps):
    """Values (frames, bones, k) with the frames of each gap (``gaps`` (frames, bones) bool)
    replaced by linear interpolation of the values either side, held at clip ends: what
    Blender's F-curves with LINEAR keys show once the keys in a gap are deleted."""
    out = np.array(values, dtype=float)
    frames = np.arange(len(out))
    for b in np.flatnonzero(gaps.any(axis=0)):
        keyed = ~gaps[:, b]
        if not keyed.any():
            continue
        for k in range(out.shape[2]):
            out[~keyed, b, k] = np.interp(frames[~keyed], frames[keyed], out[keyed, b, k])
    return out


def bone_matrix(head, tail, roll=0.0):
    """Rest matrix (4, 4) of a bone from its head and tail with ``roll`` (Blender's
    ``vec_roll_to_mat3``: the Y axis along the bone, the smallest turn from +Y, then the roll).
    """
    head, tail = np.asarray(head, float), np.asarray(tail, float)
    y = tail - head
    x0, y0, z0 = y / np.linalg.norm(y)
    theta, theta_alt = 1.0 + y0, x0 * x0 + z0 * z0
    if theta > 6.1e-3 or theta_alt > 2.5e-4 ** 2:
        if theta <= 6.1e-3:
            theta = theta_alt * 0.5 + theta_alt * theta_alt * 0.125
        m = np.array([[1 - x0 * x0 / theta, x0, -x0 * z0 / theta],
                      [-x0, y0, -z0],
                      [-x0 * z0 / theta, z0, 1 - z0 * z0 / theta]])
    else:  # pointing down -Y: the symmetric choice
        m = np.diag([-1.0, -1.0, 1.0])
    m = Rotation.from_rotvec(np.array([x0, y0, z0]) * roll).as_matrix() @ m
    out = np.eye(4)
    out[:3, :3], out[:3, 3] = m, head
    return out


def bone_ends(motion):
    """Head and tail (bones, 3) of the one-bone-per-segment armature of a skeleton motion, in
    its rest pose (``motion.rest``, else its first complete frame): each bone from its parent
    joint to its joint; a root bone points 0.1 m up from the root; a zero-length segment points
    0.1 mm along its parent's bone."""
    complete = np.flatnonzero(~motion.missing.any(axis=1))
    if motion.parents is None or not len(complete):
        raise GapFillError("an armature needs a skeleton with a complete frame")
    pos = motion.positions[complete[0]] if motion.rest is None else motion.rest
    heads, tails = pos.copy(), pos.copy()
    for j, p in enumerate(motion.parents):
        if p < 0:
            tails[j] = pos[j] + [0.0, 0.0, 0.1]
            continue
        heads[j] = pos[p]
        if np.linalg.norm(pos[j] - pos[p]) <= 1e-4:
            up = pos[p] - pos[motion.parents[p]] if motion.parents[p] >= 0 else np.zeros(3)
            norm = np.linalg.norm(up)
            tails[j] = pos[p] + 1e-4 * (up / norm if norm > 1e-9 else np.array([0.0, 0.0, 1.0]))
    return heads, tails


def rig_from_motion(motion):
    """The armature the add-on's skeleton import builds for a skeleton motion (one bone per
    segment, joints = bone tails, quaternion rotations) and its channels: ``(rig, channels,
    location)``, posed by :func:`skeleton_basis`."""
    heads, tails = bone_ends(motion)
    rest = np.stack([bone_matrix(h, t) for h, t in zip(heads, tails)])
    lengths = np.linalg.norm(tails - heads, axis=1)
    rig = Rig(motion.names, motion.parents, rest, ("QUATERNION",) * motion.n_points, lengths)
    basis = skeleton_basis(rest, motion.parents, lengths, motion.positions, ~motion.missing)
    return rig, channels_of(basis[..., :3, :3], rig.modes), basis[..., :3, 3].copy()


def skeleton_basis(rest, parents, lengths, positions, present):
    """Basis matrices (frames, bones, 4, 4) that put the joints of a one-bone-per-segment
    armature (a root's head, every other bone's tail) on ``positions`` where ``present``. A root
    bone is placed on its joint and turned as its children's joints turn from the rest pose
    (Kabsch; at rest where one of them is missing), as an ASF root turns: the bones below it
    then hold rotations relative to the body, not to the world."""
    from .posing import best_rotation, solve_pose, tail_handles

    rest = np.asarray(rest, dtype=float)
    positions = np.asarray(positions, dtype=float)
    parents = [int(p) for p in parents]
    roots = np.array([p < 0 for p in parents])
    reference = np.tile(np.eye(4), (len(positions), len(parents), 1, 1))
    rest_joints = rest[:, :3, 3] + rest[:, :3, 1] * np.asarray(lengths)[:, None]
    for r in np.flatnonzero(roots):
        kids = [c for c, p in enumerate(parents) if p == r]
        if len(kids) < 2:
            continue
        seen = present[:, kids].all(axis=1) & present[:, r]
        turn, determined = best_rotation(rest_joints[kids] - rest[r, :3, 3],
                                         positions[seen][:, kids] - positions[seen][:, [r]])
        frames = np.flatnonzero(seen)[determined]
        reference[frames, r, :3, :3] = (rest[r, :3, :3].T @ turn[determined] @ rest[r, :3, :3])
    basis, _ = solve_pose(rest, parents, reference, positions, present & ~roots,
                          present & roots, tail_handles(lengths, parents))
    return basis


def hermite_channels(values, gaps, damping=None):
    """Like :func:`interpolate_channels`, but each gap with two keys on both sides takes the
    cubic (Hermite) curve that leaves the key before it and reaches the key after it with the
    velocities those keys show (one-frame differences): smooth motion stays smooth through
    the gap. Gaps at clip ends, or without a second key on a side, stay linear. With
    ``damping`` (frames), the velocities of a gap spanning more frames are scaled by
    ``damping / span``: a long gap does not carry the end velocities far (overshoot)."""
    out = interpolate_channels(values, gaps)
    for b, a, e, s, span, scale in _cubic_spans(gaps, damping):
        x0, x1 = out[a - 1, b], out[e + 1, b]
        v0, v1 = (x0 - out[a - 2, b]) * scale, (out[e + 2, b] - x1) * scale
        out[a:e + 1, b] = ((2 * s ** 3 - 3 * s ** 2 + 1) * x0 + (s ** 3 - 2 * s ** 2 + s) * v0
                           + (3 * s ** 2 - 2 * s ** 3) * x1 + (s ** 3 - s ** 2) * v1)
    return out


def bezier_channels(values, gaps):
    """Like :func:`interpolate_channels`, but each gap as Blender draws it once the keys either
    side are Bezier (Key > Interpolation Mode > Bezier) with the handles and smoothing new keys
    and F-curves get by default (4.2-5.2): ``AUTO_CLAMPED`` handles, a key at a turning point of
    the curve (or at its ends) level, and ``Continuous Acceleration``, the handles of each run of
    keys between two such keys chosen together so that the curve's second derivative is
    continuous at every key, within limits that keep each handle from overshooting the next
    key's value or pointing back (Blender's ``BKE_nurb_handle_smooth_fcurve``). One F-curve per
    bone and channel, keyed on every frame outside its gaps; held at clip ends. Agrees with
    Blender's own curves to float precision (tests/addon)."""
    out = interpolate_channels(values, gaps)  # held at clip ends
    for b in np.flatnonzero(gaps.any(axis=0)):
        keyed = np.flatnonzero(~gaps[:, b])
        for k in range(out.shape[2]):
            y = out[keyed, b, k]
            turning = np.ones(len(y), dtype=bool)  # level handles: the ends, turning points
            before, after = y[:-2] - y[1:-1], y[2:] - y[1:-1]
            turning[1:-1] = ((before <= 0) & (after <= 0)) | ((before >= 0) & (after >= 0))
            locks, runs = np.flatnonzero(turning), {}
            for p in np.flatnonzero(np.diff(keyed) > 1):  # the key before a gap
                s = locks[np.searchsorted(locks, p, side="right") - 1]
                e = locks[np.searchsorted(locks, p + 1)]
                if (s, e) not in runs:  # a run of keys between level ones: solved once
                    runs[s, e] = _smooth_handles(keyed[s:e + 1], y[s:e + 1])
                h, l = runs[s, e]
                right, left = h[p - s], -h[p + 1 - s] / l[p + 1 - s]
                span = keyed[p + 1] - keyed[p]
                t = np.arange(1, span) / span
                u = 1 - t
                out[keyed[p] + 1:keyed[p + 1], b, k] = (
                    u ** 3 * y[p] + 3 * u * u * t * (y[p] + right)
                    + 3 * u * t * t * (y[p + 1] + left) + t ** 3 * y[p + 1])
    return out


def _smooth_handles(x, y):
    """The right handles' heights over their keys (``h``; the left ones are ``-h / l``) of a
    run of auto-clamped Bezier keys ``(x, y)`` whose first and last keys are level, as
    Blender's ``Continuous Acceleration`` solves them: a tridiagonal system (the curve's second
    derivative continuous at each inner key), each handle within what keeps it from pointing
    back or overshooting the next key's value, out-of-range handles locked at their limit and
    released (at most twice each) when the solution pulls them back in."""
    n = len(x)
    h, l = np.zeros(n), np.ones(n)
    if n < 3:
        return h, l
    dx, dy = np.r_[np.nan, np.diff(x)], np.r_[np.nan, np.diff(y)]
    l[1:-1] = dx[2:] / dx[1:-1]
    low, high = np.full(n, -np.inf), np.full(n, np.inf)
    for i in range(1, n):  # the handles either side of each interval, within its rise
        for j, limit in ((i - 1, dy[i]), (i, dy[i] * l[i])):
            if limit >= 0:
                high[j], low[j] = min(high[j], limit), 0.0
            if limit <= 0:
                high[j], low[j] = 0.0, max(low[j], limit)
    below, diag, above = np.zeros(n), np.ones(n), np.zeros(n)  # the ends: level (h = 0)
    rhs = np.zeros(n)
    below[1:-1], diag[1:-1] = l[1:-1] ** 2, 2 * (l[1:-1] + 1)
    above[1:-1], rhs[1:-1] = 1 / l[2:], dy[1:-1] * l[1:-1] ** 2 + dy[2:]
    wanted = below.copy(), diag.copy(), above.copy(), rhs.copy()
    fixed, released = np.zeros(n, dtype=bool), np.zeros(n, dtype=int)
    while True:
        h = solve_banded((1, 1), np.array([np.r_[0, above[:-1]], diag, np.r_[below[1:], 0]]),
                         rhs)
        h[fixed] = rhs[fixed]  # exactly at their limit: each lock is final until released
        out = ~fixed & ((h < low) | (h > high))
        target = np.where(h > high, high, low)
        lock = out & (target != 0)  # first those that go the right way, if any
        if out.any() and not lock.any():
            lock = out
        if lock.any():  # held at their limit: solved again
            below[lock], diag[lock], above[lock], rhs[lock] = 0.0, 1.0, 0.0, target[lock]
            fixed |= lock
            continue
        pull = -(wanted[0] * np.r_[0, h[:-1]] + wanted[1] * h + wanted[2] * np.r_[h[1:], 0]
                 - wanted[3]) * wanted[1]
        free = fixed & (released < 2) & (((pull > 0) & (h < high)) | ((pull < 0) & (h > low)))
        if not free.any():
            return h, l
        for part, value in zip((below, diag, above, rhs), wanted):
            part[free] = value[free]
        fixed &= ~free
        released += free


def _cubic_spans(gaps, damping):
    """Each gap the cubics fill (two keys on both sides): ``(bone, first, last, s, span,
    scale)``, ``s`` (frames, 1) its frames' place between the keys either side (0-1), ``span``
    the frames between those keys, ``scale`` the velocities' (``span``, damped)."""
    frames = len(gaps)
    for b in np.flatnonzero(gaps.any(axis=0)):
        for a, e in _runs(gaps[:, b]):
            if a < 2 or e > frames - 3 or gaps[a - 2, b] or gaps[e + 2, b]:
                continue
            span = e - a + 2
            yield (b, a, e, ((np.arange(a, e + 1) - (a - 1)) / span)[:, None], span,
                   span if damping is None else min(span, damping))


def hermite_rotations(turns, gaps, damping=None):
    """:func:`hermite_channels` for rotations (frames, bones, 3, 3) that hold across each gap
    what the F-curves show (the interpolation of its keys), done on the rotations rather than
    on their channels: the interpolation, turned on each frame by a cubic (as a rotation
    vector, zero at both keys) that makes it leave the key before the gap and reach the key
    after it with the angular velocities those keys show (one-frame steps). Near an Euler
    angle's gimbal lock a bone's channels race while the bone itself turns slowly; their
    velocities carried into a gap turned bones by radians (docs/DESIGN.md).
    ``damping`` as there."""
    out = np.array(turns, dtype=float)
    for b, a, e, s, span, scale in _cubic_spans(gaps, damping):
        r = Rotation.from_matrix(out[[a - 2, a - 1, a, e, e + 1, e + 2], b])
        steps = (r[[0, 1, 3, 4]].inv() * r[[1, 2, 4, 5]]).as_rotvec()  # keys, path, path, keys
        d0 = steps[0] * scale - steps[1] * span  # as the channels' cubic departs from the line
        d1 = steps[3] * scale - steps[2] * span
        turn = (s ** 3 - 2 * s ** 2 + s) * d0 + (s ** 3 - s ** 2) * d1
        out[a:e + 1, b] = (Rotation.from_matrix(out[a:e + 1, b])
                           * Rotation.from_rotvec(turn)).as_matrix()
    return out


def learned_rotations(turns, gaps, keys=4, ridge=0.0, near=None, body_ridges=(0.1,),
                      fewest=10, most=200, fill=None):
    """Each gap of rotations (frames, bones, 3, 3) as the bone's own motion says a gap of its
    length goes on from the keys either side: on each gap frame, a turn off the slerp between
    the keys before and after it, linear in the path between them and in the steps to ``keys``
    keys beyond each (rotation vectors about the key), with one weight per term and frame
    shared by the three axes - fitted by least squares (ridge ``ridge``, a share of the mean
    diagonal) on every other window of the take where the bone is keyed throughout (at most
    ``most``, spread over the take). The slerp and the cubic of :func:`hermite_rotations` are
    among these predictors; the fit takes what the bone's motion favours (a jittering capture
    smooths its keys, a swinging limb carries them on). Gaps without ``keys`` + 1 keys on both
    sides are left as they are.

    ``near`` (per bone, the bones whose motion may tell of it): then what that fit misses on
    the gap is what the same fits of those of them keyed throughout the gap's window (gap,
    keys and keys beyond) miss at the same frames, times 3 x 3 weights shared by the gap's
    frames, fitted on the bone's windows where all of them are keyed too, if there are
    ``fewest`` such windows (at most ``most``, spread over the take), with the ridge of
    ``body_ridges`` that predicts each half of those windows best from the other, and not at
    all if none predicts them better than the fit alone: when the forearm swings on past what
    its keys foretold, so does the hand.

    ``fill`` ((frames, bones) bool): fill only the gaps in it (all of ``gaps`` stay unknown to
    the fits); default all."""
    out = np.array(turns, dtype=float)
    own = _OwnMotion(turns, gaps, keys, ridge, most)
    for b, a, e in learnable_runs(gaps, keys):
        if fill is not None and not fill[a, b]:
            continue
        length, key = e - a + 1, np.array([a - 1])
        filled = own.predict(b, key, length)[0]
        others = [f for f in (near[b] if near is not None else ())
                  if not gaps[a - 1 - keys:e + 2 + keys, f].any()]
        train = own.windows(b, length)[::2]
        for f in others:
            train = train[own.keyed(f, train, length)]
        train = _spread(train, most)
        if others and len(train) >= fewest:
            x = np.concatenate([own.missed(f, train, length) for f in others], axis=2)
            weights = _body_weights(x, own.missed(b, train, length), body_ridges)
            if weights is not None:
                now = np.concatenate([own.missed(f, key, length)[0] for f in others], axis=1)
                filled = _qmul(filled, _quat(now @ weights))
        out[a:e + 1, b] = Rotation.from_quat(filled).as_matrix()
    return out


def learn_losses(turns, channels, modes, gaps, levers, keys=4, ridge=0.0, most=200, worse=1.1,
                 plus=0.002):
    """Per gap of :func:`learnable_runs` ``(bone, first, last)``: the share of the bone's windows
    of the gap's length (keyed throughout, with keys beyond: those :func:`learned_rotations`
    fits on) where the bone's own fit moves the joints it places (``levers``,
    :meth:`Rig.levers`; RMS over them and the window) further from the truth than Blender's
    interpolation of the rotation ``channels`` (``modes``) does, by ``worse`` times and ``plus``
    (the rig's units) more: how often the take says ``learn`` loses a gap like it."""
    own = _OwnMotion(turns, gaps, keys, ridge, most)
    out, shares = {}, {}
    for b, a, e in learnable_runs(gaps, keys):
        length = e - a + 1
        if (b, length) not in shares:
            starts = own.windows(b, length)
            shares[b, length] = 1.0
            if len(starts):
                steps = np.arange(1, length + 1) / (length + 1)
                keyed = channels[:, b]
                line = (keyed[starts, None] + (keyed[starts + length + 1] - keyed[starts])[:, None]
                        * steps[None, :, None])
                lerp = Rotation.from_matrix(rotations(line.reshape(-1, 1, keyed.shape[-1]),
                                                      [modes[b]])[:, 0]).as_quat()
                truth = own.truth(b, starts, length)
                linear = _rotvec(_qmul(_qinv(lerp.reshape(truth.shape)), truth))
                learnt = own.missed(b, starts, length)
                shares[b, length] = float(np.mean(_lever_rms(learnt, levers[b])
                                                  > worse * _lever_rms(linear, levers[b]) + plus))
        out[b, a, e] = shares[b, length]
    return out


def _lever_rms(turns, lever):
    """(windows,): the RMS move of the joints ``lever`` (:meth:`Rig.levers`) carries for the
    turns (windows, frames, 3) off the truth."""
    return np.sqrt(np.einsum("wti,ij,wtj->w", turns, lever, turns) / turns.shape[1])


def _body_weights(x, y, ridges):
    """Weights (features, 3) of ``y`` (windows, length, 3) on ``x`` (windows, length,
    features), with the ridge of ``ridges`` (shares of the mean diagonal) that predicts each
    half of the windows in time best from the other; None where none beats predicting 0."""
    def fit(rows, ridge):
        return _ridge(x[rows].reshape(-1, x.shape[2]), y[rows].reshape(-1, 3), ridge)

    half = len(x) // 2
    folds = [(slice(None, half), slice(half, None)), (slice(half, None), slice(None, half))]
    best, chosen = np.sum(y ** 2), None
    for ridge in ridges:
        missed = sum(np.sum((y[test] - x[test] @ fit(train, ridge)) ** 2)
                     for train, test in folds)
        if missed < best:
            best, chosen = missed, ridge
    return None if chosen is None else fit(slice(None), chosen)


class _OwnMotion:
    """Each bone's own fit of :func:`learned_rotations` per gap length, made on demand."""

    def __init__(self, turns, gaps, keys, ridge, most):
        self.turns, self.gaps, self.keys, self.ridge, self.most = turns, gaps, keys, ridge, most
        self.quats, self.weights = {}, {}

    def quat(self, b):
        if b not in self.quats:
            self.quats[b] = Rotation.from_matrix(self.turns[:, b]).as_quat()
        return self.quats[b]

    def windows(self, b, length):
        """The frames before the windows of ``length`` frames where ``b`` is keyed, with keys
        and ``keys`` keys beyond on both sides."""
        return np.flatnonzero(self.keyed(b, np.arange(len(self.gaps)), length))

    def keyed(self, b, before, length):
        """(windows,) bool: whether ``b`` is keyed throughout the windows after ``before``."""
        hidden = np.concatenate([[0], np.cumsum(self.gaps[:, b])])
        lo, hi = before - self.keys, before + length + 2 + self.keys  # frames lo .. hi - 1
        fits = (lo >= 0) & (hi <= len(self.gaps))
        return fits & (hidden[np.clip(hi, 0, len(self.gaps))] == hidden[np.clip(lo, 0, None)])

    def fit(self, b, length):
        if (b, length) not in self.weights:
            q, starts = self.quat(b), _spread(self.windows(b, length)[::2], self.most)
            x = _learned_terms(q, starts, length, self.keys).transpose(0, 2, 1).reshape(
                -1, 2 * self.keys + 1)
            y = _off_slerp(q, starts, length).transpose(0, 2, 1).reshape(-1, length)
            self.weights[b, length] = _ridge(x, y, self.ridge)
        return self.weights[b, length]

    def predict(self, b, before, length):
        """(windows, length, 4): the fit's quaternions on the windows after ``before``."""
        q = self.quat(b)
        turn = np.einsum("tl,wtk->wlk", self.fit(b, length),
                         _learned_terms(q, before, length, self.keys))
        return _off_slerp(q, before, length, turn)

    def truth(self, b, before, length):
        """(windows, length, 4): the take's quaternions on the windows after ``before``."""
        return self.quat(b)[before[:, None] + 1 + np.arange(length)]

    def missed(self, b, before, length):
        """(windows, length, 3): what the fit misses there (rotation vectors)."""
        return _rotvec(_qmul(_qinv(self.predict(b, before, length)), self.truth(b, before, length)))


def _ridge(x, y, ridge):
    """Least-squares weights of ``y`` on ``x`` with a ridge of ``ridge`` times the mean diagonal
    of ``x.T @ x``, and a floor under it: a bone that stands still fits no turn at all."""
    gram = x.T @ x
    gram += (ridge * np.trace(gram) / len(gram) + 1e-12) * np.eye(len(gram))
    return np.linalg.solve(gram, x.T @ y)


def _spread(windows, most):
    """At most ``most`` of ``windows``, spread evenly."""
    if len(windows) <= most:
        return windows
    return windows[np.linspace(0, len(windows) - 1, most).round().astype(int)]


def learnable_runs(gaps, keys):
    """The gaps :func:`learned_rotations` fills, ``(bone, first, last)``: those with ``keys`` + 1
    keys on both sides."""
    frames = len(gaps)
    return [(b, a, e) for b in np.flatnonzero(gaps.any(axis=0)) for a, e in _runs(gaps[:, b])
            if a - 1 - keys >= 0 and e + 1 + keys < frames
            and not gaps[a - 1 - keys:a, b].any() and not gaps[e + 1:e + 2 + keys, b].any()]


def _learned_terms(q, before, length, keys):
    """(windows, 2 keys + 1, 3): for gaps of ``length`` after frames ``before`` (quaternions
    ``q``), the path from the key before to the key after and the steps from each to ``keys``
    keys beyond it, as rotation vectors about the key they start from."""
    first, last = q[before], q[before + length + 1]
    terms = [_rotvec(_qmul(_qinv(first), last))]
    terms += [_rotvec(_qmul(_qinv(first), q[before - j])) for j in range(1, keys + 1)]
    terms += [_rotvec(_qmul(_qinv(last), q[before + length + 1 + j])) for j in range(1, keys + 1)]
    return np.stack(terms, axis=1)


def _off_slerp(q, before, length, turn=None):
    """(windows, length, 3): each window's rotations as turns off the slerp between its keys
    (frames ``before`` and ``before + length + 1`` of quaternions ``q``); with ``turn``
    (windows, length, 3), instead the quaternions (windows, length, 4) that far off it."""
    first = q[before][:, None]
    path = _rotvec(_qmul(_qinv(q[before]), q[before + length + 1]))[:, None]
    base = _qmul(first, _quat(path * (np.arange(1, length + 1) / (length + 1))[:, None]))
    if turn is not None:
        return _qmul(base, _quat(turn))
    return _rotvec(_qmul(_qinv(base), q[before[:, None] + np.arange(1, length + 1)]))


def _qmul(p, q):
    """Quaternion products (x, y, z, w: scipy's order), broadcast."""
    pv, pw, qv, qw = p[..., :3], p[..., 3:], q[..., :3], q[..., 3:]
    return np.concatenate([pw * qv + qw * pv + np.cross(pv, qv),
                           pw * qw - np.sum(pv * qv, axis=-1, keepdims=True)], axis=-1)


def _qinv(q):
    return q * np.array([-1.0, -1.0, -1.0, 1.0])


def _rotvec(q):
    """Rotation vectors of unit quaternions (the shorter way round)."""
    q = np.where(q[..., 3:] < 0, -q, q)
    norm = np.linalg.norm(q[..., :3], axis=-1, keepdims=True)
    angle = 2 * np.arctan2(norm, q[..., 3:])
    return q[..., :3] * np.where(norm > 1e-12, angle / np.maximum(norm, 1e-300), 2.0)


def _quat(v):
    """Unit quaternions of rotation vectors."""
    angle = np.linalg.norm(v, axis=-1, keepdims=True)
    half = np.where(angle > 1e-12, np.sin(angle / 2) / np.maximum(angle, 1e-300), 0.5)
    return np.concatenate([v * half, np.cos(angle / 2)], axis=-1)


def regress_channels(values, gaps, fps, lags, window, ridge, fixed=None, kernel=False,
                     end_margin=0.1):
    """Like :func:`interpolate_channels`, but each gap with a key on a side takes what the
    rest of the body says of the bone: a ridge regression of its channels on the channels of
    every bone keyed throughout the gap (at the frame and ``lags`` seconds either side, so the
    other bones' motion counts, not only their pose), fitted on the frames within ``window``
    seconds of the gap where the bone and all of those are keyed; the regression's miss at the
    keys either side is interpolated across the gap, so the fill meets both keys (at a clip end
    the miss at the one key is carried, and the prediction kept within the training frames'
    range widened by ``end_margin`` of it on each side, as the points' regression: a take that
    ends standing still is not the walk it learnt from). ``ridge``:
    the penalty per training frame on standardised channels. ``fixed`` ((bones,) bool): bones
    left as interpolated (roots). A gap with too few training frames stays linear. ``kernel``:
    a Gaussian kernel (bandwidth: the median squared distance between training frames, scaled to
    the linear kernel's mean) beside the linear one, so the bone may follow the others in a
    curve."""
    out = interpolate_channels(values, gaps)
    frames, bones, width = out.shape
    steps = sorted({0} | {s * int(round(abs(t) * fps)) for t in lags for s in (-1, 1)})
    reach = int(round(window * fps))
    enough = max(10, int(round(0.25 * fps)))
    for b in np.flatnonzero(gaps.any(axis=0) & (True if fixed is None else ~np.asarray(fixed))):
        for a, e in _runs(gaps[:, b]):
            if a < 1 and e > frames - 2:
                continue
            others = ~gaps[max(0, a - 1):e + 2].any(axis=0)
            others[b] = False
            lo, hi = max(0, a - reach), min(frames, e + 1 + reach)
            rows = np.arange(lo, hi)
            train = ~gaps[lo:hi, b] & ~gaps[lo:hi][:, others].any(axis=1)
            if train.sum() < enough:
                continue
            x = np.concatenate([out[np.clip(rows + step, 0, frames - 1)][:, others]
                                .reshape(len(rows), -1) for step in steps], axis=1)
            x = x[:, x[train].std(axis=0) > 1e-9]
            mean, scale = x[train].mean(axis=0), x[train].std(axis=0)
            x = (x - mean) / scale
            y = out[rows, b]
            centre = y[train].mean(axis=0)
            # ridge in its dual form: fewer training frames than features
            pred = kernel_ridge(x, train, y[train] - centre, 1.0 if kernel else 0.0,
                                ridge) + centre
            ends = np.array([t for t in (a - 1, e + 1) if 0 <= t < frames])
            if len(ends) == 1:  # no second key to pull it back: within what training saw
                pred = within_fitted(pred, y[train], end_margin)
            miss = y - pred  # known at the keys beside the gap
            span = np.arange(a, e + 1)
            for k in range(width):
                out[a:e + 1, b, k] = pred[span - lo, k] + np.interp(span, ends,
                                                                     miss[ends - lo, k])
    return out


def _runs(mask):
    edges = np.flatnonzero(np.diff(np.concatenate([[0], mask.astype(np.int8), [0]])))
    return zip(edges[::2], edges[1::2] - 1)
