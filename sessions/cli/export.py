"""`vascsim export`: a study as one archive for another site or catalog."""

from __future__ import annotations

import click

from sessions.cli.base import (
    open_catalog,
    per_file,
    print_summary,
    user_errors,
)


@click.command("export")
@click.option("--study", required=True, help="Study to export.")
@click.option(
    "-o",
    "--out",
    type=click.Path(dir_okay=False),
    default=None,
    help="Archive to write (default: STUDY.vascsim.zip in the current directory).",
)
@click.option(
    "--sign",
    "sign_key",
    type=click.Path(dir_okay=False),
    default=None,
    help="Sign the bundle with this site's Ed25519 private key (make one with `vascsim keys new`).",
)
@click.option("--json", "as_json", is_flag=True, help="Print the summary as JSON.")
@user_errors
def export_bundle(study: str, out: str | None, sign_key: str | None, as_json: bool) -> None:
    """Write a study as one self-contained archive (catalog rows + stream files + checksums).

    The archive moves a study between machines or catalogs (SQLite <-> PostgreSQL);
    `vascsim import-bundle` reads it back. Every file is checked against its
    recorded SHA-256 on the way out. A checksum proves only that nothing was damaged
    by accident; --sign adds an Ed25519 signature, so a site holding your public key
    can verify that the study comes from you unchanged (`import-bundle --trust`).
    """
    from sessions.exchange.bundle import export_study

    catalog, _ = open_catalog()
    target = out or f"{study}.vascsim.zip"
    summary = per_file("exporting", lambda advance: export_study(catalog, study, target, advance, sign_key))
    signed = f", signed by key {summary['signed_by']}" if summary["signed_by"] else ""
    print_summary(
        summary,
        as_json,
        f"exported study {study}: {summary['sessions']} session(s), {summary['files']} file(s) "
        f"-> {summary['bundle']}{signed}",
    )
