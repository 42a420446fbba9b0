"""The one module that turns Blender data into arrays for the core, and arrays back into keys.

Two kinds of "take" live in a scene:

- a **marker set**: an empty whose child empties carry location keys, one per marker (what
  :func:`import_markers` makes from a C3D). A frame without a key is a missing sample.
- an **armature**: joint positions are the bone heads (a BVH import), or, for armatures our
  ASF/AMC import makes (one bone per segment), the bone tails and the root's head. A bone
  without keys on a frame has an unknown rotation, so the joints it and its descendants place are
  missing (:func:`..core.posing.points_missing`).

Positions go to the core in metres, Z up, world space (:func:`to_metres` gives the scale of an
object's units). Keys are read and written with ``foreach_get`` / ``foreach_set`` on numpy
buffers. Recovered keys never go into the original action: :func:`recovered_action` makes a
copy once and the object plays it; the original stays on the object's settings for preview.
"""

import re
from dataclasses import dataclass, field

import bpy
import numpy as np

from ..core.motion import UNIT_SCALES, Motion, rigid_marker_pairs, skeleton_limbs, units_for_height
from ..core.posing import bones_to_blame, points_missing, solve_pose, tail_handles
from ..core.rig import Rig, bone_ends, skeleton_basis
from . import compat

MARKER_SET = "mocap_gapfill_marker_set"  # custom property on the parent empty of a marker set
MARKER_LABEL = "mocap_gapfill_label"  # custom property of a marker: its name in the file
TAILS = "mocap_gapfill_tails"  # custom property of armatures whose joints are bone tails
LINEAR = 1  # Keyframe.interpolation "LINEAR" as foreach_set takes it
ROTATION_PATHS = {"QUATERNION": ("rotation_quaternion", 4),
                  "AXIS_ANGLE": ("rotation_axis_angle", 4)}  # others: Euler


# ---- keys --------------------------------------------------------------------------------------
def curve_keys(curve):
    """``(frames, values)`` of an F-curve's keys as float arrays."""
    co = np.empty(2 * len(curve.keyframe_points), dtype=np.float32)
    curve.keyframe_points.foreach_get("co", co)
    return co[0::2].astype(np.float64), co[1::2].astype(np.float64)


def set_keys(curves, data_path, index, frames, values, group, key_type="GENERATED"):
    """Add keys to a channel (made if needed), replacing keys on the same frames; new keys get
    ``key_type`` so filled keys stand out in the Dope Sheet and Graph Editor."""
    curve = curves.find(data_path, index=index) or compat.new_fcurve(curves, data_path, index,
                                                                       group)
    old_frames, old_values, old_types, old_modes = _keys(curve)
    keep = ~np.isin(np.round(old_frames), np.round(frames))
    frames_all = np.concatenate([old_frames[keep], frames])
    values_all = np.concatenate([old_values[keep], values])
    types = np.concatenate([old_types[keep],
                            np.full(len(frames), compat.KEY_TYPES[key_type], dtype=np.int32)])
    # kept keys keep their interpolation; new ones are linear (what a mocap importer keys)
    modes = np.concatenate([old_modes[keep], np.full(len(frames), LINEAR, dtype=np.int32)])
    _rewrite(curve, frames_all, values_all, types, modes)
    return curve


def _keys(curve):
    """``(frames, values, types, interpolations)`` of an F-curve's keys; the last two as the
    integers ``foreach_get`` gives."""
    frames, values = curve_keys(curve)
    types = np.empty(len(frames), dtype=np.int32)
    modes = np.empty(len(frames), dtype=np.int32)
    if len(frames):
        curve.keyframe_points.foreach_get("type", types)
        curve.keyframe_points.foreach_get("interpolation", modes)
    return frames, values, types, modes


def _rewrite(curve, frames, values, types, modes):
    """Replace an F-curve's keys (in frame order) in one go."""
    order = np.argsort(frames, kind="stable")
    curve.keyframe_points.clear()
    curve.keyframe_points.add(len(order))
    co = np.empty(2 * len(order), dtype=np.float32)
    co[0::2], co[1::2] = frames[order], values[order]
    curve.keyframe_points.foreach_set("co", co)
    curve.keyframe_points.foreach_set("type", types[order])
    curve.keyframe_points.foreach_set("interpolation", modes[order])
    curve.update()


def revert_keys(owner, point, first, last, every=False):
    """Take the filled keys (typed GENERATED; ``every``: all keys, a marker's cut for the fill)
    of ``point`` (a bone of an armature, a marker of a marker set) on frames ``first``-``last``
    out of its recovered action: the keys either side show there again as the original shows
    them; the recovered actions play afterwards. Returns how many keys went."""
    if is_marker_set(owner):
        target, prefix = bpy.data.objects.get(point), "location"
    else:
        target, prefix = owner, f'pose.bones["{bpy.utils.escape_identifier(point)}"].'
    if target is not None and every:
        original_action(target)
        recovered_action(target)
    if target is None or target.mocap_gapfill.recovered_action is None:
        return 0
    show(owner, "RECOVERED")
    removed = 0
    for curve in compat.fcurves(target) or ():
        if not curve.data_path.startswith(prefix):
            continue
        frames, values, types, modes = _keys(curve)
        drop = (((types == compat.KEY_TYPES["GENERATED"]) | every) & (np.round(frames) >= first)
                & (np.round(frames) <= last))
        if drop.any():
            _rewrite(curve, frames[~drop], values[~drop], types[~drop], modes[~drop])
            removed += int(drop.sum())
    return removed


def _keyed_frames(curves, data_path, count):
    frames = set()
    for i in range(count):
        curve = curves.find(data_path, index=i)
        if curve is not None:
            frames.update(np.round(curve_keys(curve)[0]).astype(int).tolist())
    return frames


# ---- units ---------------------------------------------------------------------------------------
def to_metres(units, height):
    """Metres per Blender unit: ``units`` is a key of UNIT_SCALES or "AUTO" (guessed from the
    height of the take in Blender units, a person being ~1.7 m)."""
    key = units_for_height(height) if units == "AUTO" else units.lower()
    return UNIT_SCALES[key]


# ---- takes -------------------------------------------------------------------------------------
@dataclass
class Take:
    """What the core needs of one object's animation, and what writing back needs."""

    name: str  # the object owning the gaps
    kind: str  # "markers" or "armature"
    first: int  # Blender frame of row 0
    points: tuple  # marker or bone names
    positions: np.ndarray  # (frames, points, 3) world space, Blender units, NaN where no key
    keyed: np.ndarray  # (frames, points) bool: a key (markers) / a rotation or location key (bones)
    fps: float
    metres: float  # metres per Blender unit
    world: np.ndarray  # (4, 4) object space -> world space
    parents: tuple = None
    extra: dict = field(default_factory=dict)
    labels: tuple = None  # the points' own names where they differ from the objects' (markers)

    @property
    def names(self):
        """The points' names for the core (knowledge bases match these)."""
        return self.labels or self.points

    def motion(self, missing):
        """A core :class:`Motion` (metres) with ``missing`` (frames, points) samples removed."""
        known = self.positions * self.metres
        if self.kind == "armature":
            limbs = skeleton_limbs(self.parents)
        else:
            limbs = rigid_marker_pairs(known)
        return Motion(np.where(missing[..., None], np.nan, known), self.names, self.fps,
                      parents=self.parents, limbs=limbs, source=self.name,
                      source_format="blender")


def scene_fps(scene):
    """The scene's frame rate; within a millionth of a whole rate, that rate (Blender's BVH
    importer sets 120.000048 from a frame time of 0.00833333, which the command line reads as
    120: a 90-frame gap is then 0.75 s in both). NTSC rates (30 / 1.001) stay as they are."""
    fps = scene.render.fps / scene.render.fps_base
    nearest = round(fps)
    return float(nearest) if nearest and abs(fps - nearest) < 1e-6 * nearest else fps


def is_marker_set(obj):
    return obj is not None and obj.type == "EMPTY" and bool(obj.get(MARKER_SET))


def take_owner(obj):
    """The object owning the gaps of ``obj``: an armature, or the marker set of a marker."""
    if obj is None:
        return None
    if obj.type == "ARMATURE" or is_marker_set(obj):
        return obj
    if obj.parent is not None and is_marker_set(obj.parent):
        return obj.parent
    return None


def markers_of(root):
    """The marker empties of a marker set, in name order."""
    return sorted((c for c in root.children if c.type == "EMPTY"), key=lambda c: c.name)


def _matrix(m):
    return np.array(m, dtype=np.float64)


def read_markers(root, scene):
    """A marker set's location keys as a :class:`Take` (parent space -> world space)."""
    children = markers_of(root)
    keys = []
    for child in children:
        curves = compat.fcurves(child)
        per_axis = [curves and curves.find("location", index=i) for i in range(3)]
        if curves is None or any(c is None for c in per_axis):
            keys.append((np.zeros(0, dtype=int), np.zeros((0, 3))))
            continue
        axes = [curve_keys(c) for c in per_axis]
        frames = axes[0][0]
        # the frames of x; y and z are read from their keys where keyed alike (our import),
        # else evaluated there
        values = np.stack([v if np.array_equal(f, frames) else [c.evaluate(t) for t in frames]
                           for (f, v), c in zip(axes, per_axis)], axis=1)
        keys.append((np.round(frames).astype(int), values))
    all_frames = np.concatenate([k[0] for k in keys]) if keys else np.zeros(0, dtype=int)
    if not len(all_frames):
        raise ValueError(f"'{root.name}' has no marker keys")
    first, last = int(all_frames.min()), int(all_frames.max())
    local = np.full((last - first + 1, len(children), 3), np.nan)
    for j, (frames, values) in enumerate(keys):
        local[frames - first, j] = values
    world = _matrix(root.matrix_world)
    inverse = np.stack([_matrix(c.matrix_parent_inverse) for c in children])
    pos = np.einsum("pij,fpj->fpi", world[:3, :3] @ inverse[:, :3, :3], local)
    pos += (world[:3, :3] @ inverse[:, :3, 3].T).T + world[:3, 3]
    height = np.nanmedian(np.nanmax(pos[..., 2], axis=1) - np.nanmin(pos[..., 2], axis=1))
    units = root.mocap_gapfill.units
    return Take(root.name, "markers", first, tuple(c.name for c in children), pos,
                ~np.isnan(local[..., 0]), scene_fps(scene), to_metres(units, height), world,
                extra={"inverse": inverse}, labels=tuple(marker_label(c) for c in children))


def marker_label(obj):
    """A marker's own name: the label it was imported with, else its object's name without the
    ``.001`` Blender adds when a second take brings markers of the same names."""
    return str(obj.get(MARKER_LABEL) or re.sub(r"\.\d{3}$", "", obj.name))


def _matrices(collection, prop, count):
    buf = np.empty(count * 16, dtype=np.float32)
    collection.foreach_get(prop, buf)
    return buf.reshape(count, 4, 4).transpose(0, 2, 1).astype(np.float64)  # column-major in RNA


def _frame_range(obj):
    curves = compat.fcurves(obj)
    frames = [curve_keys(c)[0] for c in curves or ()]
    frames = np.concatenate(frames) if frames else np.zeros(0)
    if not len(frames):
        raise ValueError(f"'{obj.name}' has no keys")
    return int(np.floor(frames.min())), int(np.ceil(frames.max()))


def read_armature(obj, scene):
    """An armature's joints (bone heads, or tails for our ASF/AMC armatures) over its keyed
    range as a :class:`Take`, with what writing back needs: rest matrices, the evaluated basis
    matrices (the twist reference inside gaps), which bones have animated locations, each
    bone's rotation mode and what each bone places (tail handles for our armatures)."""
    first, last = _frame_range(obj)
    bones = obj.pose.bones
    names = tuple(b.name for b in bones)
    index = {n: i for i, n in enumerate(names)}
    parents = tuple(index[b.parent.name] if b.parent else -1 for b in bones)
    n = len(names)
    frames = last - first + 1
    tails = bool(obj.get(TAILS))
    heads = np.empty((frames, n, 3))
    basis = np.empty((frames, n, 4, 4))
    channels = np.zeros((frames, n, 4))
    location = np.empty((frames, n, 3))
    modes = tuple(b.rotation_mode for b in bones)
    quaternion = np.array([m in ROTATION_PATHS for m in modes])  # 4 values: w x y z / angle x y z
    keep = scene.frame_current
    buf = np.empty(n * 3, dtype=np.float32)
    buf4 = np.empty(n * 4, dtype=np.float32)
    ends = np.array([tails and p >= 0 for p in parents])
    for f in range(frames):
        scene.frame_set(first + f)
        bones.foreach_get("head", buf)
        heads[f] = buf.reshape(n, 3)
        if tails:
            bones.foreach_get("tail", buf)
            heads[f, ends] = buf.reshape(n, 3)[ends]
        basis[f] = _matrices(bones, "matrix_basis", n)
        bones.foreach_get("location", buf)
        location[f] = buf.reshape(n, 3)
        bones.foreach_get("rotation_euler", buf)
        channels[f, :, :3] = buf.reshape(n, 3)
        for mode, path in (("QUATERNION", "rotation_quaternion"),
                           ("AXIS_ANGLE", "rotation_axis_angle")):
            if mode in modes:
                bones.foreach_get(path, buf4)
                rows = np.array([m == mode for m in modes])
                channels[f, rows] = buf4.reshape(n, 4)[rows]
    scene.frame_set(keep)
    channels[:, ~quaternion, 3] = 0.0
    curves = compat.fcurves(obj)
    keyed = np.zeros((frames, n), dtype=bool)
    moves = np.zeros(n, dtype=bool)
    for j, b in enumerate(bones):
        path = f'pose.bones["{bpy.utils.escape_identifier(b.name)}"]'
        rot_path, count = ROTATION_PATHS.get(b.rotation_mode, ("rotation_euler", 3))
        rot = _keyed_frames(curves, f"{path}.{rot_path}", count)
        loc = _keyed_frames(curves, f"{path}.location", 3)
        moves[j] = bool(loc) and not b.bone.use_connect
        for f in rot | (loc if moves[j] else set()):
            if first <= f <= last:
                keyed[f - first, j] = True
    world = _matrix(obj.matrix_world)
    pos = heads @ world[:3, :3].T + world[:3, 3]
    rest = _matrices(obj.data.bones, "matrix_local", n)
    rest_heads = rest[:, :3, 3] @ world[:3, :3].T
    height = float(np.ptp(rest_heads[:, 2])) if n > 1 else 0.0
    lengths = np.empty(n, dtype=np.float32)
    obj.data.bones.foreach_get("length", lengths)
    rig = Rig(names, parents, rest, modes, lengths.astype(np.float64) if tails else None)
    return Take(obj.name, "armature", first, names, pos, keyed, scene_fps(scene),
                to_metres(obj.mocap_gapfill.units, height), world, parents,
                extra={"rest": rest, "basis": basis, "moves": moves, "modes": modes,
                       "handles": tail_handles(lengths, parents) if tails else None,
                       "rig": rig, "channels": channels, "location": location})


def read_take(obj, scene):
    owner = take_owner(obj)
    if owner is None:
        raise ValueError(f"'{obj.name}' is neither an armature nor part of a marker set")
    return read_markers(owner, scene) if owner.type == "EMPTY" else read_armature(owner, scene)


def _placed_by_own_bone(take):
    """Which joints move with their own bone's rotation (tails) or location (moving heads)."""
    if take.extra["handles"] is not None:
        return np.ones(len(take.points), dtype=bool)
    return take.extra["moves"]


def missing_points(take, gap_mask):
    """Point samples unknown under per-point gaps (markers) or per-bone gaps (armatures)."""
    if take.kind == "armature":
        return points_missing(gap_mask, take.parents, _placed_by_own_bone(take))
    return gap_mask.copy()


def blame_bones(take, suspect):
    """Bone gaps that explain suspect joint samples of an armature."""
    if take.extra["handles"] is not None:  # a tail moves with its own bone only
        return suspect.copy()
    return bones_to_blame(suspect, take.parents, take.extra["moves"])


def unkeyed(take):
    """Samples with no key inside the take's range: markers never keyed there; bones without
    keys on frames (over the whole range for a bone never keyed while others are), skipping
    bones whose rotation places no joint (leaf bones of a BVH armature)."""
    gaps = ~take.keyed
    if take.kind == "armature":
        places = np.isin(np.arange(len(take.points)), take.parents) | _placed_by_own_bone(take)
        gaps &= places & take.keyed.any()
    return gaps


# ---- actions -----------------------------------------------------------------------------------
def original_action(obj):
    """The action the object had before any fill (remembered on first use)."""
    settings = obj.mocap_gapfill
    if settings.original_action is None and obj.animation_data and obj.animation_data.action:
        settings.original_action = obj.animation_data.action
        settings.original_action.use_fake_user = True
    return settings.original_action


def recovered_action(obj):
    """The action recovered keys go into: a copy of the original, made once and then reused.
    The object plays it afterwards."""
    settings = obj.mocap_gapfill
    original = original_action(obj)
    if settings.recovered_action is None:
        action = original.copy()
        action.name = original.name + ".recovered"
        action.use_fake_user = True
        settings.recovered_action = action
    if obj.animation_data.action != settings.recovered_action:
        compat.assign_action(obj, settings.recovered_action)
    return settings.recovered_action


def show(obj, which):
    """Play the ``"ORIGINAL"`` or ``"RECOVERED"`` action on the object (and its markers)."""
    targets = markers_of(obj) if is_marker_set(obj) else [obj]
    for target in targets:
        action = getattr(target.mocap_gapfill, f"{which.lower()}_action")
        if action is not None:
            compat.assign_action(target, action)


# ---- writing back ------------------------------------------------------------------------------
def write_markers(take, filled, mask):
    """Location keys on the filled samples of a marker set (world metres -> parent space)."""
    root = bpy.data.objects[take.name]
    children = {c.name: c for c in markers_of(root)}
    world_inv = np.linalg.inv(take.world)
    written = 0
    for j, name in enumerate(take.points):
        rows = np.flatnonzero(mask[:, j])
        if not len(rows):
            continue
        child = children[name]
        original_action(child)
        recovered_action(child)
        local_from_world = np.linalg.inv(take.extra["inverse"][j]) @ world_inv
        p = filled[rows, j] / take.metres
        local = p @ local_from_world[:3, :3].T + local_from_world[:3, 3]
        curves = compat.fcurves(child, create=True)
        for axis in range(3):
            set_keys(curves, "location", axis, rows + take.first, local[:, axis], child.name)
        written += len(rows)
    return written


def solve_armature(take, filled, bone_gaps):
    """Basis matrices for the gap frames of an armature and the heads they give (world units).

    Targets are the filled joint positions in armature space; rotations are solved where a bone
    has a gap, locations where a moving bone has one.
    """
    world_inv = np.linalg.inv(take.world)
    targets = (filled / take.metres) @ world_inv[:3, :3].T + world_inv[:3, 3]
    moves = take.extra["moves"]
    basis, pose = solve_pose(take.extra["rest"], take.parents, take.extra["basis"], targets,
                             bone_gaps, bone_gaps & moves, take.extra["handles"])
    return basis, pose


def write_armature(take, basis, bone_gaps, recovered=True):
    """Rotation (and location, for moving bones) keys of the gap frames, in each bone's rotation
    mode, continuous with the key before each gap (compatible Euler angles, quaternion signs).
    Into the recovered action, typed GENERATED; with ``recovered=False`` (import), into the
    current action as ordinary keys."""
    from mathutils import Matrix

    obj = bpy.data.objects[take.name]
    key_type = "GENERATED" if recovered else "KEYFRAME"
    if recovered:
        original_action(obj)
        recovered_action(obj)
    curves = compat.fcurves(obj, create=True)
    written = 0
    for j, name in enumerate(take.points):
        rows = np.flatnonzero(bone_gaps[:, j])
        if not len(rows):
            continue
        mode = take.extra["modes"][j]
        path = f'pose.bones["{bpy.utils.escape_identifier(name)}"]'
        rot_path, count = ROTATION_PATHS.get(mode, ("rotation_euler", 3))
        channels = [curves.find(f"{path}.{rot_path}", index=i) for i in range(count)]
        values, previous = [], None
        for k, r in enumerate(rows):
            if k == 0 or rows[k - 1] != r - 1:  # a new run: continue from the value before it
                frame = take.first + r - 1
                previous = (tuple(c.evaluate(frame) for c in channels)
                            if all(c is not None for c in channels) else None)
            previous = _rotation_values(Matrix(basis[r, j].tolist()), mode, previous)
            values.append(previous)
        values = np.array(values)
        for axis in range(count):
            set_keys(curves, f"{path}.{rot_path}", axis, rows + take.first, values[:, axis], name,
                     key_type)
        if take.extra["moves"][j]:
            for axis in range(3):
                set_keys(curves, f"{path}.location", axis, rows + take.first,
                         basis[rows, j, axis, 3], name, key_type)
        written += len(rows)
    return written


def _rotation_values(matrix, mode, previous):
    """Rotation of a 4x4 basis matrix as the values of a bone's rotation mode, chosen closest to
    ``previous`` (Euler: compatible angles; quaternion: same hemisphere)."""
    from mathutils import Euler, Quaternion

    rot = matrix.to_3x3().normalized()
    if mode == "QUATERNION":
        q = rot.to_quaternion()
        if previous is not None:
            q.make_compatible(Quaternion(previous))
        return tuple(q)
    if mode == "AXIS_ANGLE":
        axis, angle = rot.to_quaternion().to_axis_angle()
        return (angle, *axis)
    if previous is not None:
        return tuple(rot.to_euler(mode, Euler(previous, mode)))
    return tuple(rot.to_euler(mode))


# ---- import ------------------------------------------------------------------------------------
def _link(context, obj, collection=None):
    (collection or context.scene.collection).objects.link(obj)
    return obj


def import_markers(context, motion, name, first_frame=1):
    """Make a marker set from a core :class:`Motion`: a parent empty and one child empty per
    point, location keys only where the point is present (metres, Z up). Returns the parent."""
    root = _link(context, bpy.data.objects.new(name, None))
    root.empty_display_type = "ARROWS"
    root[MARKER_SET] = True
    root.mocap_gapfill.units = "M"
    frames = np.arange(motion.n_frames) + first_frame
    for j, label in enumerate(motion.names):
        child = _link(context, bpy.data.objects.new(label, None))
        child[MARKER_LABEL] = label  # the name may become LFHD.001 beside another take
        child.empty_display_type = "SPHERE"
        child.empty_display_size = 0.012
        child.parent = root
        present = ~motion.missing[:, j]
        action = bpy.data.actions.new(f"{name}|{label}")
        compat.assign_action(child, action)
        curves = compat.fcurves(child, create=True)
        if present.any():
            for axis in range(3):
                set_keys(curves, "location", axis, frames[present],
                         motion.positions[present, j, axis], child.name, key_type="KEYFRAME")
            child.location = motion.positions[np.flatnonzero(present)[0], j]
    set_scene_timing(context.scene, motion.fps, first_frame, first_frame + motion.n_frames - 1)
    return root


def set_scene_timing(scene, fps, first, last):
    rate = round(fps)
    scene.render.fps = max(1, rate)
    scene.render.fps_base = rate / fps if rate else 1.0
    scene.frame_start, scene.frame_end = first, last


def import_armature(context, motion, name, first_frame=1):
    """Make an armature from a skeleton :class:`Motion` (e.g. ASF/AMC): one bone per segment,
    from the parent joint (head) to the joint (tail), plus a short root bone at the root; rest
    pose = the skeleton's own (an ASF's zero pose) or else the first complete frame
    (:func:`~..core.rig.bone_ends`); root location and every rotation keyed per frame, so the
    tails follow the joints exactly (joints with several children, like the CMU thorax, need a
    bone per child: one bone per joint could not place them all)."""
    heads, tails = bone_ends(motion)  # GapFillError without a complete frame
    arm = bpy.data.armatures.new(name)
    obj = _link(context, bpy.data.objects.new(name, arm))
    obj[TAILS] = True
    obj.mocap_gapfill.units = "M"
    previous_active = context.view_layer.objects.active
    context.view_layer.objects.active = obj
    bpy.ops.object.mode_set(mode="EDIT")
    for label, head, tail in zip(motion.names, heads, tails):
        bone = arm.edit_bones.new(label)
        bone.head, bone.tail = head, tail
    for j, p in enumerate(motion.parents):
        if p >= 0:
            arm.edit_bones[j].parent = arm.edit_bones[p]
    bpy.ops.object.mode_set(mode="OBJECT")
    context.view_layer.objects.active = previous_active
    for pbone in obj.pose.bones:
        pbone.rotation_mode = "QUATERNION"
    compat.assign_action(obj, bpy.data.actions.new(name))
    n = motion.n_points
    rest = _matrices(arm.bones, "matrix_local", n)
    lengths = np.empty(n, dtype=np.float32)
    arm.bones.foreach_get("length", lengths)
    present, parents = ~motion.missing, motion.parents
    basis = skeleton_basis(rest, parents, lengths, motion.positions, present)
    take = Take(obj.name, "armature", first_frame, motion.names, motion.positions, present,
                motion.fps, 1.0, np.eye(4), parents,
                extra={"rest": rest, "basis": basis, "moves": np.array([p < 0 for p in parents]),
                       "modes": ("QUATERNION",) * n, "handles": tail_handles(lengths, parents)})
    write_armature(take, basis, present, recovered=False)
    set_scene_timing(context.scene, motion.fps, first_frame, first_frame + motion.n_frames - 1)
    return obj

