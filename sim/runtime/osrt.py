"""The operating system's part of real time: priorities, memory, CPUs, and waiting to the microsecond.

What :mod:`sim.runtime.realtime` asks of Linux for a run: a real-time scheduling class where
permitted, the haptic core left to the haptic process, its pages locked, no transparent huge pages
and a frozen heap for the run (:func:`process_prepared`), deadlines met by sleeping then spinning,
and a child process waited for and its error pipe read.
"""

from __future__ import annotations

import contextlib
import functools
import gc
import os
import signal
import time as clock
from collections.abc import Iterator
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from sim.runtime.shared import ControlBlock

SPIN_MARGIN = 3e-4  # s before a deadline at which the haptic process stops sleeping and spins
PR_SET_PDEATHSIG = 1  # prctl option: the signal this process gets when its parent dies
PR_SET_THP_DISABLE, PR_GET_THP_DISABLE = 41, 42  # prctl options: no transparent huge pages
M_TRIM_THRESHOLD, M_MMAP_MAX = -1, -4  # mallopt options (glibc's malloc.h)
DEFAULTS = ((M_MMAP_MAX, 65536), (M_TRIM_THRESHOLD, 128 * 1024))  # glibc's, put back after a run


def leave_last_core_to_haptics(pin_cpus: bool) -> set[int] | None:
    """Move every thread of this process (BLAS pools and GL workers included) off the haptic core.

    Returns the previous affinity, or None when nothing was changed.
    """
    if not pin_cpus or not hasattr(os, "sched_setaffinity"):
        return None
    cpus = os.sched_getaffinity(0)
    if len(cpus) < 2:
        return None
    set_all_threads(set(sorted(cpus)[:-1]))
    return cpus


def set_all_threads(cpus: set[int]) -> None:
    for tid in os.listdir("/proc/self/task"):
        try:
            os.sched_setaffinity(int(tid), cpus)
        except OSError:  # a thread that just ended
            continue


def try_realtime_priority(priority: int = 50) -> bool:
    """SCHED_FIFO for the calling thread where permitted (root or CAP_SYS_NICE).

    With both cores busy, the kernel balances other processes onto the haptic core
    and preempts the 1 kHz loop for milliseconds; a real-time class stops that. The
    loop sleeps most of each period, so the kernel's RT throttling never engages.
    """
    if not hasattr(os, "sched_setscheduler"):
        return False
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except (PermissionError, OSError):
        return False
    return True


@contextlib.contextmanager
def process_prepared() -> Iterator[None]:
    """This process's settings for the length of a run, put back after; enter it before anything
    of the run is forked, so that the forked processes inherit them.

    - The heap is collected once and frozen: a full collection walks every object of this process
      (the meshes, the scene, the libraries), 20-45 ms that would stall the FEM and graphics
      threads mid-run; frozen, the run's collections scan only what the run allocates.
    - No new transparent huge pages, and khugepaged leaves the memory alone
      (``PR_SET_THP_DISABLE``; the flag belongs to the process, so a killed run leaves nothing
      behind). NumPy asks for huge pages on its large arrays, and khugepaged collapses them 2 MB
      at a time. Traced on the haptic core (``benchmarks/runtime.py --trace``): a collapse ran
      6.3 ms there without giving way to the woken haptic process, since this guest kernel
      preempts only at its voluntary points; all 16 guest-side periods over 3 ms of a 60 s
      artery run were such kernel threads. Huge pages already mapped stay.
    - Memory this process frees is kept for its next allocations, never handed back to the system
      (glibc's ``mallopt``: large blocks from the heap instead of their own mappings, no trimming),
      as real-time processes are advised to. The prefetched K0^-1 columns come and go 8.6 MB a node
      on a 119k-node wall; each block mapped anew and returned made the machine slow this process
      for a while after: measured here, 560 rows read from an old array took 1.4-2.1 ms at p90
      after 260 MB of such blocks, 0.09 ms with the memory kept, and contact starts on that wall
      took 6-9 ms in a few of 40 instead of 2-3 ms (``benchmarks/meshing.py``). The process's
      size then stays at its peak for the run.
    """
    libc = libc_functions()
    previous = -1 if libc is None else libc.prctl(PR_GET_THP_DISABLE, 0, 0, 0, 0)
    if previous >= 0:  # else not Linux, or a kernel without the option: left as it is
        libc.prctl(PR_SET_THP_DISABLE, 1, 0, 0, 0)
    keeping = _keep_freed_memory(libc, True)
    gc.collect()
    gc.freeze()
    try:
        yield
    finally:
        gc.unfreeze()
        if keeping:
            _keep_freed_memory(libc, False)
        if previous >= 0:
            libc.prctl(PR_SET_THP_DISABLE, previous, 0, 0, 0)


def _keep_freed_memory(libc, keep: bool) -> bool:
    """Tell glibc's malloc to keep freed memory (``keep``) or to go back to its defaults; False
    where the C library has no ``mallopt`` (not glibc) or refuses."""
    mallopt = getattr(libc, "mallopt", None)
    if mallopt is None:
        return False
    values = ((M_MMAP_MAX, 0), (M_TRIM_THRESHOLD, -1)) if keep else DEFAULTS
    return all([bool(mallopt(option, value)) for option, value in values])


@functools.cache
def libc_functions():
    """The C library through ctypes (prctl, mlockall), or None where it cannot be loaded."""
    import ctypes

    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl  # noqa: B018 - not every C library has it
    except (OSError, AttributeError):
        return None
    return libc


def lock_memory() -> bool:
    """Keep the haptic process's pages resident (it is off transparent huge pages already: the
    setting of :func:`process_prepared` is inherited).

    Large allocations elsewhere on the machine can make a page fault wait for
    memory compaction for milliseconds; locked, pre-faulted memory never does.
    """
    libc = libc_functions()
    # MCL_FUTURE only: locking the inherited heap (MCL_CURRENT) would copy every
    # copy-on-write page of the parent, seconds of work for a large precomputation.
    return libc is not None and libc.mlockall(2) == 0


def sleep_until(deadline: float) -> None:
    remaining = deadline - clock.perf_counter()
    if remaining > SPIN_MARGIN:
        clock.sleep(remaining - SPIN_MARGIN)
    while clock.perf_counter() < deadline:
        pass


def wait_for(pid: int, timeout: float) -> None:
    deadline = clock.monotonic() + timeout
    while clock.monotonic() < deadline:
        try:
            done, _ = os.waitpid(pid, os.WNOHANG)
        except ChildProcessError:  # already reaped (it died during its set-up)
            return
        if done:
            return
        clock.sleep(0.01)
    os.kill(pid, 9)
    os.waitpid(pid, 0)


def read_all(fd: int, close: bool = True) -> str:
    """Everything a child wrote to its error pipe (the child has exited: the pipe is at its end)."""
    chunks = []
    while chunk := os.read(fd, 4096):
        chunks.append(chunk)
    if close:
        os.close(fd)
    return b"".join(chunks).decode(errors="replace")


# -- what every forked layer process does ------------------------------------------------------
def leave_interrupts_to_parent() -> None:
    """In a forked child: Ctrl-C reaches the terminal's whole process group; the parent turns it into
    a stop every layer sees, so the child ignores it rather than dying with a traceback."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def report_failure(fd: int, layer: str, error: BaseException) -> None:
    """In a forked child: the failure, named with its layer, for the parent to read."""
    try:
        os.write(fd, f"{layer}: {type(error).__name__}: {error}".encode()[:4000])
    except OSError:
        pass


def stop_with_parent(parent: int, control: ControlBlock) -> None:
    """In a forked child: stop the run (the loop winds down, force to zero first) when the process
    that forked it dies, killed included. An orphaned haptic loop would go on commanding the
    device. Linux sends the child SIGTERM then (PR_SET_PDEATHSIG); elsewhere nothing changes."""
    signal.signal(signal.SIGTERM, lambda signum, frame: control.request_stop())
    libc = libc_functions()
    if libc is None:
        return
    libc.prctl(PR_SET_PDEATHSIG, signal.SIGTERM, 0, 0, 0)
    if os.getppid() != parent:  # it died before the request was in place
        control.request_stop()
