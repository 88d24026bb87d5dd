"""The speed-dependent contact law is passive and agrees with Frick et al. 2001 (issue 43, item 3).

Before, the stiff phase switched on by tip speed whatever its direction: loading slowly to 0.6 mm and
withdrawing at 10 mm/s returned 1.69x the work put in, and the force at 0.4 mm was 0.247 N at 2 mm/s
against 0.377 N at 10 mm/s, where Frick et al. (J Biomech 34:1335) found no effect of speed between 1
and 10 mm/s.
"""

import numpy as np
import pytest

from sessions.tasks import task_preset, task_spec, tissue_for
from sim.calibration.indentation import PressedNeedle, load_cycle


@pytest.fixture(scope="module")
def wall_stitch():
    return tissue_for(task_spec("wall-stitch"), None)


@pytest.fixture(scope="module")
def setting(wall_stitch):
    spec = task_spec("wall-stitch")
    return wall_stitch, task_preset(task_spec("wall-stitch")).forces, spec.entry, spec.normal


def test_slow_in_fast_out_returns_no_more_work_than_it_took(setting):
    cycle = load_cycle(*setting, depth=0.6e-3, speed_in=0.002, speed_out=0.01)
    assert cycle.work_out <= cycle.work_in * (1 + 1e-9)
    fast_in = load_cycle(*setting, depth=0.6e-3, speed_in=0.2, speed_out=0.002)
    assert fast_in.work_out < fast_in.work_in  # a fast push meets the stiff phase sooner; it dissipates


def test_a_thousand_random_cycles_never_return_more_work_than_they_took(setting):
    """1,000 load/unload cycles between random depths (0.02-0.7 mm) at random speeds (0.5-50 mm/s
    each way), one after another on one needle: no cycle gives back more than it took."""
    rng = np.random.default_rng(43)
    pressed = PressedNeedle(*setting, step=5e-5)
    pressed.press_to(0.02e-3, 0.005)
    worst = -np.inf
    for _ in range(1000):
        low = rng.uniform(0.02e-3, 0.3e-3)
        high = rng.uniform(low + 0.02e-3, 0.7e-3)
        speed_in, speed_out = np.exp(rng.uniform(np.log(5e-4), np.log(5e-2), size=2))
        pressed.press_to(low, speed_out)
        depth_in, force_in = pressed.press_to(high, speed_in)
        depth_out, force_out = pressed.press_to(low, speed_out)
        work_in = np.trapezoid(force_in, depth_in)
        work_out = -np.trapezoid(force_out, depth_out)
        assert work_in > 0
        worst = max(worst, work_out / work_in)
        assert work_out <= work_in * (1 + 1e-9), (low, high, speed_in, speed_out, work_out / work_in)
    assert pressed.interaction.state == "contact"  # one contact throughout, never lost
    assert worst > 0.9  # slow unloading returns nearly all of it: the law is elastic where it should be


def test_force_at_fixed_depth_does_not_depend_on_speed_between_1_and_10_mm_s(setting):
    """Frick et al. 2001: within 10 % between 1 and 10 mm/s."""
    at = []
    for speed in (0.001, 0.01):
        pressed = PressedNeedle(*setting)
        pressed.press_to(0.0, speed)
        depth, force = pressed.press_to(0.4e-3, speed)
        at.append(force[-1])
    slow, fast = at
    assert slow > 0.1  # N: the wall does push back at 0.4 mm
    assert abs(fast - slow) <= 0.1 * slow
