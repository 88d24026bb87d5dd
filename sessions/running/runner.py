"""Running a session: device + simulator runtime + recorder + catalog row, then scoring.

The catalog row is committed as ``running`` before the first sample; it becomes
``complete`` only after the recorder has closed its files and their SHA-256 are
stored. An exception or Ctrl-C closes the recorder (the data is kept) and marks the
row ``failed`` with the reason; a hard crash leaves ``running`` plus a journal that
``vascsim recover`` turns into a ``recovered`` session.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import NamedTuple

import pandas as pd

from metrics import REGISTRY_VERSION, SessionStreams, from_recorded, metrics_of
from metrics.bench.tracking import TRACK_FILE, load_track
from metrics.datasets.jigsaws import Trial, read_kinematics
from metrics.signals.placement import STITCH_QUANTITIES, stitch_table
from metrics.signals.tissue import with_tissue_fields
from recorder import SessionWriter, open_session
from recorder import recover as recover_files
from recorder.runtime import RuntimeRecorder
from sessions.catalog import Catalog, CatalogError, metric_results, new_uid, now, stream_file
from sessions.catalog.lookups import forget_results, forget_stream_files, session_in_directory
from sessions.catalog.models import (
    MetricResult,
    StitchResult,
)
from sessions.config import cache_dir
from sessions.running.camera import open_camera_device
from sessions.running.hands import forceps_on, instruments, open_forceps_device
from sessions.running.live import LiveView
from sessions.running.scene import LIVE_TIME_FACTOR, mapped_onto_task, start_pose, stop_when_done
from sessions.running.streaming import StreamedSession, StreamTarget
from sessions.running.streaming import log as streaming_log
from sessions.status import SCORABLE, SCRIPTED_DEVICE, SessionStatus
from sessions.synthetic import aimed_bites, bite_parameters, for_everted_bite, in_restricted_access
from sessions.tasks import (
    edge_grasps,
    region_presets,
    session_tissue,
    task_preset,
    task_simulation,
    task_spec,
)
from sim.devices import DeviceIdentity, ReplayDevice, ScriptedDevice, SuturingPass
from sim.devices.assisting import ScriptedHands, assisting_hand
from sim.devices.mouse import MouseDevice
from sim.devices.openhaptics import OpenHapticsDevice
from sim.devices.scripted import SuturingPassParameters, sequence_of_passes
from sim.devices.spacemouse import SpaceMouse
from sim.needle import Needle
from sim.runtime import RuntimeSettings


@dataclass(frozen=True)
class SessionPlan:
    study: str
    participant: str
    task: str
    trial: int | None  # None: the participant's next trial on the task, allocated as the row is added
    phase: str = "practice"
    device: str = "scripted"
    clock: str = "simulated"
    sub_device: str | None = None  # the subordinate hand's forceps (sessions.running.hands), None: one hand
    handedness: str = "right"  # left: the instruments swap devices, and hand-held devices are mirrored


def _header(plan: SessionPlan, uid: str, code: str, label: str, synthetic: bool) -> dict:
    spec = task_spec(plan.task)
    return {
        "session_id": uid,
        "participant_id": code,
        "label": label,
        "trial": plan.trial,
        "phase": plan.phase,
        "synthetic": synthetic,
        "task": plan.task,
        "device": plan.device,
        "sub_device": plan.sub_device or "none",
        "clock": plan.clock,
        "tissue_preset": task_preset(spec).name,
        "needle_forces": task_preset(spec).forces.as_dict(),
        "region_tissue": {region: preset.name for region, preset in region_presets(spec).items()},
        "haptic_scale": 1.0,  # the device is sent the tissue's force, clamped to its rating
        "placement": spec.placement,  # the wound edge and targets bites are scored against
    }


MAPPED_DEVICES = ("spacemouse", "openhaptics", "camera")
"""Devices whose own frame is mapped onto the task's scene (sessions.running.scene.mapped_onto_task)."""
LIVE_SETTINGS = RuntimeSettings(display_delay_frames=0, display_on_haptic_core=True)
"""A person's live view draws the newest graphics frame, with the haptic core's idle time to draw it in
(sim.runtime.RuntimeSettings)."""


class OpenedDevice(NamedTuple):
    """The device named by ``--device``, the session's duration (s, None = until stopped) and the
    subordinate hand's device (None: one-handed)."""

    device: object
    duration: float | None
    subordinate: object = None


def open_device(
    spec: str,
    plan: SessionPlan,
    catalog: Catalog,
    parameters: SuturingPassParameters | ScriptedHands | None,
    home: Path | None = None,
    companions: tuple[str, ...] = (),
) -> OpenedDevice:
    """The device named by ``--device`` (and, for a scripted session given both hands' parameters
    on a task with a wound edge, the subordinate hand's), and the session's duration. ``home``: the
    data directory, where a camera's calibration and the instruments' registered tips are kept;
    ``companions``: instruments a camera tracks beside the needle holder (the forceps)."""
    task = task_spec(plan.task)
    if spec == "scripted":
        hands = (
            parameters
            if isinstance(parameters, ScriptedHands)
            else ScriptedHands(parameters or SuturingPassParameters())
        )
        bites = aimed_bites(task)  # an edge to be everted: the wrist at its stop
        each = bite_parameters(hands.needle, len(bites))
        approach = None
        if task.access is not None:  # the hand comes in from where the wound lets it
            approach = task.access["approach"]
            each = [in_restricted_access(p, task.access["tilt_deg"]) for p in each]
        passes = [
            SuturingPass(Needle.curved(), *bite, p, approach=approach)
            for bite, p in zip(bites, each, strict=True)
        ]
        subordinate = None
        grasps = edge_grasps(task)
        if hands.assisting is not None and grasps:
            assisting = hands.assisting
            if task.eversion is not None:
                assisting = for_everted_bite(assisting, task.eversion.lift_m)
            subordinate = ScriptedDevice(
                assisting_hand(passes, grasps, assisting),
                identity=DeviceIdentity("scripted", "scripted subordinate hand (forceps)"),
            )
        if len(passes) == 1:
            return OpenedDevice(ScriptedDevice(passes[0].pose_and_grip), passes[0].duration, subordinate)
        trajectory, duration = sequence_of_passes(passes)
        return OpenedDevice(ScriptedDevice(trajectory), duration, subordinate)
    if spec.startswith("replay:"):
        uid = spec.split(":", 1)[1]
        with catalog.session() as orm:
            row = catalog.recorded_session(orm, uid)
            directory = row.directory
        recorded = open_session(directory).samples_frame()
        device = ReplayDevice(
            recorded["time"],
            recorded[["tool_x", "tool_y", "tool_z"]].to_numpy(),
            recorded[["tool_qw", "tool_qx", "tool_qy", "tool_qz"]].to_numpy(),
            recorded["grip"].to_numpy(),
            session=uid,
        )
        return OpenedDevice(device, float(recorded["time"].iloc[-1]))
    if spec == "mouse":
        return OpenedDevice(MouseDevice(start_pose(task)), None)
    if spec == "spacemouse":
        return OpenedDevice(SpaceMouse(), None)  # mapped onto the task's scene by run_session
    if spec == "openhaptics":
        return OpenedDevice(OpenHapticsDevice(), None)
    if spec == "camera" or spec.startswith("camera:"):  # mapped onto the task's scene by run_session
        device, length = open_camera_device(spec, plan.clock, home, companions=companions)
        return OpenedDevice(device, length)
    raise CatalogError(
        f"unknown device {spec!r}; use scripted, mouse, spacemouse, openhaptics, camera[:INDEX|URL|FILE] "
        "or replay:SESSION"
    )


def run_session(
    catalog: Catalog,
    home: Path,
    plan: SessionPlan,
    parameters: SuturingPassParameters | ScriptedHands | Callable[[int], object] | None = None,
    duration: float | None = None,
    score: bool = True,
    view: LiveView | None = None,
    stream: StreamTarget | None = None,
) -> str:
    """Run, record and catalogue one session; returns its uid.

    The row is added first (with the next trial number when ``plan.trial`` is None);
    ``parameters`` may be a function of that trial number (a scripted pass seeded by it).
    If the device cannot be opened or the task's simulation cannot be built, nothing was recorded
    and the row is removed again (the recording starts only after both).
    A live device with no ``duration`` runs until the task is done, the trainee stops it, or
    :data:`sessions.running.scene.LIVE_TIME_FACTOR` times the task's budget. ``view``: a real-time
    session's window on the station's display (:class:`LiveView`); stopping it early (Escape,
    Ctrl-C) ends the session complete, scored up to where it stopped. ``stream``: a central recorder
    that receives the recording as it is made, and the window's view (sessions.running.streaming); the
    local recording stays the session of record whatever happens to the link."""
    spec = task_spec(plan.task)
    uid = new_uid()
    directory = home / "sessions" / uid
    with catalog.session() as orm:  # checked before the task row is made: a typo creates nothing
        study = catalog.study(orm, plan.study)
        participant = catalog.participant(orm, study, plan.participant)
        participant_id = participant.id
        code, label, synthetic = participant.code, participant.group_label, participant.synthetic
    task_id = catalog.ensure_task(
        spec.name, spec.scenario, spec.parameters.as_dict()
    )  # first runs of a task race
    fields = {"participant_id": participant_id, "task_id": task_id}
    row = catalog.add_session(
        dict(
            fields,
            uid=uid,
            device=plan.device,
            clock=plan.clock,
            trial=plan.trial,
            phase=plan.phase,
            status=SessionStatus.RUNNING,
            started_at=now(),
            directory=str(directory),
        )
    )
    plan = replace(plan, trial=row.trial)
    if callable(parameters):
        parameters = parameters(row.trial)
    device = subordinate = None
    try:
        left = plan.handedness == "left" or (view is not None and view.mapping.handedness == "left")
        hands = instruments(plan.device, plan.sub_device, "left" if left else "right")
        both_on_camera = hands.forceps == "camera" and hands.needle.split(":", 1)[0] == "camera"
        companions = ("forceps",) if both_on_camera else ()
        device, natural, subordinate = open_device(hands.needle, plan, catalog, parameters, home, companions)
        camera = device if both_on_camera else None
        if hands.needle.split(":", 1)[0] in MAPPED_DEVICES:  # the hand's workspace onto the scene, as shown
            device = mapped_onto_task(device, spec, left_handed=left)
        if camera is not None:  # the forceps in the same camera's frames
            subordinate = forceps_on(camera.companion(), spec, left)
        elif hands.forceps is not None:  # a person's second hand: the forceps on their own device
            subordinate = open_forceps_device(hands.forceps, spec, left, hands.needle, home, plan.clock)
        if natural is not None and plan.device == SCRIPTED_DEVICE:  # a script's hand stops where it ends
            duration = natural if duration is None else min(duration, natural)
        duration = duration if duration is not None else natural
        if duration is None:  # a live device: until done or stopped, within a bound the arena needs
            duration = LIVE_TIME_FACTOR * spec.time_budget_s
        window = None
        if view is not None and plan.clock == "realtime":
            window = view.window(spec, device, catalog, home, study_and_task_ids(catalog, uid), uid)
            window.toggle_forceps = getattr(subordinate, "toggle_grip", None)  # camera-tracked forceps: F
            window.forceps_problem = getattr(subordinate, "tracking_problem", None)
        options = {} if window is None else {"renderer": window, "settings": LIVE_SETTINGS}
        if subordinate is not None:
            options["subordinate"] = subordinate
        simulated = task_simulation(spec, device, cache_dir(home), **options)
    except BaseException:  # nothing was recorded: no row, journal or ring is left behind
        close_devices(device, subordinate)
        with catalog.session() as orm:
            orm.delete(catalog.recorded_session(orm, uid))
        raise
    synthetic = synthetic or plan.device == SCRIPTED_DEVICE  # a script, not this person's hand
    header = _header(plan, uid, code, label, synthetic)
    streamed = None if stream is None else StreamedSession(stream, home, uid, header)
    mirror = None if streamed is None else streamed.submit
    writer = SessionWriter(directory, header, flush_interval=0.1, mirror=mirror)
    if streamed is not None:
        streamed.start()
    simulation = RuntimeRecorder(writer).attach(simulated)
    if window is not None:
        window.simulation = simulation
        stop_when_done(simulation, spec.stitch_count)
    try:
        if plan.clock == "simulated":
            simulation.run_simulated(duration)
        else:
            simulation.run_realtime(duration)
    except BaseException as error:
        writer.close()
        _finish(catalog, uid, directory, "failed", f"{type(error).__name__}: {error}".strip())
        _end_stream(streamed, "failed")
        raise
    finally:
        close_devices(device, subordinate)
    writer.close()
    _finish(catalog, uid, directory, "complete")
    _end_stream(streamed, "complete")
    if score:
        score_session(catalog, uid, home)
    return uid


def _end_stream(streamed: StreamedSession | None, status: str) -> None:
    """Close a streamed session's stream; what the central recorder did not take is said (a warning:
    the trial is recorded here either way) and stays in the spool for the next streamed session."""
    if streamed is not None:
        left = streamed.finish(status)
        if left is not None:
            said = "%s; kept in %s and sent by the next streamed session"
            streaming_log.warning(said, left, streamed.spool)


def close_devices(*devices) -> None:
    """Let go of each opened device (a camera's tracking process, a HID handle), each even if another
    fails to."""
    for device in devices:
        close = getattr(device, "close", None)
        if close is None:
            continue
        try:
            close()
        except OSError:
            pass  # already gone (unplugged): nothing left to let go of


def study_and_task_ids(catalog: Catalog, uid: str) -> tuple[int, int]:
    """The study and task a session belongs to (catalog ids)."""
    with catalog.session() as orm:
        row = catalog.recorded_session(orm, uid)
        return row.participant.study_id, row.task_id


def _finish(catalog: Catalog, uid: str, directory: Path, status: str, error: str = "") -> None:
    with catalog.session() as orm:
        row = catalog.recorded_session(orm, uid)
        forget_stream_files(orm, row.id)
        orm.add_all(stream_file(row.id, path) for path in sorted(directory.iterdir()) if path.is_file())
        row.status = status
        row.error = error
        row.ended_at = now()


def recover_session(catalog: Catalog, target: str) -> tuple[str | None, dict]:
    """Recover a session a crash left ``running``: ``target`` is its uid or its directory.

    The recorder turns the journal into verified Parquet files (header marked recovered);
    the catalog row, when there is one, becomes ``recovered`` with the files' SHA-256 and
    can then be scored. Returns (uid or None for an uncatalogued directory, header)."""

    folder = Path(target)
    with catalog.session() as orm:
        row = None
        if folder.is_dir():
            resolved = str(folder.resolve())
            row = session_in_directory(orm, (target, resolved))
        else:
            row = catalog.recorded_session(orm, target)
            folder = Path(row.directory)
        if row is not None and row.status != SessionStatus.RUNNING:
            raise CatalogError(
                f"session {row.uid} is {row.status}; only sessions left running by a crash are recovered"
            )
        uid = row.uid if row is not None else None
    header = recover_files(folder)
    if uid is not None:
        _finish(catalog, uid, folder, "recovered", "recovered after a crash")
    return uid, header


def scored_streams(
    directory: Path, device: str, uid: str, code: str, label: str, home: Path | None = None
) -> SessionStreams:
    """The streams of the session stored in ``directory`` as metrics read them (read, never changed).

    Simulator sessions get their tissue streams and stitch points derived with the task's model
    (cached under ``home/cache``; ``home`` defaults to VASCSIM_HOME); a bench video's tracked
    path is the session's data; a JIGSAWS trial's is its kinematics file."""
    if device == "bench-video":
        return load_track(directory / TRACK_FILE).to_streams(uid, code, label)
    if device == "jigsaws":  # one kinematics file; labels come from the catalog, not the file
        samples = read_kinematics(directory)
        return Trial(directory.stem, "", code, 0, label, "", float("nan"), {}, samples).to_streams()
    streams = from_recorded(open_session(directory))
    model = session_tissue(streams, cache_dir(home))
    return with_tissue_fields(streams, model) if model is not None else streams


def compute_metrics(
    directory: Path, device: str, uid: str, code: str, label: str, home: Path | None = None
) -> dict[str, float]:
    """Every registered metric of the session stored in ``directory`` (:func:`scored_streams`)."""
    return metrics_of(scored_streams(directory, device, uid, code, label, home))


@dataclass(frozen=True)
class ScoringInput:
    """What scoring a session reads: its folder, device, id, participant code and group label (all
    plain values, so a Dask worker on another machine can be handed them)."""

    directory: str
    device: str
    uid: str
    code: str
    label: str


def scoring_input(catalog: Catalog, uid: str) -> ScoringInput:
    with catalog.session() as orm:
        row = catalog.recorded_session(orm, uid)
        if row.status not in SCORABLE:
            raise CatalogError(
                f"session {uid} is {row.status}; only complete or recovered sessions are scored"
            )
        return ScoringInput(row.directory, row.device, uid, row.participant.code, row.participant.group_label)


def session_scores(
    what: ScoringInput, home: Path | None = None
) -> tuple[dict[str, float], pd.DataFrame | None]:
    """Every registered metric of the session and its per-stitch placement (reads, stores nothing)."""
    streams = scored_streams(Path(what.directory), what.device, what.uid, what.code, what.label, home)
    return metrics_of(streams), stitch_table(streams)


def store_scores(catalog: Catalog, uid: str, values: dict[str, float], stitches: pd.DataFrame | None) -> None:
    """Store a session's scores with the registry version, replacing what that version had."""
    with catalog.session() as orm:
        row = catalog.recorded_session(orm, uid)
        forget_results(orm, (MetricResult, StitchResult), row.id, REGISTRY_VERSION)
        orm.add_all(metric_results(row.id, values))
        orm.add_all(stitch_results(row.id, stitches))


def score_session(catalog: Catalog, uid: str, home: Path | None = None) -> dict[str, float]:
    """Compute every registered metric of a stored session (:func:`compute_metrics`) and store it
    with the registry version, replacing what that version had (computed or imported)."""
    values, stitches = session_scores(scoring_input(catalog, uid), home)
    store_scores(catalog, uid, values, stitches)
    return values


def stitch_results(session_id: int, stitches: pd.DataFrame | None) -> list[StitchResult]:
    """Catalog rows of a session's per-stitch placement (NaN stored as NULL)."""
    if stitches is None:
        return []
    return [
        StitchResult(
            session_id=session_id,
            stitch=int(row["stitch"]),
            quantity=name,
            value=None if math.isnan(row[name]) else float(row[name]),
            registry_version=REGISTRY_VERSION,
        )
        for _, row in stitches.iterrows()
        for name in STITCH_QUANTITIES
    ]
