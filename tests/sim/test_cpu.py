"""The cores' idle limit is held for a run and released after it, even by a killed run; never required."""

import os
import signal
import subprocess
import sys

from sim.runtime.cpu import CPU_LATENCY, IdlePolling, cpu_latency_limit


def test_the_request_is_written_and_released_with_the_file(tmp_path):
    device = tmp_path / "cpu_dma_latency"
    device.write_bytes(b"\xff" * 4)
    with IdlePolling(device) as polling:
        assert polling.active and device.read_bytes() == bytes(4)  # 0 us: nothing deeper than polling
    assert not polling.active and polling._request is None


def test_the_request_is_released_when_the_run_fails():
    before = cpu_latency_limit()
    try:
        with IdlePolling():
            assert cpu_latency_limit() == 0
            raise RuntimeError("a layer failed")
    except RuntimeError:
        pass
    assert cpu_latency_limit() == before


def test_without_the_device_nothing_happens(tmp_path):
    with IdlePolling(tmp_path / "missing") as polling:
        assert not polling.active
    assert not (tmp_path / "missing").exists()


def test_the_real_run_leaves_the_machine_as_it_found_it():
    """Root here: the request holds while active, and the previous limit is back after."""
    before = cpu_latency_limit()
    seen = []
    with IdlePolling() as polling:
        seen.append((polling.active, cpu_latency_limit()))
    assert seen == [(True, 0)] and cpu_latency_limit() == before
    assert CPU_LATENCY.exists()


def test_a_killed_run_cannot_leave_the_request_behind():
    """SIGKILL runs no clean-up code: the kernel drops the request with the dead process's file."""
    before = cpu_latency_limit()
    script = (
        "import os, signal, sys\n"
        "from sim.runtime.cpu import IdlePolling, cpu_latency_limit\n"
        "with IdlePolling() as polling:\n"
        "    print(polling.active, cpu_latency_limit(), flush=True)\n"
        "    os.kill(os.getpid(), signal.SIGKILL)\n"
    )
    child = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=60)
    assert child.returncode == -signal.SIGKILL
    assert child.stdout.split() == ["True", "0"]
    assert cpu_latency_limit() == before and before != 0


def test_steal_is_read_per_core_in_seconds(tmp_path):
    from sim.runtime.cpu import stolen_seconds

    ticks = os.sysconf("SC_CLK_TCK")
    stat = tmp_path / "stat"
    stat.write_text(
        "cpu  10554 0 4196 22630 517 0 78 22 0 0\n"
        "cpu0 2295 0 1198 15432 51 0 12 6 0 0\n"
        f"cpu1 8259 0 2998 7197 465 0 65 {3 * ticks} 0 0\n"
        "intr 1 2 3\n"
    )
    assert stolen_seconds(stat) == {0: 6 / ticks, 1: 3.0}
    assert stolen_seconds(tmp_path / "missing") == {}
