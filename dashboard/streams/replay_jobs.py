"""Replay videos rendered on request from the session page, one at a time, with progress.

A supervisor who opens a session without a replay can have it rendered here instead of running
`vascsim replay SESSION --vs-group experts`: the same inputs (the session, its task's tissue, the
study's expert sessions on the task) and the same file (``VASCSIM_HOME/replays/SESSION-vs.mp4``), so
the page and the CLI show the same video. Rendering runs in a worker thread (VTK renders offscreen,
PyAV encodes; both release the interpreter for most of the work); one job at a time, so a server
never renders two videos at once. A blind render for the rating page (``blind=True``) is a job of
its own (:func:`sessions.replaying.render_blind_replay`); its failure is reported without its cause,
which can name the session, and the cause goes to the server's log.
"""

from __future__ import annotations

import logging
import threading
from dataclasses import dataclass, field
from pathlib import Path

from metrics.replay.export import ReplaySettings, export_replay
from sessions.catalog import Catalog, WrongState
from sessions.replaying import render_blind_replay, replay_inputs

REPLAY_SIZE = (640, 360)
log = logging.getLogger("vascsim.dashboard")


@dataclass
class ReplayJob:
    uid: str
    blind: bool = False
    state: str = "rendering"  # rendering, done, failed
    done: int = 0
    total: int = 0
    error: str = ""
    thread: threading.Thread | None = field(default=None, repr=False)

    def as_dict(self) -> dict:
        return {"state": self.state, "frames_done": self.done, "frames": self.total, "error": self.error}


class ReplayJobs:
    """The server's replay renders: at most one running; finished ones remembered until restart."""

    def __init__(self, catalog: Catalog, home: Path) -> None:
        self.catalog, self.home = catalog, home
        self._jobs: dict[tuple[str, bool], ReplayJob] = {}
        self._lock = threading.Lock()

    def start(self, uid: str, blind: bool = False) -> ReplayJob:
        """Start rendering ``uid``'s replay against the experts, or its blind render (refused while
        another renders)."""

        with self._lock:
            busy = [j for j in self._jobs.values() if j.state == "rendering"]
            if busy:
                if (busy[0].uid, busy[0].blind) == (uid, blind):
                    return busy[0]
                which = "another replay" if busy[0].blind or blind else f"the replay of session {busy[0].uid}"
                raise WrongState(f"{which} is rendering; try again when it is done")
            job = ReplayJob(uid, blind)
            # checked before the job starts, and read once: the render uses them
            inputs = replay_inputs(self.catalog, self.home, uid, versus_group=None if blind else "experts")
            render = self._render_blind if blind else self._render
            job.thread = threading.Thread(target=render, args=(job, inputs), daemon=True)
            self._jobs[uid, blind] = job
            job.thread.start()
            return job

    def status(self, uid: str, blind: bool = False) -> ReplayJob | None:
        return self._jobs.get((uid, blind))

    def _render_blind(self, job: ReplayJob, inputs) -> None:

        def advance(done: int, total: int) -> None:
            job.done, job.total = done, total

        try:
            settings = ReplaySettings(size=REPLAY_SIZE)
            render_blind_replay(self.catalog, self.home, job.uid, settings, advance, inputs)
            job.state = "done"
        except Exception:  # the rater is told it failed, not why (the cause can name the session)
            log.exception("blind render of session %s failed", job.uid)
            job.state, job.error = "failed", "the blind render failed; the server's log says why"

    def _render(self, job: ReplayJob, inputs) -> None:

        recorded, tissue, experts = inputs

        def advance(done: int, total: int) -> None:
            job.done, job.total = done, total

        target = self.home / "replays" / f"{job.uid}-vs.mp4"
        target.parent.mkdir(parents=True, exist_ok=True)
        part = target.with_name(f".{target.stem}.part.mp4")
        try:
            export_replay(recorded, tissue, part, experts, ReplaySettings(size=REPLAY_SIZE), progress=advance)
            part.replace(target)  # the page never sees a half-written video
            job.state = "done"
        except Exception as error:  # reported on the page; the server carries on
            job.state, job.error = "failed", f"{type(error).__name__}: {error}"
            part.unlink(missing_ok=True)
