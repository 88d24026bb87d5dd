"""Keeping the haptic core awake: its idle state limited to polling for the length of a run;
and how much CPU time the hypervisor has taken from each core (the real-time figures follow it).

On these virtual machines an idle vCPU halts and the host takes the physical core; the
haptic process, woken from its sleep before each 1 ms deadline, then runs with cold caches
and branch predictors. Measured with record() paced at 1 kHz: p99 20 us with the core
allowed to halt, 3 us with its idle state limited to polling (back to back: 2.4 us). Linux
exposes the limit per CPU as a PM QoS resume latency; "n/a" means "never enter an idle
state deeper than polling". Writing it needs root (or a writable sysfs); without it the run
goes on as before. (Steering device interrupts off the core was tried too: the disk's virtio
interrupts are kernel-managed here and cannot be moved.)
"""

from __future__ import annotations

import os
from pathlib import Path
from types import TracebackType

SYSFS_CPUS = Path("/sys/devices/system/cpu")
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
    """Context manager: while active, ``cpu`` idles by polling; the previous limit is restored.

    ``active`` says whether the limit could be set (it cannot without the sysfs file or
    permission to write it; nothing else changes then).
    """

    def __init__(self, cpu: int, root: Path = SYSFS_CPUS) -> None:
        self.path = root / f"cpu{cpu}" / "power" / "pm_qos_resume_latency_us"
        self.active = False
        self._previous: str | None = None

    def __enter__(self) -> IdlePolling:
        try:
            self._previous = self.path.read_text().strip()
            self.path.write_text("n/a")
            self.active = True
        except OSError:  # no such file (not Linux, no cpuidle), or not permitted
            self.active = False
        return self

    def __exit__(
        self, kind: type[BaseException] | None, error: BaseException | None, trace: TracebackType | None
    ) -> None:
        if self.active and self._previous is not None:
            try:
                self.path.write_text(self._previous)
            except OSError:
                pass
            self.active = False
