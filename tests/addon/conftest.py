"""Add-on tests run inside the bpy module. Blender writes its user files to a temp dir."""

import os
import tempfile

import pytest

_USER = tempfile.mkdtemp(prefix="mocap_gapfill_blender_user_")
os.environ["BLENDER_USER_RESOURCES"] = _USER  # before bpy is imported anywhere

try:
    import bpy  # noqa: F401
except ImportError:
    bpy = None


@pytest.fixture(scope="session")
def blender():
    if bpy is None:
        if os.environ.get("MOCAP_GAPFILL_REQUIRE_BPY") == "1":
            pytest.fail("the bpy module is not installed")
        pytest.skip("the bpy module is not installed")
    return bpy


@pytest.fixture(scope="session")
def user_dir():
    return _USER
