"""Several performers in one marker take: points named with a performer prefix (``A:LFHD``,
``B:LFHD``) are split by prefix, so each performer is matched to the knowledge base by its own
names and filled on its own (rigid partners from the same performer only)."""

#: a prefix names a performer where at least this many points carry it
LEAST_POINTS = 3


def performers(names):
    """``{prefix: [indices]}`` of a take's performers, in the order they first appear (points
    without a performer's prefix together under ""); empty where fewer than two prefixes each
    name at least :data:`LEAST_POINTS` points (one performer: nothing to split)."""
    groups = {}
    for i, name in enumerate(names):
        prefix = name.rsplit(":", 1)[0] if ":" in name.strip(":") else ""
        groups.setdefault(prefix, []).append(i)
    named = [p for p, members in groups.items() if p and len(members) >= LEAST_POINTS]
    if len(named) < 2:
        return {}
    out = {p: groups[p] for p in named}
    rest = [i for p, members in groups.items() if p not in out for i in members]
    if rest:
        out[""] = sorted(rest)
    return out


def bare(name):
    """A point's name without its performer prefix (``A:LFHD`` -> ``LFHD``)."""
    return name.rsplit(":", 1)[-1] or name


def names_for_kb(names):
    """The names a knowledge base is chosen by: those of the take's first performer without
    their prefix where it holds several (:func:`performers`), else the names as they are."""
    groups = performers(names)
    if not groups:
        return list(names)
    first = next(iter(groups.values()))
    return [bare(names[i]) for i in first]
