"""The `vascsim` console script: every catalog command from sessions.cli, plus `vascsim serve`.

It lives here so that ``sessions`` never imports the web application (imports point
dashboard -> sessions); the web stack is imported only when `serve` runs.
"""

from __future__ import annotations

import errno
import inspect
import socket

import click

from sessions.cli import main, open_catalog, user_errors

__all__ = ["main"]


def _settings_help() -> str:
    """The settings block of `serve --help`, one per line, kept as written (click's \\b)."""
    from dashboard.settings import documented_settings

    lines = []
    for name, default, text in documented_settings():
        lines += [f"{name} (default {default})", f"    {text}"]
    return "\b\n" + "\n".join(lines)


@main.command()
@click.option(
    "--host", default="127.0.0.1", show_default=True, help="Address to bind (localhost only by default)."
)
@click.option("--port", default=8000, show_default=True, type=click.IntRange(1, 65535), help="TCP port.")
@click.option("--secure-cookies", is_flag=True, help="Mark cookies Secure (when served behind HTTPS).")
@click.option(
    "--setting",
    "setting_pairs",
    multiple=True,
    metavar="NAME=VALUE",
    help="Any setting listed above (repeatable); also VASCSIM_SETTING_NAME in the environment.",
)
@user_errors
def serve(host: str, port: int, secure_cookies: bool, setting_pairs: tuple[str, ...]) -> None:
    """Run the dashboard web application.

    Open http://HOST:PORT/ and sign in; create the first account with
    `vascsim users add NAME --role admin`. Stations stream to /ingest with the
    tokens issued on the Administration page. Every asset is served locally.
    """
    import uvicorn
    from click.core import ParameterSource

    from dashboard.app import create_app
    from dashboard.serving import ClientLimits, guarded_protocol
    from dashboard.settings import DashboardSettings, SettingError, parse_settings
    from sessions.config import settings_from_environment

    catalog, home = open_catalog()
    chosen = dict(parse_settings(settings_from_environment(), "environment"))
    pairs = {}
    for pair in setting_pairs:
        name, separator, value = pair.partition("=")
        if not separator:
            raise SettingError(f"--setting {pair!r}: expected NAME=VALUE")
        pairs[name.strip()] = value.strip()
    chosen.update(parse_settings(pairs, "--setting"))
    context = click.get_current_context()
    for name, value in (("host", host), ("port", port), ("secure_cookies", secure_cookies)):
        if name not in chosen or context.get_parameter_source(name) is not ParameterSource.DEFAULT:
            chosen[name] = value  # an explicit --host/--port/--secure-cookies wins
    settings = DashboardSettings(home=home, database_url=catalog.url, **chosen)
    host, port = settings.host, settings.port
    listening = _listen(host, port)  # before the banner: a busy port is one line, not a banner and a trace
    app = create_app(settings, catalog)
    if host not in ("127.0.0.1", "localhost", "::1"):
        click.echo(f"warning: binding {host}: the dashboard is reachable from other machines", err=True)
    click.echo(f"vascsim dashboard on http://{host}:{port}/ (data: {home}; Ctrl-C stops)")
    limits = ClientLimits(
        settings.header_timeout_s, settings.body_timeout_s, settings.body_min_rate, settings.max_connections
    )
    with listening:  # slow or too many clients are cut off (dashboard.serving)
        uvicorn.run(
            app,
            fd=listening.fileno(),
            log_level="warning",
            proxy_headers=False,
            http=guarded_protocol(limits),
        )


def _listen(host: str, port: int) -> socket.socket:
    """A listening socket on ``host``:``port`` for the server, or a one-line SettingError saying why not."""
    from dashboard.settings import SettingError

    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    try:
        return socket.create_server((host, port), family=family, reuse_port=False)
    except OSError as error:
        if error.errno == errno.EADDRINUSE:
            raise SettingError(
                f"port {port} on {host} is already in use (another vascsim serve?); choose another: --port"
            ) from None
        raise SettingError(f"cannot listen on {host}:{port}: {error.strerror or error}") from None


serve.help = inspect.cleandoc(serve.help or "") + "\n\nSettings:\n\n" + _settings_help()
