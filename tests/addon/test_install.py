"""The extension validates, builds per platform, installs from its zip into Blender and works.

Uses the blender_ext.py that ships inside the bpy wheel, as Blender's own command line does.
"""

import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
MODULE = "bl_ext.user_default.mocap_gapfill"
PLATFORMS = ("linux_x64", "macos_arm64", "windows_x64")


def run_blender_ext(bpy, *args):
    script = Path(bpy.utils.system_resource("SCRIPTS")) / "addons_core/bl_pkg/cli/blender_ext.py"
    assert script.is_file(), script
    return subprocess.run([sys.executable, str(script), *map(str, args)], capture_output=True,
                          text=True, timeout=600)


@pytest.fixture(scope="module")
def built(blender, tmp_path_factory):
    assert list((ROOT / "wheels").glob("*.whl")), "no wheels: run python tools/fetch_wheels.py"
    out = tmp_path_factory.mktemp("dist")
    r = run_blender_ext(blender, "validate", ROOT)
    assert r.returncode == 0, r.stdout + r.stderr
    r = run_blender_ext(blender, "build", "--split-platforms", "--source-dir", ROOT,
                        "--output-dir", out)
    assert r.returncode == 0, r.stdout + r.stderr
    return out


@pytest.fixture(scope="module")
def installed(blender, built):
    import addon_utils

    blender.ops.wm.read_homefile(use_empty=True)
    result = blender.ops.extensions.package_install_files(
        filepath=str(built / "mocap_gapfill-0.1.0-linux_x64.zip"), repo="user_default",
        enable_on_install=True)
    assert result == {"FINISHED"}
    yield blender
    addon_utils.disable(MODULE)


def test_split_platform_zips(built):
    assert sorted(p.name for p in built.glob("*.zip")) == [
        f"mocap_gapfill-0.1.0-{p}.zip" for p in PLATFORMS]
    names = zipfile.ZipFile(built / "mocap_gapfill-0.1.0-linux_x64.zip").namelist()
    assert "blender_manifest.toml" in names and "core/motion.py" in names
    assert "addon/operators.py" in names and "__init__.py" in names
    assert not [n for n in names if n.startswith(("tests/", ".ci/", ".venv", "tools/", "docs/"))]
    wheels = [n for n in names if n.endswith(".whl")]
    # scipy + ezc3d for Python 3.11 (Blender 4.2-5.0) and 3.13 (5.1+), linux only; threadpoolctl
    # (pure Python) for every platform
    assert all("linux" in w or w.endswith("-none-any.whl") for w in wheels)
    assert sorted(w.split("-")[2] for w in wheels) == ["cp311", "cp311", "cp313", "cp313", "py3"]
    assert not any("numpy" in n for n in names)  # numpy comes with Blender


def test_installs_enables_and_runs(installed, user_dir, data_dir):
    import addon_utils

    bpy = installed
    assert addon_utils.check(MODULE) == (True, True)
    # Blender installed the bundled wheels into the extensions' own site-packages
    site = Path(user_dir) / "extensions" / ".local" / "lib"
    installed_pkgs = {p.name for p in site.glob("python3.*/site-packages/*")}
    assert {"scipy", "ezc3d", "threadpoolctl.py"} <= installed_pkgs, installed_pkgs
    result = bpy.ops.mocap_gapfill.file_info(filepath=str(data_dir / "cmu/c3d/01_01.c3d"))
    assert result == {"FINISHED"}
    info = bpy.context.window_manager.mocap_gapfill.last_info
    assert info.startswith("2751 frames at 120 fps, 42 points, 2.40 % missing")


def test_bad_file_is_reported_not_raised(installed, tmp_path):
    bad = tmp_path / "bad.c3d"
    bad.write_bytes(b"\x02\x50" + b"\x00" * 100)
    before = installed.context.window_manager.mocap_gapfill.last_info
    # an operator that reports an ERROR raises RuntimeError with the report text in bpy
    with pytest.raises(RuntimeError, match="too short for a C3D file"):
        installed.ops.mocap_gapfill.file_info(filepath=str(bad))
    assert installed.context.window_manager.mocap_gapfill.last_info == before  # kept as it was
