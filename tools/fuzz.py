"""Coverage-guided fuzzing of the readers with atheris (libFuzzer), one format per run.

    python tools/fuzz.py FORMAT --runs 100000 --work /tmp/fuzz/FORMAT [--data ../shared/data]

FORMAT is c3d, bvh, asf, amc, kb (knowledge bases), npz or csv (our motion tables). Every input
is written to a file and read the way users read it (``read_motion``; ``load_kb`` and the checks
a fill makes for a knowledge base). An input must end in a successful read or in our own error
type (``GapFillError``); anything else - another exception, a crash, a hang over ``--timeout``
seconds, memory over ``--rss-mb`` - stops libFuzzer, which leaves the input in the work folder
(``crash-*``, ``timeout-*``, ``oom-*``); the tool then keeps it in tests/fuzz_crashers/ as edits
of its seed (see tests/fuzz_inputs.py).

The code under test is instrumented for coverage (``atheris.instrument_imports``), so inputs
that reach new lines or branches of our readers are kept and mutated further. The seed corpus is
made at run time from the real files (tests/fuzz_inputs.py). For speed, the C3D reader's child
process (which runs ezc3d, see core/formats/c3d.py) is forked from this warm process instead
of started anew; it runs the same reader code, and a crash or hang in it is still contained.
Outcomes are counted in ``WORK/stats.json`` (rewritten every 500 inputs and at the end).
"""

import argparse
import json
import os
import random
import re
import resource
import select
import signal
import subprocess
import sys
import tempfile
import time
import zipfile
from collections import Counter
from io import BytesIO
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tests"))

import atheris  # noqa: E402

with atheris.instrument_imports(include=["mocap_gapfill"]):
    from mocap_gapfill.core import io, kb, normalize  # noqa: E402,F401
    from mocap_gapfill.core.errors import GapFillError  # noqa: E402
    from mocap_gapfill.core.formats import asfamc, bvh, c3d, tabular  # noqa: E402,F401

import fuzz_inputs  # noqa: E402

DICTIONARIES = {
    "bvh": ["HIERARCHY", "ROOT", "JOINT", "End Site", "OFFSET", "CHANNELS", "Xposition",
            "Yposition", "Zposition", "Xrotation", "Yrotation", "Zrotation", "MOTION", "Frames:",
            "Frame Time:", "{", "}", "nan", "inf", "-inf", "1e308", "-0", "0.0000001"],
    "asf": [":version", ":name", ":units", "mass", "length", "angle", "deg", "rad",
            ":documentation", ":root", "order", "axis", "position", "orientation", ":bonedata",
            "begin", "end", "id", "name", "direction", "dof", "rx", "ry", "rz", "tx", "ty", "tz",
            "limits", ":hierarchy", "XYZ", "ZYX", "(-inf inf)", "nan", "inf", "1e308"],
    "amc": [":FULLY-SPECIFIED", ":DEGREES", ":RADIANS", "root", "lowerback", "upperback",
            "lhumerus", "rfemur", "nan", "inf", "-inf", "1e308", "99999"],
    "c3d": ["POINT", "RATE", "LABELS", "LABELS2", "FRAMES", "SCALE", "USED", "UNITS",
            "DATA_START", "Y_SCREEN", "ANALOG", "TRIAL", "mm", "+Y"],
    "kb": ["format_version", "poses", "names", "fps", "limbs", "sources", "source_index",
           "reference", "<f4", "<f8", "|O", "<U", "fortran_order", "shape"],
    "npz": ["format_version", "positions", "names", "fps", "parents", "limbs", "filled", "units",
            "up_axis", "<f4", "<f8", "|O", "<U", "|b1", "fortran_order", "shape"],
    "csv": ["# mocap-gapfill csv 1 fps=", "frame", ".x", ".y", ".z", ",", "nan", "inf", "1e308"],
}


def fork_reader(path, out):
    """c3d._run_reader's contract, in a child forked from this process (ezc3d already loaded)."""
    read_end, write_end = os.pipe()
    pid = os.fork()
    if pid == 0:  # child: never returns
        code = 1
        try:
            os.close(read_end)
            os.dup2(write_end, 2)
            sys.argv = ["-c", str(path), str(out)]
            exec(compile(c3d.reader_script(), "<c3d reader>", "exec"), {"__name__": "__main__"})
            code = 0
        except SystemExit as exc:
            code = exc.code if isinstance(exc.code, int) else 1
        finally:
            sys.stderr.flush()
            os._exit(code)
    os.close(write_end)
    deadline = time.monotonic() + c3d.READ_TIMEOUT
    err = b""
    while True:
        done, status = os.waitpid(pid, os.WNOHANG)
        ready, _, _ = select.select([read_end], [], [], 0.002)
        if ready:
            err += os.read(read_end, 65536)
        if done:
            break
        if time.monotonic() > deadline:
            os.kill(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
            os.close(read_end)
            raise subprocess.TimeoutExpired("c3d reader", c3d.READ_TIMEOUT)
    os.close(read_end)
    return os.waitstatus_to_exitcode(status), err.decode(errors="replace")


#: array names of knowledge-base and motion .npz files (a mutated member may take one)
NPZ_MEMBERS = ["format_version", "poses", "names", "fps", "limbs", "sources", "source_index",
               "reference", "positions", "parents", "filled"]


def zip_mutator(data, max_size, seed):
    """Mutations inside an .npz (knowledge base or motion): one member's .npy bytes (header or
    values) mutated, a member dropped, duplicated or renamed, then zipped again with valid
    checksums; one time in five the zip's own bytes."""
    rnd = random.Random(seed)
    try:
        with zipfile.ZipFile(BytesIO(data)) as archive:
            members = {i.filename: archive.read(i) for i in archive.infolist()}
    except Exception:
        members = None
    if not members or rnd.random() < 0.2:
        return atheris.Mutate(data, max_size)
    name = rnd.choice(sorted(members))
    action = rnd.random()
    if action < 0.8:
        members[name] = atheris.Mutate(members[name], max(len(members[name]) * 2, 64))
    elif action < 0.9:
        del members[name]
    else:
        other = rnd.choice(NPZ_MEMBERS)
        members[other + ".npy"] = members[name]
    out = BytesIO()
    with zipfile.ZipFile(out, "w", zipfile.ZIP_STORED) as archive:
        for key, raw in members.items():
            archive.writestr(key, raw)
    return out.getvalue()[:max_size]


NUMBERS = [b"0", b"-0", b"1", b"-1", b"0.5", b"1e308", b"-1e308", b"1e-320", b"nan", b"inf",
           b"-inf", b"99999999999999999999", b"3.4e38", b"2147483648", b"65536", b"1e5"]


def text_mutator(data, max_size, seed):
    """Mutations that keep a text file's shape: a number replaced by an odd one (huge, tiny,
    NaN, infinite, negative) or scaled, a line deleted, duplicated or swapped; else bytes."""
    rnd = random.Random(seed)
    lines = data.split(b"\n")
    if len(lines) < 2 or rnd.random() < 0.35:
        return atheris.Mutate(data, max_size)
    for _ in range(rnd.randint(1, 3)):
        i = rnd.randrange(len(lines))
        action = rnd.random()
        if action < 0.55:
            tokens = lines[i].split(b" ")
            numeric = [j for j, t in enumerate(tokens) if re.fullmatch(rb"-?\d+(\.\d*)?", t)]
            if numeric:
                j = rnd.choice(numeric)
                tokens[j] = (rnd.choice(NUMBERS) if rnd.random() < 0.7
                             else str(float(tokens[j]) * rnd.choice([-1, 10, 0.1, 1e6])).encode())
                lines[i] = b" ".join(tokens)
        elif action < 0.7:
            del lines[i]
        elif action < 0.85:
            lines.insert(i, lines[i])
        else:
            j = rnd.randrange(len(lines))
            lines[i], lines[j] = lines[j], lines[i]
        if len(lines) < 2:
            break
    return b"\n".join(lines)[:max_size]


def outcome_key(message):
    """A ParseError message without the path and numbers: its kind."""
    message = re.sub(r"^[^:]*fuzz[^:]*: ", "", message)
    message = re.sub(r"^(line|frame) \d+: ", "", message)
    message = re.sub(r"'[^']*'|\"[^\"]*\"|\([^)]*\)", "..", message)
    return re.sub(r"-?\d[\d.e+-]*", "N", message)[:70]


class Target:
    def __init__(self, fmt, data, work, runs):
        self.fmt, self.work, self.runs = fmt, work, runs
        self.tmp = Path(tempfile.mkdtemp(prefix=f"fuzz_{fmt}_"))
        self.file, self.partner = fuzz_inputs.input_paths(fmt, self.tmp, data)
        self.counts = Counter()
        self.start = time.time()
        self.slowest = 0.0

    def read(self):
        return fuzz_inputs.read_as_user(self.fmt, self.file, self.partner)

    def __call__(self, data):
        self.file.write_bytes(data)
        t0 = time.perf_counter()
        try:
            self.read()
            self.counts["read"] += 1
        except GapFillError as exc:
            self.counts["error: " + outcome_key(str(exc).replace(f"{self.tmp}/", "<tmp>/"))] += 1
        finally:
            self.slowest = max(self.slowest, time.perf_counter() - t0)
        total = sum(self.counts.values())
        if total % 500 == 0 or total >= self.runs:
            self.save()

    def save(self):
        usage = resource.getrusage(resource.RUSAGE_SELF)
        children = resource.getrusage(resource.RUSAGE_CHILDREN)
        total = sum(self.counts.values())
        stats = {"format": self.fmt, "inputs": total, "seconds": round(time.time() - self.start, 1),
                 "slowest_input_s": round(self.slowest, 3),
                 "peak_rss_mb": round(usage.ru_maxrss / 1024, 1),
                 "peak_child_rss_mb": round(children.ru_maxrss / 1024, 1),
                 "read": self.counts["read"], "errors": total - self.counts["read"],
                 "outcomes": dict(self.counts.most_common())}
        (self.work / "stats.json").write_text(json.dumps(stats, indent=1) + "\n")


def keep_crashers(fmt, work, seeds):
    """Store libFuzzer's crash/timeout/oom inputs as edits of their nearest seed."""
    kept = []
    for path in sorted(work.glob("*-*")):
        if path.name.split("-")[0] not in ("crash", "timeout", "oom", "leak"):
            continue
        data = path.read_bytes()
        name = min(seeds, key=lambda n: len(json.dumps(fuzz_inputs.encode(seeds[n], data))))
        kept.append(fuzz_inputs.save_crasher(fmt, name, seeds[name], data, path.name))
    return kept


MUTATORS = {"kb": zip_mutator, "npz": zip_mutator, "bvh": text_mutator, "asf": text_mutator,
            "amc": text_mutator, "csv": text_mutator}


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("format", choices=fuzz_inputs.FORMATS)
    parser.add_argument("--runs", type=int, default=100_000)
    parser.add_argument("--work", type=Path, required=True)
    parser.add_argument("--data", type=Path, default=ROOT.parent / "shared" / "data")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--timeout", type=int, default=30, help="seconds per input")
    parser.add_argument("--rss-mb", type=int, default=2048)
    parser.add_argument("--replay", type=Path, help="read this one input and show what happens")
    parser.add_argument("--keep", action="store_true",
                        help="only store the crashers left in --work as regression inputs")
    args = parser.parse_args()
    work = args.work.resolve()
    seeds = fuzz_inputs.seeds(args.format, args.data)
    if args.replay:
        target = Target(args.format, args.data, work, 1)
        target.file.write_bytes(args.replay.read_bytes())
        print("read:", target.read())
        return
    if args.keep:
        for path in keep_crashers(args.format, work, seeds):
            print("kept", path)
        return
    corpus, seed_dir = work / "corpus", work / "seeds"
    for folder in (corpus, seed_dir):
        folder.mkdir(parents=True, exist_ok=True)
    for name, raw in seeds.items():
        (seed_dir / name).write_bytes(raw)
    (work / "dict").write_text("".join(f"k{i}={json.dumps(w)}\n"
                                       for i, w in enumerate(DICTIONARIES[args.format])))
    if args.format == "c3d":
        import ezc3d  # noqa: F401  (loaded once, shared with the forked readers)

        c3d._run_reader = fork_reader
        c3d.READ_TIMEOUT = max(1, args.timeout // 3)
    target = Target(args.format, args.data, work, args.runs)
    max_len = 2 * max(len(s) for s in seeds.values())
    atheris.Setup([sys.argv[0], str(corpus), str(seed_dir), f"-runs={args.runs}",
                   f"-seed={args.seed}", f"-timeout={args.timeout}", f"-rss_limit_mb={args.rss_mb}",
                   f"-max_len={max_len}", f"-dict={work / 'dict'}", f"-artifact_prefix={work}/",
                   "-print_final_stats=1", "-close_fd_mask=1"], target,
                  custom_mutator=MUTATORS.get(args.format))
    atheris.Fuzz()


if __name__ == "__main__":
    main()
