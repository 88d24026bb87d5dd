"""`vascsim recover`: a session a crash left running, back to verified files."""

from __future__ import annotations

import json

import click

from sessions.cli.base import (
    open_catalog,
    user_errors,
)
from sessions.cli.lrs import push_after_scoring


@click.command()
@click.argument("session")
@click.option("--score/--no-score", default=True, show_default=True, help="Score the session once recovered.")
@click.option("--json", "as_json", is_flag=True, help="Print the recovered session's header as JSON.")
@user_errors
def recover(session: str, score: bool, as_json: bool) -> None:
    """Recover a session a crash left unfinished: SESSION is its id or its directory.

    Every batch of the journal that verifies against its checksum becomes the
    session's Parquet files (reading stops at the first damaged or torn batch, and
    what was cut is reported); if the recording process died but the machine did
    not, the samples it recorded after its last flush are taken from its memory
    (tmpfs) too. The header records the measured loss. A catalogued session becomes
    `recovered`, with its files' checksums, and is scored. Find candidates with
    `vascsim sessions list --status running`.
    """
    from sessions.running.runner import recover_session, score_session

    catalog, home = open_catalog()
    uid, header = recover_session(catalog, session)
    if uid is not None and score and header["samples"]["rows"]:
        score_session(catalog, uid, home)
        push_after_scoring(catalog, home, [uid])
    if as_json:
        click.echo(json.dumps(dict(header, catalog_session=uid), indent=2, sort_keys=True))
        return
    rows = header["samples"]["rows"]
    until = header.get("recovered_until_s")
    kept = f"up to {until:.3f} s" if until is not None else "no samples"
    click.echo(f"recovered {uid or session}: {rows} samples kept ({kept}); {header['loss_note']}")
    for stream in ("samples", "events"):
        cut = header[stream].get("cut")
        if cut:
            click.echo(
                f"  {stream}: {cut['bytes']} damaged or incomplete bytes cut after batch "
                f"{cut['after_batches']} ({cut['reason']})"
            )
