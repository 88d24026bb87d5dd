"""Rating sessions in the browser: a GRS or OSATS form beside the replay, open or blinded.

Blinded rating (``/studies/{id}/rate``): the rater sees a queue of the study's sessions under
opaque names and, for each, the replay and the task only: no participant, group, trial, date or
session id (the session id names the participant). A blinded session is addressed by a token, an
HMAC of its id under a key the server draws at start-up, so the id cannot be read from the
address, the video's address or the page. Open rating (``/sessions/{uid}/rate``) shows who it is.
Every rating goes through :func:`sessions.ratings.add_rating` with the signed-in user as the rater.
"""

from __future__ import annotations

import hashlib
import hmac
from typing import Annotated

from fastapi import APIRouter, Depends, Request
from fastapi.responses import FileResponse, HTMLResponse, RedirectResponse, Response
from sqlalchemy import select

from dashboard import access
from dashboard.auth import STAFF, Viewer, require
from dashboard.errors import DashboardError, not_found, status_of
from dashboard.pages import render
from dashboard.signals import replay_video
from metrics.instruments import INSTRUMENTS, instrument
from metrics.streams import MetricsError
from sessions.models import Participant, Rating, Session, Task
from sessions.ratings import add_rating, session_ratings
from sim.errors import VascsimError

router = APIRouter(include_in_schema=False)
Staff = Annotated[Viewer, Depends(require(*STAFF))]


def blind_token(request: Request, uid: str) -> str:
    """The opaque name of a session in blinded rating (stable while the server runs)."""
    return hmac.new(request.app.state.blind_key, uid.encode(), hashlib.sha256).hexdigest()[:24]


def _study_sessions(request: Request, viewer: Viewer, study_id: int) -> list[dict]:
    """The study's sessions in their blinded order (by token), each with its task and whether this
    rater has rated it."""
    with request.app.state.catalog.session() as orm:
        access.owned_study(orm, viewer, study_id, whole=True)
        rows = orm.execute(
            select(Session.uid, Task.name)
            .join(Participant, Session.participant_id == Participant.id)
            .join(Task, Session.task_id == Task.id)
            .where(Participant.study_id == study_id)
        ).all()
        rated = set(
            orm.scalars(
                select(Session.uid)
                .join(Rating, Rating.session_id == Session.id)
                .join(Participant, Session.participant_id == Participant.id)
                .where(Participant.study_id == study_id, Rating.rater == viewer.username)
            )
        )
    listed = [
        {"token": blind_token(request, uid), "task": task, "rated": uid in rated, "uid": uid}
        for uid, task in rows
    ]
    return sorted(listed, key=lambda row: row["token"])


def _unblind(request: Request, viewer: Viewer, token: str) -> tuple[str, int, str]:
    """(uid, study id, task) of a blinded token; not found for anything else."""
    if len(token) != 24 or not all(c in "0123456789abcdef" for c in token):
        raise not_found("session")
    with request.app.state.catalog.session() as orm:
        rows = orm.execute(
            select(Session.uid, Participant.study_id, Task.name)
            .join(Participant, Session.participant_id == Participant.id)
            .join(Task, Session.task_id == Task.id)
            .where(access.session_filter(viewer))
        ).all()
    for uid, study_id, task in rows:
        if hmac.compare_digest(blind_token(request, uid), token):
            return uid, study_id, task
    raise not_found("session")


def _chosen(name: str | None) -> str:
    try:
        return instrument(name or "GRS").name
    except MetricsError as error:
        raise DashboardError(422, str(error)) from None


def _form_page(
    request: Request,
    viewer: Viewer,
    *,
    uid: str,
    blind: bool,
    action: str,
    back: str,
    task: str,
    instrument_name: str,
    video: str | None,
    message: str | None = None,
    status: int = 200,
    who: dict | None = None,
) -> Response:
    mine = [r for r in session_ratings(request.app.state.catalog, uid) if r["rater"] == viewer.username]
    page = render(
        request,
        "rate.html",
        viewer,
        blind=blind,
        action=action,
        back=back,
        task=task,
        instrument=INSTRUMENTS[instrument_name],
        instruments=list(INSTRUMENTS),
        video=video,
        message=message,
        mine=[r for r in mine if r["instrument"] == instrument_name],
        who=who,
    )
    page.status_code = status
    return page


async def _submitted(request: Request, viewer: Viewer, uid: str, instrument_name: str) -> str | None:
    """Store the posted rating; the error message when refused (nothing stored), else None."""
    form = await request.form()
    spec = INSTRUMENTS[instrument_name]
    scores = {name: form.get(name) for name in spec.item_names if form.get(name) not in (None, "")}
    try:
        add_rating(
            request.app.state.catalog, uid, viewer.username, spec.name, scores, form.get("replace") == "yes"
        )
    except VascsimError as error:
        return str(error) if status_of(error) != 404 else "session not found"
    return None


@router.get("/studies/{study_id}/rate", response_class=HTMLResponse)
def rating_queue(request: Request, study_id: int, viewer: Staff, rated: str | None = None) -> Response:
    sessions = _study_sessions(request, viewer, study_id)
    for number, row in enumerate(sessions, start=1):
        row["name"] = f"Session {number}"
        row.pop("uid")
    return render(
        request, "rate_queue.html", viewer, study_id=study_id, sessions=sessions, rated=rated is not None
    )


@router.get("/rate/{token}", response_class=HTMLResponse)
def blinded_form(request: Request, token: str, viewer: Staff, instrument: str | None = None) -> Response:
    uid, study_id, task = _unblind(request, viewer, token)
    has_video = replay_video(request.app.state.settings.home, uid) is not None
    return _form_page(
        request,
        viewer,
        uid=uid,
        blind=True,
        action=f"/rate/{token}",
        back=f"/studies/{study_id}/rate",
        task=task,
        instrument_name=_chosen(instrument),
        video=f"/rate/{token}/video" if has_video else None,
    )


@router.post("/rate/{token}", response_class=HTMLResponse)
async def blinded_submit(
    request: Request, token: str, viewer: Staff, instrument: str | None = None
) -> Response:
    uid, study_id, task = _unblind(request, viewer, token)
    chosen = _chosen(instrument)
    problem = await _submitted(request, viewer, uid, chosen)
    if problem is None:
        return RedirectResponse(f"/studies/{study_id}/rate?rated=1", status_code=303)
    has_video = replay_video(request.app.state.settings.home, uid) is not None
    return _form_page(
        request,
        viewer,
        uid=uid,
        blind=True,
        action=f"/rate/{token}",
        back=f"/studies/{study_id}/rate",
        task=task,
        instrument_name=chosen,
        video=f"/rate/{token}/video" if has_video else None,
        message=problem,
        status=400 if "already rated" not in problem else 409,
    )


@router.get("/rate/{token}/video")
def blinded_video(request: Request, token: str, viewer: Staff) -> FileResponse:
    uid, _, _ = _unblind(request, viewer, token)
    path = replay_video(request.app.state.settings.home, uid)
    if path is None:
        raise not_found("video")
    return FileResponse(path, media_type="video/mp4" if path.suffix == ".mp4" else "video/webm")


def _open_context(request: Request, viewer: Viewer, uid: str) -> tuple[str, dict]:
    with request.app.state.catalog.session() as orm:
        row = access.owned_session(orm, viewer, uid)
        participant = orm.get(Participant, row.participant_id)
        task = orm.get(Task, row.task_id)
        who = {
            "code": participant.code,
            "group": participant.group_label,
            "trial": row.trial,
            "id": participant.id,
        }
        return task.name, who


@router.get("/sessions/{uid}/rate", response_class=HTMLResponse)
def open_form(request: Request, uid: str, viewer: Staff, instrument: str | None = None) -> Response:
    task, who = _open_context(request, viewer, uid)
    has_video = replay_video(request.app.state.settings.home, uid) is not None
    return _form_page(
        request,
        viewer,
        uid=uid,
        blind=False,
        action=f"/sessions/{uid}/rate",
        back=f"/sessions/{uid}",
        task=task,
        instrument_name=_chosen(instrument),
        video=f"/api/sessions/{uid}/video" if has_video else None,
        who=who,
    )


@router.post("/sessions/{uid}/rate", response_class=HTMLResponse)
async def open_submit(request: Request, uid: str, viewer: Staff, instrument: str | None = None) -> Response:
    task, who = _open_context(request, viewer, uid)
    chosen = _chosen(instrument)
    problem = await _submitted(request, viewer, uid, chosen)
    if problem is None:
        return RedirectResponse(f"/sessions/{uid}", status_code=303)
    has_video = replay_video(request.app.state.settings.home, uid) is not None
    return _form_page(
        request,
        viewer,
        uid=uid,
        blind=False,
        action=f"/sessions/{uid}/rate",
        back=f"/sessions/{uid}",
        task=task,
        instrument_name=chosen,
        video=f"/api/sessions/{uid}/video" if has_video else None,
        message=problem,
        status=400 if "already rated" not in problem else 409,
        who=who,
    )
