"""Bone transforms from joint positions (core.posing) and suspect detection (core.suspect)."""

import numpy as np

from mocap_gapfill.core import synth
from mocap_gapfill.core.io import read_motion
from mocap_gapfill.core.posing import (best_rotation, bones_to_blame, forward, points_missing,
                                       rotation_between, solve_pose)
from mocap_gapfill.core.suspect import find_suspects


def rest_of_synth():
    heads = np.zeros((len(synth.NAMES), 3))
    for j, p in enumerate(synth.PARENTS):
        heads[j] = synth.OFFSETS[j] + (heads[p] if p >= 0 else 0)
    rest = np.broadcast_to(np.eye(4), (len(heads), 4, 4)).copy()
    rest[:, :3, 3] = heads
    return rest


def test_solved_pose_reaches_every_joint_of_a_moving_skeleton():
    skeleton, _ = synth.take(synth.KB_GAITS[3], frames=120)  # turning walk
    rest = rest_of_synth()
    frames, n = skeleton.n_frames, skeleton.n_points
    reference = np.broadcast_to(np.eye(4), (frames, n, 4, 4))
    has_child = np.isin(np.arange(n), synth.PARENTS)
    rotate = np.broadcast_to(has_child, (frames, n))
    translate = np.zeros((frames, n), bool)
    translate[:, 0] = True
    basis, pose = solve_pose(rest, synth.PARENTS, reference, skeleton.positions, rotate, translate)
    assert np.abs(pose[..., :3, 3] - skeleton.positions).max() < 1e-9
    assert np.allclose(forward(rest, synth.PARENTS, basis), pose)
    rot = basis[..., :3, :3]  # proper rotations
    assert np.allclose(rot @ np.swapaxes(rot, -1, -2), np.eye(3), atol=1e-9)
    assert np.allclose(np.linalg.det(rot), 1.0)


def test_single_child_keeps_the_reference_twist():
    rest = np.broadcast_to(np.eye(4), (2, 4, 4)).copy()
    rest[1, :3, 3] = (0, 0, 1)
    twist = np.eye(4)
    c, s = np.cos(0.7), np.sin(0.7)
    twist[:3, :3] = [[c, -s, 0], [s, c, 0], [0, 0, 1]]  # a turn about the bone (Z)
    reference = np.stack([twist, np.eye(4)])[None]
    targets = np.array([[[0, 0, 0], [0, 0, 1.0]]])  # already there: nothing to turn
    basis, _ = solve_pose(rest, [-1, 0], reference, targets, [[True, False]], [[False, False]])
    assert np.allclose(basis[0, 0], twist)


def test_rotation_helpers():
    a = np.array([[1.0, 0, 0], [0, 0, 1.0]])
    r = rotation_between(a, -a)  # opposite directions: a half turn
    assert np.allclose(np.einsum("nij,nj->ni", r, a), -a)
    assert np.allclose(np.linalg.det(r), 1)
    _, ok = best_rotation(np.array([[[1.0, 0, 0], [2.0, 0, 0]]]),
                          np.array([[[0, 1.0, 0], [0, 2.0, 0]]]))
    assert not ok[0]  # collinear: a free turn about the line



def test_a_free_turn_is_the_least_not_the_roundings():
    """Donors in a line (a skeleton's chain) leave the turn about it free, and the SVD filled it
    with whatever the rounding gave: inputs moved by 1e-12 turned the fit 49-169 degrees here,
    and the rigid fill of a joint's copies with it (ASF/AMC 07_05: `auto` 1.1 mm apart). With a
    lean towards the identity the least turn is taken: the angle between the lines."""
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(0)
    line = np.array([[0.0, 0, 0], [0.1, 0.02, 0.0], [0.25, 0.05, 0.0]])
    line -= line.mean(axis=0)
    there = line @ Rotation.from_rotvec([0.3, -0.2, 0.5]).as_matrix().T

    def turns(lean):
        return np.stack([best_rotation((line * (1 + 1e-12 * rng.standard_normal(line.shape)))[None],
                                       there[None], lean)[0][0] for _ in range(5)])

    free, least = turns(0.0), turns(1e-9)
    assert np.abs(free - free[0]).max() > 0.1  # the rounding's choice (when written: 1.7)
    assert np.abs(least - least[0]).max() < 1e-6
    assert np.allclose(line @ least[0].T, there, atol=1e-9)
    angle = np.linalg.norm(Rotation.from_matrix(least[0]).as_rotvec())
    assert np.isclose(angle, np.arccos(line[2] @ there[2] / (line[2] @ line[2])), atol=1e-6)

def test_bone_gaps_and_points():
    parents = [-1, 0, 1, 1, 0]  # root, a, a's two children, b
    gaps = np.zeros((2, 5), bool)
    gaps[0, 1] = True  # bone a without keys: its children are unknown
    moves = np.array([True, False, False, False, False])
    missing = points_missing(gaps, parents, moves)
    assert missing[0].tolist() == [False, False, True, True, False] and not missing[1].any()
    gaps[1, 0] = True  # the root without keys: it moves, so every joint is unknown
    assert points_missing(gaps, parents, moves)[1].all()
    suspect = np.zeros((1, 5), bool)
    suspect[0, 2] = True
    assert np.flatnonzero(bones_to_blame(suspect, parents, moves)[0]).tolist() == [1]


def test_suspects_on_real_markers(data_dir):
    take = read_motion(data_dir / "cmu/c3d/85_02.c3d")  # complete and clean
    clean = find_suspects(take.positions, take.fps, take.limbs)
    assert clean.mean() < 0.002, clean.sum()
    pos = take.positions.copy()
    j = take.names.index("LWRA")
    pos[400:402, j] += (0.15, 0, 0)  # a ghost: two frames 15 cm off
    k = take.names.index("RKNE")
    pos[600:640, [j, k]] = pos[600:640, [k, j]]  # a label swap for 40 frames
    flagged = find_suspects(pos, take.fps, take.limbs)
    assert flagged[400:402, j].all() and flagged[399:403, j].sum() <= 4
    assert flagged[[600, 639], k].all() and flagged[[600, 639], j].all()  # the swap's ends
    # inside the swap, the wrist breaks its rigid pairs with the other wrist marker
    assert flagged[601:639, j].mean() > 0.9
    assert (flagged & ~clean).sum() < 300  # the wrist's rigid partners are flagged with it
