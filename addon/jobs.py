"""Long work without freezing Blender.

An operator prepares plain arrays on the main thread (``prepare``), the numeric work runs on
them (``work(progress, should_cancel)``, never touching bpy), and the result is written back on
the main thread in one step (``finish``), so one Ctrl-Z undoes it and a cancelled job changes
nothing. Invoked from the UI the work runs on a thread while a modal timer shows progress and
ESC cancels; in background mode, or called from a script, it blocks with progress.

The work runs with the package's BLAS threads (:func:`~mocap_gapfill.blas_threads`, at most 4)
where the user set none: Blender has loaded numpy long before, so the command line's way (the
environment) comes too late here, and threadpoolctl (bundled) limits them for the job's time.
"""

import contextlib
import os
import threading
import time

import bpy

from .. import blas_threads
from ..core.errors import GapFillError


def blas_limit(environ=os.environ, cores=None):
    """A context in which BLAS and OpenMP run with :func:`~mocap_gapfill.blas_threads` threads;
    none (nothing limited) where the user set theirs or threadpoolctl is missing."""
    threads = blas_threads(environ, cores)
    if threads is None:
        return contextlib.nullcontext()
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:
        return contextlib.nullcontext()
    import scipy.linalg  # noqa: F401  scipy's own BLAS: threadpoolctl limits only what is loaded

    return threadpool_limits(limits=threads)  # BLAS and OpenMP, as the variables would


class Job:
    def __init__(self, work, on_progress=None):
        self.work = work
        self.on_progress = on_progress
        self.fraction, self.message = 0.0, "starting"
        self.cancelled = False
        self.result = self.error = None
        self.thread = None

    def progress(self, fraction, message):
        self.fraction, self.message = float(fraction), str(message)
        if self.on_progress:
            self.on_progress(self.fraction, self.message)

    def run(self):
        try:
            with blas_limit():
                self.result = self.work(self.progress, lambda: self.cancelled)
        except KeyboardInterrupt:
            self.cancelled = True
        except (GapFillError, ValueError, OSError, MemoryError) as exc:
            self.error = exc

    def start(self):
        self.thread = threading.Thread(target=self.run, name="mocap_gapfill job", daemon=True)
        self.thread.start()

    @property
    def done(self):
        return self.thread is not None and not self.thread.is_alive()


class JobOperator:
    """Mixin for operators with long numeric work: define ``prepare(context)`` returning the
    ``work`` callable (or None after reporting why) and ``finish(context, result)``."""

    _job = None
    _timer = None
    #: set by an invoke that opened the file browser: its execute then runs modal too
    _modal_after_browser = False

    def execute(self, context):
        if self._modal_after_browser and not bpy.app.background and context.window:
            return self._start_modal(context)
        work = self._prepare(context)
        if work is None:
            return {"CANCELLED"}
        wm = context.window_manager
        last = [0.0]

        def show(fraction, message):
            wm.progress_update(int(100 * fraction))
            if bpy.app.background and time.monotonic() - last[0] > 2.0:
                last[0] = time.monotonic()
                print(f"mocap_gapfill: {100 * fraction:3.0f} % {message}", flush=True)

        wm.progress_begin(0, 100)
        try:
            job = Job(work, on_progress=show)
            job.run()
        finally:
            wm.progress_end()
        return self._end(context, job)

    def invoke(self, context, event):
        if bpy.app.background:
            return self.execute(context)
        return self._start_modal(context)

    def _start_modal(self, context):
        work = self._prepare(context)
        if work is None:
            return {"CANCELLED"}
        wm = context.window_manager
        self._job = Job(work)
        self._job.start()
        self._timer = wm.event_timer_add(0.1, window=context.window)
        wm.modal_handler_add(self)
        wm.mocap_gapfill.running = True
        return {"RUNNING_MODAL"}

    def modal(self, context, event):
        job = self._job
        if event.type == "ESC" and event.value == "PRESS":
            job.cancelled = True
            job.message = "cancelling"
        if event.type != "TIMER":
            return {"RUNNING_MODAL"} if event.type == "ESC" else {"PASS_THROUGH"}
        state = context.window_manager.mocap_gapfill
        state.progress, state.message = 100 * job.fraction, job.message
        if context.workspace:
            context.workspace.status_text_set(
                f"Mocap Gap Fill: {100 * job.fraction:.0f} % {job.message} (Esc to cancel)")
        for area in context.screen.areas if context.screen else ():
            if area.type == "VIEW_3D":
                area.tag_redraw()
        if not job.done:
            return {"RUNNING_MODAL"}
        context.window_manager.event_timer_remove(self._timer)
        if context.workspace:
            context.workspace.status_text_set(None)
        state.running = False
        return self._end(context, job)

    def _prepare(self, context):
        try:
            return self.prepare(context)
        except (GapFillError, ValueError, OSError) as exc:
            self.report({"ERROR"}, str(exc))
            return None

    def _end(self, context, job):
        if job.cancelled:
            self.report({"WARNING"}, "Cancelled: nothing was changed")
            return {"CANCELLED"}
        if job.error is not None:
            self.report({"ERROR"}, str(job.error))
            return {"CANCELLED"}
        try:
            return self.finish(context, job.result)
        except (GapFillError, ValueError, OSError) as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
