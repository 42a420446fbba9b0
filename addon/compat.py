"""Differences between the Blender versions we support (4.2 LTS to 5.0), in one place.

- 4.4 added action slots and layers: an object plays ``animation_data.action`` through
  ``animation_data.action_slot``, and F-curves live in the slot's channelbag.
- 5.0 removed ``Action.fcurves`` (the 4.4-4.5 legacy view of the first channelbag).
"""

import bpy

HAS_SLOTS = "slots" in bpy.types.Action.bl_rna.properties

#: ``Keyframe.type`` as the integers ``foreach_set`` takes (DNA ``eBezTriple_KeyframeType``)
KEY_TYPES = {"KEYFRAME": 0, "EXTREME": 1, "BREAKDOWN": 2, "JITTER": 3, "MOVING_HOLD": 4,
             "GENERATED": 5}


def assign_action(obj, action):
    """Make ``obj`` play ``action`` (on 4.4+ through a slot for this object, made if needed)."""
    anim = obj.animation_data or obj.animation_data_create()
    anim.action = action
    if HAS_SLOTS and action is not None and anim.action_slot is None:
        slot = next((s for s in action.slots if s.target_id_type in {"OBJECT", "UNSPECIFIED"}),
                    None) or action.slots.new("OBJECT", obj.name)
        anim.action_slot = slot


def fcurves(obj, create=False):
    """The F-curve collection that animates ``obj`` in its current action (None if there is none;
    with ``create``, a channelbag is made for the object's slot when missing)."""
    anim = obj.animation_data
    if anim is None or anim.action is None:
        return None
    if not HAS_SLOTS:
        return anim.action.fcurves
    from bpy_extras import anim_utils

    if anim.action_slot is None:
        if not create:
            return None
        assign_action(obj, anim.action)
    if create:
        return anim_utils.action_ensure_channelbag_for_slot(anim.action, anim.action_slot).fcurves
    bag = anim_utils.action_get_channelbag_for_slot(anim.action, anim.action_slot)
    return None if bag is None else bag.fcurves


def new_fcurve(curves, data_path, index, group):
    """A new F-curve in ``curves`` (group name given the same way on every version)."""
    try:
        return curves.new(data_path, index=index, action_group=group)
    except TypeError:  # 4.4+ channelbag F-curves take ``group_name``
        return curves.new(data_path, index=index, group_name=group)


def select_objects(context, objects, active=None):
    """Select exactly ``objects`` in the view layer and make ``active`` the active one."""
    for obj in context.view_layer.objects:
        obj.select_set(obj in objects)
    if active is not None:
        context.view_layer.objects.active = active


def select_bones(obj, names):
    """Select exactly the named bones of an armature (selection moved to PoseBone in 5.0)."""
    names = set(names)
    for pbone in obj.pose.bones:
        target = pbone if hasattr(pbone, "select") else pbone.bone
        target.select = pbone.name in names
