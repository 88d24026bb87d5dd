"""xAPI statements to a real Learning Record Store (ralph, started here on 127.0.0.1): stored and read
back through the xAPI query API, idempotent re-push, an LRS stopped mid-push loses nothing, a
refused statement is a clear error, a changed statement voids the one it replaces."""

from __future__ import annotations

import json
import os
import socket
import subprocess
import time
from pathlib import Path

import httpx
import pytest
from click.testing import CliRunner
from sqlalchemy import func, select, update

from metrics.session.registry import REGISTRY_VERSION
from sessions.catalog import Catalog
from sessions.catalog.models import MetricResult, Session
from sessions.cli import main
from sessions.demo import DEMO_STUDY
from sessions.exchange.lrs import LrsEndpoint, LrsRejected, LrsUnreachable, Outbox, push, read_statements
from sessions.exchange.xapi import (
    CMI5_CATEGORY,
    CMI5_MASTERY,
    MOVEON_CATEGORY,
    Statement,
    XapiSettings,
    study_statements,
)

ROOT = Path(__file__).resolve().parents[2]
RALPH = ROOT / ".venv-lrs" / "bin"
HOME_PAGE = "https://sim.hospital.test"
KEY, SECRET = "vascsim", "lrs-secret"


class Ralph:
    """ralph's LRS in its own process, stoppable and restartable on the same port and store."""

    def __init__(self, folder: Path) -> None:
        self.environment = dict(
            os.environ,
            RALPH_APP_DIR=str(folder / "app"),
            RALPH_RUNSERVER_BACKEND="fs",
            RALPH_BACKENDS__LRS__FS__DEFAULT_DIRECTORY_PATH=str(folder / "store"),
        )
        (folder / "store").mkdir(parents=True)
        self.log = folder / "server.log"
        # the basic-auth credentials file must exist before the server starts
        subprocess.run(
            [RALPH / "ralph", "auth", "-u", KEY, "-p", SECRET, "-s", "all", "-A", KEY, HOME_PAGE, "-w"],
            env=self.environment,
            check=True,
            capture_output=True,
        )
        with socket.socket() as probe:
            probe.bind(("127.0.0.1", 0))
            self.port = probe.getsockname()[1]
        self.url = f"http://127.0.0.1:{self.port}/xAPI/"
        self.process: subprocess.Popen | None = None

    def start(self) -> None:
        with open(self.log, "ab") as log:
            self.process = subprocess.Popen(
                [RALPH / "python", ROOT / "tests" / "lrs_server.py", str(self.port)],
                env=self.environment,
                stdout=log,
                stderr=subprocess.STDOUT,
            )
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            try:
                if httpx.get(f"http://127.0.0.1:{self.port}/__heartbeat__", timeout=1).status_code == 200:
                    return
            except httpx.HTTPError:
                time.sleep(0.2)
        raise RuntimeError(f"ralph did not start: {self.log.read_text()[-2000:]}")

    def stop(self) -> None:
        if self.process is not None:
            self.process.terminate()
            self.process.wait(20)
            self.process = None


@pytest.fixture
def ralph(tmp_path):
    server = Ralph(tmp_path / "ralph")
    server.start()
    yield server
    server.stop()


def _statements(catalog) -> list[Statement]:
    return study_statements(catalog, DEMO_STUDY, XapiSettings(HOME_PAGE))


def test_statements_follow_xapi_and_cmi5(demo_catalog):
    catalog, _ = demo_catalog
    statements = _statements(catalog)
    again = _statements(catalog)
    assert [s.id for s in statements] == [s.id for s in again]  # deterministic ids
    assert len({s.id for s in statements}) == len(statements)
    with catalog.session() as orm:
        sessions = orm.scalar(select(func.count(Session.id)))
    verbs = [s.body["verb"]["display"]["en-US"] for s in statements]
    assert verbs.count("attempted") == verbs.count("completed") == sessions  # every demo session completed
    for statement in statements:
        body = statement.body
        account = body["actor"]["account"]
        assert set(body["actor"]) == {"objectType", "account"}  # pseudonymous: never a name
        assert account["homePage"] == HOME_PAGE and account["name"].startswith(f"{DEMO_STUDY}/")
        categories = [c["id"] for c in body["context"]["contextActivities"].get("category", [])]
        kind = body["verb"]["display"]["en-US"]
        if kind in ("completed",) or (
            kind in ("passed", "failed") and "/retention" not in body["object"]["id"]
        ):
            assert CMI5_CATEGORY in categories and MOVEON_CATEGORY in categories
            assert body["result"]["duration"].startswith("PT")
        if kind in ("passed", "failed") and "/retention" not in body["object"]["id"]:
            score, mastery = body["result"]["score"], body["context"]["extensions"][CMI5_MASTERY]
            # cmi5: passed exactly when the scaled score reaches the mastery score
            assert (score["scaled"] >= mastery) == (kind == "passed") == body["result"]["success"]
            assert score["raw"] == round(score["scaled"] * score["max"])
            metric = body["result"]["extensions"]["https://vascsim.org/xapi/metrics/entry_to_target"]
            assert metric["unit"] == "mm" and metric["registry_version"] == REGISTRY_VERSION
        if kind == "attempted":
            assert CMI5_CATEGORY not in categories  # not a cmi5-defined statement
    retention = [s for s in statements if s.body["object"]["id"].endswith("/retention")]
    assert len(retention) == 3  # the three trainees' retention results, their own statements


def test_statements_are_stored_and_read_back_once(demo_catalog, ralph, tmp_path):
    catalog, _ = demo_catalog
    statements = _statements(catalog)
    endpoint = LrsEndpoint(ralph.url, KEY, SECRET)
    result = push(statements, endpoint, tmp_path)
    assert result.sent == len(statements) and result.spooled == 0
    stored = {s["id"]: s for s in read_statements(endpoint, {"limit": "20"})}  # pages through "more"
    assert set(stored) == {s.id for s in statements}
    one = next(s for s in statements if s.body["verb"]["display"]["en-US"] == "failed")
    assert stored[one.id]["result"]["score"] == one.body["result"]["score"]
    agent = json.dumps(one.body["actor"])
    mine = read_statements(endpoint, {"agent": agent})
    assert mine and all(s["actor"]["account"] == one.body["actor"]["account"] for s in mine)
    # pushed again: the ledger sends nothing; sent again regardless: the LRS keeps one of each
    assert push(statements, endpoint, tmp_path).sent == 0
    assert push(statements, endpoint, tmp_path, resend=True).sent == len(statements)
    assert len(read_statements(endpoint)) == len(statements)


def test_an_lrs_stopped_mid_push_loses_nothing(demo_catalog, ralph, tmp_path):
    catalog, _ = demo_catalog
    statements = _statements(catalog)
    endpoint = LrsEndpoint(ralph.url, KEY, SECRET)
    answered = []

    def stop_after_the_first_batch(response):
        answered.append(response.status_code)
        if len(answered) == 1:
            ralph.stop()

    with httpx.Client(timeout=5, event_hooks={"response": [stop_after_the_first_batch]}) as client:
        with pytest.raises(LrsUnreachable, match="stay spooled"):
            push(statements, endpoint, tmp_path, client=client)
    outbox = Outbox(tmp_path / "lrs" / endpoint.slug)
    assert answered == [200] and outbox.pending() == len(statements) - 50  # the first batch of 50 went
    ralph.start()
    result = push(statements, endpoint, tmp_path)
    assert result.sent == len(statements) - 50 and outbox.pending() == 0
    stored = read_statements(endpoint)
    assert sorted(s["id"] for s in stored) == sorted(s.id for s in statements)  # each exactly once


def test_a_refused_statement_is_a_clear_error_and_kept_aside(demo_catalog, ralph, tmp_path):
    catalog, _ = demo_catalog
    good = _statements(catalog)[0]
    body = {k: v for k, v in good.body.items() if k != "object"}  # a statement must have an object
    bad = Statement("bad|attempted", {**body, "id": "7c3c2a4e-6a36-4f8e-9d59-1d2f00000001"})
    endpoint = LrsEndpoint(ralph.url, KEY, SECRET)
    with pytest.raises(LrsRejected, match=r"refused 1 statements \(4\d\d: .*object.*kept in .*rejected"):
        push([bad], endpoint, tmp_path)
    outbox = Outbox(tmp_path / "lrs" / endpoint.slug)
    assert outbox.pending() == 0 and len(list(outbox.rejected.glob("*.json"))) == 1
    assert push([good], endpoint, tmp_path).sent == 1  # the refusal does not block what follows
    wrong = LrsEndpoint(ralph.url, KEY, "not the secret")
    with pytest.raises(LrsRejected, match="401"):
        push([good], wrong, tmp_path / "other")


def test_a_rescored_session_voids_the_statement_it_replaces(tmp_path, copy_demo, ralph):
    catalog = Catalog(copy_demo(tmp_path / "home"))
    endpoint = LrsEndpoint(ralph.url, KEY, SECRET)
    before = _statements(catalog)
    push(before, endpoint, tmp_path)
    with catalog.session() as orm:
        uid, session_id = orm.execute(select(Session.uid, Session.id).order_by(Session.id).limit(1)).one()
        orm.execute(
            update(MetricResult)
            .where(MetricResult.session_id == session_id, MetricResult.metric == "path_length")
            .values(value=MetricResult.value * 2)
        )
    after = _statements(catalog)
    known = {s.key: s.id for s in before}
    changed = {s.key for s in after if known.get(s.key) != s.id}
    assert f"{uid}|completed" in changed
    result = push(after, endpoint, tmp_path)
    assert result.voided >= 1 and result.sent == len(changed) + result.voided
    voids = [
        s for s in read_statements(endpoint) if s["verb"]["id"] == "http://adlnet.gov/expapi/verbs/voided"
    ]
    old = next(s.id for s in before if s.key == f"{uid}|completed")
    assert old in {v["object"]["id"] for v in voids}
    catalog.close()


def test_cli_push_dry_run_and_errors(demo_catalog, ralph, monkeypatch):
    catalog, home = demo_catalog
    monkeypatch.setenv("VASCSIM_HOME", str(home))
    monkeypatch.setenv("VASCSIM_DATABASE_URL", catalog.url)
    runner = CliRunner()
    dry = runner.invoke(
        main, ["lrs", "push", "--study", DEMO_STUDY, "--home-page", HOME_PAGE, "--dry-run", "--json"]
    )
    assert dry.exit_code == 0, dry.output
    assert {s["id"] for s in json.loads(dry.stdout)} == {s.id for s in _statements(catalog)}
    missing = runner.invoke(main, ["lrs", "push", "--study", DEMO_STUDY, "--dry-run"])
    assert (
        missing.exit_code == 1 and "no --home-page: give it, or set VASCSIM_LRS_HOME_PAGE" in missing.output
    )
    monkeypatch.setenv("VASCSIM_LRS_SECRET", SECRET)  # a secret kept out of the process list
    args = [
        "lrs",
        "push",
        "--study",
        DEMO_STUDY,
        "--home-page",
        HOME_PAGE,
        "--endpoint",
        ralph.url,
        "--key",
        KEY,
    ]
    sent = runner.invoke(main, args)
    assert sent.exit_code == 0 and sent.stdout.startswith("sent ") and "0 already there" in sent.stdout
    assert "0 already there" not in runner.invoke(main, args).stdout
    ralph.stop()
    extra = runner.invoke(main, [*args, "--resend"])
    assert extra.exit_code == 1 and "did not answer" in extra.output and extra.output.count("\n") == 1


def test_a_study_set_to_push_does_so_whenever_a_session_is_scored(tmp_path, copy_demo, ralph, monkeypatch):
    home = tmp_path / "home"
    url = copy_demo(home)
    monkeypatch.setenv("VASCSIM_HOME", str(home))
    monkeypatch.setenv("VASCSIM_DATABASE_URL", url)
    monkeypatch.setenv("VASCSIM_LRS_SECRET", SECRET)
    runner = CliRunner()
    refused = runner.invoke(
        main,
        [
            "lrs",
            "configure",
            "--study",
            DEMO_STUDY,
            "--endpoint",
            "ftp://x",
            "--key",
            KEY,
            "--home-page",
            HOME_PAGE,
        ],
    )
    assert refused.exit_code == 1 and "http(s)" in refused.output
    args = ["lrs", "configure", "--study", DEMO_STUDY, "--endpoint", ralph.url, "--key", KEY]
    configured = runner.invoke(main, [*args, "--home-page", HOME_PAGE, "--auto"])
    assert configured.exit_code == 0 and "pushed whenever a session is scored" in configured.output
    assert SECRET not in (home / "lrs" / "studies.json").read_text()  # the secret is never stored
    catalog = Catalog(url)
    with catalog.session() as orm:
        uid = orm.scalar(select(Session.uid).order_by(Session.id).limit(1))
    scored = runner.invoke(main, ["score", uid, "--json"])
    assert scored.exit_code == 0 and json.loads(scored.stdout)[uid]  # stdout stays JSON
    assert f"LRS: sent {len(_statements(catalog))} statement(s) of study {DEMO_STUDY}" in scored.stderr
    again = runner.invoke(main, ["score", uid])  # the same values: nothing new to send
    assert "LRS: sent 0 statement(s)" in again.stderr
    ralph.stop()  # a trainee practises while the LRS is away: the session is kept, its statements spooled
    offline = runner.invoke(
        main, ["run", "--study", DEMO_STUDY, "--participant", "T01", "--task", "interrupted-stitch"]
    )
    assert offline.exit_code == 0 and "complete and scored" in offline.stdout
    assert "LRS: the LRS at" in offline.stderr and "stay spooled" in offline.stderr
    ralph.start()
    back = runner.invoke(main, ["lrs", "push", "--study", DEMO_STUDY])  # the study's configured LRS
    assert back.exit_code == 0 and back.stdout.startswith("sent ")
    endpoint = LrsEndpoint(ralph.url, KEY, SECRET)
    assert {s["id"] for s in read_statements(endpoint)} >= {s.id for s in _statements(catalog)}
    catalog.close()
