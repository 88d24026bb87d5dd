"""One error shape for every failure: ``{"error": {"status": 404, "message": "..."}}``.

API paths answer it as JSON; pages render the same message in HTML (and send a
signed-out browser to the sign-in page).
"""

from __future__ import annotations

import shlex

from sessions.catalog import AlreadyExists, Forbidden, NotFound, WrongState
from sim.errors import VascsimError


class DashboardError(VascsimError):
    """A request the dashboard refuses, with the HTTP status to answer."""

    def __init__(self, status: int, message: str) -> None:
        super().__init__(message)
        self.status = status
        self.message = message


def not_found(what: str) -> DashboardError:
    """The same answer for "does not exist" and "not yours": ids cannot be probed."""
    return DashboardError(404, f"{what} not found")


def forbidden(what: str) -> DashboardError:
    return DashboardError(403, f"{what} needs a different role")


def error_body(status: int, message: str) -> dict:
    return {"error": {"status": status, "message": message}}


ERROR_SCHEMA = {
    "description": "The one error shape",
    "content": {
        "application/json": {
            "schema": {
                "type": "object",
                "required": ["error"],
                "properties": {
                    "error": {
                        "type": "object",
                        "required": ["status", "message"],
                        "properties": {"status": {"type": "integer"}, "message": {"type": "string"}},
                    }
                },
            }
        }
    },
}
ERROR_RESPONSES = {status: ERROR_SCHEMA for status in (400, 401, 403, 404, 422, 429)}
CONFLICT = {409: ERROR_SCHEMA}
"""Documented on the routes that answer 409: what they would create exists, or the state forbids it."""


REMEDIES = {
    "replace-rating": "to replace it, tick “Replace my earlier rating” below",
    "score": "score its sessions first (`vascsim score --study {}` where the catalog is)",
    "recover": "recover it first (`vascsim recover {}` where the catalog is)",
}
"""A domain error's remedy (:attr:`sim.errors.VascsimError.remedy`) in a page's words."""
API_REMEDIES = {**REMEDIES, "replace-rating": 'to replace it, send "replace": true'}
"""The same for a caller of the JSON API."""


def said(error: VascsimError, api: bool = False) -> str:
    """The error's message with its remedy in the dashboard's words (a page's, or the API's)."""
    remedy = getattr(error, "remedy", None)
    words = API_REMEDIES if api else REMEDIES
    if remedy is None or remedy[0] not in words:
        return str(error)
    return f"{error}; {words[remedy[0]].format(shlex.quote(str(remedy[1])))}"  # pastes as shown


def status_of(error: VascsimError) -> int:
    """The HTTP status of a domain error, by its type: not found 404, forbidden 403, already there or
    in the wrong state 409, anything else the request's fault (400)."""
    if isinstance(error, NotFound):
        return 404
    if isinstance(error, Forbidden):
        return 403
    if isinstance(error, AlreadyExists | WrongState):
        return 409
    return 400
