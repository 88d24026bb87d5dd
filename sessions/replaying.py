"""`vascsim replay`: find a session, its task's tissue model and its expert reference in the catalog."""

from __future__ import annotations

from pathlib import Path

from metrics.replay.export import ReplaySettings, export_replay
from recorder import open_session
from sessions.catalog import Catalog, CatalogError, NotFound
from sessions.catalog.lookups import group_sessions, latest_session_of, session_with_uid
from sessions.catalog.models import Session
from sessions.config import cache_dir
from sessions.scoring.review import experts_on_task
from sessions.status import SCORABLE
from sessions.tasks import known_task, task_spec, tissue_for

REPLAYABLE = SCORABLE


def _replayable(row: Session) -> None:
    if row.device in ("jigsaws", "bench-video") or row.task.scenario in ("jigsaws", "bench"):
        raise CatalogError(
            f"session {row.uid} was imported (a tool path only); it has no 3-D scene to replay"
        )
    if row.status not in REPLAYABLE:
        raise CatalogError(f"session {row.uid} is {row.status}; only complete or recovered sessions replay")
    if not known_task(row.task.name):
        raise CatalogError(f"session {row.uid} ran task {row.task.name!r}, which this vascsim cannot rebuild")


def _versus_session(catalog: Catalog, orm, versus: str, study_id: int, task_id: int) -> Session:
    """``--vs``: a session id, or a participant code of the session's study meaning that
    participant's latest replayable session on the same task."""
    found = session_with_uid(orm, versus)
    if found is not None:
        return found
    latest = latest_session_of(orm, study_id, versus, task_id, REPLAYABLE)
    if latest is None:
        raise NotFound("session or participant with a session on this task", versus)
    return latest


def replay_inputs(
    catalog: Catalog, home: Path, uid: str, versus: str | None = None, versus_group: str | None = None
):
    """(session, tissue model, expert sessions) as recorder sessions, checked for a replay."""
    if versus and versus_group:
        raise CatalogError("compare with one session or one group, not both")
    with catalog.session() as orm:
        row = catalog.recorded_session(orm, uid)
        _replayable(row)
        task, directory, study_id = row.task.name, row.directory, row.participant.study_id
        expert_dirs: list[str] = []
        if versus:
            other = _versus_session(catalog, orm, versus, study_id, row.task_id)
            _replayable(other)
            if other.task.name != task:
                raise CatalogError(
                    f"session {versus} ran task {other.task.name!r}, not {task!r}; they cannot be aligned"
                )
            expert_dirs.append(other.directory)
        if versus_group:
            labels = {versus_group, versus_group.rstrip("s")}  # "experts" finds group "expert"
            rows = group_sessions(orm, study_id, labels, row.task_id, REPLAYABLE, uid)
            if not rows:
                raise CatalogError(
                    f"no complete sessions of group {versus_group!r} on task {task!r} in this session's study"
                )
            expert_dirs += [r.directory for r in rows]
    tissue = tissue_for(task_spec(task), cache_dir(home))
    return open_session(directory), tissue, [open_session(d) for d in expert_dirs]


def blind_replay_path(home: Path, uid: str) -> Path:
    """Where session ``uid``'s blind render lives (served to raters only under an opaque address)."""
    return home / "replays" / "blind" / f"{uid}.mp4"


def render_blind_replay(
    catalog: Catalog, home: Path, uid: str, settings=None, progress=None, inputs=None
) -> Path:
    """Render session ``uid`` for blinded rating (:mod:`metrics.replay.blind`: the session alone, no
    identity, ghost, colours that judge, or readouts) to :func:`blind_replay_path` (the video writer
    moves the file into place only once it is whole)."""
    from dataclasses import replace

    settings = replace(settings or ReplaySettings(), blind=True, mode="ghost")
    recorded, tissue, _ = inputs if inputs is not None else replay_inputs(catalog, home, uid)
    return export_replay(recorded, tissue, blind_replay_path(home, uid), [], settings, progress=progress).path


def replay_against_experts(catalog: Catalog, home: Path, uid: str) -> Path:
    """Render session ``uid``'s replay against its study's experts on the same task (the most typical
    one ghosted in; the trainee alone when there is none) to ``home/replays/UID-vs.mp4``."""

    with catalog.session() as orm:
        row = catalog.recorded_session(orm, uid)
        study, task = row.participant.study.name, row.task.name
    group = "expert" if experts_on_task(catalog, study, task) else None
    recorded, tissue, experts = replay_inputs(catalog, home, uid, versus_group=group)
    target = home / "replays" / f"{uid}-vs.mp4"
    return export_replay(recorded, tissue, target, experts, ReplaySettings()).path
