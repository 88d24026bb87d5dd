"""`vascsim markers`: the printed marker cubes that let a camera track real instruments."""

from __future__ import annotations

import click

from sessions.cli.base import user_errors


@click.group()
def markers() -> None:
    """Marker cubes for instruments tracked by a camera (`--device camera`)."""


@markers.command("print")
@click.option(
    "-o", "--out", default="vascsim-markers.pdf", show_default=True, type=click.Path(dir_okay=False),
    help="Sheet to write: .pdf (A4) or .png (24 px/mm, its resolution stored).",
)  # fmt: skip
@click.option(
    "--instrument", "names", multiple=True, type=click.Choice(["needle-holder", "forceps"]),
    help="Instruments to print (repeat; default both).",
)  # fmt: skip
@user_errors
def print_sheet(out, names) -> None:
    """Write the marker sheet: a cube net per instrument, at true scale.

    Print at 100 % ("actual size", never "fit to page"), check the 50 mm bar with a
    ruler, cut out each net, fold it round a 30 mm cube (foam or card) and fix the
    cube on the instrument's handle, the shaft through the open face. Then register
    each instrument's tip with `vascsim instruments register`.
    """
    from sim.tracking.markers import INSTRUMENTS
    from sim.tracking.sheets import write_marker_sheet

    bodies = [INSTRUMENTS[name] for name in (names or INSTRUMENTS)]
    path = write_marker_sheet(bodies, out)
    faces = ", ".join(f"{b.name} {b.ids[0]}-{b.ids[-1]}" for b in bodies)
    click.echo(f"marker sheet: {path} (markers {faces}; {bodies[0].side_m * 1e3:g} mm, A4, print at 100 %)")
