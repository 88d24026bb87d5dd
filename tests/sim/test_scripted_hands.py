"""Every task with a clumsy and a skilled scripted hand (issue 43's acceptance).

Before: at skill 0.2 the interrupted stitch's trial 1 went straight through the wall at 0 N with 63
implausible hits and was stored with no puncture; restricted-access trainees spent 0.27-0.68 s inside
the wall at zero force (22-67 implausible hits); a restricted-access trainee peaked at 16.7 N; experts
fired ``overstress`` on four tasks and recorded stretches of 2.9-5.5.
"""

from pathlib import Path

import numpy as np
import pytest

from sessions.running.runner import SessionPlan, open_device
from sessions.synthetic import pass_parameters
from sessions.tasks import TASKS, task_simulation, task_spec


def run(task: str, skill: float, trial: int, cache: Path | None):
    plan = SessionPlan(study="s", participant="p", task=task, device="scripted", trial=trial)
    device, duration, _ = open_device("scripted", plan, None, pass_parameters(skill, seed=trial))
    simulation = task_simulation(task_spec(task), device, cache)
    stretch = []
    simulation.on_sample = lambda now, sample, force, fem: stretch.append(fem.stretch) if fem else None
    result = simulation.run_simulated(duration)
    assert result.error is None, result.error
    return simulation.events, np.array(stretch, dtype=float)


@pytest.fixture(scope="module")
def cache():
    return None  # the tasks' tissues as the other tests build them (one per process)


TRAINEE_TRIALS = {"interrupted-stitch": (1, 2, 3), "restricted-access": (1, 2, 3)}
"""Trials 1-3 where the issue saw the needle pass unfelt; trial 1 elsewhere (all 15 measured:
docs/benchmarks.md, session 20; the suite stays under its 15 minutes)."""


@pytest.mark.parametrize("task", list(TASKS))
def test_a_clumsy_hand_pierces_with_a_felt_force_and_nothing_implausible(task, cache):
    for trial in TRAINEE_TRIALS.get(task, (1,)):
        events, _ = run(task, 0.2, trial, cache)
        pierces = [e for e in events if e.kind == "pierce"]
        assert pierces, (task, trial, "no puncture")
        for pierce in pierces:
            normal = float(pierce.detail.split()[2]) / 1e3  # "normal force X mN"
            assert 0.3 <= normal <= 6.0, (task, trial, pierce.detail)
        implausible = [e.detail for e in events if e.kind == "implausible_hit"]
        assert not implausible, (task, trial, implausible)


@pytest.mark.parametrize("task", list(TASKS))
def test_a_skilled_hand_does_not_overstress_the_wall(task, cache):
    for trial in (
        1,
    ):  # trials 2-3 too when measured (docs/benchmarks.md, session 20); one keeps the suite short
        events, stretch = run(task, 0.9, trial, cache)
        kinds = [e.kind for e in events]
        assert "pierce" in kinds
        assert "overstress" not in kinds and "tear" not in kinds, (task, trial)
        assert "implausible_hit" not in kinds, (task, trial)
        assert np.nanmax(stretch) <= 1.6, (task, trial, np.nanmax(stretch))


@pytest.mark.parametrize("task", ["interrupted-stitch", "arteriotomy-closure"])
def test_a_skilled_hands_exits_are_where_the_run_asks_for_columns_ahead(task, cache):
    """A real-time run asks the column worker, from its start, for the surface nodes round where a
    needle planned square on each bite comes out (sim.devices.suturing.planned_exits): a skilled
    hand's exits come out within half a millimetre of one of them (its entries are 1.5 mm away),
    well inside the reach asked round each."""
    from sim.devices.suturing import planned_exits
    from sim.runtime.simulation import EXIT_REACH_KERNELS

    plan = SessionPlan(study="s", participant="p", task=task, device="scripted", trial=1)
    device, duration, _ = open_device("scripted", plan, None, pass_parameters(0.95, seed=1))
    simulation = task_simulation(task_spec(task), device, cache)
    sites = planned_exits(simulation.interaction.needle, simulation.interaction.collision, simulation.bites)
    assert len(simulation.bites) == len(task_spec(task).bites()) and len(sites) >= len(simulation.bites)
    simulation.run_simulated(duration)
    corners = simulation.interaction.collision.corners
    exits = [np.asarray(e.barycentric) @ corners[e.triangle] for e in simulation.events if e.kind == "exit"]
    assert len(exits) == len(simulation.bites)
    assert EXIT_REACH_KERNELS * simulation.interaction.forces.kernel_radius >= 1e-3
    for point in exits:
        assert np.linalg.norm(sites - point, axis=1).min() <= 0.5e-3, (task, point, sites)
