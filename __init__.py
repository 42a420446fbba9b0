"""Mocap Gap Fill: a Blender extension (this folder) and the numeric core behind it.

Importing the package never imports ``bpy``: Blender calls :func:`register`, which loads the
add-on layer. The command line and the tests use :mod:`.core` alone.
"""


def register():
    from . import addon

    addon.register()


def unregister():
    from . import addon

    addon.unregister()
