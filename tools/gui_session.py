"""Runs inside a real Blender (tools/gui_check.sh), with the add-on loaded from a local extension
repository. In background mode (``-b -- build``) it builds the demo scene with the add-on's own
code and saves it; in the GUI it opens that scene, fills it with the UI operator (invoked: modal,
progress, Esc to cancel), shows the recovered motion and a ghost of the original, builds a
knowledge base from a folder, then imports the real CMU marker take 01_01 and fills its real gaps
with the starter knowledge base, and opens the panel's armature sample (CMU 03_02, three bones'
keys deleted) and fills it, taking screenshots. Prints 'mocap_gapfill: ...' lines."""

import subprocess
import sys

import addon_utils
import bpy

REPO = "/work/repo"
OUT = "/work/out"
MODULE = "bl_ext.gui_check.mocap_gapfill"


def say(*args):
    print("mocap_gapfill:", *args, flush=True)


def shot(name):
    subprocess.run(f"xwd -root -display :99 | xwdtopnm 2>/dev/null | pnmtopng > {OUT}/{name}.png",
                   shell=True, check=True)
    say("screenshot", name)


def view3d():
    for window in bpy.context.window_manager.windows:
        for area in window.screen.areas:
            if area.type == "VIEW_3D":
                return window, area
    raise RuntimeError("no 3D view")


def enable():
    say("Blender", bpy.app.version_string, "Python", sys.version.split()[0])
    bpy.context.preferences.extensions.repos.new(name="gui_check", module="gui_check",
                                                 custom_directory=REPO, source="USER")
    addon_utils.enable(MODULE, default_set=True)
    say("enabled", addon_utils.check(MODULE))


def build():
    import importlib

    commands = importlib.import_module(MODULE + ".addon.commands")
    demo_mod = importlib.import_module(MODULE + ".core.demo")
    bpy.ops.wm.read_homefile(use_empty=True)
    demo = demo_mod.run_demo(OUT, report=lambda m: say(m))
    commands.build_demo_scene(bpy.context, demo)
    bpy.ops.wm.save_as_mainfile(filepath=f"{OUT}/mocap_demo.blend")
    say("scene saved", f"{OUT}/mocap_demo.blend")
    bpy.context.preferences.view.show_splash = False  # saved prefs: no first-run splash either
    bpy.ops.wm.save_userpref()


def frame_view(frame):
    """Frame the walker at ``frame`` in the 3D view, with the sidebar open on the Mocap tab."""
    arm = bpy.data.objects["Walker"]
    context_select(arm)
    bpy.context.scene.frame_set(frame)
    window, area = view3d()
    space = area.spaces.active
    space.show_region_ui = True
    space.overlay.show_relationship_lines = False
    region = [r for r in area.regions if r.type == "WINDOW"][0]
    with bpy.context.temp_override(window=window, area=area, region=region):
        bpy.ops.view3d.view_selected()


def show_mocap_tab():
    """The sidebar on the Mocap tab (once the sidebar has drawn: its tabs exist only then)."""
    window, area = view3d()
    ui = [r for r in area.regions if r.type == "UI"][0]
    try:
        ui.active_panel_category = "Mocap"
        ui.tag_redraw()
        say("sidebar tab:", ui.active_panel_category)
    except (AttributeError, TypeError):  # read-only before 4.4: click the tab, the last one
        # (Item, Tool, View, Mocap) in the column of tabs at the sidebar's right edge: its
        # middle is 168 px below the sidebar's top at Blender 4.3's default scale
        x = ui.x + ui.width - 10
        y = window.height - (ui.y + ui.height) + 168
        subprocess.run(f"xdotool mousemove {x} {y} click 1", shell=True,
                       env={"DISPLAY": ":99"})
        say("sidebar tab: clicked at", x, y)


def context_select(obj):
    for o in bpy.context.view_layer.objects:
        o.select_set(o == obj)
    bpy.context.view_layer.objects.active = obj


STATE = {"step": 0}


def still_running(wm):
    """Whether a job runs; if so, its progress said as the panel shows it."""
    if wm.mocap_gapfill.running:
        say(f"progress {wm.mocap_gapfill.progress:.0f} % {wm.mocap_gapfill.message}")
    return wm.mocap_gapfill.running


def step():
    state = STATE
    window, area = view3d()
    arm = bpy.data.objects["Walker"]
    wm = bpy.context.window_manager
    if state["step"] == 0:
        arm.mocap_gapfill.gap_index = 0
        frame_view(100)
        state["step"] = 0.25
        return 1.0
    if state["step"] == 0.25:
        show_mocap_tab()
        state["step"] = 0.5
        return 1.0
    if state["step"] == 0.5:
        shot("1_gaps_detected")
        with bpy.context.temp_override(window=window, area=area):
            result = bpy.ops.mocap_gapfill.fill_gaps("INVOKE_DEFAULT", scope="ALL")
        say("fill invoked:", result)
        state["step"] = 1
        return 0.05
    if state["step"] == 1:
        if still_running(wm):
            return 0.05
        say("filled; showing", arm.mocap_gapfill.showing, "gaps filled:",
            sum(g.filled for g in arm.mocap_gapfill.gaps), "of", len(arm.mocap_gapfill.gaps))
        with bpy.context.temp_override(window=window, area=area):
            bpy.ops.ed.undo()
        arm = bpy.data.objects["Walker"]
        say("after one Ctrl-Z: showing", arm.mocap_gapfill.showing, "recovered action:",
            arm.mocap_gapfill.recovered_action, "action:", arm.animation_data.action.name)
        with bpy.context.temp_override(window=window, area=area):
            bpy.ops.ed.redo()
        arm = bpy.data.objects["Walker"]
        say("after redo: showing", arm.mocap_gapfill.showing, "action:",
            arm.animation_data.action.name)
        frame_view(130)
        state["step"] = 2
        return 1.0
    if state["step"] == 2:
        shot("2_filled")
        with bpy.context.temp_override(window=window, area=area):
            bpy.ops.mocap_gapfill.ghost()
        say("ghost of original:", bpy.data.objects.get("Walker (original)") is not None)
        state["step"] = 3
        return 1.0
    if state["step"] == 3:
        shot("3_ghost")
        # a knowledge base built modally from a folder of motion files (here the demo's output)
        import glob
        import os
        import shutil

        os.makedirs(f"{OUT}/takes", exist_ok=True)
        for path in glob.glob(f"{OUT}/demo_markers_filled.*"):
            shutil.copy(path, f"{OUT}/takes/")
        with bpy.context.temp_override(window=window, area=area):
            result = bpy.ops.mocap_gapfill.build_kb("INVOKE_DEFAULT", source="FOLDER",
                                                    directory=f"{OUT}/takes", name="gui_check")
        say("build_kb invoked:", result)
        state["step"] = 4
        return 0.1
    if state["step"] == 4:
        if wm.mocap_gapfill.running:
            return 0.1
        say("knowledge base now:", bpy.context.scene.mocap_gapfill.kb_path)
        # the real CMU take 01_01 with the gaps it really has (converted to .npz by
        # gui_check.sh: Debian's Blender has no ezc3d), filled with the starter knowledge base
        with bpy.context.temp_override(window=window, area=area):
            bpy.ops.mocap_gapfill.import_markers(filepath=f"{OUT}/01_01.npz")
        root = bpy.data.objects["01_01"]
        say("imported 01_01:", len(root.mocap_gapfill.gaps), "gaps:",
            [(g.point, g.first, g.last) for g in root.mocap_gapfill.gaps])
        bpy.context.scene.mocap_gapfill.kb_path = ""  # none chosen: the starter one
        with bpy.context.temp_override(window=window, area=area):
            result = bpy.ops.mocap_gapfill.fill_gaps("INVOKE_DEFAULT", scope="ALL",
                                                     objects="01_01")
        say("fill of 01_01 invoked:", result)
        state["step"] = 5
        return 0.1
    if state["step"] >= 10:
        return problems_step()
    if state["step"] >= 7:
        return sample_step(state, window, area, wm)
    if wm.mocap_gapfill.running:
        return 0.1
    root = bpy.data.objects["01_01"]
    say("01_01 filled:", sum(g.filled for g in root.mocap_gapfill.gaps), "of",
        len(root.mocap_gapfill.gaps), "gaps; showing", root.mocap_gapfill.showing)
    say("01_01 how filled:", [(g.point, g.first, g.how, round(g.expected_mm, 1))
                              for g in root.mocap_gapfill.gaps][:8])
    if state["step"] == 5:
        gap = next(g for g in root.mocap_gapfill.gaps if g.point.split(".")[0] == "RBAC")
        root.mocap_gapfill.gap_index = list(root.mocap_gapfill.gaps).index(gap)
        frame_markers(root, window, area, (gap.first + gap.last) // 2)
        state["step"] = 6
        return 1.0
    shot("4_real_markers_filled")
    # the panel's "Sample: Armature": CMU 03_02 through Blender's BVH importer, three bones'
    # keys deleted, the starter knowledge base without subject 03
    with bpy.context.temp_override(window=window, area=area):
        result = bpy.ops.mocap_gapfill.open_sample("EXEC_DEFAULT", kind="ARMATURE")
    arm = bpy.context.view_layer.objects.active
    state["sample"] = arm.name
    say("quick start 2, Sample: Armature:", result, arm.name, len(arm.mocap_gapfill.gaps), "gaps:",
        [(g.point, g.first, g.last) for g in arm.mocap_gapfill.gaps], "knowledge base:",
        bpy.context.scene.mocap_gapfill.kb_path)
    frame_object(arm, area, 170)
    state["step"] = 7
    return 1.0


def gaps_module():
    import importlib

    return importlib.import_module(MODULE + ".addon.gaps")


def frame_object(obj, area, frame):
    """Select ``obj`` alone, go to ``frame`` and frame it in the 3D View."""
    for o in bpy.context.view_layer.objects:
        o.select_set(o == obj)
    bpy.context.view_layer.objects.active = obj
    bpy.context.scene.frame_set(frame)
    region = [r for r in area.regions if r.type == "WINDOW"][0]
    with bpy.context.temp_override(window=bpy.context.window_manager.windows[0], area=area,
                                   region=region):
        bpy.ops.view3d.view_selected()


def frame_markers(root, window, area, frame):
    """Select a marker set's markers, go to ``frame`` and frame them (the root is at 0)."""
    for o in bpy.context.view_layer.objects:
        o.select_set(o.parent == root)
    bpy.context.view_layer.objects.active = root
    bpy.context.scene.frame_set(frame)
    region = [r for r in area.regions if r.type == "WINDOW"][0]
    with bpy.context.temp_override(window=window, area=area, region=region):
        bpy.ops.view3d.view_selected()


def sample_step(state, window, area, wm):
    arm = bpy.data.objects[state["sample"]]
    if state["step"] == 7:
        shot("5_sample_armature_gaps")
        with bpy.context.temp_override(window=window, area=area):
            result = bpy.ops.mocap_gapfill.fill_gaps("INVOKE_DEFAULT", scope="ALL",
                                                     objects=arm.name)
        say("quick start 3, Fill All Gaps:", result)
        state["step"] = 8
        return 0.1
    if state["step"] == 8:
        if wm.mocap_gapfill.running:
            return 0.1
        say("sample armature filled:", sum(g.filled for g in arm.mocap_gapfill.gaps), "of",
            len(arm.mocap_gapfill.gaps), "gaps; showing", arm.mocap_gapfill.showing,
            "action:", arm.animation_data.action.name)
        say("how each gap was filled:", [(g.point, g.how, round(g.estimate, 2))
                                          for g in arm.mocap_gapfill.gaps])
        # the panel says in words how the selected gap was filled (one that went on to the
        # long-gap consensus where there is one)
        listed = list(arm.mocap_gapfill.gaps)
        arm.mocap_gapfill.gap_index = next(
            (i for i, g in enumerate(listed) if ", blended with " in g.how),
            next((i for i, g in enumerate(listed) if g.how not in ("", "kept Blender's curve")),
                 0))
        frame_object(arm, area, 170)
        state["step"] = 9
        return 1.0
    shot("6_sample_armature_filled")
    gap = arm.mocap_gapfill.gaps[arm.mocap_gapfill.gap_index]
    say("quick start 4, the selected gap says:", gap.point,
        gaps_module().describe(gap, True))
    # quick start 5: Original / Recovered switches the action, then Revert Gap
    arm.mocap_gapfill.showing = "ORIGINAL"
    say("quick start 5, Original:", arm.animation_data.action.name)
    arm.mocap_gapfill.showing = "RECOVERED"
    say("quick start 5, Recovered:", arm.animation_data.action.name)
    with bpy.context.temp_override(window=window, area=area):
        result = bpy.ops.mocap_gapfill.revert_gap()
    gap = arm.mocap_gapfill.gaps[arm.mocap_gapfill.gap_index]
    say("revert gap:", result, gap.point, "filled:", gap.filled, "still filled:",
        sum(g.filled for g in arm.mocap_gapfill.gaps))
    state["step"] = 10
    return 1.0


def problems_step():
    """A take with a label swap and a spike (CMU 06_01 made faulty by gui_check.sh): Detect Gaps
    lists them with their own icons, Repair All mends them, one Ctrl-Z undoes the repair."""
    state = STATE
    window, area = view3d()
    wm = bpy.context.window_manager
    if state["step"] == 10:
        with bpy.context.temp_override(window=window, area=area):
            bpy.ops.mocap_gapfill.import_markers(filepath=f"{OUT}/06_01_faulty.npz")
            # the undo steps a user's clicks leave (a script's operator calls leave none)
            bpy.ops.ed.undo_push(message="Import C3D")
            # as the button does: the search runs as a job, its progress in the panel
            result = bpy.ops.mocap_gapfill.detect_gaps("INVOKE_DEFAULT")
        say("detect invoked:", result)
        state["step"] = 10.5
        return 0.05
    if state["step"] == 10.5:
        if still_running(wm):
            return 0.05
        with bpy.context.temp_override(window=window, area=area):
            bpy.ops.ed.undo_push(message="Detect Gaps")
        root = bpy.data.objects["06_01_faulty"]
        listed = list(root.mocap_gapfill.gaps)
        say("problems listed:", [(g.kind, g.point, g.other, g.first, g.last)
                                 for g in listed if g.kind in ("SWAP", "SPIKE", "GHOST")])
        root.mocap_gapfill.gap_index = next(i for i, g in enumerate(listed) if g.kind == "SWAP")
        frame_markers(root, window, area, 230)
        state["step"] = 11
        return 1.0
    root = bpy.data.objects["06_01_faulty"]
    if state["step"] == 11:
        shot("7_problems_listed")
        with bpy.context.temp_override(window=window, area=area):
            result = bpy.ops.mocap_gapfill.repair(scope="ALL")
        bpy.ops.ed.undo_push(message="Repair")  # what a click on the button (UNDO flag) leaves
        say("repair all:", result, [(g.kind, g.repaired, g.how) for g in root.mocap_gapfill.gaps
                                    if g.kind in ("SWAP", "SPIKE", "GHOST")])
        state["step"] = 12
        return 1.0
    if state["step"] == 12:
        shot("8_problems_repaired")
        with bpy.context.temp_override(window=window, area=area):
            bpy.ops.ed.undo()
        root = bpy.data.objects["06_01_faulty"]  # Detect Gaps' list is back, unrepaired
        say("after one Ctrl-Z:", [(g.kind, g.repaired) for g in root.mocap_gapfill.gaps
                                  if g.kind in ("SWAP", "SPIKE", "GHOST")],
            "showing", root.mocap_gapfill.showing)
        bpy.ops.wm.quit_blender()
    return None


enable()
if "build" in sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []:
    build()
else:
    bpy.app.timers.register(step, first_interval=2.0)
