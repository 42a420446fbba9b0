"""``mocap-gapfill demo``: the main job on a built-in default, offline.

Motion made by this project's own code (:mod:`.synth`): six walking/jogging/turning takes form
two tiny knowledge bases (the skeleton's joints with each bone's rotation, and markers); a seventh
take, in a gait none of them has, gets gaps: three bones of its armature lose their keys over
60-100 frames (one at the clip's end), filled in the space of their rotations as the add-on
fills them (:func:`~.bonefill.fill_bones`) and compared with what Blender shows without a fill
(its interpolation of the keys either side) and the other curves an animator has; six markers
vanish over 70-90 frames (one at the clip's start), filled by the default and compared with the
knowledge-base method alone, the studios' rigid-body fill and linear and spline interpolation.
The RMSE against the known truth is printed and a plot of original vs recovered trajectories is
written.
Then the real takes shipped in ``sample_scenes/`` (CMU): the marker take 01_01 with the gaps it
really has, and the armature take 03_02 with three bones' keys deleted, filled with the starter
knowledge bases without their subject (:func:`run_real_demo`).
The add-on's command line adds the Blender scenes (see ``addon/commands.py``).
"""

from pathlib import Path

import numpy as np

from . import synth
from .evaluate import (bone_errors, complete_take, kb_without, punch_gaps, rmse_mm, subject_of,
                       with_gaps)
from .fill import DEFAULT_METHOD, REVIEW_FIRST, fill, worst_first
from .io import read_motion, write_motion
from .kb import STARTER_DIR, kb_from_motions, motion_turns, starter_kb
from .motion import gap_runs
from .rig import rig_from_motion

FPS = 60.0
FRAMES = 360
#: (bone, first, last) rows whose keys are removed (0-based frames)
BONE_GAPS = (("LeftForeArm", 60, 159), ("RightLeg", 120, 199), ("Spine1", 300, 359))
#: (marker, first, last) samples removed
MARKER_GAPS = (("LELB", 40, 129), ("LWRA", 90, 169), ("RKNE", 150, 229), ("RANK", 170, 249),
               ("RTOE", 200, 279), ("LFHD", 0, 69))
COMPARE = (DEFAULT_METHOD, "knn", "rigid", "linear", "spline")
#: the armature's: the default and the curves an animator already has across deleted keys
#: (Blender's own curves through LINEAR and Bezier keys, a velocity-matched cubic, slerp)
COMPARE_BONES = ("auto", "interp", "bezier", "hermite", "slerp")


def demo_takes():
    """Knowledge-base motions and the test take: ``(kb_skeletons, kb_markers, skeleton,
    markers)``, all complete."""
    kb_sk, kb_mk = [], []
    for i, gait in enumerate(synth.KB_GAITS):
        sk, mk = synth.take(gait, frames=600, fps=FPS, phase=0.7 * i, name=f"kb take {i + 1}")
        kb_sk.append(sk)
        kb_mk.append(mk)
    sk, mk = synth.take(synth.TEST_GAIT, frames=FRAMES, fps=FPS, name="test take")
    return kb_sk, kb_mk, sk, mk


def bone_gap_mask(names, gaps=BONE_GAPS, frames=FRAMES):
    mask = np.zeros((frames, len(names)), dtype=bool)
    for name, a, b in gaps:
        mask[a:b + 1, names.index(name)] = True
    return mask


def run_demo(outdir="out", progress=None, report=print):
    """Build the KBs, fill the test take's gaps, report errors; returns what the scenes need."""
    outdir = Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    kb_sk, kb_mk, skeleton, markers = demo_takes()
    kb_skeleton = kb_from_motions(kb_sk, turns=[motion_turns(m) for m in kb_sk])
    kb_markers = kb_from_motions(kb_mk)
    kb_skeleton.save(outdir / "kb_skeleton.npz", overwrite=True)
    kb_markers.save(outdir / "kb_markers.npz", overwrite=True)
    report(f"knowledge bases: {kb_skeleton.size} poses of {len(kb_skeleton.names)} joints with "
           f"each bone's rotation, {kb_markers.size} poses of {len(kb_markers.names)} markers "
           f"({len(synth.KB_GAITS)} synthetic takes) -> {outdir}/kb_*.npz")

    bone_gaps = bone_gap_mask(skeleton.names)
    rig, channels, location = rig_from_motion(skeleton)
    report(f"armature: {FRAMES} frames at {FPS:g} fps, keys deleted: "
           + ", ".join(f"{name} {a}-{b}" for name, a, b in BONE_GAPS)
           + f" (the clip ends at {FRAMES - 1})")
    scores = {("skeleton", method): mm for method, mm in bone_scores(
        rig, channels, location, bone_gaps, FPS, kb_skeleton, COMPARE_BONES).items()}
    for method in COMPARE_BONES:
        report(f"  {method:7s} RMSE over the joints the gapped bones move "
               f"{scores[('skeleton', method)]:7.1f} mm")
    marker_miss = bone_gap_mask(markers.names, MARKER_GAPS)
    query = markers.replace(positions=np.where(marker_miss[..., None], np.nan,
                                               markers.positions))
    report(f"markers: {FRAMES} frames at {FPS:g} fps, {int(marker_miss.sum())} of "
           f"{marker_miss.size} samples missing")
    for method in COMPARE:
        result = fill(query, method, kb=kb_markers, progress=progress)
        scores[("markers", method)] = rmse_mm(result, markers, marker_miss)
        report(f"  {method:7s} RMSE over missing samples {scores[('markers', method)]:7.1f} mm")
        if method == DEFAULT_METHOD:
            filled = result
            out = _write_c3d_or_npz(result, outdir / "demo_markers_filled.c3d")
            report(f"filled markers -> {out}")
    plot = write_plot(outdir / "demo_markers.svg", markers, query, filled,
                      fill(query, "linear"), "LWRA")
    report(f"plot of original vs recovered -> {plot}")
    real = run_real_demo(outdir, report)
    return {"scores": scores, "real_scores": real, "skeleton": skeleton, "markers": markers,
            "bone_gaps": bone_gaps,
            "marker_gaps": marker_miss, "kb_skeleton": outdir / "kb_skeleton.npz",
            "kb_markers": outdir / "kb_markers.npz"}


# ---- real takes shipped in sample_scenes/ (CMU), filled with the starter knowledge bases ------
#: CMU 01_01 (41 markers, 120 fps) with the gaps it really has (RBAC: its last 30 frames)
REAL_MARKERS = "01_01.c3d"
#: CMU 03_02 (Daz-friendly BVH, 120 fps) and the bones an animator deleted keys of (frames)
REAL_ARMATURE = "03_02.bvh.gz"
REAL_BONE_GAPS = (("lForeArm", 120, 219), ("rShin", 150, 239), ("chest", 300, 359))


def run_real_demo(outdir="out", report=print):
    """Fill the real sample takes with the starter knowledge bases (their subject left out, as
    for a take the KB has never seen) and print the accuracy where the truth is known; returns
    ``{(take, method): rmse_mm}``."""
    outdir = Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    scores = {}
    try:
        import ezc3d  # noqa: F401
    except ImportError:  # e.g. a distribution's Blender without the bundled wheels
        report(f"ezc3d is not installed: the real marker take {REAL_MARKERS} is skipped")
    else:
        _real_markers(outdir, scores, report)
    _real_armature(scores, report)
    return scores


def _real_markers(outdir, scores, report):
    take = read_motion(STARTER_DIR / REAL_MARKERS)
    path, kb = starter_kb(take.names)
    kb = kb_without(kb, subject_of(REAL_MARKERS))
    report(f"real markers {REAL_MARKERS} (CMU): {take.n_frames} frames at {take.fps:g} fps, "
           f"{int(take.missing.sum())} samples missing in {len(take.gap_runs())} real gaps; "
           f"knowledge base {path.name} without subject {subject_of(REAL_MARKERS)} "
           f"({kb.size} poses)")
    filled = fill(take, DEFAULT_METHOD, kb=kb, report=report)
    out = _write_c3d_or_npz(filled, outdir / f"{REAL_MARKERS.split('.')[0]}_filled.c3d")
    report(f"  filled {int((take.missing & ~filled.missing).sum())} samples "
           f"({int(filled.missing.sum())} left: points the knowledge base and the take's other "
           f"markers cannot place) -> {out}")
    # where the truth is known: 10 % of the markers hidden per 60 frames of the complete frames
    truth = complete_take(take, kb.names)
    miss = punch_gaps(truth.n_frames, truth.n_points, "markers", 0.1, np.random.default_rng(0))
    query = with_gaps(truth, miss)
    filled, accounts = fill(query, DEFAULT_METHOD, kb=kb, return_account=True)
    scores[(REAL_MARKERS, DEFAULT_METHOD)] = rmse_mm(filled, truth, miss)
    for method in ("rigid", "linear"):
        scores[(REAL_MARKERS, method)] = rmse_mm(fill(query, method, kb=kb), truth, miss)
    report("  10 % of the markers hidden per 60 frames, RMSE over them: " + ", ".join(
        f"{m} {scores[(REAL_MARKERS, m)]:.1f} mm" for m in (DEFAULT_METHOD, "rigid", "linear")))
    # what a technician reviews first: the gaps whose copies expect the largest error
    error = np.linalg.norm(filled.positions - truth.positions, axis=2)
    came_out = {a: 1000 * np.sqrt(np.mean(error[a.first:a.last + 1, truth.names.index(a.point)]
                                           ** 2)) for a in worst_first(accounts)[:REVIEW_FIRST]}
    report("  gaps to review first, by what copies of them expect (came out): " + ", ".join(
        f"{a.summary()} ({mm:.0f})" for a, mm in came_out.items()))


def bone_scores(rig, channels, location, gaps, fps, kb, methods):
    """``{method: RMSE (mm)}`` of each method's fill of an armature's bone gaps (``gaps``:
    (frames, bones) bool, keys deleted) over the joints the gapped bones move, against the take
    as keyed."""
    from .bonefill import fill_bones
    from .rig import basis_matrices, interpolate_channels

    truth = basis_matrices(rig, channels, location)
    seen = interpolate_channels(channels, gaps)  # what Blender shows across the deleted keys
    return {method: bone_errors(rig, fill_bones(rig, seen, location, gaps, fps, kb=kb,
                                                method=method), truth, gaps)["rmse_missing_mm"]
            for method in methods}


def _real_armature(scores, report):
    from .formats.bvh import read_bvh_rig

    rig, channels, location, fps = read_bvh_rig(STARTER_DIR / REAL_ARMATURE)
    path, kb = starter_kb(rig.names)
    kb = kb_without(kb, subject_of(REAL_ARMATURE))
    gaps = np.zeros(channels.shape[:2], dtype=bool)
    for name, a, b in REAL_BONE_GAPS:
        gaps[a:b + 1, rig.names.index(name)] = True
    report(f"real armature {REAL_ARMATURE} (CMU, Daz-friendly BVH as Blender imports it): "
           f"{len(channels)} frames at {fps:g} fps, keys deleted: "
           + ", ".join(f"{n} {a}-{b}" for n, a, b in REAL_BONE_GAPS)
           + f"; knowledge base {path.name} without subject {subject_of(REAL_ARMATURE)}")
    for method, mm in bone_scores(rig, channels, location, gaps, fps, kb,
                                  ("auto", "interp", "bezier")).items():
        scores[(REAL_ARMATURE, method)] = mm
    report(f"  joints below the gapped bones, RMSE: auto {scores[(REAL_ARMATURE, 'auto')]:.1f} mm"
           f", Blender's own interpolation {scores[(REAL_ARMATURE, 'interp')]:.1f} mm (its "
           f"curves through Bezier keys {scores[(REAL_ARMATURE, 'bezier')]:.1f} mm)")


def quiet(message):
    """A report that says nothing: the demo's steps without ``--verbose``."""


def summary(demo, outdir, scenes=False):
    """The demo's result in a few lines: per take what was removed and the fill against what the
    user would otherwise have (Blender's interpolation, the studios' rigid-body fill), then the
    files written (``scenes``: the Blender scenes too)."""
    s, real = demo["scores"], demo["real_scores"]
    lines = [
        "Synthetic take (made offline; RMSE over the gaps, lower is better):",
        f"  armature, 3 bones' keys deleted for 1-1.7 s: fill {s[('skeleton', 'auto')]:.1f} mm,"
        f" Blender's interpolation {s[('skeleton', 'interp')]:.1f} mm",
        f"  markers, 6 gone for 1.2-1.5 s: fill {s[('markers', 'auto')]:.1f} mm, rigid-body "
        f"fill {s[('markers', 'rigid')]:.1f} mm, linear {s[('markers', 'linear')]:.1f} mm"]
    if (REAL_MARKERS, DEFAULT_METHOD) in real:
        lines.append(f"Real CMU take 01_01 (markers), 10 % hidden per half second: fill "
                     f"{real[(REAL_MARKERS, 'auto')]:.1f} mm, rigid-body fill "
                     f"{real[(REAL_MARKERS, 'rigid')]:.1f} mm")
    lines.append(f"Real CMU take 03_02 (armature), keys of lForeArm, rShin, chest deleted: fill "
                 f"{real[(REAL_ARMATURE, 'auto')]:.1f} mm, Blender's interpolation "
                 f"{real[(REAL_ARMATURE, 'interp')]:.1f} mm")
    lines += [f"Wrote to {outdir}/:",
              "  demo_markers_filled.c3d, 01_01_filled.c3d: filled markers; demo_markers.svg: "
              "original vs recovered",
              "  kb_skeleton.npz, kb_markers.npz: the demo's knowledge bases"]
    if scenes:
        lines += ["  mocap_demo.blend, cmu_01_01_markers.blend, cmu_03_02_armature.blend: "
                  "scenes with gaps,",
                  "  and each *_filled.blend after Fill All Gaps: open one in Blender, Mocap tab, "
                  "Original / Recovered"]
    return lines


def _write_c3d_or_npz(motion, path):
    try:
        import ezc3d  # noqa: F401
    except ImportError:  # e.g. a distribution's Blender without the bundled wheels
        path = path.with_suffix(".npz")
    return write_motion(motion, path, overwrite=True)


def write_plot(path, truth, query, recovered, linear, name, width=900, height=560):
    """An SVG of one point's x, y, z over time: the original (truth), what was observed, the
    knowledge-base recovery and linear interpolation; the gap frames shaded."""
    j = truth.names.index(name)
    t = np.arange(truth.n_frames)
    panels = []
    gap = np.isnan(query.positions[:, j, 0])
    h = (height - 60) / 3
    colours = (("original", truth, "#999999", "6,4"), ("recovered", recovered, "#d62728", ""),
               ("linear", linear, "#1f77b4", "2,3"))
    for axis in range(3):
        top = 30 + axis * h
        series = [m.positions[:, j, axis] for _, m, _, _ in colours]
        lo = min(np.nanmin(s) for s in series)
        hi = max(np.nanmax(s) for s in series)
        span = (hi - lo) or 1.0

        def xy(values):
            x = 60 + t / max(truth.n_frames - 1, 1) * (width - 80)
            y = top + h - 10 - (values - lo) / span * (h - 20)
            return " ".join(f"{a:.1f},{b:.1f}" for a, b in zip(x, y) if np.isfinite(b))

        for _, a, b in gap_runs(gap[:, None]):
            x0 = 60 + a / (truth.n_frames - 1) * (width - 80)
            x1 = 60 + b / (truth.n_frames - 1) * (width - 80)
            panels.append(f'<rect x="{x0:.1f}" y="{top:.1f}" width="{max(x1 - x0, 1):.1f}" '
                          f'height="{h - 5:.1f}" fill="#fde8c8"/>')
        for (label, _, colour, dash), values in zip(colours, series):
            panels.append(f'<polyline fill="none" stroke="{colour}" stroke-width="1.5" '
                          f'stroke-dasharray="{dash}" points="{xy(values)}"/>')
        panels.append(f'<text x="8" y="{top + h / 2:.1f}" font-size="13">{"xyz"[axis]} (m)'
                      f'</text>')
    legend = "".join(f'<text x="{80 + 170 * i}" y="18" font-size="13" fill="{c}">&#9473; {label}'
                     f'</text>' for i, (label, _, c, _) in enumerate(colours))
    svg = (f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" '
           f'font-family="sans-serif"><rect width="100%" height="100%" fill="white"/>{legend}'
           f'{"".join(panels)}<text x="{width / 2 - 120:.0f}" y="{height - 8}" font-size="13">'
           f'marker {name}: frames (gap shaded)</text></svg>')
    path = Path(path)
    path.write_text(svg)
    return path
