"""Exact K-nearest-neighbour search over the points present in each query frame.

For a query q with present-point mask m (one flag per point), the distance to a knowledge-base
pose k is ``sum_present ||q_i - k_i||^2 = m.(q^2) - 2 (m*q).k + m.(k^2)`` where ``k^2`` is summed
per point. All three terms come out of one matrix product against ``[k, per-point |k|^2]``, so
every frame may have its own mask and the work is one blocked GEMM (float32), bounded in memory.
The K best are chosen exactly: a threshold from a sample of each row keeps the candidates (a row
whose threshold keeps too few falls back to a full partition), and the final order is decided on
K + ``KBIndex.margin`` candidates by direct differences (float32 differences, float64 sums), so
results equal the brute-force float64 oracle (:func:`knn_oracle`) up to ties and float32 rounding
of the data.
"""

import numpy as np

from .backend import resolve
from .errors import GapFillError

class KBIndex:
    """A knowledge base prepared for masked search.

    Parameters
    ----------
    poses : ndarray, shape (n, points, 3)
        Normalised knowledge-base poses (no NaN).
    device : str
        Where the distance products run (:data:`~mocap_gapfill.core.backend.DEVICES`).
    """

    #: extra candidates re-ranked in float64 beyond K, absorbing float32 rounding
    margin = 16

    def __init__(self, poses, device="auto"):
        poses = np.asarray(poses)
        if poses.ndim != 3 or poses.shape[2] != 3 or not len(poses):
            raise GapFillError(f"knowledge-base poses must be (n, points, 3), got {poses.shape}")
        self.poses = poses
        self.n, self.points = poses.shape[:2]
        flat = poses.reshape(self.n, -1).astype(np.float32, copy=False)
        # the matrix every query block multiplies: [k, |k_i|^2], transposed for a fast GEMM
        rhs = np.empty((flat.shape[1] + self.points, self.n), np.float32)
        rhs[:flat.shape[1]] = flat.T
        rhs[flat.shape[1]:] = np.einsum("npc,npc->pn", poses, poses)
        self.backend = resolve(device).prepare(rhs)
        self._flat = flat
        self._buffer = np.empty(0, np.float32)

    def gather(self, idx):
        """The flat float32 poses of ``idx`` (q, k): shape (q, k, points * 3), written into a
        buffer that the next call reuses (a fresh array of this size costs more in page faults
        than the copy itself)."""
        need = idx.size * self._flat.shape[1]
        if self._buffer.size < need:
            self._buffer = np.empty(need, np.float32)
        out = self._buffer[:need].reshape(*idx.shape, self._flat.shape[1])
        return np.take(self._flat, idx, axis=0, out=out, mode="clip")

    def search(self, queries, present, k, ordered=True, progress=None, should_cancel=None):
        """Exact K nearest poses for each query over its present points.

        Parameters
        ----------
        queries : ndarray, shape (q, points, 3)
            Normalised query poses (values at absent points are ignored, NaN allowed).
        present : ndarray, shape (q, points), bool
        k : int
            Neighbours per query (at most the KB size).
        ordered : bool
            True: neighbours nearest first, distances from direct differences. False: the same
            set of neighbours (up to float32 rounding at the K-th distance) in no order, with
            float32 distances, skipping the re-ranking (what a local model needs).

        Returns
        -------
        index : ndarray, shape (q, k), int64
            KB rows, nearest first when ``ordered``.
        dist2 : ndarray, shape (q, k), float64
            Squared distances over the present points.

        Examples
        --------
        >>> rng = np.random.default_rng(0)
        >>> kb = rng.normal(size=(500, 4, 3))
        >>> q = kb[:3] + 0.01
        >>> idx, d2 = KBIndex(kb).search(q, np.ones((3, 4), bool), k=2)
        >>> idx[:, 0].tolist()
        [0, 1, 2]
        """
        queries = np.asarray(queries, dtype=np.float64)
        present = np.asarray(present, dtype=bool)
        if queries.shape[1:] != (self.points, 3) or present.shape != queries.shape[:2]:
            raise GapFillError("queries and mask do not match the knowledge base's points")
        k = int(k)
        if not 1 <= k <= self.n:
            raise GapFillError(f"K = {k} must be between 1 and the knowledge-base size {self.n}")
        q = np.where(present[..., None], queries, 0.0).astype(np.float32)
        out_idx = np.empty((len(q), k), dtype=np.int64)
        out_d2 = np.empty((len(q), k))
        lhs = np.concatenate([-2.0 * q.reshape(len(q), -1), present.astype(np.float32)], axis=1)
        qsq = (q.astype(np.float64) ** 2).sum(axis=(1, 2))
        rows = max(1, self.backend.block_bytes // (4 * self.n))
        for start in range(0, len(q), rows):
            if should_cancel and should_cancel():
                raise KeyboardInterrupt
            sel = slice(start, start + rows)
            # the smallest of lhs @ [k, |k_i|^2]^T: squared distances minus |q|^2
            if ordered:
                cand, _ = self.backend.smallest(lhs[sel], min(self.n, k + self.margin))
                # direct differences on the candidates (no cancellation), then the K in order
                diff = self._flat[cand] - q[sel].reshape(len(cand), 1, -1)
                diff *= np.repeat(present[sel], 3, axis=1)[:, None, :]
                exact = np.einsum("qkd,qkd->qk", diff, diff, dtype=np.float64)
                order = np.argsort(exact, axis=1, kind="stable")[:, :k]
                out_idx[sel] = np.take_along_axis(cand, order, axis=1)
                out_d2[sel] = np.take_along_axis(exact, order, axis=1)
            else:
                out_idx[sel], d = self.backend.smallest(lhs[sel], k)
                out_d2[sel] = d + qsq[sel, None]
            if progress:
                progress(min(len(q), start + rows) / len(q), "searching")
        return out_idx, out_d2


def smallest_columns(d, k):
    """Column indices of the k smallest entries of each row (any order), exactly."""
    n = d.shape[1]
    if k >= n:
        return np.broadcast_to(np.arange(n), d.shape).copy()
    if n < 8 * k:
        return np.argpartition(d, k - 1, axis=1)[:, :k]
    # threshold from a strided sample: mu sample entries are expected below the k-th smallest;
    # taking rank mu + 4 sqrt(mu) + 2 keeps at least k survivors but in rare rows (those fall
    # back to a full partition), and few more than k when k is large
    step = max(1, n // min(16 * k + 1, 4096))
    sample = d[:, ::step]
    mu = k * sample.shape[1] / n
    rank = min(sample.shape[1] - 1, int(np.ceil(mu + 4 * np.sqrt(mu) + 2)))
    tau = np.partition(sample, rank, axis=1)[:, rank]
    keep = d <= tau[:, None]
    counts = keep.sum(axis=1)
    result = np.empty((len(d), k), dtype=np.int64)
    ok = counts >= k
    if (~ok).any():
        bad = np.flatnonzero(~ok)
        result[bad] = np.argpartition(d[bad], k - 1, axis=1)[:, :k]
    if ok.any():
        good = np.flatnonzero(ok)
        keep[~ok] = False
        flat = np.flatnonzero(keep)
        r_all, c = np.divmod(flat, d.shape[1])
        r = np.searchsorted(good, r_all)  # row within `good`
        width = int(counts[good].max())
        slot = np.arange(len(flat)) - np.repeat(np.cumsum(counts[good]) - counts[good], counts[good])
        cols = np.zeros((len(good), width), dtype=np.int64)
        vals = np.full((len(good), width), np.inf, dtype=d.dtype)
        cols[r, slot] = c
        vals[r, slot] = d.reshape(-1)[flat]
        part = np.argpartition(vals, k - 1, axis=1)[:, :k]
        result[good] = np.take_along_axis(cols, part, axis=1)
    return result


def knn_oracle(kb_poses, queries, present, k):
    """Brute-force float64 reference: the K nearest by present-point distance, nearest first."""
    kb = np.asarray(kb_poses, dtype=np.float64)
    out_idx, out_d2 = [], []
    for q, m in zip(np.asarray(queries, dtype=np.float64), np.asarray(present, dtype=bool)):
        d2 = ((kb[:, m] - q[m]) ** 2).sum(axis=(1, 2))
        order = np.argsort(d2, kind="stable")[:k]
        out_idx.append(order)
        out_d2.append(d2[order])
    return np.array(out_idx), np.array(out_d2)
