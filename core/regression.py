"""A point in a gap from the rest of the body: the take's own regression.

Where a limb is gone for seconds, the points still seen say much about it on this very take:
a walk's arm swings against its legs, a dancer's free hand follows the rest of the figure. No
knowledge base holds that subject; the take's own frames where the point is seen do. Per gap, a
ridge regression (in the body's frame, :mod:`.normalize`) of the point on every point seen
throughout the gap, fitted on the frames where all of them are seen, with a Gaussian kernel
beside the linear one (so the point may follow the others in a curve, as the armatures'
``regress_kernel`` does), predicts the gap; the prediction's miss at the observations either
side is blended across it (:func:`~.motion.blend_into_gaps`), so the fill meets both ends.

On a marker set the same idea works closer in (:func:`regress_in_frame`): a marker's place
among its steadiest partners, which the rigid fill holds constant, regressed on where further
partners sit among them.
"""

from dataclasses import dataclass

import numpy as np

from .errors import GapFillError
from .motion import blend_into_gaps, gap_runs, widened
from .normalize import denormalize, find_reference, frames_of, normalize
from .posing import gram_schmidt

@dataclass(frozen=True)
class RegressionSettings:
    """The take's own regressions' settings (tuned on non-test takes, docs/DESIGN.md)."""

    #: penalty per training frame on the standardised coordinates
    ridge: float = 0.01
    #: coordinates are standardised by their spread over the training frames, at least this
    #: (metres): a partner that barely moves against the root (the other hip) would otherwise
    #: weigh its every millimetre of error as much as a swinging hand's decimetres
    scale_floor: float = 0.01
    #: predictions are kept within the point's training range, widened by this share on each
    #: side (a body frame carried across a gap of its root can put the features where no
    #: training frame was)
    margin: float = 0.1
    #: fewest training frames
    least: int = 20
    #: weight of the Gaussian kernel beside the linear one, as a share of the linear kernel's
    #: mean (its bandwidth: the median squared distance between training frames); at most
    #: ``kernel_frames`` training frames, evenly spaced over those of the take
    kernel: float = 0.3
    kernel_frames: int = 800
    #: :func:`regress_in_frame`: the partners that make a marker's frame, the further partners
    #: whose coordinates in it are the features (at most; at least ``frame_least_features``),
    #: the penalty per fitted frame; the frame's donors may be this many times less steady (RMS
    #: spread) than the marker's steadiest partners
    frame_donors: int = 3
    frame_features: int = 6
    frame_least_features: int = 3
    frame_ridge: float = 0.1
    frame_steady: float = 10.0


def regress_points(positions, names, only=None, settings=RegressionSettings()):
    """Positions (frames, points, 3) with each gap (NaN runs) of the points in ``only``
    ((frames, points) bool: gaps starting there; default every gap) filled by the take's own
    regression of the point on the points seen throughout it; other samples as given. Gaps
    without a point seen throughout, with too few training frames, or in a take whose body has
    no frame stay NaN."""
    pos = np.asarray(positions, dtype=np.float64)
    missing = np.isnan(pos[..., 0])
    try:
        root, angle = frames_of(pos, find_reference(names))
    except GapFillError:
        return pos.copy()
    local = normalize(pos, root, angle)
    seen = ~missing
    n_frames = len(pos)
    pred = np.full_like(pos, np.nan)
    wanted = np.zeros_like(missing)
    for p, a, b in gap_runs(missing):
        if only is not None and not only[a, p]:
            continue
        lo, hi = max(a - 1, 0), min(b + 1, n_frames - 1)
        partners = seen[lo:hi + 1].all(axis=0)
        partners[p] = False
        train = np.flatnonzero(seen[:, p] & seen[:, partners].all(axis=1))
        if not partners.any() or len(train) < settings.least:
            continue
        if len(train) > settings.kernel_frames:
            train = train[np.linspace(0, len(train) - 1,
                                      settings.kernel_frames).round().astype(int)]
        x = local[:, partners].reshape(n_frames, -1)
        mean = x[train].mean(axis=0)
        scale = np.maximum(x[train].std(axis=0), settings.scale_floor)
        xs = (x - mean) / scale
        y = local[train, p]
        centre = y.mean(axis=0)
        span = np.arange(lo, hi + 1)
        # one system for the training frames and the gap's: the former make the Gram matrix
        fit = kernel_ridge(xs[np.concatenate([train, span])], np.arange(len(train)),
                           y - centre, settings.kernel, settings.ridge)[len(train):] + centre
        pred[span, p] = within_fitted(fit, y, settings.margin)
        wanted[a:b + 1, p] = True
    world = denormalize(pred, root, angle)
    return blend_into_gaps(np.where(wanted[..., None], np.nan, pos), world, wanted,
                           widened(wanted))


def within_fitted(pred, y, margin=RegressionSettings.margin):
    """``pred`` kept within the range of the fitted values ``y`` (per column), widened by
    ``margin`` of it on each side. Shared with the armatures' regression
    (:func:`~.rig.regress_channels`)."""
    low, high = y.min(axis=0), y.max(axis=0)
    pad = margin * (high - low)
    return np.clip(pred, low - pad, high + pad)


def kernel_ridge(x, train, y, weight, ridge):
    """Ridge regression in its dual form: predictions at every row of ``x`` of ``y``, known at
    its rows ``train``; ``ridge`` the penalty per training row; ``weight`` (0: linear alone)
    that of a Gaussian kernel beside the linear one, as a share of the linear kernel's mean,
    with the median squared distance between training rows as its bandwidth. Shared with the
    armatures' regression (:func:`~.rig.regress_channels`)."""
    xt = x[train]
    ridged = ridge * len(xt) * np.eye(len(xt))
    if not weight:
        return x @ (xt.T @ np.linalg.solve(xt @ xt.T + ridged, y))
    near = x @ xt.T  # the linear kernel, every row against the training rows
    scale = weight * np.trace(near[train]) / len(xt)
    squared = np.maximum(np.sum(x ** 2, axis=1)[:, None] + np.sum(xt ** 2, axis=1)[None]
                         - 2 * near, 0)
    inner = squared[train]
    # between two training rows (a row against itself is 0 give or take the rounding)
    apart = inner[~np.eye(len(xt), dtype=bool)]
    apart = apart[apart > 0]
    band = np.median(apart) if len(apart) else 1.0
    gram = near[train] + ridged + scale * np.exp(-inner / band)
    return (near + scale * np.exp(-squared / band)) @ np.linalg.solve(gram, y)


def regress_in_frame(positions, steady, only=None, least_at_ends=0,
                     settings=RegressionSettings()):
    """Positions (frames, points, 3) with each gap (NaN run) of the points in ``only`` ((frames,
    points) bool: gaps starting there; default every gap) filled by the point's place among its
    rigid partners, regressed: its coordinates in the frame (:func:`_frame`) of its
    ``settings.frame_donors`` first partners seen throughout the gap, ridge-regressed on the next
    ones' coordinates in that frame (``settings.frame_features``, fitted where all of them and the
    point are seen), the miss at the gap's ends blended across it (at a clip's end, the miss at
    the one end carried through; only gaps of ``least_at_ends`` frames or more). ``steady(p)``:
    every point's spread against ``p`` and the partners in the order to take them
    (:func:`~.baselines.steady_partners`). Skin slides and a marker near a joint does not keep
    its place among its donors, as the rigid fill takes it to; the further partners say where
    it goes. Predictions are kept within the point's fitted range, widened by ``settings.margin``
    (a take that stands still where it is seen says little of where a foot goes when it
    steps). Gaps stay NaN whose donors are far less steady than the point's steadiest
    (``settings.frame_steady``), or with too few partners or fitted frames. Other samples NaN."""
    pos = np.asarray(positions, dtype=np.float64)
    seen = np.isfinite(pos[..., 0])
    n_frames = len(pos)
    out = np.full_like(pos, np.nan)
    for p, a, b in gap_runs(~seen):
        at_end = a == 0 or b == n_frames - 1
        if ((only is not None and not only[a, p]) or (a == 0 and b == n_frames - 1)
                or (at_end and b - a + 1 < least_at_ends)):
            continue
        lo, hi = max(a - 1, 0), min(b + 1, n_frames - 1)
        spread, order = steady(p)[:2]
        donors = settings.frame_donors
        through = order[seen[lo:hi + 1, order].all(axis=0)][:donors + settings.frame_features]
        if len(through) < donors + settings.frame_least_features or (
                _rms(spread[through[:donors]])
                > settings.frame_steady * _rms(spread[order[:donors]])):
            continue
        ok = seen[:, p] & seen[:, through].all(axis=1)
        ok[a:b + 1] = False
        train = np.flatnonzero(ok)
        if len(train) < settings.least:
            continue
        rows = np.concatenate([train, np.arange(lo, hi + 1)])
        with np.errstate(invalid="ignore", divide="ignore"):
            origin, axes = _frame(pos[rows[:, None], through[:donors]])
        if not np.isfinite(axes).all():  # donors in a line
            continue
        own = np.einsum("tji,tj->ti", axes, pos[rows, p] - origin)
        x = np.einsum("tji,tkj->tki", axes, pos[rows[:, None], through[donors:]]
                      - origin[:, None]).reshape(len(rows), -1)
        fitted = slice(0, len(train))
        mean = x[fitted].mean(axis=0)
        scale = np.maximum(x[fitted].std(axis=0), settings.scale_floor)
        xs = (x - mean) / scale
        y = own[fitted]
        centre = y.mean(axis=0)
        fit = xs[len(train):] @ np.linalg.solve(
            xs[fitted].T @ xs[fitted] + settings.frame_ridge * len(train) * np.eye(xs.shape[1]),
            xs[fitted].T @ (y - centre)) + centre
        fit = within_fitted(fit, y, settings.margin)
        miss = own[len(train):] - fit  # known at the gap's ends only
        if not at_end:
            ramp = np.linspace(0.0, 1.0, len(fit))[:, None]
            fit += (1 - ramp) * miss[0] + ramp * miss[-1]
        else:
            fit += miss[0] if a > 0 else miss[-1]
        world = origin[len(train):] + np.einsum("tij,tj->ti", axes[len(train):], fit)
        out[a:b + 1, p] = world[a - lo:len(world) - (hi - b)]
    return out


def _frame(points):
    """Origin (frames, 3) and axes (frames, 3, 3; in columns) of three points (frames, 3, 3):
    their mean; the first to the second; the first to the third made square to that; their
    cross product."""
    return points.mean(axis=1), gram_schmidt(points[:, 1] - points[:, 0],
                                             points[:, 2] - points[:, 0])


def _rms(values):
    return float(np.sqrt(np.mean(np.square(values))))

