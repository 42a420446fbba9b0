"""The normalised motion type every reader produces and every writer and method consumes.

Conventions (the one place they are written down)
--------------------------------------------------
- Positions are in **metres**, in a right-handed frame with **Z up** (Blender's frame).
  Readers convert on the way in: C3D millimetres -> metres; Y-up files (BVH, ASF/AMC and C3D files
  whose ``POINT:Y_SCREEN`` is ``+Y``) are turned with :func:`y_up_to_z_up`, the same mapping as
  Blender's BVH importer (``forward=-Z, up=Y``): ``(x, y, z) -> (x, -z, y)``.
- A missing sample is NaN in all three coordinates of that (frame, point).
- ``Motion.up_axis`` and ``Motion.units`` record what the *source file* used, for display and
  provenance; they never change how ``positions`` are to be read.
"""

from dataclasses import dataclass, field, replace

import numpy as np

from .errors import GapFillError
from .performers import performers

#: metres per source unit, for the unit names readers report
UNIT_SCALES = {
    "m": 1.0,
    "cm": 0.01,
    "mm": 0.001,
    "in": 0.0254,
    "cmu": 0.0254 / 0.45,  # ASF "length 0.45": 1 unit = 1/0.45 inch = 0.056444 m
}


def y_up_to_z_up(points):
    """Map Y-up coordinates to the Z-up frame of :class:`Motion` (last axis is xyz).

    >>> y_up_to_z_up(np.array([1.0, 2.0, 3.0])).tolist()
    [1.0, -3.0, 2.0]
    """
    points = np.asarray(points, dtype=float)
    return np.stack([points[..., 0], -points[..., 2], points[..., 1]], axis=-1)


def z_up_to_y_up(points):
    """Inverse of :func:`y_up_to_z_up`."""
    points = np.asarray(points, dtype=float)
    return np.stack([points[..., 0], points[..., 2], -points[..., 1]], axis=-1)


@dataclass(frozen=True, eq=False)
class Motion:
    """Point trajectories of one take.

    Parameters
    ----------
    positions : ndarray, shape (frames, points, 3), float64
        Metres, Z up, NaN where missing (see the module docstring).
    names : tuple of str
        One unique, non-empty name per point (joint or marker label).
    fps : float
        Frames per second, > 0.
    parents : tuple of int or None
        For a skeleton, the index of each point's parent (-1 for the root); None for markers.
    limbs : ndarray, shape (limbs, 2), int
        Pairs of points whose distance should stay constant: (parent, child) bones for a skeleton,
        pairs of markers on one rigid segment for markers (see :func:`rigid_marker_pairs`).
    source : str or None
        Path of the file it was read from.
    source_format : str
        ``"c3d"``, ``"bvh"``, ``"asf/amc"``, ``"npz"``, ``"csv"`` or ``"array"``.
    units : str
        Unit of the source file, a key of :data:`UNIT_SCALES` (positions are always metres).
    up_axis : str
        ``"y"`` or ``"z"``: the up axis of the source file.
    filled : ndarray, shape (frames, points), bool, or None
        True where a sample was filled by a gap-filling method rather than observed (C3D files
        mark such samples with residual 0). None when nothing was filled.
    rest : ndarray, shape (points, 3), or None
        A skeleton's own rest pose where its file defines one (an ASF with every angle zero),
        metres and axes as ``positions``; armatures built from the motion take it as their rest
        pose, so bone rotations mean the same across takes of that skeleton. None: the rest pose
        is the first complete frame.
    """

    positions: np.ndarray
    names: tuple
    fps: float
    parents: tuple = None
    limbs: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), dtype=np.int64))
    source: str = None
    source_format: str = "array"
    units: str = "m"
    up_axis: str = "z"
    filled: np.ndarray = None
    rest: np.ndarray = None

    def __post_init__(self):
        pos = np.asarray(self.positions, dtype=np.float64)
        if pos.ndim != 3 or pos.shape[2] != 3:
            raise GapFillError(f"positions must have shape (frames, points, 3), got {pos.shape}")
        names = tuple(str(n) for n in self.names)
        if len(names) != pos.shape[1]:
            raise GapFillError(f"{len(names)} names for {pos.shape[1]} points")
        if any(not n for n in names):
            raise GapFillError("every point needs a non-empty name")
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise GapFillError(f"duplicated point names: {', '.join(dup)}")
        if not np.isfinite(self.fps) or self.fps <= 0:
            raise GapFillError(f"fps must be a positive number, got {self.fps}")
        # a sample is missing as a whole: one NaN coordinate (or an infinite one) hides the point
        bad = ~np.isfinite(pos).all(axis=2)
        if bad.any():
            pos = pos.copy()
            pos[bad] = np.nan
        limbs = np.asarray(self.limbs, dtype=np.int64).reshape(-1, 2)
        if limbs.size and (limbs.min() < 0 or limbs.max() >= len(names)):
            raise GapFillError("limb index out of range")
        parents = None if self.parents is None else tuple(int(p) for p in self.parents)
        if parents is not None and len(parents) != len(names):
            raise GapFillError(f"{len(parents)} parents for {len(names)} points")
        filled = None
        if self.filled is not None:
            filled = np.asarray(self.filled, dtype=bool)
            if filled.shape != pos.shape[:2]:
                raise GapFillError(f"filled mask has shape {filled.shape}, expected {pos.shape[:2]}")
            filled = filled & ~bad if filled.any() else None
        if filled is not None:
            filled.setflags(write=False)
        object.__setattr__(self, "filled", filled)
        if self.rest is not None:
            rest = np.array(self.rest, dtype=np.float64)
            if rest.shape != pos.shape[1:] or not np.isfinite(rest).all():
                raise GapFillError(f"rest pose must be finite of shape {pos.shape[1:]}, "
                                   f"got {rest.shape}")
            rest.setflags(write=False)
            object.__setattr__(self, "rest", rest)
        pos.setflags(write=False)
        limbs.setflags(write=False)
        object.__setattr__(self, "positions", pos)
        object.__setattr__(self, "names", names)
        object.__setattr__(self, "fps", float(self.fps))
        object.__setattr__(self, "limbs", limbs)
        object.__setattr__(self, "parents", parents)

    # ---- shape -------------------------------------------------------------------------------
    @property
    def n_frames(self):
        return self.positions.shape[0]

    @property
    def n_points(self):
        return self.positions.shape[1]

    @property
    def missing(self):
        """Boolean mask, shape (frames, points): True where a sample is missing."""
        return np.isnan(self.positions[..., 0])

    def replace(self, **changes):
        """A copy with some fields changed (``dataclasses.replace``)."""
        return replace(self, **changes)

    def select(self, names):
        """The motion restricted to the named points, in that order (limbs among them kept)."""
        index = {n: i for i, n in enumerate(self.names)}
        unknown = [n for n in names if n not in index]
        if unknown:
            raise GapFillError(f"unknown point names: {', '.join(unknown)}")
        keep = [index[n] for n in names]
        remap = {old: new for new, old in enumerate(keep)}
        limbs = [(remap[a], remap[b]) for a, b in self.limbs if a in remap and b in remap]
        parents = None
        if self.parents is not None:
            parents = []
            for old in keep:  # nearest kept ancestor
                p = self.parents[old]
                while p >= 0 and p not in remap:
                    p = self.parents[p]
                parents.append(remap.get(p, -1))
        return self.replace(positions=self.positions[:, keep], names=tuple(names),
                            parents=parents, limbs=np.array(limbs, dtype=np.int64).reshape(-1, 2),
                            filled=None if self.filled is None else self.filled[:, keep],
                            rest=None if self.rest is None else self.rest[keep])

    def frame_range(self, start, stop=None):
        """The motion restricted to frames ``start:stop`` (Python slice semantics)."""
        frames = slice(start, stop)
        return self.replace(positions=self.positions[frames],
                            filled=None if self.filled is None else self.filled[frames])

    # ---- statistics --------------------------------------------------------------------------
    def gap_runs(self):
        """Every gap as ``(point, first_frame, last_frame)`` (inclusive), point-major order."""
        return gap_runs(self.missing)

    def summary(self):
        """A dict of the facts ``mocap-gapfill info`` prints."""
        runs = self.gap_runs()
        longest = max(runs, key=lambda r: r[2] - r[1], default=None)
        return {
            "path": self.source,
            "format": self.source_format,
            "frames": self.n_frames,
            "fps": self.fps,
            "seconds": self.n_frames / self.fps,
            "points": self.n_points,
            "kind": "skeleton" if self.parents is not None else "markers",
            "units": self.units,
            "up_axis": self.up_axis,
            "missing_fraction": float(self.missing.mean()) if self.missing.size else 0.0,
            "gaps": len(runs),
            "longest_gap_frames": 0 if longest is None else longest[2] - longest[1] + 1,
            "longest_gap_point": None if longest is None else self.names[longest[0]],
            "limbs": int(len(self.limbs)),
            "performers": (len([p for p in performers(self.names) if p]) or 1
                           if self.parents is None else 1),
        }


def gap_runs(missing):
    """Runs of True per column of a (frames, points) mask: ``(point, first, last)`` inclusive,
    point-major order."""
    runs = []
    for p in range(missing.shape[1]):
        m = np.concatenate([[False], missing[:, p], [False]]).astype(np.int8)
        edges = np.flatnonzero(np.diff(m))
        runs.extend((p, int(a), int(b) - 1) for a, b in zip(edges[::2], edges[1::2]))
    return runs


def interpolate_rows(values, valid):
    """Rows of ``values`` (frames, ...) where ``valid`` is False, filled by linear interpolation
    in time from the valid rows (held constant before the first and after the last)."""
    if valid.all() or not valid.any():
        return values
    frames = np.arange(len(values))
    flat = values.reshape(len(values), -1)
    out = flat.copy()
    for k in range(flat.shape[1]):
        out[~valid, k] = np.interp(frames[~valid], frames[valid], flat[valid, k])
    return out.reshape(values.shape)


def widened(mask):
    """(frames, points) ``mask`` with one more frame either side of each run: where a model is
    evaluated beside a gap, for :func:`blend_into_gaps` to meet the data at its ends."""
    out = mask.copy()
    out[1:] |= mask[:-1]
    out[:-1] |= mask[1:]
    return out


def blend_into_gaps(pos, pred, missing, model):
    """Observed values kept; each gap takes the prediction plus the observation-minus-prediction
    offset at its two ends, blended linearly (one end at clip ends)."""
    out = pos.copy()
    n_frames = len(pos)
    for p, a, b in gap_runs(missing):
        seg = pred[a:b + 1, p]
        if np.isnan(seg).any():
            continue
        ends = [t for t in (a - 1, b + 1) if 0 <= t < n_frames and model[t, p]
                and np.isfinite(pred[t, p]).all()]
        offsets = [pos[t, p] - pred[t, p] for t in ends]
        if len(offsets) == 2:
            w = ((np.arange(a, b + 1) - (a - 1)) / (b + 2 - a))[:, None]
            shift = offsets[0] * (1 - w) + offsets[1] * w
        else:
            shift = offsets[0] if offsets else 0.0
        out[a:b + 1, p] = seg + shift
    return out


def units_for_height(height):
    """The unit (a key of :data:`UNIT_SCALES`) in which a person ``height`` tall is ~1.7 m.

    >>> units_for_height(170.0), units_for_height(1.75), units_for_height(31.0)
    ('cm', 'm', 'cmu')
    """
    height = float(height) if np.isfinite(height) and height > 0 else 1.7
    return min(UNIT_SCALES, key=lambda u: abs(np.log(height * UNIT_SCALES[u] / 1.7)))


def snap_fps(fps):
    """Round a frame rate read from a truncated frame time (``.0083333`` -> 120) to an integer.

    >>> snap_fps(1 / 0.0083333), snap_fps(29.97)
    (120.0, 29.97)
    """
    nearest = round(fps)
    return float(nearest) if nearest > 0 and abs(fps - nearest) < 1e-3 * nearest else float(fps)


def skeleton_limbs(parents):
    """(parent, child) pairs of a skeleton given each point's parent index (-1 for the root)."""
    return np.array([(p, c) for c, p in enumerate(parents) if p >= 0], dtype=np.int64).reshape(-1, 2)


def rigid_marker_pairs(positions, max_std=0.006, max_rel_std=0.03, min_frames=10):
    """Pairs of markers whose distance stays nearly constant: markers on one rigid segment.

    A pair qualifies when, over the frames where both markers are present (at least
    ``min_frames``), the standard deviation of their distance is at most ``max_std`` metres and
    at most ``max_rel_std`` times the mean distance. Skin and soft tissue make even markers on
    one bone move a few millimetres against each other, hence the tolerance.

    Parameters
    ----------
    positions : ndarray, shape (frames, points, 3)
        Metres, NaN where missing.

    Returns
    -------
    ndarray, shape (pairs, 2), int
        ``i < j`` index pairs, sorted.
    """
    pos = np.asarray(positions, dtype=np.float64)
    n = pos.shape[1]
    i, j = np.triu_indices(n, k=1)
    pairs = []
    # chunk the pairs so memory stays bounded on long takes
    step = max(1, 2_000_000 // max(1, pos.shape[0]))
    for s in range(0, len(i), step):
        a, b = i[s:s + step], j[s:s + step]
        d = np.linalg.norm(pos[:, a] - pos[:, b], axis=2)  # (frames, pairs)
        valid = np.isfinite(d)
        count = valid.sum(axis=0)
        with np.errstate(invalid="ignore", divide="ignore"):
            mean = np.where(valid, d, 0).sum(axis=0) / count
            var = np.where(valid, (d - mean) ** 2, 0).sum(axis=0) / count
        std = np.sqrt(var)
        ok = (count >= min_frames) & (std <= max_std) & (std <= max_rel_std * mean)
        pairs.extend(zip(a[ok].tolist(), b[ok].tolist()))
    return np.array(sorted(pairs), dtype=np.int64).reshape(-1, 2)
