"""Operators. Each reads like a sentence: Blender data -> core -> Blender data."""

from pathlib import Path

import bpy
from bpy.props import EnumProperty, IntProperty, StringProperty
from bpy_extras.io_utils import ImportHelper

from ..core.errors import GapFillError
from ..core.fill import USES_KB
from . import bridge, compat, gaps, prefs
from .jobs import JobOperator


def _owner_poll(cls, context):
    if bridge.take_owner(context.active_object) is None:
        cls.poll_message_set("Select an armature or a marker set (an imported C3D)")
        return False
    return True


def _idle_poll(cls, context):
    if context.window_manager.mocap_gapfill.running:
        cls.poll_message_set("A gap search or fill is running (Esc cancels it)")
        return False
    return True


def focus_gap(context, owner, index):
    """Select the gap's point (marker empty or bone) and jump to its first frame."""
    settings = owner.mocap_gapfill
    if not 0 <= index < len(settings.gaps):
        return
    gap = settings.gaps[index]
    if bridge.is_marker_set(owner):
        marker = next((c for c in bridge.markers_of(owner) if c.name == gap.point), None)
        if marker is not None:
            compat.select_objects(context, [marker], active=marker)
    elif owner.type == "ARMATURE":
        compat.select_objects(context, [owner], active=owner)
        compat.select_bones(owner, [gap.point])
        bone = owner.data.bones.get(gap.point)
        if bone is not None:
            owner.data.bones.active = bone
    context.scene.frame_current = gap.first


class MOCAP_GAPFILL_OT_file_info(bpy.types.Operator, ImportHelper):
    """Read a motion capture file and report its frames, rate, points and gaps"""

    bl_idname = "mocap_gapfill.file_info"
    bl_label = "Inspect Mocap File"
    bl_options = {"REGISTER"}

    filter_glob: StringProperty(default="*.c3d;*.bvh;*.bvh.gz;*.amc;*.npz;*.csv",
                                options={"HIDDEN"})

    def execute(self, context):
        from ..core.io import read_motion

        try:
            summary = read_motion(self.filepath).summary()
        except GapFillError as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        gap_text = (f"{100 * summary['missing_fraction']:.2f} % missing in {summary['gaps']} gaps, "
                    f"longest {summary['longest_gap_frames']} frames" if summary["gaps"]
                    else "no gaps")
        info = (f"{summary['frames']} frames at {summary['fps']:g} fps, {summary['points']} "
                f"points, {gap_text}")
        context.window_manager.mocap_gapfill.last_info = info
        self.report({"INFO"}, info)
        return {"FINISHED"}


class MOCAP_GAPFILL_OT_import_markers(bpy.types.Operator, ImportHelper):
    """Import a C3D file as marker empties, keyed only where each marker was seen"""

    bl_idname = "mocap_gapfill.import_markers"
    bl_label = "Import C3D Markers"
    bl_options = {"REGISTER", "UNDO"}

    filter_glob: StringProperty(default="*.c3d;*.npz;*.csv", options={"HIDDEN"})
    up: EnumProperty(name="Up", default="DETECT", items=(
        ("DETECT", "Detect", "As the file's header says, unless the take then lies on its side"),
        ("FILE", "File header", "As the file's header (C3D POINT:Y_SCREEN) says"),
        ("y", "Y up", "The data is Y-up, whatever the header says"),
        ("z", "Z up", "The data is Z-up, whatever the header says")))

    def execute(self, context):
        from ..core.io import read_motion
        from ..core.upright import stand_up, upright_warning

        try:
            motion = read_motion(self.filepath, up=self.up if self.up in ("y", "z") else None)
        except GapFillError as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        if motion.parents is not None:
            self.report({"ERROR"}, "this file holds a skeleton: use Import Skeleton")
            return {"CANCELLED"}
        if self.up == "DETECT":
            motion, message = stand_up(motion)
        else:
            message = upright_warning(motion)
        if message:
            self.report({"WARNING"}, message.replace("--up", "Up:"))
        root = bridge.import_markers(context, motion, Path(self.filepath).stem)
        compat.select_objects(context, [root], active=root)
        take = gaps.detect(root, context.scene, suspects=False)
        self.report({"INFO"}, f"{len(take.points)} markers, {take.positions.shape[0]} frames, "
                              f"{len(root.mocap_gapfill.gaps)} gaps")
        return {"FINISHED"}


class MOCAP_GAPFILL_OT_open_sample(bpy.types.Operator):
    """Open a real CMU take with gaps and pick the starter knowledge base without its subject"""

    bl_idname = "mocap_gapfill.open_sample"
    bl_label = "Open Sample Take"
    bl_options = {"REGISTER", "UNDO"}

    kind: EnumProperty(name="Sample", default="MARKERS", items=(
        ("MARKERS", "Markers", "CMU 01_01 (C3D, 41 markers) with the gaps the capture really has"),
        ("ARMATURE", "Armature", "CMU 03_02 through Blender's BVH importer, three bones' keys "
                                 "deleted")))

    def execute(self, context):
        from . import samples

        try:
            owner, _ = samples.load(context, self.kind)
        except GapFillError as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        self.report({"INFO"}, f"{owner.name}: {len(owner.mocap_gapfill.gaps)} gaps; knowledge "
                              f"base {Path(context.scene.mocap_gapfill.kb_path).name}")
        return {"FINISHED"}


class MOCAP_GAPFILL_OT_import_skeleton(bpy.types.Operator, ImportHelper):
    """Import an ASF/AMC or BVH skeleton as an armature"""

    bl_idname = "mocap_gapfill.import_skeleton"
    bl_label = "Import Skeleton (ASF/AMC)"
    bl_options = {"REGISTER", "UNDO"}

    filter_glob: StringProperty(default="*.amc;*.bvh;*.bvh.gz", options={"HIDDEN"})
    asf: StringProperty(name="ASF file", subtype="FILE_PATH",
                        description="Skeleton file of the AMC (found beside it when empty)")

    def execute(self, context):
        from ..core.io import read_motion

        try:
            motion = read_motion(self.filepath, asf=self.asf or None)
            if motion.parents is None:
                raise GapFillError("this file holds markers, not a skeleton: use Import C3D")
            obj = bridge.import_armature(context, motion, Path(self.filepath).name.split(".")[0])
        except (GapFillError, ValueError) as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        compat.select_objects(context, [obj], active=obj)
        gaps.detect(obj, context.scene, suspects=False)
        self.report({"INFO"}, f"{len(obj.pose.bones)} bones, {motion.n_frames} frames")
        return {"FINISHED"}


class MOCAP_GAPFILL_OT_detect_gaps(JobOperator, bpy.types.Operator):
    """Find the frames without keys in the selected takes, and keys that jump or stretch a limb"""

    bl_idname = "mocap_gapfill.detect_gaps"
    bl_label = "Detect Gaps"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        return _idle_poll(cls, context) and _owner_poll(cls, context)

    def prepare(self, context):
        settings = context.scene.mocap_gapfill
        owners = gaps.takes_in(context)
        plans = [(owner.name, *gaps.plan_detect(owner, context.scene, settings.detect_suspects,
                                                settings.jump_factor)) for owner in owners]
        self._takes = [(name, take) for name, take, _ in plans]

        def work(progress, should_cancel):
            found = []
            for i, (name, _, find) in enumerate(plans):
                found.append(find(lambda f, m, i=i: progress((i + f) / len(plans),
                                                             f"{name}: {m}"), should_cancel))
            return found

        return work

    def finish(self, context, results):
        total = problems = 0
        for (name, take), found in zip(self._takes, results):
            owner = bpy.data.objects.get(name)
            if owner is None:  # deleted while the search ran
                continue
            gaps.write_detected(owner, take, found)
            kinds = [g.kind in gaps.REPAIRED for g in owner.mocap_gapfill.gaps]
            total, problems = total + kinds.count(False), problems + sum(kinds)
        self.report({"INFO"}, f"{total} gaps found" + (
            f", and {problems} swaps, spikes or ghosts to repair first" if problems else ""))
        return {"FINISHED"}


class MOCAP_GAPFILL_OT_mark_gap(bpy.types.Operator):
    """Mark the selected bones or markers as a gap over the preview range or the selected keys"""

    bl_idname = "mocap_gapfill.mark_gap"
    bl_label = "Mark Gap"
    bl_options = {"REGISTER", "UNDO"}

    frames: EnumProperty(name="Frames", default="PREVIEW", items=(
        ("PREVIEW", "Preview range", "The scene's preview range (or the scene range)"),
        ("KEYS", "Selected keys", "From the first to the last selected keyframe")))

    poll = classmethod(_owner_poll)

    def execute(self, context):
        owner = bridge.take_owner(context.active_object)
        if owner.type == "ARMATURE":
            points = [b.name for b in owner.pose.bones
                      if (b.select if hasattr(b, "select") else b.bone.select)]
            holders = [owner]
        else:
            holders = [o for o in context.selected_objects if o.parent == owner]
            points = [o.name for o in holders]
        if not points:
            self.report({"ERROR"}, "select the bones or markers to mark")
            return {"CANCELLED"}
        scene = context.scene
        if self.frames == "KEYS":
            span = _selected_key_span(holders)
            if span is None:
                self.report({"ERROR"}, "no selected keyframes on these points")
                return {"CANCELLED"}
        elif scene.use_preview_range:
            span = scene.frame_preview_start, scene.frame_preview_end
        else:
            span = scene.frame_start, scene.frame_end
        gaps.mark(owner, points, *span)
        self.report({"INFO"}, f"marked {len(points)} points over frames {span[0]}-{span[1]}")
        return {"FINISHED"}


def _selected_key_span(objects):
    frames = []
    for obj in objects:
        for curve in compat.fcurves(obj) or ():
            frames += [k.co[0] for k in curve.keyframe_points if k.select_control_point]
    return (int(min(frames)), int(max(frames))) if frames else None


class MOCAP_GAPFILL_OT_remove_gap(bpy.types.Operator):
    """Remove the selected gap from the list (keys are not touched)"""

    bl_idname = "mocap_gapfill.remove_gap"
    bl_label = "Remove Gap"
    bl_options = {"REGISTER", "UNDO"}

    poll = classmethod(_owner_poll)

    def execute(self, context):
        settings = bridge.take_owner(context.active_object).mocap_gapfill
        if not 0 <= settings.gap_index < len(settings.gaps):
            return {"CANCELLED"}
        settings.gaps.remove(settings.gap_index)
        settings.gap_index = min(settings.gap_index, len(settings.gaps) - 1)
        return {"FINISHED"}


class MOCAP_GAPFILL_OT_revert_gap(bpy.types.Operator):
    """Take the selected gap's recovered keys out again"""

    bl_idname = "mocap_gapfill.revert_gap"
    bl_label = "Revert Gap"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        owner = bridge.take_owner(context.active_object)
        settings = owner.mocap_gapfill if owner is not None else None
        if settings is None or not 0 <= settings.gap_index < len(settings.gaps):
            cls.poll_message_set("Select a gap in the list")
            return False
        if not settings.gaps[settings.gap_index].filled:
            cls.poll_message_set("The selected gap was not filled")
            return False
        return True

    def execute(self, context):
        owner = bridge.take_owner(context.active_object)
        settings = owner.mocap_gapfill
        gap = settings.gaps[settings.gap_index]
        removed = bridge.revert_keys(owner, gap.point, gap.first, gap.last)
        gap.filled, gap.how, gap.estimate, gap.expected_mm = False, "", 0.0, 0.0
        settings.showing = "RECOVERED"
        self.report({"INFO"}, f"{gap.point} {gap.first}-{gap.last}: {removed} recovered keys "
                              "taken out; the original keys either side show there")
        return {"FINISHED"}


class MOCAP_GAPFILL_OT_repair(bpy.types.Operator):
    """Repair label problems: exchange swapped markers back, cut spikes and ghosts for Fill"""

    bl_idname = "mocap_gapfill.repair"
    bl_label = "Repair"
    bl_options = {"REGISTER", "UNDO"}

    scope: EnumProperty(name="Scope", default="ALL", items=(
        ("ALL", "All problems", "Every swap, spike and ghost of the active take"),
        ("SELECTED", "Selected problem", "The problem selected in the list")))

    @classmethod
    def poll(cls, context):
        owner = bridge.take_owner(context.active_object)
        if owner is None or not any(g.kind in gaps.REPAIRED and not g.repaired
                                    for g in owner.mocap_gapfill.gaps):
            cls.poll_message_set("Detect Gaps finds no swap, spike or ghost to repair here")
            return False
        return True

    def execute(self, context):
        owner = bridge.take_owner(context.active_object)
        settings = owner.mocap_gapfill
        ids = ([settings.gap_index] if self.scope == "SELECTED" else range(len(settings.gaps)))
        ids = [i for i in ids if 0 <= i < len(settings.gaps)]
        try:
            done = gaps.repair(owner, gaps.read_original(owner, context.scene), ids)
        except (GapFillError, ValueError) as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        if not done:
            self.report({"WARNING"}, "the selected entry is not a problem left to repair")
            return {"CANCELLED"}
        self.report({"INFO"}, f"repaired {done} problem{'s' * (done > 1)}; Fill fills what "
                              "was cut; switch Original/Recovered to compare")
        return {"FINISHED"}


class MOCAP_GAPFILL_OT_fill_gaps(JobOperator, bpy.types.Operator):
    """Fill the gaps into a copy of the action, keeping the original to compare with"""

    bl_idname = "mocap_gapfill.fill_gaps"
    bl_label = "Fill Gaps"
    bl_options = {"REGISTER", "UNDO"}

    scope: EnumProperty(name="Scope", default="ALL", items=(
        ("ALL", "All gaps", "Every gap of the selected takes"),
        ("SELECTED", "Selected gap", "The gap selected in the list")))
    objects: StringProperty(name="Objects", description="Takes to fill, comma-separated "
                            "(default: the selected ones)", options={"SKIP_SAVE"})

    poll = classmethod(_idle_poll)

    def prepare(self, context):
        settings = context.scene.mocap_gapfill
        names = [n.strip() for n in self.objects.split(",") if n.strip()]
        owners = gaps.takes_in(context, names)
        if not owners:
            raise GapFillError("select an armature or a marker set")
        kb = None
        path = gaps.kb_path(context) if settings.method in USES_KB else ""
        if path:  # none chosen: the starter knowledge base that fits each take
            kb = gaps.load_kb_cached(path)
            prefs.remember_kb(path, context)
        self._plans, work = gaps.plan_fill(context, owners, self.scope == "SELECTED",
                                           settings.method, settings.k, settings.max_gap, kb,
                                           prefs.device(context))
        return work

    def finish(self, context, results):
        written = gaps.apply_fill(context, self._plans, results)
        for plan in self._plans:
            for message in plan.messages:
                self.report({"INFO"}, f"{plan.owner}: {message}")
        self.report({"INFO"}, f"filled {written} samples in {len(self._plans)} take(s); "
                              "switch Original/Recovered to compare")
        return {"FINISHED"}


class MOCAP_GAPFILL_OT_ghost(bpy.types.Operator):
    """Show or hide a wireframe copy of the take playing its original keys"""

    bl_idname = "mocap_gapfill.ghost"
    bl_label = "Ghost of Original"
    bl_options = {"REGISTER", "UNDO"}

    poll = classmethod(_owner_poll)

    def execute(self, context):
        owner = bridge.take_owner(context.active_object)
        name = f"{owner.name} (original)"
        ghost = bpy.data.objects.get(name)
        if ghost is not None:
            for child in list(ghost.children):
                bpy.data.objects.remove(child)
            bpy.data.objects.remove(ghost)
            return {"FINISHED"}
        sources = [owner] + (bridge.markers_of(owner) if bridge.is_marker_set(owner) else [])
        copies = {}
        for src in sources:
            action = bridge.original_action(src)
            dup = src.copy()
            dup.name = name if src is owner else f"{src.name} (original)"
            dup.mocap_gapfill.gaps.clear()
            dup.pop(bridge.MARKER_SET, None)  # the ghost is no take of its own
            context.scene.collection.objects.link(dup)
            dup.display_type = "WIRE"
            dup.show_in_front = True
            dup.hide_select = True
            if action is not None:
                compat.assign_action(dup, action)
            copies[src] = dup
        for src, dup in copies.items():
            if src is not owner:
                dup.parent = copies[owner]
        return {"FINISHED"}


class MOCAP_GAPFILL_OT_load_kb(bpy.types.Operator, ImportHelper):
    """Choose a knowledge-base file (.npz) for this scene; it is checked before use"""

    bl_idname = "mocap_gapfill.load_kb"
    bl_label = "Load Knowledge Base"
    bl_options = {"REGISTER", "UNDO"}

    filter_glob: StringProperty(default="*.npz", options={"HIDDEN"})

    def execute(self, context):
        try:
            kb = gaps.load_kb_cached(self.filepath)
        except (GapFillError, OSError) as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        context.scene.mocap_gapfill.kb_path = self.filepath
        prefs.remember_kb(self.filepath, context)
        self.report({"INFO"}, f"{kb.size} poses of {len(kb.names)} points at {kb.fps:g} fps")
        return {"FINISHED"}


class MOCAP_GAPFILL_OT_build_kb(JobOperator, bpy.types.Operator):
    """Build a knowledge base from a folder of motion files or the selected takes, and use it"""

    bl_idname = "mocap_gapfill.build_kb"
    bl_label = "Build Knowledge Base"
    bl_options = {"REGISTER", "UNDO"}

    source: EnumProperty(name="From", default="FOLDER", items=(
        ("FOLDER", "Folder", "Motion files in a folder (searched recursively)"),
        ("TAKE", "Selected take", "The selected takes' original keys, frames with gaps left out")))
    directory: StringProperty(name="Folder", subtype="DIR_PATH")
    name: StringProperty(name="Name", default="knowledge_base")
    fps: IntProperty(name="Frame rate", default=0, min=0,
                     description="Resample to this rate (0: the scene's)")

    def invoke(self, context, event):
        if self.source == "FOLDER" and not self.directory and not bpy.app.background:
            self._modal_after_browser = True  # the build runs modal once a folder is chosen
            context.window_manager.fileselect_add(self)
            return {"RUNNING_MODAL"}
        return JobOperator.invoke(self, context, event)

    def prepare(self, context):
        from ..core.kb import build_kb, kb_from_motions, rig_turns

        fps = self.fps or bridge.scene_fps(context.scene)
        safe = "".join(c if c.isalnum() or c in "-_." else "_" for c in self.name) or "kb"
        self._path = prefs.kb_folder() / f"{safe}.npz"
        if self.source == "FOLDER":
            folder = bpy.path.abspath(self.directory)
            if not folder or not Path(folder).is_dir():
                raise GapFillError(f"not a folder: {folder!r}")

            def work(progress, should_cancel):
                return build_kb([folder], fps=fps, progress=progress, should_cancel=should_cancel)
            return work
        motions, turns = [], []
        for owner in gaps.takes_in(context):
            take = gaps.read_original(owner, context.scene)
            motions.append(take.motion(gaps.take_missing(owner, take)))
            if take.kind == "armature":  # armatures also give their bones' rotations
                turns.append(rig_turns(take.extra["rig"], take.extra["basis"]))
        if not motions:
            raise GapFillError("select the takes to learn from")
        turns = turns if len(turns) == len(motions) else None

        def work(progress, should_cancel):
            return kb_from_motions(motions, fps=fps, turns=turns)
        return work

    def finish(self, context, kb):
        kb.save(self._path, overwrite=True)
        context.scene.mocap_gapfill.kb_path = str(self._path)
        prefs.remember_kb(self._path, context)
        self.report({"INFO"}, f"knowledge base of {kb.size} poses saved to {self._path}")
        return {"FINISHED"}


class MOCAP_GAPFILL_OT_use_recent_kb(bpy.types.Operator):
    """Use a recently used knowledge base"""

    bl_idname = "mocap_gapfill.use_recent_kb"
    bl_label = "Use Recent Knowledge Base"
    bl_options = {"REGISTER", "UNDO"}

    path: StringProperty(name="Path", subtype="FILE_PATH")

    def execute(self, context):
        context.scene.mocap_gapfill.kb_path = self.path
        prefs.remember_kb(self.path, context)
        return {"FINISHED"}


classes = (MOCAP_GAPFILL_OT_file_info, MOCAP_GAPFILL_OT_import_markers,
           MOCAP_GAPFILL_OT_open_sample, MOCAP_GAPFILL_OT_import_skeleton, MOCAP_GAPFILL_OT_detect_gaps,
           MOCAP_GAPFILL_OT_mark_gap, MOCAP_GAPFILL_OT_remove_gap, MOCAP_GAPFILL_OT_revert_gap,
           MOCAP_GAPFILL_OT_repair, MOCAP_GAPFILL_OT_fill_gaps,
           MOCAP_GAPFILL_OT_ghost, MOCAP_GAPFILL_OT_load_kb, MOCAP_GAPFILL_OT_build_kb,
           MOCAP_GAPFILL_OT_use_recent_kb)
register, unregister = bpy.utils.register_classes_factory(classes)
