"""Baseline gap-filling methods, behind the same interface as the knowledge-base method.

- ``linear``: linear interpolation in time per coordinate (values held at clip ends);
- ``spline``: cubic spline through the observed samples (natural ends; held outside them);
- ``svt``: low-rank matrix completion of the (frames, 3 x points) matrix by singular value
  soft-thresholding (SoftImpute, Mazumder et al. 2010), a form of the SVT family;
- ``pca``: a global PCA of the knowledge base (18 components, as the baseline of Kucherenko et
  al. 2018), its coefficients fitted to the present points of each normalised frame;
- ``intercorrelation``: PCA of the take itself (Gloersen & Federolf 2016): marker trajectories
  are centred and scaled, the principal components of the frames where all points are present
  are fitted to the present coordinates of each incomplete frame (no training data needed);
- ``rigid``: rigid-body fill (Vicon Nexus "Rigid Body Fill", QTM "rigid body" fill): per missing
  sample, 3 points seen there carry it from each gap end by a best-fit rigid transform (Kabsch),
  the two estimates blended linearly across the gap: a rigid body with it where one is seen (each
  donor's distance to it and to the donors before it steady within 5 mm while seen), else the 3
  whose distance to it varied least (on a marker set, 3 steady against each other too where
  they turn it less wrongly; copies of one point counted once);
- ``pattern``: pattern fill (Vicon Nexus "Pattern Fill"): the gap takes the shape of the donor
  trajectory, seen across the whole gap, whose offset to the point varied least while both were
  seen, offset-blended to the point's values at both gap ends;
- ``local-spline``: cubic spline of each point in the body's own frame (root at the origin, hips
  facing +X: the method's normalisation), turned back into the world.

Samples that ``rigid`` and ``pattern`` have no donors for are interpolated linearly, as a user of
those tools would do next.

Every function takes positions (frames, points, 3) with NaN gaps and returns them filled; points
missing in every frame stay NaN where a method has nothing to go on.
"""

import warnings

import numpy as np

from .errors import GapFillError
from .motion import gap_runs, interpolate_rows
from .posing import rigidly_carried

#: donors of a rigid-body fill
RIGID_DONORS = 3
#: metres: a point's donors form a rigid body with it where each stays this steady (SD of the
#: distance) against it and the other donors (:func:`_donors`; tuned, docs/DESIGN.md)
RIGID_TOGETHER = 0.005
#: metres: donors steadier than this against a point (SD of the distance) are alike to
#: :func:`_donors` (on a skeleton many joints ride exactly on one segment and their spreads
#: differ by rounding alone), which takes them in the order of :func:`_alike_first` and weighs
#: them alike
RIGID_TIE = 1e-4
#: metres added (in quadrature) to the donors' spread when two rigid estimates are weighed
SPREAD_FLOOR = 0.005
#: donors in a line (a skeleton's chain) leave the turn about it free: the least turn is taken
#: there, not the one the rounding picks (:func:`~.posing.best_rotation`)
LEAN = 1e-9
#: the window of a partner's own spline in :func:`fill_spline_carried`: this many gap lengths
#: either side of the gap (a natural spline's reach falls by about 4x a frame)
CARRIED_PAD = 3
#: (gap, donor set) pairs times frames that the search for the gaps' nearest references looks at
#: in one batch
NEAREST_CHUNK = 1 << 20
#: :func:`fill_learned`: frames beyond each gap end it reads, windows a point it fits on at
#: most, and the fewest windows of a gap's length it fits on (docs/DESIGN.md);
#: at most this many window frames over all points in one fit (fewer windows a point for long
#: gaps of many points: memory)
LEARNED_KEYS = 4
LEARNED_WINDOWS = 400
LEARNED_LEAST = 20
LEARNED_FRAMES = 2_000_000


def fill_linear(pos):
    out = pos.copy()
    for p in range(pos.shape[1]):
        out[:, p] = interpolate_rows(pos[:, p], np.isfinite(pos[:, p, 0]))
    return out


def fill_spline(pos):
    from scipy.interpolate import CubicSpline

    out = pos.copy()
    t = np.arange(len(pos))
    for p in range(pos.shape[1]):
        ok = np.isfinite(pos[:, p, 0])
        if ok.sum() < 4 or ok.all():
            if ok.any() and not ok.all():
                out[:, p] = fill_linear(pos[:, p:p + 1])[:, 0]
            continue
        spline = CubicSpline(t[ok], pos[ok, p], bc_type="natural")
        first, last = t[ok][0], t[ok][-1]
        out[~ok, p] = spline(np.clip(t[~ok], first, last))
    return out


def fill_learned(pos, spline=None, only=None, longest=None, keys=LEARNED_KEYS,
                 most=LEARNED_WINDOWS):
    """Each gap (both ends in the take, with ``keys`` seen frames beyond each end) as the take's
    points move on from their keys: on each gap frame, the straight line between the frames
    either side plus an offset linear in the step between them and in the steps from each to
    ``keys`` frames beyond it, one weight per term and frame shared by the three axes and by every
    point, fitted by least squares on the take's own windows of the gap's length where a point is
    seen throughout (every other one, at most ``most`` a point, spread over the take). A natural
    spline is one such linear rule fixed in advance; this one takes what the take's motion
    favours (a jittering marker smooths its keys, a swinging hand carries them on). Only the gaps
    that start in ``only`` ((frames, points) bool; default every gap) and last at most
    ``longest`` frames (default any); the others, and every gap where fewer than
    :data:`LEARNED_LEAST` windows fit, take ``spline`` (default :func:`fill_spline` of
    ``pos``)."""
    pos, missing, hidden = _seen_so_far(pos)
    out = fill_spline(pos) if spline is None else np.array(spline, dtype=np.float64)
    frames = len(pos)
    gaps = {}  # (length, point) -> the frames before its gaps of that length
    for p, a, b in gap_runs(missing):
        length = b - a + 1
        if not ((only is not None and not only[a, p]) or (longest is not None and length > longest)
                or a - 1 - keys < 0 or b + 1 + keys >= frames
                or missing[a - 1 - keys:a, p].any() or missing[b + 1:b + 2 + keys, p].any()):
            gaps.setdefault((length, p), []).append(a - 1)
    weights = {}  # per gap length
    for (length, p), before in gaps.items():
        if length not in weights:  # windows after the frame before them, as a gap is
            weights[length] = _learned_weights(
                pos, hidden, keys, length + 1 + keys, most,
                lambda track, before: _learned_terms(track, before, length, keys),
                lambda track, before: track[before[:, None] + 1 + np.arange(length)]
                - _line(track, before, length))
        if weights[length] is not None:
            before = np.array(before)
            out[before[:, None] + 1 + np.arange(length), p] = (
                _line(pos[:, p], before, length) + np.einsum(
                    "kl,wkc->wlc", weights[length],
                    _learned_terms(pos[:, p], before, length, keys)))
    return out


def fill_learned_ends(pos, only=None, keys=LEARNED_KEYS, most=LEARNED_WINDOWS):
    """Each gap at a clip end (a point seen on one side of it only, with ``keys`` seen frames
    behind its key) as the take's points move on from a key: on each gap frame, the key plus a
    sum of the steps from it to the ``keys`` frames behind it, one weight per step and distance
    from the key, shared by the three axes and by every point, fitted by least squares on the
    take's own windows (every other one, at most ``most`` a point; a gap at the clip's start is
    read backwards in time, with the weights of the windows read forwards). Over a few frames
    a point carries on as it moved into its key, which holding the key does not. Only the gaps
    that start in ``only`` ((frames, points) bool; default every gap at a clip end); the rest,
    and gaps without enough windows (:data:`LEARNED_LEAST`), are NaN."""
    pos, missing, hidden = _seen_so_far(pos)
    out = np.full(pos.shape, np.nan)
    frames = len(pos)
    weights = {}  # per gap length
    for p, a, b in gap_runs(missing):
        length = b - a + 1
        if (a == 0) == (b == frames - 1) or (only is not None and not only[a, p]):
            continue
        track, key = (pos[:, p], a - 1) if a > 0 else (pos[::-1, p], frames - 2 - b)
        if key - keys < 0 or np.isnan(track[key - keys:key + 1, 0]).any():
            continue
        if length not in weights:  # windows after their key
            weights[length] = _learned_weights(
                pos, hidden, keys, length, most,
                lambda track, key: _steps_back(track, key, keys),
                lambda track, key: track[key[:, None] + 1 + np.arange(length)]
                - track[key][:, None])
        if weights[length] is None:
            continue
        moved = track[key] + weights[length].T @ _steps_back(track, np.array([key]), keys)[0]
        out[a:b + 1, p] = moved if a > 0 else moved[::-1]
    return out


def _seen_so_far(pos):
    """``pos`` as floats, its missing samples (frames, points) and how many of each point's
    samples are missing before each frame ((frames + 1, points): a window is seen throughout
    where the counts at its two ends agree)."""
    pos = np.asarray(pos, dtype=np.float64)
    missing = np.isnan(pos[..., 0])
    return pos, missing, np.concatenate([np.zeros((1, missing.shape[1]), int),
                                         np.cumsum(missing, axis=0)])


def _learned_weights(pos, hidden, back, on, most, terms, targets):
    """The least-squares weights (terms, targets) of ``targets(track, anchors)`` ((windows,
    targets, 3)) on ``terms(track, anchors)`` ((windows, terms, 3)), one per term and target
    shared by the three axes, over every point's windows: the anchor frames whose ``back``
    frames before and ``on`` after are all seen (``hidden``: :func:`_seen_so_far`), every other
    one, at most ``most`` a point (fewer where :data:`LEARNED_FRAMES` says), spread over the
    take. None with fewer than
    :data:`LEARNED_LEAST` windows in all."""
    anchors = np.arange(back, len(pos) - on)
    seen = hidden[anchors + on + 1] == hidden[anchors - back]
    most = min(most, max(1, LEARNED_FRAMES // (pos.shape[1] * (back + on + 1))))
    x, y = [], []
    for q in range(pos.shape[1]):
        windows = anchors[seen[:, q]][::2]
        if len(windows) > most:
            windows = windows[np.linspace(0, len(windows) - 1, most).round().astype(int)]
        x.append(terms(pos[:, q], windows))
        y.append(targets(pos[:, q], windows))
    x, y = np.concatenate(x), np.concatenate(y)
    if len(x) < LEARNED_LEAST:
        return None
    x = x.transpose(0, 2, 1).reshape(-1, x.shape[1])
    y = y.transpose(0, 2, 1).reshape(-1, y.shape[1])
    gram = x.T @ x
    gram += (1e-12 * np.trace(gram) / len(gram) + 1e-15) * np.eye(len(gram))
    return np.linalg.solve(gram, x.T @ y)


def _learned_terms(track, before, length, keys):
    """(windows, 2 keys + 1, 3): for windows of ``length`` frames after the frames ``before`` of
    one point's ``track``, the step across the window and the steps from its frames either side
    to ``keys`` frames beyond each."""
    first, last = track[before], track[before + length + 1]
    steps = ([last - first] + [track[before - j] - first for j in range(1, keys + 1)]
             + [track[before + length + 1 + j] - last for j in range(1, keys + 1)])
    return np.stack(steps, axis=1)


def _steps_back(track, key, keys):
    """(windows, keys, 3): the steps from the frames ``key`` of one point's ``track`` to the
    ``keys`` frames before each."""
    return np.stack([track[key - j] - track[key] for j in range(1, keys + 1)], axis=1)


def _line(track, before, length):
    """(windows, length, 3): the straight line over windows of ``length`` frames after the frames
    ``before`` of one point's ``track``, between the frames either side."""
    first, last = track[before], track[before + length + 1]
    return first[:, None] + np.arange(1, length + 1)[None, :, None] / (length + 1) * (
        last - first)[:, None]


def fill_svt(pos, rank_fraction=0.02, iterations=200, tol=1e-5):
    """SoftImpute: iterate X <- S_lambda(observed where known, X elsewhere)."""
    frames, n = pos.shape[:2]
    m = pos.reshape(frames, -1)
    known = np.isfinite(m)
    mean = np.where(known, m, 0).sum(axis=0) / np.maximum(known.sum(axis=0), 1)
    x = np.where(known, m - mean, 0.0)
    obs = x.copy()
    s0 = np.linalg.svd(x, compute_uv=False)[0] if x.size else 0.0
    lam = rank_fraction * s0
    z = x
    for _ in range(iterations):
        u, s, vt = np.linalg.svd(np.where(known, obs, z), full_matrices=False)
        s = np.maximum(s - lam, 0)
        z_new = (u * s) @ vt
        change = np.linalg.norm(z_new - z) / max(np.linalg.norm(z), 1e-12)
        z = z_new
        if change < tol:
            break
    out = np.where(known, m, z + mean)
    out[:, ~known.any(axis=0)] = np.nan
    return out.reshape(pos.shape)


def fill_global_pca(pos, kb_poses, reference, components=18, ridge=1e-6):
    """Knowledge-base PCA fitted per normalised frame to the present points."""
    from .normalize import denormalize, frames_of, normalize, reference_template

    frames, n = pos.shape[:2]
    flat = kb_poses.reshape(len(kb_poses), -1).astype(np.float64)
    mean = flat.mean(axis=0)
    _, _, vt = np.linalg.svd(flat[:: max(1, len(flat) // 20000)] - mean, full_matrices=False)
    basis = vt[:components].T  # (d, c)
    root, angle = frames_of(pos, reference, reference_template(kb_poses, reference))
    x = normalize(pos, root, angle).reshape(frames, -1)
    known = np.isfinite(x)
    out = x.copy()
    for t in np.flatnonzero(~known.all(axis=1)):
        k = known[t]
        if not k.any():
            continue
        b = basis[k]
        h = np.linalg.solve(b.T @ b + ridge * np.eye(b.shape[1]), b.T @ (x[t, k] - mean[k]))
        out[t, ~k] = mean[~k] + basis[~k] @ h
    return denormalize(out.reshape(frames, n, 3), root, angle)


def fill_intercorrelation(pos, variance=0.99, iterations=30, tol=1e-6):
    """Gloersen & Federolf (2016): PCA of the take's own marker intercorrelations.

    Trajectories are centred and scaled per coordinate; gaps start from linear interpolation and
    are replaced, until they settle, by their projection on the principal components that
    explain ``variance`` of the take (every frame takes part, so no complete frame is needed).
    """
    frames, n = pos.shape[:2]
    m = pos.reshape(frames, -1)
    known = np.isfinite(m)
    if known.all(axis=0).sum() == 0 and not known.any():
        raise GapFillError("intercorrelation needs some observed samples")
    start = fill_linear(pos).reshape(frames, -1)
    cols = known.any(axis=0)  # coordinates never seen cannot be inferred from the take
    x = start[:, cols]
    k = known[:, cols]
    mean = np.where(k, x, 0).sum(axis=0) / k.sum(axis=0)
    scale = np.sqrt(np.where(k, (x - mean) ** 2, 0).sum(axis=0) / k.sum(axis=0)) + 1e-9
    z = (x - mean) / scale
    for _ in range(iterations):
        u, s, vt = np.linalg.svd(z, full_matrices=False)
        share = np.cumsum(s ** 2) / max((s ** 2).sum(), 1e-30)
        basis = vt[: int(np.searchsorted(share, variance)) + 1]
        new = np.where(k, z, (z @ basis.T) @ basis)
        change = np.linalg.norm(new - z) / max(np.linalg.norm(z), 1e-12)
        z = new
        if change < tol:
            break
    out = m.copy()
    out[:, cols] = np.where(k, x, z * scale + mean)
    return out.reshape(pos.shape)


def _pair_stats(pos, p, seen):
    """For point ``p`` against every point: the standard deviation of their distance, the
    total variance of their offset and their mean distance over the frames where both are seen
    (inf where fewer than 10 such frames, and for ``p`` itself)."""
    both = seen & seen[:, p:p + 1]
    count = both.sum(axis=0)
    offset = np.where(both[..., None], pos - pos[:, p:p + 1], 0.0)
    square = np.einsum("tnc,tnc->tn", offset, offset)
    dist = np.sqrt(square)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean_d = dist.sum(axis=0) / count
        dist_sd = np.sqrt(np.where(both, (dist - mean_d) ** 2, 0).sum(axis=0) / count)
        mean_o = offset.sum(axis=0) / count[:, None]
        # E|o|^2 - |E o|^2 (offsets of metres, variances of square millimetres and more)
        offset_var = np.maximum(square.sum(axis=0) / count
                                - (mean_o ** 2).sum(axis=1), 0.0)
    bad = count < 10
    bad[p] = True
    return (np.where(bad, np.inf, dist_sd), np.where(bad, np.inf, offset_var),
            np.where(bad, np.inf, mean_d))


def _gap_ends(a, b, frames):
    """The observed frames either side of a gap a..b (inclusive) that exist."""
    return [t for t in (a - 1, b + 1) if 0 <= t < frames]


def _end_weights(a, b, ends):
    """(frames of the gap, ends) linear blending weights of the estimates from each end."""
    if len(ends) == 1:
        return np.ones((b - a + 1, 1))
    w = (np.arange(a, b + 1) - ends[0]) / (ends[1] - ends[0])
    return np.stack([1 - w, w], axis=1)


def fill_rigid(pos, donors=RIGID_DONORS):
    """Rigid-body fill: each missing sample carried by the ``donors`` steadiest partners seen at
    its frame and at the gap's ends (see the module docstring)."""
    return rigid_estimates(pos, donors)[0]


def rigid_estimates(pos, donors=RIGID_DONORS, weighted=False, partners=None, cache=None,
                    reach=None, should_cancel=None, only=None):
    """:func:`fill_rigid` and, per sample it carried, the RMS spread (metres) of its donors'
    distances to it (and, where they form a rigid body with it, to each other: :func:`_donors`):
    near 0 where the point rides on a rigid segment with them (NaN elsewhere).

    ``weighted`` weighs each donor's fit by the inverse square of its spread. ``partners``:
    positions (same shape, more of them seen) to choose the donors from, e.g. a take whose
    gaps are hidden further to test the fill. ``cache``: a dict kept between calls with the
    same ``partners``, so their statistics are computed once. Of points that are one
    (:func:`same_points`), only the steadiest is a donor.

    ``reach``: a second estimate is weighed in, from the steadiest donors seen at each frame of
    the gap even where they are not seen at its ends, carried from the nearest frames before and
    after the gap (at most ``reach`` times the gap's length away) where the point and those
    donors are seen; the two are weighted by the inverse of their donors' squared spread plus
    :data:`SPREAD_FLOOR` squared. With many points gone at once, the gap's ends often miss the
    steadiest donors and the fill from the ends falls back to partners on other segments.
    ``should_cancel()``, asked before each point's gaps, may stop the work (KeyboardInterrupt).
    ``only``: a (frames, points) mask; the gaps that start outside it keep NaN (and no spread).
    """
    pos = np.asarray(pos, dtype=np.float64)
    seen = np.isfinite(pos[..., 0])
    out = pos.copy()
    spreads = np.full(seen.shape, np.nan)
    stats = {} if cache is None else cache
    partners = pos if partners is None else np.asarray(partners, dtype=np.float64)
    runs = {}
    for p, a, b in gap_runs(~seen):
        if only is None or only[a, p]:
            runs.setdefault(p, []).append((a, b))
    for p, gaps in runs.items():
        if should_cancel and should_cancel():
            raise KeyboardInterrupt
        steady = steady_partners(partners, p, stats)
        estimate, rms = _carry(pos, seen, p, gaps, steady, donors, weighted)
        if reach:
            estimate, rms = _weigh([(estimate, rms), _carry(pos, seen, p, gaps, steady, donors,
                                                            weighted, reach)])
        rows = np.isfinite(rms)
        frames = np.concatenate([np.arange(a, b + 1) for a, b in gaps])[rows]
        out[frames, p] = estimate[rows]
        spreads[frames, p] = rms[rows]
    return (fill_linear(out) if only is None else out), spreads


def steady_partners(partners, p, cache):
    """Point ``p``'s partners on ``partners`` (positions, frames x points x 3) as the rigid
    fill tries them for donors: every point's spread against ``p`` (SD of their distance while
    both are seen; inf where too rarely), the points in the order they are tried (steadiest
    first; of copies (:func:`same_points`) only the steadiest; those alike as
    :func:`_alike_first` orders them), their spreads against each other (:func:`_mutual`) and,
    on a marker set, :func:`_donors`' ``apart``. Kept in ``cache``, a dict shared by calls on
    the same ``partners``, with every pair's statistics, so each is computed once."""
    if p in cache:
        return cache[p]
    partners = np.asarray(partners, dtype=np.float64)

    if "seen" not in cache:
        cache["seen"] = np.isfinite(partners[..., 0])

    def spread_of(q, of="spread"):  # every point's spread (or distance) against q, once per take
        if ("spread", q) not in cache:
            spread, _, distance = _pair_stats(partners, q, cache["seen"])
            cache[("spread", q)], cache[("distance", q)] = spread, distance
        return cache[(of, q)]

    spread = spread_of(p)
    order = np.flatnonzero(np.isfinite(spread))
    order = order[np.argsort(np.maximum(spread[order], RIGID_TIE), kind="stable")]
    # a second copy of a donor adds nothing to its fit but a turn about the others
    if "same" not in cache:
        cache["same"], cache["between"], cache["skeleton"] = _pair_table(partners,
                                                                             cache=cache)
    kept = np.array([j for i, j in enumerate(order)
                     if not cache["same"][j, order[:i]].any()], dtype=int)
    mutual = _mutual(spread, kept, spread_of)
    first = _alike_first(spread[kept], spread_of(p, "distance")[kept], mutual)
    kept, mutual = kept[first], mutual[np.ix_(first, first)]
    # a marker set's loose donors may be taken steady against each other too
    apart = None if cache["skeleton"] else (
        np.where(np.isfinite(mutual), mutual, 0.0), spread_of(p, "distance")[kept],
        cache["between"][np.ix_(kept, kept)])
    cache[p] = spread, kept, mutual, apart
    return cache[p]


def same_points(pos, tolerance=0.001):
    """(points, points) booleans: the pairs of points that are one, less than ``tolerance``
    (metres) apart on the mean while both are seen (e.g. HDM05's unlabelled ``*0 *1 *2``,
    copies of three labelled markers), judged on at most 500 frames."""
    return _pair_table(pos, tolerance)[0]


def steady_pairs(pos, most=RIGID_TIE, cache=None):
    """The pairs of points (pairs x 2, ``i < j``) whose distance keeps within ``most`` (metres,
    SD) over 10 or more frames where both are seen, that distance (on the mean) and its SD:
    at :data:`RIGID_TIE`, a skeleton's bones and the joints on one segment, points of a rigid
    cluster the capture software solved; at a few millimetres, markers on one segment as well
    (skin slides); judged on at most 500 frames."""
    mean, spread = _pair_spreads(pos, cache)[:2]
    first, second = np.nonzero(np.triu(spread <= most, 1))
    return np.stack([first, second], axis=1), mean[first, second], spread[first, second]


def _pair_spreads(pos, cache=None):
    """On at most 500 frames: every pair's mean distance while both are seen (NaN where never),
    its SD (inf where fewer than 10 such frames, and for a point with itself), and which points
    are seen there. ``cache``: a dict kept between calls on the same ``pos``."""
    if cache is not None and "pair spreads" in cache:
        return cache["pair spreads"]
    sample = np.asarray(pos, dtype=np.float64)[::max(1, len(pos) // 500)]
    seen = np.isfinite(sample[..., 0])
    points = sample.shape[1]
    mean, spread = np.full((points, points), np.nan), np.full((points, points), np.inf)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # pairs never seen together
        for i in range(points):
            distance = np.linalg.norm(sample - sample[:, i:i + 1], axis=2)
            mean[i] = np.nanmean(distance, axis=0)
            spread[i] = np.where((seen & seen[:, i:i + 1]).sum(axis=0) >= 10,
                                 np.nanstd(distance, axis=0), np.inf)
    np.fill_diagonal(spread, np.inf)
    if cache is not None:
        cache["pair spreads"] = mean, spread, seen
    return mean, spread, seen


def _pair_table(pos, tolerance=0.001, cache=None):
    """On at most 500 frames: :func:`same_points`, every pair's mean distance while both are
    seen (NaN where never), and whether the take is a skeleton: every point seen keeps its
    distance to another (not its copy) within :data:`RIGID_TIE` over 10 frames or more, as a
    skeleton's joints do, each a bone's length from the next; no marker on soft tissue does
    (HDM05's head, thorax and pelvis markers are rigid to 0.04 mm among themselves, its limb
    markers are not)."""
    mean, spread, seen = _pair_spreads(pos, cache)
    exact = spread <= RIGID_TIE
    same = mean < tolerance
    np.fill_diagonal(same, False)
    skeleton = bool((exact & ~same).any(axis=1)[seen.sum(axis=0) >= 10].all())
    return same, mean, skeleton


def _carry(pos, seen, p, runs, steady, donors, weighted, reach=None):
    """Rigid estimates of point ``p`` over its gaps ``runs`` ((first, last) frames, inclusive)
    and their donors' RMS spread, one row per gap frame in the order of ``runs`` (NaN where
    none). ``steady``: every point's spread against ``p``, the points in order of it (the
    steadiest first, those alike as :func:`_alike_first` orders them), their spreads against
    each other (:func:`_mutual`) and, on a marker set, :func:`_donors`' ``apart``. Per frame,
    ``donors`` seen there (:func:`_donors`), carried from the gap's ends (where the donors must
    be seen) or, given ``reach``, from the nearest frames within ``reach`` times the gap's
    length where ``p`` and the donors are seen; estimates from references either side are
    blended linearly across the gap. All gaps of the point are fitted at once (one batch of
    Kabsch fits)."""
    frames = len(pos)
    a, b = np.array(runs, dtype=int).reshape(-1, 2).T
    length = b - a + 1
    gap = np.repeat(np.arange(len(a)), length)  # each row's gap
    t = np.arange(length.sum()) - np.repeat(np.cumsum(length) - length - a, length)
    estimate = np.full((len(t), 3), np.nan)
    rms = np.full(len(t), np.nan)
    spread, order, mutual, apart = steady
    if len(order) < donors:
        return estimate, rms
    # the donors each gap may take: seen at its ends, or with the point within reach of them
    before, after = a > 0, b < frames - 1
    if reach is None:
        allowed = np.ones((len(a), len(order)), bool)
        allowed[before] &= seen[a[before] - 1][:, order]
        allowed[after] &= seen[b[after] + 1][:, order]
    else:
        far = (reach * length).astype(int)
        before &= far > 0
        after &= far > 0
        both = np.concatenate([np.zeros((1, len(order)), int),
                               np.cumsum(seen[:, order] & seen[:, p:p + 1], axis=0)])
        allowed = np.repeat((before | after)[:, None], len(order), axis=1)
        lo = np.maximum(0, a - far)
        allowed[before] &= both[a[before]] > both[lo[before]]
        hi = np.minimum(frames, b + 1 + far)
        allowed[after] &= both[hi[after]] > both[b[after] + 1]
    ok = seen[t][:, order] & allowed[gap]
    places, costs = _donors(ok, spread[order], mutual, donors, apart)
    rows = np.flatnonzero(np.isfinite(costs).all(axis=1))
    if not len(rows):
        return estimate, rms
    chosen, costs = order[places[rows]], costs[rows]  # (rows, donors)
    g, t = gap[rows], t[rows]
    if reach is None:
        refs = np.stack([np.where(before[g], a[g] - 1, -1), np.where(after[g], b[g] + 1, -1)],
                        axis=1)
    else:
        refs = _nearest_seen(seen, p, chosen, g, a, b, far)
    # each row's first reference (before the gap if any), then its second
    refs = np.where((refs[:, :1] < 0), refs[:, ::-1], refs)
    has = refs[:, 0] >= 0
    rows, chosen, costs, t, refs = rows[has], chosen[has], costs[has], t[has], refs[has]
    if not len(rows):
        return estimate, rms
    two = refs[:, 1] >= 0
    with np.errstate(invalid="ignore", divide="ignore"):
        late = np.where(two, (t - refs[:, 0]) / (refs[:, 1] - refs[:, 0]), 0.0)
    weights = np.stack([np.where(two, 1 - late, 1.0), late], axis=1)
    w = 1 / np.maximum(costs, RIGID_TIE) ** 2 if weighted else np.ones(chosen.shape)
    w /= w.sum(axis=1, keepdims=True)
    cw = w[..., None]  # (rows, donors, 1)
    cur = pos[t[:, None], chosen]  # (rows, donors, 3)
    found = np.zeros((len(rows), 3))
    for k in range(2):
        use = refs[:, k] >= 0
        if not use.any():
            continue
        ref_t = refs[use, k]
        ref = pos[ref_t[:, None], chosen[use]]  # (rows, donors, 3)
        moved = rigidly_carried(ref, cur[use], cw[use], pos[ref_t, p], lean=LEAN)
        found[use] += weights[use, k][:, None] * moved
    estimate[rows] = found
    rms[rows] = np.sqrt(np.mean(costs ** 2, axis=1))
    return estimate, rms


def _mutual(spread, order, spread_of):
    """The spreads between the candidate donors ``order`` of a point (``spread``: theirs against
    it), in that order: from ``spread_of(q)`` (every point's spread against ``q``) for those
    within :data:`RIGID_TOGETHER` of the point, the only ones that can be a rigid body with it
    (:func:`_donors`); inf between the others."""
    order = np.asarray(order, dtype=int)
    mutual = np.full((len(order),) * 2, np.inf)
    steady = np.flatnonzero(spread[order] <= RIGID_TOGETHER)
    for i in steady:
        mutual[i] = spread_of(order[i])[order]
    return mutual


def _alike_first(spread, distance, mutual):
    """The order in which candidate donors (steadiest first; ``spread`` against the point,
    ``distance`` to it on the mean, ``mutual`` spreads) are taken: those steadier than
    :data:`RIGID_TIE`, alike to :func:`_donors`, with the most others of them steady against
    them first, then the nearest. On a skeleton the joints up and down the chain from a point
    keep their distance to it too (a bone's length) but turn about it; the joints of its own
    segment are steady against each other as well."""
    alike = spread <= RIGID_TIE
    together = (alike[:, None] & alike[None] & (mutual <= RIGID_TIE)).sum(axis=1)
    return np.lexsort((distance, -together, np.maximum(spread, RIGID_TIE)))


def _donors(ok, spread, mutual, donors, apart=None):
    """Per row of candidates ``ok`` ((rows, candidates) bool; ``spread``: theirs against the point,
    ``mutual``: theirs against each other), the places of its ``donors`` among the candidates and
    their spread, (rows, donors) each (inf where fewer are there). A rigid body with the point
    first: the donors chosen one by one, each the steadiest against the point and the donors
    before it, where all of that stays within :data:`RIGID_TOGETHER`; elsewhere the steadiest
    against the point alone. A joint keeps its distance to the next one down the chain (a bone's
    length) while that one turns about it: three such partners are no rigid body, and where a
    rigid one rides with the point (a clavicle with the back) the fit through them swung it 180
    mm off; where none does (a knee) they are still the best guess.

    Markers on soft tissue have no such chain (``apart``, given for a marker set: ``mutual``
    with 0 where unknown, the candidates' mean distance to the point and to each other): there
    three donors chosen as the rigid body is, without its bound, are taken instead where they
    promise the point a smaller error (:func:`_turn_error`); donors steady against each other
    may lie along one limb (elbow, wrist, finger), about which the fit turns freely."""
    places, costs = _steadiest(ok, spread, mutual, donors)
    loose = np.flatnonzero(~(costs.max(axis=1) <= RIGID_TOGETHER))
    places[loose], costs[loose] = _steadiest(ok[loose], spread, np.zeros_like(mutual), donors)
    if apart is None or donors != 3 or not len(loose):
        return places, costs
    known, to_point, between = apart
    other, other_costs = _steadiest(ok[loose], spread, known, donors)
    pairs = [known[places[loose, i], places[loose, j]] for i, j in ((0, 1), (0, 2), (1, 2))]
    worst = np.maximum.reduce([costs[loose].max(axis=1), *pairs])
    # the same three in another order promise the same: rounding must not choose their costs
    better = ((_turn_error(other, other_costs.max(axis=1), to_point, between)
               < _turn_error(places[loose], worst, to_point, between))
              & (np.sort(other, axis=1) != np.sort(places[loose], axis=1)).any(axis=1))
    places[loose[better]], costs[loose[better]] = other[better], other_costs[better]
    return places, costs


def _turn_error(places, worst, to_point, between):
    """What three donors (``places``, rows of 3) promise a point they carry, up to a factor:
    their worst spread ``worst`` times the point's mean distance from them over the least
    height of their triangle (``to_point``, ``between``: mean distances), the lever by which a
    turn about the triangle's longest side, which the spread leaves free, moves the point. NaN
    where there is no triangle (a row without candidates names one place thrice; pairs never
    seen together): it compares as no better."""
    a, b, c = (between[places[:, i], places[:, j]] for i, j in ((0, 1), (1, 2), (0, 2)))
    half = (a + b + c) / 2
    area = np.sqrt(np.maximum(half * (half - a) * (half - b) * (half - c), 0.0))
    # no triangle (the three places one, a pair never seen together): NaN, as said
    with np.errstate(invalid="ignore"):
        height = 2 * area / np.maximum(np.maximum(a, b), c)
        return worst * to_point[places].mean(axis=1) / np.maximum(height, 1e-6)


def _steadiest(ok, spread, mutual, donors):
    """:func:`_donors` chosen one by one, each the steadiest against the point and the donors
    before it (with ``mutual`` all 0: against the point alone, the first in ``spread``'s order)."""
    rows = np.arange(len(ok))
    cost = np.where(ok, spread[None], np.inf)
    places, costs = [], []
    for _ in range(donors):
        pick = np.argmin(np.maximum(cost, RIGID_TIE), axis=1)
        places.append(pick)
        costs.append(cost[rows, pick])
        cost[rows, pick] = np.inf
        cost = np.maximum(cost, mutual[pick])
    return np.stack(places, axis=1), np.stack(costs, axis=1)


def _weigh(found):
    """Rigid estimates ``(estimate, rms)`` of the same frames averaged with the inverse of their
    donors' squared spread (plus :data:`SPREAD_FLOOR` squared, the error that the donors'
    steadiness does not show) as weights; NaN where none has an estimate."""
    weights = [np.where(np.isfinite(rms), 1 / (np.nan_to_num(rms) ** 2 + SPREAD_FLOOR ** 2), 0.0)
               for _, rms in found]
    total = sum(weights)
    with np.errstate(invalid="ignore"):
        estimate = sum(w[:, None] * np.nan_to_num(e) for w, (e, _) in zip(weights, found)) \
            / total[:, None]
        rms = np.sqrt(sum(w * np.nan_to_num(r) ** 2 for w, (_, r) in zip(weights, found)) / total)
    return estimate, rms


def _nearest_seen(seen, p, chosen, gap, a, b, far):
    """Per row (its donors ``chosen``, its ``gap`` among ``a``..``b``): the last frame before
    the gap and the first after it, at most ``far[gap]`` frames away, where ``p`` and the
    donors are all seen (-1 where there is none)."""
    combos, which = np.unique(np.column_stack([gap, chosen]), axis=0, return_inverse=True)
    which = which.reshape(-1)
    g, points = combos[:, 0], np.column_stack([np.full(len(combos), p), combos[:, 1:]])
    out = np.full((len(combos), 2), -1)
    # combos in order of reach, in chunks of at most NEAREST_CHUNK frames looked at
    order = np.argsort(far[g], kind="stable")
    start = 0
    while start < len(order):
        stop = start + 1
        while stop < len(order) and (stop + 1 - start) * far[g[order[stop]]] <= NEAREST_CHUNK:
            stop += 1
        some = order[start:stop]
        steps = np.arange(1, far[g[some]].max() + 1)
        for side, (edge, sign) in enumerate(((a, -1), (b, 1))):
            f = edge[g[some]][:, None] + sign * steps
            inside = (steps <= far[g[some]][:, None]) & (f >= 0) & (f < len(seen))
            hit = seen[np.clip(f, 0, len(seen) - 1)[..., None], points[some][:, None]].all(
                axis=2) & inside
            found = hit.any(axis=1)
            out[some[found], side] = f[found, hit[found].argmax(axis=1)]
        start = stop
    return out[which]



def fill_pattern(pos, only=None, cache=None):
    """Pattern fill: each gap shaped like its steadiest donor's trajectory (see the module
    docstring): ``F(t) = V_F(t) - V_D(t) + D(t)`` with ``V`` the straight line between a
    trajectory's values at the gap's ends (the offset at the one end at a clip end).

    ``only``: a (frames, points) mask; the gaps that start outside it, and those no donor spans,
    keep NaN. ``cache``: a dict of each point's donor statistics, kept between calls on the same
    take (with some samples hidden, say)."""
    pos = np.asarray(pos, dtype=np.float64)
    frames = len(pos)
    seen = np.isfinite(pos[..., 0])
    out = pos.copy()
    stats = {} if cache is None else cache
    for p, a, b in gap_runs(~seen):
        ends = _gap_ends(a, b, frames)
        if not ends or (only is not None and not only[a, p]):
            continue
        if p not in stats:
            stats[p] = _pair_stats(pos, p, seen)[1]
        lo, hi = min(ends), max(ends)
        usable = seen[lo:hi + 1].all(axis=0) & np.isfinite(stats[p])
        if not usable.any():
            continue
        q = int(np.argmin(np.where(usable, stats[p], np.inf)))
        weights = _end_weights(a, b, ends)
        offsets = np.stack([pos[t, p] - pos[t, q] for t in ends])  # (ends, 3)
        out[a:b + 1, p] = pos[a:b + 1, q] + weights @ offsets
    return fill_linear(out) if only is None else out


def fill_spline_carried(pos, spline, only, donors=RIGID_DONORS):
    """The cubic spline of each point through the take (``spline``: :func:`fill_spline` of
    ``pos``) carried by how far its partners stray from theirs over the gap: on each gap with
    both ends in the take that starts in ``only`` (a (frames, points) mask), the spline plus
    the mean of what the ``donors`` partners seen across the gap (and a frame either side) whose
    offset to the point varied least do beyond a spline of their own with the gap's frames
    hidden (over a window of :data:`CARRIED_PAD` gap lengths either side), weighted by the
    inverse of that variance; where fewer partners are seen, their mean counts for their share
    of ``donors`` (one far partner's stray is its own). What a spline misses where most of the
    body is gone at once (a landing, a turn) the body's seen points miss too. With one partner,
    equal to it plus a spline of the point's offset to it: a pattern fill whose offset follows a
    spline, not a straight line. Gaps without a partner keep ``spline``; the others outside
    ``only`` are NaN."""
    from scipy.interpolate import CubicSpline

    pos = np.asarray(pos, dtype=np.float64)
    frames = len(pos)
    seen = np.isfinite(pos[..., 0])
    out = np.full(pos.shape, np.nan)
    stats = {}  # each point's offset variance to every other
    chosen = {}  # (first, last) -> [(point, partners, shares)]
    for p, a, b in gap_runs(~seen):
        if a == 0 or b == frames - 1 or not only[a, p]:
            continue
        out[a:b + 1, p] = spline[a:b + 1, p]
        if p not in stats:
            stats[p] = _pair_stats(pos, p, seen)[1]
        variance = np.where(seen[a - 1:b + 2].all(axis=0), stats[p], np.inf)
        partners = np.argsort(variance)[:donors]
        partners = partners[np.isfinite(variance[partners])]
        if len(partners):
            w = 1 / np.maximum(variance[partners], RIGID_TIE ** 2)
            # fewer partners than ``donors``: their stray for that share of the whole
            chosen.setdefault((a, b), []).append(
                (p, partners, w / w.sum() * len(partners) / donors))
    for (a, b), gaps in chosen.items():
        pad = CARRIED_PAD * (b - a + 1)
        lo, hi = max(0, a - pad), min(frames, b + 1 + pad)
        t = np.arange(lo, hi)
        outside = (t < a) | (t > b)
        partners = np.unique(np.concatenate([q for _, q, _ in gaps]))
        # a partner's track less its spline over the gap, one spline for those seen throughout
        # the window
        stray = {}
        whole = seen[lo:hi, partners].all(axis=0)
        groups = [partners[whole]] + [[q] for q in partners[~whole]]
        for group in groups:
            if not len(group):
                continue
            ok = outside & seen[lo:hi, group].all(axis=1)
            track = pos[lo:hi][:, group]
            fitted = CubicSpline(t[ok], track[ok], bc_type="natural")(np.arange(a, b + 1))
            stray.update(zip(group, np.moveaxis(pos[a:b + 1][:, group] - fitted, 1, 0)))
        for p, qs, shares in gaps:
            out[a:b + 1, p] += sum(share * stray[q] for share, q in zip(shares, qs))
    return out


def fill_local_spline(pos, reference):
    """Cubic spline of each point in the body's own frame (:mod:`.normalize`), back in the
    world; ``reference`` is the point set's :class:`~.normalize.Reference`. Where no frame
    shows the root and hips, the body has no frame: the spline in the world."""
    from .normalize import denormalize, frames_of, normalize

    try:
        root, angle = frames_of(pos, reference)
    except GapFillError:
        return fill_spline(pos)
    return denormalize(fill_spline(normalize(pos, root, angle)), root, angle)
