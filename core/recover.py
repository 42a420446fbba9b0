"""The knowledge-base method (``knn``): local PCA of the K nearest poses + energy optimisation.

For every frame that has missing points (METHOD.md, steps 3-6):

1. search the K nearest knowledge-base poses over the points present in that frame;
2. fit a local PCA to them: mean ``mu_t``, the top components ``W_t`` that capture ``variance``
   of the neighbours' spread (at most ``max_components``), eigenvalues ``lambda``, and the mean
   variance left out, ``sigma2_t`` (probabilistic PCA's noise);
3. the pose is ``mu_t + W_t h_t``; all ``h_t`` are found together by minimising

   ``w_r sum h^2/lambda``                               retrieval prior (Mahalanobis)
   ``+ w_in sum_present (pose - observed)^2 / sigma2_t``     input term
   ``+ w_l sum_limbs (length - clip median)^2 / s_l^2``      limb term
   ``+ w_s sum_missing |sum_j c_j X_{t+j}|^2 / s_s^2``      smoothness (world coordinates)

   first in closed form per frame without the last two terms, then refined jointly over the
   clip with L-BFGS (one batched energy and gradient, no loop over frames; the first two terms
   come from each frame's normal equations, the last two from sparse maps over the modelled
   points only, see :class:`_Problem`).

Beyond the paper:
- the model is also evaluated one frame outside each gap (the point is hidden there), and the
  difference to the observation at both ends is blended linearly across the gap, so a fill meets
  the observed data without a jump; at clip ends the one known offset is kept;
- smoothness penalises acceleration by default (the paper's term, ``smoothness="paper"``, pulls
  each frame towards the previous ones and lags on fast motion);
- frames with fewer than ``min_present`` points present are not modelled: their prediction is
  interpolated in time from the model trajectory around them, then blended like any other; the
  smoothness term skips the windows that reach into their missing points.
"""

from dataclasses import dataclass, replace

import numpy as np
from scipy.optimize import minimize
from scipy.sparse import csr_matrix

from .baselines import fill_linear
from .errors import GapFillError
from .kb import match_names
from .motion import gap_runs
from .normalize import (denormalize, frames_of, normalize, reference_points,
                        reference_template, rotation_z)
from .search import KBIndex

#: smoothness kernels: residual_t = sum_j c_j X_{t+j} for j = 0..len-1 (t = first frame)
KERNELS = {
    "acceleration": np.array([1.0, -2.0, 1.0]),
    "paper": np.array([-1.0, -2.0, -3.0, 6.0]) / 6.0,  # X_t - (3X_{t-1} + 2X_{t-2} + X_{t-3})/6
}


#: a second pass models again the frames whose root moved more than this (m) or whose facing
#: turned more than this (rad) once the hips are filled
CHANGE_ROOT = 0.01
CHANGE_ANGLE = np.deg2rad(1.0)


#: the query-noise factors "auto" chooses from, how many frames it checks, and the factor used
#: where no frame shows the points some gap hides (then nothing can be checked)
NOISE_FACTORS = (0.0, 0.125, 0.25, 0.5, 1.0)
CALIBRATION_FRAMES = 192
UNCHECKED_FACTOR = 0.25

#: neighbours per frame when KnnSettings.k is None
DEFAULT_K = 4096
#: subspace iteration of the local PCA: extra columns and power iterations
OVERSAMPLE = 8
POWER_ITERATIONS = 1


@dataclass(frozen=True)
class KnnSettings:
    """Settings of the ``knn`` method (the paper's weights; see docs/METHOD_NOTES.md).

    ``k`` None means 4096 neighbours, or the whole knowledge base when it is smaller: on our
    knowledge bases (7k-100k poses) accuracy kept improving up to K = 2048-4096, unlike the
    paper's K = 256 on the whole CMU database. What matters is how far the neighbourhood
    reaches, not how many poses the model sees: each local model is fitted to a random
    ``model_neighbours`` of the K (same accuracy within 2 %, a quarter of the cost at K = 4096;
    docs/METHOD_NOTES.md).
    """

    k: int = None
    #: the local PCA is fitted to a random sample of this many of the K neighbours (None: all)
    model_neighbours: int = 1024
    w_r: float = 0.55
    w_in: float = 0.9
    w_l: float = 0.3
    w_s: float = 0.15
    variance: float = 0.999
    max_components: int = 32
    smoothness: str = "acceleration"
    #: scales that make the terms unitless: limb length error (m), acceleration (m/s^2)
    limb_scale: float = 0.01
    accel_scale: float = 11.0
    #: lower bound of the model's per-coordinate noise variance (m^2)
    noise_floor: float = 1e-6
    min_present: int = 3
    #: raise each frame's model noise to ``query_noise * missing share * (mean squared distance
    #: per coordinate from the query to its median neighbour)``; "auto" picks the factor among
    #: NOISE_FACTORS per fill by hiding present points and predicting them (0: the paper)
    query_noise: object = "auto"
    max_iterations: int = 20
    batch_frames: int = 256
    #: local models are fitted at most this often per second (Hz); frames in between with the
    #: same missing points share the model before them (None: every frame)
    model_fps: float = 30.0
    #: a longer take is filled in pieces of about this many frames, each one read with
    #: ``segment_overlap`` frames of the next and cross-faded into it (memory stays bounded)
    segment_frames: int = 6000
    segment_overlap: int = 600
    #: where the search and the local models' products run: "auto" (torch on a CUDA GPU, else
    #: torch on the CPU, else numpy when torch is absent), "numpy", "cpu" or "cuda" (torch)
    device: str = "auto"
    random_state: int = 0


def _local_pca(neighbours, settings, rng, backend):
    """Top principal components of each frame's neighbours (batched subspace iteration).

    neighbours: (t, k, d) float32, centred in place. Returns mean (t, d), components (t, d, r)
    and eigenvalues (t, r), both 0 where a component is not used, and the noise variance (t,):
    the mean variance the used components leave out (probabilistic PCA); float64. The mean, the
    covariance and the iteration are float32 like the poses (the eigenvalues that matter lie far
    above its rounding), the small eigenproblem and the results float64.
    """
    t, k, d = neighbours.shape
    # sums by a product (float32, like the poses: errors of a few um; 2x a float64 reduction)
    mean = (np.ones((1, k), neighbours.dtype) @ neighbours)[:, 0].astype(np.float64) / k
    neighbours -= mean[:, None, :].astype(neighbours.dtype)
    cov = backend.gram(neighbours) / np.float32(max(1, k - 1))
    total = np.trace(cov, axis1=1, axis2=2, dtype=np.float64)
    r = min(settings.max_components, d, k - 1)
    start = rng.standard_normal((d, min(d, r + OVERSAMPLE))).astype(cov.dtype)
    y = (cov.reshape(-1, d) @ start).reshape(t, d, -1)  # one product: the start is shared
    for _ in range(POWER_ITERATIONS):
        y = cov @ _orthonormal(y)
    basis = _orthonormal(y)  # (t, d, r+8)
    small = basis.transpose(0, 2, 1) @ (cov @ basis)
    lam, vec = np.linalg.eigh(small.astype(np.float64))  # float64: faster here, and exact
    lam = lam[:, ::-1][:, :r]
    comps = basis @ np.ascontiguousarray(vec[:, :, ::-1][:, :, :r], dtype=basis.dtype)
    comps = comps.astype(np.float64)
    lam = np.clip(lam, 0, None)
    captured = np.cumsum(lam, axis=1) / np.maximum(total, 1e-30)[:, None]
    used = np.concatenate([np.ones((t, 1), bool), captured[:, :-1] < settings.variance], axis=1)
    lam = np.where(used, lam, 0.0)
    comps *= (lam > 0)[:, None, :]
    left = np.maximum(total - lam.sum(axis=1), 0) / np.maximum(1, d - used.sum(axis=1))
    return mean, comps, lam, np.maximum(left, settings.noise_floor)


def _orthonormal(y):
    """Orthonormal columns spanning each (d, r) matrix of the batch (Householder QR)."""
    return np.linalg.qr(y)[0]


class _Problem:
    """The clip-wide energy over the PCA coefficients ``h`` (m, r) of the modelled frames.

    The prior and input terms are quadratic in each frame's ``h``: they are evaluated from the
    per-frame normal equations (``h^T A h + 2 b^T h + c``, O(r^2) a frame). The limb and
    smoothness terms see only the modelled points ("entries", E of them): their normalised
    positions ``z`` come from the rows of the components for those points, and the limb vectors
    and the smoothness residuals are affine in them (sparse matrices over the entries plus the
    observed values' constant part).
    """

    def __init__(self, frames, obs_norm, model_missing, mean, comps, lam, noise, root, angle,
                 limbs, lengths, fps, settings, world_obs):
        m, n = model_missing.shape
        s = self.s = settings
        # only the components some frame uses (they come first): the products cost less
        r = max(1, int((lam > 0).sum(axis=1).max()))
        comps, lam = np.ascontiguousarray(comps[:, :, :r]), lam[:, :r]
        self.mean, self.comps = mean, comps
        obs = np.nan_to_num(obs_norm)
        self.entries = entries = _Entries(model_missing)
        self.sub_mean = entries.gather(mean)
        self.sub_comps = entries.gather(comps)
        gram, lin, const = _normal_equations(model_missing, obs, mean, comps, self.sub_comps)
        scale = s.w_in / noise
        self.lhs = _lhs(gram * scale[:, None, None], lam, s)
        self.lin = lin * scale[:, None]
        self.const = float((const * scale).sum())
        rows, pts = entries.rows, entries.points
        n_entries = len(rows)
        entry_of = np.full((m, n), n_entries)  # n_entries: an observed point
        entry_of[rows, pts] = np.arange(n_entries)
        # limbs with a modelled end: vector = limb_const + limb_map @ z
        self.limb_map = self.limb_const = self.limb_length = None
        if len(limbs) and s.w_l:
            fr, li = np.nonzero(model_missing[:, limbs[:, 0]] | model_missing[:, limbs[:, 1]])
            ends = entry_of[fr[:, None], limbs[li]]  # (pairs, 2)
            known = ends == n_entries
            self.limb_const = (obs[fr, limbs[li, 0]] * known[:, :1]
                               - obs[fr, limbs[li, 1]] * known[:, 1:])
            self.limb_map = _incidence(ends, np.array([1.0, -1.0]), n_entries)
            self.limb_map_t = self.limb_map.T.tocsr()
            self.limb_length = lengths[li]
        # smoothness: residual of window (t, p) = sum_j c_j X[t + j, p] over the windows that
        # touch a modelled point and no point that is neither observed nor modelled (frames with
        # too little present); world entries = rot z + root
        self.rot = rotation_z(angle[frames])[rows]  # normalised -> world, (E, 3, 3)
        self.root = root[frames][rows]
        kernel = KERNELS[s.smoothness]
        taps = len(kernel)
        self.smooth_map = self.smooth_const = None
        span = len(world_obs) - taps + 1
        if s.w_s and span > 0:
            world_entry = np.full(world_obs.shape[:2], n_entries)
            world_entry[frames] = entry_of
            modelled = world_entry < n_entries
            unknown = np.isnan(world_obs[..., 0]) & ~modelled
            window = np.zeros((span, n), bool)
            blocked = np.zeros((span, n), bool)
            for j in range(taps):
                window |= modelled[j:j + span]
                blocked |= unknown[j:j + span]
            wt, wp = np.nonzero(window & ~blocked)
            ends = np.stack([world_entry[wt + j, wp] for j in range(taps)], axis=1)
            self.smooth_const = sum(c * np.nan_to_num(world_obs[wt + j, wp])
                                    * (ends[:, j:j + 1] == n_entries) for j, c in enumerate(kernel))
            self.smooth_map = _incidence(ends, kernel, n_entries)
            self.smooth_map_t = self.smooth_map.T.tocsr()
            scale = s.accel_scale / fps ** (2 if s.smoothness == "acceleration" else 1)
            self.smooth_weight = s.w_s / scale ** 2

    def poses(self, h):
        return _poses(self.mean, self.comps, h)

    def energy(self, flat):
        s = self.s
        m = len(self.lhs)
        h = flat.reshape(m, -1)
        # retrieval prior + input term
        ah = (self.lhs @ h[..., None])[..., 0]
        e = float((h * (ah + 2 * self.lin)).sum()) + self.const
        grad_h = 2 * (ah + self.lin)
        # the modelled points
        z = self.entries.pick(self.sub_mean + (self.sub_comps @ h[..., None])[..., 0])
        grad_z = np.zeros_like(z)
        if self.limb_map is not None:
            vec = self.limb_const + self.limb_map @ z
            length = np.sqrt((vec * vec).sum(axis=1))
            err = (length - self.limb_length) / s.limb_scale
            e += s.w_l * float((err * err).sum())
            g = (2 * s.w_l / s.limb_scale) * err / np.maximum(length, 1e-9)
            grad_z += self.limb_map_t @ (g[:, None] * vec)
        if self.smooth_map is not None:
            world = np.einsum("eij,ej->ei", self.rot, z) + self.root
            res = self.smooth_const + self.smooth_map @ world
            e += self.smooth_weight * float((res * res).sum())
            grad_world = self.smooth_map_t @ ((2 * self.smooth_weight) * res)
            grad_z += np.einsum("eji,ej->ei", self.rot, grad_world)
        grad_h += (self.entries.spread(grad_z)[:, None, :] @ self.sub_comps)[:, 0]
        return e, grad_h.ravel()

    def closed_form(self):
        """Per-frame minimiser of the prior and input terms alone: (m, r)."""
        return np.linalg.solve(self.lhs, -self.lin[..., None])[..., 0]


class _Entries:
    """The points a model provides ("entries"): (frame row, point) pairs of a (m, n) mask in
    row order, and each row's entries padded to the most any row has (``width``)."""

    def __init__(self, miss):
        self.rows, self.points = np.nonzero(miss)
        m, n = miss.shape
        slot = np.arange(len(self.rows)) - np.searchsorted(self.rows, self.rows)
        self.width = int(slot.max()) + 1 if len(slot) else 1
        self.flat = self.rows * self.width + slot  # places in the padded (m * width) rows
        self.shape = (m, n)

    def gather(self, flat):
        """(m, 3n, ...) per-coordinate values -> (m, 3 width, ...), zero padded."""
        m, n = self.shape
        out = np.zeros((m * self.width, 3) + flat.shape[2:])
        out[self.flat] = flat.reshape((m, n, 3) + flat.shape[2:])[self.rows, self.points]
        return out.reshape((m, 3 * self.width) + flat.shape[2:])

    def pick(self, padded):
        """(m, 3 width) padded values -> (E, 3) of the entries."""
        return padded.reshape(-1, 3)[self.flat]

    def spread(self, values):
        """(E, 3) -> (m, 3 width), the inverse of :meth:`pick` (zeros in the padding)."""
        out = np.zeros((self.shape[0] * self.width, 3))
        out[self.flat] = values
        return out.reshape(self.shape[0], -1)


def _incidence(ends, coefficients, n_entries):
    """Sparse (rows, n_entries) matrix with ``coefficients[j]`` at (i, ends[i, j]) wherever
    ``ends[i, j]`` is an entry (< n_entries)."""
    rows = np.repeat(np.arange(len(ends)), ends.shape[1])
    cols = ends.ravel()
    vals = np.tile(coefficients, len(ends))
    keep = cols < n_entries
    return csr_matrix((vals[keep], (rows[keep], cols[keep])), shape=(len(ends), n_entries))


def _normal_equations(miss, obs, mean, comps, sub_comps=None):
    """Per frame, the input term's ``|P (mean + W h - obs)|^2 = h^T G h + 2 g^T h + c`` over the
    points the model does not provide (P): G (m, r, r), g (m, r), c (m,). ``sub_comps``: the rows
    of ``comps`` for the points it provides (:meth:`_Entries.gather`), when already at hand."""
    if sub_comps is None:
        sub_comps = _Entries(miss).gather(comps)
    # W^T P W = W^T W - (missing rows)^T (missing rows): no masked copy of the components
    gram = comps.transpose(0, 2, 1) @ comps - sub_comps.transpose(0, 2, 1) @ sub_comps
    x = (mean - obs.reshape(len(obs), -1)) * np.repeat(~miss, 3, axis=1)
    return gram, (x[:, None, :] @ comps)[:, 0], (x * x).sum(axis=1)


def _lhs(gram, lam, settings):
    """The scaled input Gram matrices plus the retrieval prior on the diagonal (1 for unused
    components, whose columns are 0: they stay 0)."""
    used = lam > 0
    diag = np.where(used, settings.w_r / np.where(used, lam, 1.0), 1.0)
    out = gram.copy()
    out[:, np.arange(lam.shape[1]), np.arange(lam.shape[1])] += diag
    return out


def _poses(mean, comps, h):
    """Flat poses ``mean + comps @ h`` of each frame's local model."""
    return mean + (comps @ h[..., None])[..., 0]


def _fit_models(index, queries, mask, settings, rng):
    """Search each query's K neighbours over its present points (``~mask``) and fit its local
    model; also its spread: how far the query lies from its neighbours, per coordinate, times
    the missing share. With a noise level far below that, the components chase the difference
    and may extrapolate wildly into the missing points (see docs/METHOD_NOTES.md).

    Returns the :func:`_local_pca` arrays (means, comps, lams, noise) and the spread (q,).
    """
    idx, dist2 = index.search(queries, ~mask, settings.k, ordered=False)
    sample = settings.model_neighbours
    if sample and sample < idx.shape[1]:
        # the same random places of each row, sorted first so every backend samples alike
        idx = np.sort(idx, axis=1)[:, np.sort(rng.choice(idx.shape[1], sample, replace=False))]
    means, comps, lams, noise = _local_pca(index.gather(idx), settings, rng, index.backend)
    n = mask.shape[1]
    present = (~mask).sum(axis=1)
    spread = ((n - present) / n) * np.median(dist2, axis=1) / (3 * np.maximum(present, 1))
    return means, comps, lams, noise, spread


def _closed_form(normal, lam, noise, settings):
    """Coefficients (m, r) minimising the retrieval prior + input terms frame by frame, from
    :func:`_normal_equations`' (G, g, c) and the model noise (m,)."""
    gram, lin, _ = normal
    scale = settings.w_in / noise
    lhs = _lhs(gram * scale[:, None, None], lam, settings)
    return np.linalg.solve(lhs, -(lin * scale[:, None])[..., None])[..., 0]


def _noise_factor(obs_norm, model, frames, index, settings, rng):
    """The query-noise factor (of NOISE_FACTORS) that best recovers known points hidden the way
    the gaps hide points: frames are drawn where the points missing in some modelled frame are
    all present, those points are hidden, the frames are searched and modelled as in a fill,
    and each factor's closed-form prediction of the hidden points is scored."""
    patterns, counts = np.unique(model[frames], axis=0, return_counts=True)
    order = rng.permutation(len(patterns))[:16]
    budget = min(CALIBRATION_FRAMES, len(frames))
    share = counts[order] / counts[order].sum()
    rows, hidden = [], []
    for pattern, part in zip(patterns[order], share):
        ok = ~(model & pattern).any(axis=1) & ((~model).sum(axis=1) - pattern.sum()
                                                 >= settings.min_present)
        candidates = np.flatnonzero(ok)
        take = min(len(candidates), max(1, int(round(budget * part))))
        if take:
            rows.extend(rng.choice(candidates, take, replace=False))
            hidden.extend([pattern] * take)
    if not rows:
        return UNCHECKED_FACTOR
    rows, hidden = np.array(rows), np.array(hidden)
    mask = model[rows] | hidden
    means, comps, lams, noise, spread = _fit_models(index, obs_norm[rows], mask, settings, rng)
    obs = np.nan_to_num(obs_norm[rows])
    normal = _normal_equations(mask, obs, means, comps)
    errors = []
    for factor in NOISE_FACTORS:
        h = _closed_form(normal, lams, np.maximum(noise, factor * spread), settings)
        pose = _poses(means, comps, h).reshape(obs.shape)
        errors.append(float(((pose - obs) ** 2)[hidden].sum()))
    return NOISE_FACTORS[int(np.argmin(errors))]


def pieces(n_frames, size, overlap):
    """The (start, stop) frame ranges a take is filled in: one range when it holds at most
    ``size + overlap`` frames, else ranges of at most that length, each sharing ``overlap``
    frames with the next."""
    if n_frames <= size + overlap:
        return [(0, n_frames)]
    count = -(-(n_frames - overlap) // size)
    step = -(-(n_frames - overlap) // count)
    return [(i * step, min(n_frames, i * step + step + overlap)) for i in range(count)]


def fill_knn(motion, kb, settings=KnnSettings(), progress=None, should_cancel=None, report=None):
    """Fill the gaps of ``motion`` from the knowledge base ``kb``.

    Returns a new :class:`~mocap_gapfill.core.motion.Motion` whose missing samples (of the points
    the knowledge base knows) are filled and marked in ``filled``; observed samples are kept.

    A long take is filled piece by piece (:func:`pieces`): each piece exactly as if it were a
    take of its own, the shared frames of two pieces cross-faded linearly from the one to the
    other, so memory depends on the piece length only.
    """
    progress = progress or (lambda fraction, message: None)
    said = set()

    def once(message):  # the pieces report the same things
        if report and message not in said:
            said.add(message)
            report(message)

    ranges = pieces(motion.n_frames, settings.segment_frames, settings.segment_overlap)
    if len(ranges) == 1:
        return _fill_piece(motion, kb, settings, progress, should_cancel, once)
    out = np.array(motion.positions)
    known = [motion.names.index(n) for n in match_names(kb, motion.names)[0]]
    for i, (a, b) in enumerate(ranges):
        def step(fraction, message, i=i):
            progress((i + fraction) / len(ranges), f"part {i + 1} of {len(ranges)}: {message}")

        piece = motion.frame_range(a, b)
        if piece.missing[:, known].all():
            once(f"frames {a}-{b - 1}: every sample is missing, left unfilled")
            continue
        done = _fill_piece(piece, kb, settings, step, should_cancel, once).positions
        shared = ranges[i - 1][1] - a if i else 0  # frames also filled by the previous piece
        w = (np.arange(shared) + 1.0) / (shared + 1.0)
        prev = out[a:a + shared]
        blend = np.where(np.isnan(prev), done[:shared],
                         np.where(np.isnan(done[:shared]), prev,
                                  prev * (1 - w[:, None, None]) + done[:shared] * w[:, None, None]))
        out[a:a + shared] = blend
        out[a + shared:b] = done[shared:]
    observed = ~motion.missing
    out[observed] = motion.positions[observed]  # exactly, not through the cross-fade
    filled = motion.missing & ~np.isnan(out[..., 0])
    if motion.filled is not None:
        filled |= motion.filled
    progress(1.0, "done")
    return motion.replace(positions=out, filled=filled)


def _kb_index(kb, common, settings):
    """The search index over the knowledge base's ``common`` points (no copy when they are all
    of its points, in order) and the settings with K resolved (None: DEFAULT_K or the KB size)."""
    if settings.k is None:
        settings = replace(settings, k=min(DEFAULT_K, kb.size))
    elif settings.k > kb.size:
        raise GapFillError(f"K = {settings.k} is larger than the knowledge base ({kb.size} poses)")
    cols = [kb.names.index(n) for n in common]
    poses = kb.poses if cols == list(range(len(kb.names))) else kb.poses[:, cols]
    return KBIndex(poses, settings.device), settings


def _fill_piece(motion, kb, settings, progress, should_cancel, report):
    """:func:`fill_knn` of one piece."""
    common, lacking = match_names(kb, motion.names)
    if lacking:
        report(f"not in the knowledge base, left unfilled: {', '.join(lacking)}")
    reference = kb.reference_for(common)
    q_index = [motion.names.index(n) for n in common]
    pos = motion.positions[:, q_index]
    missing = np.isnan(pos[..., 0])
    if not missing.any():
        return motion
    if not (~missing).any():
        raise GapFillError("every sample is missing: nothing to fill from")
    index, settings = _kb_index(kb, common, settings)
    name_to = {nm: i for i, nm in enumerate(common)}
    limbs = np.asarray([(name_to[kb.names[a]], name_to[kb.names[b]]) for a, b in kb.limbs
                        if kb.names[a] in name_to and kb.names[b] in name_to], dtype=np.int64)
    limbs = limbs.reshape(-1, 2)
    lengths = _clip_lengths(pos, limbs, index.poses)
    # the model's mask: the gaps, widened by one frame each side (boundary predictions)
    model = missing.copy()
    model[1:] |= missing[:-1]
    model[:-1] |= missing[1:]
    thin = (~model).sum(axis=1) < settings.min_present
    model[thin] = missing[thin]  # too little left: do not widen there
    empty = (~missing).sum(axis=1) < settings.min_present
    if empty.any():
        report(f"{int(empty.sum())} frames have fewer than {settings.min_present} points present: "
               "filled from the frames around them")
    masks = (missing, model, empty)
    template = reference_template(index.poses, reference)
    root, angle = frames_of(pos, reference, template)
    cache = {}
    filled_pos = _fill_pass(pos, masks, root, angle, index, limbs, lengths, motion.fps,
                            settings, progress, should_cancel, cache, 0.0, 0.6)
    if missing[:, reference_points(reference)].any():
        # the root or hips were in a gap: normalise again with their filled positions, and
        # model again the frames whose normalisation changed
        root2, angle2 = frames_of(filled_pos, reference, template)
        cache["changed"] = ((np.linalg.norm(root2 - root, axis=1) > CHANGE_ROOT)
                            | (np.abs(angle2 - angle) > CHANGE_ANGLE))
        filled_pos = _fill_pass(pos, masks, root2, angle2, index, limbs, lengths, motion.fps,
                                settings, progress, should_cancel, cache, 0.6, 1.0)
    out = motion.positions.copy()
    out[:, q_index] = filled_pos
    filled = np.zeros_like(motion.missing)
    filled[:, q_index] = missing & ~np.isnan(filled_pos[..., 0])
    if motion.filled is not None:
        filled |= motion.filled
    progress(1.0, "done")
    return motion.replace(positions=out, filled=filled)


def _fill_pass(pos, masks, root, angle, index, limbs, lengths, fps, settings, progress,
               should_cancel, cache, p0, p1):
    """One normalise - search - model - optimise - blend pass; the filled positions.

    ``masks`` are (missing, model, empty): the gaps, the points the model provides (the gaps
    widened by a frame), and the frames with too little present to model. ``cache`` keeps the
    local models of the first pass; a second pass models again only the frames flagged in
    ``cache["changed"]``.
    """
    missing, model, empty = masks
    n = missing.shape[1]
    obs_norm = normalize(pos, root, angle)
    frames = np.flatnonzero(model.any(axis=1) & ~empty)

    rng = np.random.default_rng(settings.random_state)
    m = len(frames)
    d = 3 * n
    source = _model_sources(frames, model, fps, settings.model_fps)
    if "models" in cache:
        means, comps, lams, noise, spread = cache["models"]
        todo = np.unique(source[cache["changed"][frames]])
    else:
        means = np.empty((m, d))
        comps = np.empty((m, d, min(settings.max_components, d, settings.k - 1)))
        lams = np.empty((m, comps.shape[2]))
        noise = np.empty(m)
        spread = np.zeros(m)
        cache["models"] = (means, comps, lams, noise, spread)
        todo = np.unique(source)
    for start in range(0, len(todo), settings.batch_frames):
        if should_cancel and should_cancel():
            raise KeyboardInterrupt
        rows = todo[start:start + settings.batch_frames]
        sel = frames[rows]
        means[rows], comps[rows], lams[rows], noise[rows], spread[rows] = _fit_models(
            index, obs_norm[sel], model[sel], settings, rng)
        progress(p0 + (p1 - p0) * 0.7 * (start + len(sel)) / max(1, len(todo)),
                 "searching and fitting local models")
    shared = np.flatnonzero(source != np.arange(m))
    for array in (means, comps, lams, noise, spread):
        array[shared] = array[source[shared]]
    if "factor" not in cache:
        cache["factor"] = (_noise_factor(obs_norm, model, frames, index, settings,
                                         np.random.default_rng([settings.random_state, 1]))
                           if settings.query_noise == "auto" else float(settings.query_noise))
    level = np.maximum(noise, cache["factor"] * spread)
    problem = _Problem(frames, obs_norm[frames], model[frames], means, comps, lams, level, root,
                       angle, limbs, lengths, fps, settings, pos)
    h0 = problem.closed_form()
    if settings.max_iterations > 0 and (settings.w_s or settings.w_l):
        def fun(x):
            if should_cancel and should_cancel():
                raise KeyboardInterrupt
            return problem.energy(x)

        result = minimize(fun, h0.ravel(), jac=True, method="L-BFGS-B",
                          options={"maxiter": settings.max_iterations, "gtol": 1e-6})
        h = result.x.reshape(h0.shape)
    else:
        h = h0
    progress(p0 + (p1 - p0) * 0.95, "writing the fill")
    pred_norm = problem.poses(h).reshape(m, n, 3)
    pred = np.full_like(pos, np.nan)
    pred[frames] = denormalize(pred_norm, root[frames], angle[frames])
    if empty.any():
        # too little present to model: predict from the model trajectory around those frames
        trajectory = np.where(model[..., None], pred, pos)
        trajectory[empty] = np.nan
        pred[empty] = fill_linear(trajectory)[empty]
    return blend_into_gaps(pos, pred, missing, model)


def _model_sources(frames, model, fps, model_fps):
    """For each modelled frame (row of ``frames``), the row whose local model it uses: itself,
    or, above ``model_fps``, the frame that starts its stretch of ``round(fps / model_fps)``
    consecutive frames with the same missing points (poses a few ms apart have the same
    neighbours; each frame still gets its own coefficients)."""
    rows = np.arange(len(frames))
    step = 1 if not model_fps else max(1, int(round(fps / model_fps)))
    if step == 1 or not len(frames):
        return rows
    same = np.zeros(len(frames), bool)
    same[1:] = (np.diff(frames) == 1) & (model[frames[1:]] == model[frames[:-1]]).all(axis=1)
    start = np.maximum.accumulate(np.where(same, 0, rows))
    return start + (rows - start) // step * step


def _clip_lengths(pos, limbs, kb_poses):
    """Median length of each limb over the frames where both ends are present; the knowledge
    base's median where the clip never shows both ends."""
    a, b = limbs[:, 0], limbs[:, 1]
    seen = np.linalg.norm(pos[:, a] - pos[:, b], axis=2)
    lengths = np.array([np.median(c[np.isfinite(c)]) if np.isfinite(c).any() else np.nan
                        for c in seen.T]).reshape(-1)
    unseen = np.flatnonzero(np.isnan(lengths))
    if len(unseen):
        lengths[unseen] = np.median(np.linalg.norm(kb_poses[:, a[unseen]] - kb_poses[:, b[unseen]],
                                                   axis=2), axis=0)
    return lengths


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


def soft_poses(positions, names, uncertainty, kb, fps, settings=KnnSettings(), frames=None,
               should_cancel=None):
    """The local models' most likely poses near a complete first guess.

    ``positions`` (frames, points, 3) world metres hold a value for every point; each value is
    trusted to within ``uncertainty`` (frames, points) metres (0: known, larger: a guess, e.g.
    interpolation deep inside a gap). For each of ``frames`` (default: those with some guessed
    point) the K nearest knowledge-base poses over every point are searched, their local PCA
    fitted (at most ``settings.model_fps`` models a second, shared like :func:`fill_knn`'s),
    and the pose minimising ``w_r sum h^2/lambda + w_in sum_j |pose_j - x_j|^2 /
    (noise + uncertainty_j^2)`` returned (the other frames unchanged); points the knowledge base
    lacks stay as given.
    """
    pos = np.asarray(positions, dtype=float)
    out = pos.copy()
    common, _ = match_names(kb, names)
    cols = [names.index(n) for n in common]
    doubt = np.asarray(uncertainty, dtype=float)[:, cols]
    rows = np.flatnonzero((doubt > 0).any(axis=1)) if frames is None else np.asarray(frames)
    if not len(rows):
        return out
    reference = kb.reference_for(common)
    index, settings = _kb_index(kb, common, settings)
    sub = pos[:, cols]
    root, angle = frames_of(sub, reference, reference_template(index.poses, reference))
    norm = normalize(sub[rows], root[rows], angle[rows])
    var = np.repeat(doubt[rows] ** 2, 3, axis=1)
    source = _model_sources(rows, doubt > 0, fps, settings.model_fps)
    todo = np.unique(source)
    rng = np.random.default_rng(settings.random_state)
    poses = np.empty((len(rows), 3 * len(cols)))
    for start in range(0, len(todo), settings.batch_frames):
        if should_cancel and should_cancel():
            raise KeyboardInterrupt
        fit = todo[start:start + settings.batch_frames]
        means, comps, lams, noise, _ = _fit_models(index, norm[fit],
                                                   np.zeros(norm[fit].shape[:2], bool),
                                                   settings, rng)
        served = np.flatnonzero(np.isin(source, fit))
        model = np.searchsorted(fit, source[served])
        means, comps, lams, noise = means[model], comps[model], lams[model], noise[model]
        weight = settings.w_in / (noise[:, None] + var[served])  # (q, 3n)
        gram = comps.transpose(0, 2, 1) @ (comps * weight[..., None])
        lin = ((means - norm[served].reshape(len(served), -1)) * weight)[:, None, :] @ comps
        h = np.linalg.solve(_lhs(gram, lams, settings), -lin.transpose(0, 2, 1))[..., 0]
        poses[served] = _poses(means, comps, h)
    out[np.ix_(rows, cols)] = denormalize(poses.reshape(len(rows), len(cols), 3), root[rows],
                                          angle[rows])
    return out
