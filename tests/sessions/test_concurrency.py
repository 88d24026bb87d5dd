"""Concurrent first use and concurrent runs (issue 23, part 6), on SQLite and PostgreSQL."""

import multiprocessing

import pytest
from alembic import command
from sqlalchemy import select, text

from sessions.catalog import Catalog, CatalogError, alembic_config, make_engine, now
from sessions.catalog.models import Participant, Session, Study, Task


def _first_use(url, start, index, results):
    start.wait(60)
    try:
        catalog = Catalog(url)  # every process migrates the new catalog "first"
        with catalog.session() as orm:
            catalog.study(orm, f"study-{index}", create=True)
        catalog.close()
        results.put((index, "ok"))
    except BaseException as error:  # the report is the assertion: name what broke
        results.put((index, f"{type(error).__name__}: {error}"))


def _together(target, url, count, *extra):
    context = multiprocessing.get_context("spawn")
    start, results = context.Event(), context.Queue()
    workers = [context.Process(target=target, args=(url, start, k, results, *extra)) for k in range(count)]
    for worker in workers:
        worker.start()
    start.set()
    outcome = dict(results.get(timeout=240) for _ in workers)
    for worker in workers:
        worker.join(60)
    return outcome


@pytest.mark.slow
def test_processes_opening_a_new_catalog_at_once_all_see_it_migrated(catalog_url, open_catalog):
    outcome = _together(_first_use, catalog_url, 8)
    assert outcome == {k: "ok" for k in range(8)}
    catalog = open_catalog(catalog_url)
    with catalog.session() as orm:
        assert sorted(orm.scalars(select(Study.name))) == sorted(f"study-{k}" for k in range(8))


def _runs(url, start, index, results, participant_id, task_id, count):
    catalog = Catalog(url)
    start.wait(60)
    try:
        trials = []
        for k in range(count):
            row = catalog.add_session(
                {
                    "uid": f"S-{index}-{k}",
                    "participant_id": participant_id,
                    "task_id": task_id,
                    "device": "scripted",
                    "clock": "simulated",
                    "trial": None,
                    "phase": "practice",
                    "status": "running",
                    "started_at": now(),
                    "directory": f"/nowhere/{index}/{k}",
                }
            )
            trials.append(row.trial)
        results.put((index, trials))
    except BaseException as error:
        results.put((index, f"{type(error).__name__}: {error}"))
    finally:
        catalog.close()


def _participant_and_task(catalog):
    with catalog.session() as orm:
        study = catalog.study(orm, "s", create=True)
        person = catalog.add_participant(orm, study, "T01", level="trainee")
        task = catalog.task(orm, "wall-stitch", "wall-stitch", {})
        return person.id, task.id


@pytest.mark.slow
def test_parallel_runs_for_one_participant_get_distinct_trial_numbers(catalog_url, open_catalog):
    catalog = open_catalog(catalog_url)
    person, task = _participant_and_task(catalog)
    outcome = _together(_runs, catalog_url, 3, person, task, 12)
    assert all(isinstance(trials, list) for trials in outcome.values()), outcome
    every = sorted(t for trials in outcome.values() for t in trials)
    assert every == list(range(1, 37))
    for trials in outcome.values():
        assert trials == sorted(trials)  # each loop's own runs in order


def test_an_explicit_trial_that_exists_is_refused(catalog_url, open_catalog):
    catalog = open_catalog(catalog_url)
    person, task = _participant_and_task(catalog)
    fields = {
        "participant_id": person,
        "task_id": task,
        "device": "scripted",
        "clock": "simulated",
        "trial": 3,
        "status": "complete",
        "started_at": now(),
        "directory": "/x",
    }
    catalog.add_session(dict(fields, uid="S-a"))
    with pytest.raises(CatalogError, match="trial 3 of this participant on this task is already catalogued"):
        catalog.add_session(dict(fields, uid="S-b"))
    assert catalog.add_session(dict(fields, uid="S-c", trial=None)).trial == 4


def test_the_migration_renumbers_trials_that_earlier_races_duplicated(catalog_url):
    engine = make_engine(catalog_url)
    with engine.begin() as connection:
        command.upgrade(alembic_config(connection), "0003")
        connection.execute(
            text("INSERT INTO studies (id, name, description, created_at) VALUES (1, 's', '', :t)"),
            {"t": now()},
        )
        connection.execute(
            text(
                "INSERT INTO participants (id, study_id, code, level, group_label, handedness, synthetic, "
                "created_at) VALUES (1, 1, 'T01', 'trainee', 'trainee', 'right', false, :t)"
            ),
            {"t": now()},
        )
        connection.execute(
            text("INSERT INTO tasks (id, name, scenario, parameters) VALUES (1, 'w', 'w', '{}')")
        )
        for uid, trial, minute in (("a", 1, 0), ("b", 1, 1), ("c", 2, 2), ("d", 2, 3)):
            connection.execute(
                text(
                    "INSERT INTO sessions (uid, participant_id, task_id, device, clock, trial, phase, "
                    "status, "
                    "started_at, directory, error) VALUES (:u, 1, 1, 'scripted', 'simulated', :trial, "
                    "'practice', 'complete', :t, '/x', '')"
                ),
                {"u": uid, "trial": trial, "t": now().replace(minute=minute)},
            )
    engine.dispose()
    catalog = Catalog(catalog_url)
    with catalog.session() as orm:
        assert list(orm.execute(select(Session.uid, Session.trial).order_by(Session.uid))) == [
            ("a", 1),
            ("b", 2),
            ("c", 3),
            ("d", 4),
        ]
        assert orm.scalar(select(Participant.code)) == "T01" and orm.scalar(select(Task.name)) == "w"
    catalog.close()


def _first_runs_of_tasks(url, start, index, results, names, barrier):
    catalog = Catalog(url)
    start.wait(60)
    try:
        ids = []
        for name in names:  # all four at the same task's first run each time
            barrier.wait(60)
            ids.append(catalog.ensure_task(name, "wall-stitch", {}))
        results.put((index, ids))
    except BaseException as error:
        results.put((index, f"{type(error).__name__}: {error}"))
    finally:
        catalog.close()


@pytest.mark.slow
def test_first_runs_of_a_new_task_at_once_share_one_task_row(catalog_url, open_catalog):
    """Issue 45, seen 5: creating a task row was select-then-insert: four processes behind a barrier
    raised IntegrityError (UNIQUE tasks.name) in 4 of 6 rounds, reached from the first `vascsim run`
    of a task. Twelve new tasks, four processes creating each at once."""
    open_catalog(catalog_url)  # migrated once, so the race is the task rows', not the schema's
    names = [f"task-{k}" for k in range(12)]
    barrier = multiprocessing.get_context("spawn").Barrier(4)
    outcome = _together(_first_runs_of_tasks, catalog_url, 4, names, barrier)
    assert all(isinstance(ids, list) for ids in outcome.values()), outcome
    assert len({tuple(ids) for ids in outcome.values()}) == 1  # everyone got the same six rows
    catalog = open_catalog(catalog_url)
    with catalog.session() as orm:
        assert sorted(orm.scalars(select(Task.name))) == sorted(names)
