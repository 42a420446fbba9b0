"""Markdown tables from evaluation JSON files (mocap-gapfill evaluate --json).

Usage: python tools/results_table.py docs/results/*.json
Per setting: mean RMSE over missing entries (and over all entries) across test takes, per method,
and knn's ratio to the best baseline.
"""

import json
import sys
from pathlib import Path

import numpy as np


def table(path):
    payload = json.loads(Path(path).read_text())
    rows = payload["results"]
    methods = list(dict.fromkeys(r["method"] for r in rows))
    settings = list(dict.fromkeys(r["setting"] for r in rows))
    tests = sorted({r["test"] for r in rows})
    out = [f"### {Path(path).stem}: protocol `{payload['protocol']}`, {payload.get('fps')} fps, "
           f"seed {payload.get('seed')}",
           f"Test takes ({len(tests)}): {', '.join(tests)}. Knowledge base: "
           f"{', '.join(Path(s).as_posix().split('data/')[-1] for s in payload['kb_sources'])}, "
           "test subject left out.", "",
           "| setting | " + " | ".join(methods) + " | knn / best baseline |",
           "|---|" + "---:|" * (len(methods) + 1)]
    for s in settings:
        cells, means = [], {}
        for m in methods:
            sel = [r for r in rows if r["setting"] == s and r["method"] == m]
            means[m] = np.mean([r["rmse_missing_mm"] for r in sel])
            cells.append(f"{means[m]:.1f} ({np.mean([r['rmse_all_mm'] for r in sel]):.1f})")
        best = min(v for m, v in means.items() if m != "knn")
        bold = [f"**{c}**" if means[m] == min(means.values()) else c for m, c in zip(methods, cells)]
        out.append(f"| {s} | " + " | ".join(bold) + f" | {means['knn'] / best:.2f} |")
    seconds = {m: np.mean([r["seconds"] for r in rows if r["method"] == m]) for m in methods}
    out += ["", "Mean seconds per fill: " + ", ".join(f"{m} {v:.2f}" for m, v in seconds.items()),
            ""]
    return "\n".join(out)


if __name__ == "__main__":
    print("\n".join(table(p) for p in sys.argv[1:]))
