"""The "Mocap" tab of the 3D View sidebar."""

import bpy


class MOCAP_GAPFILL_PT_main(bpy.types.Panel):
    """Mocap Gap Fill"""

    bl_idname = "MOCAP_GAPFILL_PT_main"
    bl_label = "Mocap Gap Fill"
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "Mocap"

    def draw(self, context):
        layout = self.layout
        layout.operator("mocap_gapfill.file_info", icon="FILE")
        info = context.window_manager.mocap_gapfill_last_info
        if info:
            layout.label(text=info)


classes = (MOCAP_GAPFILL_PT_main,)
register, unregister = bpy.utils.register_classes_factory(classes)
