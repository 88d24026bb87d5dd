"""`vascsim import-bundle`: a study exported by another site or catalog, checked before it is stored."""

from __future__ import annotations

import click

from sessions.cli.base import (
    open_catalog,
    per_file,
    print_summary,
    user_errors,
)


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
    from sessions.exchange.bundle import import_bundle

    catalog, home = open_catalog()
    summary = per_file(
        "verifying",
        lambda advance: import_bundle(catalog, home, bundle, advance, trust, not keep_imported_metrics),
    )
    if keep_imported_metrics:
        metrics = "metrics imported as stated, unverified"
    else:
        differing = summary["metric_values_differing"]
        metrics = f"metrics recomputed from the streams ({differing} stated value(s) differed, replaced)"
    signed = f"; signed by trusted key {summary['signed_by']}" if summary["signed_by"] else ""
    print_summary(
        summary,
        as_json,
        f"imported study {summary['study']}: {summary['participants']} participant(s), "
        f"{summary['sessions']} session(s); {metrics}{signed}",
    )
