"""Ratings of sessions by named raters (GRS, OSATS): stored in the catalog's ratings table with the
rater and the time, every item and the total, several raters per session.

Every rating is checked against its instrument (:mod:`metrics.instruments`: each item once, whole
scores on the scale) and the session must exist before anything is stored; a CSV import is checked
row by row completely first and stored in one transaction, so a bad row stores nothing.
A rater rating a session again with the same instrument replaces their rating only when asked.
"""

from __future__ import annotations

import csv
import io
import re
from collections.abc import Mapping
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path

import pandas as pd

from metrics.errors import MetricsError
from metrics.instruments import TOTAL, Instrument, instrument
from sessions.catalog import AlreadyExists, Catalog, CatalogError, now
from sessions.catalog.models import Rating
from sessions.catalog.results import (
    forget_rating,
    has_rated,
    raters_in_order,
    session_rating_rows,
    study_rating_rows,
)

RATER_NAME = re.compile(r"^[^\x00-\x1f\x7f]{1,100}$")
MAX_IMPORT_BYTES = 16 * 1024 * 1024
MAX_IMPORT_ROWS = 100_000


@dataclass(frozen=True)
class SessionRating:
    """One rater's rating of one session with one instrument, checked."""

    session_uid: str
    rater: str
    instrument: Instrument
    scores: dict[str, int]

    @property
    def total(self) -> int:
        return sum(self.scores.values())


def checked_rating(
    session_uid: str, rater: str, instrument_name: str, scores: Mapping[str, object]
) -> SessionRating:
    """A :class:`SessionRating` from raw input; :class:`CatalogError` naming the problem."""
    rater = rater.strip() if isinstance(rater, str) else rater
    if not isinstance(rater, str) or not RATER_NAME.match(rater):
        raise CatalogError(f"rater must be a name of 1-100 printable characters; got {rater!r}")
    if not isinstance(session_uid, str) or not session_uid.strip():
        raise CatalogError("a rating needs the id of the session it rates")
    try:
        spec = instrument(instrument_name)
        values = spec.checked(scores)
    except MetricsError as error:
        raise CatalogError(f"rating of session {session_uid!r} by {rater!r}: {error}") from None
    return SessionRating(session_uid.strip(), rater, spec, values)


def store_ratings(catalog: Catalog, ratings: list[SessionRating], replace: bool = False) -> int:
    """Store checked ratings in one transaction (all or nothing); returns how many. A rater who already
    rated a session with the instrument is refused (:class:`AlreadyExists`) unless ``replace``."""
    stamp = now()
    with catalog.session() as orm:
        for rating in ratings:
            session = catalog.recorded_session(orm, rating.session_uid)
            if has_rated(orm, session.id, rating.rater, rating.instrument.name):
                if not replace:
                    raise AlreadyExists(
                        f"{rating.rater!r} already rated session {rating.session_uid} with "
                        f"{rating.instrument.name}",
                        remedy=("replace-rating", rating.session_uid),
                    )
                forget_rating(orm, session.id, rating.rater, rating.instrument.name)
            rows = {**rating.scores, TOTAL: rating.total}
            orm.add_all(
                Rating(
                    session_id=session.id,
                    rater=rating.rater,
                    instrument=rating.instrument.name,
                    item=item,
                    score=float(score),
                    created_at=stamp,
                )
                for item, score in rows.items()
            )
            orm.flush()
    return len(ratings)


def add_rating(
    catalog: Catalog,
    session_uid: str,
    rater: str,
    instrument_name: str,
    scores: Mapping[str, object],
    replace: bool = False,
) -> SessionRating:
    """Check and store one rating; returns it."""
    rating = checked_rating(session_uid, rater, instrument_name, scores)
    store_ratings(catalog, [rating], replace)
    return rating


def read_ratings_csv(data: bytes, what: str) -> list[SessionRating]:
    """Ratings from CSV bytes: columns ``session_id``, ``rater``, ``instrument`` and one column per
    item of the instrument(s) used (``total`` optional, checked against the items). Every row is
    checked; the first bad one raises :class:`CatalogError` naming its line."""
    if len(data) > MAX_IMPORT_BYTES:
        raise CatalogError(
            f"{what}: {len(data)} bytes is more than a ratings file may hold ({MAX_IMPORT_BYTES})"
        )
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError:
        raise CatalogError(f"{what}: not UTF-8 text") from None
    reader = csv.DictReader(io.StringIO(text, newline=""))
    header = reader.fieldnames or []
    needed = {"session_id", "rater", "instrument"}
    if not needed <= set(header):
        raise CatalogError(
            f"{what}: needs the columns session_id, rater, instrument; found {', '.join(header)}"
        )
    if len(set(header)) != len(header):
        raise CatalogError(f"{what}: a column is named twice")
    ratings, seen = [], set()
    try:
        for line, row in enumerate(reader, start=2):
            if line - 1 > MAX_IMPORT_ROWS:
                raise CatalogError(f"{what}: more than {MAX_IMPORT_ROWS} rows")
            if None in row:
                raise CatalogError(f"{what} line {line}: more fields than columns")
            try:
                spec = instrument(row["instrument"] or "")
            except MetricsError as error:
                raise CatalogError(f"{what} line {line}: {error}") from None
            scores = {k: v for k, v in row.items() if k in (*spec.item_names, TOTAL) and v not in ("", None)}
            others = [
                k for k, v in row.items() if k not in needed and k not in scores and v not in ("", None)
            ]
            if others:
                raise CatalogError(f"{what} line {line}: {spec.name} has no item {others[0]!r}")
            try:
                rating = checked_rating(row["session_id"] or "", row["rater"] or "", spec.name, scores)
            except CatalogError as error:
                raise CatalogError(f"{what} line {line}: {error}") from None
            key = (rating.session_uid, rating.rater, spec.name)
            if key in seen:
                raise CatalogError(
                    f"{what} line {line}: {rating.rater!r} rates session {rating.session_uid} twice"
                )
            seen.add(key)
            ratings.append(rating)
    except csv.Error as error:
        raise CatalogError(f"{what}: not a CSV file ({error})") from None
    if not ratings:
        raise CatalogError(f"{what}: no ratings in the file")
    return ratings


def import_ratings(catalog: Catalog, path: Path, replace: bool = False) -> int:
    """Check every row of a ratings CSV, then store them all in one transaction."""
    if not path.is_file():
        raise CatalogError(f"no ratings file {str(path)!r}")
    return store_ratings(catalog, read_ratings_csv(path.read_bytes(), str(path)), replace)


def study_ratings(catalog: Catalog, study_name: str, instrument_name: str | None = None) -> pd.DataFrame:
    """A study's ratings, long: session_id (uid), participant_id, label, rater, instrument, item,
    score, created_at; in time order (a rater's latest rating last)."""
    with catalog.session() as orm:
        study = catalog.study(orm, study_name)
        named = None if instrument_name is None else instrument(instrument_name).name
        rows = study_rating_rows(orm, study.id, named)
    columns = ["session_id", "participant_id", "label", "rater", "instrument", "item", "score", "created_at"]
    return pd.DataFrame(rows, columns=columns)


def rater_pseudonyms(catalog: Catalog) -> dict[str, str]:
    """Each rater's stable pseudonym ("rater 1", "rater 2", ...), numbered by their first rating in the
    catalog: what a reader who must not see account names (a researcher) sees instead."""
    with catalog.session() as orm:
        raters = raters_in_order(orm)
    return {rater: f"rater {k}" for k, rater in enumerate(raters, start=1)}


def session_ratings(catalog: Catalog, session_uid: str, pseudonymous: bool = False) -> list[dict]:
    """One row per rater and instrument of a session: rater, instrument, when, total, items; the rater
    as their stable pseudonym (:func:`rater_pseudonyms`) when ``pseudonymous``."""
    with catalog.session() as orm:
        session = catalog.recorded_session(orm, session_uid)
        rows = session_rating_rows(orm, session.id)
    grouped: dict[tuple[str, str], dict] = {}
    for rater, name, item, score, created in rows:
        entry = grouped.setdefault(
            (rater, name), {"rater": rater, "instrument": name, "rated_at": created, "items": {}}
        )
        if item == TOTAL:
            entry["total"] = score
        else:
            entry["items"][item] = score
        entry["rated_at"] = max(entry["rated_at"], created) if isinstance(created, datetime) else created
    found = list(grouped.values())
    if pseudonymous and found:
        names = rater_pseudonyms(catalog)
        for entry in found:
            entry["rater"] = names[entry["rater"]]
    return found
