"""Where the heavy arithmetic runs: numpy, or torch on the CPU or a CUDA GPU.

The method is written once (``search.py``, ``models.py``, ``energy.py``); a backend only does
the two operations that dominate its time, on plain numpy arrays in and out:

- ``smallest(lhs, k)``: the product ``lhs @ rhs`` with the knowledge-base matrix ``rhs`` it was
  prepared with, and the ``k`` smallest entries of each row (any order);
- ``gram(a)``: the batched ``a^T a`` of the local PCA's neighbour sets (float32 in and out).

torch is optional: "auto" takes torch on a CUDA GPU when there is one, else torch on the CPU
when torch is installed (its GEMM and top-K searched 2.2-2.4x faster than numpy's on our 2-core
machine, docs/BENCHMARKS.md), else numpy. "numpy", "cpu" and "cuda" force a backend.
"""

import numpy as np

from .errors import GapFillError

DEVICES = ("auto", "numpy", "cpu", "cuda")


def _torch():
    try:
        import torch
    except ImportError:
        return None
    return torch


def resolve(device="auto"):
    """The backend for a device name (one of :data:`DEVICES`)."""
    if device not in DEVICES:
        raise GapFillError(f"unknown device {device!r}; choose from {', '.join(DEVICES)}")
    if device == "numpy":
        return NumpyBackend()
    torch = _torch()
    if device == "auto":
        if torch is None:
            return NumpyBackend()
        return TorchBackend("cuda" if torch.cuda.is_available() else "cpu")
    if torch is None:
        raise GapFillError(f"device {device!r} needs PyTorch, which is not installed "
                           "(pip install torch, or use --device numpy)")
    if device == "cuda" and not torch.cuda.is_available():
        raise GapFillError("device 'cuda': PyTorch sees no CUDA GPU on this machine")
    return TorchBackend(device)


class NumpyBackend:
    name = "numpy"
    #: memory for one block of the distance matrix
    block_bytes = 32 << 20

    def prepare(self, rhs):
        self.rhs = np.ascontiguousarray(rhs, dtype=np.float32)
        return self

    def smallest(self, lhs, k):
        from .search import smallest_columns

        d = lhs @ self.rhs
        idx = smallest_columns(d, k)
        return idx, np.take_along_axis(d, idx, axis=1)

    def gram(self, a):
        return a.transpose(0, 2, 1) @ a


class TorchBackend:
    block_bytes = 256 << 20

    def __init__(self, device):
        self.torch = _torch()
        self.device = self.torch.device(device)
        self.name = f"torch-{self.device.type}"
        if self.device.type == "cuda":
            self.block_bytes = 1 << 30

    def prepare(self, rhs):
        self.rhs = self.torch.as_tensor(np.ascontiguousarray(rhs, dtype=np.float32),
                                        device=self.device)
        return self

    def smallest(self, lhs, k):
        torch = self.torch
        d = torch.as_tensor(lhs, device=self.device) @ self.rhs
        vals, idx = torch.topk(d, k, dim=1, largest=False, sorted=False)
        return idx.cpu().numpy().astype(np.int64), vals.cpu().numpy()

    def gram(self, a):
        t = self.torch.as_tensor(a, device=self.device)
        return (t.transpose(1, 2) @ t).cpu().numpy()
