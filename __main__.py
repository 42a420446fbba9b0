"""``python -m mocap_gapfill`` and the ``mocap-gapfill`` command: the core's command line plus
the Blender commands of the add-on (which import bpy only when run)."""

import os
import sys

from . import THREAD_VARIABLES, blas_threads

#: OpenBLAS kernels by the x86 features they need, best first
BLAS_KERNELS = (("SkylakeX", {"avx512f", "avx512cd", "avx512bw", "avx512dq", "avx512vl"}),
                ("Haswell", {"avx2", "fma"}))


def choose_blas_kernel(environ=os.environ, cpuinfo="/proc/cpuinfo"):
    """Name OpenBLAS's kernel after the CPU's features (``OPENBLAS_CORETYPE``), before numpy
    loads it; returns the kernel set, or None where nothing was changed.

    numpy 1.26 bundles OpenBLAS 0.3.23, which picks its kernel by CPU model and falls back to
    an old, slow one on models it does not know: on our Xeon VM (family 6, model 207) float32
    GEMM ran at 34 GFLOP/s instead of 142-160 (docs/BENCHMARKS.md). The kernels named here are
    the ones OpenBLAS gives the CPUs it knows with those features. Nothing is changed when the
    variable is set, numpy is already loaded (inside Blender), or the features are unknown
    (no /proc/cpuinfo, not x86).
    """
    if "OPENBLAS_CORETYPE" in environ or "numpy" in sys.modules:
        return None
    try:
        with open(cpuinfo, encoding="ascii", errors="replace") as f:
            flags = next((set(line.split(":", 1)[1].split()) for line in f
                          if line.startswith("flags")), set())
    except OSError:
        return None
    for kernel, needs in BLAS_KERNELS:
        if needs <= flags:
            environ["OPENBLAS_CORETYPE"] = kernel
            return kernel
    return None


#: commands that set their threads themselves: ``batch`` gives each worker its share of the
#: cores, ``bench`` measures the backends as they come
THREADS_OF_THEIR_OWN = ("batch", "bench")


def cap_blas_threads(argv, environ=os.environ, cores=None):
    """The package's :func:`~mocap_gapfill.blas_threads` set in the environment
    (:data:`~mocap_gapfill.THREAD_VARIABLES`) before numpy loads; returns the number set, or None
    where nothing was changed: one of the variables is set, numpy is already loaded (Blender's
    add-on limits its jobs at run time instead), or the command divides or measures the cores
    itself (:data:`THREADS_OF_THEIR_OWN`).
    """
    if "numpy" in sys.modules or (argv and argv[0] in THREADS_OF_THEIR_OWN):
        return None
    threads = blas_threads(environ, cores)
    if threads is not None:
        environ.update({name: str(threads) for name in THREAD_VARIABLES})
    return threads


def main(argv=None):
    choose_blas_kernel()
    cap_blas_threads(sys.argv[1:] if argv is None else list(argv))
    from .addon.commands import add_commands
    from .addon.bpy_exit import leave_if_bpy_would_crash
    from .core.cli import main as core_main

    code = core_main(argv, extra=add_commands)
    leave_if_bpy_would_crash(code)
    return code


if __name__ == "__main__":
    sys.exit(main())
