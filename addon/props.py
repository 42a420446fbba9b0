"""Properties: one PropertyGroup per owner (Object: its gaps and actions; Scene: fill settings;
WindowManager: the running job), each reached through one ``mocap_gapfill`` PointerProperty."""

import bpy
from bpy.props import (BoolProperty, CollectionProperty, EnumProperty, FloatProperty,
                       IntProperty, PointerProperty, StringProperty)

GAP_KINDS = (
    ("MISSING", "Missing", "No key on these frames", "ERROR", 0),
    ("SUSPECT", "Suspect", "Keyed, but jumps or stretches a limb", "QUESTION", 1),
    ("MARKED", "Marked", "Marked by hand", "BOOKMARKS", 2),
    ("SWAP", "Swap", "Two markers' labels exchanged over these frames (Repair exchanges them "
     "back)", "ARROW_LEFTRIGHT", 3),
    ("SPIKE", "Spike", "Keys that leave the body's rigid structure for a few frames (Repair "
     "cuts them, Fill fills them)", "IPO_ELASTIC", 4),
    ("GHOST", "Ghost", "The label picked up another trajectory (Repair cuts it, Fill fills "
     "it)", "GHOST_ENABLED", 5),
)
#: the kinds that are problems of the labels, not gaps (Repair, not Fill, mends them)
PROBLEMS = ("SWAP", "SPIKE", "GHOST")
UNITS = (
    ("AUTO", "Auto", "Guess from the height of the take (a person is about 1.7 m)"),
    ("M", "Metres", ""), ("CM", "Centimetres", ""), ("MM", "Millimetres", ""),
    ("IN", "Inches", ""), ("CMU", "CMU units", "1/0.45 inch, the CMU ASF unit"),
)
METHOD_ITEMS = (
    ("auto", "Automatic", "Every fill that helps (knowledge base, rigid partners, the rest of "
                          "the body), judged on copies of each gap"),
    ("knn", "Knowledge base", "The knowledge base alone: nearest poses and local PCA (armatures: "
                              "as Automatic)"),
    ("rigid", "Rigid body", "Carried by 3 points that keep their distance to it, as the Vicon "
                            "and QTM rigid-body fill"),
    ("pattern", "Pattern", "Follows the point that moves most like it, as the Vicon pattern "
                           "fill"),
    ("linear", "Linear", "Linear interpolation of joint positions, for comparison"),
    ("spline", "Spline", "Cubic spline interpolation, for comparison"),
    ("local-spline", "Spline in the body's frame", "Cubic spline of each point with the root at "
                                                   "the origin and the hips facing one way"),
    ("intercorrelation", "Marker intercorrelation", "PCA of the take itself (no knowledge base)"),
    ("pca", "Global PCA", "PCA of the knowledge base"),
)


def _select_gap(self, context):
    from . import operators  # selection and frame jump live with the operators

    operators.focus_gap(context, self.id_data, self.gap_index)


def _show(self, context):
    from . import bridge

    bridge.show(self.id_data, self.showing)


class MOCAP_GAPFILL_PG_gap(bpy.types.PropertyGroup):
    """One gap: a point (marker or bone) over an inclusive frame range"""

    point: StringProperty(name="Point")
    other: StringProperty(name="Other point", description="A swap's second marker")
    repaired: BoolProperty(name="Repaired", description="Repair mended this problem")
    first: IntProperty(name="First frame")
    last: IntProperty(name="Last frame")
    kind: EnumProperty(name="Kind", items=GAP_KINDS, default="MISSING")
    filled: BoolProperty(name="Filled", description="Recovered keys were written for this gap")
    how: StringProperty(name="Filled by", description="How the gap was filled, in words: "
                        "what the fill used, and its share")
    estimate: FloatProperty(name="Estimate", min=0.0, description=(
        "An armature gap's expected error as a share of Blender's interpolation's (0: not "
        "judged)"))
    expected_mm: FloatProperty(name="Expected error", min=0.0, description=(
        "A marker gap's expected error in millimetres, from copies of the gap (0: not "
        "judged)"))


class MOCAP_GAPFILL_PG_point(bpy.types.PropertyGroup):
    """Gap totals of one point"""

    gaps: IntProperty(name="Gaps")
    frames: IntProperty(name="Frames missing")
    percent: FloatProperty(name="Missing", subtype="PERCENTAGE")
    longest: IntProperty(name="Longest gap")


class MOCAP_GAPFILL_PG_object(bpy.types.PropertyGroup):
    """Gaps of one take (an armature or a marker set) and its original/recovered actions"""

    gaps: CollectionProperty(type=MOCAP_GAPFILL_PG_gap)
    gap_index: IntProperty(name="Gap", default=-1, update=_select_gap,
                           description="Click a gap to select its point and jump to its frames")
    points: CollectionProperty(type=MOCAP_GAPFILL_PG_point)
    point_index: IntProperty(name="Point", default=-1)
    frames: IntProperty(name="Frames", description="Frames in the take's range")
    original_action: PointerProperty(name="Original", type=bpy.types.Action)
    recovered_action: PointerProperty(name="Recovered", type=bpy.types.Action)
    showing: EnumProperty(name="Show", default="ORIGINAL", update=_show, items=(
        ("ORIGINAL", "Original", "Play the original keys"),
        ("RECOVERED", "Recovered", "Play the keys with the gaps filled")))
    units: EnumProperty(name="Units", items=UNITS, default="AUTO",
                        description="Length unit of this take in the scene")


class MOCAP_GAPFILL_PG_scene(bpy.types.PropertyGroup):
    """Fill settings of this file"""

    kb_path: StringProperty(name="Knowledge base", subtype="FILE_PATH",
                            description="Knowledge-base file (.npz) of clean motion")
    method: EnumProperty(name="Method", items=METHOD_ITEMS, default="auto")
    k: IntProperty(name="K", default=0, min=0, soft_max=16384,
                   description="Neighbours per frame (0: automatic, min(4096, poses))")
    max_gap: IntProperty(name="Max gap", default=0, min=0,
                         description="Leave gaps longer than this many frames unfilled "
                                     "(0: fill all)")
    detect_suspects: BoolProperty(name="Detect suspect data", default=True,
                                  description="Also flag keys that jump or stretch a limb")
    jump_factor: FloatProperty(name="Jump factor", default=8.0, min=2.0,
                               description="Flag a key this many times further than usual "
                               "from its neighbours' midpoint (and over 3 cm)")


class MOCAP_GAPFILL_PG_job(bpy.types.PropertyGroup):
    """The running job (not saved)"""

    running: BoolProperty(name="Running")
    progress: FloatProperty(name="Progress", subtype="PERCENTAGE", min=0, max=100)
    message: StringProperty(name="Status")
    last_info: StringProperty(name="Last inspected file")


classes = (MOCAP_GAPFILL_PG_gap, MOCAP_GAPFILL_PG_point, MOCAP_GAPFILL_PG_object,
           MOCAP_GAPFILL_PG_scene, MOCAP_GAPFILL_PG_job)
_register, _unregister = bpy.utils.register_classes_factory(classes)
_OWNERS = ((bpy.types.Object, MOCAP_GAPFILL_PG_object), (bpy.types.Scene, MOCAP_GAPFILL_PG_scene),
           (bpy.types.WindowManager, MOCAP_GAPFILL_PG_job))


def register():
    _register()
    for owner, group in _OWNERS:
        owner.mocap_gapfill = PointerProperty(type=group)


def unregister():
    for owner, _ in _OWNERS:
        del owner.mocap_gapfill
    _unregister()
