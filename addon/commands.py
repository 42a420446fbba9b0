"""The command line's Blender commands (``mocap-gapfill blend``, and the scenes of
``mocap-gapfill demo``); bpy is imported only when one of them runs."""

import os
import sys
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from ..core.backend import DEVICES
from ..core.demo import BONE_GAPS
from ..core.fill import DEFAULT_METHOD, METHODS


def add_commands(sub):
    """Add the Blender subcommands to the core command line's subparsers."""
    p = sub.add_parser("blend", help="fill every gap of the takes in a .blend file (needs the "
                                     "bpy module); saves a new file")
    add_arguments(p, with_input=True)
    p.set_defaults(func=cmd_blend)
    sub.choices["demo"].set_defaults(func=cmd_demo)


def add_arguments(parser, with_input=False):
    """Options of the batch fill, shared by ``mocap-gapfill blend`` and ``blender -c``."""
    if with_input:
        parser.add_argument("blend", help="the .blend file to clean")
    parser.add_argument("--kb", "-k", help="knowledge-base file (.npz)")
    parser.add_argument("--objects", nargs="+", default=None,
                        help="armatures / marker-set empties to fill (default: every take)")
    parser.add_argument("--output", "-o", help="where to save (default: <input>_filled.blend)")
    parser.add_argument("--overwrite", action="store_true",
                        help="allow saving over the input or an existing output")
    parser.add_argument("--method", default=DEFAULT_METHOD, choices=METHODS)
    parser.add_argument("-K", type=int, default=0, help="neighbours per frame (0: automatic)")
    parser.add_argument("--max-gap", type=int, default=0, help="leave longer gaps unfilled")
    parser.add_argument("--no-suspects", action="store_true",
                        help="do not treat jumping or stretching keys as gaps, nor repair "
                             "label swaps, spikes and ghosts")
    parser.add_argument("--device", default="auto", choices=DEVICES,
                        help="where the knn search runs (torch is optional)")
    parser.add_argument("--stats", metavar="FILE.json", help="also write what was done as JSON "
                        "(gaps, longest gap, samples filled; for mocap-gapfill batch)")


def cmd_demo(args):
    """The core demo (numbers, KBs, plot), then the Blender scenes when bpy is installed; a
    short summary, every step with ``--verbose``."""
    from ..core.demo import quiet, run_demo, summary

    report = print if args.verbose else quiet
    demo = run_demo(args.outdir, report=report)
    try:
        import bpy  # noqa: F401
    except ImportError:
        print("\n".join(summary(demo, args.outdir)))
        print("the bpy module is not installed: Blender scenes skipped "
              "(bash tools/setup.sh installs it)")
        return 0
    with _blender_output(args.verbose):  # Blender prints each operator's report
        demo_scenes(args.outdir, demo, report)
        real_scenes(args.outdir, report)
    print("\n".join(summary(demo, args.outdir, scenes=True)))
    return 0


@contextmanager
def _blender_output(shown):
    """What Blender itself prints to standard output (operator reports, the BVH importer), shown
    or sent to the null device."""
    if shown:
        yield
        return
    sys.stdout.flush()
    saved = os.dup(1)
    with open(os.devnull, "w") as null:
        os.dup2(null.fileno(), 1)
        try:
            yield
        finally:
            sys.stdout.flush()
            os.dup2(saved, 1)
            os.close(saved)


def cmd_blend(args):
    from . import batch

    batch.write_stats(args, batch.blend_main(args))
    return 0


def demo_scenes(outdir, demo, report=print):
    """Blender scenes of the demo: an armature whose bones lost keys and a marker set with gaps,
    saved as ``mocap_demo.blend``; filled through the add-on's operator and saved as
    ``mocap_demo_filled.blend``. Returns the RMSE (mm) measured on Blender's own evaluation."""
    import bpy

    from . import register as register_addon, unregister as unregister_addon

    outdir = Path(outdir).resolve()
    register_addon()
    try:
        bpy.ops.wm.read_homefile(use_empty=True)
        context = bpy.context
        arm, root = build_demo_scene(context, demo)
        markers = demo["markers"]
        bpy.ops.wm.save_as_mainfile(filepath=str(outdir / "mocap_demo.blend"))
        report(f"scene with gaps -> {outdir / 'mocap_demo.blend'}")
        scores = {}
        for owner, kb, truth in ((arm, demo["kb_skeleton"], demo["skeleton"]),
                                 (root, demo["kb_markers"], markers)):
            context.scene.mocap_gapfill.kb_path = str(kb)
            bpy.ops.mocap_gapfill.fill_gaps(objects=owner.name)
            scores[owner.name] = take_rmse(owner, truth, context.scene)
            report(f"  Blender {owner.name}: RMSE over the gap samples "
                   f"{scores[owner.name]:6.1f} mm")
        bpy.ops.wm.save_as_mainfile(filepath=str(outdir / "mocap_demo_filled.blend"))
        report(f"filled scene -> {outdir / 'mocap_demo_filled.blend'} "
               "(Mocap tab: switch Original / Recovered)")
        return scores
    finally:
        unregister_addon()


def real_scenes(outdir, report=print):
    """Blender scenes of the real sample takes (:mod:`.samples`), each saved as found
    (``cmu_*.blend``) and after "Fill All Gaps" with the starter knowledge base without the
    take's subject (``cmu_*_filled.blend``). Returns ``{bone: (fill_mm, interp_mm)}`` for the
    armature's gaps, measured on Blender's own evaluation against the take before its keys were
    deleted."""
    import bpy

    from . import bridge, register as register_addon, samples, unregister as unregister_addon

    outdir = Path(outdir).resolve()
    scores = {}
    register_addon()
    try:
        for kind, take in samples.SAMPLES.items():
            if kind == "MARKERS" and not _has_ezc3d():
                report(f"ezc3d is not installed: the scene of {take} is skipped")
                continue
            stem = f"cmu_{take.split('.')[0]}_{kind.lower()}"
            bpy.ops.wm.read_homefile(use_empty=True)
            scene = bpy.context.scene
            scene.mocap_gapfill.detect_suspects = False
            owner, truth = samples.load(bpy.context, kind)
            bpy.ops.wm.save_as_mainfile(filepath=str(outdir / f"{stem}.blend"), compress=True)
            before = bridge.read_take(owner, scene)
            bpy.ops.mocap_gapfill.fill_gaps(objects=owner.name)
            bpy.ops.wm.save_as_mainfile(filepath=str(outdir / f"{stem}_filled.blend"),
                                        compress=True)
            after = bridge.read_take(owner, scene)
            report(f"Blender scene of {take} (CMU), {len(owner.mocap_gapfill.gaps)} gaps -> "
                   f"{outdir / stem}.blend; filled with "
                   f"{Path(scene.mocap_gapfill.kb_path).name} -> {outdir / stem}_filled.blend")
            if kind == "MARKERS":
                was, left = (np.isnan(t.positions[..., 0]) for t in (before, after))
                report(f"  {int(was.sum())} marker samples missing, {int((was & ~left).sum())} "
                       "filled (the rest: points the knowledge base and the take's other "
                       "markers cannot place)")
                continue
            scores = samples.bone_gap_scores(truth, before, after)
            how = {g.point: g.how for g in owner.mocap_gapfill.gaps}
            report("  joints below each gapped bone, RMSE on Blender's evaluation: " + ", ".join(
                f"{bone} {fill:.1f} mm by {how.get(bone) or 'the fill'} (Blender's "
                f"interpolation {interp:.1f})" for bone, (fill, interp) in scores.items()))
        return scores
    finally:
        unregister_addon()


def _has_ezc3d():
    try:
        import ezc3d  # noqa: F401
    except ImportError:  # e.g. a distribution's Blender without the bundled wheels
        return False
    return True


def build_demo_scene(context, demo):
    """The demo's armature (keys removed from three bones) and marker set (six markers with
    gaps) in the current scene, gaps detected; returns ``(armature, marker_set)``."""
    import bpy

    from . import bridge, compat
    from .samples import remove_keys

    arm = bridge.import_armature(context, demo["skeleton"], "Walker")
    remove_keys(arm, [(name, a + 1, b + 1) for name, a, b in BONE_GAPS])
    markers = demo["markers"]
    gappy = markers.replace(positions=np.where(demo["marker_gaps"][..., None], np.nan,
                                               markers.positions))
    root = bridge.import_markers(context, gappy, "WalkerMarkers")
    for owner in (arm, root):
        compat.select_objects(context, [owner], active=owner)
        bpy.ops.mocap_gapfill.detect_gaps()
    context.scene.mocap_gapfill.kb_path = str(demo["kb_skeleton"])
    return arm, root


def take_rmse(owner, truth, scene):
    """RMSE (mm) between a take as Blender now plays it and the truth, over the samples its gap
    list covers (converted to points for armatures)."""
    from . import bridge, gaps

    take = bridge.read_take(owner, scene)
    mask = gaps.take_missing(owner, take)
    ref = truth.select(list(take.names)).positions[:len(mask)]
    err = (take.positions * take.metres - ref)[mask]
    return float(1000 * np.sqrt(np.mean(np.sum(err ** 2, axis=1))))
