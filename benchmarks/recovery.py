"""Crash recovery figures of issue 23 (parts 3 and 4).

Run:  .venv/bin/python benchmarks/recovery.py [--kills 40] [--flips 60] [--load 2]

Kills: a child process records a 1 kHz session through the Python API (``SessionWriter``,
100 ms flush interval, paced on the monotonic clock) and notes each count of samples the
writer reports durable ("acknowledged"). It is killed with SIGKILL at a random moment 0-1.5 s
after recording starts (so about a tenth of the kills land before the first flush), and the
session is recovered twice from copies:

- as after a process crash (the ring on tmpfs is still there): loss = time of the kill minus
  the last recovered sample;
- as after a machine crash (the ring deleted first): loss from the journal alone.

Printed per case: every acknowledged sample kept (count of runs where not), loss median and
max, and whether the header told the truth (process crash: ``lost_at_most_s`` 0 and the
measured loss within one tick plus scheduling; machine crash: ``lost_at_most_s`` null, the
note says the extent is unknown, and ``unflushed_s`` is 0 as it must be with no ring).

Flips: a crashed session of 10 flushed batches x 100 rows; each of ``--flips`` copies gets one
random bit flipped in ``samples.arrows`` and is recovered: counted are the recoveries that
accepted an altered value (must be 0), those that cut the journal at the damaged batch, and
those that changed nothing (a flip in Arrow's alignment padding alters no value).
"""

from __future__ import annotations

import argparse
import os
import random
import shutil
import signal
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

import numpy as np

sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != Path(__file__).resolve().parent]

from recorder import COLUMN, SAMPLE_COLUMNS, RecorderError, SessionWriter, open_session, recover  # noqa: E402

CHILD = textwrap.dedent("""
    import sys, time, numpy as np
    from recorder import SessionWriter, COLUMN, SAMPLE_COLUMNS
    path, started, ack = sys.argv[1], sys.argv[2], sys.argv[3]
    writer = SessionWriter(path, {"participant": "crash"}, flush_interval=0.1)
    row = np.zeros(len(SAMPLE_COLUMNS))
    t0 = time.monotonic()
    with open(started, "w") as note:
        note.write(repr(t0))
    acked = 0
    with open(ack, "w") as log:
        i = 0
        while True:
            row[COLUMN["time"]] = i * 1e-3
            row[COLUMN["tool_x"]] = i
            writer.record(row)
            i += 1
            if writer.durable_samples != acked:
                acked = writer.durable_samples
                log.write(f"{acked}\\n"); log.flush()
            pause = t0 + i * 1e-3 - time.monotonic()
            if pause > 0:
                time.sleep(pause)
""")


def one_kill(folder: Path, rng: random.Random) -> dict:
    session, started, ack = folder / "session", folder / "started", folder / "ack"
    child = subprocess.Popen([sys.executable, "-c", CHILD, str(session), str(started), str(ack)])
    deadline = time.monotonic() + 60
    while not (started.exists() and started.read_text()) and time.monotonic() < deadline:
        time.sleep(0.001)
    t0 = float(started.read_text())
    time.sleep(rng.uniform(0.0, 1.5))
    killed = time.monotonic()
    os.kill(child.pid, signal.SIGKILL)
    child.wait()
    acknowledged = max([int(x) for x in ack.read_text().split()] or [0])
    machine = folder / "machine"
    shutil.copytree(session, machine)
    result = {"at": killed - t0, "acknowledged": acknowledged}
    for case, where in (("machine", machine), ("process", session)):
        if case == "machine":
            import json

            ring = json.loads((where / "header.json").read_text())["ring"]["file"]
            header_ring = Path(ring)
            saved = header_ring.read_bytes()  # the process case still needs it: put back after
            header_ring.unlink()
            header = recover(where)
            header_ring.write_bytes(saved)
        else:
            header = recover(where)
        x = open_session(where).samples.column("tool_x").to_numpy()
        loss = (killed - t0) - ((len(x) - 1) * 1e-3 if len(x) else -1e-3)
        contiguous = bool(np.array_equal(x, np.arange(len(x))))
        if case == "process":
            truthful = header["lost_at_most_s"] == 0.0 and loss < 0.02
        else:
            truthful = header["lost_at_most_s"] is None and "unknown" in header["loss_note"]
            truthful &= header["unflushed_s"] in (0.0, None)
        result[case] = {
            "kept_acknowledged": len(x) >= acknowledged and contiguous,
            "loss": loss,
            "truthful": truthful,
        }
    return result


def kills(count: int, seed: int) -> None:
    rng = random.Random(seed)
    results = []
    for k in range(count):
        with tempfile.TemporaryDirectory() as folder:
            results.append(one_kill(Path(folder), rng))
        print(f"  kill {k + 1}/{count} at {results[-1]['at']:.3f} s", file=sys.stderr, end="\r")
    before_first = sum(r["acknowledged"] == 0 for r in results)
    print(
        f"SIGKILL at {count} random moments 0-1.5 s into a 1 kHz recording "
        f"({before_first} before the first acknowledged flush)"
    )
    for case, label in (
        ("process", "process crash (ring on tmpfs kept)"),
        ("machine", "machine crash (journal only)"),
    ):
        losses = np.array([r[case]["loss"] for r in results])
        print(f"  {label}:")
        kept = sum(r[case]["kept_acknowledged"] for r in results)
        print(f"    acknowledged samples all kept in {kept}/{count} runs")
        print(f"    loss median {np.median(losses) * 1e3:.1f} ms, max {losses.max() * 1e3:.1f} ms")
        print(f"    header truthful in {sum(r[case]['truthful'] for r in results)}/{count} runs")


def flips(count: int, seed: int) -> None:
    with tempfile.TemporaryDirectory() as folder:
        original = Path(folder) / "original"
        writer = SessionWriter(original, {}, flush_interval=10.0)
        for batch in range(10):
            data = np.zeros((100, len(SAMPLE_COLUMNS)))
            index = np.arange(batch * 100, (batch + 1) * 100)
            data[:, COLUMN["time"]] = index * 1e-3
            data[:, COLUMN["tool_x"]] = index
            data[:, COLUMN["tool_qw"]] = 1.0
            writer.record_block(data)
            writer.flush()
        writer._stop.set()
        writer._thread.join()
        writer._sample_sink.close()
        writer._event_sink.close()
        Path(writer.header["ring"]["file"]).unlink()
        size = (original / "samples.arrows").stat().st_size
        rng = random.Random(seed)
        altered = cut = unchanged = refused = 0
        for flip in range(count):
            copy = Path(folder) / f"flip{flip}"
            shutil.copytree(original, copy)
            data = bytearray((copy / "samples.arrows").read_bytes())
            data[rng.randrange(size)] ^= 1 << rng.randrange(8)
            (copy / "samples.arrows").write_bytes(bytes(data))
            try:
                recover(copy)
            except RecorderError:
                refused += 1
                continue
            x = open_session(copy).samples.column("tool_x").to_numpy()
            altered += not np.array_equal(x, np.arange(len(x)))
            cut += len(x) < 1000
            unchanged += len(x) == 1000
    print(
        f"{count} single bit flips in a crashed session's samples journal: "
        f"{altered} altered values accepted, {cut} cut at the damaged batch, "
        f"{refused} refused (journal header hit), {unchanged} with every value intact"
    )


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--kills", type=int, default=40)
    parser.add_argument("--flips", type=int, default=60)
    parser.add_argument("--seed", type=int, default=23)
    parser.add_argument("--load", type=int, default=0, help="busy processes running meanwhile (load)")
    args = parser.parse_args()
    busy = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(args.load)]
    try:
        flips(args.flips, args.seed)
        print(f"(with {args.load} busy processes on {os.cpu_count()} cores)")
        kills(args.kills, args.seed)
    finally:
        for process in busy:
            process.kill()


if __name__ == "__main__":
    main()
