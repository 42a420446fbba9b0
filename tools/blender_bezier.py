"""What one click in the Graph Editor gives an animator (issue 15): the ``bones`` protocol's
gaps as Blender's own F-curves show them once the keys left either side are Bezier (Key >
Interpolation Mode > Bezier), with the handles and smoothing new keys and F-curves get by default
in Blender 4.2-5.2 (``AUTO_CLAMPED``, ``Continuous Acceleration``), evaluated by Blender itself
(bpy), beside the figures of an ``evaluate --protocol bones --json`` run on the same takes and
gaps (the protocol's gaps are seeded: the same here). The ``hermite`` baseline is this project's
cubic from the keys' one-frame velocities; this is the curve Blender draws.

    .venv/bin/python tools/blender_bezier.py docs/results/bones_bvh43.json --skip-frames 6
    .venv/bin/python tools/blender_bezier.py docs/results/bones_amc31.json

Prints per setting the mean over takes (mm, RMSE over the joints the gapped bones move) of
``interp`` (beside the run's own: a check that the gaps are the run's), Blender's Bezier,
``hermite`` and the run's default method, with the default over the Bezier (the mean, and per
take); and the gaps where the Bezier is worse than the interpolation by more than 10 % + 2 mm.
"""

import argparse
import json
from collections import defaultdict
from pathlib import Path

import numpy as np

from mocap_gapfill.core.bonefill import fill_bones
from mocap_gapfill.core.evaluate import BONE_SETTINGS, bone_errors, punch_bone_gaps
from mocap_gapfill.core.io import read_rig_take
from mocap_gapfill.core.rig import basis_matrices, interpolate_channels


def blender_bezier(values, gaps):
    """``values`` (frames, bones, k) with each gap's frames (``gaps`` (frames, bones) bool) as a
    Blender F-curve per bone and channel, keyed on every frame outside its gaps with Bezier keys
    of the default handles and smoothing, evaluates there (held at clip ends, as Blender
    does)."""
    import bpy

    from mocap_gapfill.addon import compat

    holder = bpy.data.objects.new("bezier holder", None)
    holder["c"] = 0.0
    holder.keyframe_insert('["c"]', frame=0)  # an action and its curves, on every version
    action = holder.animation_data.action
    curves = compat.fcurves(holder)
    out = np.array(values, dtype=float)
    frames = np.arange(len(out))
    try:
        for b in np.flatnonzero(gaps.any(axis=0)):
            keyed = ~gaps[:, b]
            if not keyed.any():
                continue
            for k in range(out.shape[2]):
                curve = curves.new(data_path=f'["b{b}c{k}"]')
                points = curve.keyframe_points
                points.add(int(keyed.sum()))
                points.foreach_set("co", np.c_[frames[keyed], out[keyed, b, k]].ravel()
                                   .astype(np.float32))
                for point in points:
                    point.interpolation = "BEZIER"
                    point.handle_left_type = point.handle_right_type = "AUTO_CLAMPED"
                curve.auto_smoothing = "CONT_ACCEL"
                curve.update()
                out[~keyed, b, k] = [curve.evaluate(float(f)) for f in frames[~keyed]]
                curves.remove(curve)
    finally:
        bpy.data.objects.remove(holder)
        bpy.data.actions.remove(action)
    return out


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("results", help="an `evaluate --protocol bones --json` file")
    parser.add_argument("--skip-frames", type=int, default=0, help="as the run had it")
    args = parser.parse_args()
    run = json.loads(Path(args.results).read_text())
    if run["protocol"] != "bones":
        raise SystemExit(f"{args.results}: protocol {run['protocol']!r}, not 'bones'")
    theirs = {(r["test"], r["setting"], r["method"]): r for r in run["results"]}
    default = run["default_method"]
    table = defaultdict(lambda: defaultdict(list))
    lost = defaultdict(int)
    for test in run["tests"]:
        rig, channels, location, fps = read_rig_take(test, args.skip_frames)
        truth = basis_matrices(rig, channels, location)
        for n, l in BONE_SETTINGS:  # those of the run, in the protocol's order
            setting = f"n={n},l={l}"
            if (Path(test).name, setting, default) not in theirs:
                continue
            gaps = punch_bone_gaps(rig, len(channels), (n, l), run["seed"])
            seen = interpolate_channels(channels, gaps)
            interp = bone_errors(rig, basis_matrices(rig, seen, location), truth, gaps)
            bezier = bone_errors(rig, basis_matrices(rig, blender_bezier(channels, gaps),
                                                     location), truth, gaps)
            hermite = bone_errors(rig, fill_bones(rig, seen, location, gaps, fps,
                                                  method="hermite"), truth, gaps)
            name = Path(test).name
            row = table[setting]
            for key, scores in (("interp", interp), ("bezier", bezier), ("hermite", hermite)):
                row[key].append(scores["rmse_missing_mm"])
            row[default].append(theirs[name, setting, default]["rmse_missing_mm"])
            lost[setting] += int(np.sum(np.array(bezier["gaps_mm"])
                                        > 1.1 * np.array(interp["gaps_mm"]) + 2))
            lost[setting, "n"] += len(interp["gaps_mm"])
            print(f"{name} {setting}: interp {interp['rmse_missing_mm']:.1f} "
                  f"(run {theirs[name, setting, 'interp']['rmse_missing_mm']:.1f}), "
                  f"Blender's Bezier {bezier['rmse_missing_mm']:.1f}", flush=True)
    print(f"\n| setting | interp | Blender's Bezier | hermite | {default} | {default} / Bezier "
          f"| {default} / Bezier per take (min-max) | hermite / Bezier "
          "| gaps where the Bezier > 1.1 interp + 2 mm |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    for setting, row in table.items():
        mean = {key: float(np.mean(v)) for key, v in row.items()}
        per_take = np.array(row[default]) / np.array(row["bezier"])
        print(f"| {setting} | {mean['interp']:.1f} | {mean['bezier']:.1f} | "
              f"{mean['hermite']:.1f} | {mean[default]:.1f} | "
              f"{mean[default] / mean['bezier']:.2f} | "
              f"{min(per_take):.2f}-{max(per_take):.2f} | "
              f"{mean['hermite'] / mean['bezier']:.2f} | "
              f"{lost[setting]} / {lost[setting, 'n']} |")


if __name__ == "__main__":
    main()
