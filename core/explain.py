"""What a fill did to each gap, in the words a user reads (the command line, the gap report,
``batch``'s report, the add-on's gap list and ``blend``).

A marker's or joint's gap is described by the shares of the estimates ``auto`` blended into it
(:class:`~.fill.GapAccount`) and the error copies of its gaps expect; a bone's gap by the fills
its rotation went to (:class:`~.bonefill.GapChoice`) and the copies' error as a share of
Blender's own interpolation. No stage or generator is named by its internal name
(:data:`INTERNAL_NAMES`)."""

import numpy as np

#: the estimates of a point's gap (:class:`~.fill.GapAccount`'s fields), in words
POINT_SOURCES = (("rigid", "rigid partners"), ("models", "knowledge base"),
                 ("windows", "knowledge-base motion"), ("own", "rest of the body"),
                 ("spline", "smooth curve"), ("pattern", "a partner's path"))

#: the rotation fills of a bone's gap (:data:`~.bonefill.CANDIDATES` and the stacks), in words
BONE_SOURCES = {
    "interp": "Blender's curve", "bezier": "Blender's Bezier curve",
    "hermite": "a smooth curve", "slerp": "a smooth curve",
    "learn": "its own motion", "knn": "knowledge-base poses",
    "half": "knowledge-base poses", "recall": "knowledge-base poses",
    "match": "knowledge-base motion", "mix": "knowledge-base motion",
    "regress": "the other bones", "regress_pose": "the other bones",
    "regress_kernel": "the other bones",
    "stack": "a blend of several fills",
    "stack_long": "a blend of several fills",
}

#: what a bone's gap says where Blender's interpolation was kept
KEPT = "kept Blender's curve"

#: names of the fill's internal stages and generators that no message to a user contains
INTERNAL_NAMES = ("interp", "hermite", "learn", "knn", "recall", "match", "mix",
                  "regress", "regress_pose", "regress_kernel", "stack", "stack_long", "medoid",
                  "models", "windows", "consensus")

#: estimates of a point's gap below this share are not named
LEAST_SHARE = 0.05


def point_shares(accounts):
    """``[(share, words), ...]`` of the estimates blended into one or more gaps of a point (the
    mean over their accounts, weighted by the gaps' lengths), largest first, those of
    :data:`LEAST_SHARE` or more."""
    lengths = [a.last - a.first + 1 for a in accounts]
    shares = [(float(np.average([getattr(a, field) for a in accounts], weights=lengths)), words)
              for field, words in POINT_SOURCES]
    return [(s, words) for s, words in sorted(shares, reverse=True) if s >= LEAST_SHARE]


def point_gap(accounts):
    """``"knowledge base 60%, rigid partners 40%"``: the estimates of a point's gap(s)."""
    return ", ".join(f"{words} {share:.0%}" for share, words in point_shares(accounts))


def expected(estimate):
    """``"expected error ~12 mm"`` from an estimate in metres (NaN: not judged)."""
    if not np.isfinite(estimate):
        return "no copies to judge the error by"
    return f"expected error ~{1000 * estimate:.0f} mm"


def bone_gap(choices):
    """How a bone's gap(s) went from Blender's curve (:class:`~.bonefill.GapChoice`), in words:
    :data:`KEPT` where no fill moved it, else ``"knowledge-base motion, blended with the other
    bones"`` (the fill it took, then what it was blended with)."""
    return "; ".join(dict.fromkeys(_bone_words(c) for c in choices))


def _bone_words(c):
    if c.medoid:  # the fill that took the gap's place in the end
        return f"{BONE_SOURCES[c.medoid]}, which the other fills bear out"
    main = "Blender's curve" if c.share == 0 else BONE_SOURCES[c.method] + (
        f" ({c.share:.0%} of the way from Blender's curve)" if c.share < 1 else "")
    others = (c.corroborated.split(" + ") if c.corroborated else []) \
        + (["hermite"] if c.cubic else []) + (["learn"] if c.learnt else []) \
        + (c.towards.split(" + ") if c.consensus else [])
    words = [w for w in dict.fromkeys(BONE_SOURCES[o] for o in others)
             if not main.startswith(w)]
    if not words:
        return KEPT if c.share == 0 else main
    return f"{main}, blended with {_listed(words)}"


def bone_estimate(estimate):
    """``"expected error 0.82x Blender's curve"`` from a share of the interpolation's error."""
    return f"expected error {estimate:.2f}x Blender's curve" if estimate else \
        "no copies to judge the error by"


def _listed(words):
    return words[0] if len(words) == 1 else ", ".join(words[:-1]) + " and " + words[-1]
