"""``mocap-gapfill batch`` on a library built here from real takes with punched gaps: every
output equals what a single-file fill writes, corrupt files are reported and change nothing
else, interrupted and killed runs leave no partial file and resume without redoing takes, and
the Ray and Dask engines write what the local one does."""

import gzip
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from mocap_gapfill.core.batch import Options, output_name, run_batch
from mocap_gapfill.core.evaluate import punch_gaps
from mocap_gapfill.core.fill import fill
from mocap_gapfill.core.io import read_motion, write_motion
from mocap_gapfill.core.kb import build_kb

TAKES = ("01_01", "02_05", "06_01", "85_02", "135_02")
CORRUPT = ("truncated.c3d", "garbage.bvh", "empty.amc")
FAST = Options(method="rigid")  # the library test is about the batch, not the method's cost


@pytest.fixture(scope="module")
def library(data_dir, tmp_path_factory):
    """>= 100 C3D takes cut from the CMU marker takes, gaps punched (markers protocol, 20 %),
    in nested folders; a take of 10,530 frames; a BVH take; three corrupt files; a .blend of an
    armature with bone keys deleted where the bpy module is installed."""
    root = tmp_path_factory.mktemp("library")
    rng = np.random.default_rng(0)
    count = 0
    for name in TAKES:
        take = read_motion(data_dir / f"cmu/c3d/{name}.c3d")
        for start in np.linspace(0, take.n_frames - 150, 21).astype(int):
            part = take.frame_range(start, start + 150)
            miss = punch_gaps(part.n_frames, part.n_points, "markers", 0.2, rng)
            folder = root / name[:2] / ("slow" if count % 3 else "fast")
            folder.mkdir(parents=True, exist_ok=True)
            write_motion(part.replace(positions=np.where(miss[..., None], np.nan,
                                                         part.positions), filled=None),
                         folder / f"{name}_{start:05d}.c3d")
            count += 1
    long = read_motion(data_dir / "cmu/c3d/85_02.c3d")
    tiled = np.concatenate([long.positions] * 13)
    miss = punch_gaps(len(tiled), long.n_points, "markers", 0.1, rng)
    write_motion(long.replace(positions=np.where(miss[..., None], np.nan, tiled), filled=None),
                 root / "long_85_02.c3d")
    bvh = root / "bvh" / "03_02.bvh"
    bvh.parent.mkdir()
    bvh.write_bytes(gzip.decompress((data_dir / "cmu/bvh/daz_friendly/03/03_02.bvh.gz")
                                    .read_bytes()))
    (root / "bad").mkdir()
    (root / "bad" / "truncated.c3d").write_bytes((data_dir / "cmu/c3d/01_01.c3d")
                                                 .read_bytes()[:3000])
    (root / "bad" / "garbage.bvh").write_text("HIERARCHY\nROOT hip\n{ OFFSET 0 0\n")
    (root / "bad" / "empty.amc").write_bytes(b"")
    blend = _blend_take(bvh, root / "scenes" / "03_02_gaps.blend")
    return {"root": root, "count": count + 2, "blend": blend}


def _blend_take(bvh, path):
    """An armature take with the keys of lForeArm deleted over frames 100-159, or None."""
    try:
        import bpy
    except ImportError:
        return None
    from mocap_gapfill.addon.samples import remove_keys

    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.ops.import_anim.bvh(filepath=str(bvh), frame_start=1)
    arm = bpy.context.object
    remove_keys(arm, [("lForeArm", 100, 159)])
    path.parent.mkdir(parents=True)
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    return path


def _same_as_fill(source, output, options, kb=None):
    """The batch's output reads back exactly as the single-file fill's does (label problems
    repaired first, as ``fill`` does)."""
    from mocap_gapfill.core.faults import repaired

    motion = read_motion(source)
    if options.repair:
        motion = repaired(motion)[0]
    single = output.with_name("single_" + output.name)
    write_motion(fill(motion, options.method, kb=kb), single, overwrite=True)
    a, b = read_motion(output).positions, read_motion(single).positions
    single.unlink()
    return np.array_equal(np.isnan(a), np.isnan(b)) and np.array_equal(a[~np.isnan(a)],
                                                                        b[~np.isnan(b)])


def test_a_library_is_filled_like_single_files(library, tmp_path):
    options = FAST
    seen = []
    rows = run_batch([library["root"]], tmp_path / "out", options, jobs=2,
                     progress=lambda done, total, failed, left: seen.append((done, total)))
    total = library["count"] + len(CORRUPT) + (library["blend"] is not None)
    assert library["count"] >= 100 and len(rows) == total and seen[-1] == (total, total)
    by_input = {Path(r["input"]).name: r for r in rows}
    for name in CORRUPT:  # each listed with its one-line error
        assert by_input[name]["status"] == "failed" and by_input[name]["error"], name
        assert "\n" not in by_input[name]["error"]
    failed = {n: r["error"] for n, r in by_input.items() if r["status"] == "failed"}
    assert set(failed) == set(CORRUPT), failed
    for row in rows:
        if row["status"] != "filled" or row["input"].endswith(".blend"):
            continue
        source, output = Path(row["input"]), Path(row["output"])
        rel = source.relative_to(library["root"])
        assert output == tmp_path / "out" / output_name(rel, "same")
        assert _same_as_fill(source, output, options), rel
    long = by_input["long_85_02.c3d"]
    assert read_motion(Path(long["output"])).n_frames == 10530 and long["samples_filled"] > 0
    assert by_input["03_02.bvh"]["output"].endswith("bvh/03_02.npz")
    if library["blend"] is not None:
        scene = by_input["03_02_gaps.blend"]
        assert scene["status"] == "filled", scene["error"]
        assert scene["gaps"] >= 1 and scene["samples_filled"] >= 60
        assert Path(scene["output"]).is_file()
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    assert report["summary"] == f"{total - 3} filled, 0 up to date, 3 failed of {total} takes"
    assert (tmp_path / "out" / "report.csv").read_text().count("\n") == total + 1
    assert not list((tmp_path / "out").rglob(".*part*"))
    again = run_batch([library["root"]], tmp_path / "out", options, jobs=2)
    assert sorted(r["status"] for r in again) == sorted(r["status"].replace("filled", "skipped")
                                                        for r in rows)
    changed = run_batch([library["root"]], tmp_path / "out", Options(method="linear"), jobs=2)
    assert not any(r["status"] == "skipped" for r in changed)  # other settings: done again


def test_the_knowledge_base_fills_a_batch_as_it_fills_one_file(library, data_dir, tmp_path):
    kb_path = tmp_path / "kb.npz"
    build_kb([data_dir / "cmu/c3d/01_01.c3d", data_dir / "cmu/c3d/135_02.c3d"],
             fps=30).save(kb_path)
    folder = library["root"] / "85"
    options = Options(kb=str(kb_path), method="auto")
    rows = run_batch([folder], tmp_path / "out", options, jobs=2)
    kb = build_kb([data_dir / "cmu/c3d/01_01.c3d", data_dir / "cmu/c3d/135_02.c3d"], fps=30)
    for row in rows[:4]:
        assert row["status"] == "filled", row["error"]
        assert _same_as_fill(Path(row["input"]), Path(row["output"]), options, kb)
    # each take names the gaps to review first, with the largest error their copies expect
    for row in rows:
        worst = row["review_first"].split("; ")
        assert row["expected_mm"] > 0 and 1 <= len(worst) <= 3, row
        assert abs(float(worst[0].split("~")[1].split(" mm")[0]) - row["expected_mm"]) < 0.6
    report = (tmp_path / "out" / "report.csv").read_text().splitlines()
    assert "expected_mm,review_first" in report[0]


def test_takes_no_knowledge_base_fits_are_filled_from_the_take_alone(data_dir, tmp_path):
    """No -k and a marker set no starter knowledge base knows: `auto` fills each take from the
    take alone (as `fill` does) where `knn` reports that it needs a knowledge base."""
    take = read_motion(data_dir / "cmu/c3d/85_02.c3d").frame_range(0, 300)
    positions = take.positions.copy()
    positions[50:80, 5] = np.nan
    take = take.replace(names=tuple(f"P{i}" for i in range(take.n_points)), positions=positions)
    (tmp_path / "in").mkdir()
    write_motion(take, tmp_path / "in" / "studio.c3d")
    (row,) = run_batch([tmp_path / "in"], tmp_path / "auto", Options(method="auto"), jobs=1)
    assert row["status"] == "filled" and row["samples_filled"] == 30, row["error"]
    assert _same_as_fill(Path(row["input"]), Path(row["output"]), Options(method="auto"), None)
    (row,) = run_batch([tmp_path / "in"], tmp_path / "knn", Options(method="knn"), jobs=1)
    assert row["status"] == "failed" and "no starter knowledge base fits" in row["error"]


def _children(pid):
    out = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid:
            out.append(int(stat.parent.name))
    return out


def _start(library, out):
    return subprocess.Popen([sys.executable, "-m", "mocap_gapfill", "batch",
                             str(library["root"]), "-o", str(out), "--jobs", "2",
                             "--method", "rigid", "--quiet"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env={**os.environ, "OMP_NUM_THREADS": "1"},
                            # as from a terminal, also where this run's shell ignores Ctrl-C
                            # (a background job of a script inherits SIGINT ignored)
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))


def _wait_for(out, lines, proc, limit=120):
    """Until the manifest holds ``lines`` finished takes."""
    manifest = out / "manifest.jsonl"
    end = time.time() + limit
    while time.time() < end and proc.poll() is None:
        if manifest.is_file() and manifest.read_text().count("\n") >= lines:
            return
        time.sleep(0.05)
    raise AssertionError("the batch did not get going: " + (proc.stderr.read() or ""))


def _complete(out, rows):
    """Every output the manifest names exists and no temporary file is left."""
    assert not list(out.rglob(".*part*")) and not list(out.rglob("*.blend@"))
    manifest = [json.loads(line) for line in (out / "manifest.jsonl").read_text().splitlines()]
    for entry in manifest:
        assert (out / entry["output"]).is_file()
    return len(manifest)


def test_ctrl_c_keeps_finished_takes_and_the_next_run_skips_them(library, tmp_path):
    out = tmp_path / "out"
    proc = _start(library, out)
    _wait_for(out, 10, proc)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert "interrupted" in err and "Traceback" not in err
    done = _complete(out, None)
    assert 10 <= done < library["count"]
    rows = run_batch([library["root"]], out, FAST, jobs=2)
    skipped = sum(r["status"] == "skipped" for r in rows)
    assert skipped == done  # nothing finished was done again
    finished = sum(r["status"] in ("filled", "skipped") for r in rows)
    assert finished == library["count"] + (library["blend"] is not None)


def test_a_killed_worker_costs_one_retry_not_the_batch(library, tmp_path):
    out = tmp_path / "out"
    proc = _start(library, out)
    _wait_for(out, 5, proc)
    workers = [p for p in _children(proc.pid)
               if b"spawn_main" in Path(f"/proc/{p}/cmdline").read_bytes()]
    assert workers
    os.kill(workers[0], signal.SIGKILL)
    _, err = proc.communicate(timeout=300)
    assert proc.returncode == 1, err  # the corrupt files only
    assert err.count("failed:") == len(CORRUPT), err
    assert _complete(out, None) >= library["count"]
    rows = run_batch([library["root"]], out, FAST, jobs=2)
    assert not any(r["status"] == "filled" for r in rows)


@pytest.mark.parametrize("engine", ["ray", "dask"])
def test_cluster_engines_write_what_the_local_one_does(engine, library, tmp_path):
    if os.environ.get("MOCAP_GAPFILL_REQUIRE_CLUSTER") != "1":
        pytest.importorskip("ray" if engine == "ray" else "distributed")
    folder = library["root"] / "01"
    local = run_batch([folder], tmp_path / "local", FAST, jobs=2)
    remote = run_batch([folder], tmp_path / engine, FAST, engine=engine, jobs=2)
    assert len(remote) == len(local) >= 20
    for row in remote:
        assert row["status"] == "filled", row["error"]
        mine = tmp_path / "local" / Path(row["output"]).relative_to(tmp_path / engine)
        assert np.array_equal(read_motion(row["output"]).positions, read_motion(mine).positions,
                              equal_nan=True)


def test_dask_workers_keep_glibcs_adaptive_malloc():
    """Dask's nannies give workers MALLOC_TRIM_THRESHOLD_=65536, which made fills ~20 % slower
    (docs/BENCHMARKS.md); the local cluster of ``--engine dask`` starts them without it and with
    one BLAS thread each, and leaves Dask's configuration as it was."""
    if os.environ.get("MOCAP_GAPFILL_REQUIRE_CLUSTER") != "1":
        pytest.importorskip("distributed")
    import dask
    from distributed import Client

    from mocap_gapfill.core.batch import dask_local_cluster

    cluster = dask_local_cluster(2)
    try:
        with Client(cluster) as client:
            seen = client.run(lambda: (os.environ.get("MALLOC_TRIM_THRESHOLD_"),
                                       os.environ.get("OPENBLAS_NUM_THREADS")))
    finally:
        cluster.close()
    assert len(seen) == 2 and all(trim is None for trim, _ in seen.values()), seen
    assert all(blas == "1" for _, blas in seen.values()), seen
    assert dask.config.get("distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_") == 65536
