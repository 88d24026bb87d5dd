"""Filters that turn noisy camera poses (30-120 a second) into a smooth pose and its velocity.

Two position filters, measured against each other in ``benchmarks/camera.py``:

- :class:`OneEuroFilter` (Casiez, Roussel & Vogel, CHI 2012): a first-order low-pass whose cut-off
  rises with the signal's speed, ``f_c = f_min + beta |x'|``, so a still hand is smoothed hard (no
  jitter) and a moving one barely lags. Its derivative, low-passed at its own cut-off, is the
  velocity used for prediction.
- :class:`ConstantVelocityKalman`: the textbook constant-velocity model driven by white acceleration
  noise of spectral density ``q`` (m^2/s^3), measurement noise ``r`` (m RMS) per axis: a marker's
  depth (the camera's z) is several times noisier than its position across the image.

:class:`RotationFilter` applies the one-euro rule to orientation: it moves the estimate along the
shortest arc (slerp) towards each measurement by the one-euro weight for the filtered angular speed,
and keeps that angular velocity (rad/s, camera frame) for prediction.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from sim.errors import TrackingError


def smoothing_weight(cutoff_hz: float, interval_s: float) -> float:
    """The weight of a new sample in a first-order low-pass at ``cutoff_hz`` sampled every ``interval_s``."""
    tau = 1.0 / (2.0 * math.pi * cutoff_hz)
    return 1.0 / (1.0 + tau / interval_s)


class OneEuroFilter:
    """One-euro filter on a vector signal (see the module docstring).

    min_cutoff_hz: cut-off for a still signal; beta: how fast the cut-off rises with speed (Hz per unit
    of speed, here per m/s); derivative_cutoff_hz: cut-off of the derivative's own low-pass.
    """

    def __init__(self, min_cutoff_hz: float = 1.0, beta: float = 300.0, derivative_cutoff_hz: float = 2.0):
        if not (min_cutoff_hz > 0 and beta >= 0 and derivative_cutoff_hz > 0):
            raise TrackingError(
                f"one-euro filter: cut-offs must be positive and beta not negative, got min_cutoff_hz="
                f"{min_cutoff_hz}, beta={beta}, derivative_cutoff_hz={derivative_cutoff_hz}"
            )
        self.min_cutoff_hz, self.beta, self.derivative_cutoff_hz = min_cutoff_hz, beta, derivative_cutoff_hz
        self.reset()

    def reset(self) -> None:
        self.value: NDArray[np.float64] | None = None
        self.velocity = np.zeros(3)
        self._time = 0.0

    def __call__(self, time: float, measured: NDArray[np.float64]) -> tuple[NDArray, NDArray]:
        """Feed one measurement taken at ``time`` (s); returns (filtered value, filtered velocity)."""
        measured = np.asarray(measured, dtype=np.float64)
        if self.value is None or time <= self._time:
            if self.value is None:
                self.value = measured.copy()
            self._time = time
            return self.value.copy(), self.velocity.copy()
        interval = time - self._time
        raw_velocity = (measured - self.value) / interval
        self.velocity = self.velocity + smoothing_weight(self.derivative_cutoff_hz, interval) * (
            raw_velocity - self.velocity
        )
        cutoff = self.min_cutoff_hz + self.beta * float(np.linalg.norm(self.velocity))
        self.value = self.value + smoothing_weight(cutoff, interval) * (measured - self.value)
        self._time = time
        return self.value.copy(), self.velocity.copy()


def constant_velocity_update(
    covariance: NDArray[np.float64], dt: float, q: float, r2
) -> tuple[NDArray, NDArray]:
    """One step of the constant-velocity model's covariance: predicted over ``dt`` with white
    acceleration of density ``q``, then updated by a measurement of the value with variance ``r2``.
    ``covariance``: (2, 2) [[var value, cov], [cov, var rate]], or (k, 2, 2) with ``r2`` of shape (k,)
    (one per axis). Returns the gains on (value, rate) ((2,) or (k, 2)) and the updated covariance."""
    F = np.array([[1.0, dt], [0.0, 1.0]])
    Q = q * np.array([[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]])
    P = F @ covariance @ F.T + Q
    gain = P[..., :, 0] / (P[..., 0, 0] + r2)[..., None]
    return gain, P - gain[..., :, None] * P[..., None, 0, :]


class ConstantVelocityKalman:
    """Constant-velocity Kalman filter on a 3-vector (see the module docstring)."""

    def __init__(self, acceleration_density: float = 0.1, measurement_noise_m=(3e-4, 3e-4, 1.5e-3)) -> None:
        noise = np.broadcast_to(np.asarray(measurement_noise_m, dtype=np.float64), (3,))
        if not (acceleration_density > 0 and np.all(noise > 0)):
            raise TrackingError(
                "Kalman filter: acceleration density and measurement noise must be positive, got "
                f"{acceleration_density} and {measurement_noise_m}"
            )
        self.q, self.r2 = acceleration_density, noise**2
        self.reset()

    def reset(self) -> None:
        self.value: NDArray[np.float64] | None = None
        self.velocity = np.zeros(3)
        self._covariance = np.zeros((2, 2))
        self._time = 0.0

    def __call__(self, time: float, measured: NDArray[np.float64]) -> tuple[NDArray, NDArray]:
        measured = np.asarray(measured, dtype=np.float64)
        if self.value is None:
            self.value = measured.copy()
            # per axis [[var x, cov], [cov, var v]]; velocity unknown: hands move ~5 cm/s
            self._covariance = np.zeros((3, 2, 2))
            self._covariance[:, 0, 0], self._covariance[:, 1, 1] = self.r2, 0.05**2
            self._time = time
            return self.value.copy(), self.velocity.copy()
        dt = max(time - self._time, 0.0)
        self._time = max(time, self._time)
        self.value = self.value + self.velocity * dt  # predicted, then corrected
        gain, self._covariance = constant_velocity_update(self._covariance, dt, self.q, self.r2)
        innovation = measured - self.value
        self.value = self.value + gain[:, 0] * innovation
        self.velocity = self.velocity + gain[:, 1] * innovation
        return self.value.copy(), self.velocity.copy()


def position_filter(kind: str):
    """A fresh position filter by name: ``kalman`` (the default) or ``one-euro``.

    Measured on rendered video of the marker cube rolled at 30 cm, 1280x720, 30 frames/s
    (``benchmarks/camera.py``, docs/benchmarks.md): the Kalman filters' haptic-rate tip was 0.72 mm RMS
    from the truth, the one-euro filters' (position beta 300, rotation beta 30, tuned on it) 1.05 mm, and
    their lag 1 ms against 4 ms: the one-euro filter lags as it smooths, and the tip 120 mm from the
    cube turns its rotation lag into millimetres. Both hold a still instrument well inside 0.1 mm."""
    if kind == "one-euro":
        return OneEuroFilter()
    if kind == "kalman":
        return ConstantVelocityKalman()
    raise TrackingError(f"unknown pose filter {kind!r}; use one-euro or kalman")


FILTERS = ("kalman", "one-euro")


def rotation_vector(rotation: NDArray[np.float64]) -> NDArray[np.float64]:
    """The axis times angle (rad) of a rotation matrix (angle in [0, pi])."""
    cosine = min(max((np.trace(rotation) - 1.0) / 2.0, -1.0), 1.0)
    angle = math.acos(cosine)
    if angle < 1e-9:
        return np.zeros(3)
    axis = np.array(
        [rotation[2, 1] - rotation[1, 2], rotation[0, 2] - rotation[2, 0], rotation[1, 0] - rotation[0, 1]]
    )
    if angle > math.pi - 1e-4:  # near a half turn the skew part vanishes: read the axis off the diagonal
        diagonal = np.sqrt(np.maximum((np.diag(rotation) + 1.0) / 2.0, 0.0))
        k = int(np.argmax(diagonal))
        axis = (rotation[:, k] + np.eye(3)[k]) / 2.0
        axis = axis / max(np.linalg.norm(axis), 1e-12)
        return angle * axis
    return angle * axis / (2.0 * math.sin(angle))


def rotation_from_vector(vector: NDArray[np.float64]) -> NDArray[np.float64]:
    """Rodrigues' formula: the rotation about ``vector`` by its length (rad)."""
    angle = float(np.linalg.norm(vector))
    if angle < 1e-12:
        return np.eye(3)
    k = np.asarray(vector) / angle
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + math.sin(angle) * K + (1.0 - math.cos(angle)) * (K @ K)


class RotationKalman:
    """Constant-angular-velocity Kalman filter on an orientation (a multiplicative filter: the state is
    a rotation and an angular velocity, the innovation the rotation vector from the prediction to the
    measurement). ``acceleration_density``: angular acceleration noise (rad^2/s^3); ``measurement_noise_rad``:
    a pose's orientation noise (rad RMS, the same about every axis)."""

    def __init__(self, acceleration_density: float = 5.0, measurement_noise_rad: float = 0.01) -> None:
        if not (acceleration_density > 0 and measurement_noise_rad > 0):
            raise TrackingError(
                "rotation Kalman filter: acceleration density and measurement noise must be positive, got "
                f"{acceleration_density} and {measurement_noise_rad}"
            )
        self.q, self.r2 = acceleration_density, measurement_noise_rad**2
        self.reset()

    def reset(self) -> None:
        self.rotation: NDArray[np.float64] | None = None
        self.angular_velocity = np.zeros(3)
        self._covariance = np.zeros((2, 2))
        self._time = 0.0

    def __call__(self, time: float, measured: NDArray[np.float64]) -> tuple[NDArray, NDArray]:
        if self.rotation is None:
            self.rotation = np.array(measured, dtype=np.float64)
            self._covariance = np.diag([self.r2, 1.0])  # angular velocity unknown: ~1 rad/s
            self._time = time
            return self.rotation.copy(), self.angular_velocity.copy()
        dt = max(time - self._time, 0.0)
        self._time = max(time, self._time)
        predicted = rotation_from_vector(self.angular_velocity * dt) @ self.rotation
        gain, self._covariance = constant_velocity_update(self._covariance, dt, self.q, self.r2)
        innovation = rotation_vector(np.asarray(measured) @ predicted.T)
        self.rotation = orthonormal(rotation_from_vector(gain[0] * innovation) @ predicted)
        self.angular_velocity = self.angular_velocity + gain[1] * innovation
        return self.rotation.copy(), self.angular_velocity.copy()


def orthonormal(rotation: NDArray[np.float64]) -> NDArray[np.float64]:
    """The nearest rotation to a matrix a rounding error away from one (Gram-Schmidt on its columns)."""
    x = rotation[:, 0] / np.linalg.norm(rotation[:, 0])
    y = rotation[:, 1] - np.dot(x, rotation[:, 1]) * x
    y = y / np.linalg.norm(y)
    return np.column_stack([x, y, np.cross(x, y)])


class RotationFilter:
    """One-euro smoothing of an orientation (see the module docstring). ``beta`` in Hz per rad/s."""

    def __init__(self, min_cutoff_hz: float = 0.8, beta: float = 30.0, derivative_cutoff_hz: float = 2.0):
        self.min_cutoff_hz, self.beta, self.derivative_cutoff_hz = min_cutoff_hz, beta, derivative_cutoff_hz
        self.reset()

    def reset(self) -> None:
        self.rotation: NDArray[np.float64] | None = None
        self.angular_velocity = np.zeros(3)
        self._time = 0.0

    def __call__(self, time: float, measured: NDArray[np.float64]) -> tuple[NDArray, NDArray]:
        """Feed one rotation matrix taken at ``time``; returns (filtered rotation, angular velocity)."""
        if self.rotation is None or time <= self._time:
            if self.rotation is None:
                self.rotation = np.array(measured, dtype=np.float64)
            self._time = time
            return self.rotation.copy(), self.angular_velocity.copy()
        interval = time - self._time
        step = rotation_vector(measured @ self.rotation.T)  # from the estimate to the measurement
        self.angular_velocity = self.angular_velocity + smoothing_weight(
            self.derivative_cutoff_hz, interval
        ) * (step / interval - self.angular_velocity)
        cutoff = self.min_cutoff_hz + self.beta * float(np.linalg.norm(self.angular_velocity))
        turned = rotation_from_vector(smoothing_weight(cutoff, interval) * step) @ self.rotation
        self.rotation = orthonormal(turned)
        self._time = time
        return self.rotation.copy(), self.angular_velocity.copy()
