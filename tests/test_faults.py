"""Label swaps, spikes and ghosts found and repaired before the fill (core/faults.py), the
``check`` command, ``fill``'s repair and takes of several performers, on real CMU takes."""

import json

import numpy as np
import pytest

from mocap_gapfill.core import faulteval
from mocap_gapfill.core.cli import main
from mocap_gapfill.core.evaluate import punch_gaps, rmse_mm, with_gaps
from mocap_gapfill.core.faults import FITTED, FaultConfig, find_faults, repaired
from mocap_gapfill.core.fill import fill, kb_for_take
from mocap_gapfill.core.io import read_motion, write_motion
from mocap_gapfill.core.performers import performers


@pytest.fixture(scope="module")
def walk(data_dir):
    """CMU 06_01 (a walk, 494 frames, 41 markers, no gaps)."""
    return read_motion(data_dir / "cmu/c3d/06_01.c3d")


def _swapped(motion, a, b, first, last):
    pos = motion.positions.copy()
    i, j = motion.names.index(a), motion.names.index(b)
    pos[first:last + 1, [i, j]] = pos[first:last + 1, [j, i]]
    return motion.replace(positions=pos)


def test_a_real_take_as_it_is_has_no_problems(walk):
    assert find_faults(walk).faults == []


def test_a_swap_is_found_and_exchanged_back(walk):
    faulted = _swapped(walk, "LFHD", "RWRA", 200, 259)  # head and wrist, half a second
    repair = find_faults(faulted)
    assert [(f.kind, set(f.points), f.first, f.last) for f in repair.faults] == [
        ("swap", {"LFHD", "RWRA"}, 200, 259)]
    np.testing.assert_array_equal(repair.positions, walk.positions)


def test_a_spike_is_cut_and_filled_back_near_the_truth(walk):
    pos = walk.positions.copy()
    p = walk.names.index("LKNE")
    pos[300:304, p] += [0.0, 0.04, 0.0]  # 4 frames, 40 mm
    faulted = walk.replace(positions=pos)
    motion, found = repaired(faulted)
    assert [(f.kind, f.points, f.first, f.last) for f in found] == [("spike", ("LKNE",), 300, 303)]
    assert motion.missing[300:304, p].all() and motion.missing.sum() == 4
    out = fill(motion, "auto")
    mask = np.zeros(walk.missing.shape, bool)
    mask[300:304, p] = True
    assert rmse_mm(out, walk, mask) < 0.2 * rmse_mm(faulted, walk, mask)


def test_a_ghost_take_over_is_cut(walk):
    pos = walk.positions.copy()
    p, q = walk.names.index("RTHI"), walk.names.index("RKNE")
    pos[120:240, p] = pos[120:240, q]  # the thigh's label on the knee for a second
    found = find_faults(walk.replace(positions=pos)).faults
    assert [(f.kind, f.points) for f in found] == [("ghost", ("RTHI",))]
    assert abs(found[0].first - 120) <= 1 and abs(found[0].last - 239) <= 2


def test_the_protocol_finds_what_it_injects(walk):
    for kind in faulteval.KINDS:
        faulted, truths, repair, (found, barred, right, reported) = faulteval.run_take(
            walk, kind, 0)
        assert barred >= 1 and found == barred and right == reported, kind


def test_the_shipped_thresholds_are_fitted_by_the_tool(repo_root=None):
    fitted = json.loads(FITTED.read_text())
    config = FaultConfig.fitted()
    assert {k: getattr(config, k) for k in fitted["chosen"]} == fitted["chosen"]
    assert set(fitted["left_out"]) == {"01_01", "02_05", "06_01", "135_02"}  # no test take
    for key, value in fitted["chosen"].items():
        assert value in fitted["grid"][key]


def test_check_lists_the_problems_as_json(walk, tmp_path, capsys):
    src = tmp_path / "swapped.c3d"
    write_motion(_swapped(walk, "LFHD", "RWRA", 200, 259), src)
    out = tmp_path / "events.json"
    assert main(["check", str(src), "--json", str(out)]) == 0
    said = capsys.readouterr().out
    assert "1 problem found" in said and "swap" in said
    assert json.loads(out.read_text()) == {
        "events": [{"kind": "swap", "points": ["LFHD", "RWRA"], "first": 200, "last": 259}]}


def test_fill_repairs_first_unless_told_not_to(walk, tmp_path, capsys):
    src = tmp_path / "swapped.c3d"
    faulted = _swapped(walk, "LFHD", "RWRA", 200, 259)
    write_motion(faulted, src)
    assert main(["fill", str(src), "-o", str(tmp_path / "out.c3d"), "--method", "linear"]) == 0
    said = capsys.readouterr().out
    assert "repaired 1 problem" in said and "labels exchanged back" in said
    out = read_motion(tmp_path / "out.c3d")
    assert np.abs(out.positions - walk.positions).max() < 1e-4  # C3D float32 millimetres
    assert out.filled[200:260, [walk.names.index("LFHD"), walk.names.index("RWRA")]].all()
    assert main(["fill", str(src), "-o", str(tmp_path / "kept.c3d"), "--method", "linear",
                 "--no-repair"]) == 0
    assert "repaired" not in capsys.readouterr().out
    kept = read_motion(tmp_path / "kept.c3d")
    assert np.abs(kept.positions - faulted.positions).max() < 1e-4


def test_two_performers_are_filled_each_with_the_knowledge_base(data_dir, tmp_path, capsys):
    a = read_motion(data_dir / "cmu/c3d/85_02.c3d").frame_range(0, 480)
    b = read_motion(data_dir / "cmu/c3d/06_01.c3d").frame_range(0, 480)
    b = b.replace(positions=b.positions + [3.0, 0.0, 0.0])  # beside the first
    names = tuple(f"A:{n}" for n in a.names) + tuple(f"B:{n}" for n in b.names)
    both = a.replace(positions=np.concatenate([a.positions, b.positions], axis=1), names=names,
                     limbs=np.zeros((0, 2), int), filled=None)
    write_motion(both, tmp_path / "two.c3d")
    both = read_motion(tmp_path / "two.c3d")
    assert both.names == names and list(performers(names)) == ["A", "B"]
    assert main(["info", str(tmp_path / "two.c3d")]) == 0
    assert "2 performers" in capsys.readouterr().out
    kb, note = kb_for_take(both.names, "auto")
    assert kb is not None and "starter" in note
    miss = punch_gaps(480, both.n_points, "markers", 0.2, np.random.default_rng(0))
    together = fill(with_gaps(both, miss), "auto", kb=kb)
    for part, cols in ((a, slice(0, 41)), (b, slice(41, 82))):
        alone = fill(with_gaps(part, miss[:, cols]), "auto", kb=kb)
        mine = together.select(list(names[cols])).replace(names=part.names)
        assert rmse_mm(mine, part, miss[:, cols]) <= 1.1 * rmse_mm(alone, part, miss[:, cols])
        assert rmse_mm(alone, part, miss[:, cols]) < 60  # filled from the knowledge base


def test_batch_repairs_first_and_reports_it(walk, tmp_path):
    from mocap_gapfill.core.batch import Options, run_batch

    (tmp_path / "in").mkdir()
    write_motion(_swapped(walk, "LFHD", "RWRA", 200, 259), tmp_path / "in/swapped.c3d")
    for repair, out in ((True, "out"), (False, "kept")):
        rows = run_batch([tmp_path / "in"], tmp_path / out, Options(method="linear",
                                                                   repair=repair), jobs=1)
        assert [r["status"] for r in rows] == ["filled"]
        assert rows[0]["repaired"] == ("swap LFHD / RWRA 201-260" if repair else "")
        done = read_motion(rows[0]["output"])
        assert (np.abs(done.positions - walk.positions).max() < 1e-4) == repair
