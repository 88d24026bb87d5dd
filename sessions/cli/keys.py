"""`vascsim keys`: the site's Ed25519 key pair that signs study bundles."""

from __future__ import annotations

import click

from sessions.cli.base import (
    user_errors,
)


@click.group()
def keys() -> None:
    """Signing keys for study bundles (Ed25519)."""


@keys.command("new")
@click.argument("path", type=click.Path(dir_okay=False))
@user_errors
def keys_new(path: str) -> None:
    """Make a site key pair: PATH (private, readable by you only) and PATH.pub (hand this out).

    Sign exports with `vascsim export --sign PATH`; a receiving site verifies them with
    `vascsim import-bundle --trust PATH.pub`.
    """
    from sessions.exchange.signing import new_key_pair, trusted_fingerprint

    private, public = new_key_pair(path)
    key = trusted_fingerprint(public)
    click.echo(f"private key {private} (keep it safe), public key {public}: key {key}")
