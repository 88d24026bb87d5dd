"""A station streaming its sessions to a central recorder (`--stream-to`): the central copy equals the
local recording; a central recorder that is down never costs the trainee the trial, and what it did not
take is sent by the next streamed session (issue 42's remote stations)."""

from __future__ import annotations

import logging
import re

import numpy as np
import pytest
from click.testing import CliRunner

from recorder import open_session
from sessions.catalog import Catalog
from sessions.cli import main
from sessions.running.runner import SessionPlan, run_session
from sessions.running.streaming import StreamTarget, catalog_status, send_leftovers
from sessions.synthetic import scripted_hands
from tests.recorder.test_remote import free_port, start_server

pytestmark = pytest.mark.slow
TOKEN = "secret-station-a"


def course(home) -> Catalog:
    catalog = Catalog(f"sqlite:///{home / 'catalog.sqlite'}")
    with catalog.session() as orm:
        study = catalog.study(orm, "S", create=True)
        catalog.add_participant(orm, study, "E1", level="expert")
    return catalog


def same_recording(local_directory, central_directory) -> None:
    local, central = open_session(local_directory), open_session(central_directory)
    assert central.header["status"] == "complete" and central.header["participant_id"] == "E1"
    assert central.samples.num_rows == local.samples.num_rows > 1000
    for name in ("time", "tool_x", "force_x"):
        np.testing.assert_array_equal(central.samples.column(name), local.samples.column(name))
    assert central.events.column("kind").to_pylist() == local.events.column("kind").to_pylist()


def test_a_run_streamed_from_the_command_line_arrives_whole(tmp_path, monkeypatch):
    home = tmp_path / "station"
    home.mkdir()
    course(home).close()
    port = free_port()
    server = start_server(tmp_path / "central", port)
    monkeypatch.setenv("VASCSIM_HOME", str(home))
    monkeypatch.delenv("VASCSIM_DATABASE_URL", raising=False)
    monkeypatch.setenv("VASCSIM_STATION_TOKEN", TOKEN)
    try:
        args = ["run", "--study", "S", "--participant", "E1", "--stream-to", f"http://127.0.0.1:{port}"]
        result = CliRunner().invoke(main, [*args, "--json"])
    finally:
        server.kill()
        server.wait()
    assert result.exit_code == 0, result.output
    uid = result.output[result.output.index('"session": "') + 12 :].split('"', 1)[0]
    same_recording(home / "sessions" / uid, tmp_path / "central" / "station-a" / uid)
    assert not (home / "spool" / uid).exists()


def test_streaming_needs_the_station_token_said_in_one_line(tmp_path, monkeypatch):
    monkeypatch.setenv("VASCSIM_HOME", str(tmp_path))
    monkeypatch.delenv("VASCSIM_STATION_TOKEN", raising=False)
    args = ["run", "--study", "S", "--participant", "E1", "--stream-to", "http://127.0.0.1:9/ingest"]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 2 and "needs this station's token in VASCSIM_STATION_TOKEN" in result.output
    result = CliRunner().invoke(main, [*args[:-1], "central:8000"])
    assert result.exit_code == 2 and "must start with http:// or https://" in result.output


def test_a_central_recorder_down_costs_no_trial_and_the_next_session_sends_what_it_missed(tmp_path, caplog):
    home = tmp_path / "station"
    home.mkdir()
    catalog = course(home)
    port = free_port()  # nothing listens there yet
    target = StreamTarget(f"http://127.0.0.1:{port}", TOKEN, drain_timeout_s=0.5)
    try:
        with caplog.at_level(logging.WARNING, logger="vascsim.streaming"):
            uid = run_session(
                catalog, home, SessionPlan("S", "E1", "interrupted-stitch", None), scripted_hands(0.9, 1),
                stream=target,
            )  # fmt: skip
        with catalog.session() as orm:
            row = catalog.recorded_session(orm, uid)
            assert row.status == "complete"  # the trial is kept, scored, here
        spool = home / "spool" / uid
        assert spool.is_dir() and f"kept in {spool}" in caplog.text
        assert re.search(rf"did not take \d+ item\(s\) of session {uid} within 0.5 s", caplog.text)
        server = start_server(tmp_path / "central", port)
        try:
            assert send_leftovers(target, home, catalog_status(catalog)) == []
        finally:
            server.kill()
            server.wait()
        assert not spool.exists()
        same_recording(home / "sessions" / uid, tmp_path / "central" / "station-a" / uid)
    finally:
        catalog.close()
