"""Who is asking: sign-in cookies, roles, CSRF tokens and the sign-in rate limit."""

from __future__ import annotations

import secrets
import threading
import time
from collections import deque
from dataclasses import dataclass

from fastapi import Depends, Request
from starlette.concurrency import run_in_threadpool

from dashboard.errors import DashboardError, forbidden
from sessions.store import Scope

COOKIE = "vascsim_login"
PRE_LOGIN_COOKIE = "vascsim_prelogin"  # double-submit CSRF token of the sign-in form
CSRF_HEADER = "x-csrf-token"
UNSAFE_METHODS = ("POST", "PUT", "PATCH", "DELETE")
FORM_TYPES = ("application/x-www-form-urlencoded", "multipart/form-data")


@dataclass(frozen=True, kw_only=True)
class Viewer(Scope):
    """The signed-in user as every query sees them: their :class:`sessions.store.Scope` (role, a
    trainee's own participants) with who they are and their sign-in's CSRF token."""

    user_id: int
    username: str
    csrf_token: str


class LoginRateLimiter:
    """At most ``attempts`` failed sign-ins per key within ``window_s`` seconds (a sliding window)."""

    def __init__(self, attempts: int, window_s: float) -> None:
        self.attempts, self.window_s = attempts, window_s
        self._failures: dict[str, deque[float]] = {}
        self._lock = threading.Lock()

    def _recent(self, key: str, at: float) -> deque[float]:
        failures = self._failures.setdefault(key, deque())
        while failures and failures[0] <= at - self.window_s:
            failures.popleft()
        return failures

    def retry_after(self, key: str, at: float | None = None) -> float:
        """Seconds until ``key`` may try again (0 when it may now)."""
        at = time.monotonic() if at is None else at
        with self._lock:
            failures = self._recent(key, at)
            if len(failures) < self.attempts:
                return 0.0
            return failures[0] + self.window_s - at

    def claim(self, key: str, at: float | None = None) -> float:
        """Take one attempt for ``key`` before the password is checked: 0 when it may try (the attempt
        counts as failed until :meth:`succeeded` clears it), else the seconds to wait. Counted under
        the lock, so concurrent attempts cannot all pass the check before any failure is recorded."""
        at = time.monotonic() if at is None else at
        with self._lock:
            failures = self._recent(key, at)
            if len(failures) >= self.attempts:
                return failures[0] + self.window_s - at
            failures.append(at)
            return 0.0

    def failed(self, key: str, at: float | None = None) -> None:
        at = time.monotonic() if at is None else at
        with self._lock:
            self._recent(key, at).append(at)

    def succeeded(self, key: str) -> None:
        with self._lock:
            self._failures.pop(key, None)


def limiter_key(request: Request, username: str) -> str:
    address = request.client.host if request.client else "?"
    return f"{username.lower()}|{address}"


def optional_viewer(request: Request) -> Viewer | None:
    token = request.cookies.get(COOKIE)
    if not token:
        return None
    found = request.app.state.store.signed_in(token)
    if found is None:
        return None
    user, csrf = found
    owned = frozenset(user.participant_ids) if user.role == "trainee" else frozenset()
    return Viewer(
        role=user.role, participant_ids=owned, user_id=user.id, username=user.username, csrf_token=csrf
    )


async def current_viewer(request: Request) -> Viewer:
    """The signed-in user (401 otherwise); unsafe methods also need the sign-in's CSRF token, from the
    ``X-CSRF-Token`` header (scripts, API) or the ``csrf_token`` form field (HTML forms)."""
    viewer = await run_in_threadpool(optional_viewer, request)
    if viewer is None:
        raise DashboardError(401, "sign in first")
    if request.method in UNSAFE_METHODS:
        await check_csrf(request, viewer.csrf_token)
    return viewer


async def check_csrf(request: Request, expected: str) -> None:
    sent = request.headers.get(CSRF_HEADER, "")
    if not sent and request.headers.get("content-type", "").startswith(FORM_TYPES):
        value = (await request.form()).get("csrf_token", "")
        sent = value if isinstance(value, str) else ""
    if not expected or not secrets.compare_digest(sent.encode(), expected.encode()):
        raise DashboardError(403, "missing or wrong CSRF token; reload the page and try again")


def require(*roles: str):
    """A dependency admitting only ``roles``."""

    def check(viewer: Viewer = Depends(current_viewer)) -> Viewer:  # noqa: B008
        if viewer.role not in roles:
            raise forbidden("this page")
        return viewer

    return check
