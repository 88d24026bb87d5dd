"""`vascsim users ...`: dashboard accounts from the command line (the first admin is made here)."""

from __future__ import annotations

import sys

import click

from sessions.catalog.models import ROLES
from sessions.catalog.store import CatalogStore
from sessions.cli.base import open_catalog, print_json, user_errors


def _password(value: str | None) -> str:
    if value is not None:
        return value
    return click.prompt("password", hide_input=True, confirmation_prompt=True)


@click.group()
def users() -> None:
    """Dashboard accounts: admin, supervisor, researcher, trainee."""


@users.command("add")
@click.argument("username")
@click.option("--role", type=click.Choice(ROLES), required=True, help="What the account may see and do.")
@click.option(
    "--participant",
    "participants",
    multiple=True,
    metavar="STUDY:CODE",
    help="Trainees: a participant whose sessions this account sees (repeatable).",
)
@click.option(
    "--password-stdin", is_flag=True, help="Read the password from the first line of stdin (scripts)."
)
@user_errors
def users_add(username: str, role: str, participants: tuple[str, ...], password_stdin: bool) -> None:
    """Create an account; the password is prompted for (10+ characters) and stored as an Argon2id hash."""
    password = sys.stdin.readline().rstrip("\n") if password_stdin else _password(None)
    catalog, _ = open_catalog()
    CatalogStore(catalog).create_user(username, password, role, participants)  # nothing made on an error
    click.echo(f"created {role} account {username!r}")


@users.command("list")
@click.option("--json", "as_json", is_flag=True, help="Print as JSON.")
@user_errors
def users_list(as_json: bool) -> None:
    """Every account with its role, state and linked participants."""
    catalog, _ = open_catalog()
    rows = [
        {"username": u.username, "role": u.role, "active": u.active, "participants": list(u.participants)}
        for u in CatalogStore(catalog).users()
    ]  # participants as STUDY:CODE, as the dashboard shows them
    if as_json:
        print_json(rows)
        return
    for row in rows:
        state = "" if row["active"] else " (inactive)"
        linked = f" -> {', '.join(row['participants'])}" if row["participants"] else ""
        click.echo(f"{row['username']}: {row['role']}{state}{linked}")


@users.command("passwd")
@click.argument("username")
@click.option("--password-stdin", is_flag=True, help="Read the new password from stdin.")
@user_errors
def users_passwd(username: str, password_stdin: bool) -> None:
    """Set a new password (signs the account out everywhere)."""
    password = sys.stdin.readline().rstrip("\n") if password_stdin else _password(None)
    store = CatalogStore(open_catalog()[0])
    store.change_user(store.user_named(username).id, password=password)
    click.echo(f"password of {username!r} changed")
