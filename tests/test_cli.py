"""The mocap-gapfill command line, run as a user would (python -m mocap_gapfill)."""

import json
import re
import subprocess
import sys

import numpy as np

from mocap_gapfill.core.io import read_motion, write_motion
from mocap_gapfill.core.kb import load_kb


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


def test_kb_build_then_fill(data_dir, tmp_path):
    kb = tmp_path / "kb.npz"
    r = cli("kb", "build", data_dir / "cmu/c3d/85_02.c3d", data_dir / "cmu/c3d/135_02.c3d",
            "-o", kb, "--quiet")
    assert r.returncode == 0, r.stderr
    assert "6012 poses of 41 points at 120 fps from 2 files" in r.stdout
    r = cli("kb", "build", data_dir / "cmu/c3d/85_02.c3d", "-o", kb, "--quiet")
    assert r.returncode == 2 and "exists" in r.stderr  # never replaced silently
    src = data_dir / "cmu/c3d/01_01.c3d"
    out = tmp_path / "filled.c3d"
    r = cli("fill", src, "-k", kb, "-o", out, "--quiet")
    assert r.returncode == 0, r.stderr
    assert "filled 30 samples with auto" in r.stdout
    assert "RBAC-1" in r.stderr  # the extra marker the KB does not know is reported
    before, after = read_motion(src), read_motion(out)
    assert after.missing.sum() == before.missing.sum() - 30
    observed = ~before.missing
    np.testing.assert_allclose(after.positions[observed], before.positions[observed], atol=1e-6)
    # --max-gap leaves longer gaps alone: RBAC's gap is 30 frames
    r = cli("fill", src, "-k", kb, "-o", tmp_path / "short.npz", "--max-gap", "20", "--quiet")
    assert r.returncode == 0 and "filled 0 samples" in r.stdout
    # no -k: the starter knowledge base of the marker set; none for a skeleton it does not know
    r = cli("fill", src, "-o", tmp_path / "x.npz", "--method", "pca", "--quiet")
    assert r.returncode == 0 and "starter knowledge base cmu_markers41_kb.npz" in r.stderr
    r = cli("fill", data_dir / "cmu/asfamc/01/01_01.amc", "-o", tmp_path / "y.npz")
    assert r.returncode == 0 and "starter knowledge base cmu_asf31_kb.npz" in r.stderr
    # a marker set no starter knowledge base knows: knn cannot fill it; auto fills from the take
    unknown = read_motion(data_dir / "cmu/c3d/85_02.c3d").frame_range(0, 200)
    positions = unknown.positions.copy()
    positions[50:80, 5] = positions[100:110, 12] = np.nan
    unknown = unknown.replace(names=tuple(f"P{i}" for i in range(unknown.n_points)),
                              positions=positions)
    write_motion(unknown, tmp_path / "unknown.npz")
    r = cli("fill", tmp_path / "unknown.npz", "-o", tmp_path / "z.npz", "--method", "knn")
    assert r.returncode == 2 and "needs a knowledge base" in r.stderr
    assert "no starter knowledge base fits this take" in r.stderr and "P0" in r.stderr
    r = cli("fill", tmp_path / "unknown.npz", "-o", tmp_path / "z.npz")
    assert r.returncode == 0 and "filled 40 samples with auto" in r.stdout, r.stderr
    assert "until then, auto fills from the take alone" in r.stderr
    assert "no knowledge base: filled from the take alone: P5, P12" in r.stderr


def test_fill_reports_each_gap_worst_first(data_dir, tmp_path):
    """``--gap-report``: per gap auto filled, the estimates' shares and what copies of it expect
    of the error, the largest first (CSV or JSON); the worst three on the command line too."""
    import csv

    from mocap_gapfill.core.evaluate import punch_gaps, with_gaps
    from mocap_gapfill.core.motion import gap_runs

    take = read_motion(data_dir / "cmu/c3d/85_02.c3d")
    miss = punch_gaps(take.n_frames, take.n_points, "markers", 0.1, np.random.default_rng(0))
    src = tmp_path / "gapped.c3d"
    write_motion(with_gaps(take, miss).replace(filled=None), src)
    r = cli("fill", src, "-o", tmp_path / "out.c3d", "--gap-report", tmp_path / "gaps.csv",
            "--quiet")
    assert r.returncode == 0, r.stderr
    with open(tmp_path / "gaps.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == len(gap_runs(miss)) == 50
    expected = [float(row["expected_mm"]) for row in rows]
    assert expected == sorted(expected, reverse=True) and expected[-1] > 0
    for row in rows:
        shares = [float(row[k]) for k in ("rigid", "models", "windows", "own", "spline", "pattern")]
        first, last = int(row["first_frame"]), int(row["last_frame"])
        assert abs(sum(shares) - 1) < 1e-3 and int(row["frames"]) == last - first + 1
        assert miss[first - 1:last, take.names.index(row["point"])].all()
    worst = f"{rows[0]['point']} frames {rows[0]['first_frame']}-{rows[0]['last_frame']}: "
    assert f"  {worst}{rows[0]['filled_from']}; expected error ~" in r.stdout
    assert all(row["filled_from"] for row in rows)
    # in plain words: no stage or generator named by its internal name, unless asked for
    assert not internal_names(r.stdout + r.stderr + "".join(row["filled_from"] for row in rows))
    r = cli("fill", src, "-o", tmp_path / "verbose.c3d", "--verbose", "--quiet")
    assert r.returncode == 0 and "auto: rigid partners carry" in r.stderr
    r = cli("fill", src, "-o", tmp_path / "out2.c3d", "--gap-report", tmp_path / "gaps.json",
            "--max-gap", "30", "--quiet")
    short = json.loads((tmp_path / "gaps.json").read_text())  # only the gaps it filled
    assert r.returncode == 0 and len(short) == sum(b - a < 30 for _, a, b in gap_runs(miss)) == 4
    assert all(row["frames"] <= 30 for row in short)
    r = cli("fill", src, "-o", tmp_path / "out3.c3d", "--gap-report", tmp_path / "gaps.json",
            "--quiet")
    assert r.returncode == 2 and "gaps.json exists" in r.stderr  # never replaced silently
    r = cli("fill", src, "-o", tmp_path / "out3.c3d", "--method", "rigid", "--gap-report",
            tmp_path / "rigid.csv")
    assert r.returncode == 2 and "use --method auto" in r.stderr
    assert not (tmp_path / "out3.c3d").exists()  # checked before anything is filled


def internal_names(text):
    """The internal names of the fill's stages and generators that ``text`` contains."""
    import re

    from mocap_gapfill.core.explain import INTERNAL_NAMES

    return sorted({n for n in INTERNAL_NAMES if re.search(rf"\b{n}\b", text)})


def test_evaluate_writes_json(data_dir, tmp_path):
    out = tmp_path / "eval.json"
    r = cli("evaluate", "--protocol", "markers", "--settings", "rate=0.1", "--fps", "120",
            "--methods", "knn", "linear", "--test", data_dir / "cmu/c3d/85_02.c3d",
            "--kb-sources", data_dir / "cmu/c3d", "--json", out, "--quiet")
    assert r.returncode == 0, r.stderr
    payload = json.loads(out.read_text())
    assert payload["protocol"] == "markers"
    assert payload["default_method"] == "auto" and payload["baselines"] == ["linear"]
    rows = payload["results"]
    assert {(row["method"], row["setting"], row["test"]) for row in rows} == {
        ("knn", "rate=0.1", "85_02.c3d"), ("linear", "rate=0.1", "85_02.c3d")}
    for row in rows:
        assert row["rmse_missing_mm"] > row["rmse_all_mm"] > 0 and row["seconds"] > 0
    assert "rate=0.1" in r.stdout


def test_evaluate_goes_on_past_a_take_setting_a_method_cannot_fill(data_dir, tmp_path):
    """CMU 09_05 is 69 frames at 60 fps: six joints gone for 120 frames are gone throughout,
    the hip among them, and `knn` cannot normalise a pose without its root. The run says so
    and goes on (every missing sample counts as infinitely wrong there); the other settings and
    methods keep their scores, and the JSON is written."""
    out = tmp_path / "short.json"
    daz = data_dir / "cmu/bvh/daz_friendly"
    r = cli("evaluate", "--protocol", "joints", "--settings", "m=6,l=120", "m=3,l=90",
            "--skip-frames", "6", "--methods", "knn", "spline", "--test", daz / "09/09_05.bvh.gz",
            "--kb-sources", daz / "06", "--json", out, "--quiet")
    assert r.returncode == 0, r.stderr
    assert "09_05.bvh.gz m=6,l=120 knn: the root and hip points are missing" in r.stderr
    rows = {(row["method"], row["setting"]): row for row in json.loads(out.read_text())["results"]}
    failed = rows["knn", "m=6,l=120"]
    assert failed["rmse_missing_mm"] == np.inf and "cannot normalise" in failed["error"]
    assert 0 < rows["knn", "m=3,l=90"]["rmse_missing_mm"] < np.inf
    assert "error" not in rows["knn", "m=3,l=90"] and "error" not in rows["spline", "m=6,l=120"]


def test_evaluate_bones_goes_on_past_a_method_that_cannot_fill(data_dir, tmp_path):
    """Protocol bones on a short Daz take against a knowledge base of C3D markers, which shares
    no point with the armature: `match` cannot fill, and the run says so, scores it inf and goes
    on; `interp` and `slerp`, which need no knowledge base, are scored on the same gaps. The
    take (129 frames) is too short for gaps of 240 frames: that setting is said and left out,
    not scored as NaN; asked for alone, the run stops with that said."""
    out = tmp_path / "bones.json"
    r = cli("evaluate", "--protocol", "bones", "--settings", "n=1,l=15", "n=1,l=240",
            "--methods", "interp",
            "match", "slerp", "--test", data_dir / "cmu/bvh/daz_friendly/09/09_03.bvh.gz",
            "--kb-sources", data_dir / "cmu/c3d/02_05.c3d", "--json", out, "--quiet")
    assert r.returncode == 0, r.stderr
    assert "09_03.bvh.gz n=1,l=15 match: the knowledge base does not match this motion: it " \
        "lacks 43 of its 43 points" in r.stderr
    rows = {row["method"]: row for row in json.loads(out.read_text())["results"]}
    assert rows["match"]["rmse_missing_mm"] == np.inf and "lacks" in rows["match"]["error"]
    assert all(0 < rows[m]["rmse_missing_mm"] < np.inf and "error" not in rows[m]
               for m in ("interp", "slerp"))
    assert len(rows["interp"]["gaps_mm"]) == len(rows["match"]["gaps_mm"]) == 4  # 129 frames
    assert "09_03.bvh.gz n=1,l=240: the take is too short for it (no gaps); skipped" in r.stderr
    assert {row["setting"] for row in json.loads(out.read_text())["results"]} == {"n=1,l=15"}
    r = cli("evaluate", "--protocol", "bones", "--settings", "n=1,l=240", "--methods", "interp",
            "--test", data_dir / "cmu/bvh/daz_friendly/09/09_03.bvh.gz", "--no-kb", "--quiet")
    assert r.returncode != 0 and "too short for every setting" in r.stderr
    assert "Traceback" not in r.stderr


def test_evaluate_gaps_at_the_clip_ends(data_dir, tmp_path):
    """Protocols `endgaps` (points) and `bone-ends` (armatures): gaps that touch the take's
    first or last frame, where Blender and the interpolations hold the one key. On the walk
    07_05 without a knowledge base the take's own regression carries the bones on from it,
    closer than the held key."""
    from mocap_gapfill.core.evaluate import gappable_bones, punch_bone_gaps, punch_gaps
    from mocap_gapfill.core.io import read_rig_take

    miss = punch_gaps(100, 20, "endgaps", 12, np.random.default_rng(0))
    starts, ends = miss[:12].all(axis=0), miss[-12:].all(axis=0)
    assert starts.sum() == ends.sum() == 3 and not (starts & ends).any()
    assert miss.sum() == 6 * 12
    walk = data_dir / "cmu/bvh/daz_friendly/07/07_05.bvh.gz"
    rig = read_rig_take(walk)[0]
    gaps = punch_bone_gaps(rig, 500, (1, 30), ends=True)
    assert gaps[:30].sum() == gaps[-30:].sum() == gaps.sum() // 2 == 30
    assert set(np.flatnonzero(gaps.any(axis=0))) <= set(gappable_bones(rig))
    # a take too short for the setting gets no gaps: a bone gapped throughout would keep its
    # true values (nothing to interpolate from) and score every fill as perfect
    assert not punch_bone_gaps(rig, 120, (1, 120), ends=True).any()
    assert punch_bone_gaps(rig, 121, (1, 120), ends=True).sum() == 240
    out = tmp_path / "ends.json"
    r = cli("evaluate", "--protocol", "bone-ends", "--settings", "n=1,l=120", "--methods",
            "interp", "regress", "--test", walk, "--no-kb", "--json", out, "--quiet")
    assert r.returncode == 0, r.stderr
    rows = {row["method"]: row for row in json.loads(out.read_text())["results"]}
    assert len(rows["interp"]["gaps_mm"]) == 2
    print(f"\n07_05 bones keyless for their first or last second: held "
          f"{rows['interp']['rmse_missing_mm']:.1f} mm, regress {rows['regress']['rmse_missing_mm']:.1f}")
    assert rows["regress"]["rmse_missing_mm"] < 0.8 * rows["interp"]["rmse_missing_mm"]


def test_evaluate_bursts_take_most_points_at_once(data_dir, tmp_path):
    """Protocol `bursts`: once per 120 frames a run of l frames loses 50-100 % of the points
    together (occlusions that take most of the body); on 06_01 without a knowledge base `auto`
    fills them (a spline through the take joins where the partners left stray)."""
    from mocap_gapfill.core.evaluate import punch_gaps

    miss = punch_gaps(600, 40, "bursts", 30, np.random.default_rng(0))
    frames = np.flatnonzero(miss.any(axis=1))
    assert len(frames) == 5 * 30  # one run of 30 frames per interval
    assert all(20 <= miss[t].sum() <= 40 for t in frames)
    assert (miss[frames] == miss[frames[0]]).all(axis=1)[:30].all()
    out = tmp_path / "bursts.json"
    r = cli("evaluate", "--protocol", "bursts", "--settings", "l=30", "--methods", "auto",
            "spline", "rigid", "--test", data_dir / "cmu/c3d/06_01.c3d", "--fps", "120",
            "--no-kb", "--json", out, "--quiet")
    assert r.returncode == 0, r.stderr
    rows = {row["method"]: row["rmse_missing_mm"] for row in json.loads(out.read_text())["results"]}
    print(rows)
    assert rows["auto"] < min(rows["rigid"], 1.3 * rows["spline"])


def test_evaluate_without_a_knowledge_base(data_dir, tmp_path):
    """`evaluate --no-kb`: what `auto` does on a rig or a marker set no knowledge base fits (the
    take alone), beside the methods that need one (scored inf, the run goes on); a knowledge
    base and --no-kb together, or neither, is a clear error."""
    out = tmp_path / "alone.json"
    r = cli("evaluate", "--protocol", "bones", "--settings", "n=1,l=30", "--methods", "interp",
            "auto", "match", "--test", data_dir / "cmu/bvh/daz_friendly/09/09_03.bvh.gz",
            "--no-kb", "--json", out, "--quiet")
    assert r.returncode == 0, r.stderr
    payload = json.loads(out.read_text())
    assert payload["kb_sources"] == []
    rows = {row["method"]: row for row in payload["results"]}
    assert rows["match"]["rmse_missing_mm"] == np.inf and "needs a knowledge base" in \
        rows["match"]["error"]
    assert 0 < rows["auto"]["rmse_missing_mm"] < np.inf and "error" not in rows["auto"]
    out = tmp_path / "markers.json"
    r = cli("evaluate", "--protocol", "markers", "--settings", "rate=0.1", "--methods", "auto",
            "knn", "--test", data_dir / "cmu/c3d/85_02.c3d", "--fps", "120", "--no-kb",
            "--json", out, "--quiet")
    assert r.returncode == 0, r.stderr
    rows = {row["method"]: row for row in json.loads(out.read_text())["results"]}
    assert rows["knn"]["rmse_missing_mm"] == np.inf
    assert 0 < rows["auto"]["rmse_missing_mm"] < np.inf
    for extra in ((), ("--no-kb", "--kb", tmp_path / "kb.npz")):
        r = cli("evaluate", "--protocol", "bones", "--test", data_dir / "cmu/c3d/85_02.c3d",
                *extra, "--quiet")
        assert r.returncode == 2 and "--no-kb" in r.stderr and "Traceback" not in r.stderr


def test_evaluate_real_gaps(data_dir, tmp_path):
    """realgaps: the gaps 01_01.c3d really has (RBAC, its last 30 frames), by name, on other
    takes of the same marker set."""
    from mocap_gapfill.core.evaluate import real_gaps

    source = read_motion(data_dir / "cmu/c3d/01_01.c3d")
    take = read_motion(data_dir / "cmu/c3d/85_02.c3d")
    miss = real_gaps(source, list(take.names), 3 * source.n_frames)
    rbac = take.names.index("RBAC")
    assert miss.sum() == 3 * 30 and miss[:, rbac].sum() == 3 * 30  # repeated in time
    assert miss[source.n_frames - 30:source.n_frames, rbac].all()
    folded = real_gaps(source, list(take.names), take.n_frames)  # a shorter take: folded
    start = (source.n_frames - 30) % take.n_frames
    assert folded.sum() == 30 and folded[start:start + 30, rbac].all()
    out = tmp_path / "real.json"
    c3d = data_dir / "cmu/c3d"
    r = cli("evaluate", "--protocol", "realgaps", "--gap-sources", c3d / "01_01.c3d", "--fps",
            "120", "--methods", "rigid", "linear", "--test", c3d / "85_02.c3d",
            "--kb-sources", data_dir / "cmu/c3d/02_05.c3d", "--json", out, "--quiet")
    assert r.returncode == 0, r.stderr
    rows = {row["method"]: row for row in json.loads(out.read_text())["results"]}
    assert set(rows) == {"rigid", "linear"} and rows["rigid"]["setting"] == "gaps=01_01"
    assert rows["rigid"]["rmse_missing_mm"] < rows["linear"]["rmse_missing_mm"]
    r = cli("evaluate", "--protocol", "realgaps", "--test", data_dir / "cmu/c3d/06_01.c3d",
            "--kb-sources", data_dir / "cmu/c3d/02_05.c3d", "--quiet")
    assert r.returncode == 2 and "--gap-sources" in r.stderr and "Traceback" not in r.stderr


def test_ctrl_c_stops_cleanly_and_writes_nothing(data_dir, tmp_path):
    import signal
    import time

    from mocap_gapfill.core.evaluate import punch_gaps, with_gaps

    kb = tmp_path / "kb.npz"
    assert cli("kb", "build", data_dir / "cmu/bvh/daz_friendly/08", "-o", kb, "--skip-frames",
               "6", "--quiet").returncode == 0
    assert load_kb(kb).turns is not None  # armature takes: the bones' rotations are kept
    take = read_motion(data_dir / "cmu/bvh/daz_friendly/13/13_30.bvh.gz", skip_frames=6)
    miss = punch_gaps(take.n_frames, take.n_points, "joints", (6, 120), np.random.default_rng(0))
    gappy = write_motion(with_gaps(take, miss), tmp_path / "gappy.npz")
    out = tmp_path / "filled.npz"
    proc = subprocess.Popen([sys.executable, "-m", "mocap_gapfill", "fill", str(gappy), "-k",
                             str(kb), "-o", str(out)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True,
                            # as from a terminal, also where this run's shell ignores Ctrl-C
                            # (a background job of a script inherits SIGINT ignored)
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    seen = ""
    while "%" not in seen:  # the fill has begun (its first progress line)
        char = proc.stderr.read(1)
        assert char, "the fill ended before it could be interrupted"
        seen += char
    time.sleep(0.5)
    assert proc.poll() is None, "the fill ended before it could be interrupted"
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    err = seen + err
    # 130, or killed by SIGINT (-2), which a shell also reports as 130: seen once under heavy
    # load on Python 3.13 after our handler had run (the message below was printed)
    assert proc.returncode in (130, -signal.SIGINT), err
    assert "interrupted: nothing was written" in err and "Traceback" not in err
    assert not out.exists() and not list(tmp_path.glob(".filled*"))


def test_demo_says_its_result_in_a_few_plain_lines(tmp_path):
    """By default the demo prints a short summary: per take the fill against what the user would
    have had (Blender's interpolation, the studios' rigid-body fill), then the files written."""
    r = subprocess.run([sys.executable, "-m", "mocap_gapfill", "demo", str(tmp_path)],
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stdout + r.stderr
    lines = (r.stdout + r.stderr).strip().splitlines()
    assert len(lines) <= 20, lines
    against = [(float(a), float(b)) for a, b in re.findall(
        r"fill ([\d.]+) mm, (?:Blender's interpolation|rigid-body fill) ([\d.]+) mm", r.stdout)]
    assert len(against) == 4 and all(a < b for a, b in against), r.stdout
    assert not internal_names(r.stdout + r.stderr)


def test_demo_is_the_main_job(tmp_path):
    """Offline: synthetic takes, tiny KBs, fills; the scenes too where bpy is installed (every
    step with --verbose)."""
    r = subprocess.run([sys.executable, "-m", "mocap_gapfill", "demo", str(tmp_path),
                        "--verbose"], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stdout + r.stderr
    # the armature's bones filled in the space of their rotations, from a knowledge base that
    # keeps each bone's rotation, against what Blender shows across the deleted keys
    bones = {method: float(value) for method, value in re.findall(
        r"^\s+(\w+)\s+RMSE over the joints the gapped bones move\s+([\d.]+) mm", r.stdout, re.M)}
    assert set(bones) == {"auto", "interp", "bezier", "hermite", "slerp"}, r.stdout
    assert bones["auto"] < 0.2 * min(bones[m] for m in ("interp", "bezier", "hermite", "slerp"))
    assert "holds no bone rotations" not in r.stdout
    assert load_kb(tmp_path / "kb_skeleton.npz").turns is not None
    markers = {method: float(value) for method, value in re.findall(
        r"^\s+(\w+)\s+RMSE over missing samples\s+([\d.]+) mm", r.stdout, re.M)}
    assert set(markers) == {"auto", "knn", "rigid", "linear", "spline"}
    assert markers["auto"] < 0.2 * min(markers["linear"], markers["spline"])
    assert markers["auto"] <= 1.1 * min(markers["knn"], markers["rigid"])
    # the real CMU takes of sample_scenes/ with the starter knowledge bases
    real = re.search(r"RMSE over them: auto ([\d.]+) mm, rigid ([\d.]+) mm, linear ([\d.]+) mm",
                     r.stdout)
    assert real and float(real[1]) < min(float(real[2]), 0.5 * float(real[3])), r.stdout
    real_armature = re.search(r"RMSE: auto ([\d.]+) mm, Blender's own interpolation ([\d.]+) mm "
                              r"\(its curves through Bezier keys ([\d.]+) mm\)", r.stdout)
    assert real_armature and float(real_armature[1]) < min(float(real_armature[2]),
                                                           float(real_armature[3])), r.stdout
    assert "filled 30 samples" in r.stdout  # 01_01's real gap: RBAC's last 30 frames
    for name in ("kb_skeleton.npz", "kb_markers.npz", "demo_markers.svg",
                 "demo_markers_filled.c3d", "01_01_filled.c3d"):
        assert (tmp_path / name).is_file(), name
    assert read_motion(tmp_path / "demo_markers_filled.c3d").missing.sum() == 0
    assert "<polyline" in (tmp_path / "demo_markers.svg").read_text()
    try:
        import bpy  # noqa: F401
    except ImportError:
        assert "Blender scenes skipped" in r.stdout
        return
    assert (tmp_path / "mocap_demo.blend").is_file()
    assert (tmp_path / "mocap_demo_filled.blend").is_file()
    blender = dict(re.findall(r"Blender (\w+): RMSE over the gap samples\s+([\d.]+) mm",
                              r.stdout))
    assert set(blender) == {"Walker", "WalkerMarkers"}
    assert float(blender["Walker"]) < bones["interp"] / 5
    # the add-on's fill is the core's (4.1 mm in Blender, 4.0 in numpy)
    assert float(blender["Walker"]) <= 1.1 * bones["auto"] + 1.0
    assert float(blender["WalkerMarkers"]) < markers["linear"] / 5
    # the real CMU takes as Blender scenes (01_01's empties, 03_02 through Blender's BVH
    # importer), as found and filled with the starter knowledge bases without their subject
    for stem in ("cmu_01_01_markers", "cmu_03_02_armature"):
        for suffix in ("", "_filled"):
            assert (tmp_path / f"{stem}{suffix}.blend").is_file(), stem + suffix
    assert "2773 marker samples missing, 30 filled" in r.stdout
    found = re.findall(r"(\w+) ([\d.]+) mm by (.+?) \(Blender's interpolation ([\d.]+)\)",
                       r.stdout)
    real_bones = {bone: (float(fill), float(interp)) for bone, fill, _, interp in found}
    assert set(real_bones) == {"lForeArm", "rShin", "chest"}, r.stdout
    # and how each was filled, in words: where the interpolation was kept, nothing changed
    how = {bone: by for bone, _, by, _ in found}
    assert not internal_names(" ".join(how.values())), how
    # the forearm's gap (0.83 s) went on to the long-gap consensus of the knowledge base's
    # motion and the take's own regression
    assert how["lForeArm"].endswith("blended with knowledge-base motion and the other bones"), how
    assert all(real_bones[b][0] == real_bones[b][1] for b, by in how.items()
               if by == "kept Blender's curve")
    # measured 116.6 / 74.1 / 10.4 vs 128.2 / 86.0 / 7.2 mm: the chest's cubic and regression
    # agree on a bend the take does not make (the kept interpolation went half way
    # to them; 6.9 before, 103.7 / 87.5 / 7.2 earlier; 11.3 before the fifth of
    # the way on to learn): no gap more than twice as bad + 5
    # mm, the gaps together better
    assert all(fill <= 2 * interp + 5.0 for fill, interp in real_bones.values())
    frames = {"lForeArm": 100, "rShin": 90, "chest": 60}
    assert (sum(f * real_bones[b][0] ** 2 for b, f in frames.items())
            < sum(f * real_bones[b][1] ** 2 for b, f in frames.items()))


def test_blas_kernel_follows_the_cpu_features(tmp_path):
    """The command line names OpenBLAS's kernel from /proc/cpuinfo's flags before numpy loads
    (numpy 1.26's OpenBLAS falls back to a 4x slower kernel on CPUs it does not know), and
    leaves everything alone when the variable is set, numpy is loaded or the flags are unknown."""
    cases = {"avx512": "fpu sse2 avx avx2 fma avx512f avx512cd avx512bw avx512dq avx512vl",
             "avx512f only": "fpu sse2 avx avx2 fma avx512f",
             "old": "fpu sse2 sse4_2"}
    for name, flags in cases.items():
        (tmp_path / name).write_text(f"processor\t: 0\nvendor_id\t: x\nflags\t\t: {flags}\n\n")
    code = (
        "import json, sys\n"
        "from mocap_gapfill.__main__ import choose_blas_kernel\n"
        f"d = {str(tmp_path)!r}\n"
        "out = {n: choose_blas_kernel({}, d + '/' + n) for n in sys.argv[1:]}\n"
        "out['missing file'] = choose_blas_kernel({}, d + '/none')\n"
        "env = {'OPENBLAS_CORETYPE': 'Zen'}\n"
        "out['already set'] = [choose_blas_kernel(env, d + '/avx512'), env['OPENBLAS_CORETYPE']]\n"
        "import numpy\n"
        "out['numpy loaded'] = choose_blas_kernel({}, d + '/avx512')\n"
        "print(json.dumps(out))\n"
    )
    result = subprocess.run([sys.executable, "-c", code, *cases], capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    assert json.loads(result.stdout) == {
        "avx512": "SkylakeX", "avx512f only": "Haswell", "old": None, "missing file": None,
        "already set": [None, "Zen"], "numpy loaded": None}


def test_blas_threads_capped_for_the_fills():
    """The command line lets a fill use at most four BLAS threads (two BLAS users at once in
    `auto` made 16 threads each 1.5x slower than 4), and leaves the threads alone where a
    variable is set, numpy is loaded, or the command is `batch` or `bench`."""
    code = (
        "import json\n"
        "from mocap_gapfill.__main__ import cap_blas_threads\n"
        "out = {}\n"
        "for name, argv, env, cores in [('16 cores', ['fill'], {}, 16), ('2 cores', ['blend'], {}, 2),\n"
        "        ('set', ['fill'], {'OPENBLAS_NUM_THREADS': '8'}, 16), ('batch', ['batch'], {}, 16),\n"
        "        ('bench', ['bench'], {}, 16), ('no command', [], {}, 16)]:\n"
        "    out[name] = [cap_blas_threads(argv, env, cores), env]\n"
        "import numpy\n"
        "out['numpy loaded'] = cap_blas_threads(['fill'], {}, 16)\n"
        "print(json.dumps(out))\n"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    four = {"OMP_NUM_THREADS": "4", "OPENBLAS_NUM_THREADS": "4", "MKL_NUM_THREADS": "4"}
    assert json.loads(result.stdout) == {
        "16 cores": [4, four], "2 cores": [2, {k: "2" for k in four}],
        "set": [None, {"OPENBLAS_NUM_THREADS": "8"}], "batch": [None, {}], "bench": [None, {}],
        "no command": [4, four], "numpy loaded": None}
