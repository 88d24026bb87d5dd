"""Who is asking: sign-in cookies, roles, CSRF tokens and the sign-in rate limit."""

from __future__ import annotations

import secrets
import threading
import time
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass

from fastapi import Depends, Request
from starlette.concurrency import run_in_threadpool

from dashboard.errors import DashboardError, forbidden
from sessions.catalog.store import Scope

COOKIE = "vascsim_login"
PRE_LOGIN_COOKIE = "vascsim_prelogin"  # double-submit CSRF token of the sign-in form
CSRF_HEADER = "x-csrf-token"
UNSAFE_METHODS = ("POST", "PUT", "PATCH", "DELETE")
FORM_TYPES = ("application/x-www-form-urlencoded", "multipart/form-data")


@dataclass(frozen=True, kw_only=True)
class Viewer(Scope):
    """The signed-in user as every query sees them: their :class:`sessions.catalog.store.Scope` (role, a
    trainee's own participants) with who they are and their sign-in's CSRF token."""

    user_id: int
    username: str
    csrf_token: str


ACCOUNT_SPREAD = 4
"""Failed sign-ins for one account from all addresses together: this many times the per-address limit
(guessing from many addresses at once is throttled per account)."""
ADDRESS_SPREAD = 10
"""Failed sign-ins from one address over all accounts together: this many times the per-account
limit (one address trying many names; generous, as a course's lab shares one address)."""


class LoginRateLimiter:
    """At most ``attempts`` failed sign-ins per key within ``window_s`` seconds (a sliding window);
    a sign-in claims several keys at once (:func:`sign_in_keys`), each with its own limit."""

    def __init__(self, attempts: int, window_s: float) -> None:
        self.attempts, self.window_s = attempts, window_s
        self._failures: dict[str, deque[float]] = {}
        self._lock = threading.Lock()

    def _recent(self, key: str, at: float) -> deque[float]:
        failures = self._failures.setdefault(key, deque())
        while failures and failures[0] <= at - self.window_s:
            failures.popleft()
        return failures

    def _limited(self, keys: str | Sequence[tuple[str, int]]) -> list[tuple[str, int]]:
        return [(keys, self.attempts)] if isinstance(keys, str) else list(keys)

    def retry_after(self, keys: str | Sequence[tuple[str, int]], at: float | None = None) -> float:
        """Seconds until ``keys`` (one key, or (key, limit) pairs) may try again (0 when they may now)."""
        at = time.monotonic() if at is None else at
        with self._lock:
            return self._wait(self._limited(keys), at)

    def _wait(self, keys: list[tuple[str, int]], at: float) -> float:
        waits = [
            failures[len(failures) - limit] + self.window_s - at
            for key, limit in keys
            if len(failures := self._recent(key, at)) >= limit
        ]
        return max(waits, default=0.0)

    def claim(self, keys: str | Sequence[tuple[str, int]], at: float | None = None) -> float:
        """Take one attempt on every key before the password is checked: 0 when it may try (the
        attempt counts as failed until :meth:`succeeded` clears it), else the seconds to wait.
        Counted under the lock, so concurrent attempts cannot all pass the check before any
        failure is recorded, and no key is charged for an attempt another key refused."""
        at = time.monotonic() if at is None else at
        limited = self._limited(keys)
        with self._lock:
            wait = self._wait(limited, at)
            if wait > 0:
                return wait
            for key, _ in limited:
                self._recent(key, at).append(at)
            return 0.0

    def failed(self, key: str, at: float | None = None) -> None:
        at = time.monotonic() if at is None else at
        with self._lock:
            self._recent(key, at).append(at)

    def succeeded(self, keys: str | Sequence[tuple[str, int]], at: float | None = None) -> None:
        """A right password: the first key (this name from this address) starts afresh; the wider
        keys only lose the attempt claimed ``at`` (a success must not clear others' guesses)."""
        limited = self._limited(keys)
        with self._lock:
            self._failures.pop(limited[0][0], None)
            for key, _ in limited[1:]:
                failures = self._failures.get(key)
                if failures is not None and at is not None and at in failures:
                    failures.remove(at)


def sign_in_keys(request: Request, username: str, attempts: int) -> tuple[tuple[str, int], ...]:
    """The limiter keys a sign-in claims, with their limits: this name from this address
    (``attempts``), this name from anywhere, and this address for any name."""
    address = request.client.host if request.client else "?"
    name = username.lower()
    return (
        (f"{name}|{address}", attempts),
        (f"account:{name}", attempts * ACCOUNT_SPREAD),
        (f"address:{address}", attempts * ADDRESS_SPREAD),
    )


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
