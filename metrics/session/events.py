"""Session events in the words a supervisor reads: one name per kind, and the simulator's own
checks collapsed into one line with a count and what they mean.

The dashboard's event list (and anything else that lists events) takes them from
:func:`readable_events`, so a kind reads the same everywhere.
"""

from __future__ import annotations

import math
import re

import pandas as pd

EVENT_NAMES: dict[str, str] = {
    "contact_start": "needle touched the tissue",
    "contact_end": "needle lifted off the tissue",
    "pierce": "needle entered the tissue",
    "exit": "needle came out",
    "pull_through": "needle pulled through",
    "release": "needle released",
    "regrab": "needle re-grasped",
    "implausible_hit": "the needle crossed the tissue in a way the simulator does not follow",
    "overstress": "tissue stress at the needle above the damage threshold",
    "edge_overstress": "wound edge stressed past the damage threshold (tearing risk)",
    "tear": "the wall gave way under the needle (more force than it can carry)",
    "wrist_stop": "the wrist at its stop: evert the edge to enter square",
    "grasp": "forceps took the wound edge",
    "release_grasp": "forceps let go of the wound edge",
    "edge_torn": "the wound edge tore out of the forceps (pulled harder than it holds)",
    "watchdog": "simulator fell behind (safety watchdog)",
    "watchdog_recovered": "simulator caught up",
    "force_clamped": "force to the device limited to its rating",
    "nonfinite_force": "invalid force withheld from the device",
    "device_lost": "device disconnected",
    "layer_failed": "a simulator layer failed",
    "tracking_lost": "the camera lost the instrument (held still until seen again)",
    "tracking_regained": "the camera saw the instrument again",
    "stopped": "session stopped",
    "queue_overflow": "recorder queue overflowed",
    "marker": "marker",
    "annotation": "annotation",
}
"""Every event kind the recorder stores, named for a person (tests check none is missing)."""

COLLAPSED: dict[str, str] = {
    "implausible_hit": "the simulator's plausibility check: the needle crossed the tissue's surface in a way "
    "the model does not follow (inside the wall without piercing it, touching at more points than it models "
    "at once, or into a wall out of turn); listed once",
    "force_clamped": "the force sent to the device was limited to what it can render safely; listed once",
}
"""Kinds that come in runs: one line with a count and this explanation instead of one line each."""


SAFETY_EVENTS = (
    "overstress",
    "edge_overstress",
    "tear",
    "edge_torn",
    "force_clamped",
    "nonfinite_force",
    "device_lost",
)
"""Kinds that say the patient (or the trainee's hand) was at risk: listed first, apart from the rest."""


EPISODE_GAP_S = 0.5
"""Safety events of one kind less than this apart (s) are one episode: listed once with a count and
the time it ended (a levered needle overstresses the wall tick after tick)."""


_FIRST_NUMBER = re.compile(r"-?\d+(?:\.\d+)?")


def event_name(kind: str) -> str:
    return EVENT_NAMES.get(kind, kind.replace("_", " "))


def _recorded_words(event) -> str:
    """The words the simulator recorded with the event (their first line; "" for none)."""
    words = getattr(event, "detail", None)
    return words.splitlines()[0].strip() if isinstance(words, str) and words.strip() else ""


def _size(words: str) -> float:
    """The first number in an event's words: the value the one code site writing each kind puts
    first ("local stress 930 kPa over 800 kPa", "2400 mN clamped to the rated 880 mN"); -inf for none."""
    found = _FIRST_NUMBER.search(words)
    return float(found.group()) if found else -math.inf


def readable_events(events: pd.DataFrame) -> list[dict]:
    """One entry per event in time order (time s, kind, name, the needle's angle to the surface's
    normal in deg or None, ``detail``: the words the simulator recorded with it and that angle as
    text, ``safety`` for :data:`SAFETY_EVENTS`), the :data:`COLLAPSED` kinds as one entry each at their
    first time with ``count`` and ``explanation``, and a run of one safety kind (:data:`EPISODE_GAP_S`)
    as one entry with ``count`` and ``until`` (s). An entry standing for several events shows the
    words of the largest one ("largest: local stress 930 kPa over 800 kPa")."""
    out: list[dict] = []
    largest: dict[int, str] = {}  # id of an entry -> the words of its largest event
    collapsed: dict[str, dict] = {}  # kind -> its one entry in ``out``
    episodes: dict[str, dict] = {}  # safety kind -> its latest episode's entry
    for event in events.sort_values("time", kind="stable").itertuples():
        kind = str(event.kind)
        words = _recorded_words(event)
        run = collapsed.get(kind)
        episode = episodes.get(kind)
        if run is None and episode is not None and float(event.time) - episode["until"] < EPISODE_GAP_S:
            run = episode
            run["until"] = round(float(event.time), 4)
        if run is not None:
            run["count"] += 1
            if _size(words) > _size(largest[id(run)]):
                largest[id(run)] = words
            continue
        angle = getattr(event, "entry_angle_deg", None)
        angle = None if angle is None or not math.isfinite(angle) else round(float(angle), 1)
        entry = {
            "time": round(float(event.time), 4),
            "kind": kind,
            "name": event_name(kind),
            "entry_angle_deg": angle,  # the needle's angle to the surface's normal where it met it
            "detail": "; ".join(
                part for part in (words, "" if angle is None else f"{angle:g} deg off perpendicular") if part
            ),
            "safety": kind in SAFETY_EVENTS,
        }
        if kind in COLLAPSED:
            entry.update(count=1, explanation=COLLAPSED[kind])
            collapsed[kind] = entry
        elif kind in SAFETY_EVENTS:
            entry.update(count=1, until=entry["time"])
            episodes[kind] = entry
        largest[id(entry)] = words
        out.append(entry)
    for entry in out:
        words = largest.get(id(entry), "")
        if entry.get("count", 1) > 1 and words and math.isfinite(_size(words)):
            entry["detail"] = f"largest: {words}"
    return out
