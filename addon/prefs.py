"""Add-on preferences (per user): the default knowledge base and the recently used ones.

Knowledge bases built in Blender are saved in the extension's user folder
(``bpy.utils.extension_path_user``), never inside the add-on folder, which an update replaces.
"""

from pathlib import Path

import bpy
from bpy.props import CollectionProperty, EnumProperty, StringProperty

ADDON = __package__.rpartition(".")[0]  # the extension's module, e.g. bl_ext.user_default.x
MAX_RECENT = 8


class MOCAP_GAPFILL_PG_recent(bpy.types.PropertyGroup):
    """A recently used knowledge base"""

    path: StringProperty(name="Path", subtype="FILE_PATH")


class MOCAP_GAPFILL_AP_preferences(bpy.types.AddonPreferences):
    """Mocap Gap Fill preferences"""

    bl_idname = ADDON

    default_kb: StringProperty(name="Default knowledge base", subtype="FILE_PATH",
                               description="Used when a scene names no knowledge base")
    recent: CollectionProperty(type=MOCAP_GAPFILL_PG_recent)
    device: EnumProperty(name="Compute on", default="auto", items=(
        ("auto", "Automatic", "A CUDA GPU through PyTorch if there is one, else PyTorch on the "
                              "CPU, else NumPy"),
        ("numpy", "NumPy", "NumPy and SciPy only"),
        ("cpu", "PyTorch CPU", "PyTorch on the CPU"),
        ("cuda", "PyTorch CUDA", "PyTorch on a CUDA GPU")))

    def draw(self, context):
        layout = self.layout
        layout.prop(self, "default_kb")
        layout.prop(self, "device")
        layout.label(text=f"Knowledge bases you build are saved in {kb_folder(create=False)}")
        if self.recent:
            col = layout.column(align=True)
            col.label(text="Recent knowledge bases:")
            for item in self.recent:
                col.label(text=item.path, icon="FILE")


def get(context=None):
    """The preferences, or None when the add-on runs without being installed (bpy module)."""
    addon = (context or bpy.context).preferences.addons.get(ADDON)
    return addon.preferences if addon else None


def device(context=None):
    prefs = get(context)
    return prefs.device if prefs else "auto"


def kb_folder(create=True):
    """Where knowledge bases built in Blender go: the extension's user folder (or, when the code
    runs outside an extension, a folder in Blender's user scripts)."""
    try:
        return Path(bpy.utils.extension_path_user(ADDON, path="knowledge_bases", create=create))
    except (ValueError, TypeError):  # not loaded as an extension
        path = Path(bpy.utils.user_resource("SCRIPTS", path="mocap_gapfill_kb"))
        if create:
            path.mkdir(parents=True, exist_ok=True)
        return path


def remember_kb(path, context=None):
    """Put ``path`` first in the recent knowledge bases (at most :data:`MAX_RECENT`)."""
    prefs = get(context)
    if prefs is None:
        return
    path = str(path)
    for i in reversed(range(len(prefs.recent))):
        if prefs.recent[i].path == path:
            prefs.recent.remove(i)
    prefs.recent.add().path = path
    prefs.recent.move(len(prefs.recent) - 1, 0)
    while len(prefs.recent) > MAX_RECENT:
        prefs.recent.remove(len(prefs.recent) - 1)


classes = (MOCAP_GAPFILL_PG_recent, MOCAP_GAPFILL_AP_preferences)
register, unregister = bpy.utils.register_classes_factory(classes)
