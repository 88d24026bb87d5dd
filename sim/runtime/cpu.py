"""Keeping the cores awake for a run: their idle state limited to polling while it lasts;
and how much CPU time the hypervisor has taken from each core (the real-time figures follow it).

On these virtual machines an idle vCPU halts and the host takes the physical core; the
haptic process, woken from its sleep before each 1 ms deadline, then runs with cold caches
and branch predictors. Measured with record() paced at 1 kHz: p99 20 us with the core
allowed to halt, 3 us with its idle state limited to polling (back to back: 2.4 us).

The limit is a PM QoS request on ``/dev/cpu_dma_latency``: 0 us while the file is held open.
The kernel drops the request when the file is closed, and it is closed however the process
ends, a SIGKILL included, so a killed run cannot leave the machine polling (a per-CPU sysfs
limit, used before, stayed set after a killed run). The request holds every core, not only
the haptic one; during a run the other core is busy with the FEM, graphics and display
layers anyway. Opening it needs root (or a readable-writable device); without it the run
goes on as before. (Steering device interrupts off the core was tried too: the disk's
virtio interrupts are kernel-managed here and cannot be moved.)
"""

from __future__ import annotations

import os
import struct
from pathlib import Path
from types import TracebackType
from typing import BinaryIO

CPU_LATENCY = Path("/dev/cpu_dma_latency")
PROC_STAT = Path("/proc/stat")


def stolen_seconds(stat: Path = PROC_STAT) -> dict[int, float]:
    """CPU time (s) the hypervisor has taken from each core since boot ("steal", the eighth value
    of each ``cpuN`` line of /proc/stat, in clock ticks); empty where the file is missing.

    A vCPU stalls whenever the host runs something else on its physical core, however the guest
    schedules it: the benchmarks print this next to their real-time figures.
    """
    try:
        lines = stat.read_text().splitlines()
    except OSError:
        return {}
    ticks = os.sysconf("SC_CLK_TCK")
    stolen = {}
    for line in lines:
        fields = line.split()
        if len(fields) > 8 and fields[0].startswith("cpu") and fields[0][3:].isdigit():
            stolen[int(fields[0][3:])] = int(fields[8]) / ticks
    return stolen


class IdlePolling:
    """Context manager: while active, no core leaves polling for a deeper idle state (a 0 us CPU
    latency request, held by an open file the kernel releases when it is closed or the process
    dies).

    ``active`` says whether the request could be made (it cannot without the device or
    permission to open it; nothing else changes then).
    """

    def __init__(self, device: Path = CPU_LATENCY) -> None:
        self.device = device
        self.active = False
        self._request: BinaryIO | None = None

    def __enter__(self) -> IdlePolling:
        try:
            request = open(self.device, "r+b", buffering=0)  # held open for the run
        except OSError:  # no such device (not Linux), or not permitted
            return self
        try:
            request.write(struct.pack("i", 0))  # microseconds: nothing deeper than polling
        except OSError:
            request.close()
            return self
        self._request, self.active = request, True
        return self

    def __exit__(
        self, kind: type[BaseException] | None, error: BaseException | None, trace: TracebackType | None
    ) -> None:
        if self._request is not None:
            self._request.close()  # the kernel drops the request with the file
            self._request = None
        self.active = False


def cpu_latency_limit(device: Path = CPU_LATENCY) -> int:
    """The machine's current CPU latency limit (us) across every request; 2000000000 means none."""
    with open(device, "rb", buffering=0) as current:
        return struct.unpack("i", current.read(4))[0]
