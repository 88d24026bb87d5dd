"""Why a haptic period ran late, from the kernel's own trace of the haptic core (ftrace).

The steal counters of /proc/stat move in 10 ms ticks, too coarse to pin a 4-9 ms stall on
the host. The kernel's trace of the core is not: every timer the core arms is logged with
its expiry (``timer:hrtimer_start``) and when it fires (``timer:hrtimer_expire_entry``, with
the time the interrupt was handled). A timer interrupt handled late means the core was not
executing at all (a vCPU the host did not run, or interrupts held off, which a working guest
kernel does for microseconds, not milliseconds). With context switches, interrupts and page
faults also traced, each late period falls in one of:

- ``a timer came late``: a timer fired late enough to explain the period, with no event at
  all on the core between its expiry and its interrupt (the vCPU did not run);
- ``woken on time, then nothing else ran``: the haptic process's timer fired on time and the
  core ran no other task and no interrupt (beyond the scheduler tick) until the step began, late:
  the process held the core, spinning to its deadline, and a gap with no event on a core that
  had nothing else to do is the vCPU stopped, in a stretch where no timer was due to show it;
- ``woken on time, the core ran other work first``: tasks or interrupt handlers (named) ran
  in between: contention inside the guest;
- ``the step ran long``: the haptic step itself took the time (page faults counted).

Needs root and tracefs (mounted here if missing). Used by ``benchmarks/runtime.py --trace``;
the tracing settings are put back afterwards.
"""

from __future__ import annotations

import re
import subprocess
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

TRACEFS = Path("/sys/kernel/tracing")
EVENTS = (
    "timer:hrtimer_start",
    "timer:hrtimer_expire_entry",
    "sched:sched_switch",
    "sched:sched_waking",
    "irq:irq_handler_entry",
    "irq:softirq_entry",
    "exceptions:page_fault_user",
    "exceptions:page_fault_kernel",
)
LINE = re.compile(
    r"^\s*(?P<comm>.*?)-(?P<pid>\d+)\s+\[\d+\]\s+\S+\s+(?P<ts>\d+\.\d+): (?P<event>\w+): (?P<rest>.*)$"
)
FIELD = re.compile(r"(\w+)=(\S+)")
TIMER_LATE = "the vCPU did not run (a timer came late)"
NOTHING_ELSE = "the vCPU did not run (woken on time, then nothing else ran on the core)"
RAN_LATE = "woken on time, the core ran other work first"
STEP_LONG = "the step ran long"
TICK_SOFTIRQS = {"SCHED", "TIMER", "HRTIMER", "RCU"}
"""The scheduler tick's own softirqs (microseconds each), not work that competes with the loop."""
SETTINGS = ("tracing_on", "trace_clock", "tracing_cpumask", "buffer_size_kb", "set_event")


@dataclass
class CoreTrace:
    """The parsed trace of one core: timer expiries with their lateness, and what ran when."""

    expiry_times: np.ndarray  # s, monotonic (perf_counter's clock)
    # s the interrupt was handled after the timer's expiry, counted only while the core was silent
    expiry_lateness: np.ndarray
    expiry_is_haptic: np.ndarray  # bool: the haptic process's own sleep timer
    switches: list[tuple[float, str]] = field(default_factory=list)  # (s, other task switched to)
    interrupts: list[tuple[float, str]] = field(default_factory=list)  # (s, handler or softirq)
    faults: np.ndarray = field(default_factory=lambda: np.zeros(0))  # s of the haptic process's faults

    def explain(self, begin: float, end: float, haptic_step_wall: float) -> tuple[str, str]:
        """What made the period from ``begin`` to ``end`` (s, step starts) late: (cause, detail)."""
        inside = (self.expiry_times >= begin) & (self.expiry_times <= end + 1e-4)
        late_by = float(self.expiry_lateness[inside].max()) if inside.any() else 0.0
        period = end - begin
        if late_by > 0.5 * (period - 1e-3):
            return TIMER_LATE, f"a timer fired {1e3 * late_by:.1f} ms late"
        if haptic_step_wall > 0.5 * period:
            faults = int(np.count_nonzero((self.faults >= begin) & (self.faults <= end)))
            return STEP_LONG, f"a {1e3 * haptic_step_wall:.1f} ms step with {faults} page faults"
        ran = Counter(task for when, task in self.switches if begin <= when <= end)
        ran += Counter(
            name for when, name in self.interrupts if begin <= when <= end and name not in TICK_SOFTIRQS
        )
        if not ran:  # the haptic process held the core throughout, spinning to its deadline
            return NOTHING_ELSE, f"a {1e3 * period:.1f} ms period with no other task or interrupt"
        return RAN_LATE, "the core ran " + ", ".join(f"{k} x{v}" for k, v in ran.most_common(4))


class HapticCoreTrace:
    """Context manager: ftrace of ``cpu`` for the length of a run, then :meth:`parse`."""

    def __init__(self, cpu: int, buffer_kb: int = 262144) -> None:
        self.cpu, self.buffer_kb = cpu, buffer_kb
        self._saved: dict[str, str] = {}
        self.text = ""

    def _write(self, name: str, value: str) -> None:
        (TRACEFS / name).write_text(value)

    def __enter__(self) -> HapticCoreTrace:
        if not (TRACEFS / "README").exists():
            subprocess.run(["mount", "-t", "tracefs", "nodev", str(TRACEFS)], check=True)
        for name in SETTINGS:
            text = (TRACEFS / name).read_text()
            if name == "trace_clock":  # "[local] global ...": the bracketed one is in use
                text = text.split("[", 1)[1].split("]", 1)[0]
            self._saved[name] = text
        self._write("tracing_on", "0")
        self._write("trace", "")
        self._write("trace_clock", "mono")  # CLOCK_MONOTONIC, perf_counter's clock
        self._write("tracing_cpumask", f"{1 << self.cpu:x}")
        self._write("buffer_size_kb", str(self.buffer_kb))
        self._write("set_event", "\n".join(EVENTS) + "\n")
        self._write("tracing_on", "1")
        return self

    def __exit__(self, *exc: object) -> None:
        self._write("tracing_on", "0")
        self.text = (TRACEFS / "per_cpu" / f"cpu{self.cpu}" / "trace").read_text()
        self._write("trace", "")
        for name in ("set_event", "trace_clock", "tracing_cpumask", "buffer_size_kb", "tracing_on"):
            self._write(name, self._saved[name].strip() + "\n")

    def parse(self, haptic_pid: int) -> CoreTrace:
        armed: dict[str, tuple[int, bool]] = {}  # timer -> (expires ns, armed by the haptic process)
        times, lateness, haptic = [], [], []
        previous = -np.inf  # s of the core's last traced event
        switches, interrupts, faults = [], [], []
        for line in self.text.splitlines():
            match = LINE.match(line)
            if match is None:
                continue
            event, when, pid = match["event"], float(match["ts"]), int(match["pid"])
            fields = dict(FIELD.findall(match["rest"]))
            silent_since, previous = previous, when
            if event == "hrtimer_start":
                own = pid == haptic_pid and fields["function"] == "hrtimer_wakeup"  # its sleep
                armed[fields["hrtimer"]] = (int(fields["expires"]), own)
            elif event == "hrtimer_expire_entry":
                expiry = armed.pop(fields["hrtimer"], None)
                if expiry is not None:
                    times.append(when)
                    # late only if nothing at all happened on the core from the timer's expiry
                    # to its interrupt: an idle core's tick can be handled on its way out of idle
                    # with no expiry traced, and the next expiry of that timer would otherwise
                    # read as late by a whole tick, although the core ran in between
                    late = max(0, int(fields["now"]) - expiry[0]) * 1e-9
                    lateness.append(late if silent_since <= when - late + 2e-5 else 0.0)
                    haptic.append(expiry[1])
            elif event == "sched_switch" and int(fields["next_pid"]) not in (0, haptic_pid):
                switches.append((when, fields["next_comm"]))
            elif event in ("irq_handler_entry", "softirq_entry"):
                interrupts.append((when, fields.get("name") or fields.get("action", "?").strip("[]")))
            elif event.startswith("page_fault") and pid == haptic_pid:
                faults.append(when)
        return CoreTrace(
            np.array(times),
            np.array(lateness),
            np.array(haptic, dtype=bool),
            switches,
            interrupts,
            np.array(faults),
        )


def late_periods_explained(steps: np.ndarray, trace: CoreTrace, over: float = 3e-3) -> str:
    """The haptic periods over ``over`` s by what the kernel trace says of each (see the module
    docstring); ``steps`` are the benchmark's per-step (start, wall, cpu) rows."""
    starts = steps[:, 0]
    late = np.flatnonzero(np.diff(starts) > over)
    periods: dict[str, list[float]] = {TIMER_LATE: [], NOTHING_ELSE: [], RAN_LATE: [], STEP_LONG: []}
    example: dict[str, str] = {}
    for i in late:
        cause, detail = trace.explain(float(starts[i]), float(starts[i + 1]), float(steps[i, 1]))
        periods[cause].append(float(starts[i + 1] - starts[i]))
        example.setdefault(cause, detail)
    parts = [
        f"{cause} {len(found)}"
        + (f" (longest {1e3 * max(found):.1f} ms; e.g. {example[cause]})" if found else "")
        for cause, found in periods.items()
    ]
    return f"{len(late)} periods > {1e3 * over:.0f} ms by the kernel trace of the haptic core: " + "; ".join(
        parts
    )
