"""Baseline gap-filling methods, behind the same interface as the knowledge-base method.

- ``linear``: linear interpolation in time per coordinate (values held at clip ends);
- ``spline``: cubic spline through the observed samples (natural ends; held outside them);
- ``svt``: low-rank matrix completion of the (frames, 3 x points) matrix by singular value
  soft-thresholding (SoftImpute, Mazumder et al. 2010), a form of the SVT family;
- ``pca``: a global PCA of the knowledge base (18 components, as the baseline of Kucherenko et
  al. 2018), its coefficients fitted to the present points of each normalised frame;
- ``intercorrelation``: PCA of the take itself (Gloersen & Federolf 2016): marker trajectories
  are centred and scaled, the principal components of the frames where all points are present
  are fitted to the present coordinates of each incomplete frame (no training data needed).

Every function takes positions (frames, points, 3) with NaN gaps and returns them filled; points
missing in every frame stay NaN where a method has nothing to go on.
"""

import numpy as np

from .errors import GapFillError
from .motion import interpolate_rows


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
