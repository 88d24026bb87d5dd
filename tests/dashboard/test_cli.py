"""`vascsim users` and `vascsim serve` through the real command line."""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import time
from pathlib import Path

import httpx
from click.testing import CliRunner

from dashboard.cli import main


def test_users_add_list_and_passwd(home):
    runner = CliRunner()
    assert runner.invoke(main, ["studies", "add", "course"]).exit_code == 0
    assert runner.invoke(main, ["participants", "add", "T01", "--study", "course"]).exit_code == 0
    made = runner.invoke(
        main, ["users", "add", "ada", "--role", "admin", "--password-stdin"], input="long enough pw\n"
    )
    assert made.exit_code == 0 and "created admin account 'ada'" in made.output
    linked = runner.invoke(
        main,
        ["users", "add", "tom", "--role", "trainee", "--participant", "course:T01", "--password-stdin"],
        input="another long pw\n",
    )
    assert linked.exit_code == 0, linked.output
    listed = runner.invoke(main, ["users", "list"])
    assert listed.output.splitlines() == ["ada: admin", "tom: trainee -> course:T01"]  # as the dashboard says
    for args, stdin, message in (
        (
            ["users", "add", "ada", "--role", "admin", "--password-stdin"],
            "long enough pw\n",
            "already exists",
        ),
        (["users", "add", "bob", "--role", "admin", "--password-stdin"], "short\n", "at least 10 characters"),
        (["users", "add", "x y", "--role", "admin", "--password-stdin"], "long enough pw\n", "must be 2-64"),
        (
            ["users", "add", "eve", "--role", "trainee", "--participant", "course:T99", "--password-stdin"],
            "long enough pw\n",
            "no participant 'T99'",
        ),
        (["users", "passwd", "nobody", "--password-stdin"], "long enough pw\n", "no user 'nobody'"),
    ):
        failed = runner.invoke(main, args, input=stdin)
        assert failed.exit_code == 1 and message in failed.output, (args, failed.output)
    assert runner.invoke(main, ["users", "list"]).output.count("\n") == 2  # nothing half-created
    assert (
        runner.invoke(main, ["users", "passwd", "ada", "--password-stdin"], input="a new long pw\n").exit_code
        == 0
    )


def _listening_addresses(port: int) -> list[str]:
    rows = (
        Path("/proc/net/tcp").read_text().splitlines()[1:]
        + Path("/proc/net/tcp6").read_text().splitlines()[1:]
    )
    found = []
    for row in rows:
        local, state = row.split()[1], row.split()[3]
        address, hex_port = local.split(":")
        if state == "0A" and int(hex_port, 16) == port:
            found.append(address)
    return found


def test_serve_binds_localhost_and_answers(tmp_path):
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    env = dict(os.environ, VASCSIM_HOME=str(tmp_path / "home"), VASCSIM_SETTING_LOGIN_ATTEMPTS="1")
    env.pop("VASCSIM_DATABASE_URL", None)
    command = Path(sys.executable).with_name("vascsim")
    arguments = [str(command), "serve", "--port", str(port), "--setting", "login_window_s=60"]
    with subprocess.Popen(arguments, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE) as server:
        try:
            page = _first_answer(server, f"http://127.0.0.1:{port}/login")
            assert page.status_code == 200 and "Sign in" in page.text
            me = httpx.get(f"http://127.0.0.1:{port}/api/me")
            assert me.status_code == 401 and me.json()["error"]["message"] == "sign in first"
            assert _listening_addresses(port) == ["0100007F"]  # 127.0.0.1 only, as /proc/net/tcp writes it
            # issue 24: settings from the environment and --setting reach the app (one failure allowed)
            login = {"username": "nobody", "password": "a wrong password"}
            assert httpx.post(f"http://127.0.0.1:{port}/api/login", json=login).status_code == 401
            assert httpx.post(f"http://127.0.0.1:{port}/api/login", json=login).status_code == 429
            # issue 44, seen 10: a second server on the busy port printed the banner, uvicorn's error and
            # exited 3; now one line naming the port, exit 1, and the first server still answers
            second = subprocess.run(arguments, env=env, capture_output=True, text=True, timeout=60)
            assert second.returncode == 1 and second.stdout == ""
            assert second.stderr == (
                f"vascsim: error: port {port} on 127.0.0.1 is already in use (another vascsim serve?); "
                "choose another: --port\n"
            )
            assert httpx.get(f"http://127.0.0.1:{port}/login").status_code == 200
        finally:
            server.terminate()
            server.wait(20)


def _first_answer(server: subprocess.Popen, url: str) -> httpx.Response:
    deadline = time.monotonic() + 60
    while True:
        try:
            return httpx.get(url, timeout=2)
        except httpx.TransportError:
            if server.poll() is not None:
                raise AssertionError(f"vascsim serve exited: {server.stderr.read().decode()}") from None
            if time.monotonic() > deadline:
                raise AssertionError("vascsim serve did not answer within 60 s") from None
            time.sleep(0.2)


def test_serve_help_lists_every_setting():
    from dashboard.settings import documented_settings

    shown = CliRunner().invoke(main, ["serve", "--help"]).output
    for name, _default, _help in documented_settings():
        assert name in shown


def test_bad_settings_are_one_line_errors_naming_them(tmp_path, monkeypatch):
    monkeypatch.setenv("VASCSIM_HOME", str(tmp_path))
    monkeypatch.delenv("VASCSIM_DATABASE_URL", raising=False)
    cases = [
        (
            ["--setting", "login_attempts=many"],
            {},
            "--setting: setting login_attempts must be a whole number; got 'many'",
        ),
        (["--setting", "colour=blue"], {}, "--setting: unknown setting 'colour'; settings: host, port"),
        (["--setting", "live_rate_hz"], {}, "--setting 'live_rate_hz': expected NAME=VALUE"),
        ([], {"VASCSIM_SETTING_LIVE_POLL_S": "-1"}, "environment: setting live_poll_s must be positive"),
    ]
    for arguments, environment, message in cases:
        for name, value in environment.items():
            monkeypatch.setenv(name, value)
        result = CliRunner().invoke(main, ["serve", *arguments])
        for name in environment:
            monkeypatch.delenv(name)
        assert result.exit_code == 1 and message in result.output, (arguments, result.output)
        assert result.output.count("\n") == 1
