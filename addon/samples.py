"""The real sample takes shipped in ``sample_scenes/`` (CMU) as Blender scenes: the marker take
01_01 as empties with the gaps it really has, and the Daz-friendly take 03_02 imported by
Blender's own BVH importer with the keys of three bones deleted as an animator would. Each is
given the starter knowledge base without the take's subject, so a fill shows what a take the
knowledge base has never seen gets."""

import gzip
import tempfile
from pathlib import Path

import numpy as np

from ..core.demo import REAL_ARMATURE, REAL_BONE_GAPS, REAL_MARKERS
from ..core.errors import GapFillError
from ..core.evaluate import kb_without, subject_of
from ..core.kb import STARTER_DIR, starter_kb

#: kind -> file in sample_scenes/
SAMPLES = {"MARKERS": REAL_MARKERS, "ARMATURE": REAL_ARMATURE}


def load(context, kind):
    """Import sample ``kind`` (of :data:`SAMPLES`) into the current scene, gaps detected and the
    knowledge base set; returns ``(owner, truth)``: the take's object, and for the armature the
    take as imported, before its keys were deleted (None for the markers)."""
    import bpy

    from . import bridge, compat, gaps

    take = SAMPLES[kind]
    if not (STARTER_DIR / take).is_file():
        raise GapFillError(f"the sample take {take} is not in {STARTER_DIR}")
    scene = context.scene
    truth = None
    if kind == "MARKERS":
        if "FINISHED" not in bpy.ops.mocap_gapfill.import_markers(
                filepath=str(STARTER_DIR / take)):
            raise GapFillError(f"{take} could not be imported (see the report)")
        owner = context.active_object
    else:
        with tempfile.TemporaryDirectory() as tmp:  # Blender's importer reads plain BVH
            bvh = Path(tmp) / take.removesuffix(".gz")
            bvh.write_bytes(gzip.decompress((STARTER_DIR / take).read_bytes()))
            if "FINISHED" not in bpy.ops.import_anim.bvh(
                    filepath=str(bvh), update_scene_fps=True, update_scene_duration=True):
                raise GapFillError(f"Blender's BVH importer could not read {take}")
        owner = context.active_object
        truth = bridge.read_take(owner, scene)
        remove_keys(owner, [(name, a + 1, b + 1) for name, a, b in REAL_BONE_GAPS])
        compat.select_objects(context, [owner], active=owner)
        gaps.detect(owner, scene, suspects=False)  # the deleted keys, not the take's jumps
    scene.mocap_gapfill.kb_path = str(kb_for(take, bridge.read_take(owner, scene).names))
    return owner, truth


def kb_for(take, names):
    """The starter knowledge base that fits ``names`` without the subject of ``take``, saved
    once into the extension's user folder (a temporary folder outside an extension)."""
    import bpy

    path, kb = starter_kb(list(names))
    try:
        folder = Path(bpy.utils.extension_path_user(__package__.rsplit(".", 1)[0], create=True))
    except (AttributeError, ValueError):  # Blender before 4.2, or not installed as an extension
        folder = Path(tempfile.gettempdir()) / "mocap_gapfill"
    folder.mkdir(parents=True, exist_ok=True)
    out = folder / f"{path.stem}_without_{subject_of(take)}.npz"
    if not out.is_file() or out.stat().st_mtime < path.stat().st_mtime:
        kb_without(kb, subject_of(take)).save(out, overwrite=True, compact=True)
    return out


def remove_keys(obj, gaps):
    """Delete the keys of bones over frame ranges: ``[(bone, first, last), ...]``."""
    from . import bridge, compat

    curves = compat.fcurves(obj)
    for bone, first, last in gaps:
        tag = f'pose.bones["{bone}"]'
        for curve in curves:
            if curve.data_path.startswith(tag):
                frames, values = bridge.curve_keys(curve)
                keep = (frames < first) | (frames > last)
                modes = np.empty(len(frames), dtype=np.int32)
                curve.keyframe_points.foreach_get("interpolation", modes)
                curve.keyframe_points.clear()
                curve.keyframe_points.add(int(keep.sum()))
                co = np.empty(2 * int(keep.sum()), dtype=np.float32)
                co[0::2], co[1::2] = frames[keep], values[keep]
                curve.keyframe_points.foreach_set("co", co)
                curve.keyframe_points.foreach_set("interpolation", modes[keep])
                curve.update()


def bone_gap_scores(truth, before, after, bone_gaps=REAL_BONE_GAPS):
    """``{bone: (filled_mm, interpolated_mm)}``: RMSE of the joints each gapped bone places over
    its gap (0-based rows), the filled take and the take as found against the truth."""
    below = truth.extra["rig"].placed_by()
    out = {}
    for bone, a, b in bone_gaps:
        joints = below[list(truth.names).index(bone)]
        ref = truth.positions[a:b + 1, joints] * truth.metres
        out[bone] = tuple(float(1000 * np.sqrt(np.mean(np.sum(
            (take.positions[a:b + 1, joints] * take.metres - ref) ** 2, axis=-1))))
            for take in (after, before))
    return out
