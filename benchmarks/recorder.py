"""Recorder figures of issue 5 (in-process part).

Run:  .venv/bin/python benchmarks/recorder.py

- record() cost per call where a session calls it: in the haptic process of a 30 s
  real-time run on the test cube (all layers, offscreen rendering), the writer
  thread flushing in the parent;
- record() cost per call, p50/p99, from a 1 kHz producer thread while the writer
  thread flushes every 100 ms (5 runs of 10 s of samples, paced at 1 kHz);
- sustained in-process throughput: samples/s recorded and made durable when the
  producer writes as fast as it can (ring of 2^20 rows);
- record() back to back (hot caches), p50/p99;
- record() from a forked producer paced at 1 kHz while this process's writer
  thread flushes (the real-time layout: the haptic process records), with a
  memoryview row (as RuntimeRecorder passes it), a numpy row, and with the
  producer's core allowed to halt; and an empty call timed the same way (the floor);
- durability lag: time from record() to the sample being fsynced, p50/p99/max.

Network ingest (``--part ingest``): one central-recorder server process (uvicorn,
``recorder.remote.ingest``) on this machine; N simulated stations (default 50, asyncio in
this process) each send their session header, then generate 1 kHz samples and
send a 100-sample batch every 100 ms (their local flush interval) over WebSocket
or HTTP on loopback, for ``--seconds``. Printed: per-sample durability lag (sample generated -> its batch
acknowledged, i.e. fsynced by the server), batch round trip, server CPU, and
after closing every session, the samples stored per session against those sent
(zero loss means every sample exactly once, in order).

    .venv/bin/python benchmarks/recorder.py                       # everything
    .venv/bin/python benchmarks/recorder.py --part ingest --stations 50 --transport websocket
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

# This script shares its name with the package it measures: keep its own folder off the path.
sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != Path(__file__).resolve().parent]

from recorder import COLUMN, SAMPLE_COLUMNS, SessionWriter  # noqa: E402
from recorder.remote.protocol import encode_batch, pack_frame  # noqa: E402
from recorder.writer import samples_batch  # noqa: E402
from sessions.config import prepare_rendering  # noqa: E402
from sim.calibration.presets import tissue_preset  # noqa: E402
from sim.runtime.cpu import IdlePolling, stolen_seconds  # noqa: E402
from sim.runtime.osrt import set_all_threads, sleep_until  # noqa: E402

ARTERY = tissue_preset("porcine-artery").biphase  # the calibrated wall the default needle forces suit


def paced_cost(directory: str, seconds: float = 10.0) -> tuple[np.ndarray, np.ndarray]:
    writer = SessionWriter(directory, {"benchmark": "paced"}, flush_interval=0.1)
    row = np.zeros(len(SAMPLE_COLUMNS))
    costs = np.empty(int(seconds * 1000))
    recorded_at = np.empty(len(costs))
    start = time.perf_counter()
    lag: list[float] = []
    for i in range(len(costs)):
        sleep_until(start + i * 1e-3)  # as the haptic loop waits: sleep, then spin the last 0.3 ms
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


def forked_cost(directory: str, seconds: float = 10.0, poll: bool = True, view: bool = True) -> np.ndarray:
    """record() from a forked producer paced at 1 kHz, laid out as the real-time haptic process
    records: pinned to the last core, which idles by polling (``poll``, as ``run_realtime`` sets
    it; sim.runtime.cpu), the writer thread flushing in this process on the other cores. The row
    is a memoryview of a numpy row (``view``, as ``recorder.runtime.RuntimeRecorder`` passes it)
    or the numpy row itself."""
    import contextlib
    import mmap

    cpus = sorted(os.sched_getaffinity(0))
    haptic_core = cpus[-1]
    writer = SessionWriter(directory, {"benchmark": "forked"}, flush_interval=0.1)
    calls = int(seconds * 1000)
    costs = np.frombuffer(mmap.mmap(-1, 8 * calls), dtype=np.float64)
    start = time.perf_counter() + 0.1
    pid = os.fork()
    if pid == 0:
        os.sched_setaffinity(0, {haptic_core})
        writer.prefault()  # as the haptic process does before its loop
        row = np.zeros(len(SAMPLE_COLUMNS))
        recorded = memoryview(row) if view else row
        for i in range(calls):
            sleep_until(start + i * 1e-3)
            row[0] = i * 1e-3
            t0 = time.perf_counter_ns()
            writer.record(recorded)
            costs[i] = (time.perf_counter_ns() - t0) * 1e-9
        os._exit(0)
    if len(cpus) > 1:
        set_all_threads(set(cpus[:-1]))
    with IdlePolling(haptic_core) if poll else contextlib.nullcontext():  # as run_realtime does
        os.waitpid(pid, 0)
    set_all_threads(set(cpus))
    while writer.durable_samples < calls:
        time.sleep(0.01)
    writer.close()
    return costs.copy()


def haptic_process_cost(directory: str, seconds: float = 30.0) -> tuple[np.ndarray, dict]:
    """record() where it runs in a session: in the real-time haptic process, called by
    ``RuntimeRecorder`` at the end of every haptic step, all layers running on the test cube (FEM
    at 500 Hz, global CD at 30 Hz, the display rendering offscreen at 30 Hz), the writer thread
    flushing in this process. Each call is timed by a wrapper around the writer's own record (the
    wrapper's frame is counted in: the figure errs high)."""
    import mmap

    from recorder.runtime import RuntimeRecorder
    from sim.calibration.indentation import paper_cube
    from sim.calibration.scenarios import practice_passes, scenario
    from sim.devices import ScriptedDevice
    from sim.devices.scripted import sequence_of_passes
    from sim.fem import BiphaseTissue
    from sim.needle import Needle
    from sim.render import TissueRenderer
    from sim.runtime import RuntimeSettings, Simulation
    from sim.runtime.display import DisplayScene

    needle = Needle.curved()
    mesh, fixed = paper_cube()
    cube = BiphaseTissue.build(mesh, fixed, ARTERY)
    cube.precompute(use_cache=False)
    trajectory, total = sequence_of_passes(practice_passes(scenario("paper_cube"), needle, 20))
    duration = min(seconds, total)
    writer = SessionWriter(directory, {"benchmark": "haptic process"}, flush_interval=0.1)
    capacity = int(duration * 1000 * 1.2) + 2000
    costs = np.frombuffer(mmap.mmap(-1, 8 * capacity), dtype=np.float64)  # shared with the child
    count = np.frombuffer(mmap.mmap(-1, 8), dtype=np.int64)
    record = writer.record

    def timed(row) -> bool:
        t0 = time.perf_counter_ns()
        kept = record(row)
        t1 = time.perf_counter_ns()
        n = int(count[0])
        if n < capacity:
            costs[n] = (t1 - t0) * 1e-9
            count[0] = n + 1
        return kept

    writer.record = timed  # type: ignore[method-assign]
    scene = DisplayScene(cube, TissueRenderer(cube.mesh, size=(640, 480), offscreen=True))
    simulation = Simulation(
        cube, needle, ScriptedDevice(trajectory), RuntimeSettings(fem_rate=500.0), renderer=scene
    )
    result = RuntimeRecorder(writer).attach(simulation).run_realtime(duration)
    writer.close()
    return costs[: int(count[0])].copy(), result.telemetry["haptic"]


def cost_line(label: str, seconds: np.ndarray) -> str:
    """``label: p50, p99, max`` of per-call costs given in seconds, printed in microseconds."""
    us = 1e6 * seconds
    return (
        f"{label}: p50={np.percentile(us, 50):.2f} us p99={np.percentile(us, 99):.2f} us "
        f"max={us.max():.1f} us (n={len(us)})"
    )


def paced_floor(calls: int = 10_000) -> np.ndarray:
    """The same timing around a call that does nothing, paced the same way: the measurement floor."""

    def nothing(row: np.ndarray) -> bool:
        return True

    row = np.zeros(len(SAMPLE_COLUMNS))
    costs = np.empty(calls)
    start = time.perf_counter() + 0.05
    for i in range(calls):
        sleep_until(start + i * 1e-3)
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


SERVER = """
import sys, json, uvicorn
from recorder.remote.ingest import IngestStore
from recorder.remote.routes import create_app

tokens = json.loads(sys.argv[2])
uvicorn.run(create_app(IngestStore(sys.argv[1], tokens)), host="127.0.0.1", port=int(sys.argv[3]),
            log_level="warning", ws_max_size=16 * 2**20, ws_per_message_deflate=False)
"""


def _cpu_seconds(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


class BatchTemplate:
    """Valid sample batches made by patching a template's time column and sequence digits, so the
    load generator (sharing the two cores with the server) spends microseconds per batch, not the
    ~0.6 ms a fresh Arrow encoding costs. The server checks them like any other batch."""

    def __init__(self, batch_size: int) -> None:
        rows = np.zeros((batch_size, len(SAMPLE_COLUMNS)))
        rows[:, COLUMN["tool_qw"]] = 1.0
        rows[:, COLUMN["local_stress"]] = np.nan
        rows[:, COLUMN["tool_x"]] = 0.01 * np.sin(np.arange(batch_size))
        rows[:, COLUMN["time"]] = 1e9 + np.pi * np.arange(batch_size)  # a pattern found only once
        self.template = encode_batch(samples_batch(rows), 10**11)  # twelve digits to overwrite
        self.time_at = self.template.index(rows[:, COLUMN["time"]].tobytes())
        self.sequence_at = self.template.index(b"100000000000")
        self.batch_size = batch_size

    def body(self, sequence: int, times: np.ndarray) -> bytes:
        data = bytearray(self.template)
        data[self.time_at : self.time_at + 8 * self.batch_size] = times.astype("<f8").tobytes()
        data[self.sequence_at : self.sequence_at + 12] = f"{sequence:012d}".encode()
        return bytes(data)


class StartLine:
    """Stations connect and send their session header first (a station's session starts with its
    header: the central recorder opens the session's files then); the clock starts once all have,
    each station offset by its share of one batch interval, as independent machines would be."""

    def __init__(self, stations: int) -> None:
        self.stations, self.connected, self.go, self.start = stations, 0, asyncio.Event(), 0.0

    async def connected_wait(self) -> float:
        self.connected += 1
        if self.connected == self.stations:
            self.start = time.perf_counter() + 0.2
            self.go.set()
        await self.go.wait()
        return self.start


class LeanHttp:
    """A minimal HTTP/1.1 keep-alive client on asyncio streams: the load generator shares the two
    cores with the server, and httpx's ~2 ms of CPU per request would make it the bottleneck."""

    def __init__(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter, host: str, auth: str):
        self.reader, self.writer, self.host, self.auth = reader, writer, host, auth

    @classmethod
    async def connect(cls, base: str, auth: str) -> LeanHttp:
        host, port = base.removeprefix("http://").split(":")
        reader, writer = await asyncio.open_connection(host, int(port))
        return cls(reader, writer, f"{host}:{port}", auth)

    async def request(self, method: str, path: str, body: bytes | str) -> tuple[int, str]:
        data = body.encode() if isinstance(body, str) else body
        head = (
            f"{method} {path} HTTP/1.1\r\nHost: {self.host}\r\nAuthorization: {self.auth}\r\n"
            f"Content-Length: {len(data)}\r\n\r\n"
        )
        self.writer.write(head.encode() + data)
        status_line = await self.reader.readline()
        length = 0
        while (line := await self.reader.readline()) not in (b"\r\n", b""):
            name, _, value = line.decode("latin-1").partition(":")
            if name.strip().lower() == "content-length":
                length = int(value)
        answer = await self.reader.readexactly(length)
        return int(status_line.split()[1]), answer.decode()

    def close(self) -> None:
        self.writer.close()


async def _station(index, base, transport, seconds, line, acks, batch_size=100, interval=0.1):
    """One simulated station: a batch of ``batch_size`` 1 kHz samples every ``interval`` seconds."""
    import websockets

    token = {"Authorization": f"Bearer token-{index}"}
    template = BatchTemplate(batch_size)
    batches = int(seconds / interval)
    session = f"bench-{index}"
    header = {"participant": f"P{index:02d}", "task": "benchmark", "device": "simulated station"}
    sent_at: dict[int, float] = {}

    def body(sequence: int) -> bytes:
        return template.body(sequence, (sequence * batch_size + np.arange(batch_size)) * 1e-3)

    async def wait_until(deadline: float) -> None:
        delay = deadline - time.perf_counter()
        if delay > 0:
            await asyncio.sleep(delay)

    start = 0.0
    offset = interval * index / line.stations

    def acknowledged(sequence: int) -> None:
        now = time.perf_counter()
        generated = start + (sequence * batch_size + np.arange(batch_size)) * 1e-3
        acks.append((now - generated, now - sent_at.pop(sequence)))

    if transport == "websocket":
        url = base.replace("http://", "ws://") + f"/api/sessions/{session}/ws"
        async with websockets.connect(
            url, additional_headers=token, max_size=None, compression=None
        ) as socket:
            await socket.send(json.dumps({"op": "header", "header": header}))  # as a station starts
            if json.loads(await socket.recv())["status"] != 200:
                raise RuntimeError(f"station {index}: header refused")
            start = await line.connected_wait() + offset

            async def receive() -> None:
                for _ in range(batches):
                    answer = json.loads(await socket.recv())
                    if answer["status"] != 200:
                        raise RuntimeError(f"station {index}: {answer}")
                    acknowledged(answer["ack"])

            receiver = asyncio.create_task(receive())
            for sequence in range(batches):
                await wait_until(start + (sequence + 1) * interval)
                payload = pack_frame("samples", sequence, body(sequence))
                sent_at[sequence] = time.perf_counter()
                await socket.send(payload)
            await receiver
    else:
        client = await LeanHttp.connect(base, token["Authorization"])
        try:
            status, text = await client.request("PUT", f"/api/sessions/{session}/header", json.dumps(header))
            if status != 200:
                raise RuntimeError(f"station {index}: {text}")
            start = await line.connected_wait() + offset
            for sequence in range(batches):
                await wait_until(start + (sequence + 1) * interval)
                payload = body(sequence)
                sent_at[sequence] = time.perf_counter()
                path = f"/api/sessions/{session}/samples/{sequence}"
                status, text = await client.request("POST", path, payload)
                if status != 200:
                    raise RuntimeError(f"station {index}: {text}")
                acknowledged(sequence)
        finally:
            client.close()
    return batches


async def _close_all(base: str, stations: int, sent: list[int]) -> list[dict]:
    import httpx

    answers = []
    async with httpx.AsyncClient(base_url=base, timeout=120) as client:
        for index in range(stations):
            answer = await client.post(
                f"/api/sessions/bench-{index}/close",
                json={"batches": {"samples": sent[index], "events": 0}},
                headers={"Authorization": f"Bearer token-{index}"},
            )
            answers.append(answer.json())
    return answers


def ingest_load(stations: int, seconds: float, transport: str) -> dict:
    """Run one ingest load test against a fresh server process; returns its figures."""
    import socket
    import subprocess

    from recorder import open_session

    with tempfile.TemporaryDirectory() as root:
        with socket.socket() as probe:
            probe.bind(("127.0.0.1", 0))
            port = probe.getsockname()[1]
        tokens = {f"token-{i}": f"station-{i}" for i in range(stations)}
        server = subprocess.Popen([sys.executable, "-c", SERVER, root, json.dumps(tokens), str(port)])
        try:
            for _ in range(300):
                try:
                    socket.create_connection(("127.0.0.1", port), timeout=0.2).close()
                    break
                except OSError:
                    time.sleep(0.05)
            base = f"http://127.0.0.1:{port}"
            acks: list = []
            cpu_before, wall_before = _cpu_seconds(server.pid), time.perf_counter()
            steal_before = stolen_seconds()

            async def run() -> list[int]:
                line = StartLine(stations)
                return await asyncio.gather(
                    *[_station(i, base, transport, seconds, line, acks) for i in range(stations)]
                )

            sent = asyncio.run(run())
            cpu = (_cpu_seconds(server.pid) - cpu_before) / (time.perf_counter() - wall_before)
            steal_after = stolen_seconds()
            closed = asyncio.run(_close_all(base, stations, sent))
        finally:
            server.terminate()
            server.wait()
        lost = 0
        for index in range(stations):
            times = open_session(Path(root) / f"station-{index}" / f"bench-{index}").samples.column("time")
            expected = np.arange(sent[index] * 100) * 1e-3
            stored = times.to_numpy()
            if len(stored) != len(expected) or not np.array_equal(stored, expected):
                lost += abs(len(expected) - len(stored)) or 1
    lags = np.concatenate([lag for lag, _ in acks])
    round_trips = np.array([rt for _, rt in acks])
    return {
        "stations": stations,
        "transport": transport,
        "samples_sent": sum(sent) * 100,
        "samples_lost_or_wrong": lost,
        "closed": sum(1 for c in closed if c.get("closed")),
        "lag_ms": np.percentile(lags, [50, 99, 100]) * 1e3,
        "round_trip_ms": np.percentile(round_trips, [50, 99, 100]) * 1e3,
        "server_cpu_cores": cpu,
        "stolen_s": {core: steal_after[core] - steal_before[core] for core in sorted(steal_after)},
    }


def print_ingest(result: dict) -> None:
    lag, rt = result["lag_ms"], result["round_trip_ms"]
    print(
        f"ingest {result['stations']} stations x 1 kHz over {result['transport']}: "
        f"durability lag p50={lag[0]:.0f} ms p99={lag[1]:.0f} ms max={lag[2]:.0f} ms; "
        f"batch round trip p50={rt[0]:.1f} ms p99={rt[1]:.1f} ms max={rt[2]:.1f} ms; "
        f"server CPU {result['server_cpu_cores']:.2f} cores; "
        f"{result['samples_sent']:,} samples sent, {result['samples_lost_or_wrong']} lost or wrong, "
        f"{result['closed']}/{result['stations']} sessions closed; hypervisor steal during the run: "
        + ", ".join(f"cpu{core} {1e3 * seconds:.0f} ms" for core, seconds in result["stolen_s"].items())
    )


def in_process() -> None:
    with tempfile.TemporaryDirectory() as directory:
        haptic, loop = haptic_process_cost(directory + "/s")
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
    runs: dict[str, list[np.ndarray]] = {"forked": [], "numpy row": [], "halting": []}
    for _ in range(3):
        for kind, options in (("forked", {}), ("numpy row", {"view": False}), ("halting", {"poll": False})):
            with tempfile.TemporaryDirectory() as directory:
                runs[kind].append(forked_cost(directory + "/s", **options))
    forked, numpy_row, halting = (np.concatenate(runs[kind]) for kind in runs)
    floor = paced_floor()
    print(
        cost_line("record() in the haptic process of a 30 s real-time run (test cube, all layers)", haptic)
        + f"; haptic {loop.rate_hz:.1f} Hz, periods > 3 ms: {loop.periods_over_3ms}"
    )
    print(cost_line("floor: an empty call timed and paced as below", floor))
    print(
        cost_line("record() from a forked producer at 1 kHz, writer thread in the parent", forked)
        + " (its core idles by polling; the row a memoryview, as RuntimeRecorder passes it)"
    )
    print(cost_line("  the same with a numpy row", numpy_row))
    print(
        cost_line("  the same with the producer's core allowed to halt between calls", halting)
        + f" (ratio of p99s {np.percentile(halting, 99) / np.percentile(forked, 99):.1f}x)"
    )
    print(cost_line("record() back to back with the writer running", hot))
    print(cost_line("record() at 1 kHz from a thread of the writer's process (numpy row)", costs))
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


def main() -> None:
    prepare_rendering()  # offscreen EGL without a display, as the CLI
    formatter = argparse.RawDescriptionHelpFormatter
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=formatter)
    parser.add_argument("--part", choices=["all", "in-process", "ingest"], default="all")
    parser.add_argument("--stations", type=int, nargs="+", default=[50], help="station counts to run")
    parser.add_argument("--seconds", type=float, default=30.0, help="length of each ingest run")
    parser.add_argument("--transport", choices=["websocket", "http", "both"], default="both")
    parser.add_argument("--repeats", type=int, default=3, help="ingest runs per setting (median printed)")
    options = parser.parse_args()
    if options.part in ("all", "in-process"):
        in_process()
    if options.part in ("all", "ingest"):
        transports = ["websocket", "http"] if options.transport == "both" else [options.transport]
        for stations in options.stations:
            for transport in transports:
                runs = [ingest_load(stations, options.seconds, transport) for _ in range(options.repeats)]
                for run in runs:
                    print_ingest(run)
                median = sorted(runs, key=lambda r: r["lag_ms"][1])[len(runs) // 2]
                print("median run (by p99 lag):", end=" ")
                print_ingest(median)


if __name__ == "__main__":
    main()
