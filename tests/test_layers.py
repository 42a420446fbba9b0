"""The core never imports Blender: every core module imports with bpy made unimportable."""

import pkgutil
import subprocess
import sys

import mocap_gapfill.core as core


def test_core_imports_without_bpy():
    names = [m.name for m in pkgutil.walk_packages(core.__path__, "mocap_gapfill.core.")]
    assert "mocap_gapfill.core.formats.c3d" in names
    code = (
        "import sys, importlib\n"
        "for blocked in ('bpy', 'mathutils', 'bpy_extras', 'mocap_gapfill.addon'):\n"
        "    sys.modules[blocked] = None\n"
        f"for name in {names!r}:\n"
        "    importlib.import_module(name)\n"
        "import mocap_gapfill\n"  # the root package must not import the add-on either
        "print('ok', len(sys.modules))\n"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    assert result.stdout.startswith("ok")
