"""The display layer in its own process: rendering never takes the FEM thread's interpreter lock.

:func:`start_display_process` forks it at the column worker's niceness, off the haptic core; the
run waits for its view to open (:func:`wait_for_display`) so the first frames are on time."""

from __future__ import annotations

import gc
import os
import time as clock
from typing import TYPE_CHECKING

from sim.runtime.osrt import leave_interrupts_to_parent, report_failure, stop_with_parent
from sim.runtime.prefetch import WORKER_NICENESS
from sim.runtime.shared import ControlBlock
from sim.runtime.telemetry import SharedTelemetry

if TYPE_CHECKING:
    from sim.runtime.simulation import Simulation

DISPLAY_PHASE = 0.004
"""s after each graphics deadline at which a display that draws the newest graphics frame steps
(the graphics step, global collision detection, takes 1-2 ms)."""


def wait_for_display(pid: int | None, control: ControlBlock, timeout: float = 30.0) -> None:
    """Block until the display process has opened its view (a window takes a second or so), so the
    first frames are on time; a display that died setting up is left (its error is read after the
    run, and the session goes on without a view)."""
    if pid is None:
        return
    deadline = clock.monotonic() + timeout
    while not control.display_ready and clock.monotonic() < deadline and not control.stop_requested:
        finished, _ = os.waitpid(pid, os.WNOHANG)
        if finished:
            return
        clock.sleep(0.005)


def start_display_process(
    simulation: Simulation, duration: float, control: ControlBlock, telemetry: SharedTelemetry
) -> tuple[int | None, int]:
    """The display layer in its own process, so rendering never takes the FEM thread's GIL; at the
    column worker's niceness (:data:`sim.runtime.prefetch.WORKER_NICENESS`), below the real-time
    FEM and graphics threads."""
    errors_read, errors_write = os.pipe()
    if simulation.renderer is None:
        os.close(errors_write)
        return None, errors_read
    parent = os.getpid()
    pid = os.fork()
    if pid != 0:
        os.close(errors_write)
        return pid, errors_read
    os.close(errors_read)
    status = 0
    try:
        leave_interrupts_to_parent()
        stop_with_parent(parent, control)
        from threadpoolctl import threadpool_limits

        renderer = simulation.renderer
        prepare = getattr(renderer, "prepare", None)
        if prepare is not None:  # a window opens here, in the process that draws into it
            prepare(
                lambda reason="stopped_by_trainee": control.request_stop(reason),
                lambda: clock.perf_counter() - control.start if control.start else 0.0,
            )
        control.mark_display_ready()
        os.nice(WORKER_NICENESS)
        threadpool_limits(1)
        spare = not simulation.settings.display_on_haptic_core
        if spare and hasattr(os, "sched_setaffinity") and len(os.sched_getaffinity(0)) > 1:
            os.sched_setaffinity(0, set(sorted(os.sched_getaffinity(0))[:-1]))  # off the haptic core
        gc.freeze()
        period = simulation.settings.period("display")
        start, k = control.wait_for_start(), 0
        # drawing the newest graphics frame: just after the graphics layer posts it
        phase = DISPLAY_PHASE if simulation.settings.display_delay_frames == 0 else 0.0
        while not control.stop_requested and control.haptic_state == ControlBlock.RUNNING:
            deadline = start + k * period + phase
            wait = deadline - clock.perf_counter()
            if wait > 0:
                clock.sleep(min(wait, period))
            now = clock.perf_counter() - start
            if now > duration:
                break
            began = clock.perf_counter()
            simulation.display_step(now)
            telemetry.record(now, clock.perf_counter() - began)
            k = max(k + 1, int((clock.perf_counter() - start) / period))
        finish = getattr(renderer, "finish", None)
        if finish is not None:  # a window closes, and writes what it measured
            finish()
    except BaseException as error:
        status = 1
        control.mark_display_failed(clock.perf_counter())
        report_failure(errors_write, "display", error)
    finally:
        os._exit(status)
