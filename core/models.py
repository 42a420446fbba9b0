"""Neighbours and local models of the ``knn`` method (METHOD.md, steps 3-4): the K nearest
knowledge-base poses over the points present, a local PCA of them per frame (shared by frames
a few ms apart), the query-noise factor, and the models' most likely poses near a complete
guess (:func:`soft_poses`, the armature fill's pull towards the knowledge base).
"""

from dataclasses import dataclass, replace

import numpy as np

from .energy import closed_form, model_poses, normal_equations, system_matrix
from .errors import GapFillError
from .kb import match_names
from .normalize import denormalize, frames_of, normalize, reference_template
from .search import KBIndex

@dataclass(frozen=True)
class KnnSettings:
    """Settings of the ``knn`` method (the paper's weights; see docs/DESIGN.md).

    ``k`` None means 4096 neighbours, or the whole knowledge base when it is smaller: on our
    knowledge bases (7k-100k poses) accuracy kept improving up to K = 2048-4096, unlike the
    paper's K = 256 on the whole CMU database. What matters is how far the neighbourhood
    reaches, not how many poses the model sees: each local model is fitted to a random
    ``model_neighbours`` of the K (same accuracy within 2 %, a quarter of the cost at K = 4096;
    docs/DESIGN.md).
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
    #: ``noise_factors`` per fill by hiding present points and predicting them (0: the paper)
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
    #: where the root or hips were in a gap, normalise again with their fill and model again the
    #: frames whose normalisation moved (``auto``'s refill of its copies does without)
    renormalise: bool = True
    #: that second pass models again the frames whose root moved more than this (m) or whose
    #: facing turned more than this (degrees) once the hips are filled
    change_root: float = 0.01
    change_degrees: float = 1.0
    #: neighbours per frame when ``k`` is None
    default_k: int = 4096
    #: subspace iteration of the local PCA: extra columns and power iterations
    oversample: int = 8
    power_iterations: int = 1
    #: the query-noise factors "auto" chooses from, how many frames it checks, and the factor
    #: used where no frame shows the points some gap hides (then nothing can be checked)
    noise_factors: tuple = (0.0, 0.125, 0.25, 0.5, 1.0)
    calibration_frames: int = 192
    unchecked_factor: float = 0.25
    #: where the search and the local models' products run: "auto" (torch on a CUDA GPU, else
    #: torch on the CPU, else numpy when torch is absent), "numpy", "cpu" or "cuda" (torch)
    device: str = "auto"
    random_state: int = 0


def local_pca(neighbours, settings, rng, backend):
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
    start = rng.standard_normal((d, min(d, r + settings.oversample))).astype(cov.dtype)
    y = (cov.reshape(-1, d) @ start).reshape(t, d, -1)  # one product: the start is shared
    for _ in range(settings.power_iterations):
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


def fit_models(index, queries, mask, settings, rng):
    """Search each query's K neighbours over its present points (``~mask``) and fit its local
    model; also its spread: how far the query lies from its neighbours, per coordinate, times
    the missing share. With a noise level far below that, the components chase the difference
    and may extrapolate wildly into the missing points (see docs/DESIGN.md).

    Returns the :func:`local_pca` arrays (means, comps, lams, noise) and the spread (q,).
    """
    idx, dist2 = index.search(queries, ~mask, settings.k, ordered=False)
    sample = settings.model_neighbours
    if sample and sample < idx.shape[1]:
        # the same random places of each row, sorted first so every backend samples alike
        idx = np.sort(idx, axis=1)[:, np.sort(rng.choice(idx.shape[1], sample, replace=False))]
    means, comps, lams, noise = local_pca(index.gather(idx), settings, rng, index.backend)
    n = mask.shape[1]
    present = (~mask).sum(axis=1)
    spread = ((n - present) / n) * np.median(dist2, axis=1) / (3 * np.maximum(present, 1))
    return means, comps, lams, noise, spread


def kb_index(kb, common, settings):
    """The search index over the knowledge base's ``common`` points (no copy when they are all
    of its points, in order) and the settings with K resolved (None: ``default_k`` or the KB
    size)."""
    if settings.k is None:
        settings = replace(settings, k=min(settings.default_k, kb.size))
    elif settings.k > kb.size:
        raise GapFillError(f"K = {settings.k} is larger than the knowledge base ({kb.size} poses)")
    cols = [kb.names.index(n) for n in common]
    poses = kb.poses if cols == list(range(len(kb.names))) else kb.poses[:, cols]
    return KBIndex(poses, settings.device), settings


def model_sources(frames, model, fps, model_fps):
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


def noise_factor(obs_norm, model, frames, index, settings, rng):
    """The query-noise factor (of ``settings.noise_factors``) that best recovers known points
    hidden the way the gaps hide points: frames are drawn where the points missing in some
    modelled frame are all present, those points are hidden, the frames are searched and
    modelled as in a fill, and each factor's closed-form prediction of the hidden points is
    scored."""
    patterns, counts = np.unique(model[frames], axis=0, return_counts=True)
    order = rng.permutation(len(patterns))[:16]
    budget = min(settings.calibration_frames, len(frames))
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
        return settings.unchecked_factor
    rows, hidden = np.array(rows), np.array(hidden)
    mask = model[rows] | hidden
    means, comps, lams, noise, spread = fit_models(index, obs_norm[rows], mask, settings, rng)
    obs = np.nan_to_num(obs_norm[rows])
    normal = normal_equations(mask, obs, means, comps)
    errors = []
    for factor in settings.noise_factors:
        h = closed_form(normal, lams, np.maximum(noise, factor * spread), settings)
        pose = model_poses(means, comps, h).reshape(obs.shape)
        errors.append(float(((pose - obs) ** 2)[hidden].sum()))
    return settings.noise_factors[int(np.argmin(errors))]


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
    index, settings = kb_index(kb, common, settings)
    sub = pos[:, cols]
    root, angle = frames_of(sub, reference, reference_template(index.poses, reference))
    norm = normalize(sub[rows], root[rows], angle[rows])
    var = np.repeat(doubt[rows] ** 2, 3, axis=1)
    source = model_sources(rows, doubt > 0, fps, settings.model_fps)
    todo = np.unique(source)
    rng = np.random.default_rng(settings.random_state)
    poses = np.empty((len(rows), 3 * len(cols)))
    for start in range(0, len(todo), settings.batch_frames):
        if should_cancel and should_cancel():
            raise KeyboardInterrupt
        fit = todo[start:start + settings.batch_frames]
        means, comps, lams, noise, _ = fit_models(index, norm[fit],
                                                   np.zeros(norm[fit].shape[:2], bool),
                                                   settings, rng)
        served = np.flatnonzero(np.isin(source, fit))
        model = np.searchsorted(fit, source[served])
        means, comps, lams, noise = means[model], comps[model], lams[model], noise[model]
        weight = settings.w_in / (noise[:, None] + var[served])  # (q, 3n)
        gram = comps.transpose(0, 2, 1) @ (comps * weight[..., None])
        lin = ((means - norm[served].reshape(len(served), -1)) * weight)[:, None, :] @ comps
        h = np.linalg.solve(system_matrix(gram, lams, settings), -lin.transpose(0, 2, 1))[..., 0]
        poses[served] = model_poses(means, comps, h)
    out[np.ix_(rows, cols)] = denormalize(poses.reshape(len(rows), len(cols), 3), root[rows],
                                          angle[rows])
    return out
