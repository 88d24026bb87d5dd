"""`vascsim tasks list|show`: the task library."""

from __future__ import annotations

import click

from sessions.cli.base import (
    print_json,
    user_errors,
)


@click.group()
def tasks() -> None:
    """The suturing tasks a session can run (the task library)."""


@tasks.command("list")
@click.option("--json", "as_json", is_flag=True, help="Print the tasks as JSON.")
def tasks_list(as_json: bool) -> None:
    """List the tasks: name, tissue preset, and what the trainee is asked to do."""
    from sessions.tasks import all_tasks

    rows = [
        {
            "task": t.name,
            "tissue": t.parameters.tissue,
            "stitches": t.stitch_count,
            "time_budget_s": t.time_budget_s,
            "description": t.description,
        }
        for t in all_tasks().values()
    ]
    if as_json:
        print_json(rows)
        return
    for row in rows:
        asks = f"{row['stitches']} stitch(es) in {row['time_budget_s']:g} s"
        click.echo(f"{row['task']}  ({row['tissue']}; {asks})")
        click.echo(click.wrap_text(row["description"], 78, initial_indent="  ", subsequent_indent="  "))


@tasks.command("show")
@click.argument("name")
@click.option("--json", "as_json", is_flag=True, help="Print the task as JSON (SI units).")
@user_errors
def tasks_show(name: str, as_json: bool) -> None:
    """Show one task: geometry, tissue, where the stitch goes and the marks it is scored against."""
    from dataclasses import asdict

    from sessions.tasks import task_spec
    from sessions.tasks.kinds import kind_of

    spec = task_spec(name)
    if as_json:
        print_json(asdict(spec))
        return
    text = f"{spec.name}: {spec.description}"
    click.echo(click.wrap_text(text, 78, initial_indent="task         ", subsequent_indent=" " * 13))
    click.echo(f"tissue       {spec.parameters.tissue} ({spec.parameters.model} model)")
    geometry = kind_of(spec).geometry(spec)
    if geometry:
        click.echo(click.wrap_text(geometry, 78, initial_indent="geometry     ", subsequent_indent=" " * 13))
    for region, preset in spec.parameters.region_tissue.items():
        click.echo(f"region       {region}: {preset} preset (its moduli, puncture, passage)")
    if spec.access is not None:
        tilt = spec.access["tilt_deg"]
        click.echo(f"access       restricted: the hand comes in {tilt:g} deg off the wall's normal")
    if spec.eversion is not None:
        e = spec.eversion
        words = (
            f"the wrist stops {e.short_deg:g} deg short of square to the resting wall; the forceps "
            f"lifting the edge {e.lift_m * 1e3:g} mm turn it {e.turn_deg:.1f} deg to meet the needle"
        )
        click.echo(click.wrap_text(words, 78, initial_indent="two hands    ", subsequent_indent=" " * 13))
    budget = f"{spec.stitch_count} stitch(es) in {spec.time_budget_s:g} s"
    click.echo(f"asks for     {budget} (the course's time budget)")
    entry = ", ".join(f"{1e3 * v:.1f}" for v in spec.entry)
    click.echo(f"entry        ({entry}) mm, the scripted passes' aim")
    placement = spec.placement
    if placement is None:
        click.echo("placement    no target marks: placement metrics are not scored")
        return
    click.echo(f"target bite  {1e3 * placement['target_bite_m']:.1f} mm from the wound edge")
    if "target_exit_bite_m" in placement:
        exit_bite = 1e3 * placement["target_exit_bite_m"]
        click.echo(f"  on exit    {exit_bite:.2f} mm (straight through the curved wall)")
    if "target_spacing_m" in placement:
        spacing = 1e3 * placement["target_spacing_m"]
        click.echo(f"spacing      {spacing:.1f} mm between stitches along the wound")
    for kind in ("entry", "exit"):
        for mark in placement[f"{kind}_targets"]:
            click.echo(f"{kind} mark   ".ljust(13) + "(" + ", ".join(f"{1e3 * v:.1f}" for v in mark) + ") mm")


def _numbers(value: str, option: str, names: str = "X,Y,Z") -> list[float]:
    """``value`` as comma-separated numbers, as many as ``names`` has (a usage error otherwise)."""
    try:
        numbers = [float(v) for v in value.split(",")]
    except ValueError:
        numbers = []
    if len(numbers) != len(names.split(",")):
        raise click.BadParameter(f"{value!r} is not {names}", param_hint=option)
    return numbers


@tasks.command("add")
@click.argument("name")
@click.option(
    "--mesh",
    "mesh_path",
    type=click.Path(dir_okay=False),
    required=True,
    help="A lumen surface (STL, OBJ, VTP, PLY: meshed here) or a tetrahedral mesh (VTU, MSH).",
)
@click.option(
    "--thickness",
    type=click.FloatRange(0.1, 10),
    default=None,
    help="Wall thickness (mm) to offset the lumen by.",
)
@click.option(
    "--outer",
    "outer_path",
    type=click.Path(dir_okay=False),
    default=None,
    help="The outer surface instead of a thickness.",
)
@click.option(
    "--max-edge",
    type=click.FloatRange(0.05, 5),
    default=0.4,
    show_default=True,
    help="Largest element edge (mm).",
)
@click.option(
    "--units",
    type=click.Choice(["mm", "m", "cm", "um"]),
    default="mm",
    show_default=True,
    help="The surface file's units.",
)
@click.option(
    "--entry", required=True, help="Where the bite goes in, X,Y,Z (mm): the nearest outer-surface point."
)
@click.option(
    "--bite-direction",
    default=None,
    help="X,Y,Z: the direction the bite heads across the wall (default: about the z axis).",
)
@click.option(
    "--tissue",
    default="porcine-artery",
    show_default=True,
    help="Tissue preset (vascsim indentation --help lists them).",
)
@click.option(
    "--calcified", default=None, help="X,Y,Z,R (mm): a calcified sphere (its own preset, 'calcified')."
)
@click.option("--mesher", type=click.Choice(["auto", "tetgen", "tetwild"]), default="auto", show_default=True)
@click.option("--description", default="", help="What the trainee is asked to do.")
@user_errors
def tasks_add(
    name,
    mesh_path,
    thickness,
    outer_path,
    max_edge,
    units,
    entry,
    bite_direction,
    tissue,
    calcified,
    mesher,
    description,
) -> None:
    """Add a task on your own vessel geometry: a segmentation's lumen surface (with --thickness or
    --outer) is meshed into a layered wall (TetGen; fTetWild when TetGen refuses the surface) and its
    quality reported; a tetrahedral mesh is taken as it is. The cut ends (end0, end1, ...) are held.
    Then `vascsim run --task NAME` runs it."""
    from pathlib import Path

    from sessions.tasks import add_mesh_task
    from sim.mesh import load_mesh
    from sim.mesh.quality import mesh_quality
    from sim.mesh.surfaces import CalcifiedSphere, mesh_vessel_surface

    path = Path(mesh_path)
    sphere = None
    if calcified is not None:
        x, y, z, r = _numbers(calcified, "--calcified", "X,Y,Z,R")
        sphere = CalcifiedSphere((x * 1e-3, y * 1e-3, z * 1e-3), r * 1e-3)
    if path.suffix.lower() in (".vtu", ".msh", ".mesh", ".xdmf"):
        mesh = load_mesh(path, reorient=True)
        quality = mesh_quality(mesh.points, mesh.tets)
    else:
        mesh, quality = mesh_vessel_surface(
            path,
            thickness=None if thickness is None else thickness * 1e-3,
            outer_path=outer_path,
            max_edge=max_edge * 1e-3,
            units=units,
            calcified=sphere,
            mesher=mesher,
        )
    fixed = sorted(k for k in mesh.node_sets if k.startswith("end"))
    regions = {"calcified": "calcified"} if "calcified" in mesh.region_names.values() else {}
    spec = add_mesh_task(
        name,
        mesh,
        [v * 1e-3 for v in _numbers(entry, "--entry")],
        tissue=tissue,
        fixed=fixed,
        bite_direction=None if bite_direction is None else _numbers(bite_direction, "--bite-direction"),
        description=description,
        region_tissue=regions,
    )
    for line in quality.lines():
        click.echo(click.wrap_text(line, 78, subsequent_indent="  "))
    where = ", ".join(f"{1e3 * v:.2f}" for v in spec.entry)
    click.echo(f"task {name} added: one bite at ({where}) mm, held on {', '.join(fixed) or 'nothing'}")
