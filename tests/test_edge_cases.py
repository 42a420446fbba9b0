"""Odd motions through the whole fill: every case ends in a fill or a clear GapFillError.

(Covered elsewhere: frames with nothing present and gaps touching the first and last frame,
tests/test_engine.py; a KB of another skeleton, K larger than the KB, a 0-byte KB and a KB of a
future format, tests/test_engine.py; corrupt files, tests/test_corrupt_files.py and the fuzz
crashers, tests/test_fuzz_crashers.py. The list with what the user sees: docs/ROBUSTNESS.md.)
"""

import subprocess
import sys

import numpy as np
import pytest

from mocap_gapfill.core.errors import GapFillError, ParseError
from mocap_gapfill.core.evaluate import rmse_mm
from mocap_gapfill.core.fill import METHODS, fill
from mocap_gapfill.core.io import read_motion, write_motion
from mocap_gapfill.core.kb import build_kb, resample
from mocap_gapfill.core.recover import KnnSettings

FAST = KnnSettings(k=64, device="numpy")


@pytest.fixture(scope="module")
def kb(data_dir):
    return build_kb([data_dir / "hdm05/c3d"], stride=8)


@pytest.fixture(scope="module")
def take(data_dir):
    return read_motion(data_dir / "cmu/c3d/85_02.c3d").frame_range(0, 360)


def hide(motion, frames, points):
    pos = motion.positions.copy()
    pos[frames, points] = np.nan
    return motion.replace(positions=pos)


def run(motion, method, kb):
    return fill(motion, method, kb=kb, settings=FAST if method == "knn" else None)


@pytest.mark.parametrize("method", METHODS)
def test_an_empty_motion_has_nothing_to_fill(kb, take, method):
    empty = take.frame_range(0, 0)
    assert run(empty, method, kb).n_frames == 0


def test_one_frame(kb, take):
    """One frame with a marker missing: the KB methods fill it; interpolations cannot and leave
    it missing (never a crash)."""
    one = hide(take.frame_range(100, 101), 0, [3, 20])
    for method in METHODS:
        out = run(one, method, kb)
        assert np.array_equal(out.positions[~one.missing], one.positions[~one.missing])
        if method in ("knn", "auto", "pca"):
            assert not out.missing.any(), method
            assert rmse_mm(out, take.frame_range(100, 101), one.missing) < 150
        else:
            assert out.missing.sum() == 2, method


def test_a_point_missing_in_every_frame(kb, take):
    gone = hide(take, slice(None), take.names.index("LELB"))
    out = run(gone, "knn", kb)
    assert not out.missing.any()
    # from the KB alone, with no gap end to meet: within a hand of the truth (another subject's
    # marker placement shows here; docs/ROBUSTNESS.md)
    assert rmse_mm(out, take, gone.missing) < 150
    assert run(gone, "spline", kb).missing.sum() == take.n_frames  # nothing to interpolate


def test_all_hip_markers_missing_somewhere_in_every_frame(kb, take):
    """No frame shows all four waist markers (the root): the KB's pelvis is fitted to those
    present."""
    waist = [take.names.index(n) for n in ("LFWT", "RFWT", "LBWT", "RBWT")]
    gone = take
    for f in range(take.n_frames):
        gone = hide(gone, f, waist[f % 4])
    gone = hide(gone, slice(100, 160), take.names.index("RWRA"))
    out = run(gone, "knn", kb)
    assert not out.missing.any()
    assert rmse_mm(out, take, gone.missing) < 100


def test_nan_and_infinite_values_are_gaps(kb, take):
    pos = take.positions.copy()
    pos[50:80, 7] = np.inf
    pos[90:95, 8, 1] = np.nan  # one coordinate hides the whole sample
    pos[120, 9, 2] = -np.inf
    odd = take.replace(positions=pos)
    assert odd.missing.sum() == 30 + 5 + 1 and np.isnan(odd.positions[odd.missing]).all()
    out = run(odd, "knn", kb)
    assert not out.missing.any() and rmse_mm(out, take, odd.missing) < 100


def test_non_finite_numbers_in_text_files_are_refused(data_dir, tmp_path):
    lines = (data_dir / "cmu/bvh/mb_friendly/01_01.bvh").read_text().splitlines()
    motion_at = lines.index("MOTION")
    for bad in ("nan", "inf", "1e999"):
        values = lines[motion_at + 3].split()
        values[4] = bad
        text = lines[:motion_at + 1] + ["Frames: 1", lines[motion_at + 2], " ".join(values)]
        path = tmp_path / f"{bad}.bvh"
        path.write_text("\n".join(text) + "\n")
        with pytest.raises(ParseError, match="non-finite"):
            read_motion(path)


def test_duplicated_and_empty_c3d_labels(kb, take, tmp_path):
    """Labels as some systems write them: two markers with one label, an empty label. Written
    with ezc3d in a child process (it aborts the process on some writes)."""
    part = take.frame_range(0, 120)
    labels = list(part.names)
    labels[10], labels[11] = "Male:" + labels[12], ""  # a duplicate of marker 12, an empty one
    path = tmp_path / "labels.c3d"
    script = (
        "import sys, numpy as np, ezc3d\n"
        "pts = np.load(sys.argv[1]); labels = sys.argv[3:]\n"
        "c = ezc3d.c3d(); c['parameters']['POINT']['RATE']['value'] = [120.0]\n"
        "c['parameters']['POINT']['LABELS']['value'] = tuple(labels)\n"
        "d = np.ones((4, pts.shape[1], pts.shape[0])); d[:3] = pts.transpose(2, 1, 0) * 1000\n"
        "c['data']['points'] = d; c.write(sys.argv[2])\n")
    np.save(tmp_path / "pts.npy", part.positions)
    subprocess.run([sys.executable, "-c", script, str(tmp_path / "pts.npy"), str(path), *labels],
                   check=True)
    back = read_motion(path)
    assert len(set(back.names)) == back.n_points == part.n_points
    assert back.names[11] == "P11" and back.names[10] != back.names[12]
    np.testing.assert_allclose(back.positions, part.positions, atol=1e-6)
    gapped = hide(back, slice(30, 70), [back.names.index("RWRA"), 11])
    messages = []
    out = fill(gapped, "knn", kb=kb, settings=FAST, report=messages.append)
    assert any("left unfilled: " in m and "P11" in m for m in messages)
    assert out.missing[:, 11].sum() == 40 and not out.missing[:, back.names.index("RWRA")].any()
    # the default fills the point the knowledge base lacks from its rigid partners, and says so
    messages = []
    out = fill(gapped, "auto", kb=kb, settings=FAST, report=messages.append)
    assert "points the knowledge base lacks: filled from the take alone: P11" in messages
    assert not any("left unfilled" in m for m in messages) and not out.missing.any()
    error = np.linalg.norm(out.positions[30:70, 11] - part.positions[30:70, 11], axis=1)
    print(f"P11 from its rigid partners: {1000 * error.max():.1f} mm at most")
    assert error.max() < 0.02


def test_units_and_frame_rates_that_differ_from_the_kb(kb, take, tmp_path):
    """A take in metres or at 60 fps against a KB from 120 fps millimetre C3D files."""
    gapped = hide(take, slice(100, 200), [take.names.index(n) for n in ("LKNE", "RELB")])
    base = run(gapped, "knn", kb)
    as_csv = tmp_path / "take.csv"  # CSV is in metres
    write_motion(gapped, as_csv)
    np.testing.assert_allclose(run(read_motion(as_csv), "knn", kb).positions, base.positions,
                               atol=1e-6)
    slow = take.replace(positions=resample(take.positions, 120, 60), fps=60.0, filled=None)
    slow_gapped = hide(slow, slice(50, 100), [take.names.index(n) for n in ("LKNE", "RELB")])
    error_60 = rmse_mm(run(slow_gapped, "knn", kb), slow, slow_gapped.missing)
    assert error_60 < 1.5 * rmse_mm(base, take, gapped.missing)


def test_a_motion_with_nothing_observed(kb, take):
    with pytest.raises(GapFillError, match="every sample is missing"):
        run(hide(take, slice(None), slice(None)), "knn", kb)
