"""Rating sessions in the browser: a GRS or OSATS form beside the replay, open or blinded.

Blinded rating (``/studies/{id}/rate``): the rater sees a queue of the study's sessions under
opaque names and, for each, the replay and the task only: no participant, group, trial, date or
session id (the session id names the participant). A blinded session is addressed by a token, an
HMAC of its id under a key the server draws at start-up, so the id cannot be read from the
address, the video's address or the page. The video is the blind render
(:mod:`metrics.replay.blind`: the session alone, without names, ghost, judging colours or readouts),
never the replay a supervisor reviews; without one, the page offers to render it. Open rating
(``/sessions/{uid}/rate``) shows who it is.
Every rating goes through :func:`sessions.scoring.ratings.add_rating` with the signed-in user as the rater.
"""

from __future__ import annotations

import hashlib
import hmac
from dataclasses import dataclass
from typing import Annotated

from fastapi import APIRouter, Depends, Request
from fastapi.responses import FileResponse, HTMLResponse, RedirectResponse, Response

from dashboard.api import Id
from dashboard.auth import Viewer, require
from dashboard.errors import DashboardError, not_found, said, status_of
from dashboard.pages import render
from dashboard.streams.signals import inside, replay_video
from metrics.errors import MetricsError
from metrics.instruments import INSTRUMENTS, instrument
from sessions.catalog.store import STAFF
from sessions.replaying import blind_replay_path
from sessions.scoring.ratings import add_rating, session_ratings
from sim.errors import VascsimError

router = APIRouter(include_in_schema=False)
Staff = Annotated[Viewer, Depends(require(*STAFF))]


def blind_token(request: Request, uid: str) -> str:
    """The opaque name of a session in blinded rating (stable while the server runs)."""
    return hmac.new(request.app.state.blind_key, uid.encode(), hashlib.sha256).hexdigest()[:24]


def _study_sessions(request: Request, viewer: Viewer, study_id: int) -> list[dict]:
    """The study's sessions in their blinded order (by token), each with its task and whether this
    rater has rated it."""
    rows = request.app.state.store.rating_queue(study_id, viewer, viewer.username)
    listed = [
        {"token": blind_token(request, uid), "task": task, "rated": rated, "uid": uid}
        for uid, task, rated in rows
    ]
    return sorted(listed, key=lambda row: row["token"])


def _unblind(request: Request, viewer: Viewer, token: str) -> tuple[str, int, str]:
    """(uid, study id, task) of a blinded token; not found for anything else."""
    if len(token) != 24 or not all(c in "0123456789abcdef" for c in token):
        raise not_found("session")
    rows = request.app.state.store.visible_session_keys(viewer)
    for uid, study_id, task in rows:
        if hmac.compare_digest(blind_token(request, uid), token):
            return uid, study_id, task
    raise not_found("session")


def _chosen(name: str | None) -> str:
    try:
        return instrument(name or "GRS").name
    except MetricsError as error:
        raise DashboardError(422, str(error)) from None


@dataclass(frozen=True)
class _Target:
    """What a rating page is about and where it leads: blinded (by token) or open (by id)."""

    uid: str
    blind: bool
    action: str  # where the form posts
    back: str  # where "Back" and a stored rating lead
    task: str
    video: str | None  # the replay's address, or None when none is rendered
    who: dict | None = None  # participant, group and trial (open rating only)


def _blind_video(request: Request, uid: str):
    """The session's blind render, or None while there is none."""
    home = request.app.state.settings.home
    path = blind_replay_path(home, uid)
    return inside(home, path) if path.is_file() else None


def _blinded(request: Request, viewer: Viewer, token: str) -> _Target:
    uid, study_id, task = _unblind(request, viewer, token)
    video = f"/rate/{token}/video" if _blind_video(request, uid) is not None else None
    return _Target(uid, True, f"/rate/{token}", f"/studies/{study_id}/rate", task, video)


def _open(request: Request, viewer: Viewer, uid: str) -> _Target:
    facts = request.app.state.store.session_facts(uid, viewer)
    task = facts.session.task
    who = {
        "code": facts.session.participant,
        "group": facts.group,
        "trial": facts.session.trial,
        "id": facts.participant_id,
    }
    has_video = replay_video(request.app.state.settings.home, uid) is not None
    video = f"/api/sessions/{uid}/video" if has_video else None
    return _Target(uid, False, f"/sessions/{uid}/rate", f"/sessions/{uid}", task, video, who)


def _form_page(
    request: Request,
    viewer: Viewer,
    target: _Target,
    instrument_name: str,
    problem: VascsimError | None = None,
) -> Response:
    mine = [
        r for r in session_ratings(request.app.state.catalog, target.uid) if r["rater"] == viewer.username
    ]
    page = render(
        request,
        "rate.html",
        viewer,
        blind=target.blind,
        action=target.action,
        back=target.back,
        task=target.task,
        instrument=INSTRUMENTS[instrument_name],
        instruments=list(INSTRUMENTS),
        video=target.video,
        message=None if problem is None else said(problem),
        mine=[r for r in mine if r["instrument"] == instrument_name],
        who=target.who,
    )
    if problem is not None:
        page.status_code = status_of(problem)
    return page


async def _submit(
    request: Request, viewer: Viewer, target: _Target, instrument: str | None, done: str
) -> Response:
    """Store the posted rating and go to ``done``; refused (nothing stored), the form again with why."""
    chosen = _chosen(instrument)
    form = await request.form()
    spec = INSTRUMENTS[chosen]
    scores = {name: form.get(name) for name in spec.item_names if form.get(name) not in (None, "")}
    try:
        add_rating(
            request.app.state.catalog,
            target.uid,
            viewer.username,
            spec.name,
            scores,
            form.get("replace") == "yes",
        )
    except VascsimError as error:
        return _form_page(request, viewer, target, chosen, error)
    return RedirectResponse(done, status_code=303)


@router.get("/studies/{study_id}/rate", response_class=HTMLResponse)
def rating_queue(request: Request, study_id: Id, viewer: Staff, rated: str | None = None) -> Response:
    sessions = _study_sessions(request, viewer, study_id)
    for number, row in enumerate(sessions, start=1):
        row["name"] = f"Session {number}"
        row.pop("uid")
    return render(
        request, "rate_queue.html", viewer, study_id=study_id, sessions=sessions, rated=rated is not None
    )


@router.get("/rate/{token}", response_class=HTMLResponse)
def blinded_form(request: Request, token: str, viewer: Staff, instrument: str | None = None) -> Response:
    return _form_page(request, viewer, _blinded(request, viewer, token), _chosen(instrument))


@router.post("/rate/{token}", response_class=HTMLResponse)
async def blinded_submit(
    request: Request, token: str, viewer: Staff, instrument: str | None = None
) -> Response:
    target = _blinded(request, viewer, token)
    return await _submit(request, viewer, target, instrument, f"{target.back}?rated=1")


@router.get("/rate/{token}/video")
def blinded_video(request: Request, token: str, viewer: Staff) -> FileResponse:
    uid, _, _ = _unblind(request, viewer, token)
    path = _blind_video(request, uid)
    if path is None:
        raise not_found("blind replay")
    return FileResponse(path, media_type="video/mp4")


@router.get("/rate/{token}/replay")
def blind_render_status(request: Request, token: str, viewer: Staff) -> dict:
    """Whether the session's blind render is ready, rendering or failed (the rating page polls it)."""
    uid, _, _ = _unblind(request, viewer, token)
    job = request.app.state.replays.status(uid, blind=True)
    if job is not None and job.state != "done":
        return job.as_dict()
    ready = _blind_video(request, uid) is not None
    return {"state": "ready" if ready else "none", "frames_done": 0, "frames": 0, "error": ""}


@router.post("/rate/{token}/replay", status_code=202)
def start_blind_render(request: Request, token: str, viewer: Staff) -> dict:
    """Render the session's blind replay (one render at a time on a server)."""
    uid, _, _ = _unblind(request, viewer, token)
    return request.app.state.replays.start(uid, blind=True).as_dict()


@router.get("/sessions/{uid}/rate", response_class=HTMLResponse)
def open_form(request: Request, uid: str, viewer: Staff, instrument: str | None = None) -> Response:
    return _form_page(request, viewer, _open(request, viewer, uid), _chosen(instrument))


@router.post("/sessions/{uid}/rate", response_class=HTMLResponse)
async def open_submit(request: Request, uid: str, viewer: Staff, instrument: str | None = None) -> Response:
    target = _open(request, viewer, uid)
    return await _submit(request, viewer, target, instrument, target.back)
