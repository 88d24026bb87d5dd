"""The benchmark's reading of a kernel trace of the haptic core, on excerpts of real traces
(``benchmarks/runtime.py --trace`` on this kind of VM; pids as they were in those runs)."""

import importlib.util
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
TRACES = ROOT / "tests" / "data" / "ftrace"


def kernel_trace():
    spec = importlib.util.spec_from_file_location("kernel_trace", ROOT / "benchmarks" / "kernel_trace.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault("kernel_trace", module)  # its dataclasses look their module up there
    spec.loader.exec_module(module)
    return module


def parsed(name: str, haptic_pid: int):
    module = kernel_trace()
    trace = module.HapticCoreTrace(cpu=1)
    trace.text = (TRACES / name).read_text()
    return module, trace.parse(haptic_pid)


def steps_around(begin: float, end: float) -> np.ndarray:
    """Per-step (start, wall, cpu) rows: a normal period, then the late one from begin to end."""
    return np.array([[begin - 1e-3, 2e-5, 2e-5], [begin, 2e-5, 2e-5], [end, 2e-5, 2e-5]])


def test_a_kernel_thread_holding_the_core_is_named_not_blamed_on_the_host():
    """khugepaged ran 6.3 ms on the haptic core after the haptic process was woken on time."""
    module, core = parsed("khugepaged_holds_the_haptic_core.txt", haptic_pid=28628)
    haptic = core.expiry_lateness[core.expiry_is_haptic]
    assert len(haptic) >= 8 and haptic.max() < 20e-6  # its sleep timers all fired on time
    cause, detail = core.explain(3157.206114, 3157.212518, haptic_step_wall=2e-5)
    assert cause == module.RAN_LATE and "khugepaged" in detail
    summary = module.late_periods_explained(steps_around(3157.206114, 3157.212518), core)
    assert summary.startswith("1 periods > 3 ms") and f"{module.RAN_LATE} 1 (longest 6.4 ms" in summary


def test_a_long_step_is_the_step():
    module, core = parsed("khugepaged_holds_the_haptic_core.txt", haptic_pid=28628)
    cause, detail = core.explain(3157.206114, 3157.212518, haptic_step_wall=5e-3)
    assert cause == module.STEP_LONG and detail.startswith("a 5.0 ms step")


def test_a_timer_handled_late_on_a_silent_core_is_the_host():
    """The haptic process was woken, then nothing happened on the core until the scheduler tick
    fired 7.6 ms after its expiry: the vCPU was not running."""
    module, core = parsed("haptic_timer_fires_late.txt", haptic_pid=29608)
    cause, detail = core.explain(3583.938141, 3583.947665, haptic_step_wall=2e-5)
    assert cause == module.TIMER_LATE and detail == "a timer fired 7.6 ms late"
    summary = module.late_periods_explained(steps_around(3583.938141, 3583.947665), core)
    assert f"{module.TIMER_LATE} 1 (longest 9.5 ms" in summary and f"{module.RAN_LATE} 0" in summary


def test_a_long_gap_with_nothing_else_on_the_core_is_the_host():
    module, core = parsed("nothing_else_runs.txt", haptic_pid=29608)
    cause, detail = core.explain(3588.738141, 3588.750720, haptic_step_wall=2e-5)
    assert cause == module.NOTHING_ELSE and detail.startswith("a 12.6 ms period")


def test_an_idle_tick_handled_untraced_is_not_read_as_late():
    """An idle core's tick handled on the way out of idle leaves no expiry event (only its
    softirq); the timer's next expiry must not count as a whole tick late: the core ran between."""
    _, core = parsed("idle_tick_handled_untraced.txt", haptic_pid=28628)
    armed_at_544_fired_at_548 = np.isclose(core.expiry_times, 3175.548030)
    assert armed_at_544_fired_at_548.sum() == 1 and core.expiry_lateness[armed_at_544_fired_at_548] == 0.0
    assert core.expiry_lateness.max() < 1e-4
