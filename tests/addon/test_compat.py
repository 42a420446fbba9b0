"""The compatibility helper on each Blender line the tests run (4.2 LTS, 5.0, 5.2)."""

import importlib

import numpy as np
import pytest

LOCAL_MODULE = "bl_ext.mocap_gapfill_tests.mocap_gapfill"  # conftest.extension loads it


@pytest.fixture
def compat(scene):
    return importlib.import_module(f"{LOCAL_MODULE}.addon.compat")


def test_actions_slots_and_fcurves(scene, compat):
    import bpy

    assert compat.HAS_SLOTS == (bpy.app.version >= (4, 4, 0))
    obj = bpy.data.objects.new("Probe", None)
    scene.collection.objects.link(obj)
    assert compat.fcurves(obj) is None  # no action yet
    action = bpy.data.actions.new("ProbeAction")
    compat.assign_action(obj, action)
    assert obj.animation_data.action == action
    if compat.HAS_SLOTS:
        assert obj.animation_data.action_slot is not None
    curves = compat.fcurves(obj, create=True)
    curve = compat.new_fcurve(curves, "location", 2, "Probe")
    curve.keyframe_points.add(2)
    curve.keyframe_points.foreach_set("co", np.array([1, 0.0, 11, 1.0], dtype=np.float32))
    curve.keyframe_points.foreach_set("type", np.array([compat.KEY_TYPES["KEYFRAME"],
                                                        compat.KEY_TYPES["GENERATED"]]))
    curve.update()
    assert [k.type for k in curve.keyframe_points] == ["KEYFRAME", "GENERATED"]
    scene.frame_set(6)
    assert obj.location.z == pytest.approx(0.5)
    # a copy of the action plays on the object through the same helpers
    copy = action.copy()
    compat.assign_action(obj, copy)
    assert compat.fcurves(obj).find("location", index=2) is not None


def test_every_key_type_maps_to_its_name(scene, compat):
    import bpy

    obj = bpy.data.objects.new("Keys", None)
    scene.collection.objects.link(obj)
    compat.assign_action(obj, bpy.data.actions.new("Keys"))
    curve = compat.new_fcurve(compat.fcurves(obj, create=True), "location", 0, "Keys")
    names = list(compat.KEY_TYPES)
    curve.keyframe_points.add(len(names))
    co = np.zeros(2 * len(names), dtype=np.float32)
    co[0::2] = np.arange(len(names))
    curve.keyframe_points.foreach_set("co", co)
    curve.keyframe_points.foreach_set("type", np.array([compat.KEY_TYPES[n] for n in names]))
    assert [k.type for k in curve.keyframe_points] == names


def test_selection_of_objects_and_bones(scene, compat):
    import bpy

    arm = bpy.data.objects.new("Rig", bpy.data.armatures.new("Rig"))
    other = bpy.data.objects.new("Other", None)
    for obj in (arm, other):
        scene.collection.objects.link(obj)
    compat.select_objects(bpy.context, [arm], active=arm)
    bpy.ops.object.mode_set(mode="EDIT")
    for name, z in (("a", 0.0), ("b", 1.0)):
        bone = arm.data.edit_bones.new(name)
        bone.head, bone.tail = (0, 0, z), (0, 0, z + 1)
    bpy.ops.object.mode_set(mode="OBJECT")
    compat.select_objects(bpy.context, [other], active=other)
    assert [o.name for o in bpy.context.selected_objects] == ["Other"]
    compat.select_objects(bpy.context, [arm], active=arm)
    compat.select_bones(arm, ["b"])
    selected = [b.name for b in arm.pose.bones
                if (b.select if hasattr(b, "select") else b.bone.select)]
    assert selected == ["b"]
    assert [o.name for o in bpy.context.selected_objects] == ["Rig"]
