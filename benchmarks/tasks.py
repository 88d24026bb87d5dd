"""Per-task figures of issue 22: precompute, load to first haptic tick, simulated-time throughput.

Run:  .venv/bin/python benchmarks/tasks.py [--repeats 3] [--convergence]

For every task of the library (``sessions.tasks.TASKS``):
- precompute: mesh, biphase model and condensed inverse over the stitch region, built from
  nothing (no disk cache);
- load to first tick: in a fresh cache state only the disk cache remains (what a station does
  when a session starts): load the model from it, build the simulation, run its first haptic step;
- simulated time: the whole task (every bite) by a scripted expert (all layers, no rendering, live
  local stress), simulated seconds per wall second, median of ``--repeats`` (target >= 20x on the
  interrupted stitch).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

# This folder holds scripts named like our packages (metrics.py, recorder.py): keep it off the path.
sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != Path(__file__).resolve().parent]

from sessions.running.runner import SessionPlan, open_device  # noqa: E402
from sessions.synthetic import pass_parameters  # noqa: E402
from sessions.tasks import TASKS, forget_tissues, region_forces, task_preset, task_spec, tissue_for  # noqa: E402
from sim.needle import Needle  # noqa: E402
from sim.runtime import Simulation  # noqa: E402


def simulation_for(task: str, tissue, seed: int) -> tuple[Simulation, float]:
    """The whole task (every bite) as a scripted expert makes it, through the runner's device."""
    plan = SessionPlan("benchmark", "E", task, 1)
    device, duration, _ = open_device("scripted", plan, None, pass_parameters(1.0, seed))
    forces, by_region = task_preset(task_spec(task)).forces, region_forces(task_spec(task), tissue.mesh)
    return Simulation(tissue, Needle.curved(), device, forces=forces, region_forces=by_region), duration


def convergence(task: str = "interrupted-stitch") -> None:
    """A vessel task's needle force at fixed depths on its mesh and two refinements (cells 0.3, 0.22,
    0.17 mm; the wound's gap 0.1 mm in all three, the finest grid's limit). The diseased wall is
    pressed at its second bite, in the calcified plaque, with the plaque's moduli and forces."""
    import dataclasses

    from sessions.tasks import region_presets, stitch_region_nodes, task_mesh, task_spec
    from sim.calibration.indentation import kernel_indentation_curve
    from sim.fem import BiphaseTissue

    base, preset = task_spec(task), task_preset(task_spec(task))
    regions = region_presets(task_spec(task))
    entry, normal, _ = base.more_bites[0] if regions else base.bites()[0]
    forces = next(iter(regions.values())).forces if regions else preset.forces
    for divisions in ([30, 5, 34], [40, 7, 45], [52, 9, 58]):
        wound = dataclasses.replace(base.parameters.wound, gap_m=1e-4)
        refined = dataclasses.replace(base.parameters, divisions=tuple(divisions), wound=wound)
        plaque = refined.calcification
        if plaque is not None:  # the plaque through the whole wall at every refinement
            plaque = dataclasses.replace(plaque, layers=tuple(range(divisions[1])))
            refined = dataclasses.replace(refined, calcification=plaque)
        spec = dataclasses.replace(base, parameters=refined)
        mesh = task_mesh(spec)
        fixed = np.concatenate([mesh.node_sets[k] for k in spec.parameters.fixed])
        candidates = np.setdiff1d(stitch_region_nodes(spec, mesh), fixed)
        by_region = {name: p.biphase for name, p in regions.items()}
        tissue = BiphaseTissue.build(
            mesh, fixed, preset.biphase, region_parameters=by_region, contact_nodes=candidates
        )
        curve = kernel_indentation_curve(tissue, forces, entry, normal, [0.0, 2e-4, 4e-4])
        shown = ", ".join(f"{f:.4f}" for f in curve.force[1:])
        print(f"divisions {divisions} ({mesh.n_nodes} nodes): force at 0.2 / 0.4 mm {shown} N", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument(
        "--convergence",
        nargs="?",
        const="interrupted-stitch",
        default=None,
        metavar="TASK",
        help="a vessel task's mesh convergence (default interrupted-stitch; diseased-wall: in the plaque)",
    )
    args = parser.parse_args()
    if args.convergence:
        convergence(args.convergence)
        return
    for task in TASKS:
        with tempfile.TemporaryDirectory() as folder:
            cache = Path(folder)
            forget_tissues()
            started = time.perf_counter()
            tissue = tissue_for(task_spec(task), cache)
            precompute = time.perf_counter() - started
            forget_tissues()
            started = time.perf_counter()
            loaded = tissue_for(task_spec(task), cache)
            simulation, _ = simulation_for(task, loaded, 1)
            simulation.haptic_step(0.0)
            first_tick = time.perf_counter() - started
            simulation.close()
        ratios = []
        for seed in range(1, args.repeats + 1):
            simulation, duration = simulation_for(task, tissue, seed)
            began = time.perf_counter()
            simulation.run_simulated(duration)
            ratios.append(duration / (time.perf_counter() - began))
        runs = ", ".join(f"{r:.1f}" for r in ratios)
        print(
            f"{task}: {tissue.mesh.n_nodes} nodes, {len(tissue.soft.contact_nodes)} candidates; "
            f"precompute {precompute:.2f} s; load to first tick {first_tick:.2f} s; "
            f"simulated time median {np.median(ratios):.1f}x real time (runs {runs})",
            flush=True,
        )


if __name__ == "__main__":
    main()
