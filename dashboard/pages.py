"""Server-rendered pages. Each gathers its data from :mod:`dashboard.queries` (the same calls as the API),
puts it in the page as JSON for the charts, and renders a template; forms carry the CSRF token."""

from __future__ import annotations

import json
import secrets
from typing import Annotated
from urllib.parse import quote

from fastapi import APIRouter, Depends, Form, Request
from fastapi.responses import HTMLResponse, RedirectResponse, Response
from pydantic import ValidationError
from starlette.concurrency import run_in_threadpool

from dashboard import queries
from dashboard.api import Id, NewStation, NewStudy, NewUser, sign_in, sign_out
from dashboard.auth import (
    PRE_LOGIN_COOKIE,
    Viewer,
    check_csrf,
    current_viewer,
    optional_viewer,
    require,
)
from dashboard.errors import DashboardError, said, status_of
from dashboard.streams.signals import replay_video
from recorder.layout import SAMPLES_FILE
from sessions.catalog.models import ROLES
from sessions.catalog.store import STAFF
from sessions.scoring.ratings import session_ratings
from sessions.scoring.setting import set_standard
from sim.errors import VascsimError

router = APIRouter(include_in_schema=False)
Anyone = Annotated[Viewer, Depends(current_viewer)]
Staff = Annotated[Viewer, Depends(require(*STAFF))]
Admin = Annotated[Viewer, Depends(require("admin"))]
Watcher = Annotated[Viewer, Depends(require("admin", "supervisor"))]


def render(request: Request, template: str, viewer: Viewer | None, data: dict | None = None, **context):
    """A page; ``data`` goes into the page as JSON (read by static/app.js, never executed)."""
    page_data = json.dumps(data or {}, default=str).replace("</", "<\\/")
    return request.app.state.templates.TemplateResponse(
        request, template, {"viewer": viewer, "page_data": page_data, **context}
    )


def _safe_next(target: str | None) -> str:
    """Only same-site paths after sign-in (no open redirect)."""
    if not target or not target.startswith("/") or target.startswith("//") or "\\" in target:
        return "/"
    return target


@router.get("/login", response_class=HTMLResponse)
def login_page(request: Request, next: str = "/") -> Response:
    token = secrets.token_urlsafe(32)
    response = render(request, "login.html", None, next=_safe_next(next), csrf_token=token, error=None)
    response.set_cookie(
        PRE_LOGIN_COOKIE, token, httponly=True, samesite="strict", path="/login", max_age=3600
    )
    return response


@router.post("/login", response_class=HTMLResponse)
async def login_form(
    request: Request,
    username: Annotated[str, Form(max_length=64)],
    password: Annotated[str, Form(max_length=1024)],
    next: Annotated[str, Form(max_length=500)] = "/",
) -> Response:
    await check_csrf(request, request.cookies.get(PRE_LOGIN_COOKIE, ""))
    response = RedirectResponse(_safe_next(next), status_code=303)
    try:
        await run_in_threadpool(sign_in, request, response, username, password)
    except DashboardError as error:
        if error.status not in (401, 429):
            raise
        token = secrets.token_urlsafe(32)
        page = render(
            request, "login.html", None, next=_safe_next(next), csrf_token=token, error=error.message
        )
        page.status_code = error.status
        page.set_cookie(
            PRE_LOGIN_COOKIE, token, httponly=True, samesite="strict", path="/login", max_age=3600
        )
        return page
    response.delete_cookie(PRE_LOGIN_COOKIE, path="/login")
    return response


@router.post("/logout")
def logout_form(request: Request, viewer: Anyone) -> Response:
    response = RedirectResponse("/login", status_code=303)
    sign_out(request, response)
    return response


@router.get("/", response_class=HTMLResponse)
def home(request: Request) -> Response:
    viewer = optional_viewer(request)
    if viewer is None:
        return RedirectResponse("/login", status_code=303)
    store = request.app.state.store
    if viewer.is_trainee:
        mine = [(p.id, p.code) for p in store.my_participants(viewer)]
        if len(mine) == 1:
            return RedirectResponse(f"/participants/{mine[0][0]}", status_code=303)
        return render(request, "home.html", viewer, studies=[], participants=mine)
    return render(request, "home.html", viewer, studies=queries.studies(store, viewer), participants=[])


@router.get("/studies/{study_id}", response_class=HTMLResponse)
def study_page(request: Request, study_id: Id, viewer: Staff, standard: int | None = None) -> Response:
    return _study_view(
        request, viewer, study_id, done=None if standard is None else f"Standard v{standard} set."
    )


def _study_view(request: Request, viewer: Viewer, study_id: int, **shown) -> Response:
    """The study page, with ``shown`` (``done``, ``message``) beside the overview."""
    state = request.app.state
    overview = queries.study_overview(state.store, state.analyses, viewer, study_id)
    after = queries.ATTENTION_AFTER_TRIALS
    return render(request, "study.html", viewer, overview, overview=overview, attention_after=after, **shown)


@router.post("/studies/{study_id}/standards", response_class=HTMLResponse)
def set_study_standard(
    request: Request,
    study_id: Id,
    viewer: Watcher,
    task: Annotated[str, Form(max_length=100)],
    note: Annotated[str, Form(max_length=500)] = "",
) -> Response:
    """A supervisor sets a new version of the study's standard on ``task`` (as `vascsim standards
    set` does, signed with their name); refused, the study page again with why."""

    state = request.app.state
    study = state.store.study(study_id, viewer, whole=True)
    try:
        record = set_standard(state.catalog, study.name, task, viewer.username, note.strip())
    except VascsimError as error:
        page = _study_view(request, viewer, study_id, message=said(error))
        page.status_code = status_of(error)
        return page
    return RedirectResponse(f"/studies/{study_id}?standard={record.version}", status_code=303)


@router.get("/studies/{study_id}/validity", response_class=HTMLResponse)
def validity_page(request: Request, study_id: Id, viewer: Staff) -> Response:
    state = request.app.state
    report = queries.validity_report(state.store, state.analyses, viewer, study_id)
    return render(request, "validity.html", viewer, report, report=report)


@router.get("/participants/{participant_id}", response_class=HTMLResponse)
def participant_page(request: Request, participant_id: Id, viewer: Anyone) -> Response:
    state = request.app.state
    progress = queries.participant_progress(state.store, state.analyses, viewer, participant_id)
    return render(request, "participant.html", viewer, progress, progress=progress)


@router.get("/sessions/{uid}", response_class=HTMLResponse)
def session_page(request: Request, uid: str, viewer: Anyone) -> Response:
    state = request.app.state
    detail = queries.session_detail(state.store, state.analyses, viewer, uid)
    has_video = replay_video(state.settings.home, uid) is not None
    has_samples = any(f["name"] == SAMPLES_FILE for f in detail["files"])
    data = {
        "uid": uid,
        "has_video": has_video,
        "has_samples": has_samples,
        "signal_bands": detail.get("signal_bands", {}),
    }
    ratings = (
        session_ratings(state.catalog, uid, pseudonymous=not viewer.sees_accounts)
        if viewer.role in STAFF
        else []
    )
    return render(
        request,
        "session.html",
        viewer,
        data,
        detail=detail,
        has_video=has_video,
        has_samples=has_samples,
        ratings=ratings,
    )


@router.get("/live", response_class=HTMLResponse)
def live_page(request: Request, viewer: Watcher) -> Response:
    state = request.app.state
    running = queries.recording_now(state.store, state.settings.ingest_root)
    return render(request, "live.html", viewer, running=running)


@router.get("/live/sessions/{uid}", response_class=HTMLResponse)
def live_session_page(request: Request, uid: str, viewer: Watcher) -> Response:
    source = f"/api/live/sessions/{quote(uid)}"
    data = {"source": source, "scene": f"{source}/view.jpg"}
    return render(request, "live_view.html", viewer, data, title=f"session {uid}")


@router.get("/live/stations/{station}/{session_id}", response_class=HTMLResponse)
def live_station_page(request: Request, station: str, session_id: str, viewer: Watcher) -> Response:
    source = f"/api/live/stations/{quote(station)}/{quote(session_id)}"
    data = {"source": source, "scene": f"{source}/view.jpg"}
    return render(request, "live_view.html", viewer, data, title=f"station {station} / {session_id}")


# -- administration -----------------------------------------------------------------------
def _admin_page(request: Request, viewer: Viewer, message: str | None = None, token: dict | None = None):
    return render(
        request,
        "admin.html",
        viewer,
        users=[user.as_dict() for user in request.app.state.store.users()],
        stations=[station.as_dict() for station in request.app.state.store.stations()],
        roles=ROLES,
        participant_codes=request.app.state.store.participant_codes(),
        message=message,
        token=token,
    )


@router.get("/admin", response_class=HTMLResponse)
def admin_page(request: Request, viewer: Admin) -> Response:
    return _admin_page(request, viewer)


def _admin_action(request: Request, viewer: Viewer, action, done: str) -> Response:
    try:
        result = action()
    except (VascsimError, ValidationError) as error:
        status = getattr(error, "status", None)
        status = status or (status_of(error) if isinstance(error, VascsimError) else 422)
        if isinstance(error, ValidationError):
            message = "; ".join(f"{'.'.join(map(str, e['loc']))}: {e['msg']}" for e in error.errors())
        else:
            message = said(error)
        page = _admin_page(request, viewer, message=message)
        page.status_code = status
        return page
    return _admin_page(request, viewer, message=done, token=result if "token" in (result or {}) else None)


@router.post("/admin/users", response_class=HTMLResponse)
def admin_create_user(
    request: Request,
    viewer: Admin,
    username: Annotated[str, Form(max_length=64)],
    password: Annotated[str, Form(max_length=1024)],
    role: Annotated[str, Form(max_length=16)] = "",
    participants: Annotated[str, Form(max_length=2000)] = "",
) -> Response:
    def create():
        if role not in ROLES:
            raise DashboardError(422, f"choose a role: one of {', '.join(ROLES)}")
        form = NewUser(
            username=username, password=password, role=role, participants=_written_participants(participants)
        )
        store = request.app.state.store
        return store.create_user(form.username, form.password, form.role, form.participants).as_dict()

    return _admin_action(request, viewer, create, f"created user {username!r}")


def _written_participants(text: str) -> list[str]:
    """STUDY:CODE entries from a form field, separated by commas or spaces."""
    return [part for part in text.replace(",", " ").split() if part]


@router.post("/admin/users/{user_id}/participants", response_class=HTMLResponse)
def admin_link_participants(
    request: Request,
    user_id: Id,
    viewer: Admin,
    participants: Annotated[str, Form(max_length=2000)] = "",
) -> Response:
    def link():
        store = request.app.state.store
        return store.set_user_participants(user_id, _written_participants(participants)).as_dict()

    return _admin_action(request, viewer, link, "participants linked")


@router.post("/admin/users/{user_id}", response_class=HTMLResponse)
def admin_change_user(
    request: Request,
    user_id: Id,
    viewer: Admin,
    active: Annotated[str, Form(max_length=5)] = "",
    role: Annotated[str, Form(max_length=16)] = "",
) -> Response:
    def change():
        if role and role not in ROLES:
            raise DashboardError(422, f"role {role!r} is not one of {', '.join(ROLES)}")
        wanted = None if not active else active == "true"
        return request.app.state.store.change_user(user_id, viewer.user_id, role or None, wanted).as_dict()

    return _admin_action(request, viewer, change, "account updated")


@router.post("/admin/stations", response_class=HTMLResponse)
def admin_create_station(
    request: Request, viewer: Admin, station: Annotated[str, Form(max_length=64)]
) -> Response:
    return _admin_action(
        request,
        viewer,
        lambda: request.app.state.store.issue_station_token(NewStation(station=station).station),
        "token issued",
    )


@router.post("/admin/stations/{token_id}/revoke", response_class=HTMLResponse)
def admin_revoke_station(request: Request, token_id: Id, viewer: Admin) -> Response:
    return _admin_action(
        request,
        viewer,
        lambda: request.app.state.store.revoke_station_token(token_id).as_dict(),
        "token revoked",
    )


@router.post("/admin/studies", response_class=HTMLResponse)
def admin_create_study(
    request: Request,
    viewer: Admin,
    name: Annotated[str, Form(max_length=200)],
    description: Annotated[str, Form(max_length=5000)] = "",
) -> Response:
    return _admin_action(
        request,
        viewer,
        lambda: _new_study(request, NewStudy(name=name, description=description)),
        f"created study {name!r}",
    )


def _new_study(request: Request, form: NewStudy) -> dict:
    return request.app.state.store.create_study(form.name, form.description).as_dict()
