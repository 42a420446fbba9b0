"""The add-on's workflow on real data, through its operators, in the bpy module (4.2 LTS and 5.0).

Marker set: CMU 85_02 (C3D, complete) imported as empties, keys deleted over ranges, gaps
detected and filled from a KB of the other CMU C3D takes (subjects 01, 135). Armature: CMU 03_02
(Daz-friendly BVH, complete) imported with Blender's own BVH importer, bone keys deleted over
ranges, filled from a KB of every other Daz-friendly subject (every 4th pose). Both compared
with the truth in millimetres.
"""

import gzip
import hashlib
import re
import shutil
import subprocess
import sys
from types import SimpleNamespace

import numpy as np
import pytest

from mocap_gapfill.core.explain import KEPT

LOCAL_MODULE = "bl_ext.mocap_gapfill_tests.mocap_gapfill"  # conftest.extension loads it

GEN = 5  # Keyframe.type GENERATED as foreach_get reports it


def modules():
    import importlib

    root = importlib.import_module(LOCAL_MODULE)
    from importlib import import_module

    return (import_module(f"{root.__name__}.addon.bridge"),
            import_module(f"{root.__name__}.addon.compat"),
            import_module(f"{root.__name__}.addon.gaps"),
            import_module(f"{root.__name__}.addon.samples"))


def rmse_mm(a, b):
    return float(1000 * np.sqrt(np.mean(np.sum((a - b) ** 2, axis=-1))))


def delete_keys(obj, first, last):
    """Delete every key of an object (a marker empty) on frames first..last."""
    _, compat, _, _ = modules()
    for curve in compat.fcurves(obj):
        for key in reversed(list(curve.keyframe_points)):
            if first <= key.co[0] <= last:
                curve.keyframe_points.remove(key)


@pytest.fixture(scope="module")
def marker_kb(data_dir, tmp_path_factory):
    from mocap_gapfill.core.kb import build_kb

    path = tmp_path_factory.mktemp("kb") / "cmu_c3d.npz"
    build_kb([data_dir / "cmu/c3d/01_01.c3d", data_dir / "cmu/c3d/135_02.c3d"]).save(path)
    return path


@pytest.fixture(scope="module")
def daz_kb(daz_rotation_kb, tmp_path_factory):
    from mocap_gapfill.core.evaluate import kb_without

    path = tmp_path_factory.mktemp("kb") / "daz.npz"
    kb_without(daz_rotation_kb, "03").save(path)
    return path


MARKER_GAPS = (("LELB", 100, 189), ("RKNE", 300, 389), ("LFHD", 1, 60), ("RTOE", 751, 810),
               ("LWRA", 400, 519))


def test_a_second_marker_set_of_the_same_labels_says_how_its_gaps_were_filled(scene, data_dir,
                                                                               marker_kb):
    """Blender names the second import's empties LELB.001, ...: the fill's account (by label)
    reaches the listed gaps (by object) all the same."""
    bpy = pytest.importorskip("bpy")
    path = data_dir / "cmu/c3d/85_02.c3d"
    for _ in range(2):
        assert bpy.ops.mocap_gapfill.import_markers(filepath=str(path)) == {"FINISHED"}
    root = bpy.context.active_object
    delete_keys(bpy.data.objects["LELB.001"], 100, 189)
    scene.mocap_gapfill.detect_suspects = False
    assert bpy.ops.mocap_gapfill.detect_gaps() == {"FINISHED"}
    scene.mocap_gapfill.kb_path = str(marker_kb)
    assert bpy.ops.mocap_gapfill.fill_gaps(scope="ALL") == {"FINISHED"}
    (gap,) = root.mocap_gapfill.gaps
    assert (gap.point, gap.filled) == ("LELB.001", True)
    assert gap.how.startswith("rigid partners") and gap.expected_mm > 0


def test_a_marker_gap_names_every_estimate_blended_into_it(extension):
    """The gap list's words for a short dropout blended from rigid partners, a spline and a
    partner's pattern (``auto``'s accounts of the two gaps it overlaps, by their lengths)."""
    from mocap_gapfill.core.fill import GapAccount

    _, _, gaps, _ = modules()
    accounts = [GapAccount("LELB", 10, 12, rigid=0.3, models=0.0, windows=0.0, own=0.0,
                           spline=0.3, pattern=0.4, estimate=0.002),
                GapAccount("LELB", 14, 16, rigid=0.5, models=0.02, windows=0.0, own=0.0,
                           spline=0.38, pattern=0.1, estimate=0.003),
                GapAccount("RELB", 10, 12, rigid=1.0, models=0.0, windows=0.0, own=0.0,
                           spline=0.0, pattern=0.0, estimate=0.009)]
    how, _, expected = gaps.how_carried(accounts, "LELB", 8, 20)
    assert how == "rigid partners 40%, smooth curve 34%, a partner's path 25%" and expected == 3.0
    assert gaps.describe(SimpleNamespace(how=how, expected_mm=expected, kind="MISSING"), False) == [
        "from rigid partners 40%", "smooth curve 34%", "a partner's path 25%",
        "expected error ~3 mm"]


def test_an_armature_gap_names_the_fills_it_went_to(extension):
    """The gap list's words for a bone's gaps: a share of a fill, the rest to an agreeing pair
    (less of the way where ``learn`` is one of it) and to the cubic the take's copies favour, to
    ``learn`` where the bone's windows trust it, then on to ``learn`` on a gap of 0.4-0.6 s, then
    the fill the others bear out in its place; the interpolation kept where nothing moved it."""
    from mocap_gapfill.core.bonefill import GapChoice
    from mocap_gapfill.core.explain import INTERNAL_NAMES

    _, _, gaps, _ = modules()
    choices = [GapChoice("lShldr", 10, 24, "mix", 0.5, 0.6, corroborated="hermite + regress",
                         cubic=0.15),
               GapChoice("lShldr", 40, 54, "interp", 0.0, cubic=0.25),
               GapChoice("lShldr", 70, 84, "interp", 0.0, corroborated="hermite + learn"),
               GapChoice("lShldr", 100, 114, "learn", 0.4, 0.5, learnt=0.15),
               GapChoice("lShldr", 130, 189, "stack", 0.5, 0.7, consensus=0.2, towards="learn",
                         corroborated="hermite + match"),
               GapChoice("lShldr", 200, 214, "interp", 0.0),
               GapChoice("lShldr", 300, 359, "match", 1.0, 0.4, medoid="regress")]
    assert gaps.how_filled(choices, "lShldr", 10, 24)[:2] == (
        "knowledge-base motion (50% of the way from Blender's curve), blended with a smooth "
        "curve and the other bones", 0.6)
    assert gaps.how_filled(choices, "lShldr", 40, 54)[0] == (
        "Blender's curve, blended with a smooth curve")
    assert gaps.how_filled(choices, "lShldr", 70, 84)[0] == (
        "Blender's curve, blended with a smooth curve and its own motion")
    assert gaps.how_filled(choices, "lShldr", 200, 214)[0] == "kept Blender's curve"
    assert gaps.how_filled(choices, "lShldr", 300, 359)[0] == (
        "the other bones, which the other fills bear out")
    assert gaps.how_filled(choices, "lShldr", 100, 114)[0] == (
        "its own motion (40% of the way from Blender's curve)")
    assert gaps.how_filled(choices, "lShldr", 130, 189)[0] == (
        "a blend of several fills (50% of the way from Blender's curve), blended with a smooth "
        "curve, knowledge-base motion and its own motion")
    # the panel is narrow: each source on a line of its own
    listed = SimpleNamespace(how=gaps.how_filled(choices, "lShldr", 10, 24)[0], estimate=0.6,
                             kind="MISSING")
    assert gaps.describe(listed, True) == [
        "from knowledge-base motion (50% of the way from Blender's curve)",
        "blended with a smooth curve", "and the other bones",
        "expected error 0.60x Blender's curve"]
    listed.how = gaps.how_filled(choices, "lShldr", 200, 214)[0]
    assert gaps.describe(listed, True) == ["kept Blender's curve",
                                           "(no fill was sure to beat it here)"]
    # plain words: no stage or generator named by its internal name
    for c in choices:
        listed.how = gaps.how_filled(choices, "lShldr", c.first, c.last)[0]
        words = " ".join(gaps.describe(listed, True))
        assert not [n for n in INTERNAL_NAMES if re.search(rf"\\b{n}\\b", words)], words


def test_blend_run_names_the_marker_gaps_to_review_first(scene, data_dir, marker_kb, tmp_path):
    """What ``blend`` / ``blender -b -c mocap_gapfill`` hands the batch report for a marker
    scene: the largest error the gaps' copies expect and the gaps to review first."""
    import argparse
    import importlib

    bpy = pytest.importorskip("bpy")
    batch = importlib.import_module(f"{LOCAL_MODULE}.addon.batch")
    commands = importlib.import_module(f"{LOCAL_MODULE}.addon.commands")
    assert bpy.ops.mocap_gapfill.import_markers(
        filepath=str(data_dir / "cmu/c3d/85_02.c3d")) == {"FINISHED"}
    root = bpy.context.active_object
    for name, first, last in MARKER_GAPS[:2]:
        delete_keys(bpy.data.objects[name], first, last)
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "take.blend"))
    parser = argparse.ArgumentParser()
    commands.add_arguments(parser)
    done = batch.run(parser.parse_args(["--kb", str(marker_kb), "--no-suspects"]),
                     report=lambda line: None)
    listed = sorted(root.mocap_gapfill.gaps, key=lambda g: -g.expected_mm)
    assert sorted(g.point for g in listed) == ["LELB", "RKNE"] and listed[-1].expected_mm > 0
    assert done["gaps"] == 2 and done["expected_mm"] == round(listed[0].expected_mm, 1)
    assert done["review_first"] == "; ".join(f"{root.name}: {g.point} {g.first}-{g.last} "
                                             f"~{g.expected_mm:.0f} mm" for g in listed)
    assert (tmp_path / "take_filled.blend").is_file()


def test_c3d_markers_detect_fill_preview(scene, data_dir, marker_kb):
    from mocap_gapfill.core.fill import fill
    from mocap_gapfill.core.io import read_motion

    bpy = pytest.importorskip("bpy")
    bridge, _, gaps, _ = modules()
    path = data_dir / "cmu/c3d/85_02.c3d"
    assert bpy.ops.mocap_gapfill.import_markers(filepath=str(path)) == {"FINISHED"}
    root = bpy.context.active_object
    assert bridge.is_marker_set(root) and len(root.mocap_gapfill.gaps) == 0  # 85_02 is complete
    assert (scene.frame_start, scene.frame_end, scene.render.fps) == (1, 810, 120)
    for name, first, last in MARKER_GAPS:
        delete_keys(bpy.data.objects[name], first, last)
    scene.mocap_gapfill.detect_suspects = False
    assert bpy.ops.mocap_gapfill.detect_gaps() == {"FINISHED"}
    found = sorted((g.point, g.first, g.last, g.kind) for g in root.mocap_gapfill.gaps)
    assert found == sorted((n, a, b, "MISSING") for n, a, b in MARKER_GAPS)
    stats = {p.name: (p.gaps, p.frames, p.longest) for p in root.mocap_gapfill.points}
    assert stats["LWRA"] == (1, 120, 120) and stats["LFHD"] == (1, 60, 60)

    # fill from the knowledge base, through the operator
    scene.mocap_gapfill.kb_path = str(marker_kb)
    assert bpy.ops.mocap_gapfill.fill_gaps(scope="ALL") == {"FINISHED"}
    assert root.mocap_gapfill.showing == "RECOVERED"
    assert all(g.filled for g in root.mocap_gapfill.gaps)
    take = bridge.read_take(root, scene)
    truth = read_motion(path).select(list(take.points))
    mask = gaps.gap_mask(root.mocap_gapfill.gaps, take.points, take.first, 810)
    knn = rmse_mm(take.positions[mask], truth.positions[mask])
    query = truth.replace(positions=np.where(mask[..., None], np.nan, truth.positions))
    linear, spline = (rmse_mm(fill(query, m).positions[mask], truth.positions[mask])
                      for m in ("linear", "spline"))
    print(f"\n85_02 markers, {int(mask.sum())} samples in 5 gaps: knn RMSE {knn:.1f} mm, "
          f"linear {linear:.1f} mm, spline {spline:.1f} mm")
    assert knn < 0.5 * min(linear, spline)  # measured: 90.8 vs 313.2 / 437.5
    # observed keys kept (keys are float32: 1 micrometre)
    assert np.abs(take.positions[~mask] - truth.positions[~mask]).max() < 1e-6
    # each gap says what filled it and what its copies expect of the error; reviewing them worst
    # first starts where the fill is furthest off (measured: LWRA 27 / 30.1 mm, RKNE 19 / 20.7,
    # LELB 15 / 6.2, RTOE 5 / 1.8, LFHD 1 / 1.5 estimated / realised)
    realised = {}
    for gap in root.mocap_gapfill.gaps:
        j = take.points.index(gap.point)
        rows = slice(gap.first - take.first, gap.last - take.first + 1)
        realised[gap.point] = rmse_mm(take.positions[rows, j], truth.positions[rows, j])
        print(f"{gap.point} {gap.first}-{gap.last}: {'; '.join(gaps.describe(gap, False))} "
              f"(realised {realised[gap.point]:.1f} mm)")
        assert gap.how.startswith("rigid partners") and 0.25 < gap.expected_mm / realised[
            gap.point] < 4
    worst = sorted(root.mocap_gapfill.gaps, key=lambda g: -g.expected_mm)
    assert [g.point for g in worst[:2]] == sorted(realised, key=realised.get)[:-3:-1]

    # filled keys are typed GENERATED; the original actions are untouched
    elbow = bpy.data.objects["LELB"]
    curve = bridge.compat.fcurves(elbow).find("location", index=0)
    types = np.empty(len(curve.keyframe_points), dtype=np.int32)
    curve.keyframe_points.foreach_get("type", types)
    frames, _ = bridge.curve_keys(curve)
    assert set(frames[types == GEN].astype(int)) == set(range(100, 190))
    root.mocap_gapfill.showing = "ORIGINAL"
    assert elbow.animation_data.action == elbow.mocap_gapfill.original_action
    original = bridge.read_take(root, scene)
    assert np.array_equal(np.isnan(original.positions[..., 0]), mask)

    # Revert Gap: the elbow's gap open again in the recovered action, the other gaps filled
    root.mocap_gapfill.gap_index = next(i for i, g in enumerate(root.mocap_gapfill.gaps)
                                        if g.point == "LELB")
    assert bpy.ops.mocap_gapfill.revert_gap() == {"FINISHED"}
    assert root.mocap_gapfill.showing == "RECOVERED"
    assert [g.point for g in root.mocap_gapfill.gaps if not g.filled] == ["LELB"]
    elbow_gap = np.zeros_like(mask)
    elbow_gap[99:189, take.points.index("LELB")] = True
    reverted = bridge.read_take(root, scene)
    assert np.array_equal(np.isnan(reverted.positions[..., 0]), elbow_gap)
    assert np.array_equal(reverted.positions[~elbow_gap], take.positions[~elbow_gap])


def test_a_second_take_of_the_same_markers_fills_with_the_starter_kb(scene, data_dir):
    """Imported beside another take, the markers' objects become LFHD.001...; the core still
    sees the file's labels, so the starter knowledge base (none chosen) fits it."""
    bpy = pytest.importorskip("bpy")
    bridge, _, _, _ = modules()
    path = data_dir / "cmu/c3d/01_01.c3d"  # real gaps: RBAC's last 30 frames
    bpy.ops.mocap_gapfill.import_markers(filepath=str(path))
    bpy.ops.mocap_gapfill.import_markers(filepath=str(path))
    second = bpy.context.active_object
    take = bridge.read_take(second, scene)
    assert "LFHD.001" in take.points and "LFHD" in take.names and "LFHD.001" not in take.names
    scene.mocap_gapfill.kb_path = ""
    assert bpy.ops.mocap_gapfill.fill_gaps(scope="ALL", objects=second.name) == {"FINISHED"}
    rbac = next(g for g in second.mocap_gapfill.gaps if g.point.startswith("RBAC."))
    assert rbac.filled and rbac.last - rbac.first + 1 == 30
    # RBAC-1, a stray point seen in 8 frames, has nothing to place it: its gaps stay open
    assert not any(g.filled for g in second.mocap_gapfill.gaps if g.point.startswith("RBAC-1"))
    filled = bridge.read_take(second, scene)
    assert not np.isnan(filled.positions[:, filled.points.index(rbac.point)]).any()


def test_markers_no_knowledge_base_knows_fill_from_the_take_alone(scene, data_dir):
    """A studio's own labels, none chosen: no starter knowledge base fits, so `auto` fills from
    the take alone (rigid partners, spline, pattern) and says so; before, the fill stopped."""
    bpy = pytest.importorskip("bpy")
    bridge, _, _, _ = modules()
    bpy.ops.mocap_gapfill.import_markers(filepath=str(data_dir / "cmu/c3d/85_02.c3d"))
    root = bpy.context.active_object
    original = bridge.read_take(root, scene)
    labels = sorted(c.name for c in root.children)
    for i, child in enumerate(sorted(root.children, key=lambda c: c.name)):
        child[bridge.MARKER_LABEL] = child.name = f"M{i:02d}"
    delete_keys(bpy.data.objects["M07"], 100, 189)
    truth = bridge.read_take(root, scene)
    scene.mocap_gapfill.detect_suspects = False
    assert bpy.ops.mocap_gapfill.detect_gaps() == {"FINISHED"}
    scene.mocap_gapfill.kb_path = ""
    assert bpy.ops.mocap_gapfill.fill_gaps(scope="ALL") == {"FINISHED"}
    (gap,) = root.mocap_gapfill.gaps
    assert gap.filled and gap.how.startswith("rigid partners")
    filled = bridge.read_take(root, scene)
    m07 = filled.points.index("M07")
    assert np.isnan(truth.positions[99:189, m07]).all()
    error = rmse_mm(filled.positions[99:189, m07],
                    original.positions[99:189, original.points.index(labels[7])])
    print(f"{labels[7]} from its rigid partners: {error:.1f} mm")
    assert error < 20


def test_clicking_a_gap_selects_and_jumps(scene, data_dir):
    bpy = pytest.importorskip("bpy")
    path = data_dir / "cmu/c3d/01_01.c3d"  # real gaps
    bpy.ops.mocap_gapfill.import_markers(filepath=str(path))
    root = bpy.context.active_object
    settings = root.mocap_gapfill
    assert len(settings.gaps) == 3  # MANIFEST: 3 gaps, the longest 2,623 frames on RBAC-1
    longest = max(settings.gaps, key=lambda g: g.last - g.first)
    assert (longest.point, longest.last - longest.first + 1) == ("RBAC-1", 2623)
    settings.gap_index = list(settings.gaps).index(longest)
    assert bpy.context.active_object.name == "RBAC-1"
    assert [o.name for o in bpy.context.selected_objects] == ["RBAC-1"]
    assert scene.frame_current == longest.first


def test_sample_takes_open_with_their_gaps_and_a_kb_without_their_subject(scene):
    """The panel's Sample buttons: CMU 01_01 as empties with its real gaps, CMU 03_02 through
    Blender's BVH importer with three bones' keys deleted; each gets the starter knowledge base
    without the take's subject, written into the extension's user folder."""
    from mocap_gapfill.core.kb import load_kb

    bpy = pytest.importorskip("bpy")
    assert bpy.ops.mocap_gapfill.open_sample(kind="ARMATURE") == {"FINISHED"}
    arm = bpy.context.active_object
    assert arm.type == "ARMATURE" and scene.render.fps == 120
    found = sorted((g.point, g.first, g.last) for g in arm.mocap_gapfill.gaps)
    assert found == [("chest", 301, 360), ("lForeArm", 121, 220), ("rShin", 151, 240)]
    kb_file = scene.mocap_gapfill.kb_path
    assert "extensions" in kb_file and kb_file.endswith("cmu_daz43_kb_without_03.npz")
    kb = load_kb(kb_file)
    used = [kb.sources[i] for i in np.unique(kb.source_index)]
    assert kb.turns is not None and used and not any("03_0" in s for s in used)
    assert bpy.ops.mocap_gapfill.open_sample(kind="MARKERS") == {"FINISHED"}
    root = bpy.context.active_object
    assert root.type == "EMPTY" and len(root.children) == 42
    assert sorted((g.point, g.last - g.first + 1) for g in root.mocap_gapfill.gaps)[-1] == \
        ("RBAC-1", 2623)
    assert scene.mocap_gapfill.kb_path.endswith("cmu_markers41_kb_without_01.npz")
    # the armature is still there, untouched by the second sample
    assert len(arm.mocap_gapfill.gaps) == 3


@pytest.fixture
def daz_armature(scene, data_dir, tmp_path):
    bpy = pytest.importorskip("bpy")
    bvh = tmp_path / "03_02.bvh"
    bvh.write_bytes(gzip.decompress((data_dir / "cmu/bvh/daz_friendly/03/03_02.bvh.gz")
                                    .read_bytes()))
    bpy.ops.import_anim.bvh(filepath=str(bvh), update_scene_fps=True,
                            update_scene_duration=True)
    return bpy.context.active_object


BONE_GAPS = (("lForeArm", 120, 219), ("rShin", 150, 239), ("chest", 300, 359))


def remove_bone_keys(obj, bone_gaps):
    _, _, _, samples = modules()
    samples.remove_keys(obj, bone_gaps)


def test_bvh_armature_fill_beats_blender_interpolation(daz_armature, daz_kb, data_dir):
    """The default fill in the add-on, on gaps an animator leaves (keys deleted in Blender,
    LINEAR keys kept around them): per gap never worse than Blender's own interpolation by more
    than 10 % + 2 mm, keyed channels bit-identical, the original action untouched. The numpy
    reproduction of Blender's interpolation (the evaluation's ``interp``) within 0.01 mm."""
    from mocap_gapfill.core.formats.bvh import read_bvh_rig
    from mocap_gapfill.core.rig import basis_matrices, interpolate_channels

    bpy = pytest.importorskip("bpy")
    bridge, compat, gaps, _ = modules()
    arm = daz_armature
    scene = bpy.context.scene
    assert arm.type == "ARMATURE" and scene.render.fps == 120
    truth = bridge.read_take(arm, scene)
    assert truth.metres == 0.01  # Daz BVH in cm: guessed from the height
    original = {(c.data_path, c.array_index): bridge.curve_keys(c) for c in compat.fcurves(arm)}
    remove_bone_keys(arm, BONE_GAPS)
    scene.mocap_gapfill.detect_suspects = False
    assert bpy.ops.mocap_gapfill.detect_gaps() == {"FINISHED"}
    found = sorted((g.point, g.first, g.last) for g in arm.mocap_gapfill.gaps)
    assert found == sorted(BONE_GAPS)
    broken = bridge.read_take(arm, scene)
    bone_gaps = gaps.gap_mask(arm.mocap_gapfill.gaps, broken.points, broken.first,
                              broken.positions.shape[0])

    # Blender's interpolation across the deleted keys, reproduced in numpy from the file
    rig, channels, location, _ = read_bvh_rig(data_dir / "cmu/bvh/daz_friendly/03/03_02.bvh.gz")
    numpy_interp = rig.joints(basis_matrices(rig, interpolate_channels(channels, bone_gaps),
                                             location))
    off_mm = np.abs(numpy_interp - broken.positions * broken.metres).max() * 1000
    print(f"\nnumpy interpolation vs Blender's: max {off_mm:.5f} mm")
    assert off_mm < 0.01

    keys_before = {(c.data_path, c.array_index): len(c.keyframe_points)
                   for c in compat.fcurves(arm)}
    scene.mocap_gapfill.kb_path = str(daz_kb)
    assert bpy.ops.mocap_gapfill.fill_gaps() == {"FINISHED"}
    after = bridge.read_take(arm, scene)
    m = truth.metres
    below = rig.placed_by()
    errors = gap_errors(arm, broken, after, truth)
    for gap, fill_mm, interp_mm in errors:
        print(f"{gap.point} {gap.first}-{gap.last}: default fill {fill_mm:.1f} mm, Blender's "
              f"interpolation {interp_mm:.1f} mm")
        # measured 120.5 / 61.9 / 6.9 vs 130.0 / 83.8 / 7.4 (the chest's kept
        # interpolation goes a fifth of the way on to learn: 7.4 before; now it
        # keeps its interpolation, its fill moving it less than the copies' error: 6.7 before;
        # 125.6 / 76.1 before the long-gap consensus and the scene's 120.000048 fps read as
        # 120; earlier: the shin gap came out worse, 94.3); issue 14's bar per gap
        assert fill_mm <= 1.1 * interp_mm + 2.0
    # over the three gaps together: measured 12 % better (RMSE; earlier: 5 %, earlier: 2.7 %)
    assert total_mm(errors, 1) < total_mm(errors, 2)
    # joints no gap reaches did not move
    missing = bridge.missing_points(broken, bone_gaps)
    assert np.abs(after.positions[~missing] - truth.positions[~missing]).max() * m < 1e-4
    # each gap in the list says how it was filled: where Blender's interpolation was kept,
    # nothing moved; a fill the copies judged, with their estimate below the interpolation's
    for gap in arm.mocap_gapfill.gaps:
        rows = slice(gap.first - broken.first, gap.last - broken.first + 1)
        joints = below[rig.names.index(gap.point)]
        moved = np.abs(after.positions[rows][:, joints]
                       - broken.positions[rows][:, joints]).max() * m > 1e-4
        fill_mm = 1000 * m * np.sqrt(np.mean(np.sum((after.positions[rows][:, joints]
                                                      - truth.positions[rows][:, joints]) ** 2,
                                                     axis=-1)))
        print(f"{gap.point}: {'; '.join(gaps.describe(gap, True))} (came out {fill_mm:.1f} mm)")
        assert gap.how and moved == (gap.how != KEPT), (gap.point, gap.how)
        assert gap.estimate < 1.0 and (gap.estimate > 0 or gap.how == KEPT)
        assert gap.expected_mm == 0  # an armature's copies foretell the share, not the level
        if gap.point in ("lForeArm", "rShin"):  # 100 / 90 frames at 120 fps: the long-gap
            # consensus with the take's own regression, said on a line of its own
            said = gaps.describe(gap, True)[1:3]
            assert any(line.endswith(" the other bones") for line in said), said

    # keyed channels bit for bit: every key of the recovered action off the gaps is the original
    for curve in compat.fcurves(arm):
        frames, values = bridge.curve_keys(curve)
        modes = np.empty(len(frames), dtype=np.int32)
        curve.keyframe_points.foreach_get("interpolation", modes)
        types = np.empty(len(frames), dtype=np.int32)
        curve.keyframe_points.foreach_get("type", types)
        kept = types != GEN
        first_frames, first_values = original[(curve.data_path, curve.array_index)]
        index = np.searchsorted(first_frames, frames[kept])
        assert np.array_equal(first_values[index], values[kept]), curve.data_path
        assert (modes == 1).all()  # LINEAR, as imported; filled keys too
        bone = curve.data_path.split('"')[1]
        span = [(a, b) for n, a, b in BONE_GAPS if n == bone]
        assert all(any(a <= f <= b for a, b in span) for f in frames[~kept])

    # the original action is intact, and still plays on demand
    original_action = arm.mocap_gapfill.original_action
    assert original_action is not None and arm.animation_data.action != original_action
    arm.mocap_gapfill.showing = "ORIGINAL"
    assert {(c.data_path, c.array_index): len(c.keyframe_points)
            for c in compat.fcurves(arm)} == keys_before
    assert np.allclose(bridge.read_take(arm, scene).positions, broken.positions, equal_nan=True)

    # rotations stay continuous across the gap ends: no step bigger than the motion's own
    arm.mocap_gapfill.showing = "RECOVERED"
    for bone, first, last in BONE_GAPS:
        j = after.points.index(bone)
        steps = _rotation_steps(after.extra["basis"][:, j])
        inside = steps[first - 2:last + 1]
        assert inside.max() < 4 * _rotation_steps(truth.extra["basis"][:, j]).max() + 0.02, bone

    # Revert Gap: a filled gap back to Blender's interpolation, the other gaps as filled
    items = list(arm.mocap_gapfill.gaps)
    i = next(k for k, g in enumerate(items) if g.how != KEPT)
    reverted = items[i]
    arm.mocap_gapfill.gap_index = i
    assert bpy.ops.mocap_gapfill.revert_gap() == {"FINISHED"}
    assert not reverted.filled and not reverted.how
    assert bpy.ops.mocap_gapfill.revert_gap.poll() is False  # nothing left to revert there
    back = bridge.read_take(arm, scene)
    assert arm.animation_data.action == arm.mocap_gapfill.recovered_action
    undone = np.zeros(back.positions.shape[:2], bool)  # the joints the reverted bone moves
    undone[reverted.first - broken.first:reverted.last - broken.first + 1,
           below[rig.names.index(reverted.point)]] = True
    assert np.abs(back.positions[undone] - broken.positions[undone]).max() * m < 1e-6
    assert np.abs(back.positions[~undone] - after.positions[~undone]).max() * m < 1e-6
    prefix = f'pose.bones["{reverted.point}"]'
    assert {(c.data_path, c.array_index): len(c.keyframe_points) for c in compat.fcurves(arm)
            if c.data_path.startswith(prefix)} == {
        key: n for key, n in keys_before.items() if key[0].startswith(prefix)}


def _rotation_steps(basis):
    r = basis[:, :3, :3]
    rel = np.einsum("fji,fjk->fik", r[:-1], r[1:])
    return np.arccos(np.clip((np.trace(rel, axis1=1, axis2=2) - 1) / 2, -1, 1))


def test_bezier_is_what_blender_draws_once_the_keys_are_bezier(daz_armature, data_dir):
    """The evaluation's ``bezier`` baseline is one click in the Graph Editor: keys deleted over
    gaps of 15-100 frames, the keys left switched to Bezier (Key > Interpolation Mode; the
    handles and smoothing as Blender gives new keys), Blender's curves across the gaps against
    ``fill_bones(method="bezier")`` on the file: within 0.01 mm (measured 0.0005 on 4.2, 5.0
    and 5.2)."""
    from mocap_gapfill.core.bonefill import fill_bones
    from mocap_gapfill.core.formats.bvh import read_bvh_rig

    bpy = pytest.importorskip("bpy")
    bridge, compat, _, _ = modules()
    arm, scene = daz_armature, bpy.context.scene
    bone_gaps = BONE_GAPS + (("rHand", 400, 414), ("lThigh", 500, 529))
    remove_bone_keys(arm, bone_gaps)
    linear = bridge.read_take(arm, scene)
    handles = set()
    for curve in compat.fcurves(arm):
        for key in curve.keyframe_points:
            key.interpolation = "BEZIER"
            handles.add((key.handle_left_type, key.handle_right_type))
        handles.add((curve.auto_smoothing,))
        curve.update()
    # the defaults of new keys and F-curves (4.2-5.2), which the BVH import keeps
    assert handles == {("AUTO_CLAMPED", "AUTO_CLAMPED"), ("CONT_ACCEL",)}, handles
    blender = bridge.read_take(arm, scene)
    rig, channels, location, fps = read_bvh_rig(data_dir / "cmu/bvh/daz_friendly/03/03_02.bvh.gz")
    mask = np.zeros(channels.shape[:2], dtype=bool)
    for bone, first, last in bone_gaps:
        mask[first - blender.first:last - blender.first + 1, rig.names.index(bone)] = True
    ours = rig.joints(fill_bones(rig, channels, location, mask, fps, method="bezier"))
    off_mm = np.abs(ours - blender.positions * blender.metres).max() * 1000
    moved_mm = np.abs(blender.positions - linear.positions).max() * blender.metres * 1000
    print(f"\nnumpy Bezier vs Blender's: max {off_mm:.5f} mm (the curves moved {moved_mm:.0f} mm "
          "from the linear ones)")
    assert off_mm < 0.01 and moved_mm > 10


def test_keys_written_from_true_joints_reproduce_them(daz_armature):
    """Write-back alone: targets = the true joints; Blender's FK of the written Euler keys must
    land on them within 1 mm (rotation orders, rest matrices and parents all used for real)."""
    bpy = pytest.importorskip("bpy")
    bridge, _, gaps, _ = modules()
    arm, scene = daz_armature, bpy.context.scene
    truth = bridge.read_take(arm, scene)
    remove_bone_keys(arm, BONE_GAPS)
    scene.mocap_gapfill.detect_suspects = False
    bpy.ops.mocap_gapfill.detect_gaps()
    broken = bridge.read_take(arm, scene)
    bone_gaps = gaps.gap_mask(arm.mocap_gapfill.gaps, broken.points, broken.first,
                              broken.positions.shape[0])
    basis, _ = bridge.solve_armature(broken, truth.positions * truth.metres, bone_gaps)
    assert bridge.write_armature(broken, basis, bone_gaps) == int(bone_gaps.sum())
    modes = {b.rotation_mode for b in arm.pose.bones}
    assert modes - {"QUATERNION", "AXIS_ANGLE"}, modes  # Euler orders from the BVH
    after = bridge.read_take(arm, scene)
    error_mm = np.abs(after.positions - truth.positions).max() * truth.metres * 1000
    print(f"\nFK of written keys vs true joints: max {error_mm:.4f} mm")
    assert error_mm < 1.0


def test_suspect_keys_are_flagged(daz_armature):
    bpy = pytest.importorskip("bpy")
    arm, scene = daz_armature, bpy.context.scene
    pbone = arm.pose.bones["lForeArm"]
    scene.frame_set(250)
    pbone.rotation_euler.x += 1.5  # a flipped joint on one frame
    pbone.keyframe_insert("rotation_euler", frame=250)
    scene.mocap_gapfill.detect_suspects = True
    bpy.ops.mocap_gapfill.detect_gaps()
    suspects = [(g.point, g.first, g.last) for g in arm.mocap_gapfill.gaps if g.kind == "SUSPECT"]
    assert any(p == "lForeArm" and a <= 250 <= b and b - a < 6 for p, a, b in suspects), suspects


def test_errors_are_reported_and_change_nothing(daz_armature, marker_kb):
    bpy = pytest.importorskip("bpy")
    arm, scene = daz_armature, bpy.context.scene
    remove_bone_keys(arm, BONE_GAPS)
    bpy.ops.mocap_gapfill.detect_gaps()
    action = arm.animation_data.action
    scene.mocap_gapfill.kb_path = str(marker_kb)  # markers: the wrong knowledge base
    with pytest.raises(RuntimeError, match="does not match this motion"):
        bpy.ops.mocap_gapfill.fill_gaps()
    assert arm.animation_data.action == action and arm.mocap_gapfill.recovered_action is None
    assert not any(g.filled for g in arm.mocap_gapfill.gaps)


def test_starter_knowledge_base_when_none_is_chosen(daz_armature):
    """No knowledge base chosen: the Daz take gets the shipped CMU Daz starter KB and is filled
    (the original action kept)."""
    bpy = pytest.importorskip("bpy")
    arm, scene = daz_armature, bpy.context.scene
    remove_bone_keys(arm, BONE_GAPS)
    bpy.ops.mocap_gapfill.detect_gaps()
    action = arm.animation_data.action
    scene.mocap_gapfill.kb_path = ""
    assert bpy.ops.mocap_gapfill.fill_gaps() == {"FINISHED"}
    assert arm.mocap_gapfill.original_action == action
    assert arm.mocap_gapfill.recovered_action is not None
    assert all(g.filled for g in arm.mocap_gapfill.gaps)


def test_a_rig_no_knowledge_base_knows_fills_from_the_take_alone(scene, data_dir, tmp_path):
    """A rig of a studio's own bone names (03_02 with every joint renamed), no knowledge base
    chosen: no starter one fits, so `auto` fills the rotation gaps from the take alone (its own
    regression, a cubic and Blender's interpolation, judged on copies of the gaps) and says so;
    before, the fill stopped. Per gap never worse than Blender's interpolation by more than
    10 % + 2 mm (measured: chest 7.4 vs 7.4 mm, lForeArm 139.7 vs 130.0, rShin 65.9 vs 83.8;
    with the knowledge base 7.4 / 120.5 / 61.9), over the three gaps within 5 % of it
    (measured 0.4 % worse: the forearm's long gap weighs most); keyed channels and the other
    bones untouched."""
    import re

    bpy = pytest.importorskip("bpy")
    bridge, _, gaps, _ = modules()
    text = gzip.decompress((data_dir / "cmu/bvh/daz_friendly/03/03_02.bvh.gz").read_bytes())
    bvh = tmp_path / "studio_rig.bvh"
    bvh.write_text(re.sub(r"\b(ROOT|JOINT) (\w+)", r"\1 rig_\2", text.decode()))
    bpy.ops.import_anim.bvh(filepath=str(bvh), update_scene_fps=True,
                            update_scene_duration=True)
    arm = bpy.context.active_object
    truth = bridge.read_take(arm, scene)
    studio_gaps = [(f"rig_{bone}", first, last) for bone, first, last in BONE_GAPS]
    remove_bone_keys(arm, studio_gaps)
    scene.mocap_gapfill.detect_suspects = False
    assert bpy.ops.mocap_gapfill.detect_gaps() == {"FINISHED"}
    broken = bridge.read_take(arm, scene)
    scene.mocap_gapfill.kb_path = ""
    plans, _ = gaps.plan_fill(bpy.context, [arm])
    assert plans[0].kb is None
    (said,) = plans[0].messages
    assert said.startswith("no starter knowledge base fits this take") and said.endswith(
        "until then, auto fills from the take alone (its own regression, a cubic and Blender's "
        "interpolation, judged on copies of the gaps)")
    assert bpy.ops.mocap_gapfill.fill_gaps() == {"FINISHED"}
    after = bridge.read_take(arm, scene)
    errors = gap_errors(arm, broken, after, truth)
    for gap, fill_mm, interp_mm in errors:
        assert gap.filled and gap.how
        print(f"{gap.point}: {'; '.join(gaps.describe(gap, True))}: {fill_mm:.1f} mm, "
              f"Blender's interpolation {interp_mm:.1f} mm")
        assert fill_mm <= 1.1 * interp_mm + 2.0
    assert total_mm(errors, 1) < 1.05 * total_mm(errors, 2)
    unmoved = ~bridge.missing_points(broken, gaps.gap_mask(
        arm.mocap_gapfill.gaps, broken.points, broken.first, broken.positions.shape[0]))
    assert np.abs(after.positions[unmoved] - truth.positions[unmoved]).max() * truth.metres < 1e-4


def gap_errors(arm, broken, after, truth):
    """``(gap, fill mm, Blender's interpolation mm)`` per listed gap of an armature: the RMSE
    over its frames of the joints its bone moves, against the untouched take."""
    bridge, _, gaps, _ = modules()
    out = []
    for gap in arm.mocap_gapfill.gaps:
        rows = slice(gap.first - broken.first, gap.last - broken.first + 1)
        joints = bridge.missing_points(broken, gaps.gap_mask(
            [gap], broken.points, broken.first, broken.positions.shape[0]))[rows].any(axis=0)
        out.append((gap, *(rmse_mm(x.positions[rows][:, joints] * truth.metres,
                                   truth.positions[rows][:, joints] * truth.metres)
                           for x in (after, broken))))
    return out


def total_mm(errors, column):
    """The RMSE of ``gap_errors``' fill (column 1) or interpolation (2) over all their frames."""
    frames = [gap.last - gap.first + 1 for gap, *_ in errors]
    return float(np.sqrt(np.average([e[column] ** 2 for e in errors], weights=frames)))


def test_scene_fps_reads_a_bvh_rate_as_the_command_line_does(scene):
    """Blender's BVH importer sets 120.000048 fps from a frame time of 0.00833333; the command
    line reads 120, and so must the fill in Blender (a 90-frame gap is 0.75 s in both)."""
    bridge = modules()[0]
    scene.render.fps, scene.render.fps_base = 120, 120 / 120.000048
    assert bridge.scene_fps(scene) == 120.0
    scene.render.fps, scene.render.fps_base = 30, 1.001  # NTSC stays NTSC
    assert bridge.scene_fps(scene) == pytest.approx(30 / 1.001, rel=1e-6)  # float32 base


def test_mark_gap_over_preview_range(daz_armature):
    bpy = pytest.importorskip("bpy")
    _, compat, _, _ = modules()
    arm, scene = daz_armature, bpy.context.scene
    compat.select_bones(arm, ["rHand", "lShin"])
    scene.use_preview_range = True
    scene.frame_preview_start, scene.frame_preview_end = 40, 80
    assert bpy.ops.mocap_gapfill.mark_gap() == {"FINISHED"}
    marked = sorted((g.point, g.first, g.last, g.kind) for g in arm.mocap_gapfill.gaps)
    assert marked == [("lShin", 40, 80, "MARKED"), ("rHand", 40, 80, "MARKED")]
    bpy.ops.mocap_gapfill.detect_gaps()  # detection keeps hand-marked gaps
    assert sum(g.kind == "MARKED" for g in arm.mocap_gapfill.gaps) == 2


def _sha(path):
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_batch_command_writes_a_new_filled_file(daz_armature, daz_kb, tmp_path):
    bpy = pytest.importorskip("bpy")
    import importlib

    batch = importlib.import_module(f"{LOCAL_MODULE}.addon.batch")
    arm = daz_armature
    remove_bone_keys(arm, BONE_GAPS)
    source = tmp_path / "take.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(source))
    before = _sha(source)
    assert batch.cli_command(["--kb", str(daz_kb), "--no-suspects"]) == 0
    out = tmp_path / "take_filled.blend"
    assert out.is_file() and _sha(source) == before
    assert batch.cli_command(["--kb", str(daz_kb)]) == 1  # the output exists: not replaced

    # blender -c mocap_gapfill batch: the command line's batch over a folder holding the scene
    library = tmp_path / "library"
    library.mkdir()
    shutil.copy(source, library / "take.blend")
    assert batch.cli_command(["batch", str(library), "-o", str(tmp_path / "cleaned"), "--kb",
                              str(daz_kb), "--jobs", "1", "--quiet"]) == 0
    assert (tmp_path / "cleaned" / "take.blend").is_file() and _sha(source) == before
    assert "1 filled, 0 up to date, 0 failed" in (tmp_path / "cleaned" / "report.json").read_text()

    # the same through the command line and the bpy module, in a fresh process
    out2 = tmp_path / "via_cli.blend"
    r = subprocess.run([sys.executable, "-m", "mocap_gapfill", "blend", str(source), "--kb",
                        str(daz_kb), "--no-suspects", "-o", str(out2)], capture_output=True,
                       text=True, timeout=600)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "filled" in r.stdout and _sha(source) == before
    # the log says per gap how it was filled
    for bone, first, last in BONE_GAPS:
        assert f": {bone} {first}-{last}: " in r.stdout, r.stdout

    for path in (out, out2):
        bpy.ops.wm.open_mainfile(filepath=str(path))
        arm = bpy.data.objects[daz_armature_name(path)]
        recovered = arm.mocap_gapfill.recovered_action
        assert recovered is not None and arm.animation_data.action == recovered
        assert {g.point for g in arm.mocap_gapfill.gaps if g.filled} == {b for b, _, _ in
                                                                         BONE_GAPS}
        assert all(g.how for g in arm.mocap_gapfill.gaps)  # saved with the file
        for curve in modules()[1].fcurves(arm):
            frames, _ = modules()[0].curve_keys(curve)
            types = np.empty(len(frames), dtype=np.int32)
            curve.keyframe_points.foreach_get("type", types)
            # filled keys only on the gap frames of the gapped bones; the rest as it was
            bone = curve.data_path.split('"')[1]
            span = [(a, b) for n, a, b in BONE_GAPS if n == bone]
            assert all(any(a <= f <= b for a, b in span) for f in frames[types == GEN])
            assert not any(a <= f <= b for a, b in span for f in frames[types != GEN])


def daz_armature_name(path):
    import bpy

    return next(o.name for o in bpy.data.objects if o.type == "ARMATURE")


def test_asf_amc_import_follows_the_joints(scene, data_dir):
    """Our ASF/AMC import: an armature whose bone heads are the file's joints (Blender's own
    evaluation), rest pose = the ASF's zero pose, rotations keyed per frame."""
    from mocap_gapfill.core.io import read_motion

    bpy = pytest.importorskip("bpy")
    bridge, _, _, _ = modules()
    amc = data_dir / "cmu/asfamc/01/01_01.amc"
    assert bpy.ops.mocap_gapfill.import_skeleton(filepath=str(amc)) == {"FINISHED"}
    arm = bpy.context.active_object
    assert arm.type == "ARMATURE" and len(arm.pose.bones) == 31
    assert len(arm.mocap_gapfill.gaps) == 0  # complete take, nothing flagged
    take = bridge.read_take(arm, scene)
    truth = read_motion(amc).select(list(take.points))
    assert take.positions.shape == truth.positions.shape  # 2,751 frames
    error_mm = np.abs(take.positions - truth.positions).max() * 1000
    print(f"\n01_01.amc imported: bone heads vs ASF/AMC joints max {error_mm:.3f} mm")
    assert error_mm < 1.0


def test_amc_armature_fill_uses_a_rotation_kb_of_other_subjects(scene, data_dir, tmp_path):
    """An AMC walk imported by the add-on, three bones' keys deleted over 1 s each, filled with
    a KB built from the other subjects' AMC takes: the armature Blender holds has the rotations
    the KB has (same rest pose rule), so the default fill matches motion, and beats Blender's
    own interpolation."""
    from mocap_gapfill.core.kb import build_kb

    bpy = pytest.importorskip("bpy")
    bridge, _, gaps, _ = modules()
    kb = build_kb([data_dir / "cmu/asfamc"], fps=60, stride=2,
                  exclude=["*/07/*", "*02_01.amc"])
    kb.save(tmp_path / "amc_kb.npz")
    amc = data_dir / "cmu/asfamc/07/07_05.amc"
    assert bpy.ops.mocap_gapfill.import_skeleton(filepath=str(amc)) == {"FINISHED"}
    arm = bpy.context.active_object
    truth = bridge.read_take(arm, scene)
    cut = (("lfemur", 31, 150), ("rtibia", 191, 310), ("lhumerus", 351, 470))
    remove_bone_keys(arm, cut)
    scene.mocap_gapfill.detect_suspects = False
    assert bpy.ops.mocap_gapfill.detect_gaps() == {"FINISHED"}
    broken = bridge.read_take(arm, scene)
    scene.mocap_gapfill.kb_path = str(tmp_path / "amc_kb.npz")
    assert bpy.ops.mocap_gapfill.fill_gaps() == {"FINISHED"}
    after = bridge.read_take(arm, scene)
    moved = bridge.missing_points(broken, gaps.gap_mask(arm.mocap_gapfill.gaps, broken.points,
                                                          broken.first, len(broken.positions)))
    fill_mm, interp_mm = (rmse_mm(x.positions[moved], truth.positions[moved])
                          for x in (after, broken))
    print(f"\n07_05.amc in Blender, three 1 s gaps: fill {fill_mm:.1f} mm, Blender's "
          f"interpolation {interp_mm:.1f} mm")
    assert fill_mm < 0.8 * interp_mm  # the numpy twin of this fill: 0.68


def test_kb_built_from_a_take_and_a_cancelled_fill_changes_nothing(scene):
    """Build a KB from the selected take (operator, saved in the user folder), then a fill whose
    work is cancelled: nothing written."""
    bpy = pytest.importorskip("bpy")
    bridge, compat, gaps, _ = modules()
    import importlib

    synth = importlib.import_module(f"{LOCAL_MODULE}.core.synth")
    skeleton, _ = synth.take(synth.KB_GAITS[2], frames=240)
    arm = bridge.import_armature(bpy.context, skeleton, "Jogger")
    compat.select_objects(bpy.context, [arm], active=arm)
    assert bpy.ops.mocap_gapfill.build_kb(source="TAKE", name="jog") == {"FINISHED"}
    path = scene.mocap_gapfill.kb_path
    assert path.endswith("knowledge_bases/jog.npz") and "extensions" in path
    kb = gaps.load_kb_cached(path)
    assert kb.size == 240 and set(kb.names) == set(skeleton.names)
    assert kb.turns is not None and "LeftForeArm" in kb.bones  # the rotation fill can use it

    remove_bone_keys(arm, [("LeftForeArm", 50, 120)])
    bpy.ops.mocap_gapfill.detect_gaps()
    action = arm.animation_data.action
    plans, work = gaps.plan_fill(bpy.context, [arm], kb=kb)
    with pytest.raises(KeyboardInterrupt):
        work(lambda fraction, message: None, lambda: True)
    assert arm.animation_data.action == action and arm.mocap_gapfill.recovered_action is None
    assert not any(g.filled for g in arm.mocap_gapfill.gaps)


def test_max_gap_leaves_long_gaps_alone(daz_armature, daz_kb):
    bpy = pytest.importorskip("bpy")
    arm, scene = daz_armature, bpy.context.scene
    remove_bone_keys(arm, BONE_GAPS)  # 100, 90 and 60 frames
    scene.mocap_gapfill.detect_suspects = False
    bpy.ops.mocap_gapfill.detect_gaps()
    scene.mocap_gapfill.kb_path = str(daz_kb)
    scene.mocap_gapfill.max_gap = 80
    assert bpy.ops.mocap_gapfill.fill_gaps() == {"FINISHED"}
    filled = {g.point for g in arm.mocap_gapfill.gaps if g.filled}
    assert filled == {"chest"}


def test_a_job_runs_with_at_most_four_blas_threads(extension, monkeypatch):
    """Blender loads numpy before the add-on, with a BLAS thread per core: the job limits them
    for its own time (threadpoolctl, bundled), unless the user set theirs."""
    import importlib
    import os

    from threadpoolctl import threadpool_info

    root = importlib.import_module(LOCAL_MODULE)
    jobs = importlib.import_module(f"{root.__name__}.addon.jobs")

    def blas(progress=None, cancelled=None):
        return {pool["num_threads"] for pool in threadpool_info() if pool["user_api"] == "blas"}

    before = blas()
    for name in root.THREAD_VARIABLES:
        monkeypatch.delenv(name, raising=False)
    monkeypatch.setattr(os, "cpu_count", lambda: 16)
    job = jobs.Job(blas)
    job.run()
    assert job.result == {4} and blas() == before  # the user's threads back after the job
    monkeypatch.setattr(os, "cpu_count", lambda: 3)
    job.run()
    assert job.result == {3}
    monkeypatch.setenv("OPENBLAS_NUM_THREADS", "1")  # the user's setting stands
    job.run()
    assert job.result == before
