"""Takes whose header lies about the up axis: found from the data, named, and read standing."""

import subprocess
import sys

import numpy as np
import pytest

from mocap_gapfill.core.evaluate import punch_gaps, rmse_mm, with_gaps
from mocap_gapfill.core.fill import fill
from mocap_gapfill.core.io import read_motion, write_motion
from mocap_gapfill.core.kb import build_kb
from mocap_gapfill.core.motion import z_up_to_y_up
from mocap_gapfill.core.upright import stand_up, upright_warning


@pytest.fixture(scope="module")
def lying(data_dir, tmp_path_factory):
    """CMU 85_02 written with Y-up data and no word of it in the header (Y_SCREEN +Z)."""
    take = read_motion(data_dir / "cmu/c3d/85_02.c3d")
    path = tmp_path_factory.mktemp("upright") / "85_02_yup.c3d"
    write_motion(take.replace(positions=z_up_to_y_up(take.positions)), path)
    return take, path


def test_the_files_we_have_stand(data_dir):
    for name in ("cmu/c3d/01_01.c3d", "cmu/c3d/06_01.c3d", "hdm05/c3d/HDM_dg_06-03_03_120.c3d",
                 "cmu/bvh/daz_friendly/07/07_05.bvh.gz", "cmu/asfamc/01/01_01.amc"):
        assert upright_warning(read_motion(data_dir / name)) is None, name


def test_a_take_lying_on_its_side_is_named_and_fills_as_well_once_turned(data_dir, lying):
    take, path = lying
    read = read_motion(path)
    assert read.up_axis == "z"  # what the header says
    warning = upright_warning(read)
    assert warning and "+Y" in warning and "--up y" in warning
    turned = read_motion(path, up="y")
    assert upright_warning(turned) is None
    np.testing.assert_allclose(turned.positions, take.positions, atol=1e-6)
    stood, message = stand_up(read)
    assert "turned to Y-up" in message
    np.testing.assert_allclose(stood.positions, take.positions, atol=1e-6)
    # the same gaps, the same KB: lying, the knowledge base's fill is far worse (232 vs 144 mm)
    c3d = data_dir / "cmu/c3d"
    kb = build_kb([c3d / "01_01.c3d", c3d / "135_02.c3d"])
    miss = punch_gaps(take.n_frames, take.n_points, "markers", 0.2, np.random.default_rng(0))
    scores = {}
    for label, motion in (("original", take), ("lying", read), ("turned", turned)):
        out = fill(with_gaps(motion, miss), "knn", kb=kb)
        scores[label] = rmse_mm(out, motion, miss)
    print(scores)
    assert scores["turned"] == pytest.approx(scores["original"], rel=0.01)
    assert scores["lying"] > 1.4 * scores["original"]


def test_the_command_line_warns_and_takes_up(lying, tmp_path):
    _, path = lying
    run = [sys.executable, "-m", "mocap_gapfill", "info", str(path)]
    r = subprocess.run(run, capture_output=True, text=True)
    assert r.returncode == 0 and "lies on its side" in r.stderr and "--up y" in r.stderr
    r = subprocess.run(run + ["--up", "y"], capture_output=True, text=True)
    assert r.returncode == 0 and "lies on its side" not in r.stderr
