"""Devices without hardware: scripted trajectories (functions, files, a suturing pass: the hand itself
is :mod:`sim.devices.suturing`) and replays."""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sim.devices.base import (
    SCRIPTED_LIMITS,
    DeviceError,
    DeviceIdentity,
    DeviceLimits,
    DeviceSample,
    Trajectory,
)
from sim.devices.suturing import SuturingPass, SuturingPassParameters, blend_poses, sequence_of_passes
from sim.needle import Pose

VELOCITY_STEP = 1e-3  # s, for the finite-difference velocity of a trajectory


class ForceLog:
    """Forces commanded to a device, in a growing preallocated buffer (time, fx, fy, fz)."""

    def __init__(self, capacity: int = 65536) -> None:
        self._data = np.empty((capacity, 4))
        self._count = 0

    def append(self, time: float, force: NDArray[np.float64]) -> None:
        if self._count == len(self._data):
            self._data = np.concatenate([self._data, np.empty_like(self._data)])
        fx, fy, fz = force.tolist()
        self._data[self._count] = (time, fx, fy, fz)  # one assignment: every haptic tick
        self._count += 1

    @property
    def array(self) -> NDArray[np.float64]:
        return self._data[: self._count]


class ScriptedDevice:
    """A device driven by a trajectory ``t -> (holder pose, grip closed)``; logs the forces it is sent.

    Button 0 reports the grip. Works under both clocks: ``read(time)`` evaluates the
    trajectory at the time it is given.
    """

    def __init__(
        self,
        trajectory: Trajectory,
        limits: DeviceLimits = SCRIPTED_LIMITS,
        identity: DeviceIdentity | None = None,
    ) -> None:
        self.trajectory = trajectory
        self.limits = limits
        self.identity = identity or DeviceIdentity("scripted", "scripted trajectory")
        self.forces = ForceLog()
        self._now = 0.0
        self._previous: tuple[float, NDArray[np.float64]] | None = None

    def read(self, time: float) -> DeviceSample:
        """The trajectory at ``time``; velocity from the previous reading when it is recent."""
        self._now = time
        pose, grip = self.trajectory(time)
        if self._previous is not None and 0 < time - self._previous[0] <= 10 * VELOCITY_STEP:
            velocity = (pose.position - self._previous[1]) / (time - self._previous[0])
        else:
            before, _ = self.trajectory(time - VELOCITY_STEP)
            velocity = (pose.position - before.position) / VELOCITY_STEP
        self._previous = (time, pose.position)
        return DeviceSample(time, pose.position, pose.rotation, velocity, int(grip), pose)

    def write_force(self, force: NDArray[np.float64]) -> None:
        self.forces.append(self._now, force)

    def see_needle(self, needle_pose: Callable[[], Pose] | None) -> None:
        """Let a trajectory that can look (a :class:`SuturingPass`, :func:`sequence_of_passes`) see
        where the needle is: the simulated-time loop passes the interaction's needle pose."""
        owner = getattr(self.trajectory, "__self__", self.trajectory)
        hook = getattr(self.trajectory, "see_needle", None) or getattr(owner, "see_needle", None)
        if hook is not None:
            hook(needle_pose)

    def close(self) -> None:
        """Nothing to release."""

    @classmethod
    def from_samples(
        cls,
        times: ArrayLike,
        positions: ArrayLike,
        quaternions: ArrayLike,
        grips: ArrayLike | None = None,
        identity: DeviceIdentity | None = None,
    ) -> ScriptedDevice:
        """Play back sampled poses: positions (n, 3) m, quaternions (n, 4) w-x-y-z, grips (n,)."""
        return cls(sampled_trajectory(times, positions, quaternions, grips), identity=identity)

    @classmethod
    def from_file(cls, path: str | Path) -> ScriptedDevice:
        """A CSV or Parquet file with columns time, x, y, z, qw, qx, qy, qz and optionally grip."""
        path = Path(path)
        columns = _read_table(path)
        missing = [c for c in ("time", "x", "y", "z", "qw", "qx", "qy", "qz") if c not in columns]
        if missing:
            raise DeviceError(f"trajectory file {path} lacks column(s) {', '.join(missing)}")
        positions = np.column_stack([columns[c] for c in "xyz"])
        quaternions = np.column_stack([columns[c] for c in ("qw", "qx", "qy", "qz")])
        identity = DeviceIdentity("scripted", f"trajectory file {path.name}")
        return cls.from_samples(columns["time"], positions, quaternions, columns.get("grip"), identity)


class ReplayDevice(ScriptedDevice):
    """A recorded session played back through the same loop (samples given as arrays)."""

    def __init__(
        self,
        times: ArrayLike,
        positions: ArrayLike,
        quaternions: ArrayLike,
        grips: ArrayLike | None = None,
        session: str = "",
    ) -> None:
        super().__init__(
            sampled_trajectory(times, positions, quaternions, grips),
            identity=DeviceIdentity("replay", f"replay of session {session}".strip()),
        )


def _read_table(path: Path) -> dict[str, NDArray]:
    if not path.is_file():
        raise DeviceError(f"trajectory file {path} does not exist")
    if path.suffix == ".parquet":
        import pyarrow.parquet as pq

        table = pq.read_table(path)
        return {name: table.column(name).to_numpy() for name in table.column_names}
    try:
        data = np.genfromtxt(path, delimiter=",", names=True)
    except ValueError as error:
        raise DeviceError(f"trajectory file {path} is not a readable CSV: {error}") from error
    if data.dtype.names is None or data.size == 0:
        raise DeviceError(f"trajectory file {path} has no header row or no samples")
    return {name: np.atleast_1d(data[name]) for name in data.dtype.names}


def sampled_trajectory(
    times: ArrayLike, positions: ArrayLike, quaternions: ArrayLike, grips: ArrayLike | None = None
) -> Trajectory:
    """Linear interpolation of positions and normalised-linear interpolation of quaternions."""
    t = np.asarray(times, dtype=np.float64)
    p = np.asarray(positions, dtype=np.float64)
    q = np.asarray(quaternions, dtype=np.float64)
    g = np.ones(len(t), dtype=bool) if grips is None else np.asarray(grips) > 0.5
    if len(t) < 1 or p.shape != (len(t), 3) or q.shape != (len(t), 4):
        raise DeviceError(
            f"trajectory needs times (n,), positions (n, 3), quaternions (n, 4); "
            f"got {t.shape}, {p.shape}, {q.shape}"
        )
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(p)) and np.all(np.isfinite(q))):
        raise DeviceError("trajectory samples must be finite numbers")
    if np.any(np.diff(t) <= 0):
        bad = int(np.flatnonzero(np.diff(t) <= 0)[0])
        raise DeviceError(
            f"trajectory times must increase; sample {bad + 1} ({t[bad + 1]:.6g} s) is not after "
            f"sample {bad} ({t[bad]:.6g} s)"
        )
    flips = np.cumprod(np.where(np.einsum("ij,ij->i", q[1:], q[:-1]) < 0, -1.0, 1.0))
    q = np.vstack([q[:1], q[1:] * flips[:, None]])  # keep consecutive quaternions in one hemisphere

    def trajectory(time: float) -> tuple[Pose, bool]:
        k = int(np.clip(np.searchsorted(t, time, side="right") - 1, 0, len(t) - 1))
        if k == len(t) - 1 or time <= t[0]:
            return Pose(p[k], quaternion_matrix(q[k])), bool(g[k])
        w = (time - t[k]) / (t[k + 1] - t[k])
        quaternion = (1 - w) * q[k] + w * q[k + 1]
        return Pose((1 - w) * p[k] + w * p[k + 1], quaternion_matrix(quaternion)), bool(g[k])

    return trajectory


def quaternion_matrix(quaternion: NDArray[np.float64]) -> NDArray[np.float64]:
    """Rotation matrix of a (w, x, y, z) quaternion (normalised here)."""
    w, x, y, z = quaternion / np.linalg.norm(quaternion)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def matrix_quaternion(rotation: NDArray[np.float64]) -> NDArray[np.float64]:
    """(w, x, y, z) quaternion of a rotation matrix (w >= 0)."""
    m = rotation
    trace = np.trace(m)
    if trace > 0:
        s = 2.0 * math.sqrt(1.0 + trace)
        q = [0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s]
    else:
        i = int(np.argmax(np.diag(m)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * math.sqrt(1.0 + m[i, i] - m[j, j] - m[k, k])
        q = [0.0] * 4
        q[0] = (m[k, j] - m[j, k]) / s
        q[1 + i] = 0.25 * s
        q[1 + j] = (m[j, i] + m[i, j]) / s
        q[1 + k] = (m[k, i] + m[i, k]) / s
    q = np.array(q)
    return q if q[0] >= 0 else -q


__all__ = [
    "ForceLog",
    "ReplayDevice",
    "ScriptedDevice",
    "SuturingPass",
    "SuturingPassParameters",
    "Trajectory",
    "blend_poses",
    "matrix_quaternion",
    "quaternion_matrix",
    "sampled_trajectory",
    "sequence_of_passes",
]
