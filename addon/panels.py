"""The "Mocap" tab of the 3D View sidebar: import, knowledge base, gaps, fill, preview."""

import bpy

from ..core import explain
from . import bridge, gaps, prefs
from .props import GAP_KINDS, PROBLEMS


class MOCAP_GAPFILL_UL_gaps(bpy.types.UIList):
    """Gaps of a take: point, frames, kind; filled gaps carry a check mark (an armature's gap
    where the interpolation was kept, a curve) and a marker's what copies of it expect of the
    error"""

    worst_first: bpy.props.BoolProperty(
        name="Worst First", description="Sort marker gaps by their expected error, largest first")

    def draw_item(self, context, layout, data, item, icon, active_data, active_propname, index):
        icons = {kind: icon for kind, _, _, icon, _ in GAP_KINDS}
        row = layout.row(align=True)
        split = row.split(factor=0.45, align=True)
        split.label(text=f"{item.point} / {item.other}" if item.other else item.point,
                    icon=icons[item.kind])
        frames = f"{item.first}-{item.last}"
        if item.expected_mm:  # what copies of a marker's gap expect of the fill's error
            split.label(text=f"~{item.expected_mm:.0f}mm {frames}")
        else:
            split.label(text=f"{frames} ({item.last - item.first + 1})")
        # filled (an armature's gap where Blender's interpolation was kept: its curve icon)
        row.label(text="", icon="IPO_LINEAR" if item.how == explain.KEPT else
                  "CHECKMARK" if item.filled else "TOOL_SETTINGS" if item.repaired else
                  "BLANK1")

    def draw_filter(self, context, layout):
        row = layout.row(align=True)
        row.prop(self, "filter_name", text="")
        row.prop(self, "worst_first", text="", icon="SORT_DESC")

    def filter_items(self, context, data, propname):
        items = getattr(data, propname)
        flags = [self.bitflag_filter_item] * len(items)
        if self.filter_name:
            needle = self.filter_name.lower()
            flags = [self.bitflag_filter_item if needle in g.point.lower() else 0 for g in items]
        order = []
        if self.worst_first:
            order = bpy.types.UI_UL_list.sort_items_helper(
                [(i, g.expected_mm) for i, g in enumerate(items)], key=lambda item: -item[1])
        return flags, order


class MOCAP_GAPFILL_UL_points(bpy.types.UIList):
    """Per-point totals: gaps, missing frames and share, longest gap"""

    def draw_item(self, context, layout, data, item, icon, active_data, active_propname, index):
        row = layout.row(align=True)
        row.label(text=item.name)
        row.label(text=f"{item.gaps} gaps")
        row.label(text=f"{item.percent:.1f} %")
        row.label(text=f"max {item.longest}")


class _Panel:
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "Mocap"


class MOCAP_GAPFILL_PT_main(_Panel, bpy.types.Panel):
    """Mocap Gap Fill"""

    bl_idname = "MOCAP_GAPFILL_PT_main"
    bl_label = "Mocap Gap Fill"

    def draw(self, context):
        layout = self.layout
        row = layout.row(align=True)
        row.operator("mocap_gapfill.import_markers", text="C3D", icon="EMPTY_DATA")
        row.operator("mocap_gapfill.import_skeleton", text="ASF/AMC", icon="ARMATURE_DATA")
        row.operator("mocap_gapfill.file_info", text="", icon="INFO")
        row = layout.row(align=True)
        row.label(text="Sample:")
        row.operator("mocap_gapfill.open_sample", text="Markers", icon="EMPTY_DATA").kind = \
            "MARKERS"
        row.operator("mocap_gapfill.open_sample", text="Armature",
                     icon="ARMATURE_DATA").kind = "ARMATURE"
        info = context.window_manager.mocap_gapfill.last_info
        if info:
            layout.label(text=info)
        owner = bridge.take_owner(context.active_object)
        layout.label(text=f"Take: {owner.name}" if owner else "Select an armature or marker set",
                     icon="OUTLINER_OB_ARMATURE" if owner and owner.type == "ARMATURE"
                     else "OUTLINER_OB_EMPTY")


class MOCAP_GAPFILL_PT_kb(_Panel, bpy.types.Panel):
    bl_idname = "MOCAP_GAPFILL_PT_kb"
    bl_label = "Knowledge Base"
    bl_parent_id = "MOCAP_GAPFILL_PT_main"

    def draw(self, context):
        layout = self.layout
        settings = context.scene.mocap_gapfill
        row = layout.row(align=True)
        row.prop(settings, "kb_path", text="")
        row.operator("mocap_gapfill.load_kb", text="", icon="FILEBROWSER")
        row = layout.row(align=True)
        row.operator("mocap_gapfill.build_kb", text="Build from Folder",
                     icon="NEWFOLDER").source = "FOLDER"
        row.operator("mocap_gapfill.build_kb", text="From Take", icon="ACTION").source = "TAKE"
        p = prefs.get(context)
        if p and p.recent:
            col = layout.column(align=True)
            for item in list(p.recent)[:4]:
                name = bpy.path.basename(item.path)
                col.operator("mocap_gapfill.use_recent_kb", text=name, icon="FILE").path = item.path


class MOCAP_GAPFILL_PT_gaps(_Panel, bpy.types.Panel):
    bl_idname = "MOCAP_GAPFILL_PT_gaps"
    bl_label = "Gaps"
    bl_parent_id = "MOCAP_GAPFILL_PT_main"

    def draw(self, context):
        layout = self.layout
        owner = bridge.take_owner(context.active_object)
        row = layout.row(align=True)
        row.operator("mocap_gapfill.detect_gaps", icon="VIEWZOOM")
        row.operator("mocap_gapfill.mark_gap", icon="BOOKMARKS")
        if owner is None:
            return
        settings = owner.mocap_gapfill
        row = layout.row()
        row.template_list("MOCAP_GAPFILL_UL_gaps", "", settings, "gaps", settings, "gap_index",
                          rows=6)
        column = row.column(align=True)
        column.operator("mocap_gapfill.remove_gap", text="", icon="X")
        column.operator("mocap_gapfill.revert_gap", text="", icon="LOOP_BACK")
        if any(g.kind in PROBLEMS and not g.repaired for g in settings.gaps):
            row = layout.row(align=True)
            row.operator("mocap_gapfill.repair", text="Repair Selected").scope = "SELECTED"
            row.operator("mocap_gapfill.repair", text="Repair All",
                         icon="TOOL_SETTINGS").scope = "ALL"
        gap = (settings.gaps[settings.gap_index]
               if 0 <= settings.gap_index < len(settings.gaps) else None)
        if gap is not None and (gap.how or gap.kind in PROBLEMS):
            column = layout.box().column(align=True)
            names = f"{gap.point} / {gap.other}" if gap.other else gap.point
            column.label(text=f"{names} {gap.first}-{gap.last}:", icon="INFO")
            for line in gaps.describe(gap, owner.type == "ARMATURE"):
                column.label(text=line)
        layout.prop(context.scene.mocap_gapfill, "detect_suspects")
        if len(settings.points):
            layout.label(text=f"Points with gaps ({settings.frames} frames):")
            layout.template_list("MOCAP_GAPFILL_UL_points", "", settings, "points", settings,
                                 "point_index", rows=3)
        layout.prop(settings, "units")


class MOCAP_GAPFILL_PT_fill(_Panel, bpy.types.Panel):
    bl_idname = "MOCAP_GAPFILL_PT_fill"
    bl_label = "Fill"
    bl_parent_id = "MOCAP_GAPFILL_PT_main"

    def draw(self, context):
        layout = self.layout
        settings = context.scene.mocap_gapfill
        layout.prop(settings, "method")
        row = layout.row(align=True)
        row.prop(settings, "k")
        row.prop(settings, "max_gap")
        job = context.window_manager.mocap_gapfill
        if job.running:
            if hasattr(layout, "progress"):
                layout.progress(factor=job.progress / 100, text=job.message)
            else:
                layout.label(text=f"{job.progress:.0f} % {job.message}")
            layout.label(text="Esc to cancel", icon="CANCEL")
            return
        row = layout.row(align=True)
        row.operator("mocap_gapfill.fill_gaps", text="Fill Selected Gap").scope = "SELECTED"
        row.operator("mocap_gapfill.fill_gaps", text="Fill All Gaps",
                     icon="MOD_SMOOTH").scope = "ALL"
        owner = bridge.take_owner(context.active_object)
        if owner is not None and owner.mocap_gapfill.recovered_action is not None:
            box = layout.box()
            box.label(text="Preview")
            box.row().prop(owner.mocap_gapfill, "showing", expand=True)
            box.operator("mocap_gapfill.ghost", icon="GHOST_ENABLED")


classes = (MOCAP_GAPFILL_UL_gaps, MOCAP_GAPFILL_UL_points, MOCAP_GAPFILL_PT_main,
           MOCAP_GAPFILL_PT_kb, MOCAP_GAPFILL_PT_gaps, MOCAP_GAPFILL_PT_fill)
register, unregister = bpy.utils.register_classes_factory(classes)
