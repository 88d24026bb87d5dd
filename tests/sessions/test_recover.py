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

from recorder import SessionWriter
from recorder.writer import sha256_of
from sessions.cli import main
from tests.processes import descendants, still_running
from tests.recorder.test_recorder import rows

# the real-time clock needs the machine to itself (scripts/test runs these after the rest)
pytestmark = pytest.mark.exclusive


def invoke(*args):
    return CliRunner().invoke(main, list(args))


@pytest.mark.slow
def test_a_killed_session_is_recovered_scored_and_checksummed(home):
    assert invoke("studies", "add", "s").exit_code == 0
    assert invoke("participants", "add", "P1", "--study", "s").exit_code == 0
    child = subprocess.Popen(
        [str(Path(sys.executable).with_name("vascsim")), "run", "--study", "s", "--participant", "P1",
         "--realtime", "--duration", "60"],
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
