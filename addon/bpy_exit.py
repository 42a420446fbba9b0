"""Leaving a process that imported the bpy 4.2 module.

The bpy *module* of Blender 4.2 (not Blender itself) segfaults during Python's finalisation once
a property with an ``update`` callback has been registered, even after unregistering it (seen
with bpy 4.2.23; 4.5 and 5.0 are fine). Processes that load the add-on into the bpy module (the
``blend`` and ``demo`` commands, the test run) end through :func:`leave_if_bpy_would_crash`,
which flushes and exits without that finalisation, removing first what that finalisation
would have: Blender's temporary folder of the session (``bpy.app.tempdir``).
"""

import os
import shutil
import sys


def leave_if_bpy_would_crash(code):
    bpy = sys.modules.get("bpy")
    if bpy is not None and getattr(bpy, "app", None) and bpy.app.version < (4, 3, 0):
        sys.stdout.flush()
        sys.stderr.flush()
        if bpy.app.tempdir:
            shutil.rmtree(bpy.app.tempdir, ignore_errors=True)
        os._exit(int(code or 0))
