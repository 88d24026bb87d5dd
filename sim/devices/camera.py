"""Real instruments tracked by a camera as a live device: ``camera:INDEX``, ``camera:URL``, ``camera:FILE``.

A trainee holds a real needle holder with a printed marker cube on its handle in front of a webcam.
Each frame goes through :class:`sim.tracking.pose.BodyTracker` (markers, pose, tip) and
:class:`sim.tracking.channel.PoseEstimator` (jump test, filter); the haptic loop reads the newest
estimate through :class:`sim.tracking.channel.PosePredictor` (extrapolated to the tick, labelled
measured / predicted / held, rate-limited). The label reaches the recording (``DeviceSample.tracking``).

Where the frames are processed depends on the clock:

- **simulated** (a video file only): in :meth:`CameraDevice.read`, every frame up to the tick's time,
  in order, so a run is repeatable; the video's first frame that shows the instrument is session
  time 0;
- **real time**: in a tracking process of its own (started when the device opens, so the camera
  never takes the haptic core), which publishes estimates through shared memory. A live camera's
  frames carry their grab time on ``time.perf_counter``, the clock the haptic loop runs on; a video
  file is played at its own pace from the session's first tick.

Either way the device opens only once the instrument has been seen (``acquire_timeout_s``): the
workspace mapping anchors the task's starting pose on the first reading, which must be a real one.

Poses leave the device in a haptic device's frame (x to the trainee's right, y up the screen, z out of
the screen), with the table as the task's wall: the trainee's hands over a table move the instrument
as they would over the tissue, so the table's right, away-from-the-trainee and up are the screen's
right, up and out of the screen (towards the tissue is down to the table). ``device_from_camera``
turns the camera's axes into those. The default is a webcam on the monitor looking at the trainee
(``FACING_TRAINEE``); a camera above the table looking down, the image's top away from the trainee, is
``ABOVE_TABLE``; a registration with the calibration board lying on the table measures it exactly.
"""

from __future__ import annotations

import multiprocessing
import os
import time as clock
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from sim.devices.base import INPUT_ONLY_LIMITS, DeviceError, DeviceIdentity, DeviceLostError, DeviceSample
from sim.errors import TrackingError
from sim.runtime.osrt import try_realtime_priority
from sim.tracking.camera import Camera
from sim.tracking.channel import STALE_FRAMES, Estimate, PoseEstimator, PosePredictor, SharedEstimate
from sim.tracking.markers import NEEDLE_HOLDER, MarkerBody
from sim.tracking.pose import BodyTracker
from sim.tracking.video import LiveCamera, VideoFile

FACING_TRAINEE = np.array([[-1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, -1.0, 0.0]])
"""Camera on the monitor at the hands' height, looking at the trainee: the image's right is the
trainee's left, the image's down is down to the table, the optical axis points at the trainee."""
ABOVE_TABLE = np.diag([1.0, -1.0, -1.0])
"""Camera above the table looking down, the image's top away from the trainee: the image's right is
the trainee's right, the image's down points at the trainee, the optical axis down to the table."""
PLACEMENTS = {"facing": FACING_TRAINEE, "above": ABOVE_TABLE}
ACQUIRE_TIMEOUT_S = 10.0
TRACKING_PRIORITY = 20
"""SCHED_FIFO priority of the tracking process where the runtime's threads have one (root, or
CAP_SYS_NICE): below the haptic loop (50), the FEM (40) and graphics (30) threads, above everything in
the normal class. Without it, on two cores, the real-time threads left the tracking process too little
time while the needle was in the wall: a third of the haptic samples were predicted or held."""


def camera_source(spec: str) -> int | str | Path:
    """What ``camera``, ``camera:SPEC`` or ``SPEC`` names: a camera index (``camera`` alone: 0), a stream
    URL, or a video file (which must exist)."""
    spec = "0" if spec == "camera" else spec.removeprefix("camera:")
    if spec.isdigit():
        return int(spec)
    if "://" in spec:
        return spec
    path = Path(spec).expanduser()
    if not path.is_file():
        raise DeviceError(
            f"camera source {spec!r} is neither a camera index (0, 1, ...), a stream URL nor a video file"
        )
    return path


def _played_from(video: VideoFile, origin: float) -> float | None:
    """How long (s) ``video`` plays from ``origin`` (s into it); None when its length is not known."""
    return None if not video.frame_count else max(video.frame_count / video.fps - origin, 0.0)


def open_frames(source: int | str | Path) -> tuple[Iterator[tuple[float, NDArray[np.uint8]]], object]:
    """(time, grey frame) pairs from a video file or a live camera, and the opened source (to close)."""
    opened = VideoFile(source) if isinstance(source, Path) else LiveCamera(source)
    return iter(opened), opened


class CameraDevice:
    """Instruments tracked by one camera, read by the haptic loop (see the module docstring).

    camera: the calibrated camera model; body: the instrument this device is (the needle holder);
    companions: other instruments tracked in the same frames (the forceps), each read through
    :meth:`companion`; clock: "realtime" or "simulated"; filter_kind: "kalman" or "one-euro";
    device_from_camera: 3x3 rotation (camera axes into the device's); grip_closed: the jaws' state at
    the start (closed: the needle held; a companion's jaws start open); the jaws are then closed and
    opened by :meth:`toggle_grip` (the station's G key or a foot pedal sending it).
    """

    limits = INPUT_ONLY_LIMITS

    def __init__(
        self,
        source: int | str | Path,
        camera: Camera,
        body: MarkerBody = NEEDLE_HOLDER,
        clock_kind: str = "realtime",
        filter_kind: str = "kalman",
        device_from_camera: NDArray[np.float64] = FACING_TRAINEE,
        acquire_timeout_s: float = ACQUIRE_TIMEOUT_S,
        grip_closed: bool = True,
        companions: tuple[MarkerBody, ...] = (),
    ) -> None:
        self.source, self.camera, self.body = source, camera, body
        self.bodies = (body, *companions)
        self.clock_kind = clock_kind
        self.identity = DeviceIdentity("camera", f"{body.name} tracked by camera {source}")
        self._axes = np.asarray(device_from_camera, dtype=np.float64)
        context = multiprocessing.get_context("fork")
        self._jaws = [
            context.Value("b", int(grip_closed and k == 0), lock=False) for k in range(len(self.bodies))
        ]
        self._estimators = [PoseEstimator(filter_kind) for _ in self.bodies]
        self._fps = 30.0
        self.duration: float | None = None  # a video file's length from the first sighting (s)
        self._process = None
        self._owner = os.getpid()
        self._go = False
        if clock_kind == "simulated":
            if not isinstance(source, Path):
                raise DeviceError("a simulated clock replays a video file; a live camera needs real time")
            self._open_in_process(acquire_timeout_s)
        else:
            self._open_tracking_process(acquire_timeout_s)
        self._predictors = [PosePredictor(1.0 / self._fps) for _ in self.bodies]

    def companion(self, index: int = 1) -> TrackedCompanion:
        """The device of the ``index``-th companion instrument (tracked in this camera's frames)."""
        return TrackedCompanion(self, index)

    # -- simulated clock: frames processed in read(), in order --------------------------------
    def _open_in_process(self, timeout_s: float) -> None:
        video = VideoFile(self.source)
        self._fps = video.fps
        self._frames = iter(video)
        self._trackers = [BodyTracker(self.camera, body) for body in self.bodies]
        self._next: tuple[float, NDArray[np.uint8]] | None = None
        self._origin = 0.0
        self._played_out = False
        for stamp, frame in self._frames:
            if stamp > timeout_s:
                break
            if self._track_frame(stamp, frame):
                self._origin = stamp
                self.duration = _played_from(video, stamp)
                return
        raise DeviceError(self._not_seen(timeout_s))

    def _track_frame(self, stamp: float, frame: NDArray[np.uint8]) -> bool:
        """Every instrument's estimate updated from one frame; whether all of them were seen."""
        seen = True
        for estimator, tracker in zip(self._estimators, self._trackers, strict=True):
            estimate = estimator.update(stamp, tracker.locate(frame))
            seen = seen and estimate is not None and estimate.measured
        return seen

    def _advance(self, time: float) -> None:
        video_time = time + self._origin
        while not self._played_out:
            if self._next is None:
                self._next = next(self._frames, None)
                if self._next is None:  # the last frame's pose is held to the session's end
                    self._played_out = True
                    return
            stamp, frame = self._next
            if stamp > video_time:
                return
            self._track_frame(stamp, frame)
            self._next = None

    # -- real time: a tracking process publishing through shared memory -----------------------
    def _open_tracking_process(self, timeout_s: float) -> None:
        """Start the tracking process and wait for its first sighting of every instrument. A file that
        plays out ends the process quietly (the last poses are held); a failure leaves its reason for
        the haptic loop."""
        context = multiprocessing.get_context("fork")
        self._shared = [SharedEstimate() for _ in self.bodies]
        self._go_at = context.Value("d", 0.0, lock=False)
        self._problem = context.Array("c", 400, lock=False)
        self._process = context.Process(target=self._track, name="vascsim-camera", daemon=True)
        self._process.start()
        first = self._shared[0]
        deadline = clock.perf_counter() + timeout_s
        while clock.perf_counter() < deadline:
            estimates = [shared.get() for shared in self._shared]
            if all(e is not None and e.measured for e in estimates):
                self._fps = first.fps or 30.0
                if isinstance(self.source, Path):  # the video's length from its first sighting
                    video = VideoFile(self.source)
                    self.duration = _played_from(video, first.origin)
                    video.close()
                return
            if first.ended:
                break
            clock.sleep(0.01)
        problem = self._problem.value.decode()
        self.close()
        raise DeviceError(problem or self._not_seen(timeout_s))

    def _publish(self, frame_time: float | None = None) -> None:
        for estimator, shared in zip(self._estimators, self._shared, strict=True):
            if estimator.estimate is not None:
                estimate = estimator.estimate
                shared.put(estimate if frame_time is None else replace(estimate, frame_time=frame_time))

    def _track(self) -> None:
        """The tracking process: frames in, estimates out, until the source ends or the device closes."""
        try_realtime_priority(TRACKING_PRIORITY)
        first = self._shared[0]
        try:
            frames, opened = open_frames(self.source)
            first.fps = float(getattr(opened, "fps", 30.0))
            self._trackers = [BodyTracker(self.camera, body) for body in self.bodies]
            paced = isinstance(self.source, Path)
            interval = 1.0 / max(first.fps, 1.0)
            origin = None
            for stamp, frame in frames:
                if not paced:  # a live camera: grab times are already on the haptic loop's clock
                    self._track_frame(stamp, frame)
                    self._publish()
                    continue
                if origin is None:  # acquiring: as fast as frames decode, until every instrument is seen
                    if self._track_frame(stamp, frame):
                        origin = first.origin = stamp
                        self._publish()
                        while not self._go_at.value:
                            clock.sleep(0.001)
                        self._publish(self._go_at.value)
                    continue
                due = self._go_at.value + (stamp - origin)  # the file plays at its own pace from the go
                while (wait := due - clock.perf_counter()) > 0:
                    clock.sleep(min(wait, 0.005))
                if clock.perf_counter() > due + interval:  # behind: the next frame is due, skip to it
                    first.dropped += 1
                    continue
                self._track_frame(stamp, frame)
                self._publish(due)
        except TrackingError as error:  # says which camera already
            self._problem.value = str(error).encode()[:399]
        except Exception as error:  # the parent reads why, and the haptic loop stops cleanly
            self._problem.value = f"camera {self.source}: {error}".encode()[:399]
        finally:
            for shared in self._shared:
                shared.end()

    # -- the haptic loop's side ----------------------------------------------------------------
    def read(self, time: float) -> DeviceSample:
        return self._read(0, time)

    def _estimate_and_age(self, index: int, time: float | None) -> tuple[Estimate | None, float]:
        """The newest estimate of instrument ``index`` and how old its frame is at session ``time``
        (None: now, asked from outside the haptic loop)."""
        if self.clock_kind == "simulated":
            estimate = self._estimators[index].estimate
            return (
                estimate,
                0.0 if time is None or estimate is None else time + self._origin - estimate.frame_time,
            )
        estimate = self._shared[index].get()
        go = self._go_at.value
        # on the perf_counter clock; a file's first estimate is re-stamped at the go: until then it is new
        age = clock.perf_counter() - max(estimate.frame_time, go) if estimate is not None and go else 0.0
        return estimate, age

    def _read(self, index: int, time: float) -> DeviceSample:
        if self.clock_kind == "simulated":
            self._advance(time)
        else:
            if not self._go and time > 0.0:  # the session's first tick: a file starts playing
                self._go_at.value = clock.perf_counter()
                self._go = True
            if self._shared[0].ended and self._problem.value:
                raise DeviceLostError(self._problem.value.decode())
        estimate, age = self._estimate_and_age(index, time)
        position, rotation, velocity, state = self._predictors[index].at(time, estimate, age)
        axes = self._axes
        jaws = int(self._jaws[index].value)
        return DeviceSample(time, axes @ position, axes @ rotation, axes @ velocity, jaws, tracking=state)

    def toggle_grip(self, index: int = 0) -> None:
        """Close or open the jaws (the station's G key, or a foot pedal set to send it; shared with the
        haptic process, which reads it each tick)."""
        self._jaws[index].value = 0 if self._jaws[index].value else 1

    def tracking_problem(self, index: int = 0) -> str | None:
        """What the heads-up strip should say about the tracking now, or None when it is fine (any
        process may ask: in real time the estimate is read from shared memory)."""
        estimate, age = self._estimate_and_age(index, None)
        name = self.bodies[index].name
        if estimate is None or not estimate.measured:
            return f"the camera has lost the {name}: show it the cube (the {name} stays put until then)"
        if age > STALE_FRAMES / self._fps:
            return f"the camera's frames are late: the {name} is predicted (tracking needs a processor core)"
        return None

    def write_force(self, force: NDArray[np.float64]) -> None:
        """A camera feels nothing: the force is shown on the heads-up gauge, never felt."""

    def close(self) -> None:
        """Stop the tracking process (from the process that started it; a forked copy leaves it)."""
        if self._process is not None and os.getpid() == self._owner:
            self._process.terminate()
            self._process.join(2.0)
            self._process = None

    def _not_seen(self, timeout_s: float) -> str:
        names = " and the ".join(
            f"{b.name}'s markers ({', '.join(str(i) for i in b.ids)})" for b in self.bodies
        )
        return (
            f"the {names} were not seen by camera {self.source} within {timeout_s:.0f} s: hold "
            f"{'them' if len(self.bodies) > 1 else 'it'} in view, facing the camera, in good light"
        )


class TrackedCompanion:
    """Another instrument tracked in a :class:`CameraDevice`'s frames (the forceps beside the holder):
    a device of its own for the subordinate hand, closed with the camera device."""

    limits = INPUT_ONLY_LIMITS

    def __init__(self, device: CameraDevice, index: int) -> None:
        if not 0 < index < len(device.bodies):
            raise DeviceError(f"camera device tracks {len(device.bodies)} instruments; no companion {index}")
        self._device, self._index = device, index
        self.identity = DeviceIdentity(
            "camera", f"{device.bodies[index].name} tracked by camera {device.source}"
        )

    def read(self, time: float) -> DeviceSample:
        return self._device._read(self._index, time)

    def toggle_grip(self) -> None:
        self._device.toggle_grip(self._index)

    def tracking_problem(self) -> str | None:
        return self._device.tracking_problem(self._index)

    def write_force(self, force: NDArray[np.float64]) -> None:
        """Felt by no one."""

    def close(self) -> None:
        """The camera device's own close stops the tracking."""
