"""``python -m mocap_gapfill`` and the ``mocap-gapfill`` command: the core's command line plus
the Blender commands of the add-on (which import bpy only when run)."""

import sys


def main(argv=None):
    from .addon.commands import add_commands
    from .addon.bpy_exit import leave_if_bpy_would_crash
    from .core.cli import main as core_main

    code = core_main(argv, extra=add_commands)
    leave_if_bpy_would_crash(code)
    return code


if __name__ == "__main__":
    sys.exit(main())
