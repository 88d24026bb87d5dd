"""The catalog's errors, by type: what a front-end maps to an HTTP status or an exit code (the
dashboard's ``status_of``), never by wording. Messages name the input and carry no front-end's advice
(a ``remedy`` says which, and each front-end words it)."""

from __future__ import annotations

import difflib

from sim.errors import VascsimError


class CatalogError(VascsimError):
    """The catalog cannot be opened, or a request names something it does not hold."""


class AlreadyExists(CatalogError):
    """What a request would create is already there (HTTP 409)."""


class WrongState(CatalogError):
    """The request is well formed but what it names is not in a state that allows it (HTTP 409)."""


class NotFound(CatalogError):
    """What a request names is not in the catalog (HTTP 404). ``kind`` says what was looked for
    ("study", "session", ...), so a front-end can say where to list them."""

    def __init__(
        self,
        kind: str,
        name: object,
        known: list[str] | None = None,
        where: str = "",
        noun: str = "",
        message: str = "",
    ) -> None:
        nearest = difflib.get_close_matches(str(name), known or [], n=1, cutoff=0.6)
        hint = f"; did you mean {nearest[0]!r}?" if nearest else ""
        super().__init__(message or f"no {noun or kind} {name!r}{where}{hint}")
        self.kind = kind


class Forbidden(CatalogError):
    """The request is refused to this user or station (HTTP 403)."""
