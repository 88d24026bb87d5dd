"""The real-time clock: the haptic layer in its own process, the others in threads.

Measured on these 2-core machines, a 1 kHz Python thread sharing the interpreter
with a graphics thread falls to ~720 Hz; in its own process, with BLAS limited to
one thread, it holds ~999 Hz. So :func:`run_realtime` forks a haptic process
(pinned to the last core where the OS allows) that runs the same
``Simulation.haptic_step`` against shared-memory channels
(:mod:`sim.runtime.shared`), while the FEM, graphics and display layers run as
threads in this process. Deadlines are absolute (start + k * period): the haptic
process sleeps to just before each one and spins the rest, and a late step never
causes a burst of catch-up steps.

Linux (fork) only. The device must be usable in the forked child: scripted and
replay devices are; a live HID/USB device should be opened in the child (pass a
device whose handle is opened lazily on first read).
"""

from __future__ import annotations

import contextlib
import gc
import math
import os
import signal
import sys
import threading
import time as clock
from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

from sim.runtime.cpu import IdlePolling
from sim.runtime.display_process import start_display_process, wait_for_display
from sim.runtime.force_path import CompiledForcePath
from sim.runtime.logs import HapticLog
from sim.runtime.osrt import (
    leave_interrupts_to_parent,
    leave_last_core_to_haptics,
    lock_memory,
    process_prepared,
    read_all,
    report_failure,
    set_all_threads,
    sleep_until,
    stop_with_parent,
    try_realtime_priority,
    wait_for,
)
from sim.runtime.settings import LayerProcessError
from sim.runtime.shared import (
    Arena,
    ControlBlock,
    SharedEvents,
    SharedFem,
    SharedForceHistory,
    SharedGraphics,
    SharedHapticLog,
    SharedHolder,
)
from sim.runtime.snapshots import RuntimeEvent
from sim.runtime.telemetry import LAYERS, LoopTelemetry, RunResult, SharedTelemetry

if TYPE_CHECKING:  # the simulation it runs; the simulation imports this module
    from sim.runtime.simulation import Simulation

START_DELAY = 0.2  # s between set-up and the first tick, so every layer starts on time
WARM_LEAD = 5e-5
"""s before each haptic deadline at which the tick's reads are run dry to warm the caches (in the spin
that ends the wait, so nothing is slept away between the warming and the tick): the force path and
the latest FEM snapshot, both read-only."""
FORCE_PATH = "haptic force path"
"""The telemetry of each haptic tick's force path (holder publish, force interpolation, safety filter,
log: one compiled call, sim/runtime/force_path.py), within the whole haptic step's; the step also
reads the device, writes its force and records the sample."""
LAYER_PRIORITIES = {"fem": 40, "graphics": 30}
"""SCHED_FIFO priorities of the FEM and graphics threads (the haptic process has 50). They sleep
most of each period; in the normal class a woken FEM thread could wait a scheduler tick (4 ms) behind
the column worker's or the display's CPU time, which showed as contact-change latency."""
GIL_SWITCH_INTERVAL = 2e-4
"""s a thread may keep the interpreter lock while another waits for it (Python's default is 5 ms):
the FEM thread waking for its step must not wait out a graphics frame's collision query."""


def run_realtime(simulation: Simulation, duration: float, pin_cpus: bool = True) -> RunResult:
    """Run ``simulation`` for ``duration`` seconds of wall time (see the module docstring), inside
    :func:`process_prepared`."""
    settings = simulation.settings
    capacity = int(duration * settings.haptic_rate * 1.2) + 2000
    display_capacity = int(duration * settings.display_rate * 1.5) + 100
    arena = Arena(  # each channel states its own size
        SharedHolder.doubles()
        + SharedForceHistory.doubles()
        + SharedHapticLog.doubles(capacity)
        + 2 * SharedTelemetry.doubles(capacity)  # the whole haptic step, and its force path
        + SharedEvents.doubles()
        + ControlBlock.doubles()
        + SharedGraphics.doubles()
        + SharedFem.doubles()
        + SharedTelemetry.doubles(display_capacity)
        + (0 if simulation.subordinate is None else SharedHolder.doubles())
    )
    simulation.holder = SharedHolder(arena)
    if simulation.subordinate is not None:  # the second hand's device is read in the haptic process too
        simulation.subordinate_holder = SharedHolder(arena)
    simulation.forces = SharedForceHistory(arena)
    shared_log = SharedHapticLog(arena, capacity)
    simulation.haptic_log = shared_log
    telemetry = SharedTelemetry(arena, capacity)
    force_path_telemetry = SharedTelemetry(arena, capacity)
    events = SharedEvents(arena)
    control = ControlBlock(arena)
    simulation.graphics = SharedGraphics(arena)
    simulation.fem = SharedFem(arena, for_display=simulation.renderer is not None)
    display_telemetry = SharedTelemetry(arena, display_capacity)
    relay = HapticEventRelay(simulation, events)
    display_pid, display_errors = start_display_process(simulation, duration, control, display_telemetry)
    errors_read, errors_write = os.pipe()
    started = clock.perf_counter()
    parent = os.getpid()
    pid = os.fork()
    if pid == 0:  # the haptic process
        os.close(errors_read)
        status = 0
        try:
            leave_interrupts_to_parent()
            stop_with_parent(parent, control)
            channels = (telemetry, force_path_telemetry)
            _haptic_process(simulation, duration, control, channels, events, errors_write, pin_cpus)
        except BaseException as error:  # outside the loop's own report (set-up): the parent reads it
            status = 1
            report_failure(errors_write, "haptic", error)
        finally:
            os._exit(status)
    os.close(errors_write)
    previous_affinity = leave_last_core_to_haptics(pin_cpus)
    # the haptic core idles by polling, not halting, between ticks (sim.runtime.cpu)
    polling = IdlePolling() if previous_affinity else contextlib.nullcontext()
    try:
        with polling, _interrupts_stop(control):
            _wait_until_ready(pid, control, errors_read)
            wait_for_display(display_pid, control)
            # every layer counts from here: the haptic set-up (memory locking, warm-up) is not in the session
            control.start = clock.perf_counter() + START_DELAY
            _run_other_layers(simulation, duration, control, relay)
    finally:
        control.request_stop()
        wait_for(pid, timeout=5.0)
        if display_pid is not None:
            wait_for(display_pid, timeout=10.0)
        if previous_affinity is not None:
            set_all_threads(previous_affinity)
    child_error = read_all(errors_read)
    failed = read_all(display_errors)
    if failed:  # the session went on without its view; the failure is recorded, with its message and time
        failed_at = control.display_failed_at
        when = failed_at if math.isfinite(failed_at) else 0.0
        simulation._emit(RuntimeEvent("layer_failed", when, "display", failed))
    if display_pid is not None:
        simulation.telemetry["display"] = _as_layer_telemetry("display", simulation, display_telemetry)
    simulation.telemetry[FORCE_PATH] = _as_layer_telemetry(FORCE_PATH, simulation, force_path_telemetry)
    if control.stop_reason not in ("", "stopped"):  # the trainee, Ctrl-C or the task asked for the stop
        simulation.stop(control.stop_reason, 0.0)
    return _collect(
        simulation, shared_log, telemetry, relay, control, child_error, clock.perf_counter() - started
    )


def _wait_until_ready(pid: int, control: ControlBlock, errors: int, timeout: float = 60.0) -> None:
    """Block until the haptic process has finished its set-up; a :class:`LayerProcessError` with the
    child's own message when it died trying."""
    deadline = clock.monotonic() + timeout
    while not control.haptic_ready:
        finished, _ = os.waitpid(pid, os.WNOHANG)
        if finished:
            reason = read_all(errors, close=False) or "no message"
            raise LayerProcessError(f"haptic: the haptic process exited during its set-up ({reason})")
        if clock.monotonic() > deadline:
            raise LayerProcessError(f"haptic: the haptic process was not ready after {timeout:.0f} s")
        clock.sleep(0.001)


@contextlib.contextmanager
def _interrupts_stop(control: ControlBlock):
    """For the length of the run, Ctrl-C (SIGINT) asks every layer to stop, as the trainee's own stop
    does, instead of raising in whatever the main thread was doing: the session ends complete, with
    no traceback. Only the main thread can handle signals; elsewhere nothing changes."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, lambda signum, frame: control.request_stop("interrupted"))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def _as_layer_telemetry(layer: str, simulation: Simulation, shared: SharedTelemetry) -> LoopTelemetry:
    period = simulation.settings.period("haptic" if layer == FORCE_PATH else layer)
    telemetry = LoopTelemetry(layer, period, max(len(shared.starts), 1))
    for start, compute in zip(shared.starts, shared.computes, strict=True):
        telemetry.record(float(start), float(compute))
    return telemetry


def _haptic_process(
    simulation: Simulation,
    duration: float,
    control: ControlBlock,
    telemetries: tuple[SharedTelemetry, SharedTelemetry],
    events: SharedEvents,
    errors: int,
    pin_cpus: bool,
) -> None:
    from threadpoolctl import threadpool_limits

    if pin_cpus and hasattr(os, "sched_setaffinity"):
        cpus = sorted(os.sched_getaffinity(0))
        if len(cpus) > 1:
            os.sched_setaffinity(0, {cpus[-1]})
    threadpool_limits(1)
    try_realtime_priority()
    lock_memory()
    # The child inherits the whole heap: a full garbage collection would walk it for
    # milliseconds. Freeze what exists and collect nothing during the loop (the loop's
    # own garbage is freed by reference counting).
    gc.freeze()
    gc.disable()
    period = 1.0 / simulation.settings.haptic_rate
    if simulation.on_haptic_start is not None:
        simulation.on_haptic_start()
    simulation.device.read(0.0)  # warm caches and lazy imports before the first deadline
    if simulation.subordinate is not None:
        simulation.subordinate.read(0.0)
    simulation.forces.at(0.0)
    telemetry, force_path_telemetry = telemetries
    settings = simulation.settings
    force_path = simulation.force_path = CompiledForcePath(
        simulation.holder,
        simulation.forces,
        simulation.haptic_log,
        simulation.safety,
        settings.force_delay,
        settings.haptic_scale,
    )
    control.mark_haptic_ready()
    start = control.wait_for_start()
    step = 0
    now = 0.0
    reported = tracked = 0
    try:
        while True:
            deadline = start + step * period
            sleep_until(deadline - WARM_LEAD)
            force_path.warm(deadline - start)  # in the wait: the tick finds its code and cells cached
            simulation.fem.get()
            sleep_until(deadline)
            now = clock.perf_counter() - start
            if control.stop_requested or now > duration:
                break
            began = clock.perf_counter()
            simulation.haptic_step(now)
            telemetry.record(now, clock.perf_counter() - began)
            force_path_telemetry.record(now, simulation.force_path_seconds)
            for when, kind, detail in simulation.safety.events[reported:]:
                events.add(when, kind, detail)
            reported = len(simulation.safety.events)
            for when, kind, detail in simulation.tracking_events[tracked:]:
                events.add(when, kind, detail)
            tracked = len(simulation.tracking_events)
            if simulation.stop_reason == "device_lost":
                events.add(now, "device_lost")
                control.haptic_state = ControlBlock.DEVICE_LOST
                return
            if simulation.stop_reason == "stopped_by_trainee":  # the device's stop button
                control.request_stop("stopped_by_trainee")
            step += 1
            late = clock.perf_counter() - (start + step * period)
            if late > period:  # skip deadlines already missed instead of bursting
                step += int(late / period)
    except Exception as error:  # report with its layer, then wind down
        os.write(errors, f"haptic: {type(error).__name__}: {error}".encode())
        events.add(now, "layer_failed")
        control.haptic_state = ControlBlock.FAILED
    force_path.hand_back()  # the paced stop continues from the compiled filter's state
    simulation.force_path = None
    _paced_wind_down(simulation, now, period)
    if control.haptic_state == ControlBlock.RUNNING:
        control.haptic_state = ControlBlock.FINISHED


def _paced_wind_down(simulation: Simulation, now: float, period: float) -> None:
    """Bring the device force to zero within the rate limit, one tick at a time."""
    for when, force in simulation.safety.stop_sequence(now, period):
        sleep_until(clock.perf_counter() + period)
        simulation.device.write_force(force)
        simulation.haptic_log.append(when, np.zeros(3), False, force)


class HapticEventRelay:
    """The haptic process's events (its safety filter's, a camera's tracking changes) passed on to the
    simulation's own, and so to the recording, as they come: by the graphics layer after each of its
    frames (at most a frame late), and whatever is left when the run ends."""

    def __init__(self, simulation: Simulation, events: SharedEvents) -> None:
        self.simulation, self.events = simulation, events
        self.delivered = 0
        self._lock = threading.Lock()

    def deliver(self, failure: str = "") -> None:
        """Emit the events added since the last call (``failure``: the detail of a ``layer_failed``)."""
        with self._lock:
            new = self.events.read(self.delivered)
            self.delivered += len(new)
        for when, kind, detail in new:
            said = failure if kind == "layer_failed" else detail
            self.simulation._emit(RuntimeEvent(kind, when, "haptic", said))

    def graphics_step(self, now: float) -> None:
        self.simulation.graphics_step(now)
        self.deliver()


def _run_other_layers(
    simulation: Simulation, duration: float, control: ControlBlock, relay: HapticEventRelay
) -> None:
    from threadpoolctl import threadpool_limits

    steps: dict[str, Callable[[float], None]] = {
        "fem": simulation.fem_step,
        "graphics": relay.graphics_step,
    }
    if simulation.renderer is None:
        steps["display"] = simulation.display_step  # nothing to render: a cheap thread
    switch_interval = sys.getswitchinterval()
    sys.setswitchinterval(GIL_SWITCH_INTERVAL)
    try:
        with threadpool_limits(1):
            _run_threads(simulation, steps, duration, control)
    finally:
        sys.setswitchinterval(switch_interval)


def _run_threads(
    simulation: Simulation, steps: dict[str, Callable[[float], None]], duration: float, control: ControlBlock
) -> None:
    # the FEM layer also steps as soon as a global-CD frame is posted, so a contact change waits
    # for no FEM period (up to 2 ms at 500 Hz) before its exact forces
    wakes = {"fem": simulation.global_posted}
    threads = [
        threading.Thread(
            target=_layer_loop,
            args=(simulation, layer, steps[layer], duration, control, wakes.get(layer)),
            name=f"vascsim-{layer}",
            daemon=True,
        )
        for layer in steps
    ]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(duration + 10.0)


def _layer_loop(
    simulation: Simulation,
    layer: str,
    step: Callable[[float], None],
    duration: float,
    control: ControlBlock,
    wake: threading.Event | None = None,
) -> None:
    """Steps at start + k * period; with ``wake``, also one step whenever it is set between two."""
    if layer in LAYER_PRIORITIES:
        try_realtime_priority(LAYER_PRIORITIES[layer])
    period = simulation.settings.period(layer)
    start = control.start
    record = simulation.telemetry[layer].record
    k = 0
    while True:
        deadline = start + k * period
        wait = deadline - clock.perf_counter()
        woken = False
        if wait > 0 and wake is not None:
            woken = wake.wait(wait)  # True: something was posted before the deadline
        elif wait > 0:
            clock.sleep(wait)
        if wake is not None:
            wake.clear()  # this step takes whatever was posted until now
        now = clock.perf_counter() - start
        if (
            now > duration
            or control.stop_requested
            or simulation.stop_reason is not None
            or control.haptic_state != ControlBlock.RUNNING
        ):
            return
        began = clock.perf_counter()
        try:
            step(now)
        except Exception as error:  # any layer's failure stops the session cleanly
            simulation.fail(layer, now, error)
            control.request_stop()
            return
        record(now, clock.perf_counter() - began)
        if woken:
            continue  # an extra step: the scheduled one still follows at its deadline
        k += 1
        late = clock.perf_counter() - (start + k * period)
        if late > period:
            k += int(late / period)


def _collect(
    simulation: Simulation,
    shared_log: SharedHapticLog,
    telemetry: SharedTelemetry,
    relay: HapticEventRelay,
    control: ControlBlock,
    child_error: str,
    wall: float,
) -> RunResult:
    log = HapticLog(max(shared_log.count, 1))
    for t, p, g, f in zip(
        shared_log.time, shared_log.position, shared_log.grip, shared_log.force, strict=True
    ):
        log.append(float(t), p, bool(g), f)
    simulation.telemetry["haptic"] = _as_layer_telemetry("haptic", simulation, telemetry)
    relay.deliver(child_error)  # those the graphics layer had not passed on (the run's last frame's)
    simulation.events.sort(key=lambda event: event.time)
    if control.haptic_state == ControlBlock.DEVICE_LOST:
        simulation.stop("device_lost", 0.0)
    elif control.haptic_state == ControlBlock.FAILED:
        simulation.error, simulation.error_layer = child_error, "haptic"
        simulation.stop("haptic_failed", 0.0)
    simulation.haptic_log = log
    end = float(log.time[-1]) if log.count else 0.0
    # recorded too: why the session ended (completed, stopped_by_trainee, interrupted, task_done, ...)
    simulation._emit(RuntimeEvent("stopped", end, "runtime", simulation.stop_reason or "completed"))
    result = simulation.run_result(end, wall)
    result.telemetry = {layer: simulation.telemetry[layer].summary() for layer in (*LAYERS, FORCE_PATH)}
    return result


__all__ = ["LAYER_PRIORITIES", "START_DELAY", "process_prepared", "run_realtime"]
