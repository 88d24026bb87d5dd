"""What the station says, checked without a display: the heads-up strip, the instruction and feedback
screens' words, the terminal's closing lines, the live scene's camera and start pose."""

import dataclasses
import itertools

import numpy as np
import pytest

from sessions.cli.run import review_lines
from sessions.running.hud import HudLimits, HudTracker
from sessions.running.scene import START_HEIGHT_M, access_direction, start_pose, task_camera
from sessions.running.station import feedback_lines, instruction_lines
from sessions.scoring.review import SessionReview
from sessions.tasks import task_spec
from sim.needle import Needle

LIMITS = HudLimits(60.0, 3, (0.8, 1.0), 0.88, 8e5)


def test_the_strip_counts_stitches_marks_bites_and_says_what_is_unsafe():
    hud = HudTracker(LIMITS)
    tip = np.array([0.001, 0.002, 0.003])
    steps = [
        (0.1, "free", 0.0, 0.0),
        (0.2, "contact", 0.5, 1e5),
        (0.3, "pierced", 0.9, 9e5),  # over the damage stress
        (0.4, "exited", 0.3, 1e5),
        (0.5, "free", 0.0, 0.0),  # pulled through: one stitch done
    ]
    for now, state, force, stress in steps:
        hud.update(now, state, np.array([0.0, 0.0, force]), tip, stress)
    assert hud.completed == 1 and len(hud.entries) == 1 and len(hud.exits) == 1
    reading = hud.reading(0.5, np.zeros(3))
    assert reading.stitch == "stitch 2 of 3"
    assert reading.clock == "0:00 of 1:00" and not reading.over_time
    assert reading.warning.startswith("wall over-stressed near the needle")
    assert reading.force == "force 0 mN (experts 800-1000 mN; device max 880 mN)"
    assert hud.reading(2.6, np.zeros(3)).warning == ""  # a warning shows for two seconds
    late = hud.reading(75.0, np.array([0.0, 3.0, 4.0]))
    assert late.over_time and late.clock == "1:15 of 1:00" and late.force_fraction == 1.0
    hud.update(76.0, "contact", np.array([0.9, 0.0, 0.0]), tip, 0.0)
    assert "device's limit (880 mN)" in hud.reading(76.0, np.zeros(3)).warning


def test_the_strip_says_what_the_forceps_hold_and_warns_before_the_edge_tears():
    hud = HudTracker(LIMITS)
    tip = np.zeros(3)
    hud.update(0.1, "free", np.zeros(3), tip, 0.0)
    assert hud.reading(0.1, np.zeros(3)).forceps == ""  # one hand: nothing about forceps
    hud.update(0.2, "free", np.zeros(3), tip, 0.0, np.zeros(3))
    assert hud.reading(0.2, np.zeros(3)).forceps == "forceps not holding the edge"
    hud.update(0.3, "contact", np.zeros(3), tip, 0.0, np.array([0.0, 0.3, 0.4]))
    reading = hud.reading(0.3, np.zeros(3))
    assert reading.forceps == "forceps holding the edge, 500 mN" and not reading.warning
    assert reading.state == "needle touching the wall"
    hud.update(0.4, "contact", np.zeros(3), tip, 0.0, np.array([0.0, 0.0, 1.2]))  # 0.89 of 1.35 N
    assert hud.reading(0.4, np.zeros(3)).warning == (
        "the forceps pull hard on the edge: lift less (it tears at 1350 mN)"
    )


def test_the_instruction_screen_says_the_task_marks_budget_controls_and_how_to_start():
    spec = task_spec("arteriotomy-closure")
    words = [line.text for line in instruction_lines(spec, "mouse", "T07", "no experts yet")]
    text = " ".join(words)
    assert words[0] == "arteriotomy-closure: next trial for T07"
    assert "Time budget 3:00 for 3 stitches" in words
    assert "Drag with the left mouse button" in text and "G: open or close the jaws" in text
    assert "no experts yet" in text and "SPACE: start" in words[-1]
    assert "forceps" not in text  # one hand: nothing about a second


def test_with_a_second_device_the_instructions_say_how_the_forceps_hold_the_edge():
    spec = task_spec("interrupted-stitch")
    text = " ".join(
        line.text for line in instruction_lines(spec, "openhaptics", "T07", sub_device="spacemouse")
    )
    assert "forceps (the SpaceMouse, a rate control)" in text
    assert "closes the jaws on the edge" in text and "lift (evert) the edge" in text and "tears" in text
    spacemouse = [line.text for line in instruction_lines(spec, "spacemouse", "T07")]
    assert "rate control" in " ".join(spacemouse)
    assert spacemouse[-1].startswith("SPACE or a button: start")  # the device in hand starts it


def test_the_strip_says_when_the_wrist_is_at_its_stop():
    hud = HudTracker(LIMITS)
    tip = np.zeros(3)
    hud.update(0.1, "free", np.zeros(3), tip, 0.0, None, wrist_at_stop=False)
    assert hud.reading(0.1, np.zeros(3)).warning == ""
    hud.update(0.2, "contact", np.zeros(3), tip, 0.0, None, wrist_at_stop=True)
    assert hud.reading(0.2, np.zeros(3)).warning == (
        "your wrist is at the end of its turn: evert the edge to meet the wall square"
    )
    hud.update(3.0, "pierced", np.zeros(3), tip, 0.0, None, wrist_at_stop=True)  # in the wall: driving
    assert hud.reading(3.0, np.zeros(3)).warning == ""


def test_a_task_that_needs_the_forceps_says_so_when_the_station_has_none():
    spec = task_spec("inside-edge")
    alone = " ".join(line.text for line in instruction_lines(spec, "mouse", "T07"))
    assert "needs your other hand to evert the edge" in alone and "--sub-device" in alone
    assert "7 deg short of square" in alone  # the task's own words: why
    both = " ".join(
        line.text for line in instruction_lines(spec, "openhaptics", "T07", sub_device="spacemouse")
    )
    assert "needs your other hand" not in both and "lift (evert) the edge" in both


def test_a_long_instruction_screen_shrinks_to_clear_the_keys_line():
    """Seen: inside-edge's instructions with a standard's note ran into the pinned keys line at 960x540."""
    from sessions.running.screens import layout

    spec = task_spec("inside-edge")
    lines = instruction_lines(spec, "mouse", "T07", "No expert has recorded this task in this study yet.")
    for height in (540, 720):
        placed = layout(lines, height)
        keys = [(y, size) for line, y, size in placed if line.style == "keys"]
        flowing = sorted(((y, size) for line, y, size in placed if line.style != "keys"), reverse=True)
        assert len(keys) == 1 and len(flowing) == len(lines) - 1
        lowest, _ = flowing[-1]
        assert lowest >= keys[0][0] + keys[0][1] + 4  # above the keys line, with room
        assert flowing[0][0] <= height - 20 and all(size >= 9 for _, size in flowing)
        for (upper, _), (lower, size) in itertools.pairwise(flowing):
            assert upper - lower >= size  # no line drawn over the one above
    short = layout(instruction_lines(task_spec("wall-stitch"), "scripted", "T07"), 540)
    assert {size for line, _, size in short if line.style == "body"} == {15}  # room enough: full size


def review(verdict: str) -> SessionReview:
    return SessionReview(
        "S-1",
        "interrupted-stitch",
        4,
        verdict,
        "the study's benchmarks on interrupted-stitch: 1 metric(s), rule mean, from 5 expert(s)",
        [{"metric": "entry_to_target", "passed": False, "line": "entry_to_target 0.6 mm: not met"}],
        [{"metric": "peak_force", "kind": "safety", "line": f"Ease off. ({n})"} for n in range(4)],
        [],
    )


def test_the_feedback_screen_leads_with_the_verdict_then_the_standard_then_what_to_work_on():
    lines = feedback_lines(review("not yet"))
    assert (lines[0].text, lines[0].style) == ("Trial 4: not yet at the study's standard", "bad")
    texts = [line.text for line in lines]
    assert texts.index("Against the standard") < texts.index("What to work on")
    assert any("entry_to_target 0.6 mm: not met" in t for t in texts)
    assert feedback_lines(review("pass"))[0].style == "good"
    assert "no standard" in feedback_lines(review("no standard"))[0].text


def test_with_no_expert_yet_the_feedback_does_not_compare_with_a_band_that_does_not_exist():
    """A study whose experts have not recorded the task: 'nothing worse than the experts' middle half'
    read as praise against nothing; the screen says there is nothing to compare with yet."""
    alone = dataclasses.replace(review("no standard"), work_on=[], benchmarks=[], has_band=False)
    texts = " ".join(line.text for line in feedback_lines(alone))
    assert "Nothing to compare with yet" in texts and "middle half" not in texts
    banded = dataclasses.replace(alone, has_band=True)
    assert "Nothing worse than the experts' middle half." in " ".join(
        line.text for line in feedback_lines(banded)
    )


def test_the_terminal_ends_with_the_verdict_and_three_things_to_work_on():
    lines = review_lines(review("not yet"), "T07")
    assert lines[0] == "session S-1 (T07, trial 4) complete and scored"
    assert lines[1].startswith("verdict: NOT YET at the study's standard; the study's benchmarks")
    numbered = [line for line in lines if line.lstrip()[:2] in ("1.", "2.", "3.", "4.")]
    assert len(numbered) == 3  # three, not four
    assert lines[-1] == "all metrics: vascsim sessions show S-1"


@pytest.mark.parametrize("task", ["interrupted-stitch", "restricted-access", "wall-stitch"])
def test_the_needle_starts_square_above_the_first_mark_and_the_camera_looks_down_the_access(task):
    spec = task_spec(task)
    pose = start_pose(spec)
    tip = Needle.curved().world_vertices(pose)[0]
    approach = access_direction(spec)
    np.testing.assert_allclose(tip, np.asarray(spec.entry) + START_HEIGHT_M * approach, atol=1e-12)
    position, focal, up = (np.array(v) for v in task_camera(spec))
    looking = (position - focal) / np.linalg.norm(position - focal)
    assert np.dot(looking, approach) > 0.7  # from the side the hand comes from, within 45 deg
    assert abs(np.dot(up, looking)) < 1e-12


def test_the_calibration_window_says_the_next_turn_and_the_views_taken():
    from sessions.running.calibration_window import guidance_lines
    from sim.tracking.guided import KINDS

    lines = guidance_lines({"square-on": 3, "tilted left": 1}, 24)
    texts = [text for text, _ in lines]
    assert texts[0] == "Turn the board's left edge away from you (about 25 deg)"
    assert "square-on: done" in texts and "tilted left: 1 of 3" in texts and "tilted down: 0 of 3" in texts
    assert "board: 24 corners found" in texts
    every = guidance_lines(dict.fromkeys(KINDS, 3), 0)
    assert every[0][0] == "Every view is taken: calibrating"
    assert ("board: not found in the picture", "warn") in every
