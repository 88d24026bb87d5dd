"""Sending xAPI statements to a Learning Record Store, losing nothing when it is away.

``push`` first writes what it is about to send to a spool on disk (one file per batch, written
whole and renamed into place), then drains the spool oldest first: a batch the LRS stored (200 or
204) leaves the spool and enters the ledger; an LRS that cannot be reached (connection refused,
timeout, 5xx) leaves the batch, and every later one, spooled for the next push; a batch the LRS
refuses (400: a statement it finds invalid, 409: a different statement under the same id, 401/403:
credentials) is moved to ``rejected/`` with the LRS's answer and reported as a one-line error.

The ledger (per endpoint) remembers each statement's key and id: a statement already sent is not
sent again, and one whose content changed since (a rescore, a new benchmark) is sent together with
a ``voided`` statement for the id it replaces, as xAPI asks (statements are immutable). Statement
ids are deterministic (sessions.exchange.xapi), so sending again what the ledger forgot stores nothing twice.
"""

from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import httpx

from sessions.catalog import CatalogError
from sessions.exchange.xapi import Statement, XapiSettings, study_statements, voiding

XAPI_VERSION = "1.0.3"
BATCH = 50


class LrsError(CatalogError):
    """The LRS could not take the statements."""


class LrsUnreachable(LrsError):
    """The LRS did not answer (or answered with a server error): the statements stay spooled."""


class LrsRejected(LrsError):
    """The LRS refused a batch: it was moved aside with the LRS's answer."""


@dataclass(frozen=True)
class LrsEndpoint:
    """Where statements go: the xAPI endpoint (``https://lrs.example/xAPI/``) and its basic-auth key
    and secret."""

    url: str
    key: str
    secret: str = field(repr=False)

    def __post_init__(self) -> None:
        if not self.url.startswith(("http://", "https://")):
            raise LrsError(f"the LRS endpoint must be an http(s) address; got {self.url!r}")
        if not self.key:
            raise LrsError("no LRS key (the basic-auth user the LRS gave vascsim)")

    @property
    def statements_url(self) -> str:
        return self.url.rstrip("/") + "/statements"

    @property
    def slug(self) -> str:
        """A folder name for this endpoint's spool and ledger."""
        return hashlib.sha256(f"{self.url.rstrip('/')}|{self.key}".encode()).hexdigest()[:16]


@dataclass
class PushResult:
    sent: int = 0
    voided: int = 0
    already_sent: int = 0
    spooled: int = 0  # left in the spool (the LRS was away)
    rejected: int = 0


class Outbox:
    """An endpoint's spool, rejected batches and ledger under ``folder``."""

    def __init__(self, folder: Path) -> None:
        self.folder = folder
        self.spool = folder / "spool"
        self.rejected = folder / "rejected"
        self.ledger_path = folder / "ledger.json"
        for path in (self.spool, self.rejected):
            path.mkdir(parents=True, exist_ok=True)

    def ledger(self) -> dict[str, str]:
        if not self.ledger_path.exists():
            return {}
        try:
            data = json.loads(self.ledger_path.read_text())
        except (OSError, ValueError) as error:
            raise LrsError(
                f"the LRS ledger {self.ledger_path} cannot be read ({error}); move it aside"
            ) from error
        if not isinstance(data, dict) or not all(isinstance(v, str) for v in data.values()):
            raise LrsError(f"the LRS ledger {self.ledger_path} is not a key -> id map; move it aside")
        return data

    def remember(self, ledger: dict[str, str], statements: list[dict[str, Any]], keys: list[str]) -> None:
        """Add a stored batch to ``ledger`` (the push's copy, read once) and write it whole."""
        for key, statement in zip(keys, statements, strict=True):
            ledger[key] = statement["id"]
        _write_whole(self.ledger_path, json.dumps(ledger, indent=0, sort_keys=True))

    def enqueue(self, statements: list[Statement]) -> None:
        existing = sorted(self.spool.glob("*.json"))
        number = int(existing[-1].stem) + 1 if existing else 1
        for start in range(0, len(statements), BATCH):
            chunk = statements[start : start + BATCH]
            payload = {"keys": [s.key for s in chunk], "statements": [s.body for s in chunk]}
            _write_whole(self.spool / f"{number:09d}.json", json.dumps(payload))
            number += 1

    def batches(self) -> Iterator[tuple[Path, list[str], list[dict[str, Any]]]]:
        for path in sorted(self.spool.glob("*.json")):
            try:
                payload = json.loads(path.read_text())
                keys, statements = payload["keys"], payload["statements"]
            except (OSError, ValueError, KeyError, TypeError) as error:
                raise LrsError(f"the spooled batch {path} cannot be read ({error}); move it aside") from error
            yield path, keys, statements

    def pending(self) -> int:
        return sum(len(statements) for _, _, statements in self.batches())


def _write_whole(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` so a crash leaves the old file or the new one, never half of one."""
    part = path.with_suffix(path.suffix + ".part")
    with open(part, "w") as out:
        out.write(text)
        out.flush()
        os.fsync(out.fileno())
    os.replace(part, path)


def plan(statements: list[Statement], ledger: dict[str, str], resend: bool = False) -> list[Statement]:
    """What to send: statements not in the ledger under their id (all of them with ``resend``), and a
    voiding statement for each id a changed statement replaces."""
    out: list[Statement] = []
    for statement in statements:
        known = ledger.get(statement.key)
        if known == statement.id and not resend:
            continue
        if known is not None and known != statement.id and f"void|{known}" not in ledger:
            out.append(voiding(known, statement.body["actor"], statement.body["timestamp"]))
        out.append(statement)
    return out


def push(
    statements: list[Statement],
    endpoint: LrsEndpoint,
    home: Path,
    resend: bool = False,
    client: httpx.Client | None = None,
    timeout: float = 10.0,
) -> PushResult:
    """Spool what the ledger has not seen, then drain the spool to the LRS (module docstring)."""
    outbox = Outbox(home / "lrs" / endpoint.slug)
    ledger = outbox.ledger()
    spooled = {statement["id"] for _, _, batch in outbox.batches() for statement in batch}
    todo = [s for s in plan(statements, ledger, resend) if s.id not in spooled]
    result = PushResult(already_sent=len(statements) - sum(1 for s in todo if not s.key.startswith("void|")))
    outbox.enqueue(todo)
    own = client is None
    client = client or httpx.Client(timeout=timeout)
    try:
        for path, keys, batch in outbox.batches():
            _send(client, endpoint, path, batch, outbox)
            outbox.remember(ledger, batch, keys)
            path.unlink()
            result.sent += len(batch)
            result.voided += sum(1 for key in keys if key.startswith("void|"))
    except LrsUnreachable:
        result.spooled = outbox.pending()
        raise
    finally:
        if own:
            client.close()
    return result


def _send(
    client: httpx.Client, endpoint: LrsEndpoint, path: Path, batch: list[dict[str, Any]], outbox: Outbox
) -> None:
    try:
        answer = client.post(
            endpoint.statements_url,
            json=batch,
            auth=(endpoint.key, endpoint.secret),
            headers={"X-Experience-API-Version": XAPI_VERSION},
        )
    except httpx.HTTPError as error:
        raise LrsUnreachable(
            f"the LRS at {endpoint.url} did not answer ({type(error).__name__}); "
            f"{outbox.pending()} statements stay spooled in {outbox.spool} and go with the next push"
        ) from error
    if answer.status_code in (200, 204):
        return
    if answer.status_code >= 500 or answer.status_code == 429:
        raise LrsUnreachable(
            f"the LRS at {endpoint.url} answered {answer.status_code}; {outbox.pending()} statements stay "
            f"spooled in {outbox.spool} and go with the next push"
        )
    detail = _detail(answer)
    aside = outbox.rejected / path.name
    _write_whole(
        aside,
        json.dumps({"status": answer.status_code, "answer": detail, "batch": json.loads(path.read_text())}),
    )
    path.unlink()
    raise LrsRejected(
        f"the LRS at {endpoint.url} refused {len(batch)} statements ({answer.status_code}: {detail[:200]}); "
        f"kept in {aside}"
    )


def _detail(answer: httpx.Response) -> str:
    try:
        data = answer.json()
    except ValueError:
        return answer.text.strip().replace("\n", " ") or answer.reason_phrase
    detail = data.get("detail", data) if isinstance(data, dict) else data
    return json.dumps(detail) if not isinstance(detail, str) else detail


def read_statements(endpoint: LrsEndpoint, params: dict[str, str] | None = None) -> list[dict[str, Any]]:
    """Every statement the LRS returns for ``params`` (the xAPI query API), following ``more``."""
    out: list[dict[str, Any]] = []
    headers = {"X-Experience-API-Version": XAPI_VERSION}
    with httpx.Client(timeout=10.0) as client:
        url: str | None = endpoint.statements_url
        query = dict(params or {})
        origin = httpx.URL(endpoint.url)
        while url:
            answer = client.get(url, params=query, auth=(endpoint.key, endpoint.secret), headers=headers)
            if answer.status_code != 200:
                raise LrsError(
                    f"the LRS at {endpoint.url} answered {answer.status_code}: {_detail(answer)[:200]}"
                )
            data = answer.json()
            out += data.get("statements", [])
            more = data.get("more") or ""
            url = str(origin.join(more)) if more else None
            query = {}
    return out


# -- a study's LRS, configured once ------------------------------------------------------------
@dataclass(frozen=True)
class StudyLrs:
    """Where a study's statements go: endpoint, key, the actors' home page, and whether every
    scoring of one of its sessions pushes (``auto``). The secret is never stored: it is read from
    VASCSIM_LRS_SECRET when a push happens."""

    endpoint: str
    key: str
    home_page: str
    activity_base: str = "https://vascsim.org/xapi"
    auto: bool = False


def _configured_path(home: Path) -> Path:
    return home / "lrs" / "studies.json"


def configured(home: Path) -> dict[str, StudyLrs]:
    path = _configured_path(home)
    if not path.exists():
        return {}
    try:
        data = json.loads(path.read_text())
        return {study: StudyLrs(**fields) for study, fields in data.items()}
    except (OSError, ValueError, TypeError) as error:
        raise LrsError(f"the LRS configuration {path} cannot be read ({error}); configure again") from error


def configure(home: Path, study: str, settings: StudyLrs) -> None:
    """Store the study's LRS (checked first: a bad endpoint or home page is refused, nothing stored)."""

    LrsEndpoint(settings.endpoint, settings.key, "")
    XapiSettings(settings.home_page, settings.activity_base)
    every = {name: vars(value) for name, value in configured(home).items()}
    every[study] = vars(settings)
    path = _configured_path(home)
    path.parent.mkdir(parents=True, exist_ok=True)
    _write_whole(path, json.dumps(every, indent=1, sort_keys=True))


def push_study(catalog: Any, home: Path, study: str, secret: str, resend: bool = False) -> PushResult:
    """Push the study's statements to its configured LRS."""

    settings = configured(home).get(study)
    if settings is None:
        raise LrsError(f"study {study!r} has no LRS configured")
    statements = study_statements(catalog, study, XapiSettings(settings.home_page, settings.activity_base))
    return push(statements, LrsEndpoint(settings.endpoint, settings.key, secret), home, resend=resend)
