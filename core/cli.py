"""The ``mocap-gapfill`` command line (also ``python -m mocap_gapfill``).

Subcommands: ``info`` (what is in a file), ``convert`` (any readable format to C3D, NPZ or CSV).
Errors of the user's input are printed as one line on stderr, never as a traceback.
"""

import argparse
import json
import sys
from pathlib import Path

from .errors import GapFillError
from .io import READ_FORMATS, WRITE_FORMATS, read_motion, write_motion
from .motion import UNIT_SCALES


def _add_read_options(parser):
    group = parser.add_argument_group("reading")
    group.add_argument("--asf", help="skeleton for an AMC (default: the ASF beside it)")
    group.add_argument("--units", choices=sorted(UNIT_SCALES),
                       help="unit of a BVH file (default: guessed from the skeleton's height)")
    group.add_argument("--skip-frames", type=int, default=0, metavar="N",
                       help="drop N leading frames (e.g. 1 for a BVH reference pose)")
    group.add_argument("--end-sites", action="store_true", help="BVH: include End Site points")


def _read_kwargs(args):
    return {"asf": args.asf, "units": args.units, "skip_frames": args.skip_frames,
            "end_sites": args.end_sites}


def _format_summary(s):
    pct = 100.0 * s["missing_fraction"]
    gaps = (f"{pct:.2f} % in {s['gaps']} gaps; longest {s['longest_gap_frames']} frames "
            f"({s['longest_gap_point']})" if s["gaps"] else "none")
    return "\n".join([
        s["path"],
        f"  format   {s['format']} ({s['kind']}, {s['limbs']} limbs)",
        f"  frames   {s['frames']} at {s['fps']:g} fps ({s['seconds']:.2f} s)",
        f"  points   {s['points']}",
        f"  units    {s['units']}, {s['up_axis'].upper()} up in the file "
        "(read as metres, Z up)",
        f"  missing  {gaps}",
    ])


def cmd_info(args):
    results, failed = [], 0
    for path in args.files:
        try:
            summary = read_motion(path, **_read_kwargs(args)).summary()
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


def cmd_convert(args):
    src, dst = Path(args.input), Path(args.output)
    if dst.exists() and dst.resolve() == src.resolve() and not args.force:
        raise GapFillError("output is the input file; pass --force to replace it")
    motion = read_motion(src, **_read_kwargs(args))
    write_motion(motion, dst, overwrite=args.force)
    print(f"wrote {dst} ({motion.n_frames} frames, {motion.n_points} points)")
    return 0


def build_parser():
    parser = argparse.ArgumentParser(
        prog="mocap-gapfill",
        description="Fill gaps in motion capture from a knowledge base of clean motion.")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    p = sub.add_parser("info", help="frames, rate, points, units and gaps of motion files")
    p.add_argument("files", nargs="+", metavar="FILE", help=f"{', '.join(READ_FORMATS)}")
    p.add_argument("--json", action="store_true", help="print JSON instead of text")
    _add_read_options(p)
    p.set_defaults(func=cmd_info)

    p = sub.add_parser("convert", help="convert a motion file to C3D, NPZ or CSV")
    p.add_argument("input", help=f"{', '.join(READ_FORMATS)}")
    p.add_argument("output", help=f"{', '.join(WRITE_FORMATS)} (chosen by extension)")
    p.add_argument("--force", action="store_true", help="replace OUTPUT if it exists")
    _add_read_options(p)
    p.set_defaults(func=cmd_convert)
    return parser


def main(argv=None):
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except GapFillError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
