"""Every motion file of the shared data parses, with MANIFEST.md's frame counts."""

import re

import numpy as np
import pytest

from mocap_gapfill.core.formats import asfamc
from mocap_gapfill.core.formats.bvh import read_bvh
from mocap_gapfill.core.io import read_motion
from mocap_gapfill.core.motion import y_up_to_z_up

MOTION_SUFFIXES = (".amc", ".bvh", ".bvh.gz", ".c3d")
# MANIFEST.md: "02_01.amc ... no 02.asf found - the demo pairs it with 12.asf"
EXPLICIT_ASF = {"cmu/asfamc/02/02_01.amc": "cmu/asfamc/12/12.asf"}


def manifest_frames(data_dir):
    """{relative path: frames} from every table of MANIFEST.md that has a 'frames' column."""
    frames, columns = {}, None
    for line in (data_dir / "MANIFEST.md").read_text().splitlines():
        if not line.startswith("|"):
            columns = None
            continue
        cells = [c.strip().strip("`") for c in line.strip("|").split("|")]
        if columns is None:
            columns = cells
            continue
        if "frames" not in columns or set(cells[0]) <= set("-: "):
            continue
        path, count = cells[0], cells[columns.index("frames")]
        if path.endswith(MOTION_SUFFIXES) and count.isdigit():
            frames[path] = int(count)
    return frames


def motion_files(data_dir):
    return sorted(p for p in data_dir.rglob("*") if p.name.endswith(MOTION_SUFFIXES))


def test_every_motion_file_parses_with_manifest_frame_counts(data_dir):
    expected = manifest_frames(data_dir)
    files = motion_files(data_dir)
    assert len(files) >= 130  # MANIFEST: a few trials are held out for evaluation
    checked = 0
    for path in files:
        rel = path.relative_to(data_dir).as_posix()
        asf = EXPLICIT_ASF.get(rel)
        motion = read_motion(path, asf=data_dir / asf if asf else None)
        assert rel in expected, f"{rel} is not listed in MANIFEST.md"
        assert motion.n_frames == expected[rel], rel
        assert motion.fps == 120.0, rel
        assert motion.n_points >= 31, rel
        # metres, human-sized: the bounding box of a pose is 1.2 m to 2.8 m across
        extent = np.nanmax(motion.positions, axis=1) - np.nanmin(motion.positions, axis=1)
        size = np.nanmedian(np.linalg.norm(extent, axis=1))
        assert 1.2 < size < 2.8, (rel, size)
        checked += 1
    assert checked == len(files)


def test_asf_amc_equals_bvh_of_the_same_take(data_dir):
    """CMU 01_01 as ASF/AMC and as cgspeed's MotionBuilder-friendly BVH: same joints.

    cgspeed's BVH drops three ASF segments (it puts Neck, LeftFingerBase/LThumb and
    RightFingerBase/RThumb at OFFSET 0 0 0): thorax, lwrist and rwrist. With those three lengths
    set to zero, the ASF/AMC forward kinematics must reproduce every BVH joint in every frame.
    """
    skeleton = asfamc.parse_asf(data_dir / "cmu/asfamc/01/01.asf")
    for name in ("thorax", "lwrist", "rwrist"):
        skeleton.bones[name].length = 0.0
    data, degrees = asfamc.parse_amc(data_dir / "cmu/asfamc/01/01_01.amc", skeleton)
    positions, names = asfamc.amc_forward_kinematics(skeleton, data, degrees)
    asf = dict(zip(names, np.moveaxis(y_up_to_z_up(positions * skeleton.metres_per_unit), 1, 0)))
    bvh = read_bvh(data_dir / "cmu/bvh/mb_friendly/01_01.bvh", skip_frames=1, end_sites=True)
    bvh_points = dict(zip(bvh.names, np.moveaxis(bvh.positions, 1, 0)))
    # BVH joint -> ASF point at the same place (an ASF point is the tip of its bone)
    same = {
        "Hips": "root", "LHipJoint": "root", "RHipJoint": "root", "LowerBack": "root",
        "LeftUpLeg": "lhipjoint", "LeftLeg": "lfemur", "LeftFoot": "ltibia",
        "LeftToeBase": "lfoot", "LeftToeBase_End": "ltoes",
        "RightUpLeg": "rhipjoint", "RightLeg": "rfemur", "RightFoot": "rtibia",
        "RightToeBase": "rfoot", "RightToeBase_End": "rtoes",
        "Spine": "lowerback", "Spine1": "upperback", "Neck": "thorax", "Neck1": "lowerneck",
        "Head": "upperneck", "Head_End": "head",
        "LeftShoulder": "thorax", "LeftArm": "lclavicle", "LeftForeArm": "lhumerus",
        "LeftHand": "lradius", "LeftFingerBase": "lwrist", "LFingers": "lhand",
        "LFingers_End": "lfingers", "LThumb": "lwrist", "LThumb_End": "lthumb",
        "RightShoulder": "thorax", "RightArm": "rclavicle", "RightForeArm": "rhumerus",
        "RightHand": "rradius", "RightFingerBase": "rwrist", "RFingers": "rhand",
        "RFingers_End": "rfingers", "RThumb": "rwrist", "RThumb_End": "rthumb",
    }
    assert set(same) == set(bvh.names)
    assert set(same.values()) == set(names)  # all 31 ASF points are covered
    assert bvh.n_frames == len(asf["root"]) == 2751
    worst = max(np.linalg.norm(bvh_points[b] - asf[a], axis=1).max() for b, a in same.items())
    assert worst < 0.001, f"worst joint error {worst * 1000:.4f} mm"


def test_asf_and_bvh_units_and_axes(data_dir):
    """Standing subject: Z is up and the feet are near the floor, heads ~1.5-1.9 m up."""
    amc = read_motion(data_dir / "cmu/asfamc/07/07_05.amc")
    head = amc.positions[:, amc.names.index("head"), 2]
    toes = amc.positions[:, amc.names.index("ltoes"), 2]
    assert 1.4 < np.median(head - toes) < 1.95
    assert amc.units == "cmu" and amc.up_axis == "y" and amc.parents[0] == -1
    daz = read_motion(data_dir / "cmu/bvh/daz_friendly/07/07_05.bvh.gz", skip_frames=6)
    assert daz.units == "cm" and daz.n_points == 43
    assert 1.2 < np.median(daz.positions[:, daz.names.index("head"), 2]
                           - daz.positions[:, daz.names.index("lFoot"), 2]) < 1.95


def test_c3d_gaps_are_reported(data_dir):
    motion = read_motion(data_dir / "cmu/c3d/01_01.c3d")
    assert 0.022 < motion.missing.mean() < 0.026  # MANIFEST: "2.4 % missing samples (real gaps)"
    assert motion.names[:3] == ("LBWT", "RBWT", "LFWT")
    for clean in ("cmu/c3d/85_02.c3d", "cmu/c3d/135_02.c3d", "hdm05/c3d/HDM_bd_05-01_01_120.c3d"):
        m = read_motion(data_dir / clean)
        assert not m.missing.any(), clean
        assert all(":" not in n for n in m.names), clean  # "Male:LFHD" -> "LFHD"
    for clean in ("cmu/asfamc/01/01_01.amc", "cmu/bvh/mb_friendly/01_01.bvh"):
        assert not read_motion(data_dir / clean).missing.any()


def test_amc_finds_its_skeleton(data_dir, tmp_path):
    assert asfamc.find_asf(data_dir / "cmu/asfamc/01/01_01.amc").name == "01.asf"
    assert asfamc.find_asf(data_dir / "hdm05/asfamc/HDM_dg_06-03_03_120.amc").name == "HDM_dg.asf"
    lone = tmp_path / "lone.amc"
    lone.write_text((data_dir / "cmu/asfamc/09/09_06.amc").read_text())
    with pytest.raises(Exception, match="--asf"):
        read_motion(lone)
    motion = read_motion(lone, asf=data_dir / "cmu/asfamc/09/09.asf")
    assert motion.n_frames == 141


def test_skeleton_limbs_follow_the_hierarchy(data_dir):
    motion = read_motion(data_dir / "cmu/asfamc/01/01_01.amc")
    pairs = {(motion.names[a], motion.names[b]) for a, b in motion.limbs}
    assert ("lfemur", "ltibia") in pairs and ("root", "lhipjoint") in pairs
    assert len(pairs) == 30
    lengths = np.linalg.norm(motion.positions[:, motion.limbs[:, 0]]
                             - motion.positions[:, motion.limbs[:, 1]], axis=2)
    assert lengths.std(axis=0).max() < 1e-9  # rigid bones in FK output


def test_marker_limbs_are_rigid_pairs(data_dir):
    motion = read_motion(data_dir / "cmu/c3d/85_02.c3d")
    pairs = {frozenset((motion.names[a], motion.names[b])) for a, b in motion.limbs}
    # the four head markers sit on one rigid band
    assert {frozenset(p) for p in [("LFHD", "RFHD"), ("LFHD", "LBHD"), ("RFHD", "RBHD")]} <= pairs
    # markers on different segments never pair up
    for far in [("LFHD", "LTOE"), ("LWRA", "RWRA"), ("LKNE", "LANK")]:
        assert frozenset(far) not in pairs
    d = np.linalg.norm(motion.positions[:, motion.limbs[:, 0]]
                       - motion.positions[:, motion.limbs[:, 1]], axis=2)
    assert d.std(axis=0).max() <= 0.006
    assert re.match(r"^\w", motion.names[0])


def test_a_bvh_parsed_once_reads_as_twice(data_dir):
    """The knowledge-base build parses an armature take once for its joints and its bones'
    rotations: the same motion and basis as two reads, the parsed file left whole."""
    from mocap_gapfill.core.formats.bvh import parse_bvh, read_bvh_basis

    path = data_dir / "cmu/bvh/daz_friendly/07/07_05.bvh.gz"
    parsed = parse_bvh(path)
    frames = len(parsed.values)
    once = read_motion(path, skip_frames=6, bvh=parsed), read_bvh_basis(path, skip_frames=6,
                                                                        bvh=parsed)
    assert len(parsed.values) == frames
    twice = read_motion(path, skip_frames=6), read_bvh_basis(path, skip_frames=6)
    assert np.array_equal(once[0].positions, twice[0].positions)
    assert once[0].names == twice[0].names and len(once[0].positions) == frames - 6
    assert np.array_equal(once[1][1], twice[1][1]) and once[1][0].names == twice[1][0].names
