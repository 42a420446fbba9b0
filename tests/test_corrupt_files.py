"""Corrupt, truncated and empty files end in a ParseError: never a crash, a hang or a traceback.

Reads run in a child process, so a crash in native code (ezc3d) fails the test instead of
killing the test run; each file gets a time limit.
"""

import gzip
import json
import subprocess
import sys
import time

import numpy as np
import pytest

from mocap_gapfill.core.errors import ParseError

WORKER = r"""
import json, sys
from mocap_gapfill.core.errors import ParseError
from mocap_gapfill.core.io import read_motion
for line in sys.stdin:
    path, asf = json.loads(line)
    print(json.dumps(["start", path]), flush=True)
    try:
        m = read_motion(path, asf=asf)
        print(json.dumps(["ok", path, m.n_frames]), flush=True)
    except ParseError as exc:
        print(json.dumps(["ParseError", path, str(exc)]), flush=True)
    except BaseException as exc:
        print(json.dumps(["other", path, type(exc).__name__ + ": " + str(exc)]), flush=True)
"""


def read_isolated(jobs, timeout=120):
    """Read (path, asf) pairs in a child process: {path: (outcome, detail)}."""
    proc = subprocess.run([sys.executable, "-c", WORKER], capture_output=True, text=True,
                          input="".join(json.dumps([str(p), a and str(a)]) + "\n" for p, a in jobs),
                          timeout=timeout)
    outcome, last = {}, None
    for line in proc.stdout.splitlines():
        kind, path, *rest = json.loads(line)
        if kind == "start":
            last = path
        else:
            outcome[path] = (kind, rest[0])
    assert proc.returncode == 0, f"reader crashed (exit {proc.returncode}) on {last}: {proc.stderr[-500:]}"
    return outcome


SOURCES = {
    ".c3d": "cmu/c3d/85_02.c3d",
    ".bvh": "cmu/bvh/mb_friendly/01_01.bvh",
    ".bvh.gz": "cmu/bvh/daz_friendly/09/09_06.bvh.gz",
    ".amc": "cmu/asfamc/09/09_06.amc",
    ".asf": "cmu/asfamc/09/09.asf",
}


def corrupt_variants(raw, rng, suffix):
    """(name, bytes, must_fail) variants of one file's bytes."""
    yield "empty", b"", True
    for frac in (0.1, 0.5, 0.9):
        cut = int(len(raw) * frac)
        if suffix in (".amc", ".bvh", ".asf"):
            # cut inside a line, between two values, so whole values are lost
            while cut < len(raw) and raw[cut:cut + 1] != b" ":
                cut += 1
        yield f"truncated{int(frac * 100)}", raw[:cut], True
    yield "garbage", rng.integers(0, 256, size=4096, dtype=np.uint8).tobytes(), True
    for i in range(12):
        data = bytearray(raw)
        span = min(len(data), 4096) if suffix in (".c3d", ".bvh.gz") else len(data)
        for pos in rng.integers(0, span, size=8):
            data[pos] = int(rng.integers(0, 256))
        yield f"mutated{i}", bytes(data), False


@pytest.mark.parametrize("suffix", list(SOURCES))
def test_corrupt_files_give_parse_errors(data_dir, tmp_path, suffix):
    rng = np.random.default_rng(sum(map(ord, suffix)))
    raw = (data_dir / SOURCES[suffix]).read_bytes()
    jobs, must_fail = [], set()
    for name, data, fail in corrupt_variants(raw, rng, suffix):
        if suffix == ".asf":  # a corrupt skeleton with a good motion
            path = tmp_path / f"{name}.asf"
            path.write_bytes(data)
            jobs.append((data_dir / "cmu/asfamc/09/09_06.amc", path))
            key = str(data_dir / "cmu/asfamc/09/09_06.amc") + "|" + name
        else:
            path = tmp_path / f"{name}{suffix}"
            path.write_bytes(data)
            jobs.append((path, data_dir / "cmu/asfamc/09/09.asf" if suffix == ".amc" else None))
            key = str(path)
        if fail:
            must_fail.add(name)
        del key
    if suffix == ".asf":  # one job at a time: they share the AMC path
        results = {}
        for (amc, asf) in jobs:
            (outcome,) = read_isolated([(amc, asf)]).values()
            results[asf.stem] = outcome
    else:
        results = {p.name[:-len(suffix)]: v for p, v in
                   ((__import__("pathlib").Path(k), v) for k, v in read_isolated(jobs).items())}
    assert len(results) == len(jobs)
    for name, (kind, detail) in results.items():
        assert kind in ("ok", "ParseError"), f"{name}: {kind} {detail}"
        if name in must_fail:
            assert kind == "ParseError", f"{name} was accepted: {detail}"
    assert any(kind == "ParseError" for kind, _ in results.values())


def test_gzip_bvh_with_bad_stream(tmp_path, data_dir):
    raw = gzip.compress((data_dir / SOURCES[".bvh"]).read_bytes()[:5000])
    path = tmp_path / "bad.bvh.gz"
    path.write_bytes(raw[:-20])
    (kind, detail), = read_isolated([(path, None)]).values()
    assert kind == "ParseError" and "gzip" in detail


def test_gzip_bomb_and_gzip_in_several_members(tmp_path, data_dir, monkeypatch):
    """A .bvh.gz that unzips past the size limit is refused after reading no more than the
    limit; a file gzipped in two members (as `cat a.gz b.gz` makes) reads whole."""
    from mocap_gapfill.core import formats
    from mocap_gapfill.core.io import read_motion

    text = gzip.decompress((data_dir / SOURCES[".bvh.gz"]).read_bytes())
    two = tmp_path / "two.bvh.gz"
    two.write_bytes(gzip.compress(text[:5000]) + gzip.compress(text[5000:]))
    assert read_motion(two).n_frames == read_motion(data_dir / SOURCES[".bvh.gz"]).n_frames
    monkeypatch.setattr(formats, "MAX_TEXT_BYTES", len(text) - 1)
    with pytest.raises(ParseError, match="unzips to over"):
        read_motion(two)
    plain = tmp_path / "big.bvh"
    plain.write_bytes(text)
    with pytest.raises(ParseError, match="file too large"):
        read_motion(plain)


def test_missing_and_unknown_files(tmp_path):
    (tmp_path / "notes.txt").write_text("hello")
    out = read_isolated([(tmp_path / "nope.c3d", None), (tmp_path / "notes.txt", None),
                         (tmp_path, None)])
    messages = {k.rsplit("/", 1)[-1]: v for k, v in out.items()}
    assert messages["nope.c3d"] == ("ParseError", f"{tmp_path / 'nope.c3d'}: no such file")
    assert "unknown file type .txt" in messages["notes.txt"][1]
    assert messages[tmp_path.name] [1].endswith("not a file")


def test_a_crash_inside_the_c3d_library_is_contained(data_dir, monkeypatch):
    """Some corrupt files damage ezc3d's memory (a later read crashes): reads run in a child
    process, and a child that dies becomes a ParseError here, never our crash."""
    from mocap_gapfill.core.errors import ParseError
    from mocap_gapfill.core.formats import c3d

    monkeypatch.setattr(c3d, "_READER", "import ctypes; ctypes.string_at(0)")  # segfaults
    with pytest.raises(ParseError, match="crashed on this file"):
        c3d.read_c3d(data_dir / "cmu/c3d/85_02.c3d")
    monkeypatch.setattr(c3d, "_READER", "import time; time.sleep(30)")
    monkeypatch.setattr(c3d, "READ_TIMEOUT", 1)
    with pytest.raises(ParseError, match="over 1 s"):
        c3d.read_c3d(data_dir / "cmu/c3d/85_02.c3d")


# Byte edits of cmu/c3d/85_02.c3d found by structured mutation (docs/ROBUSTNESS.md) that pass our
# precheck and make ezc3d 1.7.2 itself segfault or hang when it reads the file.
EZC3D_CRASHES = {
    "crash143": [(853, 222), (1171, 218), (1177, 147), (2069, 213), (2278, 165), (2824, 68),
                 (3053, 90), (3125, 1), (3866, 55)],
    "crash445": [(687, 179), (2262, 102), (2300, 219), (2389, 194), (2966, 102)],
}
EZC3D_HANG = [(117, 193), (605, 250), (1644, 159), (1988, 242), (2045, 140), (2416, 18),
              (2463, 138), (2917, 33), (3801, 222)]


def _edited(data_dir, tmp_path, name, edits):
    data = bytearray((data_dir / "cmu/c3d/85_02.c3d").read_bytes())
    for offset, value in edits:
        data[offset] = value
    path = tmp_path / f"{name}.c3d"
    path.write_bytes(bytes(data))
    return path


def _raw_ezc3d(path, timeout):
    try:
        return subprocess.run([sys.executable, "-c", "import sys, ezc3d; ezc3d.c3d(sys.argv[1])",
                               str(path)], capture_output=True, timeout=timeout).returncode
    except subprocess.TimeoutExpired:
        return "hang"


def test_files_that_crash_ezc3d_give_parse_errors(data_dir, tmp_path):
    from mocap_gapfill.core.errors import ParseError
    from mocap_gapfill.core.formats.c3d import read_c3d

    for name, edits in EZC3D_CRASHES.items():
        path = _edited(data_dir, tmp_path, name, edits)
        assert _raw_ezc3d(path, 60) < 0, "ezc3d no longer crashes on this file"
        with pytest.raises(ParseError, match="crashed on this file"):
            read_c3d(path)


def test_a_file_that_hangs_ezc3d_gives_a_parse_error(data_dir, tmp_path, monkeypatch):
    from mocap_gapfill.core.errors import ParseError
    from mocap_gapfill.core.formats import c3d

    path = _edited(data_dir, tmp_path, "hang0", EZC3D_HANG)
    assert _raw_ezc3d(path, 5) == "hang", "ezc3d no longer hangs on this file"
    # ezc3d allocates without end here: under the reader's memory cap it stops at once
    start = time.monotonic()
    with pytest.raises(ParseError, match="unreadable C3D"):
        c3d.read_c3d(path)
    assert time.monotonic() - start < 10
    # without the cap, the time limit stops it
    monkeypatch.setattr(c3d, "READ_MEMORY_MB", 1 << 20)
    monkeypatch.setattr(c3d, "READ_TIMEOUT", 3)
    with pytest.raises(ParseError, match="took over 3 s"):
        c3d.read_c3d(path)


def test_a_read_killed_midway_leaves_no_folder_behind_for_long(data_dir, tmp_path, monkeypatch):
    """A process killed while ezc3d reads (a batch worker stopped by Ctrl-C, a Blender that
    crashed) cannot remove its read's temporary folder; the next read removes it once no read
    can still be using it, and leaves younger folders alone."""
    import os
    import signal
    import tempfile

    from mocap_gapfill.core.formats import c3d

    folders = tmp_path / "tmp"
    folders.mkdir()
    slow = ("import time; from mocap_gapfill.core.formats import c3d; "
            "c3d._READER = 'import time; time.sleep(60)'; c3d.read_c3d(%r)"
            % str(data_dir / "cmu/c3d/85_02.c3d"))
    victim = subprocess.Popen([sys.executable, "-c", slow], start_new_session=True,
                              env=dict(os.environ, TMPDIR=str(folders)))
    deadline = time.monotonic() + 30
    while not list(folders.glob(c3d.READ_FOLDER_PREFIX + "*")) and time.monotonic() < deadline:
        time.sleep(0.05)
    os.killpg(victim.pid, signal.SIGKILL)  # the process and its reading child
    victim.wait()
    (left,) = folders.glob(c3d.READ_FOLDER_PREFIX + "*")  # what the kill leaves
    young = folders / (c3d.READ_FOLDER_PREFIX + "young")
    young.mkdir()
    old = time.time() - 2 * c3d.READ_TIMEOUT - 60
    os.utime(left, (old, old))
    monkeypatch.setattr(tempfile, "tempdir", str(folders))
    assert c3d.read_c3d(data_dir / "cmu/c3d/85_02.c3d").n_frames > 0
    assert not left.exists()
    assert young.exists()
    assert not [f for f in folders.iterdir() if f != young]  # the read's own folder went too
