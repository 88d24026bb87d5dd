"""Issue 27's scale-out figure: scoring 1,000 demo-sized sessions, two Dask workers against one process.

Run:  .venv/bin/python benchmarks/scoring.py [--sessions 1000] [--workers 2] [--repeats 1]

A reduced demo (16 interrupted-stitch sessions through the real simulator and recorder) is run once;
its session folders are copied until the catalog holds ``--sessions`` sessions (each a catalogued
session with its own id and folder: what scoring reads is the same as for recorded ones). Each
repeat scores all of them in this process, then on a local Dask cluster of ``--workers`` single-
threaded worker processes (`vascsim score --workers N`'s path: workers compute, this process
stores), and prints the wall time, the cost per session and the ratio. The tissue model is built
once per worker (its factorisation from the disk cache), which the per-session cost includes.
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
import time
from pathlib import Path

sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != Path(__file__).resolve().parent]

import numpy as np  # noqa: E402
from sqlalchemy import select  # noqa: E402

from sessions.catalog import Catalog, new_uid  # noqa: E402
from sessions.catalog.models import Participant, Session  # noqa: E402
from sessions.demo import DEMO_STUDY, DemoSize, run_demo  # noqa: E402
from sessions.scoring.workers import score_sessions  # noqa: E402


def build(home: Path, count: int) -> tuple[Catalog, list[str]]:
    catalog = Catalog(f"sqlite:///{home / 'catalog.sqlite'}")
    run_demo(catalog, home, DemoSize(2, 2, 3, 3, True, closures=False))
    with catalog.session() as orm:
        rows = orm.execute(
            select(Session, Participant.code).join(Participant, Session.participant_id == Participant.id)
        ).all()
        originals = [
            (s.directory, s.participant_id, s.task_id, s.device, s.clock, s.phase, s.started_at, s.ended_at)
            for s, _ in rows
        ]
        uids = [s.uid for s, _ in rows]
        top = max(s.trial for s, _ in rows)
    copies = count - len(uids)
    for k in range(copies):
        directory, participant, task, device, clock, phase, started, ended = originals[k % len(originals)]
        uid = new_uid()
        target = home / "sessions" / uid
        shutil.copytree(directory, target)
        catalog.add_session(
            dict(
                uid=uid,
                participant_id=participant,
                task_id=task,
                device=device,
                clock=clock,
                trial=top + 1 + k,
                phase=phase,
                status="complete",
                started_at=started,
                ended_at=ended,
                directory=str(target),
            )
        )
        uids.append(uid)
    return catalog, uids


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sessions", type=int, default=1000)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--repeats", type=int, default=1)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        home = Path(folder)
        catalog, uids = build(home, args.sessions)
        print(f"{len(uids)} sessions of study {DEMO_STUDY} catalogued under {home}", flush=True)
        alone, spread = [], []
        for _ in range(args.repeats):
            start = time.perf_counter()
            score_sessions(catalog, uids, home)
            alone.append(time.perf_counter() - start)
            start = time.perf_counter()
            score_sessions(catalog, uids, home, workers=args.workers)
            spread.append(time.perf_counter() - start)
            print(f"  one process {alone[-1]:.1f} s; {args.workers} workers {spread[-1]:.1f} s", flush=True)
        one, many = float(np.median(alone)), float(np.median(spread))
        print(
            f"[scoring] {len(uids)} sessions: one process {one:.1f} s "
            f"({1e3 * one / len(uids):.0f} ms a session); {args.workers} Dask workers {many:.1f} s "
            f"({1e3 * many / len(uids):.0f} ms a session, cluster start included); "
            f"speed-up {one / many:.2f}x (median of {args.repeats})"
        )
        catalog.close()


if __name__ == "__main__":
    main()
