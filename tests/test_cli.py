"""The mocap-gapfill command line, run as a user would (python -m mocap_gapfill)."""

import json
import subprocess
import sys

import numpy as np

from mocap_gapfill.core.io import read_motion


def cli(*args):
    return subprocess.run([sys.executable, "-m", "mocap_gapfill", *map(str, args)],
                          capture_output=True, text=True, timeout=120)


def test_info_json_reports_gaps(data_dir):
    r = cli("info", "--json", data_dir / "cmu/c3d/01_01.c3d", data_dir / "cmu/asfamc/09/09_06.amc")
    assert r.returncode == 0, r.stderr
    c3d, amc = json.loads(r.stdout)
    assert c3d["format"] == "c3d" and c3d["frames"] == 2751 and c3d["points"] == 42
    assert abs(c3d["missing_fraction"] - 0.024) < 0.002
    assert c3d["longest_gap_point"] == "RBAC-1" and c3d["longest_gap_frames"] > 2000
    assert amc["kind"] == "skeleton" and amc["missing_fraction"] == 0 and amc["frames"] == 141


def test_info_text_and_errors(data_dir, tmp_path):
    bad = tmp_path / "bad.bvh"
    bad.write_text("HIERARCHY\nROOT Hips\n{\n")
    r = cli("info", data_dir / "cmu/c3d/85_02.c3d", bad)
    assert r.returncode == 1
    assert "frames   810 at 120 fps" in r.stdout
    assert "error:" in r.stderr and "bad.bvh" in r.stderr and "Traceback" not in r.stderr


def test_convert_to_each_format(data_dir, tmp_path):
    src = data_dir / "cmu/asfamc/09/09_06.amc"
    original = read_motion(src)
    for suffix in (".c3d", ".npz", ".csv"):
        out = tmp_path / f"run{suffix}"
        r = cli("convert", src, out)
        assert r.returncode == 0, r.stderr
        back = read_motion(out)
        assert back.n_frames == 141 and back.names == original.names
        np.testing.assert_allclose(back.positions, original.positions, atol=1e-6)


def test_convert_never_overwrites_unless_asked(data_dir, tmp_path):
    out = tmp_path / "out.npz"
    out.write_bytes(b"old")
    r = cli("convert", data_dir / "cmu/c3d/85_02.c3d", out)
    assert r.returncode == 2 and "exists" in r.stderr and out.read_bytes() == b"old"
    r = cli("convert", data_dir / "cmu/c3d/85_02.c3d", out, "--force")
    assert r.returncode == 0 and read_motion(out).n_frames == 810
    r = cli("convert", out, out)
    assert r.returncode == 2 and "input" in r.stderr
    r = cli("convert", data_dir / "cmu/c3d/85_02.c3d", tmp_path / "x.fbx")
    assert r.returncode == 2 and "cannot write .fbx" in r.stderr


def test_console_script_is_installed():
    import shutil
    from pathlib import Path

    exe = shutil.which("mocap-gapfill", path=str(Path(sys.executable).parent))
    assert exe, "pip install -e . provides the mocap-gapfill command"
    r = subprocess.run([exe, "--help"], capture_output=True, text=True)
    assert r.returncode == 0 and "info" in r.stdout and "convert" in r.stdout
