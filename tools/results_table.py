"""Markdown tables from evaluation JSON files (mocap-gapfill evaluate --json).

Usage: python tools/results_table.py docs/results/*.json (bench.json from mocap-gapfill bench
gives the speed tables); with --summary first, one line per file (docs/EVALUATION.md's summary)
Per setting: mean RMSE over missing entries (and over all entries, or the angle error for bones)
across test takes, per method, each of our methods' ratio to the best baseline, and the spread of
the default's ratio to the best baseline of each take.
"""

import json
import sys
from pathlib import Path

import numpy as np


#: our methods, for results written before the JSON named its baselines
OURS = ("knn", "auto")


def bench_table(path):
    """Markdown of a ``mocap-gapfill bench --json`` file: median ms (peak MB) per backend."""
    payload = json.loads(Path(path).read_text())
    rows = payload["results"]
    m = payload["machine"]
    out = [f"Machine: {m.get('cpu')}, {m.get('cores')} cores, OMP_NUM_THREADS={m.get('threads')}, "
           f"Python {m.get('python')}, numpy {m.get('numpy')}, torch {m.get('torch')} "
           f"({m.get('torch_threads')} threads){', GPU ' + m['gpu'] if m.get('gpu') else ''}; "
           "float32 GEMM " + ", ".join(f"{k} {v:.0f} GFLOP/s"
                                        for k, v in m.get("gemm_gflops", {}).items()) + ".", ""]
    for stage in dict.fromkeys(r["stage"] for r in rows):
        backends = list(dict.fromkeys(r["backend"] for r in rows if r["stage"] == stage))
        out += [f"**{stage}** (median ms, tracemalloc peak MB)", "",
                "| KB poses | frames | K | " + " | ".join(backends) + " | numpy / fastest |",
                "|---:|---:|---:|" + "---:|" * (len(backends) + 1)]
        cases = dict.fromkeys((r["kb_size"], r["queries"], r["k"]) for r in rows
                              if r["stage"] == stage)
        for case in cases:
            got = {r["backend"]: r for r in rows if r["stage"] == stage
                   and (r["kb_size"], r["queries"], r["k"]) == case}
            cells = [f"{1000 * got[b]['median_s']:.0f} ({got[b]['peak_mb']:.0f})" if b in got
                     else "" for b in backends]
            fastest = min(r["median_s"] for r in got.values())
            ratio = got["numpy"]["median_s"] / fastest if "numpy" in got else float("nan")
            out.append(f"| {case[0]} | {case[1]} | {case[2]} | " + " | ".join(cells)
                       + f" | {ratio:.2f} |")
        out.append("")
    return "\n".join(out)


def table(path):
    payload = json.loads(Path(path).read_text())
    rows = payload["results"]
    methods = list(dict.fromkeys(r["method"] for r in rows))
    settings = list(dict.fromkeys(r["setting"] for r in rows))
    tests = sorted({r["test"] for r in rows})
    baselines = payload.get("baselines") or [m for m in methods if m not in OURS]
    default = payload.get("default_method", "knn")
    ours = [m for m in methods if m not in baselines]
    second = "angle_deg" if "angle_deg" in rows[0] else "rmse_all_mm"
    # armature gaps: also against doing nothing (Blender's interpolation), gap by gap
    bones = payload["protocol"] in ("bones", "bone-ends") and "interp" in methods
    out = [f"### {Path(path).stem}: protocol `{payload['protocol']}`, {payload.get('fps')} fps, "
           f"seed {payload.get('seed')}",
           f"Test takes ({len(tests)}): {', '.join(tests)}. Knowledge base: "
           f"{', '.join(_data_path(s) for s in payload['kb_sources'])}, "
           f"test subject left out. Default method: `{default}`; baselines: "
           f"{', '.join(baselines)}.", "",
           "| setting | " + " | ".join(methods) + " | "
           + " | ".join(f"{m} / best baseline" for m in ours)
           + f" | {default} / best baseline per take (min-max) |"
           + (f" {default} / interp (min-max over takes) | gaps where {default} > 1.1 interp "
              "+ 2 mm |" if bones else ""),
           "|---|" + "---:|" * (len(methods) + len(ours) + 1 + 2 * bones)]
    for s in settings:
        cells, means = [], {}
        for m in methods:
            sel = [r for r in rows if r["setting"] == s and r["method"] == m]
            means[m] = np.mean([r["rmse_missing_mm"] for r in sel])
            cells.append(f"{means[m]:.1f} ({np.mean([r[second] for r in sel]):.1f})")
        best = min(v for m, v in means.items() if m in baselines)
        bold = [f"**{c}**" if means[m] == min(means.values()) else c for m, c in zip(methods, cells)]
        got = {(r["method"], r["test"]): r["rmse_missing_mm"] for r in rows if r["setting"] == s}
        per_take = [got[(default, t)] / min(got[(m, t)] for m in baselines) for t in tests
                    if (default, t) in got]
        line = (f"| {s} | " + " | ".join(bold) + " | "
                + " | ".join(f"{means[m] / best:.2f}" for m in ours)
                + f" | {min(per_take):.2f}-{max(per_take):.2f} |")
        if bones:
            ratio = [got[(default, t)] / got[("interp", t)] for t in tests]
            gaps = {(r["method"], r["test"]): np.array(r["gaps_mm"]) for r in rows
                    if r["setting"] == s}
            worse = sum(int((gaps[(default, t)] > 1.1 * gaps[("interp", t)] + 2).sum())
                        for t in tests)
            count = sum(len(gaps[("interp", t)]) for t in tests)
            line += (f" {means[default] / means['interp']:.2f} ({min(ratio):.2f}-"
                     f"{max(ratio):.2f}) | {worse} / {count} |")
        out.append(line)
    seconds = {m: np.mean([r["seconds"] for r in rows if r["method"] == m]) for m in methods}
    out += ["", "Mean seconds per fill: " + ", ".join(f"{m} {v:.2f}" for m, v in seconds.items()),
            ""]
    return "\n".join(out)


def summary_table(paths):
    """One Markdown table over evaluation JSON files: per file the protocol, the test takes, the
    knowledge base, and the default's RMSE over the best baseline's (per setting, means over
    the takes: their geometric mean and range over the settings; per take and setting: the
    range), and for armatures the same against Blender's interpolation alone."""
    out = ["| results | protocol | test takes | knowledge base | default / best baseline: "
           "geometric mean (settings' range) | per take | default / Blender's interpolation |",
           "|---|---|---:|---|---:|---:|---:|"]
    for path in paths:
        payload = json.loads(Path(path).read_text())
        if payload.get("protocol") in (None, "faults"):  # (faults: its own table)
            continue
        rows, default = payload["results"], payload.get("default_method", "knn")
        baselines = payload.get("baselines") or [m for m in {r["method"] for r in rows}
                                                 if m not in OURS]
        got = {(r["setting"], r["method"], r["test"]): r["rmse_missing_mm"] for r in rows}
        settings = list(dict.fromkeys(r["setting"] for r in rows))
        tests = sorted({r["test"] for r in rows})

        def mean(s, m):
            return np.mean([got[(s, m, t)] for t in tests if (s, m, t) in got])

        ratios = [mean(s, default) / min(mean(s, b) for b in baselines) for s in settings]
        per_take = [got[(s, default, t)] / min(got[(s, b, t)] for b in baselines)
                    for s in settings for t in tests if (s, default, t) in got]
        interp = ([mean(s, default) / mean(s, "interp") for s in settings]
                  if "interp" in baselines else [])
        kb = ", ".join(_data_path(k) for k in payload["kb_sources"]) or "none"
        out.append(f"| {Path(path).stem} | {payload['protocol']} | {len(tests)} | {kb} | "
                   f"{_geomean(ratios):.2f} ({min(ratios):.2f}-{max(ratios):.2f}) | "
                   f"{min(per_take):.2f}-{max(per_take):.2f} | "
                   + (f"{_geomean(interp):.2f} ({min(interp):.2f}-{max(interp):.2f})"
                      if interp else "") + " |")
    return "\n".join(out)


def _data_path(path):
    """A path of the test data as the evaluation names it, from the data folder on."""
    return Path(path).as_posix().split("data/")[-1].removeprefix("$MOCAP_GAPFILL_DATA/")


def _geomean(values):
    return float(np.exp(np.mean(np.log(values))))


if __name__ == "__main__":
    if sys.argv[1:2] == ["--summary"]:
        print(summary_table(sys.argv[2:]))
    else:
        print("\n".join(bench_table(p) if "machine" in json.loads(Path(p).read_text())
                        else table(p) for p in sys.argv[1:]))
