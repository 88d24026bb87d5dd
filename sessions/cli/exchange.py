"""`vascsim export`, `keys` and `import-bundle`: studies between sites."""

from __future__ import annotations

import click

from sessions.cli.base import (
    open_catalog,
    print_json,
    progress_bar,
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
    from sessions.bundle import export_study

    catalog, _ = open_catalog()
    target = out or f"{study}.vascsim.zip"
    summary = _per_file("exporting", lambda advance: export_study(catalog, study, target, advance, sign_key))
    signed = f", signed by key {summary['signed_by']}" if summary["signed_by"] else ""
    _summary(
        summary,
        as_json,
        f"exported study {study}: {summary['sessions']} session(s), {summary['files']} file(s) "
        f"-> {summary['bundle']}{signed}",
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
    from sessions.signing import new_key_pair, trusted_fingerprint

    private, public = new_key_pair(path)
    key = trusted_fingerprint(public)
    click.echo(f"private key {private} (keep it safe), public key {public}: key {key}")


def _per_file(description: str, work):
    """Run ``work(advance)`` under a transient progress bar advanced once per file."""
    with progress_bar(transient=True) as progress:
        task = progress.add_task(description, total=None, last="")
        return work(lambda name: progress.update(task, advance=1, last=name))


def _summary(summary: dict, as_json: bool, text: str) -> None:
    if as_json:
        print_json(summary)
    else:
        click.echo(text)


@click.command("import-bundle")
@click.argument("bundle", type=click.Path(dir_okay=False))
@click.option(
    "--trust",
    type=click.Path(dir_okay=False),
    default=None,
    help="Accept the bundle only if it is signed by this public key (PATH.pub of `vascsim keys new`).",
)
@click.option(
    "--keep-imported-metrics",
    is_flag=True,
    help="Store the bundle's metric values as they are (marked imported, unverified) instead of "
    "recomputing them from the streams.",
)
@click.option("--json", "as_json", is_flag=True, help="Print the summary as JSON.")
@user_errors
def import_bundle_command(bundle: str, trust: str | None, keep_imported_metrics: bool, as_json: bool) -> None:
    """Add a study exported by `vascsim export` to this catalog.

    The bundle is checked completely first: its declared schema, every file's size
    and checksum, the signature when --trust is given. Metric values are recomputed
    from the imported streams (values the bundle states differently are counted and
    replaced). A bad bundle, a study name already in use, or a session id already
    catalogued is refused and nothing is changed. Participants arrive without any
    account link: link trainee accounts here with `vascsim users`.
    """
    from sessions.bundle import import_bundle

    catalog, home = open_catalog()
    summary = _per_file(
        "verifying",
        lambda advance: import_bundle(catalog, home, bundle, advance, trust, not keep_imported_metrics),
    )
    if keep_imported_metrics:
        metrics = "metrics imported as stated, unverified"
    else:
        differing = summary["metric_values_differing"]
        metrics = f"metrics recomputed from the streams ({differing} stated value(s) differed, replaced)"
    signed = f"; signed by trusted key {summary['signed_by']}" if summary["signed_by"] else ""
    _summary(
        summary,
        as_json,
        f"imported study {summary['study']}: {summary['participants']} participant(s), "
        f"{summary['sessions']} session(s); {metrics}{signed}",
    )
