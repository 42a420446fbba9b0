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
   points only, see :class:`Problem`).

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

import numpy as np
from scipy.optimize import minimize

from .baselines import fill_linear
from .energy import Problem
from .errors import GapFillError
from .kb import match_names
from .models import KnnSettings, fit_models, kb_index, model_sources, noise_factor
from .motion import blend_into_gaps, widened
from .normalize import denormalize, frames_of, normalize, reference_points, reference_template

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
    the knowledge base knows) are filled and marked in ``filled``; observed samples are kept,
    and the points it does not know are left as they are (the callers say what becomes of them).

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


def _fill_piece(motion, kb, settings, progress, should_cancel, report):
    """:func:`fill_knn` of one piece."""
    common, _ = match_names(kb, motion.names)
    reference = kb.reference_for(common)
    q_index = [motion.names.index(n) for n in common]
    pos = motion.positions[:, q_index]
    missing = np.isnan(pos[..., 0])
    if not missing.any():
        return motion
    if not (~missing).any():
        raise GapFillError("every sample is missing: nothing to fill from")
    index, settings = kb_index(kb, common, settings)
    name_to = {nm: i for i, nm in enumerate(common)}
    limbs = np.asarray([(name_to[kb.names[a]], name_to[kb.names[b]]) for a, b in kb.limbs
                        if kb.names[a] in name_to and kb.names[b] in name_to], dtype=np.int64)
    limbs = limbs.reshape(-1, 2)
    lengths = _clip_lengths(pos, limbs, index.poses)
    # the model's mask: the gaps, widened by one frame each side (boundary predictions)
    model = widened(missing)
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
    if settings.renormalise and missing[:, reference_points(reference)].any():
        # the root or hips were in a gap: normalise again with their filled positions, and
        # model and optimise again the frames whose normalisation changed
        root2, angle2 = frames_of(filled_pos, reference, template)
        turn = np.abs(np.angle(np.exp(1j * (angle2 - angle))))  # unwrapped apart by 2 pi: same
        cache["changed"] = ((np.linalg.norm(root2 - root, axis=1) > settings.change_root)
                            | (turn > np.deg2rad(settings.change_degrees)))
        if cache["changed"].any():
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
    local models and poses of the first pass; a second pass models and optimises again only the
    frames flagged in ``cache["changed"]`` (the others keep the first pass's poses).
    """
    missing, model, empty = masks
    n = missing.shape[1]
    obs_norm = normalize(pos, root, angle)
    frames = np.flatnonzero(model.any(axis=1) & ~empty)

    rng = np.random.default_rng(settings.random_state)
    m = len(frames)
    d = 3 * n
    source = model_sources(frames, model, fps, settings.model_fps)
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
        means[rows], comps[rows], lams[rows], noise[rows], spread[rows] = fit_models(
            index, obs_norm[sel], model[sel], settings, rng)
        progress(p0 + (p1 - p0) * 0.7 * (start + len(sel)) / max(1, len(todo)),
                 "searching and fitting local models")
    shared = np.flatnonzero((source != np.arange(m)) & np.isin(source, todo))
    for array in (means, comps, lams, noise, spread):
        array[shared] = array[source[shared]]
    if "factor" not in cache:
        cache["factor"] = (noise_factor(obs_norm, model, frames, index, settings,
                                         np.random.default_rng([settings.random_state, 1]))
                           if settings.query_noise == "auto" else float(settings.query_noise))
    level = np.maximum(noise, cache["factor"] * spread)
    solve, world = np.arange(m), pos
    if "pred" in cache:
        # a second pass optimises the frames whose normalisation changed; the others keep the
        # first pass's poses, which the smoothness term sees beside them
        solve = np.flatnonzero(cache["changed"][frames])
        world = np.where((model & ~cache["changed"][:, None])[..., None], cache["pred"], pos)
    pred = cache.get("pred", np.full_like(pos, np.nan))
    if len(solve):
        pred[frames[solve]] = _optimised(pos, frames[solve], obs_norm, model, root, angle,
                                         (means[solve], comps[solve], lams[solve], level[solve]),
                                         limbs, lengths, fps, settings, world, should_cancel)
    cache["pred"] = pred.copy()
    progress(p0 + (p1 - p0) * 0.95, "writing the fill")
    if empty.any():
        # too little present to model: predict from the model trajectory around those frames
        trajectory = np.where(model[..., None], pred, pos)
        trajectory[empty] = np.nan
        pred[empty] = fill_linear(trajectory)[empty]
    return blend_into_gaps(pos, pred, missing, model)


def _optimised(pos, frames, obs_norm, model, root, angle, models, limbs, lengths, fps, settings,
               world, should_cancel):
    """The poses (world) of ``frames`` that minimise the energy, given their local ``models``
    (means, components, eigenvalues, noise level); ``world``: the take as the smoothness term
    sees it around them."""
    problem = Problem(frames, obs_norm[frames], model[frames], *models, root, angle, limbs,
                      lengths, fps, settings, world)
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
    pred_norm = problem.poses(h).reshape(len(frames), -1, 3)
    return denormalize(pred_norm, root[frames], angle[frames])


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


