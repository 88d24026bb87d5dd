"""`vascsim import`: a JIGSAWS task (kinematics and meta file) as a scored study."""

from __future__ import annotations

import click

from sessions.cli.base import (
    existing_path,
    open_catalog,
    user_errors,
)


@click.command("import")
@click.argument("kinematics_dir")
@click.argument("meta_file")
@click.option("--study", required=True, help="Study to import into (created if missing).")
@user_errors
def import_jigsaws(kinematics_dir: str, meta_file: str, study: str) -> None:
    """Import a JIGSAWS task (kinematics folder + meta file) as a scored study.

    Surgeons become participants (labels novice/intermediate/expert from the
    self-reported level; GRS totals stored as ratings); trials become sessions
    whose files are the kinematics files, with checksums.
    """
    from sessions.exchange.importing import import_jigsaws as run_import

    existing_path(kinematics_dir, "kinematics folder", folder=True)
    existing_path(meta_file, "meta file")
    catalog, _ = open_catalog()
    count = run_import(catalog, kinematics_dir, meta_file, study)
    click.echo(f"imported {count} JIGSAWS trial(s) into study {study}")
