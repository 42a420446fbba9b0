"""Operators. Each reads like a sentence: Blender data -> core -> Blender data."""

import bpy
from bpy.props import StringProperty
from bpy_extras.io_utils import ImportHelper


class MOCAP_GAPFILL_OT_file_info(bpy.types.Operator, ImportHelper):
    """Read a motion capture file (C3D, BVH, AMC) and report its frames, rate, points and gaps"""

    bl_idname = "mocap_gapfill.file_info"
    bl_label = "Inspect Mocap File"
    bl_options = {"REGISTER"}

    filter_glob: StringProperty(default="*.c3d;*.bvh;*.bvh.gz;*.amc;*.npz;*.csv",
                                options={"HIDDEN"})

    def execute(self, context):
        from ..core.errors import GapFillError
        from ..core.io import read_motion

        try:
            summary = read_motion(self.filepath).summary()
        except GapFillError as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        gaps = (f"{100 * summary['missing_fraction']:.2f} % missing in {summary['gaps']} gaps, "
                f"longest {summary['longest_gap_frames']} frames" if summary["gaps"] else "no gaps")
        context.window_manager.mocap_gapfill_last_info = (
            f"{summary['frames']} frames at {summary['fps']:g} fps, {summary['points']} points, "
            f"{gaps}")
        self.report({"INFO"}, context.window_manager.mocap_gapfill_last_info)
        return {"FINISHED"}


classes = (MOCAP_GAPFILL_OT_file_info,)
_register_classes, _unregister_classes = bpy.utils.register_classes_factory(classes)


def register():
    _register_classes()
    bpy.types.WindowManager.mocap_gapfill_last_info = StringProperty(
        name="Last inspected file", options={"SKIP_SAVE"})


def unregister():
    del bpy.types.WindowManager.mocap_gapfill_last_info
    _unregister_classes()
