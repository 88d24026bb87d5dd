"""The JSON API under ``/api`` (its OpenAPI document at ``/api/openapi.json``)."""

from __future__ import annotations

import io
import time
from datetime import timedelta
from pathlib import Path
from typing import Annotated, Literal

from fastapi import APIRouter, Depends, Query, Request, Response
from fastapi import Path as PathParameter
from fastapi.responses import FileResponse, StreamingResponse
from pydantic import BaseModel, Field

from dashboard import queries
from dashboard.auth import COOKIE, LoginRateLimiter, Viewer, current_viewer, require, sign_in_keys
from dashboard.errors import CONFLICT, ERROR_RESPONSES, DashboardError, not_found
from dashboard.streams.live import live_stream, newest_view
from dashboard.streams.signals import inside, replay_video, session_file
from metrics.reading.report import write_report
from metrics.reading.tables import validity_download
from recorder.layout import SAMPLES_JOURNAL
from recorder.remote.views import view_path
from sessions.catalog import accounts
from sessions.catalog.store import STAFF, UserRecord
from sessions.exchange.progress import progress_table, write_progress
from sessions.running.live import live_view_path
from sessions.scoring import ratings
from sessions.status import SessionStatus

router = APIRouter(prefix="/api", responses=ERROR_RESPONSES)
Staff = Annotated[Viewer, Depends(require(*STAFF))]
Admin = Annotated[Viewer, Depends(require("admin"))]
Watcher = Annotated[Viewer, Depends(require("admin", "supervisor"))]
Anyone = Annotated[Viewer, Depends(current_viewer)]
MAX_ID = 2_147_483_647  # ids are 32-bit in every catalog; larger ones cannot exist
Id = Annotated[int, PathParameter(ge=1, le=MAX_ID)]
FIGURES = ("box_plots.png", "box_plots.svg", "roc.png", "roc.svg")


class Credentials(BaseModel):
    username: str = Field(min_length=1, max_length=64)
    password: str = Field(min_length=1, max_length=1024)


# the rules sessions.catalog.accounts enforces, declared here so the OpenAPI document states them
Password = Annotated[str, Field(min_length=accounts.MIN_PASSWORD_LENGTH, max_length=1024)]


class NewUser(BaseModel):
    username: str = Field(min_length=2, max_length=64, pattern=accounts.USERNAME_PATTERN.pattern)
    password: Password
    role: Literal["admin", "supervisor", "researcher", "trainee"]
    participant_ids: list[Annotated[int, Field(ge=1, le=2_147_483_647)]] = Field(
        default_factory=list, max_length=100
    )
    participants: list[Annotated[str, Field(min_length=3, max_length=200)]] = Field(
        default_factory=list, max_length=100, description="trainees: participants as STUDY:CODE"
    )


class LinkedParticipants(BaseModel):
    participants: list[Annotated[str, Field(min_length=3, max_length=200)]] = Field(
        max_length=100, description="the trainee's participants as STUDY:CODE (replaces the links)"
    )


class UserChange(BaseModel):
    role: Literal["admin", "supervisor", "researcher", "trainee"] | None = None
    active: bool | None = None
    password: Password | None = None


class NewStation(BaseModel):
    station: str = Field(min_length=1, max_length=64, pattern=accounts.STATION_PATTERN.pattern)


class NewRating(BaseModel):
    instrument: Literal["GRS", "OSATS"]
    scores: dict[
        Annotated[str, Field(min_length=1, max_length=64)], Annotated[int, Field(strict=True, ge=1, le=5)]
    ] = Field(max_length=10, description="every item of the instrument, each a whole score 1-5")
    replace: bool = Field(default=False, description="replace the caller's earlier rating of the session")


class NewStudy(BaseModel):
    name: str = Field(min_length=1, max_length=200)
    description: str = Field(default="", max_length=5000)


def _state(request: Request):
    return request.app.state


def sign_in(request: Request, response: Response, username: str, password: str) -> tuple[UserRecord, str]:
    """Check the credentials under the rate limit, set the sign-in cookie; (user, CSRF token)."""
    state = _state(request)
    limiter: LoginRateLimiter = state.login_limiter
    keys, at = sign_in_keys(request, username, limiter.attempts), time.monotonic()
    # counted before the (slow) password check: concurrent guesses cannot race it
    wait = limiter.claim(keys, at)
    if wait > 0:
        error = DashboardError(
            429, f"too many failed sign-ins for {username!r} or from this address; try again in {wait:.0f} s"
        )
        error.retry_after = int(wait) + 1
        raise error
    signed = state.store.sign_in(username, password, timedelta(seconds=state.settings.login_lifetime_s))
    if signed is None:
        raise DashboardError(401, "wrong user name or password")  # the claimed attempt stays counted
    user, token, csrf = signed
    limiter.succeeded(keys, at)
    response.set_cookie(
        COOKIE,
        token,
        max_age=int(state.settings.login_lifetime_s),
        httponly=True,
        samesite="strict",
        secure=state.settings.secure_cookies,
        path="/",
    )
    return user, csrf


def sign_out(request: Request, response: Response) -> None:
    token = request.cookies.get(COOKIE)
    if token:
        _state(request).store.sign_out(token)
    response.delete_cookie(COOKIE, path="/")


@router.post("/login", summary="Sign in; sets an HttpOnly cookie and returns the CSRF token")
def login(request: Request, response: Response, credentials: Credentials) -> dict:
    user, csrf = sign_in(request, response, credentials.username, credentials.password)
    return {"username": user.username, "role": user.role, "csrf_token": csrf}


@router.post("/logout", summary="Sign out (ends the sign-in on the server)")
def logout(request: Request, response: Response, viewer: Anyone) -> dict:
    sign_out(request, response)
    return {"signed_out": viewer.username}


@router.get("/me")
def me(viewer: Anyone) -> dict:
    return {
        "username": viewer.username,
        "role": viewer.role,
        "participant_ids": sorted(viewer.participant_ids),
        "csrf_token": viewer.csrf_token,
    }


@router.get("/studies")
def studies(request: Request, viewer: Anyone) -> list[dict]:
    return queries.studies(_state(request).store, viewer)


@router.get("/studies/{study_id}", summary="Study overview: participants, latest scores, who needs attention")
def study(request: Request, study_id: Id, viewer: Staff) -> dict:
    state = _state(request)
    return queries.study_overview(state.store, state.analyses, viewer, study_id)


@router.get("/studies/{study_id}/validity", summary="Construct-validity report", responses=CONFLICT)
def validity(request: Request, study_id: Id, viewer: Staff) -> dict:
    state = _state(request)
    return queries.validity_report(state.store, state.analyses, viewer, study_id)


@router.get(
    "/studies/{study_id}/validity.csv",
    response_class=Response,
    summary="Validity table as CSV",
    responses=CONFLICT,
)
def validity_csv(request: Request, study_id: Id, viewer: Staff) -> Response:

    state = _state(request)
    name = state.store.study(study_id, viewer, whole=True).name
    buffer = io.StringIO()
    validity_download(state.analyses.get(study_id).analysis).to_csv(buffer, index=False)
    return Response(
        buffer.getvalue(),
        media_type="text/csv",
        headers={"Content-Disposition": f'attachment; filename="validity-{_plain(name)}.csv"'},
    )


@router.get(
    "/studies/{study_id}/progress.{kind}",
    response_class=Response,
    summary="Each participant's progress and status (CSV or Excel workbook)",
    responses=CONFLICT,
)
def progress_file(request: Request, study_id: Id, kind: str, viewer: Staff) -> Response:
    import tempfile

    if kind not in ("csv", "xlsx"):
        raise not_found(f"progress.{kind}")
    state = _state(request)
    name = state.store.study(study_id, viewer, whole=True).name
    table = progress_table(state.catalog, name, state.analyses.get(study_id).analysis)
    with tempfile.TemporaryDirectory() as folder:
        path = write_progress(table, Path(folder) / f"progress.{kind}", name)
        content = path.read_bytes()
    media = (
        "text/csv" if kind == "csv" else "application/vnd.openxmlformats-officedocument.spreadsheetml.sheet"
    )
    return Response(
        content,
        media_type=media,
        headers={"Content-Disposition": f'attachment; filename="progress-{_plain(name)}.{kind}"'},
    )


def _plain(name: str) -> str:
    return "".join(c if c.isalnum() or c in "-_" else "_" for c in name)[:80]


@router.get(
    "/studies/{study_id}/figures/{name}",
    response_class=FileResponse,
    summary="A report figure (box plots or ROC, PNG or SVG)",
)
def figure(request: Request, study_id: Id, name: str, viewer: Staff) -> FileResponse:

    if name not in FIGURES:
        raise not_found(f"figure {name!r}")
    state = _state(request)
    study_name = state.store.study(study_id, viewer, whole=True).name
    folder = state.settings.home / "reports" / "dashboard" / str(study_id)
    analysis = state.analyses.get(study_id).analysis
    stamp = folder / ".fingerprint"
    key = repr(state.analyses.fingerprint(study_id))
    if not stamp.exists() or stamp.read_text() != key:
        write_report(analysis, folder, title=f"Study {study_name}")
        stamp.write_text(key)
    path = inside(state.settings.home, folder / "figures" / name)
    if not path.is_file():
        raise not_found(f"figure {name!r}")
    return FileResponse(path, filename=f"{_plain(study_name)}-{name}")


@router.get(
    "/participants/{participant_id}/progress", summary="Learning curves, pass/fail history, retention"
)
def progress(request: Request, participant_id: Id, viewer: Anyone) -> dict:
    state = _state(request)
    return queries.participant_progress(state.store, state.analyses, viewer, participant_id)


@router.get("/sessions", summary="Sessions the caller may see, newest first")
def sessions(
    request: Request,
    viewer: Anyone,
    study_id: Annotated[int | None, Query(ge=1, le=MAX_ID)] = None,
    limit: Annotated[int, Query(ge=1, le=500)] = 50,
    offset: Annotated[int, Query(ge=0, le=10_000_000)] = 0,
) -> dict:
    return queries.session_list(_state(request).store, viewer, study_id, limit, offset)


@router.get("/sessions/{uid}", summary="A session: metrics against the expert band, events, files")
def session(request: Request, uid: str, viewer: Anyone) -> dict:
    state = _state(request)
    return queries.session_detail(state.store, state.analyses, viewer, uid)


def _directory(request: Request, viewer: Viewer, uid: str) -> tuple[str, set[str]]:
    facts = _state(request).store.session_facts(uid, viewer)
    return facts.directory, {f.name for f in facts.files}


@router.get("/sessions/{uid}/signals", summary="Force, tip speed and local stress over time; events")
def signals(request: Request, uid: str, viewer: Anyone) -> dict:
    directory, _ = _directory(request, viewer, uid)
    return _state(request).signals.signals(directory)


@router.get("/sessions/{uid}/video", response_class=FileResponse, summary="The replay video (range requests)")
def video(request: Request, uid: str, viewer: Anyone) -> FileResponse:
    _directory(request, viewer, uid)
    path = replay_video(_state(request).settings.home, uid)
    if path is None:
        raise DashboardError(
            404,
            f"session {uid!r} has no replay video yet; render it from the session's page "
            f"(staff) or with `vascsim replay {uid} --vs-group experts`",
        )
    return FileResponse(path, media_type="video/mp4" if path.suffix == ".mp4" else "video/webm")


@router.get(
    "/sessions/{uid}/ratings", summary="A session's ratings: rater, instrument, items and total (staff)"
)
def session_ratings(request: Request, uid: str, viewer: Staff) -> list[dict]:
    _directory(request, viewer, uid)
    # researchers never see account names: raters as stable pseudonyms
    return ratings.session_ratings(_state(request).catalog, uid, pseudonymous=not viewer.sees_accounts)


@router.post(
    "/sessions/{uid}/replay",
    status_code=202,
    summary="Render the session's replay against the experts (staff; one render at a time)",
    responses=CONFLICT,
)
def start_replay(request: Request, uid: str, viewer: Staff) -> dict:
    state = _state(request)
    state.store.session_facts(uid, viewer)  # the reader may see it, or it is not found
    return state.replays.start(uid).as_dict()


@router.get("/sessions/{uid}/replay", summary="Whether the session's replay is ready, rendering, or failed")
def replay_status(request: Request, uid: str, viewer: Anyone) -> dict:
    state = _state(request)
    state.store.session_facts(uid, viewer)
    job = state.replays.status(uid)
    if job is not None and job.state != "done":
        return job.as_dict()
    ready = replay_video(state.settings.home, uid) is not None
    return {"state": "ready" if ready else "none", "frames_done": 0, "frames": 0, "error": ""}


@router.post(
    "/sessions/{uid}/ratings",
    status_code=201,
    summary="Rate a session with GRS or OSATS (staff; the rater is the caller)",
    responses=CONFLICT,
)
def rate_session(request: Request, uid: str, body: NewRating, viewer: Staff) -> dict:
    _directory(request, viewer, uid)
    rating = ratings.add_rating(
        _state(request).catalog, uid, viewer.username, body.instrument, body.scores, body.replace
    )
    return {
        "rater": rating.rater,
        "instrument": rating.instrument.name,
        "scores": rating.scores,
        "total": rating.total,
    }


@router.get("/sessions/{uid}/files/{name}", response_class=FileResponse, summary="Download a stream file")
def download(request: Request, uid: str, name: str, viewer: Anyone) -> FileResponse:
    directory, names = _directory(request, viewer, uid)
    path = session_file(_state(request).settings.home, directory, name, names)
    return FileResponse(path, filename=f"{uid}-{name}")


# -- live view --------------------------------------------------------------------------
@router.get("/live", summary="Stations recording now: local sessions and remote stations")
def live(request: Request, viewer: Watcher) -> dict:
    state = _state(request)
    return queries.recording_now(state.store, state.settings.ingest_root)


def _event_stream(request: Request, directory: Path, still_running) -> StreamingResponse:
    settings = _state(request).settings
    stream = live_stream(
        directory, still_running, request.is_disconnected, settings.live_poll_s, settings.live_rate_hz
    )
    return StreamingResponse(
        stream,
        media_type="text/event-stream",
        headers={"Cache-Control": "no-store", "X-Accel-Buffering": "no"},
    )


@router.get(
    "/live/sessions/{uid}",
    response_class=StreamingResponse,
    summary="Server-sent events of a session",
    responses=CONFLICT,
)
def live_session(request: Request, uid: str, viewer: Watcher) -> StreamingResponse:
    facts = _recording(request, uid, viewer)
    directory = inside(_state(request).settings.home, Path(facts.directory))
    return _event_stream(request, directory, lambda: _state(request).store.is_running(uid))


def _recording(request: Request, uid: str, viewer: Viewer):
    """The facts of session ``uid`` as ``viewer`` may see them, refused (409) unless it is recording."""
    facts = _state(request).store.session_facts(uid, viewer)
    if facts.session.status != SessionStatus.RUNNING:
        raise DashboardError(409, f"session {uid!r} is {facts.session.status}, not recording")
    return facts


@router.get(
    "/live/sessions/{uid}/view.jpg",
    response_class=Response,
    summary="The 3-D view a recording session's station shows, as its window drew it last (JPEG)",
    responses=CONFLICT,
)
def live_session_view(request: Request, uid: str, viewer: Watcher) -> Response:
    _recording(request, uid, viewer)
    home = _state(request).settings.home
    path = inside(home, live_view_path(home, uid))
    return newest_view(path, f"3-D view of session {uid} (its station shows no window, or has not drawn yet)")


@router.get(
    "/live/stations/{station}/{session_id}",
    response_class=StreamingResponse,
    summary="Server-sent events of a remote station's session",
)
def live_station(request: Request, station: str, session_id: str, viewer: Watcher) -> StreamingResponse:
    directory = _streaming(request, station, session_id)
    return _event_stream(request, directory, lambda: (directory / SAMPLES_JOURNAL).exists())


def _streaming(request: Request, station: str, session_id: str) -> Path:
    """The folder of a remote station's session that is streaming now; 404 otherwise."""
    root = _state(request).settings.ingest_root
    if not all(part.replace("-", "").replace("_", "").isalnum() for part in (station, session_id)):
        raise not_found(f"station session {station}/{session_id}")
    directory = inside(_state(request).settings.home, root / station / session_id)
    if not (directory / SAMPLES_JOURNAL).exists():
        raise not_found(f"station session {station}/{session_id}")
    return directory


@router.get(
    "/live/stations/{station}/{session_id}/view.jpg",
    response_class=Response,
    summary="The 3-D view a remote station's window drew last, as it sent it to the ingest (JPEG)",
)
def live_station_view(request: Request, station: str, session_id: str, viewer: Watcher) -> Response:
    _streaming(request, station, session_id)
    settings = _state(request).settings
    path = inside(settings.home, view_path(settings.ingest_root, station, session_id))
    missing = f"3-D view of station session {station}/{session_id} (it sends none, or none yet)"
    return newest_view(path, missing)


# -- administration (the catalog store's; docs/architecture.md) -------------------------
@router.get("/users", summary="Accounts (admin)")
def users(request: Request, viewer: Admin) -> list[dict]:
    return [user.as_dict() for user in _state(request).store.users()]


@router.post("/users", status_code=201, summary="Create an account (admin)", responses=CONFLICT)
def create_user(request: Request, body: NewUser, viewer: Admin) -> dict:
    made = _state(request).store.create_user(
        body.username, body.password, body.role, body.participants, body.participant_ids
    )
    return made.as_dict()


@router.put(
    "/users/{user_id}/participants",
    summary="Set the participants a trainee account sees, by STUDY:CODE (admin)",
    responses=CONFLICT,
)
def set_user_participants(request: Request, user_id: Id, body: LinkedParticipants, viewer: Admin) -> dict:
    return _state(request).store.set_user_participants(user_id, body.participants).as_dict()


@router.patch(
    "/users/{user_id}", summary="Change an account's role, state or password (admin)", responses=CONFLICT
)
def change_user(request: Request, user_id: Id, body: UserChange, viewer: Admin) -> dict:
    store = _state(request).store
    changed = store.change_user(user_id, viewer.user_id, body.role, body.active, body.password)
    return changed.as_dict()


@router.get("/stations", summary="Station ingest tokens (admin; the tokens themselves are never shown again)")
def stations(request: Request, viewer: Admin) -> list[dict]:
    return [station.as_dict() for station in _state(request).store.stations()]


@router.post(
    "/stations",
    status_code=201,
    summary="Issue a station's ingest token (admin); shown once",
    responses=CONFLICT,
)
def create_station(request: Request, body: NewStation, viewer: Admin) -> dict:
    return _state(request).store.issue_station_token(body.station)


@router.delete("/stations/{token_id}", summary="Revoke a station's token (admin)")
def revoke_station(request: Request, token_id: Id, viewer: Admin) -> dict:
    row = _state(request).store.revoke_station_token(token_id)
    return {"id": row.id, "station": row.station, "revoked_at": row.revoked_at}


@router.post("/studies", status_code=201, summary="Create a study (admin)", responses=CONFLICT)
def create_study(request: Request, body: NewStudy, viewer: Admin) -> dict:
    return _state(request).store.create_study(body.name, body.description).as_dict()
