"""`vascsim ratings ...`: GRS and OSATS ratings of sessions by named raters, and how well raters agree."""

from __future__ import annotations

from pathlib import Path

import click
import pandas as pd

from metrics.instruments import INSTRUMENTS, instrument
from sessions.catalog import CatalogError
from sessions.cli.base import open_catalog, print_frame, print_json, user_errors
from sessions.scoring.ratings import add_rating, import_ratings, study_ratings

_ITEMS = "; ".join(f"{i.name}: {', '.join(i.item_names)}" for i in INSTRUMENTS.values())


@click.group()
def ratings() -> None:
    """Ratings of sessions (GRS, OSATS) by named raters, and inter-rater reliability."""


def _scores(spec_name: str, pairs: tuple[str, ...], scores: str | None) -> dict[str, str]:
    spec = instrument(spec_name)
    if scores is not None:
        values = [v.strip() for v in scores.split(",")]
        if len(values) != len(spec.items):
            raise CatalogError(
                f"--scores needs {len(spec.items)} comma-separated scores for {spec.name} "
                f"({', '.join(spec.item_names)}); got {len(values)}"
            )
        return dict(zip(spec.item_names, values, strict=True))
    result = {}
    for pair in pairs:
        name, sep, value = pair.partition("=")
        if not sep:
            raise CatalogError(f"--item takes NAME=SCORE, e.g. respect_for_tissue=4; got {pair!r}")
        result[name.strip()] = value.strip()
    return result


@ratings.command("add")
@click.argument("session_id")
@click.option("--rater", required=True, help="The rater's name (stored with the rating).")
@click.option(
    "--instrument",
    "instrument_name",
    type=click.Choice(sorted(INSTRUMENTS), case_sensitive=False),
    required=True,
)
@click.option(
    "--item", "pairs", multiple=True, metavar="NAME=SCORE", help=f"One item's score (1-5). Items: {_ITEMS}."
)
@click.option(
    "--scores", default=None, metavar="S1,S2,...", help="Every item's score in the instrument's order."
)
@click.option("--replace", is_flag=True, help="Replace this rater's earlier rating of the session.")
@user_errors
def ratings_add(session_id: str, rater: str, instrument_name: str, pairs, scores, replace: bool) -> None:
    """Rate session SESSION_ID: every item of the instrument, whole scores 1-5."""
    catalog, _ = open_catalog()
    rating = add_rating(
        catalog, session_id, rater, instrument_name, _scores(instrument_name, pairs, scores), replace
    )
    low, high = rating.instrument.total_range
    click.echo(
        f"{rating.instrument.name} {rating.total} (of {low}-{high}) by {rating.rater} stored for {session_id}"
    )


@ratings.command("import")
@click.argument("csv_file", type=click.Path(path_type=Path))
@click.option("--replace", is_flag=True, help="Replace raters' earlier ratings of the same sessions.")
@user_errors
def ratings_import(csv_file: Path, replace: bool) -> None:
    """Import ratings from a CSV: session_id, rater, instrument, then one column per item (a total column
    is optional and checked). Every row is checked first; a bad row stores nothing."""
    catalog, _ = open_catalog()
    count = import_ratings(catalog, csv_file, replace)
    click.echo(f"{count} rating(s) imported from {csv_file}")


@ratings.command("list")
@click.option("--study", required=True, help="Study whose ratings to list.")
@click.option("--instrument", "instrument_name", default=None, help="Only this instrument (GRS or OSATS).")
@click.option("--json", "as_json", is_flag=True, help="Print as JSON.")
@user_errors
def ratings_list(study: str, instrument_name: str | None, as_json: bool) -> None:
    """One line per session, rater and instrument: the total and when it was rated."""
    catalog, _ = open_catalog()
    frame = study_ratings(catalog, study, instrument_name)
    totals = frame[frame["item"] == "total"]
    rows = totals[["session_id", "participant_id", "rater", "instrument", "score", "created_at"]].rename(
        columns={"score": "total", "created_at": "rated (UTC)", "participant_id": "participant"}
    )
    if as_json:
        print_json(rows.astype({"rated (UTC)": str}).to_dict(orient="records"))
        return
    rows = rows.assign(total=rows["total"].map(lambda v: f"{v:.0f}"))
    rows["rated (UTC)"] = pd.to_datetime(rows["rated (UTC)"]).dt.strftime("%Y-%m-%d")  # --json: the time too
    print_frame(rows, f"Ratings in {study}", caption=f"{len(rows)} rating(s)")


@ratings.command("reliability")
@click.option("--study", required=True, help="Study whose ratings to analyse.")
@click.option("--instrument", "instrument_name", default="GRS", show_default=True, help="GRS or OSATS.")
@click.option("--json", "as_json", is_flag=True, help="Print as JSON.")
@user_errors
def ratings_reliability(study: str, instrument_name: str, as_json: bool) -> None:
    """Inter-rater reliability per item and of the total: ICC(2,1) and ICC(2,k) (two-way random,
    absolute agreement) on the sessions every rater rated, and Krippendorff's alpha on all ratings."""
    from metrics.study.reliability import agreement_shown, rater_agreement  # SciPy's statistics: 0.4 s

    catalog, _ = open_catalog()
    frame = study_ratings(catalog, study, instrument_name)
    if frame.empty:
        raise CatalogError(f"study {study!r} has no {instrument(instrument_name).name} ratings")
    table = rater_agreement(frame, instrument_name)
    if as_json:
        print_json(table.to_dict(orient="records"))
        return
    shown = agreement_shown(table, compact=True)
    print_frame(
        shown,
        f"{instrument(instrument_name).name} inter-rater reliability in {study}",
        caption="ICC(2,1): one rater's score, absolute agreement, 95 % CI; sessions: those every rater "
        "in the block rated. alpha: Krippendorff's (ordinal items, interval total), bootstrap 95 % CI. "
        "Reading (Koo & Li 2016): < 0.5 poor, 0.5-0.75 moderate, 0.75-0.9 good, > 0.9 excellent.",
    )
