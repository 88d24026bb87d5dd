"""`vascsim lrs`: results as xAPI statements to a Learning Record Store."""

from __future__ import annotations

from collections import Counter

import click

from sessions.cli.base import open_catalog, print_json, user_errors
from sessions.config import LRS_VARIABLES, lrs_setting


@click.group()
def lrs() -> None:
    """Send a study's results to a Learning Record Store as xAPI statements (cmi5 verbs).

    Each session gives `attempted`, `completed` and `passed`/`failed` by the study's declared
    proficiency rule; a trainee reaching proficiency gives `satisfied`, a retention session its own
    `passed`/`failed`. Actors are pseudonymous accounts (STUDY/CODE on --home-page). docs/interop.md
    says what each statement means."""


def _required(value: str | None, name: str, option: str) -> str:
    from sessions.lrs import LrsError

    if value:
        return value
    raise LrsError(f"no {option}: give it, or set {LRS_VARIABLES[name]}")


@lrs.command("push")
@click.option("--study", required=True, help="The study whose results are sent.")
@click.option("--endpoint", default=None, help=f"The LRS's xAPI endpoint URL [{LRS_VARIABLES['endpoint']}].")
@click.option("--key", default=None, help=f"Basic-auth key (user) at the LRS [{LRS_VARIABLES['key']}].")
@click.option("--secret", default=None, help=f"Basic-auth secret [{LRS_VARIABLES['secret']}].")
@click.option(
    "--home-page",
    default=None,
    help=f"The address naming this site's accounts, e.g. https://sim.hospital.example "
    f"[{LRS_VARIABLES['home_page']}].",
)
@click.option(
    "--activity-base", default="https://vascsim.org/xapi", show_default=True, help="IRI naming tasks."
)
@click.option("--dry-run", is_flag=True, help="Send nothing: print what would be sent.")
@click.option("--json", "as_json", is_flag=True, help="With --dry-run: the statements as JSON.")
@click.option("--resend", is_flag=True, help="Send statements the ledger says were sent (the LRS keeps one).")
@user_errors
def push(study, endpoint, key, secret, home_page, activity_base, dry_run, as_json, resend) -> None:
    """Send the study's statements; an unreachable LRS leaves them spooled for the next push."""
    from sessions.lrs import LrsEndpoint, LrsUnreachable, Outbox, plan
    from sessions.lrs import push as send
    from sessions.xapi import XapiSettings, study_statements

    catalog, home = open_catalog()
    settings = XapiSettings(
        _required(home_page or lrs_setting("home_page"), "home_page", "--home-page"), activity_base
    )
    statements = study_statements(catalog, study, settings)
    if dry_run and not (endpoint or lrs_setting("endpoint")):
        todo = statements  # no LRS named: everything the study gives
    else:
        target = LrsEndpoint(
            _required(endpoint or lrs_setting("endpoint"), "endpoint", "--endpoint"),
            _required(key or lrs_setting("key"), "key", "--key"),
            secret or lrs_setting("secret") or "",
        )
        if dry_run:
            todo = plan(statements, Outbox(home / "lrs" / target.slug).ledger(), resend)
        else:
            try:
                result = send(statements, target, home, resend=resend)
            except LrsUnreachable as error:
                click.echo(f"vascsim: error: {error}", err=True)
                raise SystemExit(1) from error
            click.echo(
                f"sent {result.sent} statement(s) to {target.url}"
                + (f" ({result.voided} voiding the ones they replace)" if result.voided else "")
                + f"; {result.already_sent} already there (ledger)"
            )
            return
    if as_json:
        print_json([s.body for s in todo])
        return
    verbs = Counter(s.body["verb"]["display"]["en-US"] for s in todo)
    click.echo(
        f"would send {len(todo)} statement(s) for study {study}: "
        + ", ".join(f"{count} {verb}" for verb, count in sorted(verbs.items()))
    )
