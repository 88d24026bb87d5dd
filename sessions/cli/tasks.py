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
    from sessions.tasks import TASKS

    rows = [
        {
            "task": t.name,
            "tissue": t.parameters.get("tissue", ""),
            "stitches": t.stitch_count,
            "time_budget_s": t.time_budget_s,
            "description": t.description,
        }
        for t in TASKS.values()
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

    spec = task_spec(name)
    if as_json:
        print_json(asdict(spec))
        return
    text = f"{spec.name}: {spec.description}"
    click.echo(click.wrap_text(text, 78, initial_indent="task         ", subsequent_indent=" " * 13))
    click.echo(f"tissue       {spec.parameters.get('tissue', '')} ({spec.parameters.get('model', '')} model)")
    p, held = spec.parameters, ", ".join(spec.parameters.get("fixed", []))
    geometry = ""
    if "size_m" in p:
        geometry = f"{' x '.join(f'{1e3 * v:g}' for v in p['size_m'])} mm patch, held on {held}"
    elif "inner_radius_m" in p:
        geometry = (
            f"artery r {1e3 * p['inner_radius_m']:g} mm, wall {1e3 * p['wall_m']:g} mm, "
            f"{1e3 * p['length_m']:g} mm long, {p['arc_deg']:g} deg patch, held on {held}"
        )
    if geometry:
        click.echo(click.wrap_text(geometry, 78, initial_indent="geometry     ", subsequent_indent=" " * 13))
    for region, preset in spec.parameters.get("region_tissue", {}).items():
        click.echo(f"region       {region}: {preset} preset (its moduli, puncture, passage)")
    if spec.access is not None:
        tilt = spec.access["tilt_deg"]
        click.echo(f"access       restricted: the hand comes in {tilt:g} deg off the wall's normal")
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
