"""``mocap-gapfill batch``: fill a library of takes, on one machine or on a Ray or Dask cluster.

Inputs are files or folders (searched recursively) of C3D, BVH, ASF/AMC and ``.blend`` files;
the outputs mirror the input tree under the output folder. Each take is filled exactly as
``mocap-gapfill fill`` fills it (:func:`~.fill.fill`, the same defaults); ``.blend`` files go
through ``mocap-gapfill blend`` (the bpy module) in a child process of the worker. Then:

- the knowledge base is loaded once per worker process (:func:`run_take` keeps it), never sent
  with a task: tasks carry its path;
- one bad file never stops the batch: it is reported with its one-line error, the rest go on;
- outputs are written atomically (a temporary name, then a rename), so a killed or interrupted
  batch leaves no partial output; ``manifest.jsonl`` in the output folder records each finished
  take with the hashes of its input and of the knowledge base, and a second run skips the takes
  whose output is still there, newer than both, and made with the same settings;
- a progress line on stderr (takes done / total, time left), ``report.csv`` and ``report.json``
  in the output folder (per take: gaps, samples filled, longest gap, method, seconds, the
  worker's peak memory, error).

Engines: ``local`` (a process pool; ``--jobs`` defaults to the core count), ``ray`` (an existing
cluster at ``--address``, or a local one), ``dask`` (a ``dask.distributed`` scheduler at
``--address``, or a local cluster). Ray and Dask are optional extras; their own scheduling
retries tasks whose worker died.
"""

import csv
import hashlib
import json
import os
import sys
import time
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

from .. import THREAD_VARIABLES
from .errors import GapFillError
from .io import atomic_output, file_suffix

TAKE_SUFFIXES = (".c3d", ".bvh", ".bvh.gz", ".amc", ".blend")
ENGINES = ("local", "ray", "dask")
FORMATS = ("same", "c3d", "npz", "csv")
MANIFEST = "manifest.jsonl"
REPORT_FIELDS = ("input", "output", "status", "repaired", "gaps", "samples_filled",
                 "longest_gap", "expected_mm", "review_first", "method", "seconds", "peak_mb",
                 "error")


@dataclass
class Options:
    """What every take is filled with."""

    kb: str = None
    method: str = "auto"
    max_gap: int = 0
    k: int = None
    device: str = "auto"
    repair: bool = True  # label swaps, spikes and ghosts repaired before the fill

    def key(self):
        return {"method": self.method, "max_gap": self.max_gap, "k": self.k,
                "repair": self.repair}


def find_takes(inputs):
    """``[(path, relative output stem)]``: files as given, folders searched recursively (their
    files relative to the folder, under its name when several inputs are given)."""
    out, seen = [], set()
    for raw in inputs:
        root = Path(raw)
        if root.is_dir():
            files = sorted(f for f in root.rglob("*") if f.is_file() and not f.name.startswith(".")
                           and file_suffix(f) in TAKE_SUFFIXES)
            pairs = [(f, (Path(root.name) if len(inputs) > 1 else Path()) / f.relative_to(root))
                     for f in files]
        else:
            pairs = [(root, Path(root.name))]
        for path, rel in pairs:
            if rel not in seen:
                seen.add(rel)
                out.append((path, rel))
    return out


def output_name(rel, fmt):
    """The output's path relative to the output folder: ``.blend`` stays ``.blend``; ``same``
    keeps C3D and writes BVH and ASF/AMC takes (which are not written) as ``.npz``."""
    suffix = file_suffix(rel)
    stem = rel.name[:len(rel.name) - len(suffix)] if suffix else rel.name
    if suffix == ".blend":
        new = ".blend"
    elif fmt == "same":
        new = ".c3d" if suffix == ".c3d" else ".npz"
    else:
        new = f".{fmt}"
    return rel.with_name(stem + new)


def digest(path):
    """SHA-256 of a file's bytes (None when it cannot be read)."""
    h = hashlib.sha256()
    try:
        with open(path, "rb") as handle:
            for block in iter(lambda: handle.read(1 << 20), b""):
                h.update(block)
    except OSError:
        return None
    return h.hexdigest()


_KBS = {}


def _knowledge_base(path, names, method):
    """The knowledge base for a take, the file given loaded once per process, else as
    :func:`~.fill.kb_for_take` finds it (the starter one that fits, None where the take fills
    alone)."""
    from .fill import USES_KB, kb_for_take
    from .kb import load_kb

    if path and method in USES_KB and path not in _KBS:
        _KBS[path] = load_kb(path)
    return kb_for_take(names, method, _KBS.get(path))[0]


def run_take(task):
    """Fill one take (in a worker): ``task`` = (input, output, options); returns its report row.
    Any error of the take becomes the row's one-line ``error``."""
    source, output, options = task
    row = {"input": source, "output": output, "status": "filled", "repaired": "", "gaps": 0,
           "samples_filled": 0, "longest_gap": 0, "method": options.method, "seconds": 0.0,
           "peak_mb": "", "error": ""}
    start = time.perf_counter()
    try:
        if Path(output).resolve() == Path(source).resolve():
            raise GapFillError("the output would replace the input")
        Path(output).parent.mkdir(parents=True, exist_ok=True)
        if file_suffix(source) == ".blend":
            row.update(_blend_take(source, output, options))
        else:
            row.update(_motion_take(source, output, options))
    except Exception as exc:  # one bad take never stops the batch: it is reported
        row["status"] = "failed"
        message = str(exc) if isinstance(exc, GapFillError) else f"{type(exc).__name__}: {exc}"
        row["error"] = " ".join(message.split())
    row["seconds"] = round(time.perf_counter() - start, 3)
    row["peak_mb"] = _peak_mb()
    return row


def _peak_mb():
    """The worker process's peak resident memory so far (MB; Linux and macOS)."""
    try:
        import resource
    except ImportError:  # Windows
        return ""
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return round(peak / (1 << 20 if sys.platform == "darwin" else 1 << 10), 1)


def _motion_take(source, output, options):
    from .fill import REVIEW_FIRST, fill, worst_first
    from .io import read_motion, write_motion
    from .models import KnnSettings

    motion = read_motion(source)
    found = []
    if options.repair:
        from .faults import repaired

        motion, found = repaired(motion)
    runs = motion.gap_runs()
    kb = _knowledge_base(options.kb, motion.names, options.method)
    out, accounts = fill(motion, options.method, kb=kb,
                         settings=KnnSettings(k=options.k, device=options.device),
                         max_gap=options.max_gap or None, return_account=True)
    write_motion(out, output, overwrite=True)
    worst = worst_first(accounts or [])[:REVIEW_FIRST]
    return {"repaired": "; ".join(f.summary() for f in found), "gaps": len(runs),
            "longest_gap": max((b - a + 1 for _, a, b in runs), default=0),
            "samples_filled": int((motion.missing & ~out.missing).sum()),
            "expected_mm": round(1000 * worst[0].estimate, 1) if worst else "",
            "review_first": "; ".join(a.summary() for a in worst)}


def _blend_take(source, output, options):
    """``mocap-gapfill blend`` (or, for a batch started from Blender, ``blender -b FILE -c
    mocap_gapfill``) in a child process of the worker: Blender gets a process of its own, a
    clean ``sys.path``, and a crash there fails this take only."""
    import subprocess

    blender = os.environ.get("MOCAP_GAPFILL_BLENDER")  # set by the batch run from Blender
    with atomic_output(output, overwrite=True) as tmp:
        stats = tmp.with_name(tmp.name + ".json")
        command = ([blender, "-b", str(source), "-c", "mocap_gapfill"] if blender else
                   [sys.executable, "-m", "mocap_gapfill", "blend", str(source)])
        command += ["-o", str(tmp), "--overwrite", "--method", options.method, "--max-gap",
                    str(options.max_gap or 0), "--device", options.device, "--stats", str(stats)]
        if options.kb:
            command += ["--kb", options.kb]
        if options.k:
            command += ["-K", str(options.k)]
        try:
            done = subprocess.run(command, capture_output=True, text=True)
            if done.returncode:
                lines = (done.stderr or done.stdout).strip().splitlines() or ["no output"]
                raise GapFillError(f"blend exited with {done.returncode}: {lines[-1]}")
            result = json.loads(stats.read_text())
        finally:
            stats.unlink(missing_ok=True)
    return {k: result[k] for k in ("gaps", "longest_gap", "samples_filled", "expected_mm",
                                   "review_first")}


def _engine_local(tasks, jobs, address, done):
    """A process pool; a task whose worker died is tried once more in a fresh pool."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor, as_completed
    from concurrent.futures.process import BrokenProcessPool

    tried = {}
    todo = list(tasks)
    while todo:
        pool = ProcessPoolExecutor(jobs, mp_context=multiprocessing.get_context("spawn"),
                                   initializer=_ignore_interrupts)
        retry = []
        try:
            futures = {pool.submit(run_take, task): task for task in todo}
            for future in as_completed(futures):
                task = futures[future]
                try:
                    done(future.result())
                except BrokenProcessPool:
                    tried[task[0]] = tried.get(task[0], 0) + 1
                    if tried[task[0]] < 2:
                        retry.append(task)
                    else:
                        done(_failed(task, "the worker process died twice on this take"))
        except BaseException:  # Ctrl-C: no task outlives the batch
            for process in list(getattr(pool, "_processes", {}).values()):
                process.kill()
            raise
        finally:
            pool.shutdown(wait=True, cancel_futures=True)
        todo = retry


def _ignore_interrupts():
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the driver's to handle


def _engine_ray(tasks, jobs, address, done):
    import ray

    started = not ray.is_initialized()
    if started:
        ray.init(address=address, num_cpus=None if address else jobs, include_dashboard=False,
                 log_to_driver=False)
    try:
        remote = ray.remote(num_cpus=1, max_retries=2)(run_take)
        pending = {remote.remote(task): task for task in tasks}
        while pending:
            ready, _ = ray.wait(list(pending), num_returns=1)
            task = pending.pop(ready[0])
            try:
                done(ray.get(ready[0]))
            except ray.exceptions.RayError as exc:
                done(_failed(task, f"{type(exc).__name__}: {str(exc).splitlines()[0]}"))
    finally:
        if started:
            ray.shutdown()


def _engine_dask(tasks, jobs, address, done):
    from distributed import Client, as_completed

    cluster = None if address else dask_local_cluster(jobs)
    client = Client(address or cluster)
    try:
        futures = {client.submit(run_take, task, pure=False, retries=2): task for task in tasks}
        for future in as_completed(futures):
            try:
                done(future.result())
            except Exception as exc:  # the scheduler gave up on it: reported, the rest go on
                done(_failed(futures[future], f"{type(exc).__name__}: {exc}"))
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def dask_local_cluster(jobs):
    """A Dask LocalCluster of ``jobs`` single-threaded worker processes. Dask's nannies set
    MALLOC_TRIM_THRESHOLD_=65536 in their workers, which turns off glibc's adaptive mmap
    threshold: every large numpy temporary is then mapped and unmapped afresh (a fill ran ~20 %
    slower, docs/BENCHMARKS.md); here it is left to glibc."""
    import dask
    from distributed import LocalCluster

    with dask.config.set({"distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None}):
        return LocalCluster(n_workers=jobs, threads_per_worker=1, processes=True,
                            dashboard_address=None)


ENGINE_RUNNERS = {"local": _engine_local, "ray": _engine_ray, "dask": _engine_dask}


def _failed(task, message):
    return {"input": task[0], "output": task[1], "status": "failed", "gaps": 0,
            "samples_filled": 0, "longest_gap": 0, "method": task[2].method, "seconds": 0.0,
            "peak_mb": "", "error": message}


def run_batch(inputs, outdir, options, engine="local", jobs=None, address=None, fmt="same",
              progress=None):
    """Fill every take of ``inputs`` into ``outdir``; returns the report rows (also written as
    ``report.csv`` / ``report.json`` there). Takes already done with the same input, knowledge
    base and settings are skipped (status ``skipped``)."""
    if engine not in ENGINES:
        raise GapFillError(f"unknown engine {engine!r}; choose from {', '.join(ENGINES)}")
    if fmt not in FORMATS:
        raise GapFillError(f"unknown format {fmt!r}; choose from {', '.join(FORMATS)}")
    takes = find_takes(inputs)
    if not takes:
        raise GapFillError("no C3D, BVH, ASF/AMC or .blend files in the inputs")
    outdir = Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    _remove_partial(outdir)
    jobs = jobs or os.cpu_count() or 1
    kb_hash = digest(options.kb) if options.kb else "starter"
    if options.kb and kb_hash is None:
        raise GapFillError(f"cannot read the knowledge base {options.kb}")
    kb_time = Path(options.kb).stat().st_mtime if options.kb else 0.0
    manifest = _read_manifest(outdir / MANIFEST)
    rows, tasks, hashes = [], [], {}
    for path, rel in takes:
        out_rel = output_name(rel, fmt)
        target = outdir / out_rel
        hashes[str(path)] = entry = {"input": str(rel), "output": str(out_rel),
                                     "input_sha256": digest(path), "kb_sha256": kb_hash,
                                     "settings": options.key()}
        old = manifest.get(str(rel))
        if (old == entry and target.is_file() and entry["input_sha256"] is not None
                and target.stat().st_mtime >= max(path.stat().st_mtime, kb_time)):
            rows.append({"input": str(path), "output": str(target), "status": "skipped",
                         "gaps": "", "samples_filled": "", "longest_gap": "",
                         "method": options.method, "seconds": 0.0, "peak_mb": "", "error": ""})
            continue
        tasks.append((str(path), str(target), options))
    total, start = len(takes), time.perf_counter()
    show = progress or (lambda done, total, failed, seconds_left: None)
    show(len(rows), total, 0, None)

    def done(row):
        rows.append(row)
        if row["status"] == "filled":
            _append_manifest(outdir / MANIFEST, hashes[row["input"]])
        finished = sum(r["status"] != "skipped" for r in rows)
        left = (time.perf_counter() - start) / finished * (len(tasks) - finished)
        show(len(rows), total, sum(r["status"] == "failed" for r in rows), left)

    if tasks:
        try:
            with _threads_per_job(jobs):
                ENGINE_RUNNERS[engine](tasks, jobs, address, done)
        finally:
            _remove_partial(outdir)
            write_report(outdir, rows, total)
    else:
        write_report(outdir, rows, total)
    return rows


def _remove_partial(outdir):
    """Temporary files a killed worker left (never a finished output)."""
    for stale in list(outdir.rglob(".*.part*")) + list(outdir.rglob("*.blend@")):
        stale.unlink(missing_ok=True)


@contextmanager
def _threads_per_job(jobs):
    """While workers start, BLAS / OpenMP threads per worker (they inherit the environment):
    ``OMP_NUM_THREADS`` where set, else each worker its share of the cores."""
    threads = os.environ.get("OMP_NUM_THREADS") or str(max(1, (os.cpu_count() or 1) // jobs))
    before = {name: os.environ.get(name) for name in THREAD_VARIABLES}
    os.environ.update({name: threads for name in THREAD_VARIABLES})
    try:
        yield
    finally:
        for name, value in before.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value


def _read_manifest(path):
    """The last entry per input of ``manifest.jsonl`` (a line cut short by a kill is ignored)."""
    entries = {}
    if path.is_file():
        for line in path.read_text(errors="replace").splitlines():
            try:
                entry = json.loads(line)
                entries[entry["input"]] = entry
            except (ValueError, KeyError, TypeError):
                continue
    return entries


def _append_manifest(path, entry):
    with open(path, "a") as handle:
        handle.write(json.dumps(entry) + "\n")
        handle.flush()
        os.fsync(handle.fileno())


def summary(rows, total):
    count = {s: sum(r["status"] == s for r in rows) for s in ("filled", "skipped", "failed")}
    missing = total - len(rows)
    return (f"{count['filled']} filled, {count['skipped']} up to date, {count['failed']} failed"
            + (f", {missing} not done (interrupted)" if missing else "")
            + f" of {total} takes")


def write_report(outdir, rows, total):
    """``report.csv`` and ``report.json`` (with the summary line) in ``outdir``, atomically."""
    rows = sorted(rows, key=lambda r: r["input"])
    with atomic_output(Path(outdir) / "report.csv", overwrite=True) as tmp:
        with open(tmp, "w", newline="") as handle:
            writer = csv.DictWriter(handle, REPORT_FIELDS)
            writer.writeheader()
            writer.writerows(rows)
    with atomic_output(Path(outdir) / "report.json", overwrite=True) as tmp:
        tmp.write_text(json.dumps({"summary": summary(rows, total), "total": total,
                                   "takes": rows}, indent=1))


class ProgressLine:
    """``batch: 37/120 takes (2 failed), 1m20s left`` on stderr, redrawn in place."""

    def __init__(self, quiet=False):
        self.quiet = quiet

    def __call__(self, done, total, failed, seconds_left):
        if self.quiet:
            return
        left = int(seconds_left or 0)
        eta = "" if seconds_left is None else f", {left // 60}m{left % 60:02d}s left"
        bar = "#" * int(30 * done / max(total, 1))
        sys.stderr.write(f"\rbatch [{bar:<30}] {done}/{total} takes"
                         + (f" ({failed} failed)" if failed else "") + eta + "   ")
        sys.stderr.flush()

    def done(self):
        if not self.quiet:
            sys.stderr.write("\n")
