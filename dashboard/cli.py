"""The `vascsim` console script: every catalog command from sessions.cli, plus `vascsim serve`.

It lives here so that ``sessions`` never imports the web application (imports point
dashboard -> sessions); the web stack is imported only when `serve` runs.
"""

from __future__ import annotations

import click

from sessions.cli import _catalog, main, user_errors

__all__ = ["main"]


def _settings_help() -> str:
    from dashboard.settings import documented_settings

    return "\n".join(f"  {name} (default {default}): {text}" for name, default, text in documented_settings())


@main.command()
@click.option(
    "--host", default="127.0.0.1", show_default=True, help="Address to bind (localhost only by default)."
)
@click.option("--port", default=8000, show_default=True, type=click.IntRange(1, 65535), help="TCP port.")
@click.option("--secure-cookies", is_flag=True, help="Mark cookies Secure (when served behind HTTPS).")
@user_errors
def serve(host: str, port: int, secure_cookies: bool) -> None:
    """Run the dashboard web application.

    Open http://HOST:PORT/ and sign in; create the first account with
    `vascsim users add NAME --role admin`. Stations stream to /ingest with the
    tokens issued on the Administration page. Every asset is served locally.
    """
    import uvicorn

    from dashboard.app import create_app
    from dashboard.settings import DashboardSettings

    catalog, home = _catalog()
    settings = DashboardSettings(
        home=home, database_url=catalog.url, host=host, port=port, secure_cookies=secure_cookies
    )
    app = create_app(settings, catalog)
    if host not in ("127.0.0.1", "localhost", "::1"):
        click.echo(f"warning: binding {host}: the dashboard is reachable from other machines", err=True)
    click.echo(f"vascsim dashboard on http://{host}:{port}/ (data: {home}; Ctrl-C stops)")
    uvicorn.run(app, host=host, port=port, log_level="warning", proxy_headers=False)


serve.help = (serve.help or "") + "\n\nSettings:\n\n" + _settings_help()
