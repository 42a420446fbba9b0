"""Acclaim ASF (skeleton) + AMC (motion) reader, CMU and HDM05 flavours.

The points of the resulting :class:`Motion` are the root and the tip of every bone, named after
the bone (``root``, ``lfemur`` = the knee, ...). Lengths and root translations are in the ASF's
unit: the ``:units`` block's ``length L`` means 1 file unit = 1/L inch (CMU: L = 0.45, so one unit
is 0.056444 m).
"""

import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import ParseError
from ..motion import Motion, skeleton_limbs, y_up_to_z_up
from . import read_text_bytes
from .kinematics import compose

_DOF_AXES = {"rx": "x", "ry": "y", "rz": "z"}
_TRANS = {"tx": 0, "ty": 1, "tz": 2}


@dataclass
class AsfBone:
    name: str
    direction: np.ndarray
    length: float
    axis: np.ndarray  # degrees
    axis_order: str  # e.g. "xyz"
    dofs: list = field(default_factory=list)
    parent: str = None


@dataclass
class AsfSkeleton:
    path: str
    length_scale: float  # the ":units length" value
    angle_unit: str  # "deg" or "rad"
    root_order: list  # e.g. ["tx","ty","tz","rx","ry","rz"]
    root_axis_order: str
    root_position: np.ndarray
    root_orientation: np.ndarray
    bones: dict  # name -> AsfBone, in file order

    @property
    def metres_per_unit(self):
        return 0.0254 / self.length_scale

    def order(self):
        """Bone names with every parent before its children."""
        children = {}
        for bone in self.bones.values():
            children.setdefault(bone.parent, []).append(bone.name)
        result, todo = [], list(reversed(children.get("root", [])))
        while todo:
            name = todo.pop()
            result.append(name)
            todo.extend(reversed(children.get(name, [])))
        return result


def _lines(path):
    text = read_text_bytes(path).decode("utf-8", errors="replace")
    if "\x00" in text:
        raise ParseError("binary data in a text file", path)
    return text.splitlines()


def _floats(parts, path, number, count=None):
    try:
        values = [float(p) for p in parts]
    except ValueError:
        raise ParseError(f"expected numbers, found {' '.join(parts)!r}", path, number) from None
    if count is not None and len(values) != count:
        raise ParseError(f"expected {count} numbers, found {len(values)}", path, number)
    if not np.all(np.isfinite(values)):
        raise ParseError("non-finite number", path, number)
    return values


def parse_asf(path):
    """Parse an ASF skeleton file into an :class:`AsfSkeleton`."""
    lines = _lines(path)
    section = None
    length_scale, angle_unit = 1.0, "deg"
    root_order, root_axis = ["tx", "ty", "tz", "rx", "ry", "rz"], "xyz"
    root_pos, root_ori = np.zeros(3), np.zeros(3)
    bones, bone, last_key = {}, None, None
    hierarchy_seen = False
    for number, raw in enumerate(lines, 1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        if line.startswith(":"):
            parts = line[1:].split()
            section = parts[0].lower() if parts else ""
            continue
        parts = line.split()
        key = parts[0].lower()
        if section == "units":
            if key == "length":
                length_scale = _floats(parts[1:2], path, number, 1)[0]
                if length_scale <= 0:
                    raise ParseError("units length must be positive", path, number)
            elif key == "angle":
                angle_unit = "rad" if parts[1:2] and parts[1].lower().startswith("rad") else "deg"
        elif section == "root":
            if key == "order":
                root_order = [p.lower() for p in parts[1:]]
                if not set(root_order) <= set(_DOF_AXES) | set(_TRANS):
                    raise ParseError(f"unsupported root order {line!r}", path, number)
            elif key == "axis":
                root_axis = _axis_order(parts[1:2], path, number)
            elif key == "position":
                root_pos = np.array(_floats(parts[1:4], path, number, 3))
            elif key == "orientation":
                root_ori = np.array(_floats(parts[1:4], path, number, 3))
        elif section == "bonedata":
            if key == "begin":
                bone = {"number": number}
            elif key == "end":
                if bone is None:
                    raise ParseError("'end' without 'begin'", path, number)
                missing = {"name", "direction", "length"} - set(bone)
                if missing:
                    raise ParseError(f"bone lacks {', '.join(sorted(missing))}", path, number)
                if bone["name"] in bones or bone["name"] == "root":
                    raise ParseError(f"duplicated bone {bone['name']!r}", path, number)
                bones[bone["name"]] = AsfBone(
                    bone["name"], np.asarray(bone["direction"]), bone["length"],
                    np.asarray(bone.get("axis", np.zeros(3))), bone.get("order", "xyz"),
                    bone.get("dof", []))
                bone = None
            elif bone is None:
                raise ParseError(f"{parts[0]!r} outside a begin/end block", path, number)
            elif key == "name":
                bone["name"] = parts[1] if len(parts) > 1 else ""
                if not bone["name"]:
                    raise ParseError("empty bone name", path, number)
            elif key == "direction":
                d = np.array(_floats(parts[1:4], path, number, 3))
                norm = np.linalg.norm(d)
                bone["direction"] = d / norm if norm > 0 else d
            elif key == "length":
                bone["length"] = _floats(parts[1:2], path, number, 1)[0]
            elif key == "axis":
                bone["axis"] = _floats(parts[1:4], path, number, 3)
                bone["order"] = _axis_order(parts[4:5], path, number)
            elif key == "dof":
                dofs = [p.lower() for p in parts[1:]]
                if not set(dofs) <= set(_DOF_AXES):
                    raise ParseError(f"unsupported degrees of freedom {line!r}", path, number)
                bone["dof"] = dofs
            last_key = key
        elif section == "hierarchy":
            if key in ("begin", "end"):
                hierarchy_seen = True
                continue
            parent = parts[0]
            if parent != "root" and parent not in bones:
                raise ParseError(f"unknown bone {parent!r} in hierarchy", path, number)
            for child in parts[1:]:
                if child not in bones:
                    raise ParseError(f"unknown bone {child!r} in hierarchy", path, number)
                if bones[child].parent is not None:
                    raise ParseError(f"bone {child!r} has two parents", path, number)
                bones[child].parent = parent
    del last_key
    if bone is not None:
        raise ParseError("file ends inside a bone block (truncated?)", path, len(lines))
    if not bones:
        raise ParseError("no bones (empty, truncated or not an ASF file)", path)
    if not hierarchy_seen:
        raise ParseError("no :hierarchy section (truncated?)", path)
    skeleton = AsfSkeleton(str(path), length_scale, angle_unit, root_order, root_axis, root_pos,
                           root_ori, bones)
    unreachable = set(bones) - set(skeleton.order())
    if unreachable:
        raise ParseError(f"bones not connected to the root: {', '.join(sorted(unreachable))}", path)
    return skeleton


def _axis_order(parts, path, number):
    order = parts[0].lower() if parts else "xyz"
    if sorted(order) != ["x", "y", "z"]:
        raise ParseError(f"bad axis order {order!r}", path, number)
    return order


def parse_amc(path, skeleton):
    """Parse an AMC file against its skeleton: a dict bone name -> (frames, dofs) array."""
    lines = _lines(path)
    degrees = skeleton.angle_unit == "deg"
    expected = {"root": len(skeleton.root_order)}
    expected.update({b.name: len(b.dofs) for b in skeleton.bones.values() if b.dofs})
    frames, current, current_line = [], None, None

    def close():
        if current is None:
            return
        lacking = sorted(set(expected) - set(current))
        if lacking:
            raise ParseError(f"frame lacks {', '.join(lacking)}", path, current_line,
                             frame=len(frames))
        frames.append(current)

    for number, raw in enumerate(lines, 1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        if line.startswith(":"):
            word = line[1:].strip().lower()
            if word == "radians":
                degrees = False
            elif word == "degrees":
                degrees = True
            continue
        parts = line.split()
        if len(parts) == 1 and re.fullmatch(r"\d+", parts[0]):
            close()
            current, current_line = {}, number
            continue
        if current is None:
            raise ParseError(f"data before the first frame number: {line[:40]!r}", path, number)
        name = parts[0]
        if name not in expected:
            if name in skeleton.bones:  # a bone without degrees of freedom may still be listed
                continue
            raise ParseError(f"unknown bone {name!r}", path, number)
        if name in current:
            raise ParseError(f"bone {name!r} twice in one frame", path, number)
        current[name] = _floats(parts[1:], path, number, expected[name])
    close()
    if not frames:
        raise ParseError("no frames (empty or truncated AMC)", path)
    data = {name: np.array([f[name] for f in frames], dtype=float) for name in expected}
    return data, degrees


def amc_forward_kinematics(skeleton, data, degrees=True):
    """Positions of the root and every bone tip, file units and axes: (frames, 1 + bones, 3)."""
    to_rad = np.deg2rad if degrees else (lambda a: np.asarray(a, dtype=float))
    root = data["root"]
    frames = root.shape[0]
    order = skeleton.order()
    positions = np.zeros((frames, 1 + len(order), 3))
    index = {"root": 0}
    # root
    trans = np.zeros((frames, 3))
    axes, angles = [], []
    for k, dof in enumerate(skeleton.root_order):
        if dof in _TRANS:
            trans[:, _TRANS[dof]] = root[:, k]
        else:
            axes.append(_DOF_AXES[dof])
            angles.append(to_rad(root[:, k]))
    c = _axis_matrix(skeleton.root_orientation, skeleton.root_axis_order)
    rot = c @ compose(list(reversed(axes)), list(reversed(angles))) @ c.T
    positions[:, 0] = skeleton.root_position + trans
    matrices = {"root": rot}
    for i, name in enumerate(order, 1):
        bone = skeleton.bones[name]
        index[name] = i
        c = _axis_matrix(bone.axis, bone.axis_order)
        if bone.dofs:
            values = data[name]
            dof_rot = compose([_DOF_AXES[d] for d in reversed(bone.dofs)],
                              [to_rad(values[:, k]) for k in reversed(range(len(bone.dofs)))])
            local = c @ dof_rot @ c.T
        else:
            local = np.broadcast_to(np.eye(3), (frames, 3, 3))
        matrices[name] = matrices[bone.parent] @ local
        tip = np.einsum("fij,j->fi", matrices[name], bone.direction * bone.length)
        positions[:, i] = positions[:, index[bone.parent]] + tip
    return positions, ["root"] + order


def _axis_matrix(angles_xyz, order):
    """A bone's local frame C from its ``axis`` angles (degrees, given as x y z), rotations
    applied in ``order`` (``"xyz"``: first about x, so C = Rz Ry Rx)."""
    by_axis = dict(zip("xyz", np.deg2rad(np.asarray(angles_xyz, dtype=float))))
    return compose(list(reversed(order)), [by_axis[a] for a in reversed(order)])


def find_asf(amc_path):
    """The ASF that belongs to an AMC: same stem, else the stem cut at '_' (``01_01`` -> ``01``,
    ``HDM_dg_06-03_03_120`` -> ``HDM_dg``), else the only ASF in the folder."""
    amc_path = Path(amc_path)
    parts = amc_path.stem.split("_")
    for n in range(len(parts), 0, -1):
        candidate = amc_path.with_name("_".join(parts[:n]) + ".asf")
        if candidate.is_file():
            return candidate
    others = sorted(amc_path.parent.glob("*.asf"))
    if len(others) == 1:
        return others[0]
    raise ParseError("no matching ASF skeleton beside this AMC; name it with --asf", amc_path)


def read_asf_amc(amc_path, asf_path=None):
    """Read an AMC motion (and its ASF skeleton) into a :class:`Motion`."""
    asf_path = find_asf(amc_path) if asf_path is None else asf_path
    skeleton = parse_asf(asf_path)
    data, degrees = parse_amc(amc_path, skeleton)
    positions, names = amc_forward_kinematics(skeleton, data, degrees)
    zero = {name: np.zeros((1, values.shape[1])) for name, values in data.items()}
    rest, _ = amc_forward_kinematics(skeleton, zero, degrees)
    index = {n: i for i, n in enumerate(names)}
    parents = [-1] + [index[skeleton.bones[n].parent] for n in names[1:]]
    return Motion(
        positions=y_up_to_z_up(positions * skeleton.metres_per_unit),
        names=tuple(names),
        fps=120.0,
        parents=tuple(parents),
        limbs=skeleton_limbs(parents),
        source=str(amc_path),
        source_format="asf/amc",
        units="cmu" if abs(skeleton.length_scale - 0.45) < 1e-9 else "in",
        up_axis="y",
        rest=y_up_to_z_up(rest[0] * skeleton.metres_per_unit),
    )
