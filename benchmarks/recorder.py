"""Recorder figures of issue 5 (in-process part).

Run:  .venv/bin/python benchmarks/recorder.py

- record() cost per call, p50/p99, from a 1 kHz producer thread while the writer
  thread flushes every 100 ms (5 runs of 10 s of samples, paced at 1 kHz);
- sustained in-process throughput: samples/s recorded and made durable when the
  producer writes as fast as it can (ring of 2^20 rows);
- record() back to back (hot caches), p50/p99;
- record() from a forked producer paced at 1 kHz while this process's writer
  thread flushes (the real-time layout: the haptic process records);
- durability lag: time from record() to the sample being fsynced, p50/p99/max.
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

import numpy as np

# This script shares its name with the package it measures: keep its own folder off the path.
sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != Path(__file__).resolve().parent]

from recorder import COLUMN, SAMPLE_COLUMNS, SessionWriter  # noqa: E402
from sim.runtime.realtime import _sleep_until  # noqa: E402


def paced_cost(directory: str, seconds: float = 10.0) -> tuple[np.ndarray, np.ndarray]:
    writer = SessionWriter(directory, {"benchmark": "paced"}, flush_interval=0.1)
    row = np.zeros(len(SAMPLE_COLUMNS))
    costs = np.empty(int(seconds * 1000))
    recorded_at = np.empty(len(costs))
    start = time.perf_counter()
    lag: list[float] = []
    for i in range(len(costs)):
        _sleep_until(start + i * 1e-3)  # as the haptic loop waits: sleep, then spin the last 0.3 ms
        row[COLUMN["time"]] = i * 1e-3
        t0 = time.perf_counter_ns()
        writer.record(row)
        costs[i] = (time.perf_counter_ns() - t0) * 1e-9
        recorded_at[i] = time.perf_counter()
        durable = writer.durable_samples
        if durable and (not lag or durable > lag[-1][0]):
            lag.append((durable, time.perf_counter()))
    writer.close()
    # Durability lag of every sample: from its record() to the first fsync seen covering it.
    lags, previous = [], 0
    for count, seen in lag:
        lags.append(seen - recorded_at[previous:count])
        previous = count
    return costs, np.concatenate(lags)


def forked_cost(directory: str, seconds: float = 10.0) -> np.ndarray:
    """record() from a forked producer paced at 1 kHz (as the real-time haptic process records),
    the writer thread flushing in this process: no interpreter lock is shared."""
    import mmap
    import os

    writer = SessionWriter(directory, {"benchmark": "forked"}, flush_interval=0.1)
    calls = int(seconds * 1000)
    costs = np.frombuffer(mmap.mmap(-1, 8 * calls), dtype=np.float64)
    start = time.perf_counter() + 0.1
    pid = os.fork()
    if pid == 0:
        writer.prefault()  # as the haptic process does before its loop
        row = np.zeros(len(SAMPLE_COLUMNS))
        for i in range(calls):
            _sleep_until(start + i * 1e-3)
            row[0] = i * 1e-3
            t0 = time.perf_counter_ns()
            writer.record(row)
            costs[i] = (time.perf_counter_ns() - t0) * 1e-9
        os._exit(0)
    os.waitpid(pid, 0)
    while writer.durable_samples < calls:
        time.sleep(0.01)
    writer.close()
    return costs.copy()


def paced_floor(calls: int = 10_000) -> np.ndarray:
    """The same timing around a call that does nothing, paced the same way: the measurement floor."""

    def nothing(row: np.ndarray) -> bool:
        return True

    row = np.zeros(len(SAMPLE_COLUMNS))
    costs = np.empty(calls)
    start = time.perf_counter() + 0.05
    for i in range(calls):
        _sleep_until(start + i * 1e-3)
        t0 = time.perf_counter_ns()
        nothing(row)
        costs[i] = (time.perf_counter_ns() - t0) * 1e-9
    return costs


def hot_cost(directory: str, calls: int = 200_000) -> np.ndarray:
    """record() called back to back (the writer flushing meanwhile)."""
    writer = SessionWriter(directory, {"benchmark": "hot"}, flush_interval=0.1, capacity=1 << 20)
    row = np.zeros(len(SAMPLE_COLUMNS))
    costs = np.empty(calls)
    for i in range(calls):
        row[0] = i * 1e-3
        t0 = time.perf_counter_ns()
        writer.record(row)
        costs[i] = (time.perf_counter_ns() - t0) * 1e-9
    writer.close()
    return costs


def throughput(directory: str, samples: int = 3_000_000) -> float:
    writer = SessionWriter(directory, {"benchmark": "throughput"}, flush_interval=0.1, capacity=1 << 20)
    rows = np.zeros((1000, len(SAMPLE_COLUMNS)))
    rows[:, COLUMN["time"]] = np.arange(1000) * 1e-3
    start = time.perf_counter()
    written = 0
    while written < samples:
        done = 0
        while done < len(rows):  # back-pressure for this measurement: wait, do not drop
            done += writer.record_block(rows[done:])
            if done < len(rows):
                time.sleep(0.001)
        written += len(rows)
    while writer.durable_samples < written:
        time.sleep(0.001)
    elapsed = time.perf_counter() - start
    writer.close()
    return written / elapsed


def main() -> None:
    all_costs, all_lags = [], []
    for _ in range(5):
        with tempfile.TemporaryDirectory() as directory:
            costs, lags = paced_cost(directory + "/s")
            all_costs.append(costs)
            all_lags.append(lags)
    costs = np.concatenate(all_costs)
    lags = np.concatenate(all_lags)
    with tempfile.TemporaryDirectory() as directory:
        hot = hot_cost(directory + "/s")
    forked = []
    for _ in range(3):
        with tempfile.TemporaryDirectory() as directory:
            forked.append(forked_cost(directory + "/s"))
    forked = np.concatenate(forked)
    floor = paced_floor()
    print(
        f"floor: an empty call timed and paced the same way: p50={1e6 * np.percentile(floor, 50):.2f} us "
        f"p99={1e6 * np.percentile(floor, 99):.2f} us"
    )
    p50, p99 = 1e6 * np.percentile(forked, 50), 1e6 * np.percentile(forked, 99)
    print(
        f"record() from a forked producer at 1 kHz, writer thread in the parent: p50={p50:.2f} us "
        f"p99={p99:.2f} us max={1e6 * forked.max():.1f} us (n={len(forked)})"
    )
    print(
        f"record() back to back with the writer running: p50={1e6 * np.percentile(hot, 50):.2f} us "
        f"p99={1e6 * np.percentile(hot, 99):.2f} us (n={len(hot)})"
    )
    print(
        f"record() at 1 kHz with the writer running: p50={1e6 * np.percentile(costs, 50):.2f} us "
        f"p99={1e6 * np.percentile(costs, 99):.2f} us max={1e6 * costs.max():.1f} us (n={len(costs)})"
    )
    print(
        f"durability lag (record -> fsynced): p50={1e3 * np.percentile(lags, 50):.1f} ms "
        f"p99={1e3 * np.percentile(lags, 99):.1f} ms max={1e3 * lags.max():.1f} ms (n={len(lags)})"
    )
    rates = []
    for _ in range(3):
        with tempfile.TemporaryDirectory() as directory:
            rates.append(throughput(directory + "/s"))
    print(
        f"sustained in-process throughput: median {np.median(rates):,.0f} samples/s "
        f"(runs: {', '.join(f'{r:,.0f}' for r in rates)})"
    )


if __name__ == "__main__":
    main()
