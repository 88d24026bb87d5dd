"""`vascsim indentation`: the calibrated force-depth curve of a tissue preset."""

from __future__ import annotations

import json
from typing import Any

import click
import numpy as np

from sessions.cli.base import (
    user_errors,
)
from sim.calibration.presets import DEFAULT_PRESET, PRESETS


@click.command()
@click.option(
    "--tissue",
    "preset",
    default=DEFAULT_PRESET,
    show_default=True,
    type=click.Choice(list(PRESETS)),
    help="Tissue preset: a calibrated wall pressed at the wall-stitch entry point through the force "
    "kernel, or the source paper's 10 mm cube (PAPER.md Fig. 3 and Table 1).",
)
@click.option(
    "--max-strain",
    default=0.5,
    show_default=True,
    type=click.FloatRange(0.01, 0.9),
    help="Paper cube only: deepest indentation, as strain of the 10 mm cube (0.5 = 5 mm).",
)
@click.option(
    "--max-depth",
    default=1.2,
    show_default=True,
    type=click.FloatRange(0.05, 1.5),
    help="Calibrated walls only: deepest indentation in mm (the patch is 1.5 mm thick).",
)
@click.option(
    "--steps",
    default=11,
    show_default=True,
    type=click.IntRange(2, 200),
    help="Number of indentation levels.",
)
@click.option(
    "--speed",
    "speed_mm_s",
    default=4.0,
    show_default=True,
    type=click.FloatRange(0.1, 500.0),
    help="Calibrated walls only: the needle's speed in mm/s (the stiff phase engages sooner above about "
    "30 mm/s, while loading).",
)
@click.option(
    "--unload",
    is_flag=True,
    help="Calibrated walls only: also draw the needle back out at the same speed and print the unloading "
    "branch with the work put in and given back (mJ).",
)
@click.option("--json", "as_json", is_flag=True, help="Print the results as JSON instead of a table.")
@user_errors
def indentation(
    preset: str,
    max_strain: float,
    max_depth: float,
    steps: int,
    speed_mm_s: float,
    unload: bool,
    as_json: bool,
) -> None:
    """Press a scripted needle straight into the tissue and print force against depth.

    With a calibrated preset (default porcine-artery): the wall-stitch patch (0.3 mm cells in the
    stitch region) pressed at its entry point at --speed (4 mm/s) through the runtime's force
    kernel; prints the normal force in mN, the biphase phase, the local von Mises stress in kPa and
    the depth at which the needle pierces; --unload adds the way back out and the work in and out.
    With --tissue paper: the paper's 10 mm cube (E1 = 20 kPa, E2 = 40 kPa), E1-only and biphase
    forces and the mesh volume change per strain level.
    """
    from rich.console import Console

    console = Console(stderr=True)
    if preset == "paper":
        from sim.calibration.indentation import indentation_curve

        strains = np.linspace(0.0, max_strain, steps)
        with console.status("precomputing the test cube and pressing the needle..."):
            curve = indentation_curve(strains)
        if as_json:
            click.echo(json.dumps(curve.as_dict(), indent=2))
            return
        _print_curve(curve)
        return
    from sessions.config import cache_dir
    from sessions.tasks import task_spec, tissue_for
    from sim.calibration.indentation import kernel_indentation_curve
    from sim.calibration.presets import tissue_preset
    from sim.fem import BiphaseTissue

    spec, chosen = task_spec("wall-stitch"), tissue_preset(preset)
    with console.status(f"precomputing the wall-stitch patch ({preset}) and pressing the needle..."):
        base = tissue_for(task_spec("wall-stitch"), cache_dir())
        tissue = base
        if chosen.biphase != base.parameters:
            tissue = BiphaseTissue.build(
                base.mesh, base.soft.fixed_dofs // 3, chosen.biphase, contact_nodes=base.soft.contact_nodes
            )
        depths = np.linspace(0.0, max_depth * 1e-3, steps)
        speed = speed_mm_s * 1e-3
        curve = kernel_indentation_curve(
            tissue, chosen.forces, spec.entry, spec.normal, depths, needle_speed=speed
        )
        cycle = None
        if unload:
            from sim.calibration.indentation import load_cycle

            cycle = load_cycle(tissue, chosen.forces, spec.entry, spec.normal, depths[-1], speed, speed)
    if as_json:
        result = {"tissue": preset, "speed_mm_s": speed_mm_s, **curve.as_dict()}
        if cycle is not None:
            result["cycle"] = cycle.as_dict()
        click.echo(json.dumps(result, indent=2))
        return
    _print_kernel_curve(preset, curve, speed_mm_s)
    if cycle is not None:
        _print_unloading(cycle, depths)


def _print_unloading(cycle: Any, depths: np.ndarray) -> None:
    """The way back out at the table's depths, and the work in and out."""
    from rich.console import Console
    from rich.table import Table

    table = Table(title=f"Then unloading at {cycle.speed_out * 1e3:g} mm/s")
    for header in ("depth (mm)", "force (mN)"):
        table.add_column(header, justify="right")
    order = np.argsort(cycle.unloading_depth)
    force = np.interp(depths, cycle.unloading_depth[order], cycle.unloading_force[order])
    for depth, value in zip(depths[::-1], force[::-1], strict=True):
        table.add_row(f"{depth * 1e3:.2f}", f"{max(value, 0.0) * 1e3 + 0.0:.0f}")
    console = Console()
    console.print(table)
    given_back = cycle.work_out / cycle.work_in if cycle.work_in > 0 else float("nan")
    console.print(
        f"work put in {cycle.work_in * 1e3:.4f} mJ, given back {cycle.work_out * 1e3:.4f} mJ "
        f"({given_back * 100:.1f} %; never more than 100 %: the wall does not create energy)"
    )


def _print_kernel_curve(preset: str, curve: Any, speed_mm_s: float) -> None:
    from rich.console import Console
    from rich.table import Table

    table = Table(title=f"Needle pressed into the {preset} wall-stitch patch at {speed_mm_s:g} mm/s")
    for header in ("depth (mm)", "force (mN)", "phase", "local stress (kPa)"):
        table.add_column(header, justify="right")
    for depth, force, share, stress in zip(
        curve.depth, curve.force, curve.soft_share, curve.local_stress, strict=True
    ):
        phase = "soft" if share >= 1.0 else f"stiff {100 * (1 - share):.0f}%"
        table.add_row(
            f"{depth * 1e3:.2f}", f"{max(force, 0.0) * 1e3 + 0.0:.0f}", phase, f"{stress / 1e3:.0f}"
        )
    console = Console()
    console.print(table)
    if np.isfinite(curve.pierce_depth):
        console.print(
            f"pierces at {curve.pierce_depth * 1e3:.2f} mm (puncture force "
            f"{curve.puncture_force * 1e3:.0f} mN); force kernel of {curve.kernel_nodes} nodes"
        )
    else:
        console.print(
            f"does not pierce within {curve.depth[-1] * 1e3:.2f} mm (puncture force "
            f"{curve.puncture_force * 1e3:.0f} mN); force kernel of {curve.kernel_nodes} nodes"
        )


def _print_curve(curve: Any) -> None:
    from rich.console import Console
    from rich.table import Table

    table = Table(title="Needle pressed into the 10 mm test cube (729 nodes, 3072 elements)")
    for header in (
        "strain",
        "stretch λ",
        "force E1-only (mN)",
        "force biphase (mN)",
        f"force biphase @ {curve.fast_speed * 1e3:.0f} mm/s (mN)",
        "volume change E1-only (%)",
        "volume change biphase (%)",
    ):
        table.add_column(header, justify="right")
    for i, strain in enumerate(curve.strain):
        table.add_row(
            f"{strain:.2f}",
            f"{curve.stretch_ratio[i]:.2f}",
            f"{1e3 * curve.force_linear[i]:.1f}",
            f"{1e3 * curve.force_biphase[i]:.1f}",
            f"{1e3 * curve.force_biphase_fast[i]:.1f}",
            f"{100 * curve.volume_change_linear[i]:+.2f}",
            f"{100 * curve.volume_change_biphase[i]:+.2f}",
        )
    console = Console()
    console.print(table)
    console.print(
        f"precompute (both phases, 915 condensed dofs each): {curve.precompute_seconds:.3f} s "
        "(the paper: 9 min for its smallest model)"
    )
