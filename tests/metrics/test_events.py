"""Session events named for a person (issue 25): every stored kind has a name; the simulator's own
checks collapse into one line with a count and an explanation."""

import pandas as pd

from metrics.session.events import COLLAPSED, EVENT_NAMES, SAFETY_EVENTS, readable_events
from recorder.schema import EVENT_KINDS


def test_every_stored_event_kind_has_a_name():
    assert set(EVENT_KINDS) <= set(EVENT_NAMES)
    assert set(COLLAPSED) <= set(EVENT_NAMES)


def test_a_run_of_plausibility_checks_is_one_line_with_its_count():
    """25 implausible hits among a stitch's events (as seen in one demo session): one line."""
    events = pd.DataFrame(
        [{"time": 0.5, "kind": "contact_start", "entry_angle_deg": 2.04}, {"time": 0.8, "kind": "pierce"}]
        + [{"time": 1.0 + 0.01 * k, "kind": "implausible_hit"} for k in range(25)]
        + [{"time": 2.0, "kind": "exit"}]
    )
    readable = readable_events(events)
    assert [e["name"] for e in readable] == [
        "needle touched the tissue",
        "needle entered the tissue",
        "the needle crossed the tissue in a way the simulator does not follow",
        "needle came out",
    ]
    assert readable[0]["entry_angle_deg"] == 2.0 and readable[1]["entry_angle_deg"] is None
    assert readable[0]["detail"] == "2 deg off perpendicular" and readable[1]["detail"] == ""
    assert readable[2]["count"] == 25 and readable[2]["time"] == 1.0
    assert "plausibility check" in readable[2]["explanation"]
    assert "count" not in readable[3]


def test_safety_events_are_flagged_for_listing_first():
    events = pd.DataFrame(
        [
            {"time": 0.8, "kind": "pierce"},
            {"time": 1.1, "kind": "edge_overstress"},
            {"time": 1.2, "kind": "force_clamped"},
            {"time": 1.3, "kind": "force_clamped"},
        ]
    )
    readable = readable_events(events)
    assert [(e["kind"], e["safety"]) for e in readable] == [
        ("pierce", False),
        ("edge_overstress", True),
        ("force_clamped", True),
    ]
    assert set(SAFETY_EVENTS) <= set(EVENT_NAMES)


def test_a_run_of_overstress_is_one_episode_with_its_count_and_end():
    """Seen: 18 lines of overstress in one trainee session, a tick apart."""
    ticks = [1.19, 1.28, 1.35, 1.44, 1.53, 1.60, 1.71]  # each within 0.5 s of the one before
    events = pd.DataFrame(
        [{"time": t, "kind": "overstress"} for t in ticks]
        + [{"time": 3.21, "kind": "overstress"}, {"time": 1.5, "kind": "edge_overstress"}]
    )
    readable = readable_events(events)
    assert [(e["kind"], e["time"], e["count"], e["until"]) for e in readable] == [
        ("overstress", 1.19, 7, 1.71),
        ("edge_overstress", 1.5, 1, 1.5),
        ("overstress", 3.21, 1, 3.21),  # 1.5 s after the last: a new episode
    ]
