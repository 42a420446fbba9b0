"""BVH (Biovision hierarchy) reader, plain or gzip-compressed (``.bvh.gz``).

Any hierarchy is accepted. Positions are computed by forward kinematics for every joint (and,
optionally, every End Site). BVH has no unit field: the unit is guessed from the height of the
rest skeleton (see :func:`guess_units`) unless given.
"""

from dataclasses import dataclass, replace

import numpy as np

from ..errors import ParseError
from ..motion import UNIT_SCALES, Motion, skeleton_limbs, snap_fps, units_for_height, y_up_to_z_up
from . import read_text_bytes
from .kinematics import compose

_ROT = {"Xrotation": "x", "Yrotation": "y", "Zrotation": "z"}
_POS = {"Xposition": 0, "Yposition": 1, "Zposition": 2}
MAX_CHANNELS = 100_000


@dataclass
class BvhJoint:
    name: str
    parent: int
    offset: np.ndarray
    channels: list  # channel names in file order
    first_channel: int  # column of the first channel in the motion data
    end_site: bool = False


@dataclass
class BvhFile:
    """What the file says, before any conversion: joints, raw channel values, frame time."""

    path: str
    joints: list
    frame_time: float
    values: np.ndarray  # (frames, channels)


def _open_text(path):
    raw = read_text_bytes(path)
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError:
        return raw.decode("latin-1")


def parse_bvh(path):
    """Parse a BVH file into a :class:`BvhFile` (no kinematics)."""
    text = _open_text(path)
    lines = text.splitlines()
    tokens = []  # (token, line number) of the hierarchy part
    motion_line = None
    for number, line in enumerate(lines, 1):
        if line.strip().upper() == "MOTION":
            motion_line = number
            break
        tokens.extend((tok, number) for tok in line.replace("{", " { ").replace("}", " } ").split())
    if not text.strip():
        raise ParseError("empty file", path)
    if motion_line is None:
        raise ParseError("no MOTION section (file truncated or not a BVH)", path)

    joints, n_channels = _parse_hierarchy(tokens, path, motion_line)
    frame_time, values = _parse_motion(lines, motion_line, n_channels, path)
    return BvhFile(str(path), joints, frame_time, values)


def _parse_hierarchy(tokens, path, motion_line):
    """The joints of a BVH HIERARCHY from its ``(token, line)`` pairs, and the channel count."""
    pos = 0

    def take(expect=None):
        nonlocal pos
        if pos >= len(tokens):
            raise ParseError("hierarchy ends early", path, motion_line)
        tok, number = tokens[pos]
        pos += 1
        if expect is not None and tok.upper() != expect:
            raise ParseError(f"expected {expect!r}, found {tok!r}", path, number)
        return tok, number

    def number_token():
        tok, number = take()
        try:
            value = float(tok)
        except ValueError:
            raise ParseError(f"expected a number, found {tok!r}", path, number) from None
        if not np.isfinite(value):
            raise ParseError(f"non-finite number {tok!r}", path, number)
        return value

    take("HIERARCHY")
    joints = []
    stack = []  # indices of open joints
    n_channels = 0
    tok, number = take()
    if tok.upper() != "ROOT":
        raise ParseError(f"expected ROOT, found {tok!r}", path, number)
    kind = "ROOT"
    while True:
        if kind in ("ROOT", "JOINT"):
            name, number = take()
            end_site = False
        else:  # End Site
            take("SITE")
            name = f"{joints[stack[-1]].name}_End" if stack else "End"
            end_site = True
        take("{")
        take("OFFSET")
        offset = np.array([number_token() for _ in range(3)])
        channels = []
        if not end_site:
            take("CHANNELS")
            count_tok, number = take()
            if not count_tok.isdigit() or int(count_tok) > 6:
                raise ParseError(f"bad channel count {count_tok!r}", path, number)
            for _ in range(int(count_tok)):
                ch, number = take()
                if ch not in _ROT and ch not in _POS:
                    raise ParseError(f"unknown channel {ch!r}", path, number)
                channels.append(ch)
        joints.append(BvhJoint(name, stack[-1] if stack else -1, offset, channels, n_channels,
                               end_site))
        n_channels += len(channels)
        if n_channels > MAX_CHANNELS:
            raise ParseError("too many channels", path, number)
        stack.append(len(joints) - 1)
        # children or closing braces
        while True:
            tok, number = take()
            upper = tok.upper()
            if upper == "}":
                stack.pop()
                if not stack:
                    break
                continue
            if upper in ("JOINT", "END"):
                if joints[stack[-1]].end_site:
                    raise ParseError("an End Site cannot have children", path, number)
                kind = upper
                break
            raise ParseError(f"unexpected {tok!r} in hierarchy", path, number)
        if not stack:
            break
    if pos != len(tokens):
        raise ParseError(f"unexpected {tokens[pos][0]!r} after the hierarchy", path, tokens[pos][1])
    names = [j.name for j in joints]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise ParseError(f"duplicated joint names: {', '.join(dup)}", path)
    return joints, n_channels


def _parse_motion(lines, motion_line, n_channels, path):
    """The frame time and the channel values of a BVH MOTION section (``lines`` of the file)."""
    header = lines[motion_line:motion_line + 2]
    if len(header) < 2:
        raise ParseError("MOTION section is truncated", path, motion_line)
    frames_decl = _header_value(header[0], "frames:", path, motion_line + 1)
    frame_time = _header_value(header[1], "frame time:", path, motion_line + 2)
    if frames_decl != int(frames_decl) or frames_decl < 0:
        raise ParseError(f"bad frame count {frames_decl}", path, motion_line + 1)
    if not 0 < frame_time < 10:
        raise ParseError(f"bad frame time {frame_time}", path, motion_line + 2)
    frames_decl = int(frames_decl)
    data_lines = [(i, l) for i, l in enumerate(lines[motion_line + 2:], motion_line + 3) if l.strip()]
    if len(data_lines) < frames_decl:
        raise ParseError(f"truncated: header says {frames_decl} frames, file has {len(data_lines)}",
                         path, len(lines))
    if len(data_lines) > frames_decl:
        raise ParseError(f"header says {frames_decl} frames but more lines follow",
                         path, data_lines[frames_decl][0])
    values = np.empty((frames_decl, n_channels))
    for row, (number, line) in enumerate(data_lines):
        parts = line.split()
        if len(parts) != n_channels:
            raise ParseError(f"{len(parts)} values, expected {n_channels}", path, number)
        try:
            values[row] = [float(p) for p in parts]
        except ValueError:
            raise ParseError("non-numeric value in motion data", path, number) from None
    if not np.isfinite(values).all():
        bad = int(np.argwhere(~np.isfinite(values))[0, 0])
        raise ParseError("non-finite value in motion data", path, data_lines[bad][0])
    return frame_time, values


def _header_value(line, key, path, number):
    if not line.strip().lower().startswith(key):
        raise ParseError(f"expected '{key}'", path, number)
    try:
        value = float(line.split(":", 1)[1])
    except ValueError:
        raise ParseError(f"bad value after '{key}'", path, number) from None
    if not np.isfinite(value):
        raise ParseError(f"bad value after '{key}': {value}", path, number)
    return value


def forward_kinematics(bvh):
    """Global joint positions in file units and axes, shape (frames, joints, 3)."""
    frames = bvh.values.shape[0]
    positions = np.zeros((frames, len(bvh.joints), 3))
    rotations = np.zeros((frames, len(bvh.joints), 3, 3))
    for j, joint in enumerate(bvh.joints):
        local = np.broadcast_to(joint.offset, (frames, 3)).copy()
        axes, angles = [], []
        for k, ch in enumerate(joint.channels):
            col = bvh.values[:, joint.first_channel + k]
            if ch in _POS:
                local[:, _POS[ch]] += col
            else:
                axes.append(_ROT[ch])
                angles.append(np.deg2rad(col))
        rot = compose(axes, angles) if axes else np.broadcast_to(np.eye(3), (frames, 3, 3))
        if joint.parent < 0:
            positions[:, j] = local
            rotations[:, j] = rot
        else:
            parent_rot = rotations[:, joint.parent]
            positions[:, j] = positions[:, joint.parent] + np.einsum("fij,fj->fi", parent_rot, local)
            rotations[:, j] = parent_rot @ rot
    return positions


def guess_units(bvh):
    """Guess the unit of a BVH from the height of its rest skeleton (a person is ~1.7 m tall).

    Returns a key of :data:`~mocap_gapfill.core.motion.UNIT_SCALES`.
    """
    rest = np.zeros((len(bvh.joints), 3))
    for j, joint in enumerate(bvh.joints):
        rest[j] = joint.offset + (rest[joint.parent] if joint.parent >= 0 else 0)
    return units_for_height(float(np.ptp(rest[:, 1])) or float(np.ptp(rest)))


def read_bvh(path, units=None, skip_frames=0, end_sites=False, bvh=None):
    """Read a BVH (or ``.bvh.gz``) file into a :class:`Motion`.

    Parameters
    ----------
    units : str, optional
        Unit of the file (a key of ``UNIT_SCALES``); guessed from the skeleton height if None.
    skip_frames : int
        Leading frames to drop (converters often put a reference pose in frame 0).
    end_sites : bool
        Also return End Site positions (named ``<joint>_End``).
    bvh : BvhFile, optional
        The file as :func:`parse_bvh` gave it, for a caller that converts it twice (the
        knowledge-base build: the joints here, the armature in :func:`read_bvh_basis`).
    """
    bvh = bvh or parse_bvh(path)
    if units is None:
        units = guess_units(bvh)
    elif units not in UNIT_SCALES:
        raise ParseError(f"unknown units {units!r} (use one of {', '.join(UNIT_SCALES)})", path)
    if not 0 <= skip_frames <= bvh.values.shape[0]:
        raise ParseError(f"cannot skip {skip_frames} of {bvh.values.shape[0]} frames", path)
    bvh = replace(bvh, values=bvh.values[skip_frames:])  # the caller's stays whole
    keep = [j for j, joint in enumerate(bvh.joints) if end_sites or not joint.end_site]
    positions = forward_kinematics(bvh)[:, keep] * UNIT_SCALES[units]
    remap = {old: new for new, old in enumerate(keep)}
    parents = [remap.get(bvh.joints[j].parent, -1) for j in keep]
    return Motion(
        positions=y_up_to_z_up(positions),
        names=tuple(bvh.joints[j].name for j in keep),
        fps=snap_fps(1.0 / bvh.frame_time),
        parents=tuple(parents),
        limbs=skeleton_limbs(parents),
        source=str(path),
        source_format="bvh",
        units=units,
        up_axis="y",
    )


def read_bvh_rig(path, units=None, skip_frames=0):
    """Read a BVH file as an armature the way Blender's BVH importer builds it (defaults: Y up,
    -Z forward, rotation mode of each bone = its channel order, every frame keyed).

    Returns ``(rig, channels, location, fps)``: a :class:`~..rig.Rig` in metres, Z up (bone
    heads = the joints :func:`read_bvh` gives), and per frame the rotation channels
    (frames, bones, 4) and location channels (frames, bones, 3) Blender keys.
    """
    from ..rig import channels_of

    rig, basis, fps = read_bvh_basis(path, units, skip_frames)
    channels = channels_of(basis[..., :3, :3], rig.modes, previous=np.zeros((len(rig.names), 4)))
    return rig, channels, np.ascontiguousarray(basis[..., :3, 3]), fps


def read_bvh_basis(path, units=None, skip_frames=0, bvh=None):
    """:func:`read_bvh_rig`'s armature with its pose as basis matrices (frames, bones, 4, 4)
    rather than channels: ``(rig, basis, fps)``, what a knowledge base keeps of the take
    (``bvh``: the file already parsed, as :func:`read_bvh` takes it)."""
    from ..rig import Rig, bone_matrix

    bvh = bvh or parse_bvh(path)
    units = units or guess_units(bvh)
    if units not in UNIT_SCALES:
        raise ParseError(f"unknown units {units!r} (use one of {', '.join(UNIT_SCALES)})", path)
    if not 0 <= skip_frames <= bvh.values.shape[0]:
        raise ParseError(f"cannot skip {skip_frames} of {bvh.values.shape[0]} frames", path)
    scale = UNIT_SCALES[units]
    values = bvh.values[skip_frames:]
    joints = bvh.joints
    head = np.zeros((len(joints), 3))
    for j, joint in enumerate(joints):
        head[j] = joint.offset * scale + (head[joint.parent] if joint.parent >= 0 else 0)
    keep = [j for j, joint in enumerate(joints) if not joint.end_site]
    remap = {old: new for new, old in enumerate(keep)}
    to_z_up = np.eye(4)
    to_z_up[:3, :3] = [[1, 0, 0], [0, 0, -1], [0, 1, 0]]
    rest, modes, parents = [], [], []
    frames = values.shape[0]
    basis = np.zeros((frames, len(keep), 4, 4))
    basis[..., 3, 3] = 1.0
    for new, j in enumerate(keep):
        joint = joints[j]
        kids = [c for c, child in enumerate(joints) if child.parent == j]
        ends = [c for c in kids if joints[c].end_site]
        if ends:
            tail = head[ends[0]]
        elif kids:
            tail = head[kids].mean(axis=0)
        else:
            tail = head[j].copy()
        if np.linalg.norm(tail - head[j]) <= 0.001 * scale:
            tail = tail + [0.0, 0.1 * scale, 0.0]
        bone = bone_matrix(head[j], tail)
        rot = bone[:3, :3]
        axes = "".join(_ROT[c] for c in joint.channels if c in _ROT)
        modes.append(axes.upper() if len(axes) == 3 and len(set(axes)) == 3 else "XYZ")
        cols = [joint.first_channel + k for k, c in enumerate(joint.channels) if c in _ROT]
        local = compose(axes, [np.deg2rad(values[:, c]) for c in cols])
        basis[:, new, :3, :3] = rot.T @ local @ rot
        moved = np.zeros((frames, 3))
        for k, c in enumerate(joint.channels):
            if c in _POS:
                moved[:, _POS[c]] = values[:, joint.first_channel + k] * scale
        if any(c in _POS for c in joint.channels):
            basis[:, new, :3, 3] = (moved - joint.offset * scale) @ rot
        rest.append(to_z_up @ bone)
        parents.append(remap.get(joint.parent, -1))
    rig = Rig(tuple(joints[j].name for j in keep), tuple(parents), np.array(rest), tuple(modes))
    return rig, basis, snap_fps(1.0 / bvh.frame_time)
