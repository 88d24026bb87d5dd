"""How an error reaches the person who asked: a JSON body for the API and the ingest, a page (with
its navigation and Sign out) for a browser, a redirect to sign in for a 401; and the handlers that
map every error, by type (:func:`dashboard.errors.status_of`), to one of them."""

from __future__ import annotations

from fastapi import Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse, RedirectResponse, Response
from starlette.concurrency import run_in_threadpool
from starlette.exceptions import HTTPException as StarletteHTTPException

from dashboard.auth import optional_viewer
from dashboard.errors import DashboardError, error_body, said, status_of
from sim.errors import VascsimError


async def error_response(
    request: Request, status: int, message: str, headers: dict | None = None
) -> Response:
    if request.url.path.startswith("/api") or request.url.path.startswith("/ingest"):
        return JSONResponse(error_body(status, message), status_code=status, headers=headers)
    if status == 401:
        return RedirectResponse(f"/login?next={request.url.path}", status_code=303)
    try:  # the page keeps its navigation and Sign out
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
