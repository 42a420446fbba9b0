"""Headless batch cleanup: detect and fill every gap of a .blend file's takes, save a new file.

- ``blender -b scene.blend -c mocap_gapfill --kb KB.npz [--objects A B] [--output OUT.blend]``
  (registered with ``bpy.utils.register_cli_command``);
- ``mocap-gapfill blend SCENE.blend --kb KB.npz -o OUT.blend``: the same through the bpy module;
- ``blender -b -c mocap_gapfill batch INPUT... -o OUTDIR``: ``mocap-gapfill batch`` over a
  library (files and folders of takes; see ``core/batch.py``).

The input file is never overwritten unless ``--overwrite`` is given.
"""

import argparse
from pathlib import Path

import bpy

from ..core.errors import GapFillError
from ..core.fill import REVIEW_FIRST, USES_KB
from . import gaps
from .commands import add_arguments

_cli = None


def output_path(source, output, overwrite):
    """Where to save: never the input, nor an existing file, unless ``overwrite``."""
    source = Path(source).resolve() if source else None
    if output:
        out = Path(output).resolve()
    elif source:
        out = source.with_name(source.stem + "_filled.blend")
    else:
        raise GapFillError("the scene was never saved: give --output")
    if not overwrite and (out == source or out.exists()):
        raise GapFillError(f"{out} exists (or is the input); pass --overwrite to replace it")
    return out


def run(args, report=print):
    """Detect and fill the gaps of the open file's takes and save; returns what it did:
    ``output``, ``gaps``, ``longest_gap`` (frames), ``samples_filled``, and for marker gaps
    filled by ``auto`` the largest error their copies expect (``expected_mm``) and the gaps to
    review first (``review_first``: ``object: marker first-last ~N mm``, scene frames)."""
    context = bpy.context
    scene = context.scene
    out = output_path(bpy.data.filepath, args.output, args.overwrite)
    # without --kb, each take gets the starter knowledge base that fits it (gaps.plan_fill)
    kb = gaps.load_kb_cached(args.kb) if args.kb and args.method in USES_KB else None
    owners = (gaps.takes_in(context, args.objects) if args.objects else gaps.all_takes(scene))
    if not owners:
        raise GapFillError("no armature or marker set in this file")
    found = []
    for owner in owners:
        gaps.detect(owner, scene, suspects=not args.no_suspects)
        problems = [i for i, g in enumerate(owner.mocap_gapfill.gaps) if g.kind in gaps.REPAIRED]
        if problems:  # label swaps, spikes and ghosts first, as the Repair button does
            done = gaps.repair(owner, gaps.read_original(owner, scene), problems)
            report(f"{owner.name}: repaired {done} label swaps, spikes or ghosts first")
        report(f"{owner.name}: {len(owner.mocap_gapfill.gaps)} gaps")
        found += [g.last - g.first + 1 for g in owner.mocap_gapfill.gaps]
    owners = [o for o in owners if len(o.mocap_gapfill.gaps)]
    written = 0
    if owners:
        plans, work = gaps.plan_fill(context, owners, False, args.method, args.K, args.max_gap, kb,
                                     args.device)

        def progress(fraction, message):
            report(f"{100 * fraction:3.0f} % {message}")

        written = gaps.apply_fill(context, plans, work(progress, lambda: False))
        for plan in plans:
            for message in plan.messages:
                report(f"{plan.owner}: {message}")
            owner = bpy.data.objects[plan.owner]
            for gap in owner.mocap_gapfill.gaps:
                if gap.how:
                    report(f"{plan.owner}: {gap.point} {gap.first}-{gap.last}: "
                           + "; ".join(gaps.describe(gap, owner.type == "ARMATURE")))
        report(f"filled {written} samples")
    bpy.ops.wm.save_as_mainfile(filepath=str(out), copy=True)
    report(f"saved {out}")
    worst = sorted(((g.expected_mm, owner.name, g.point, g.first, g.last) for owner in owners
                    for g in owner.mocap_gapfill.gaps if g.expected_mm > 0), reverse=True)
    worst = worst[:REVIEW_FIRST]
    return {"output": str(out), "gaps": len(found), "longest_gap": max(found, default=0),
            "samples_filled": written, "expected_mm": round(worst[0][0], 1) if worst else "",
            "review_first": "; ".join(f"{name}: {point} {first}-{last} ~{mm:.0f} mm"
                                      for mm, name, point, first, last in worst)}


def cli_command(argv):
    """``blender -b scene.blend -c mocap_gapfill ...`` (or ``... -c mocap_gapfill batch ...``:
    the command line's batch over a library); returns the exit code."""
    if argv and argv[0] == "batch":
        return core_batch(argv[1:])
    parser = argparse.ArgumentParser(prog="blender -b FILE.blend -c mocap_gapfill",
                                     description=__doc__.split("\n\n")[0])
    add_arguments(parser)
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:
        return exc.code or 0
    try:
        write_stats(args, run(args))
    except (GapFillError, ValueError, OSError) as exc:
        print(f"mocap_gapfill: error: {exc}")
        return 1
    return 0


def write_stats(args, done):
    """``--stats FILE.json``: what a run did, for ``mocap-gapfill batch``."""
    if args.stats:
        import json

        Path(args.stats).write_text(json.dumps(done))


def core_batch(argv):
    """``mocap-gapfill batch`` in a plain Python process of Blender's interpreter: its worker
    processes import the package by its own name (inside Blender it is an extension module of
    ``bl_ext``, which only Blender can import). Returns its exit code."""
    import os
    import subprocess
    import sys

    root = Path(__file__).resolve().parents[1]
    top = __name__.rsplit(".addon", 1)[0]
    name = top if "." not in top else root.name
    # Blender's scripts/modules hold a ``bpy`` package that only Blender can import: left out
    path = [str(root.parent)] + [p for p in sys.path
                                 if p and not (Path(p) / "bpy" / "__init__.py").is_file()]
    # a .blend take of the batch opens in this Blender: ``blender -b FILE -c mocap_gapfill``
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(path),
               MOCAP_GAPFILL_BLENDER=bpy.app.binary_path or "")
    return subprocess.call([sys.executable, "-m", name, "batch", *argv], env=env)


def blend_main(args, report=print):
    """``mocap-gapfill blend``: open the file in the bpy module, register the add-on, run."""
    source = Path(args.blend)
    if not source.is_file():
        raise GapFillError(f"no such file: {source}")
    args.output = str(output_path(source, args.output, args.overwrite))
    bpy.ops.wm.open_mainfile(filepath=str(source), load_ui=False)
    from . import register as register_addon, unregister as unregister_addon

    register_addon()
    try:
        return run(args, report)
    finally:
        unregister_addon()


def register():
    global _cli
    if hasattr(bpy.utils, "register_cli_command"):
        _cli = bpy.utils.register_cli_command("mocap_gapfill", cli_command)


def unregister():
    global _cli
    if _cli is not None:
        bpy.utils.unregister_cli_command(_cli)
        _cli = None
