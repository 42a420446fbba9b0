"""The energy of the ``knn`` method (METHOD.md, step 5) over the local models' coefficients.

``w_r sum h^2/lambda`` (retrieval prior) ``+ w_in sum_present (pose - observed)^2 / sigma2_t``
(input) come from each frame's normal equations; ``+ w_l`` limb lengths ``+ w_s`` smoothness
from sparse maps over the modelled points only (:class:`Problem`).
"""

import numpy as np
from scipy.sparse import csr_matrix

from .normalize import rotation_z

#: smoothness kernels: residual_t = sum_j c_j X_{t+j} for j = 0..len-1 (t = first frame)
KERNELS = {
    "acceleration": np.array([1.0, -2.0, 1.0]),
    "paper": np.array([-1.0, -2.0, -3.0, 6.0]) / 6.0,  # X_t - (3X_{t-1} + 2X_{t-2} + X_{t-3})/6
}


class Problem:
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
        gram, lin, const = normal_equations(model_missing, obs, mean, comps, self.sub_comps)
        scale = s.w_in / noise
        self.lhs = system_matrix(gram * scale[:, None, None], lam, s)
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
        return model_poses(self.mean, self.comps, h)

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


def normal_equations(miss, obs, mean, comps, sub_comps=None):
    """Per frame, the input term's ``|P (mean + W h - obs)|^2 = h^T G h + 2 g^T h + c`` over the
    points the model does not provide (P): G (m, r, r), g (m, r), c (m,). ``sub_comps``: the rows
    of ``comps`` for the points it provides (:meth:`_Entries.gather`), when already at hand."""
    if sub_comps is None:
        sub_comps = _Entries(miss).gather(comps)
    # W^T P W = W^T W - (missing rows)^T (missing rows): no masked copy of the components
    gram = comps.transpose(0, 2, 1) @ comps - sub_comps.transpose(0, 2, 1) @ sub_comps
    x = (mean - obs.reshape(len(obs), -1)) * np.repeat(~miss, 3, axis=1)
    return gram, (x[:, None, :] @ comps)[:, 0], (x * x).sum(axis=1)


def system_matrix(gram, lam, settings):
    """The scaled input Gram matrices plus the retrieval prior on the diagonal (1 for unused
    components, whose columns are 0: they stay 0)."""
    used = lam > 0
    diag = np.where(used, settings.w_r / np.where(used, lam, 1.0), 1.0)
    out = gram.copy()
    out[:, np.arange(lam.shape[1]), np.arange(lam.shape[1])] += diag
    return out


def model_poses(mean, comps, h):
    """Flat poses ``mean + comps @ h`` of each frame's local model."""
    return mean + (comps @ h[..., None])[..., 0]


def closed_form(normal, lam, noise, settings):
    """Coefficients (m, r) minimising the retrieval prior + input terms frame by frame, from
    :func:`normal_equations`' (G, g, c) and the model noise (m,)."""
    gram, lin, _ = normal
    scale = settings.w_in / noise
    lhs = system_matrix(gram * scale[:, None, None], lam, settings)
    return np.linalg.solve(lhs, -(lin * scale[:, None])[..., None])[..., 0]
