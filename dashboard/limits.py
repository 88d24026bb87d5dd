"""How much a request may send: a body limit on every dashboard route (the ingest application under
``/ingest`` keeps its own, per stream). Signing in and the HTML forms are small; the JSON API is
larger. A body over its limit is refused with 413 as soon as its declared length, or the bytes read
so far, exceed it: a 256 MiB password is never read into memory."""

from __future__ import annotations

from dashboard.error_pages import error_response

SIGN_IN_BYTES = 16 * 1024
"""Signing in: a user name and a password (at most 1,024 characters) with room to spare."""
FORM_BYTES = 256 * 1024
"""An HTML form (ratings, administration, a study's description)."""
API_BYTES = 1024 * 1024
"""A JSON API body (a rating, an annotation, an account)."""


def body_limit(path: str) -> int | None:
    """The body limit of a route (bytes); None where the route keeps its own (ingest)."""
    if path == "/ingest" or path.startswith("/ingest/"):
        return None
    if path in ("/api/login", "/login"):
        return SIGN_IN_BYTES
    if path.startswith("/api/"):
        return API_BYTES
    return FORM_BYTES


class BodyLimit:
    """ASGI middleware: a body whose declared length, or whose bytes as they arrive, exceed
    :func:`body_limit` is answered 413 in the dashboard's error shape before the route sees it (the
    body, at most the limit, is read here and handed on whole)."""

    def __init__(self, app) -> None:
        self.app = app

    async def __call__(self, scope, receive, send) -> None:
        limit = body_limit(scope["path"]) if scope["type"] == "http" else None
        if limit is None:
            await self.app(scope, receive, send)
            return
        declared = dict(scope.get("headers") or ()).get(b"content-length", b"")
        if declared.isdigit() and int(declared) > limit:
            await _refuse(scope, receive, send, limit)
            return
        chunks, seen = [], 0
        while True:
            message = await receive()
            if message["type"] != "http.request":  # the client went away: nothing to answer
                return
            chunks.append(message.get("body", b""))
            seen += len(chunks[-1])
            if seen > limit:
                await _refuse(scope, receive, send, limit)
                return
            if not message.get("more_body", False):
                break
        handed = False

        async def whole():
            nonlocal handed
            if handed:
                return await receive()
            handed = True
            return {"type": "http.request", "body": b"".join(chunks), "more_body": False}

        await self.app(scope, whole, send)


async def _refuse(scope, receive, send, limit: int) -> None:
    from starlette.requests import Request

    message = f"request body over the {limit:,}-byte limit of this address"
    response = await error_response(Request(scope, receive), 413, message)
    await response(scope, receive, send)
