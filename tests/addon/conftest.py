"""Add-on tests run inside the bpy module. Blender writes its user files to a temp dir."""

import os
import shutil
import tempfile
from pathlib import Path

import pytest

_USER = tempfile.mkdtemp(prefix="mocap_gapfill_blender_user_")
os.environ["BLENDER_USER_RESOURCES"] = _USER  # before bpy is imported anywhere

try:
    import bpy  # noqa: F401
except ImportError:
    bpy = None

ROOT = Path(__file__).resolve().parents[2]
LOCAL_MODULE = "bl_ext.mocap_gapfill_tests.mocap_gapfill"


def pytest_unconfigure(config):
    """The user folder goes with the run (before tests/conftest.py's exit, which on bpy 4.2
    skips Python's own clean-up)."""
    shutil.rmtree(_USER, ignore_errors=True)


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


@pytest.fixture(scope="module")
def extension(blender):
    """The working tree loaded as an extension from a local repository (a folder holding a link
    to it), enabled as ``bl_ext.mocap_gapfill_tests.mocap_gapfill``."""
    import addon_utils

    folder = Path(tempfile.mkdtemp(prefix="mocap_gapfill_repo_"))
    (folder / "mocap_gapfill").symlink_to(ROOT, target_is_directory=True)
    repos = blender.context.preferences.extensions.repos
    repo = repos.new(name="mocap_gapfill_tests", module="mocap_gapfill_tests",
                     custom_directory=str(folder), source="USER")
    addon_utils.enable(LOCAL_MODULE, default_set=True)
    assert addon_utils.check(LOCAL_MODULE) == (True, True)
    addon_utils.enable("io_anim_bvh", default_set=True)
    yield blender
    addon_utils.disable(LOCAL_MODULE, default_set=True)
    repos.remove(repo)
    (folder / "mocap_gapfill").unlink()  # the link, never the tree it points to
    folder.rmdir()


@pytest.fixture
def scene(extension):
    """An empty scene for each test."""
    extension.ops.wm.read_homefile(use_empty=True)
    return extension.context.scene
