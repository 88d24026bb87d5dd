"""One error shape for every failure: ``{"error": {"status": 404, "message": "..."}}``.

API paths answer it as JSON; pages render the same message in HTML (and send a
signed-out browser to the sign-in page).
"""

from __future__ import annotations

import shlex

from fastapi import Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse, RedirectResponse, Response
from starlette.concurrency import run_in_threadpool
from starlette.exceptions import HTTPException as StarletteHTTPException

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


async def error_response(
    request: Request, status: int, message: str, headers: dict | None = None
) -> Response:
    if request.url.path.startswith("/api") or request.url.path.startswith("/ingest"):
        return JSONResponse(error_body(status, message), status_code=status, headers=headers)
    if status == 401:
        return RedirectResponse(f"/login?next={request.url.path}", status_code=303)
    from dashboard.auth import optional_viewer  # the page keeps its navigation and Sign out

    try:
        viewer = await run_in_threadpool(optional_viewer, request)
    except Exception:  # an error page never fails for want of its header
        viewer = None
    templates = request.app.state.templates
    context = {"status": status, "message": message, "viewer": viewer}
    return templates.TemplateResponse(request, "error.html", context, status_code=status, headers=headers)


def install_error_handlers(app) -> None:
    async def dashboard_error(request: Request, error: DashboardError) -> Response:
        headers = {"Retry-After": str(getattr(error, "retry_after", 1))} if error.status == 429 else None
        return await error_response(request, error.status, error.message, headers)

    async def vascsim_error(request: Request, error: VascsimError) -> Response:
        api = request.url.path.startswith(("/api", "/ingest"))
        return await error_response(request, status_of(error), said(error, api))

    async def http_error(request: Request, error: StarletteHTTPException) -> Response:
        return await error_response(request, error.status_code, str(error.detail))

    async def invalid(request: Request, error: RequestValidationError) -> Response:
        problems = "; ".join(
            f"{'.'.join(str(p) for p in item.get('loc', ()))}: {item.get('msg', '')}"
            for item in error.errors()
        )
        return await error_response(request, 422, f"invalid request: {problems}"[:500])

    async def crashed(request: Request, error: Exception) -> Response:
        return await error_response(request, 500, "internal error; the server log has the details")

    app.add_exception_handler(DashboardError, dashboard_error)
    app.add_exception_handler(VascsimError, vascsim_error)
    app.add_exception_handler(StarletteHTTPException, http_error)
    app.add_exception_handler(RequestValidationError, invalid)
    app.add_exception_handler(Exception, crashed)
