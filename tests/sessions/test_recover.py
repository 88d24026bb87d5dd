"""Crash recovery through the catalog: kill -9 a live session, then `vascsim recover` it."""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from click.testing import CliRunner

from recorder import SessionWriter, open_session
from recorder.layout import SAMPLES_JOURNAL
from recorder.writer import sha256_of
from sessions.catalog import Catalog
from sessions.cli import main
from sessions.running.streaming import StreamTarget, catalog_status, send_leftovers
from tests.processes import descendants, still_running
from tests.recorder.test_recorder import rows
from tests.recorder.test_remote import free_port, start_server

# the real-time clock needs the machine to itself (scripts/test runs these after the rest)
pytestmark = pytest.mark.exclusive


def invoke(*args):
    return CliRunner().invoke(main, list(args))


def killed_run(home: Path, *extra: str) -> Path:
    """`vascsim run --realtime --duration 60` (and ``extra`` options) killed with SIGKILL once its
    journal holds 200 kB, and every process it started gone; returns the journal."""
    assert invoke("studies", "add", "s").exit_code == 0
    assert invoke("participants", "add", "P1", "--study", "s").exit_code == 0
    child = subprocess.Popen(
        [str(Path(sys.executable).with_name("vascsim")), "run", "--study", "s", "--participant", "P1",
         "--realtime", "--duration", "60", *extra],
        env=dict(os.environ),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )  # fmt: skip
    deadline = time.monotonic() + 60
    journal = None
    while time.monotonic() < deadline:
        journals = list((home / "sessions").glob("*/samples.arrows")) if (home / "sessions").exists() else []
        if journals and journals[0].stat().st_size > 200_000:
            journal = journals[0]
            break
        time.sleep(0.05)
    tree = descendants(child.pid)
    os.kill(child.pid, signal.SIGKILL)
    child.wait()
    assert journal is not None, "the live session never wrote its journal"
    # issue 45, seen 13: killed runs left their column worker and display process behind for ever
    assert tree and still_running(tree, within=10.0) == []
    return journal


@pytest.mark.slow
def test_a_killed_session_is_recovered_scored_and_checksummed(home):
    journal = killed_run(home)
    running = json.loads(invoke("sessions", "list", "--status", "running", "--json").stdout)
    assert len(running) == 1
    uid = running[0]["session"]
    assert journal.parent.name == uid
    # scoring a session that is still marked running is refused
    refused = invoke("score", uid)
    assert refused.exit_code == 1 and "only complete or recovered sessions are scored" in refused.output
    result = invoke("recover", uid)
    assert result.exit_code == 0, result.output
    assert f"recovered {uid}:" in result.output
    shown = json.loads(invoke("sessions", "show", uid, "--json").stdout)
    assert shown["status"] == "recovered"
    assert shown["metrics"]["task_time"] > 0.2
    for record in shown["files"]:
        assert sha256_of(journal.parent / record["name"]) == record["sha256"]
    assert not journal.exists()
    again = invoke("recover", uid)
    assert again.exit_code == 1 and f"session {uid} is recovered" in again.output


@pytest.mark.slow
def test_a_killed_streamed_session_is_closed_centrally_once_recovered(home, tmp_path, monkeypatch):
    """Issue 42, seen in session 30: a station that crashed while streaming left its central copy
    "recording" for ever (the dashboard listed it live), even after the session was recovered on
    the station. The next streamed session now closes it as recovered, with what the station sent;
    a session still running on the station is left alone."""
    port = free_port()
    server = start_server(tmp_path / "central", port)
    monkeypatch.setenv("VASCSIM_STATION_TOKEN", "secret-station-a")
    target = StreamTarget(f"http://127.0.0.1:{port}", "secret-station-a")
    catalog = Catalog(os.environ["VASCSIM_DATABASE_URL"])
    try:
        journal = killed_run(home, "--stream-to", target.url)
        uid = journal.parent.name
        central = tmp_path / "central" / "station-a" / uid
        assert (central / SAMPLES_JOURNAL).exists()  # it was recording there when the station died
        status_of = catalog_status(catalog)
        assert send_leftovers(target, home, status_of) == [
            f"session {uid} is still recording here, or a crash left it unrecovered"
        ]
        assert (central / SAMPLES_JOURNAL).exists() and (home / "spool" / uid).is_dir()
        assert invoke("recover", uid).exit_code == 0
        assert send_leftovers(target, home, status_of) == []
    finally:
        catalog.close()
        server.kill()
        server.wait()
    assert not (home / "spool" / uid).exists() and not (central / SAMPLES_JOURNAL).exists()
    copy, local = open_session(central), open_session(journal.parent)
    assert copy.header["status"] == local.header["status"] == "recovered"
    sent = copy.samples.num_rows
    assert 0 < sent <= local.samples.num_rows
    assert copy.samples.column("time").to_pylist() == local.samples.column("time").to_pylist()[:sent]


def test_recover_an_uncatalogued_directory(tmp_path, home):
    session = tmp_path / "s"
    writer = SessionWriter(session, {}, flush_interval=10.0)
    for row in rows(300):
        writer.record(row)
    writer.flush()
    writer._stop.set()  # a crash: no close(), no end-of-stream marker
    writer._thread.join()
    writer._sample_sink.close()
    writer._event_sink.close()
    result = invoke("recover", str(session))
    assert result.exit_code == 0, result.output
    assert "300 samples kept (up to 0.299 s)" in result.output
    again = invoke("recover", str(session))
    assert again.exit_code == 1 and "has no journal to recover" in again.output
    unknown = invoke("recover", "S-NOPE")
    assert unknown.exit_code == 1 and "no session 'S-NOPE'" in unknown.output
