"""Mocap Gap Fill: a Blender extension (this folder) and the numeric core behind it.

Importing the package never imports ``bpy``: Blender calls :func:`register`, which loads the
add-on layer. The command line and the tests use :mod:`.core` alone.
"""

import os

#: BLAS / OpenMP threads of a fill where nothing says otherwise. A fill runs BLAS on two threads
#: at once (the knowledge base's models beside the copies' other estimates), each with a BLAS
#: thread per core by default: on a 16-core machine the point ``auto`` of 2,048 frames took
#: 5.6-6.6 s so, 3.8-4.3 s with 4 (docs/BENCHMARKS.md, sessions 33-34)
BLAS_THREADS = 4
#: the variables by which a user sets them
THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


def blas_threads(environ=os.environ, cores=None):
    """The BLAS threads a fill should use: :data:`BLAS_THREADS` or the cores if fewer; None where
    the user set one of :data:`THREAD_VARIABLES` (theirs stands)."""
    if any(name in environ for name in THREAD_VARIABLES):
        return None
    return min(cores or os.cpu_count() or 1, BLAS_THREADS)


def register():
    from . import addon

    addon.register()


def unregister():
    from . import addon

    addon.unregister()
