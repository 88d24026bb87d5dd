"""Importing public data into the catalog: JIGSAWS trials as scored sessions of a study."""

from __future__ import annotations

from pathlib import Path

from metrics import metrics_of
from metrics.bench.tracking import TRACK_FILE, save_track, track_frames
from metrics.datasets import jigsaws
from sessions.catalog import Catalog, CatalogError, metric_results, new_uid, now, stream_file
from sessions.catalog.lookups import participant_coded, session_with_uid
from sessions.catalog.models import Participant, Rating, Session
from sim.tracking.camera import Camera
from sim.tracking.video import read_video


def import_jigsaws(
    catalog: Catalog, kinematics_dir: str | Path, meta_file: str | Path, study_name: str
) -> int:
    """Load and score every trial first (any error leaves the catalog untouched), then store them in
    one transaction. Returns the number of trials imported."""
    trials = jigsaws.load(kinematics_dir, meta_file)
    folder = Path(kinematics_dir)
    nested = folder / "kinematics" / "AllGestures"
    folder = nested if nested.is_dir() else folder
    scored = [(trial, metrics_of(trial.to_streams())) for trial in trials]
    with catalog.session() as orm:
        study = catalog.study(orm, study_name, create=True, description="Imported from JIGSAWS")
        task = catalog.task(orm, f"jigsaws-{trials[0].task.lower()}", "jigsaws", {"task": trials[0].task})
        people: dict[str, Participant] = {}
        for trial, values in scored:
            uid = f"J-{study.id}-{trial.trial_id}"
            if session_with_uid(orm, uid) is not None:
                raise CatalogError(f"trial {trial.trial_id} is already in study {study_name!r}")
            person = people.get(trial.participant_id)
            if person is None:
                person = participant_coded(orm, study.id, trial.participant_id)
                if person is None:
                    person = catalog.add_participant(
                        orm,
                        study,
                        trial.participant_id,
                        level=trial.skill_label,
                        group_label=trial.skill_label,
                    )
                people[trial.participant_id] = person
            path = folder / f"{trial.trial_id}.txt"
            session = Session(
                uid=uid,
                participant_id=person.id,
                task_id=task.id,
                device="jigsaws",
                clock="recorded",
                trial=trial.trial,
                phase="practice",
                status="complete",
                started_at=now(),
                ended_at=now(),
                directory=str(path.resolve()),
            )
            orm.add(session)
            orm.flush()
            orm.add(stream_file(session.id, path))
            orm.add(
                Rating(
                    session_id=session.id,
                    rater="JIGSAWS",
                    instrument="GRS",
                    item="total",
                    score=trial.grs,
                    created_at=now(),
                )
            )
            for item, value in trial.grs_items.items():
                orm.add(
                    Rating(
                        session_id=session.id,
                        rater="JIGSAWS",
                        instrument="GRS",
                        item=item,
                        score=value,
                        created_at=now(),
                    )
                )
            orm.add_all(metric_results(session.id, values))
    return len(trials)


BENCH_DEVICE = "bench-video"


def import_bench_video(
    catalog: Catalog,
    home: Path,
    video: str | Path,
    camera_file: str | Path,
    study_name: str,
    participant_code: str,
    marker=None,
    progress=None,
) -> tuple[str, dict[str, float]]:
    """Track the needle holder in a bench-session video and add it as a scored session of a study.

    The tracked path (``track.parquet``) and the camera calibration are the session's files;
    its motion metrics are computed like any other session's (force and tissue metrics are
    NaN: a video has neither). Returns the session id and its metrics."""

    with catalog.session() as orm:  # names first: a typo must not cost a whole tracking run
        study = catalog.study(orm, study_name)
        person = catalog.participant(orm, study, participant_code)
        label = person.group_label
    camera = Camera.load(camera_file)
    frames, fps, _ = read_video(video)
    path = track_frames(frames, fps, camera, marker, progress)
    uid = new_uid()
    values = metrics_of(path.to_streams(uid, participant_code, label))
    folder = home / "sessions" / uid
    folder.mkdir(parents=True)
    try:
        save_track(path, folder / TRACK_FILE)
        camera.save(folder / "camera.json")
        with catalog.session() as orm:
            study = catalog.study(orm, study_name)
            person = catalog.participant(orm, study, participant_code)
            task = catalog.task(orm, "bench-suture", "bench", {"source": "video", "marker": repr(marker)})
            fields = {"participant_id": person.id, "task_id": task.id}

        def files_and_metrics(orm, session: Session) -> None:
            orm.add_all(stream_file(session.id, file) for file in sorted(folder.iterdir()))
            orm.add_all(metric_results(session.id, values))

        fields.update(
            uid=uid,
            device=BENCH_DEVICE,
            clock="recorded",
            trial=None,  # the participant's next bench trial
            phase="practice",
            status="complete",
            started_at=now(),
            ended_at=now(),
            directory=str(folder),
            error="",
        )
        catalog.add_session(fields, files_and_metrics)
    except BaseException:
        import shutil

        shutil.rmtree(folder, ignore_errors=True)
        raise
    return uid, values
