"""`vascsim lrs`: results as xAPI statements to a Learning Record Store."""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable
from pathlib import Path

import click

from sessions.cli.base import open_catalog, open_store, print_json, user_errors
from sessions.config import LRS_VARIABLES, lrs_setting


@click.group()
def lrs() -> None:
    """Send a study's results to a Learning Record Store as xAPI statements (cmi5 verbs).

    Each session gives `attempted`, `completed` and `passed`/`failed` by the study's declared
    proficiency rule; a trainee reaching proficiency gives `satisfied`, a retention session its own
    `passed`/`failed`. Actors are pseudonymous accounts (STUDY/CODE on --home-page). An LRS that
    cannot be reached leaves the statements spooled on disk for the next push. docs/interop.md
    says what each statement means."""


def _required(value: str | None, name: str, option: str) -> str:
    from sessions.exchange.lrs import LrsError

    if value:
        return value
    raise LrsError(f"no {option}: give it, or set {LRS_VARIABLES[name]}")


def _secret(secret: str | None) -> str:
    return secret or lrs_setting("secret") or ""


ENDPOINT = click.option(
    "--endpoint", default=None, help=f"The LRS's xAPI endpoint [{LRS_VARIABLES['endpoint']}]."
)
KEY = click.option("--key", default=None, help=f"Basic-auth key (user) at the LRS [{LRS_VARIABLES['key']}].")
HOME_PAGE = click.option(
    "--home-page",
    default=None,
    help=f"The address naming this site's accounts, e.g. https://sim.hospital.example "
    f"[{LRS_VARIABLES['home_page']}].",
)
BASE = click.option(
    "--activity-base", default="https://vascsim.org/xapi", show_default=True, help="IRI naming tasks."
)


@lrs.command("configure")
@click.option("--study", required=True, help="The study whose results go to this LRS.")
@ENDPOINT
@KEY
@HOME_PAGE
@BASE
@click.option("--auto/--no-auto", default=False, show_default=True, help="Push whenever a session is scored.")
@user_errors
def configure(study, endpoint, key, home_page, activity_base, auto) -> None:
    """Remember the study's LRS (the secret is not stored: VASCSIM_LRS_SECRET at push time)."""
    from sessions.exchange.lrs import StudyLrs
    from sessions.exchange.lrs import configure as remember

    store, home = open_store()
    store.study_named(study)  # an unknown study is refused before anything is remembered
    settings = StudyLrs(
        _required(endpoint or lrs_setting("endpoint"), "endpoint", "--endpoint"),
        _required(key or lrs_setting("key"), "key", "--key"),
        _required(home_page or lrs_setting("home_page"), "home_page", "--home-page"),
        activity_base,
        auto,
    )
    remember(home, study, settings)
    click.echo(
        f"study {study}: statements go to {settings.endpoint} as {settings.key}"
        + ("; pushed whenever a session is scored" if auto else "; pushed by `vascsim lrs push`")
    )


@lrs.command("push")
@click.option("--study", required=True, help="The study whose results are sent.")
@ENDPOINT
@KEY
@click.option("--secret", default=None, help=f"Basic-auth secret [{LRS_VARIABLES['secret']}].")
@HOME_PAGE
@BASE
@click.option("--dry-run", is_flag=True, help="Send nothing: print what would be sent.")
@click.option("--json", "as_json", is_flag=True, help="With --dry-run: the statements as JSON.")
@click.option("--resend", is_flag=True, help="Send statements the ledger says were sent (the LRS keeps one).")
@user_errors
def push(study, endpoint, key, secret, home_page, activity_base, dry_run, as_json, resend) -> None:
    """Send the study's statements (to the options' LRS, else the study's configured one)."""
    from sessions.exchange.lrs import LrsEndpoint, Outbox, configured, plan
    from sessions.exchange.lrs import push as send
    from sessions.exchange.xapi import XapiSettings, study_statements

    catalog, home = open_catalog()
    stored = configured(home).get(study)
    endpoint = endpoint or (stored.endpoint if stored else None) or lrs_setting("endpoint")
    key = key or (stored.key if stored else None) or lrs_setting("key")
    home_page = home_page or (stored.home_page if stored else None) or lrs_setting("home_page")
    settings = XapiSettings(_required(home_page, "home_page", "--home-page"), activity_base)
    statements = study_statements(catalog, study, settings)
    if dry_run and not endpoint:
        todo = statements  # no LRS named: everything the study gives
    else:
        target = LrsEndpoint(
            _required(endpoint, "endpoint", "--endpoint"), _required(key, "key", "--key"), _secret(secret)
        )
        if not dry_run:
            result = send(statements, target, home, resend=resend)
            click.echo(
                f"sent {result.sent} statement(s) to {target.url}"
                + (f" ({result.voided} voiding the ones they replace)" if result.voided else "")
                + f"; {result.already_sent} already there (ledger)"
            )
            return
        todo = plan(statements, Outbox(home / "lrs" / target.slug).ledger(), resend)
    if as_json:
        print_json([s.body for s in todo])
        return
    verbs = Counter(s.body["verb"]["display"]["en-US"] for s in todo)
    click.echo(
        f"would send {len(todo)} statement(s) for study {study}: "
        + ", ".join(f"{count} {verb}" for verb, count in sorted(verbs.items()))
    )


def push_after_scoring(catalog, home: Path, uids: Iterable[str]) -> None:
    """For each study of the sessions just scored that is set to push automatically: push, and say
    what happened in one line (an unreachable LRS is not an error of the scoring: its statements
    stay spooled for the next push)."""
    from sessions.catalog.store import CatalogStore
    from sessions.exchange.lrs import LrsError, configured, push_study

    settings = configured(home)
    if not any(s.auto for s in settings.values()):
        return
    studies = CatalogStore(catalog).studies_of_sessions(list(uids))
    for study in sorted(studies):
        if study not in settings or not settings[study].auto:
            continue
        try:
            result = push_study(catalog, home, study, _secret(None))
            click.echo(
                f"LRS: sent {result.sent} statement(s) of study {study} to {settings[study].endpoint}",
                err=True,
            )
        except LrsError as error:
            click.echo(f"LRS: {error}", err=True)
