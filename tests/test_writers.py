"""Writers: round trips through C3D, NPZ and CSV; validation before ezc3d; atomic writes."""

import os
import stat

import numpy as np
import pytest

from mocap_gapfill.core.errors import GapFillError
from mocap_gapfill.core.formats.c3d import MAX_FRAMES, OBSERVED_RESIDUAL
from mocap_gapfill.core.io import read_motion, write_motion
from mocap_gapfill.core.motion import Motion


@pytest.fixture(scope="module")
def with_gaps(data_dir):
    motion = read_motion(data_dir / "cmu/c3d/01_01.c3d")
    assert motion.missing.any()
    return motion


@pytest.mark.parametrize("suffix", [".c3d", ".npz", ".csv"])
def test_round_trip_keeps_positions_and_gaps(with_gaps, tmp_path, suffix):
    gappy = np.argsort(-with_gaps.missing.sum(axis=0))[:6]  # the points with gaps, and others
    names = [with_gaps.names[i] for i in sorted(set(gappy) | set(range(6)))]
    motion = with_gaps.select(names)
    assert motion.missing.any() and not motion.missing.all()
    out = write_motion(motion, tmp_path / f"take{suffix}")
    back = read_motion(out)
    assert back.names == motion.names and back.fps == motion.fps
    np.testing.assert_array_equal(back.missing, motion.missing)
    # C3D stores float32 millimetres: 1 micrometre is far below any marker noise
    tol = 1e-6 if suffix == ".c3d" else 0.0
    np.testing.assert_allclose(back.positions, motion.positions, atol=tol, equal_nan=True)


def test_c3d_residuals_mark_filled_and_missing(tmp_path):
    rng = np.random.default_rng(0)
    pos = rng.normal(size=(20, 3, 3))
    pos[5:8, 1] = np.nan
    filled = np.zeros((20, 3), dtype=bool)
    filled[10:12, 2] = True
    motion = Motion(pos, ("A", "B", "C"), 100.0, filled=filled)
    write_motion(motion, tmp_path / "m.c3d")
    import ezc3d

    res = ezc3d.c3d(str(tmp_path / "m.c3d"))["data"]["meta_points"]["residuals"][0].T
    assert (res[5:8, 1] == -1).all()
    assert (res[10:12, 2] == 0).all()
    observed = ~motion.missing & ~filled
    assert (res[observed] == OBSERVED_RESIDUAL).all()
    back = read_motion(tmp_path / "m.c3d")
    np.testing.assert_array_equal(back.filled, filled)


def test_npz_keeps_skeleton(data_dir, tmp_path):
    motion = read_motion(data_dir / "cmu/asfamc/09/09_06.amc")
    back = read_motion(write_motion(motion, tmp_path / "run.npz"))
    assert back.parents == motion.parents
    np.testing.assert_array_equal(back.limbs, motion.limbs)
    np.testing.assert_array_equal(back.positions, motion.positions)
    np.testing.assert_array_equal(back.rest, motion.rest)  # the ASF's zero pose
    assert (back.units, back.up_axis) == ("cmu", "y")


@pytest.mark.parametrize("change, message", [
    (dict(positions=np.zeros((MAX_FRAMES + 1, 1, 3))), "at most 65535 frames"),
    (dict(positions=np.zeros((0, 1, 3))), "no frames"),
    (dict(names=("Kopf\u00e4",)), "ASCII"),
    (dict(positions=np.full((3, 1, 3), 5e6)), "wrong units"),
])
def test_c3d_writer_refuses_what_ezc3d_cannot_write(tmp_path, change, message):
    base = dict(positions=np.zeros((3, 1, 3)), names=("A",), fps=120.0)
    base.update(change)
    with pytest.raises(GapFillError, match=message):
        write_motion(Motion(**base), tmp_path / "x.c3d")
    assert list(tmp_path.iterdir()) == []  # no partial file, no temporary left behind


def test_writes_never_replace_silently_and_are_atomic(tmp_path):
    target = tmp_path / "keep.c3d"
    target.write_bytes(b"precious")
    good = Motion(np.zeros((3, 1, 3)), ("A",), 120.0)
    with pytest.raises(GapFillError, match="exists"):
        write_motion(good, target)
    bad = Motion(np.zeros((MAX_FRAMES + 1, 1, 3)), ("A",), 120.0)
    with pytest.raises(GapFillError):
        write_motion(bad, target, overwrite=True)
    assert target.read_bytes() == b"precious"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["keep.c3d"]
    write_motion(good, target, overwrite=True)
    assert read_motion(target).n_frames == 3


@pytest.mark.parametrize("mask, mode", [(0o022, 0o644), (0o077, 0o600), (0o002, 0o664)])
def test_outputs_are_as_readable_as_the_umask_wants(tmp_path, mask, mode):
    """Every writer goes through one atomic rename; the file it leaves has the mode a new file
    gets under the user's umask (colleagues and a render farm read cleaned takes under 022),
    not the owner-only mode of the temporary file it was written as."""
    from mocap_gapfill.core import synth
    from mocap_gapfill.core.kb import kb_from_motions

    motion = Motion(np.zeros((3, 1, 3)), ("A",), 120.0)
    old = os.umask(mask)
    try:
        paths = [tmp_path / f"take{suffix}" for suffix in (".c3d", ".npz", ".csv")]
        for path in paths:
            write_motion(motion, path)
        kb = kb_from_motions([synth.take(synth.KB_GAITS[0], frames=30, fps=30.0)[1]])
        paths.append(tmp_path / "kb.npz")
        kb.save(paths[-1])
    finally:
        os.umask(old)
    assert {oct(stat.S_IMODE(p.stat().st_mode)) for p in paths} == {oct(mode)}


def test_unknown_output_format(tmp_path):
    with pytest.raises(GapFillError, match="cannot write .bvh"):
        write_motion(Motion(np.zeros((3, 1, 3)), ("A",), 120.0), tmp_path / "x.bvh")


def test_motion_validates_its_input():
    with pytest.raises(GapFillError, match="duplicated"):
        Motion(np.zeros((2, 2, 3)), ("A", "A"), 30.0)
    with pytest.raises(GapFillError, match="fps"):
        Motion(np.zeros((2, 1, 3)), ("A",), 0.0)
    with pytest.raises(GapFillError, match="shape"):
        Motion(np.zeros((2, 3)), ("A",), 30.0)
    pos = np.zeros((2, 1, 3))
    pos[0, 0, 1] = np.inf  # one bad coordinate hides the whole sample
    assert Motion(pos, ("A",), 30.0).missing.tolist() == [[True], [False]]


def test_c3d_reads_all_three_gap_encodings(tmp_path):
    """NaN, a negative residual and an exact (0, 0, 0) all mean 'missing'."""
    import ezc3d

    frames = 6
    points = np.ones((4, 3, frames))
    points[:3] *= np.arange(1, frames + 1) * 100.0
    points[:3, 0, 1] = np.nan  # NaN
    points[:3, 2, 4] = 0.0  # exact zero
    residuals = np.ones((1, 3, frames))
    residuals[0, 1, 3] = -1.0  # negative residual with a valid-looking position
    c3d = ezc3d.c3d()
    c3d["parameters"]["POINT"]["RATE"]["value"] = [100.0]
    c3d["parameters"]["POINT"]["LABELS"]["value"] = ("Sub:A", "Sub:B", "Sub:C")
    c3d["data"]["points"] = points
    c3d["data"]["meta_points"] = {"residuals": residuals,
                                  "camera_masks": np.zeros((7, 3, frames), dtype=bool)}
    c3d.write(str(tmp_path / "gaps.c3d"))
    motion = read_motion(tmp_path / "gaps.c3d")
    assert motion.names == ("A", "B", "C")
    expected = np.zeros((frames, 3), dtype=bool)
    expected[1, 0] = expected[3, 1] = expected[4, 2] = True
    np.testing.assert_array_equal(motion.missing, expected)
    assert motion.positions[2, 0, 0] == pytest.approx(0.3)  # mm -> m
