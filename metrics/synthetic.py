"""Synthetic session streams for benchmarks, tests and demonstrations (clearly labelled synthetic).

These are generated directly as arrays, without the simulator, so thousands can be
made quickly; ``vascsim demo`` instead drives scripted participants through the
real simulator and recorder. ``skill`` in [0, 1] shapes every stream: lower skill
gives more hesitations, more tremor, larger entry-angle error, faster tip speed at
insertion, more force, and occasional failed attempts.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from metrics.streams import SessionStreams


def _minimum_jerk(s: np.ndarray) -> np.ndarray:
    s = np.clip(s, 0.0, 1.0)
    return 10 * s**3 - 15 * s**4 + 6 * s**5


def synthetic_session(
    session_id: str,
    participant_id: str,
    label: str,
    trial: int,
    skill: float,
    duration: float = 60.0,
    rate: float = 1000.0,
    seed: int = 0,
    phase: str = "practice",
) -> SessionStreams:
    """One synthetic session of ``duration`` s at ``rate`` Hz: stitches of reach, bite, pull."""
    rng = np.random.default_rng(seed)
    n = int(duration * rate)
    time = np.arange(n) / rate
    stitches = max(1, int(duration // 12))
    per = duration / stitches
    position = np.zeros((n, 3))
    tip = np.zeros((n, 3))
    force = np.zeros((n, 3))
    state = np.zeros(n, dtype=np.int8)
    events = []
    hesitation = 1.0 - skill
    for k in range(stitches):
        start = k * per
        entry = np.array([0.005 * k, 0.0, 0.0])
        reaches = 1 + rng.poisson(3 * hesitation)
        window = (time >= start) & (time < start + per)
        local = (time[window] - start) / per
        target = entry + np.array([0.0, 0.0, 0.004])
        path = np.zeros((local.size, 3))
        origin = entry + np.array([0.01, 0.01, 0.02])
        # sub-movements towards the entry point; a hesitant hand's intermediate waypoints stray
        # sideways (detours that lengthen the path in the hand's own band, not only tremor)
        waypoints = [origin + (target - origin) * (r + 1) / reaches for r in range(reaches)]
        for r in range(reaches - 1):
            waypoints[r] = waypoints[r] + rng.normal(0.0, 0.03 * hesitation, 3)
        for r in range(reaches):
            s = (local * 2.0 - r / reaches) * reaches
            waypoint = waypoints[r]
            previous = origin if r == 0 else waypoints[r - 1]
            path += np.where((s >= 0)[:, None], (waypoint - previous) * _minimum_jerk(s)[:, None], 0.0)
        path += origin
        tremor = (0.0001 + 0.0006 * hesitation) * np.sin(2 * np.pi * 9.0 * time[window] + rng.uniform(0, 6))[
            :, None
        ]
        position[window] = path + tremor
        contact_t = start + 0.5 * per
        attempts = rng.binomial(2, 0.4 * hesitation)
        for a in range(attempts):
            t0 = contact_t - 0.3 * (attempts - a)
            events.append((t0, "contact_start", np.nan))
            events.append((t0 + 0.1, "contact_end", np.nan))
        angle = abs(rng.normal(3 + 20 * hesitation, 3))
        insertion_speed = 0.003 + 0.006 * hesitation + rng.normal(0, 0.0005)
        pierce_t = contact_t + 0.1 + 0.4 * hesitation
        exit_t = pierce_t + 0.6
        events += [(contact_t, "contact_start", angle), (pierce_t, "pierce", angle), (exit_t, "exit", np.nan)]
        events += [(exit_t + 0.5, "release", np.nan), (exit_t + 1.0, "regrab", np.nan)]
        events += [(exit_t + 2.5, "pull_through", np.nan), (exit_t + 2.6, "contact_end", np.nan)]
        inside = (time >= contact_t) & (time < exit_t + 2.6)
        state[inside] = 1
        state[(time >= pierce_t) & (time < exit_t)] = 2
        state[(time >= exit_t) & (time < exit_t + 2.6)] = 3
        ramp = np.clip((time - contact_t) / (pierce_t - contact_t), 0, 1)
        peak = 1.0 + 1.5 * hesitation + rng.normal(0, 0.1)
        magnitude = np.where(
            inside,
            peak * np.where(time < pierce_t, ramp, np.exp(-np.clip(time - pierce_t, 0, None) * 2)),
            0.0,
        )
        force[:, 2] += magnitude
        tip[window] = position[window] - np.array([0.0, 0.0, 0.004])
        moving = (time >= contact_t) & (time < exit_t)
        tip[moving, 2] -= insertion_speed * (time[moving] - contact_t)
    frame = pd.DataFrame(events, columns=["time", "kind", "entry_angle_deg"])
    subordinate = 0.0005 * (1 + 3 * hesitation) * np.sin(2 * np.pi * 0.5 * time + rng.uniform(0, 6))[:, None]
    return SessionStreams(
        session_id=session_id,
        participant_id=participant_id,
        label=label,
        time=time,
        tool_position=position,
        tip_position=tip,
        force=force,
        needle_state=state,
        subordinate_displacement=np.repeat(subordinate, 3, axis=1),
        events=frame,
        attributes={"trial": trial, "synthetic": True, "phase": phase},
    )


def synthetic_study(
    experts: int = 4,
    expert_sessions: int = 3,
    trainees: int = 6,
    trainee_sessions: int = 6,
    retention: bool = True,
    duration: float = 60.0,
    rate: float = 1000.0,
    seed: int = 0,
):
    """Yields SessionStreams of a study: experts at a stable high skill, trainees improving with practice."""
    rng = np.random.default_rng(seed)
    for e in range(experts):
        base = rng.uniform(0.8, 0.95)
        for t in range(1, expert_sessions + 1):
            yield synthetic_session(
                f"E{e:02d}-{t:02d}",
                f"E{e:02d}",
                "expert",
                t,
                base,
                duration,
                rate,
                int(rng.integers(1 << 31)),
            )
    for p in range(trainees):
        start, gain = rng.uniform(0.1, 0.35), rng.uniform(0.3, 0.6)
        for t in range(1, trainee_sessions + 1):
            skill = start + (0.9 - start) * (1 - np.exp(-gain * (t - 1)))
            yield synthetic_session(
                f"T{p:02d}-{t:02d}",
                f"T{p:02d}",
                "trainee",
                t,
                skill,
                duration,
                rate,
                int(rng.integers(1 << 31)),
            )
        if retention:
            t = trainee_sessions + 1
            skill = start + (0.9 - start) * (1 - np.exp(-gain * (trainee_sessions - 1))) - 0.08
            yield synthetic_session(
                f"T{p:02d}-{t:02d}", f"T{p:02d}", "trainee", t, skill, duration, rate,
                int(rng.integers(1 << 31)), phase="retention",
            )  # fmt: skip
