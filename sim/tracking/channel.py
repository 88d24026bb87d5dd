"""From camera poses to the pose the 1 kHz haptic loop reads: gating, filtering, prediction, holding.

The camera side (:class:`PoseEstimator`, once per frame) refuses a pose that jumps further than a
hand can move since the last accepted one (a mirrored IPPE solution, a marker mistaken for another),
filters the rest (:mod:`sim.tracking.filters`) and publishes an :class:`Estimate`: the filtered tip,
its velocity, the rotation and angular velocity at the frame's time, and whether that frame saw the
instrument. The haptic side (:class:`PosePredictor`, once per tick) extrapolates the estimate to the
tick's time, which hides the frame's age (processing, and up to one frame interval of waiting), and
labels what it returns:

- ``MEASURED`` (0): extrapolated from a frame that saw the instrument, by at most
  :data:`STALE_FRAMES` frame intervals (the normal wait for the next frame);
- ``PREDICTED`` (1): frames are late (a stalled camera), extrapolated further, up to
  :data:`MAX_PREDICTION_FRAMES` intervals, then no further;
- ``HELD`` (2): the newest frame missed the instrument (occluded, blurred, out of view), or the last
  pose was refused: the tool is frozen where it was and its velocity is zero.

Whatever the input, the output moves at most :data:`OUTPUT_SPEED_LIMIT` (m/s) and turns at most
:data:`OUTPUT_TURN_LIMIT` (rad/s): when tracking returns after a loss the tool glides to the hand in a
few ticks instead of jumping.

:class:`SharedEstimate` carries estimates from a tracking process to the haptic process (a seqlock
over an anonymous shared mapping made before either forks).
"""

from __future__ import annotations

import math
import mmap
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from sim.runtime.shared import consistent_copy
from sim.tracking.filters import (
    RotationFilter,
    RotationKalman,
    position_filter,
    rotation_from_vector,
    rotation_vector,
)
from sim.tracking.pose import BodyPose

MEASURED, PREDICTED, HELD = 0, 1, 2
TRACKING_STATES = {MEASURED: "measured", PREDICTED: "predicted", HELD: "held"}
STALE_FRAMES = 1.5
"""An estimate older than this many frame intervals means frames are late: samples become PREDICTED."""
MAX_PREDICTION_FRAMES = 2.5
"""Extrapolation stops this many frame intervals after the last frame (the pose then stays put)."""
MAX_HAND_SPEED = 2.0
"""m/s: a tracked pose implying a faster hand than this since the last accepted one is refused
(suturing hands move at 0.01-0.3 m/s; a quick reach peaks near 1 m/s)."""
MAX_HAND_TURN = 6.0 * math.pi
"""rad/s (1,080 deg/s): the wrist's limit for the same test (a fast needle-driving turn is ~360 deg/s)."""
JUMP_MARGIN_M, TURN_MARGIN_RAD = 0.005, math.radians(15.0)
"""Allowance on top of the speed limits for one frame's pose noise."""
REFUSALS_BEFORE_RESET = 3
"""After this many refused poses in a row, which agree with each other, the tracker starts afresh from
the newest (the refused ones were right, the last accepted one wrong)."""
LOST_RESET_S = 0.5
"""After the instrument has been out of sight this long, the next pose is accepted without the jump
test and the filters start afresh."""
OUTPUT_SPEED_LIMIT = 1.0
"""m/s: the fastest the haptic pose moves (1 mm a 1 kHz tick), whatever the camera says; a quick reach
peaks near 1 m/s, suturing moves stay under 0.3 m/s."""
OUTPUT_TURN_LIMIT = 4.0 * math.pi
"""rad/s: the fastest the haptic pose turns."""


@dataclass(frozen=True)
class Estimate:
    """The filtered state at a frame: its time (s), tip position (m) and velocity (m/s), rotation and
    angular velocity (rad/s), whether the frame saw the instrument, and counts of frames so far."""

    frame_time: float
    position: NDArray[np.float64]
    velocity: NDArray[np.float64]
    rotation: NDArray[np.float64]
    angular_velocity: NDArray[np.float64]
    measured: bool
    frames: int = 0
    lost_frames: int = 0


class PoseEstimator:
    """Gates and filters one instrument's per-frame poses (the camera side; see the module docstring)."""

    def __init__(self, filter_kind: str = "kalman") -> None:
        self.filter_kind = filter_kind
        self._position = position_filter(filter_kind)
        self._rotation = RotationKalman() if filter_kind == "kalman" else RotationFilter()
        self._accepted: tuple[float, NDArray[np.float64], NDArray[np.float64]] | None = None
        self._refused: list[BodyPose] = []
        self.estimate: Estimate | None = None
        self.frames = self.lost_frames = self.refused_frames = 0

    def update(self, time: float, pose: BodyPose | None) -> Estimate | None:
        """Take the pose found in the frame at ``time`` (None: the instrument was not seen)."""
        self.frames += 1
        if pose is not None and not self._plausible(time, pose):
            self.refused_frames += 1
            pose = None
        if pose is None:
            self.lost_frames += 1
            if self.estimate is not None:
                self.estimate = Estimate(
                    self.estimate.frame_time, self.estimate.position, np.zeros(3), self.estimate.rotation,
                    np.zeros(3), False, self.frames, self.lost_frames,
                )  # fmt: skip
            return self.estimate
        if self._accepted is None or time - self._accepted[0] > LOST_RESET_S:
            self._position.reset()
            self._rotation.reset()
        self._accepted = (time, pose.tip, pose.rotation)
        # the body's origin and rotation are filtered, and the tip put back on: a tip far from the
        # markers turns their rotation noise into position noise, which the rotation filter smooths
        centre, centre_velocity = self._position(time, pose.translation)
        rotation, angular_velocity = self._rotation(time, pose.rotation)
        lever = rotation @ (pose.rotation.T @ (pose.tip - pose.translation))
        position = centre + lever
        velocity = centre_velocity + np.cross(angular_velocity, lever)
        self.estimate = Estimate(
            time, position, velocity, rotation, angular_velocity, True, self.frames, self.lost_frames
        )
        return self.estimate

    def _plausible(self, time: float, pose: BodyPose) -> bool:
        if self._accepted is None:
            return True
        then, tip, rotation = self._accepted
        elapsed = time - then
        if elapsed > LOST_RESET_S:
            return True
        moved = float(np.linalg.norm(pose.tip - tip))
        turned = float(np.linalg.norm(rotation_vector(pose.rotation @ rotation.T)))
        if (
            moved <= MAX_HAND_SPEED * elapsed + JUMP_MARGIN_M
            and turned <= MAX_HAND_TURN * elapsed + TURN_MARGIN_RAD
        ):
            self._refused.clear()
            return True
        self._refused.append(pose)
        if len(self._refused) >= REFUSALS_BEFORE_RESET and _agree(self._refused[-REFUSALS_BEFORE_RESET:]):
            self._refused.clear()
            self._accepted = None  # the refused ones agree: start afresh from this one
            return True
        return False


def _agree(poses: list[BodyPose]) -> bool:
    first = poses[0]
    return all(
        np.linalg.norm(p.tip - first.tip) < 4 * JUMP_MARGIN_M
        and np.linalg.norm(rotation_vector(p.rotation @ first.rotation.T)) < 2 * TURN_MARGIN_RAD
        for p in poses[1:]
    )


class PosePredictor:
    """The haptic side: an estimate extrapolated to a tick's time, labelled, and rate-limited."""

    def __init__(self, frame_interval_s: float) -> None:
        self.frame_interval_s = frame_interval_s
        self._last: tuple[float, NDArray[np.float64], NDArray[np.float64]] | None = None

    def at(
        self, time: float, estimate: Estimate, age: float | None = None
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], int]:
        """(position, rotation, velocity, state) at ``time``; ``age``: how old the estimate's frame is
        (s; by default ``time - estimate.frame_time``, both on one clock)."""
        age = time - estimate.frame_time if age is None else age
        interval = self.frame_interval_s
        if not estimate.measured and self._last is not None:
            state, position, rotation, velocity = HELD, self._last[1], self._last[2], np.zeros(3)
        else:
            state = MEASURED if age <= STALE_FRAMES * interval else PREDICTED
            if age > MAX_PREDICTION_FRAMES * interval:
                state = HELD
            horizon = min(max(age, 0.0), MAX_PREDICTION_FRAMES * interval)
            position = estimate.position + estimate.velocity * horizon
            rotation = rotation_from_vector(estimate.angular_velocity * horizon) @ estimate.rotation
            velocity = estimate.velocity if state != HELD else np.zeros(3)
        if self._last is not None:
            position, rotation = self._limited(time, position, rotation)
        self._last = (time, position, rotation)
        return position, rotation, velocity, state

    def _limited(self, time, position, rotation):
        then, last_position, last_rotation = self._last
        elapsed = max(time - then, 0.0)
        step = position - last_position
        reach = OUTPUT_SPEED_LIMIT * elapsed
        distance = float(np.linalg.norm(step))
        if distance > reach:
            position = last_position + step * (reach / distance)
        turn = rotation_vector(rotation @ last_rotation.T)
        angle, allowed = float(np.linalg.norm(turn)), OUTPUT_TURN_LIMIT * elapsed
        if angle > allowed:
            rotation = rotation_from_vector(turn * (allowed / angle)) @ last_rotation
        return position, rotation


class SharedEstimate:
    """The newest :class:`Estimate` of one instrument, between processes (seqlock).

    Layout: [seq, frame_time, position 3, velocity 3, rotation 9, angular velocity 3, measured,
    frames, lost frames, frame rate, origin, ended, dropped]. ``dropped``: frames the tracking process
    skipped because the next one was already due (it keeps up with the newest, never falls behind);
    ``origin``: a video file's time (s) of the first frame
    that saw the instrument (session time 0); ``ended``: the source has no more frames (a file played
    out) or failed.
    """

    DOUBLES = 27

    def __init__(self) -> None:
        self._map = mmap.mmap(-1, 8 * self.DOUBLES)
        self._slot = np.frombuffer(self._map, dtype=np.float64)

    def put(self, estimate: Estimate) -> None:
        slot = self._slot
        slot[0] += 1  # odd: writing
        slot[1] = estimate.frame_time
        slot[2:5] = estimate.position
        slot[5:8] = estimate.velocity
        slot[8:17] = estimate.rotation.ravel()
        slot[17:20] = estimate.angular_velocity
        slot[20] = 1.0 if estimate.measured else 0.0
        slot[21], slot[22] = estimate.frames, estimate.lost_frames
        slot[0] += 1

    @property
    def fps(self) -> float:
        """The source's frame rate (frames/s), 0 until the tracking process has opened it."""
        return float(self._slot[23])

    @fps.setter
    def fps(self, value: float) -> None:
        self._slot[23] = value

    @property
    def dropped(self) -> int:
        return int(self._slot[26])

    @dropped.setter
    def dropped(self, value: int) -> None:
        self._slot[26] = value

    @property
    def origin(self) -> float:
        return float(self._slot[24])

    @origin.setter
    def origin(self, value: float) -> None:
        self._slot[24] = value

    def end(self) -> None:
        self._slot[25] = 1.0

    @property
    def ended(self) -> bool:
        return bool(self._slot[25])

    def get(self) -> Estimate | None:
        """The newest estimate, or None before the first."""
        copy = consistent_copy(self._slot)
        if copy is None:
            return None
        return Estimate(
            float(copy[1]), copy[2:5].copy(), copy[5:8].copy(), copy[8:17].reshape(3, 3).copy(),
            copy[17:20].copy(), bool(copy[20]), int(copy[21]), int(copy[22]),
        )  # fmt: skip
