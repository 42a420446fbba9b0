"""Compare rules for the armature default offline, on what ``tools/tune_bones.py`` saved (issue
14): per take and setting, each candidate's squared joint error and squared deviation from
``interp`` on the gaps and on their copies. A blend ``share`` of the way from ``interp`` to a
candidate has the squared error ``(1-s)^2 I + s^2 C + s(1-s)(I + C - dev)`` (exact for a linear
blend of the joints, close for the rotation blend ``auto`` makes), so every share of every
candidate is scored from one fill of each.

    python tools/bone_rules.py TUNE_OUT [TUNE_OUT ...]

Prints, per rule, the mean over takes of the RMSE as a ratio to ``interp`` for each setting
(n=1 then n=3, l = 15 ... 240) and the gaps worse than ``interp`` by more than 10 % + 2 mm; last,
the best fill of each gap among those saved (an oracle: the judge's headroom).
"""

import sys
from pathlib import Path

import numpy as np

FPS = 120.0  # the Daz takes' own rate: gap lengths are in frames
ALL = (0.25, 0.5, 0.75, 1.0)


def blend(interp, cand, dev, share):
    return ((1 - share) ** 2 * interp + share ** 2 * cand
            + share * (1 - share) * (interp + cand - dev))


def choose(z, cands=("match", "mix"), shares=ALL, promote=0.8, short_shares=None,
           short_promote=None, long_gap=1.0, shrink=1.0, short_whole=None, trust=None):
    """(candidate, share) per gap: the one whose blend refills the gap's copies best (log
    ratio to ``interp``, the take's mean over all copies mixed in with weight ``shrink``),
    if below ``promote``; gaps under ``long_gap`` seconds use the ``short_*`` values; a take
    without copies: ``cands[0]`` on long gaps, ``cands[-1]`` on short ones. ``trust``: a long
    gap left to ``interp`` takes ``cands[0]`` where that moves the joints from ``interp`` by
    more than ``trust`` times its RMS error on the gap's copies."""
    lengths = z["gap_len"]
    out = [(cands[0] if n >= long_gap * FPS else cands[-1], 1.0) for n in lengths]
    owner = z["owner"]
    if not len(owner):
        return out
    floor = 1e-6 * z["copy_len"] * (z["copy_joints"] + 1)
    every = set(shares) | set(short_shares or ())
    ratio = {(c, s): np.log((blend(z["copy_interp"], z[f"copy_{c}"], z[f"copy_{c}_dev"], s)
                             + floor) / (z["copy_interp"] + floor))
             for c in cands for s in every}
    for i, n in enumerate(lengths):
        short = n < long_gap * FPS
        allowed = short_shares if short and short_shares else shares
        bar = short_promote if short and short_promote else promote
        own = owner == i
        score = {k: (r[own].sum() + shrink * r.mean()) / (own.sum() + shrink)
                 for k, r in ratio.items() if k[1] in allowed}
        passed = {k: v for k, v in score.items()
                  if v < np.log(short_whole if short and short_whole and k[1] == 1 else bar)}
        out[i] = min(passed, key=passed.get) if passed else ("interp", 0.0)
        if trust and not short and not passed and own.any():
            typical = np.sqrt(np.mean(z[f"copy_{cands[0]}"][own]
                                      / (z["copy_len"] * z["copy_joints"])[own]))
            if np.sqrt(z[f"gap_{cands[0]}_dev"][i] / (n * z["gap_joints"][i])) > trust * typical:
                out[i] = (cands[0], 1.0)
    return out


def evaluate(runs, **rule):
    settings = sorted({s for _, s, _ in runs}, key=lambda s: (s[2], int(s.split("l=")[1])))
    ratios, worse, gaps = {s: [] for s in settings}, 0, 0
    for _, setting, z in runs:
        err = np.array([z["gap_interp"][i] if c == "interp" else
                        blend(z["gap_interp"][i], z[f"gap_{c}"][i], z[f"gap_{c}_dev"][i], s)
                        for i, (c, s) in enumerate(choose(z, **rule))])
        count = z["gap_len"] * z["gap_joints"]
        if z["gap_interp"].sum() > 0:
            ratios[setting].append(np.sqrt(err.sum() / z["gap_interp"].sum()))
        worse += int((np.sqrt(err / count) > 1.1 * np.sqrt(z["gap_interp"] / count)
                      + 0.002).sum())
        gaps += len(count)
    return [np.mean(ratios[s]) for s in settings], worse, gaps


#: a rule that takes short gaps at most 3/4 of the way, and the chosen one
PART_WAY = dict(short_shares=(0.25, 0.5, 0.75), short_promote=0.7, promote=0.9, long_gap=0.5)
CHOSEN = dict(PART_WAY, short_shares=ALL, short_whole=0.3)
RULES = {
    "all the way (share 1, promote 0.8, 1 s)": dict(shares=(1.0,)),
    "shares, promote 0.8": dict(shares=ALL),
    "short < 0.5 s: shares to 0.75, promote 0.7; long: all, 0.9": PART_WAY,
    "same, short gaps all the way below 0.3 (chosen)": CHOSEN,
    "same, long gaps left to interp take match where it strays > 1.5x its copies' error":
        dict(CHOSEN, trust=1.5),
    "same, > 2x (not taken: no better on the test takes)": dict(CHOSEN, trust=2.0),
    "same, > 3x": dict(CHOSEN, trust=3.0),
    "same, short gaps all the way below 0.4": dict(CHOSEN, short_whole=0.4),
    "same, short gaps all the way below 0.5": dict(CHOSEN, short_whole=0.5),
    "same, short < 1 s": dict(PART_WAY, long_gap=1.0),
    "same, long promote 0.8": dict(PART_WAY, promote=0.8),
    "same, long promote 1.0": dict(PART_WAY, promote=1.0),
    "same, short promote 0.8": dict(PART_WAY, short_promote=0.8),
    "same, short shares to 0.5": dict(PART_WAY, short_shares=(0.25, 0.5)),
}


def oracle(runs):
    """As :func:`evaluate`, for the best fill of each gap among ``interp`` and every candidate
    (and blend towards ``match``) saved: what a judge that knew the truth would reach."""
    settings = sorted({s for _, s, _ in runs}, key=lambda s: (s[2], int(s.split("l=")[1])))
    ratios = {s: [] for s in settings}
    fills = [k for k in runs[0][2] if k.startswith("gap_") and not k.endswith("_dev")
             and k not in ("gap_len", "gap_joints")]  # every run saved the same fills
    for _, setting, z in runs:
        best = np.min([z[k] for k in fills], axis=0)
        if z["gap_interp"].sum() > 0:
            ratios[setting].append(np.sqrt(best.sum() / z["gap_interp"].sum()))
    return [np.mean(ratios[s]) for s in settings], fills


def main(folders):
    runs = []
    for folder in folders:
        for path in sorted(Path(folder).glob("*_n=*.npz")):
            take, setting = path.stem.split("_n=")
            runs.append((take, "n=" + setting, dict(np.load(path))))
    print(f"{len({t for t, _, _ in runs})} takes, {len(runs)} runs")
    for label, rule in RULES.items():
        ratios, worse, gaps = evaluate(runs, **rule)
        print(f"| {label} | {' / '.join(f'{r:.2f}' for r in ratios[:5])} | "
              f"{' / '.join(f'{r:.2f}' for r in ratios[5:])} | {worse} of {gaps} |")
    ratios, fills = oracle(runs)
    print(f"| the best per gap of {', '.join(f[4:] for f in fills)} | "
          f"{' / '.join(f'{r:.2f}' for r in ratios[:5])} | "
          f"{' / '.join(f'{r:.2f}' for r in ratios[5:])} | 0 |")


if __name__ == "__main__":
    main(sys.argv[1:])
