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


def test_an_event_shows_the_words_the_simulator_recorded_with_it():
    """Seen: the recording keeps each event's detail ("1200 mN clamped to the rated 880 mN", "normal
    force 815 mN"), but the event list showed only the kind's name."""
    events = pd.DataFrame(
        [
            {"time": 0.5, "kind": "contact_start", "entry_angle_deg": 4.0, "detail": "needle tip"},
            {"time": 0.8, "kind": "pierce", "entry_angle_deg": float("nan"), "detail": "normal force 815 mN"},
            {"time": 0.9, "kind": "exit", "entry_angle_deg": float("nan"), "detail": ""},
        ]
    )
    readable = readable_events(events)
    assert [e["detail"] for e in readable] == [
        "needle tip; 4 deg off perpendicular",
        "normal force 815 mN",
        "",
    ]


def test_a_run_of_one_safety_kind_shows_its_worst_recorded_value():
    """An overstress episode or a run of clamps is one line: it shows the largest value recorded in it
    (the first number of each event's words, which one code site writes per kind), not the first."""
    stresses = [813, 930, 850]
    clamps = [1200, 2400, 900]
    events = pd.DataFrame(
        [
            {"time": 1.0 + 0.1 * k, "kind": "overstress", "detail": f"local stress {s} kPa over 800 kPa"}
            for k, s in enumerate(stresses)
        ]
        + [
            {"time": 2.0 + 0.1 * k, "kind": "force_clamped", "detail": f"{c} mN clamped to the rated 880 mN"}
            for k, c in enumerate(clamps)
        ]
        + [{"time": 4.0, "kind": "edge_overstress", "detail": "wound-edge stress 618 kPa over 600 kPa"}]
    )
    readable = readable_events(events)
    assert [(e["kind"], e["count"], e["detail"]) for e in readable] == [
        ("overstress", 3, "largest: local stress 930 kPa over 800 kPa"),
        ("force_clamped", 3, "largest: 2400 mN clamped to the rated 880 mN"),
        ("edge_overstress", 1, "wound-edge stress 618 kPa over 600 kPa"),
    ]
