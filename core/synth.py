"""Synthetic motion made by this project's own code: a walking 19-joint skeleton and the 41
markers stuck on it. It drives the offline demo, the sample scenes and tests that must not depend
on downloaded data; real-data tests use ../shared/data.

Each take is a gait with its own speed, cadence, swing amplitudes, posture and turning rate
(:class:`Gait`); the skeleton follows the CMU MotionBuilder BVH naming (``Hips``, ``LeftUpLeg``,
...) and the markers the CMU 41-marker set (``LFWT``, ``LKNE``, ...), so the normalisation finds
root and facing by name as it does for real files. Z up, metres, facing -Y, left is +X.
"""

from dataclasses import dataclass

import numpy as np

from .motion import Motion, rigid_marker_pairs, skeleton_limbs

#: (name, parent, rest offset from the parent joint in metres)
JOINTS = (
    ("Hips", None, (0.0, 0.0, 0.95)),
    ("LeftUpLeg", "Hips", (0.09, 0.0, -0.06)),
    ("LeftLeg", "LeftUpLeg", (0.0, 0.0, -0.42)),
    ("LeftFoot", "LeftLeg", (0.0, 0.0, -0.41)),
    ("LeftToeBase", "LeftFoot", (0.0, -0.13, -0.06)),
    ("RightUpLeg", "Hips", (-0.09, 0.0, -0.06)),
    ("RightLeg", "RightUpLeg", (0.0, 0.0, -0.42)),
    ("RightFoot", "RightLeg", (0.0, 0.0, -0.41)),
    ("RightToeBase", "RightFoot", (0.0, -0.13, -0.06)),
    ("Spine", "Hips", (0.0, 0.0, 0.11)),
    ("Spine1", "Spine", (0.0, 0.0, 0.22)),
    ("Neck", "Spine1", (0.0, 0.0, 0.21)),
    ("Head", "Neck", (0.0, -0.01, 0.11)),
    ("LeftShoulder", "Spine1", (0.03, 0.0, 0.17)),
    ("LeftArm", "LeftShoulder", (0.15, 0.0, 0.0)),
    ("LeftForeArm", "LeftArm", (0.0, 0.0, -0.28)),
    ("LeftHand", "LeftForeArm", (0.0, 0.0, -0.25)),
    ("RightShoulder", "Spine1", (-0.03, 0.0, 0.17)),
    ("RightArm", "RightShoulder", (-0.15, 0.0, 0.0)),
    ("RightForeArm", "RightArm", (0.0, 0.0, -0.28)),
    ("RightHand", "RightForeArm", (0.0, 0.0, -0.25)),
)

#: (marker, joint whose segment carries it, offset in that joint's frame)
MARKERS = (
    ("LFWT", "Hips", (0.12, -0.08, 0.05)), ("RFWT", "Hips", (-0.12, -0.08, 0.05)),
    ("LBWT", "Hips", (0.08, 0.10, 0.06)), ("RBWT", "Hips", (-0.08, 0.10, 0.06)),
    ("LTHI", "LeftUpLeg", (0.07, -0.02, -0.22)), ("RTHI", "RightUpLeg", (-0.07, -0.02, -0.20)),
    ("LKNE", "LeftLeg", (0.06, 0.0, 0.0)), ("RKNE", "RightLeg", (-0.06, 0.0, 0.0)),
    ("LSHN", "LeftLeg", (0.04, -0.05, -0.2)), ("RSHN", "RightLeg", (-0.04, -0.05, -0.18)),
    ("LANK", "LeftFoot", (0.05, 0.0, 0.0)), ("RANK", "RightFoot", (-0.05, 0.0, 0.0)),
    ("LHEE", "LeftFoot", (0.0, 0.06, -0.04)), ("RHEE", "RightFoot", (0.0, 0.06, -0.04)),
    ("LMT5", "LeftFoot", (0.05, -0.09, -0.05)), ("RMT5", "RightFoot", (-0.05, -0.09, -0.05)),
    ("LTOE", "LeftToeBase", (0.0, -0.02, 0.01)), ("RTOE", "RightToeBase", (0.0, -0.02, 0.01)),
    ("STRN", "Spine1", (0.0, -0.12, 0.05)), ("T10", "Spine", (0.0, 0.1, 0.1)),
    ("CLAV", "Spine1", (0.0, -0.08, 0.2)), ("C7", "Neck", (0.0, 0.07, 0.0)),
    ("RBAC", "Spine1", (-0.07, 0.11, 0.08)),
    ("LFHD", "Head", (0.07, -0.08, 0.08)), ("RFHD", "Head", (-0.07, -0.08, 0.08)),
    ("LBHD", "Head", (0.06, 0.08, 0.09)), ("RBHD", "Head", (-0.06, 0.08, 0.09)),
    ("LSHO", "LeftArm", (0.0, 0.0, 0.05)), ("RSHO", "RightArm", (0.0, 0.0, 0.05)),
    ("LUPA", "LeftArm", (0.05, 0.02, -0.14)), ("RUPA", "RightArm", (-0.05, 0.02, -0.12)),
    ("LELB", "LeftForeArm", (0.0, 0.05, 0.0)), ("RELB", "RightForeArm", (0.0, 0.05, 0.0)),
    ("LFRM", "LeftForeArm", (0.04, 0.0, -0.12)), ("RFRM", "RightForeArm", (-0.04, 0.0, -0.14)),
    ("LWRA", "LeftHand", (0.03, -0.02, 0.0)), ("RWRA", "RightHand", (-0.03, -0.02, 0.0)),
    ("LWRB", "LeftHand", (-0.02, 0.03, 0.0)), ("RWRB", "RightHand", (0.02, 0.03, 0.0)),
    ("LFIN", "LeftHand", (0.0, 0.0, -0.08)), ("RFIN", "RightHand", (0.0, 0.0, -0.08)),
)

NAMES = tuple(j[0] for j in JOINTS)
PARENTS = tuple(-1 if p is None else NAMES.index(p) for _, p, _ in JOINTS)
OFFSETS = np.array([o for _, _, o in JOINTS])


@dataclass(frozen=True)
class Gait:
    """One take's style. Angles in radians, speed in m/s, cadence in strides per second."""

    speed: float = 1.3
    cadence: float = 0.9
    hip_swing: float = 0.45
    knee_flex: float = 0.9
    arm_swing: float = 0.4
    elbow_flex: float = 0.35
    lean: float = 0.05
    bounce: float = 0.025
    turn_rate: float = 0.0  # radians per second about Z


#: the demo's knowledge-base takes (slow walk to jog, straight and turning) and its test take
KB_GAITS = (
    Gait(),
    Gait(speed=0.9, cadence=0.75, hip_swing=0.35, knee_flex=0.7, arm_swing=0.25),
    Gait(speed=2.6, cadence=1.35, hip_swing=0.7, knee_flex=1.5, arm_swing=0.7, elbow_flex=1.3,
         lean=0.15, bounce=0.05),
    Gait(speed=1.1, turn_rate=0.5, arm_swing=0.3),
    Gait(speed=1.6, cadence=1.0, hip_swing=0.55, knee_flex=1.0, turn_rate=-0.4, arm_swing=0.5),
    Gait(speed=2.0, cadence=1.2, hip_swing=0.6, knee_flex=1.2, arm_swing=0.6, elbow_flex=0.9,
         lean=0.1, bounce=0.04, turn_rate=0.25),
)
TEST_GAIT = Gait(speed=1.5, cadence=0.95, hip_swing=0.5, knee_flex=1.05, arm_swing=0.45,
                 elbow_flex=0.6, lean=0.08, turn_rate=0.3)


def _rot(axis, angle):
    """Rotation matrices about a principal axis, shape (frames, 3, 3)."""
    angle = np.asarray(angle, dtype=float)
    c, s = np.cos(angle), np.sin(angle)
    i, j = {"x": (1, 2), "y": (2, 0), "z": (0, 1)}[axis]
    r = np.zeros(angle.shape + (3, 3))
    r[..., i, i] = r[..., j, j] = c
    r[..., i, j], r[..., j, i] = -s, s
    k = 3 - i - j
    r[..., k, k] = 1.0
    return r


def local_rotations(gait, frames, fps, phase=0.0):
    """Per-joint local rotations (frames, joints, 3, 3) and root translation (frames, 3)."""
    t = np.arange(frames) / fps
    ph = 2 * np.pi * gait.cadence * t + phase
    rot = np.broadcast_to(np.eye(3), (frames, len(JOINTS), 3, 3)).copy()
    idx = NAMES.index
    yaw = gait.turn_rate * t
    rot[:, idx("Hips")] = _rot("z", yaw) @ _rot("x", -gait.lean) @ _rot("z", 0.08 * np.sin(ph))
    for side, shift in (("Left", 0.0), ("Right", np.pi)):
        p = ph + shift
        # the hip flexes forward (towards -Y) with a positive swing; the knee bends in swing
        rot[:, idx(side + "UpLeg")] = _rot("x", -gait.hip_swing * np.sin(p))
        rot[:, idx(side + "Leg")] = _rot("x", gait.knee_flex * np.clip(np.sin(p + 1.2), 0, None)
                                         + 0.08)
        rot[:, idx(side + "Foot")] = _rot("x", -0.25 * np.sin(p - 0.6))
        rot[:, idx(side + "ToeBase")] = _rot("x", 0.3 * np.clip(np.sin(p + 2.4), 0, None))
        sign = 1.0 if side == "Left" else -1.0
        rot[:, idx(side + "Arm")] = (_rot("x", gait.arm_swing * np.sin(p))
                                     @ _rot("y", -sign * 0.12))
        rot[:, idx(side + "ForeArm")] = _rot("x", -gait.elbow_flex
                                             * (1 + 0.4 * np.sin(p + 0.5)))
    rot[:, idx("Spine")] = _rot("z", -0.1 * np.sin(ph)) @ _rot("x", gait.lean * 0.5)
    rot[:, idx("Spine1")] = _rot("z", -0.06 * np.sin(ph))
    rot[:, idx("Head")] = _rot("x", 0.1 * np.sin(0.3 * ph))
    heading = np.stack([np.sin(yaw), -np.cos(yaw)], axis=1)  # forward is -Y at yaw 0
    step = gait.speed / fps * heading
    root = np.zeros((frames, 3))
    root[:, :2] = np.cumsum(step, axis=0)
    root[:, 2] = gait.bounce * np.cos(2 * ph)
    return rot, root


def forward(rot, root):
    """World joint positions (frames, joints, 3) and rotations (frames, joints, 3, 3)."""
    frames = rot.shape[0]
    pos = np.zeros((frames, len(JOINTS), 3))
    world = np.zeros_like(rot)
    for j, p in enumerate(PARENTS):
        if p < 0:
            pos[:, j] = root + OFFSETS[j]
            world[:, j] = rot[:, j]
        else:
            pos[:, j] = pos[:, p] + world[:, p] @ OFFSETS[j]
            world[:, j] = world[:, p] @ rot[:, j]
    return pos, world


def rest_pose():
    """The skeleton's rest pose (joints, 3): every joint turned by nothing, the root at the
    origin (standing upright, arms hanging): the rest of every take's armature, so bone
    rotations mean the same across takes (:attr:`~.motion.Motion.rest`)."""
    pos, _ = forward(np.tile(np.eye(3), (1, len(JOINTS), 1, 1)), np.zeros((1, 3)))
    return pos[0]


def take(gait=TEST_GAIT, frames=300, fps=60.0, phase=0.0, name="synthetic"):
    """One synthetic take: ``(skeleton Motion, marker Motion)``, complete (no gaps); the
    skeleton rests in :func:`rest_pose`."""
    rot, root = local_rotations(gait, frames, fps, phase)
    pos, world = forward(rot, root)
    joint = {n: i for i, n in enumerate(NAMES)}
    markers = np.stack([pos[:, joint[j]] + world[:, joint[j]] @ np.asarray(off)
                        for _, j, off in MARKERS], axis=1)
    skeleton = Motion(pos, NAMES, fps, parents=PARENTS, limbs=skeleton_limbs(PARENTS),
                      source=f"{name} (skeleton)", source_format="array", rest=rest_pose())
    marker_names = tuple(m[0] for m in MARKERS)
    marker_set = Motion(markers, marker_names, fps, limbs=rigid_marker_pairs(markers),
                        source=f"{name} (markers)", source_format="array")
    return skeleton, marker_set
