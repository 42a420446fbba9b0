"""The ``mocap-gapfill`` command line (also ``python -m mocap_gapfill``).

Subcommands: ``info`` (what is in a file), ``convert`` (any readable format to C3D, NPZ or CSV),
``kb build`` (a knowledge base from motion files), ``fill`` (fill the gaps of a file),
``evaluate`` (accuracy of every method on punched gaps). Errors of the user's input are printed
as one line on stderr, never as a traceback; Ctrl-C stops cleanly and writes nothing.
"""

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from . import explain
from .errors import GapFillError
from .backend import DEVICES
from .fill import BASELINES, DEFAULT_METHOD, METHODS, REVIEW_FIRST, worst_first
from .io import READ_FORMATS, WRITE_FORMATS, atomic_output, read_motion, write_motion
from .motion import UNIT_SCALES


def _add_read_options(parser):
    group = parser.add_argument_group("reading")
    group.add_argument("--asf", help="skeleton for an AMC (default: the ASF beside it)")
    group.add_argument("--units", choices=sorted(UNIT_SCALES),
                       help="unit of a BVH file (default: guessed from the skeleton's height)")
    group.add_argument("--skip-frames", type=int, default=0, metavar="N",
                       help="drop N leading frames (e.g. 1 for a BVH reference pose)")
    group.add_argument("--end-sites", action="store_true", help="BVH: include End Site points")
    group.add_argument("--up", choices=["y", "z"],
                       help="the up axis of the file's data, whatever its header says (a take "
                            "that lies on its side is named in a warning)")


def _read_kwargs(args):
    return {"asf": args.asf, "units": args.units, "skip_frames": args.skip_frames,
            "end_sites": args.end_sites, "up": args.up}


def _read(path, args):
    """read_motion with the command's options; warns when the take lies on its side."""
    from .upright import upright_warning

    motion = read_motion(path, **_read_kwargs(args))
    warning = upright_warning(motion)
    if warning:
        print(f"warning: {Path(path).name}: {warning}", file=sys.stderr)
    return motion


def _format_summary(s):
    pct = 100.0 * s["missing_fraction"]
    gaps = (f"{pct:.2f} % in {s['gaps']} gaps; longest {s['longest_gap_frames']} frames "
            f"({s['longest_gap_point']})" if s["gaps"] else "none")
    return "\n".join([
        s["path"],
        f"  format   {s['format']} ({s['kind']}, {s['limbs']} limbs)",
        f"  frames   {s['frames']} at {s['fps']:g} fps ({s['seconds']:.2f} s)",
        f"  points   {s['points']}" + (f" ({s['performers']} performers, split by name "
                                        "prefix when filled)" if s["performers"] > 1 else ""),
        f"  units    {s['units']}, {s['up_axis'].upper()} up in the file "
        "(read as metres, Z up)",
        f"  missing  {gaps}",
    ])


def cmd_info(args):
    results, failed = [], 0
    for path in args.files:
        try:
            summary = _read(path, args).summary()
        except GapFillError as exc:
            failed += 1
            results.append({"path": str(path), "error": str(exc)})
            print(f"error: {exc}", file=sys.stderr)
            continue
        results.append(summary)
        if not args.json:
            print(_format_summary(summary))
    if args.json:
        json.dump(results, sys.stdout, indent=2)
        print()
    return 1 if failed else 0


def _check_output(dst, force, src=None):
    """Refuse, before any work, to replace a file (above all the input) unless forced."""
    dst = Path(dst)
    if dst.exists() and not force:
        if src is not None and dst.resolve() == Path(src).resolve():
            raise GapFillError("output is the input file; pass --force to replace it")
        raise GapFillError(f"{dst} exists; pass --force to replace it")


def cmd_convert(args):
    src, dst = Path(args.input), Path(args.output)
    _check_output(dst, args.force, src)
    motion = _read(src, args)
    write_motion(motion, dst, overwrite=args.force)
    print(f"wrote {dst} ({motion.n_frames} frames, {motion.n_points} points)")
    return 0


class Progress:
    """``progress(fraction, message)`` printing one updating line on stderr."""

    def __init__(self, quiet=False):
        self.quiet = quiet
        self.last = ""

    def __call__(self, fraction, message):
        if self.quiet:
            return
        line = f"\r{100 * fraction:5.1f} % {message}"[:100]
        if line != self.last:
            sys.stderr.write(line.ljust(len(self.last)))
            sys.stderr.flush()
            self.last = line

    def done(self):
        if self.last and not self.quiet:
            sys.stderr.write("\n")
            self.last = ""


def _report(message):
    print(f"note: {message}", file=sys.stderr)


def cmd_kb_build(args):
    from .kb import build_kb

    out = Path(args.output)
    _check_output(out, args.force)
    progress = Progress(args.quiet)
    kb = build_kb(args.sources, fps=args.fps, exclude=args.exclude or (),
                  skip_frames=args.skip_frames, stride=args.stride,
                  read_options={"units": args.units, "end_sites": args.end_sites,
                                "up": args.up},
                  progress=progress, report=_report)
    progress.done()
    kb.save(out, overwrite=args.force)
    print(f"wrote {out}: {kb.size} poses of {len(kb.names)} points at {kb.fps:g} fps "
          f"from {len(kb.sources)} files")
    return 0


def cmd_fill(args):
    from .fill import fill, kb_for_take
    from .kb import load_kb
    from .recover import KnnSettings

    src, dst = Path(args.input), Path(args.output)
    _check_output(dst, args.force, src)
    if args.gap_report:
        if args.method != "auto":
            raise GapFillError("--gap-report says how auto filled each gap: use --method auto")
        if Path(args.gap_report).suffix.lower() not in (".csv", ".json"):
            raise GapFillError(f"--gap-report {args.gap_report}: name a .csv or .json file")
        _check_output(Path(args.gap_report), args.force, src)
    motion = _read(src, args)
    if not args.no_repair:
        motion = _repaired(motion)
    kb, note = kb_for_take(motion.names, args.method, load_kb(args.kb) if args.kb else None,
                           choose="-k KB.npz; make one with 'mocap-gapfill kb build'")
    if note:
        _report(f"no -k given: {note}")
    progress = Progress(args.quiet)
    out, accounts = fill(motion, args.method, kb=kb, progress=progress, report=_report,
                         settings=KnnSettings(k=args.k, device=args.device),
                         max_gap=args.max_gap, return_account=True,
                         trace=_report if args.verbose else None)
    progress.done()
    write_motion(out, dst, overwrite=args.force)
    n_filled = int((motion.missing & ~out.missing).sum())
    left = int(out.missing.sum())
    print(f"wrote {dst}: filled {n_filled} samples with {args.method}"
          + (f", {left} left missing" if left else ""))
    worst = worst_first(accounts or [])[:REVIEW_FIRST]
    if worst:
        print("review first (the largest errors copies of the gaps expect):")
        for a in worst:
            print(f"  {a.point} frames {a.first + 1}-{a.last + 1}: {explain.point_gap([a])}; "
                  f"{explain.expected(a.estimate)}")
    if args.gap_report:
        _write_gap_report(accounts, Path(args.gap_report))
        print(f"wrote {args.gap_report}: {len(accounts)} gaps, worst first")
    return 0


def _repaired(motion):
    """The take with its label swaps, spikes and ghosts repaired (:mod:`.faults`), each said."""
    from .faults import repaired, said

    motion, found = repaired(motion)
    if found:
        print(f"repaired {len(found)} problem{'s' * (len(found) > 1)} before filling "
              "(--no-repair keeps them):")
        for fault in found:
            print(f"  {said(fault)}")
    return motion


def cmd_check(args):
    """``check``: the label swaps, spikes and ghosts of marker files, listed (and as JSON)."""
    from .faults import find_faults, said

    events, failed = {}, 0
    for path in args.files:
        try:
            motion = _read(path, args)
        except GapFillError as exc:
            failed += 1
            print(f"error: {exc}", file=sys.stderr)
            continue
        found = find_faults(motion).faults
        events[str(path)] = [f.as_dict(offset=args.skip_frames) for f in found]
        note = " (a skeleton: labels are checked on marker sets)" if motion.parents else ""
        print(f"{path}: {len(found) or 'no'} problem{'s' * (len(found) != 1)} found{note}")
        for fault in found:
            print(f"  {said(fault).split(':')[0]}")
    if args.json:
        payload = (next(iter(events.values())) if len(args.files) == 1 and events else None)
        with atomic_output(Path(args.json), overwrite=True) as tmp:
            tmp.write_text(json.dumps({"events": payload} if payload is not None
                                      else {"files": {k: {"events": v}
                                                      for k, v in events.items()}}, indent=1))
        print(f"wrote {args.json}")
    return 1 if failed else 0


#: the columns of ``fill --gap-report``: the gap, the copies' RMS error, what filled it in words
#: and the shares of auto's estimates
GAP_REPORT_FIELDS = ("point", "first_frame", "last_frame", "frames", "expected_mm", "filled_from",
                     "rigid", "models", "windows", "own", "spline", "pattern")


def _write_gap_report(accounts, path):
    """Each gap's :class:`~.fill.GapAccount`, the largest expected error first (gaps without
    copies last), as CSV or JSON by ``path``'s extension."""
    import csv

    ordered = worst_first(accounts) + [a for a in accounts if not np.isfinite(a.estimate)]
    rows = [{"point": a.point, "first_frame": a.first + 1, "last_frame": a.last + 1,
             "frames": a.last - a.first + 1,
             "expected_mm": round(1000 * a.estimate, 2) if np.isfinite(a.estimate) else None,
             "filled_from": explain.point_gap([a]),
             **{k: round(getattr(a, k), 4) for k in GAP_REPORT_FIELDS[6:]}} for a in ordered]
    with atomic_output(path, overwrite=True) as tmp:
        if path.suffix.lower() == ".json":
            tmp.write_text(json.dumps(rows, indent=1))
        else:
            with open(tmp, "w", newline="") as f:
                writer = csv.DictWriter(f, GAP_REPORT_FIELDS)
                writer.writeheader()
                writer.writerows(rows)


def cmd_batch(args):
    from .batch import Options, ProgressLine, run_batch, summary

    if args.kb and not Path(args.kb).is_file():
        raise GapFillError(f"no such knowledge-base file: {args.kb}")
    options = Options(kb=str(Path(args.kb).resolve()) if args.kb else None, method=args.method,
                      max_gap=args.max_gap or 0, k=args.k, device=args.device,
                      repair=not args.no_repair)
    progress = ProgressLine(args.quiet)
    rows = []
    try:
        rows = run_batch(args.inputs, args.output, options, engine=args.engine, jobs=args.jobs,
                         address=args.address, fmt=args.format, progress=progress)
    except KeyboardInterrupt:
        progress.done()
        print(f"interrupted: finished takes are kept and skipped by the next run; report in "
              f"{args.output}", file=sys.stderr)
        return 130
    progress.done()
    for row in rows:
        if row["status"] == "failed":
            where = "" if row["error"].startswith(row["input"]) else f"{row['input']}: "
            print(f"failed: {where}{row['error']}", file=sys.stderr)
    print(f"{summary(rows, len(rows))}; report: {Path(args.output) / 'report.csv'}")
    judged = sorted((r for r in rows if r.get("expected_mm") not in (None, "")),
                    key=lambda r: -r["expected_mm"])
    if judged:
        print("takes to review first (the largest error copies of their gaps expect): "
              + ", ".join(f"{Path(r['input']).name} ({r['review_first'].split('; ')[0]})"
                          for r in judged[:REVIEW_FIRST]))
    return 1 if any(row["status"] == "failed" for row in rows) else 0


def cmd_evaluate(args):
    from .evaluate import evaluate, table

    given = sum((bool(args.kb_sources), bool(args.kb), args.no_kb))
    if given != 1:
        raise GapFillError("give the knowledge base: --kb-sources PATH... or --kb KB.npz (or "
                           "--no-kb: auto from the take alone)" + (", one of them" if given else ""))
    progress = Progress(args.quiet)
    if args.protocol == "faults":
        return _evaluate_faults(args, progress)
    if args.protocol in ("bones", "bone-ends"):
        from .bonefill import BONE_BASELINES, BONE_METHODS
        from .evaluate import evaluate_bones

        default, baselines = "auto", BONE_BASELINES
        unknown = sorted(set(args.methods or ()) - set(BONE_METHODS))
        if unknown:
            raise GapFillError(f"protocol {args.protocol} takes the methods "
                               f"{', '.join(BONE_METHODS)}")
        methods = args.methods or list(BONE_METHODS)
        results = evaluate_bones(args.test, args.kb_sources, methods, kb_fps=args.fps,
                                 seed=args.seed, k=args.k, skip_frames=args.skip_frames,
                                 settings=args.settings, exclude=args.exclude_kb or (),
                                 kb_file=args.kb, progress=progress, report=_report,
                                 ends=args.protocol == "bone-ends")
    else:
        default, baselines = DEFAULT_METHOD, BASELINES
        unknown = sorted(set(args.methods or ()) - set(METHODS))
        if unknown:
            raise GapFillError(f"unknown methods {', '.join(unknown)}")
        methods = args.methods or list(METHODS)
        results = evaluate(args.protocol, args.test, args.kb_sources, methods=methods,
                           fps=args.fps, seed=args.seed, k=args.k, skip_frames=args.skip_frames,
                           settings=args.settings, exclude=args.exclude_kb or (),
                           gap_sources=args.gap_sources, kb_file=args.kb, progress=progress,
                           report=_report)
    progress.done()
    if not results:
        raise GapFillError("nothing to score: the test takes are too short for every setting "
                           "asked for (no gaps)")
    print(table(results))
    if args.json:
        payload = {"protocol": args.protocol, "default_method": default,
                   "baselines": [m for m in baselines if m in methods], "fps": args.fps,
                   "seed": args.seed, "k": args.k,
                   "tests": [_data_path(t) for t in args.test],
                   "kb_sources": [_data_path(s) for s in args.kb_sources or [args.kb] if s],
                   "results": results}
        Path(args.json).write_text(json.dumps(payload, indent=1))
        print(f"wrote {args.json}")
    return 0


def _evaluate_faults(args, progress):
    """``evaluate --protocol faults``: swaps, spikes and ghosts injected, found and repaired."""
    from .evaluate import _full_kb
    from .faulteval import evaluate_faults, fault_table

    kb = _full_kb(args.kb_sources, args.kb, args.fps, args.skip_frames, args.exclude_kb or (),
                  _report)
    results = evaluate_faults(args.test, kb, fps=args.fps, seed=args.seed, progress=progress,
                              report=None if args.quiet else _report)
    progress.done()
    print(fault_table(results))
    if args.json:
        payload = {"protocol": "faults", "fps": args.fps, "seed": args.seed,
                   "tests": [_data_path(t) for t in args.test],
                   "kb_sources": [_data_path(s) for s in args.kb_sources or [args.kb] if s],
                   "results": results}
        with atomic_output(Path(args.json), overwrite=True) as tmp:
            tmp.write_text(json.dumps(payload, indent=1))
        print(f"wrote {args.json}")
    return 0


def _data_path(path):
    """``path`` as the evaluation's JSON names it: under the test data folder
    (``MOCAP_GAPFILL_DATA``), from there on (``$MOCAP_GAPFILL_DATA/cmu/...``)."""
    import os

    data = os.environ.get("MOCAP_GAPFILL_DATA")
    try:
        return "$MOCAP_GAPFILL_DATA/" + Path(path).resolve().relative_to(
            Path(data).resolve()).as_posix()
    except (TypeError, ValueError):  # no data folder set, or a path outside it
        return str(path)


def cmd_demo(args):
    from .demo import quiet, run_demo, summary

    demo = run_demo(args.outdir, report=print if args.verbose else quiet)
    print("\n".join(summary(demo, args.outdir)))
    return 0


def cmd_bench(args):
    from .bench import run

    out = run(quick=args.quick, repeat=args.repeat)
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=1))
        print(f"wrote {args.json}")
    return 0


def build_parser(extra=None):
    parser = argparse.ArgumentParser(
        prog="mocap-gapfill",
        description="Fill gaps in motion capture from a knowledge base of clean motion.")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    p = sub.add_parser("info", help="frames, rate, points, units and gaps of motion files")
    p.add_argument("files", nargs="+", metavar="FILE", help=f"{', '.join(READ_FORMATS)}")
    p.add_argument("--json", action="store_true", help="print JSON instead of text")
    _add_read_options(p)
    p.set_defaults(func=cmd_info)

    p = sub.add_parser("check", help="list the label swaps, spikes and ghosts of marker files "
                                     "(fill and batch repair them first)")
    p.add_argument("files", nargs="+", metavar="FILE", help=f"{', '.join(READ_FORMATS)}")
    p.add_argument("--json", metavar="OUT", help="write the events as JSON (frames from 0 at "
                                                 "the file's first frame)")
    _add_read_options(p)
    p.set_defaults(func=cmd_check)

    p = sub.add_parser("convert", help="convert a motion file to C3D, NPZ or CSV")
    p.add_argument("input", help=f"{', '.join(READ_FORMATS)}")
    p.add_argument("output", help=f"{', '.join(WRITE_FORMATS)} (chosen by extension)")
    p.add_argument("--force", action="store_true", help="replace OUTPUT if it exists")
    _add_read_options(p)
    p.set_defaults(func=cmd_convert)

    kb = sub.add_parser("kb", help="knowledge bases").add_subparsers(dest="kb_command",
                                                                       required=True)
    p = kb.add_parser("build", help="build a knowledge base from motion files or folders")
    p.add_argument("sources", nargs="+", metavar="SOURCE", help="files or folders (recursive)")
    p.add_argument("-o", "--output", required=True, help="KB.npz to write")
    p.add_argument("--fps", type=float, help="resample to this rate (default: the first file's)")
    p.add_argument("--exclude", action="append", metavar="GLOB",
                   help="leave out matching paths or file names (repeatable)")
    p.add_argument("--stride", type=int, default=1, help="keep every N-th pose")
    p.add_argument("--force", action="store_true", help="replace the output if it exists")
    p.add_argument("--quiet", action="store_true", help="no progress line")
    _add_read_options(p)
    p.set_defaults(func=cmd_kb_build)

    _add_fill_commands(sub)
    _add_evaluate(sub)

    p = sub.add_parser("bench", help="speed of search, local models and fill per backend "
                                     "(numpy, torch CPU/CUDA, cKDTree): medians and ratios")
    p.add_argument("--quick", action="store_true", help="the 65k-pose / 2k-frame cases only")
    p.add_argument("--repeat", type=int, default=3, help="runs per case (median)")
    p.add_argument("--json", metavar="OUT", help="write the results as JSON")
    p.set_defaults(func=cmd_bench)

    p = sub.add_parser("demo", help="fill synthetic takes with gaps (offline) and show the "
                                    "accuracy on known truth")
    p.add_argument("outdir", nargs="?", default="out", help="where to write (default: out)")
    p.add_argument("--verbose", "-v", action="store_true",
                   help="every step and every method compared, not only the summary")
    p.set_defaults(func=cmd_demo)
    if extra is not None:
        extra(sub)
    return parser


def _add_fill_commands(sub):
    """``fill`` and ``batch``."""
    p = sub.add_parser("fill", help="fill the gaps of a motion file")
    p.add_argument("input", help=f"{', '.join(READ_FORMATS)}")
    p.add_argument("-k", "--kb", help="knowledge base (.npz) for the auto, knn and pca methods "
                                      "(default: the starter one shipped for the take's "
                                      "skeleton or marker set, where one fits)")
    p.add_argument("-o", "--output", required=True,
                   help=f"{', '.join(WRITE_FORMATS)} (chosen by extension)")
    p.add_argument("--method", default=DEFAULT_METHOD, choices=METHODS,
                   help="auto (default): the knowledge-base fill blended per point with a "
                        "rigid-body fill, by how well each refills copies of the point's gaps; "
                        "knn: the knowledge base alone; rigid, pattern: the Vicon Nexus / QTM "
                        "fills; the rest for comparison")
    p.add_argument("-K", dest="k", type=int,
                   help="neighbours per frame (knn; default 4096, or the KB size if smaller)")
    p.add_argument("--max-gap", type=int, metavar="FRAMES",
                   help="leave gaps longer than this unfilled")
    p.add_argument("--device", default="auto", choices=DEVICES,
                   help="knn search and models: auto (torch on a CUDA GPU, else torch on the CPU, "
                        "else numpy), numpy, cpu (torch), cuda (torch)")
    p.add_argument("--gap-report", metavar="OUT", help="auto: write per gap the estimates it "
                   "blended and what copies of the gap expect of the error, to review the worst "
                   "first (.csv or .json by extension; frames counted from 1)")
    p.add_argument("--force", action="store_true", help="replace the outputs if they exist")
    p.add_argument("--quiet", action="store_true", help="no progress line")
    p.add_argument("--verbose", "-v", action="store_true",
                   help="also say what each stage of auto did")
    p.add_argument("--no-repair", action="store_true",
                   help="fill as the take is: leave label swaps, spikes and ghosts in place")
    _add_read_options(p)
    p.set_defaults(func=cmd_fill)

    p = sub.add_parser("batch", help="fill a library of takes (files or folders) into a folder, "
                                     "on this machine or a Ray / Dask cluster; resumable")
    p.add_argument("inputs", nargs="+", metavar="INPUT",
                   help="C3D, BVH, ASF/AMC and .blend files, or folders of them (recursive)")
    p.add_argument("-k", "--kb", help="knowledge base (.npz), loaded once per worker (default: "
                                      "the starter one that fits each take)")
    p.add_argument("-o", "--output", required=True, metavar="OUTDIR",
                   help="where the filled takes go, mirroring the input tree")
    p.add_argument("--jobs", type=int, help="worker processes (default: the core count)")
    p.add_argument("--engine", default="local", choices=["local", "ray", "dask"],
                   help="local: a process pool (default); ray / dask: a cluster at --address "
                        "or a local one of --jobs workers (pip install mocap-gapfill[ray] or "
                        "[dask])")
    p.add_argument("--address", help="ray: 'auto' or ray://host:port; dask: the scheduler "
                                     "(tcp://host:8786)")
    p.add_argument("--method", default=DEFAULT_METHOD, choices=METHODS)
    p.add_argument("--max-gap", type=int, metavar="FRAMES",
                   help="leave gaps longer than this unfilled")
    p.add_argument("--format", default="same", choices=["same", "c3d", "npz", "csv"],
                   help="output format (same: C3D stays C3D, BVH and ASF/AMC become .npz; "
                        ".blend files stay .blend)")
    p.add_argument("-K", dest="k", type=int, help="neighbours per frame (knn)")
    p.add_argument("--device", default="auto", choices=DEVICES)
    p.add_argument("--no-repair", action="store_true",
                   help="fill the takes as they are: leave label swaps, spikes and ghosts")
    p.add_argument("--quiet", action="store_true", help="no progress line")
    p.set_defaults(func=cmd_batch)


def _add_evaluate(sub):
    """``evaluate``."""
    p = sub.add_parser("evaluate", help="accuracy of the methods on punched gaps in real data")
    p.add_argument("--protocol", required=True,
                   choices=["joints", "markers", "bodyparts", "shortgaps", "endgaps", "realgaps",
                            "bursts", "bones", "bone-ends", "faults"],
                   help="shortgaps: dropouts of 3-24 frames; endgaps: points missing for "
                        "the first or last 3-120 frames; bursts: 50-100 %% of the points "
                        "gone together for 3-60 frames per 120; "
                        "realgaps: the gaps of real captures (--gap-sources) on complete takes; "
                        "bones: rotation gaps on armatures (BVH, ASF/AMC) at the take's own "
                        "rate; methods auto, knn, match, regress, learn, interp, bezier, hermite, "
                        "slerp, positions; bone-ends: the same, bones keyless for the first or "
                        "last 15-240 frames; faults: label swaps, spikes and ghosts injected "
                        "into marker takes, found, repaired and filled")
    p.add_argument("--test", nargs="+", required=True, metavar="FILE", help="clean test takes")
    p.add_argument("--kb-sources", nargs="+", default=[], metavar="PATH",
                   help="knowledge-base files/folders (the test subject is left out)")
    p.add_argument("--kb", metavar="KB.npz",
                   help="a knowledge-base file instead of --kb-sources (e.g. a starter one; "
                        "the test subject is still left out)")
    p.add_argument("--no-kb", action="store_true",
                   help="no knowledge base: auto fills from the take alone, as on a skeleton or "
                        "marker set no knowledge base fits (the methods that need one score inf)")
    p.add_argument("--methods", nargs="+", metavar="METHOD",
                   help=f"some of {', '.join(METHODS)} (default: all of the protocol's)")
    p.add_argument("--settings", nargs="+", metavar="LABEL",
                   help="only these settings, e.g. 'm=6,l=60' 'rate=0.2'")
    p.add_argument("--gap-sources", nargs="+", default=(), metavar="FILE",
                   help="realgaps: captures whose gaps are transplanted by point name")
    p.add_argument("--fps", type=float, default=60.0,
                   help="evaluation frame rate (default 60; for bones the KB's rate, the takes "
                        "keep their own)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("-K", dest="k", type=int,
                   help="knn neighbours (default 4096, or the KB size if smaller)")
    p.add_argument("--skip-frames", type=int, default=0, metavar="N",
                   help="drop N leading frames of every file (6 for Daz-friendly BVH)")
    p.add_argument("--exclude-kb", action="append", metavar="GLOB",
                   help="leave matching files out of the knowledge base (repeatable)")
    p.add_argument("--json", metavar="OUT", help="write the results as JSON")
    p.add_argument("--quiet", action="store_true", help="no progress line")
    p.set_defaults(func=cmd_evaluate)


def main(argv=None, extra=None):
    """Run the command line; ``extra(subparsers)`` may add commands (the add-on's)."""
    args = build_parser(extra).parse_args(argv)
    try:
        return args.func(args)
    except GapFillError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("\ninterrupted: nothing was written", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
