"""Label problems in the add-on (bpy 4.2 LTS and 5.x): a C3D with a swap and a spike (CMU 06_01,
a walk, made faulty), detected as such in the gap list, mended by Repair, then filled."""

import numpy as np
import pytest

from test_workflow import GEN, modules, rmse_mm

SWAP = ("LFHD", "RWRA", 200, 259)  # rows of the take: frames 201-260
SPIKE = ("LKNE", 300, 303, 0.04)


@pytest.fixture
def faulty(scene, data_dir, tmp_path):
    """The faulty take imported as a marker set: (root, the truth, the faulty motion)."""
    from mocap_gapfill.core.io import read_motion, write_motion

    bpy = pytest.importorskip("bpy")
    truth = read_motion(data_dir / "cmu/c3d/06_01.c3d")
    pos = truth.positions.copy()
    a, b, first, last = SWAP
    i, j = truth.names.index(a), truth.names.index(b)
    pos[first:last + 1, [i, j]] = pos[first:last + 1, [j, i]]
    name, s0, s1, size = SPIKE
    pos[s0:s1 + 1, truth.names.index(name), 1] += size
    faulty = truth.replace(positions=pos)
    write_motion(faulty, tmp_path / "faulty.c3d")
    assert bpy.ops.mocap_gapfill.import_markers(filepath=str(tmp_path / "faulty.c3d")) == {
        "FINISHED"}
    return bpy.context.active_object, truth, faulty


def test_a_swap_and_a_spike_are_listed_repaired_and_filled(faulty):
    import bpy

    bridge, compat, gaps, _ = modules()
    root, truth, faulty = faulty
    assert bpy.ops.mocap_gapfill.detect_gaps() == {"FINISHED"}
    listed = sorted((g.kind, g.point, g.other, g.first, g.last) for g in root.mocap_gapfill.gaps)
    problems = [g for g in listed if g[0] in gaps.REPAIRED]
    assert problems == [("SPIKE", "LKNE", "", 301, 304), ("SWAP", "LFHD", "RWRA", 201, 260)]
    # the take's own jumps stay suspects; none of them is one of the problems again
    assert all(g[0] == "SUSPECT" and g[1] not in ("LKNE", "LFHD", "RWRA")
               for g in listed if g not in problems)
    swap = next(g for g in root.mocap_gapfill.gaps if g.kind == "SWAP")
    assert gaps.describe(swap, False) == ["the two markers' labels are exchanged here:",
                                          "Repair swaps their keys back"]
    assert "REGISTER" in bpy.types.MOCAP_GAPFILL_OT_repair.bl_options
    assert "UNDO" in bpy.types.MOCAP_GAPFILL_OT_repair.bl_options  # one Ctrl-Z undoes it

    assert bpy.ops.mocap_gapfill.repair(scope="ALL") == {"FINISHED"}
    assert all(g.repaired for g in root.mocap_gapfill.gaps if g.kind in gaps.REPAIRED)
    assert not bpy.ops.mocap_gapfill.repair.poll()  # nothing left to repair
    take = bridge.read_take(root, bpy.context.scene)
    m = take.metres
    truth, faulty = (t.select(list(take.names)) for t in (truth, faulty))  # the take's order
    knee = take.points.index("LKNE")
    cut = np.isnan(take.positions[..., 0])
    assert cut[300:304, knee].all() and cut.sum() == 4  # the spike cut for Fill
    suspects = gaps.gap_mask([g for g in root.mocap_gapfill.gaps if g.kind == "SUSPECT"],
                             take.points, take.first, len(cut))
    seen = ~cut & ~suspects
    assert np.abs(take.positions[seen] * m - truth.positions[seen]).max() < 1e-5  # swap mended
    head = bpy.data.objects["LFHD"]
    curve = compat.fcurves(head).find("location", index=0)
    types = np.empty(len(curve.keyframe_points), dtype=np.int32)
    curve.keyframe_points.foreach_get("type", types)
    assert set(bridge.curve_keys(curve)[0][types == GEN].astype(int)) == set(range(201, 261))
    gap = next(g for g in root.mocap_gapfill.gaps if g.kind == "SWAP")
    assert gaps.describe(gap, False) == ["labels exchanged back"]

    root.mocap_gapfill.showing = "ORIGINAL"  # the original keeps the faulty keys
    original = bridge.read_take(root, bpy.context.scene)
    assert np.abs(original.positions * m - faulty.positions).max() < 1e-5

    assert bpy.ops.mocap_gapfill.fill_gaps(scope="ALL") == {"FINISHED"}
    filled = bridge.read_take(root, bpy.context.scene)
    assert not np.isnan(filled.positions).any()
    rows = slice(300, 304)
    assert (rmse_mm(filled.positions[rows, knee] * m, truth.positions[rows, knee])
            < 0.2 * rmse_mm(faulty.positions[rows, knee], truth.positions[rows, knee]))
    assert np.abs(filled.positions[seen] * m - truth.positions[seen]).max() < 1e-5


def test_a_blend_run_repairs_first(faulty, tmp_path):
    """``blend`` / ``blender -b -c mocap_gapfill`` repairs the label problems before it fills."""
    import argparse
    import importlib

    import bpy

    from test_workflow import LOCAL_MODULE

    batch = importlib.import_module(f"{LOCAL_MODULE}.addon.batch")
    commands = importlib.import_module(f"{LOCAL_MODULE}.addon.commands")
    bridge, _, _, _ = modules()
    root, truth, _ = faulty
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "faulty.blend"))
    parser = argparse.ArgumentParser()
    commands.add_arguments(parser)
    said = []
    batch.run(parser.parse_args(["--method", "linear"]), report=said.append)
    assert f"{root.name}: repaired 2 label swaps, spikes or ghosts first" in said
    take = bridge.read_take(root, bpy.context.scene)
    truth = truth.select(list(take.names))
    swap = np.zeros(take.keyed.shape, bool)
    swap[200:260, [take.points.index("LFHD"), take.points.index("RWRA")]] = True
    assert np.abs(take.positions[swap] * take.metres - truth.positions[swap]).max() < 1e-5


def test_the_search_runs_as_a_cancellable_job(faulty):
    """Detect Gaps looks for problems on plain arrays, as a job (a thread with progress in the
    UI): cancelled, it leaves the gap list as it was."""
    import importlib

    import bpy

    from test_workflow import LOCAL_MODULE

    _, _, gaps, _ = modules()
    jobs = importlib.import_module(f"{LOCAL_MODULE}.addon.jobs")
    root, _, _ = faulty
    assert issubclass(bpy.types.MOCAP_GAPFILL_OT_detect_gaps, jobs.JobOperator)
    before = [(g.kind, g.point, g.first, g.last) for g in root.mocap_gapfill.gaps]
    take, work = gaps.plan_detect(root, bpy.context.scene)
    told = []
    with pytest.raises(KeyboardInterrupt):
        work(lambda fraction, message: told.append(message), lambda: True)
    assert told == ["looking for keys that jump", "looking for label swaps, spikes and ghosts"]
    assert [(g.kind, g.point, g.first, g.last) for g in root.mocap_gapfill.gaps] == before
    found = work(lambda fraction, message: None, lambda: False)
    gaps.write_detected(root, take, found)
    assert sorted(g.kind for g in root.mocap_gapfill.gaps if g.kind in gaps.REPAIRED) == [
        "SPIKE", "SWAP"]
