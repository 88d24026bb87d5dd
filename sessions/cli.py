"""The ``vascsim`` command line: one entry point, a subcommand per task.

User errors (any :class:`sim.errors.VascsimError`) print one line on stderr and
exit with status 1; ``--help`` on every command explains its options.
"""

from __future__ import annotations

import json
import sys
from collections.abc import Callable
from functools import wraps
from typing import Any

import click
import numpy as np

from sim.errors import VascsimError


def user_errors(command: Callable[..., Any]) -> Callable[..., Any]:
    """Turn vascsim errors into a one-line message and exit status 1 (no traceback)."""

    @wraps(command)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            return command(*args, **kwargs)
        except VascsimError as error:
            click.echo(f"vascsim: error: {error}", err=True)
            sys.exit(1)

    return wrapper


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="vascsim")
def main() -> None:
    """vascsim: a haptic vascular-suturing simulator and assessment platform.

    Run `vascsim demo` for a tour on built-in data; `vascsim COMMAND --help`
    explains each command.
    """


@main.command()
@click.option(
    "--max-strain",
    default=0.5,
    show_default=True,
    type=click.FloatRange(0.01, 0.9),
    help="Deepest indentation, as strain of the 10 mm cube (0.5 = 5 mm).",
)
@click.option(
    "--steps",
    default=11,
    show_default=True,
    type=click.IntRange(2, 200),
    help="Number of strain levels from 0 to --max-strain.",
)
@click.option("--json", "as_json", is_flag=True, help="Print the results as JSON instead of a table.")
@user_errors
def demo(max_strain: float, steps: int, as_json: bool) -> None:
    """Press a scripted needle into the paper's test cube and print force vs stretch.

    Builds the 10 mm cube (729 nodes, 3072 tetrahedra) held on its base,
    precomputes the biphase model (E1 = 20 kPa, E2 = 40 kPa, strain limit 0.2),
    presses a needle into the top centre, and prints the reaction force of the
    E1-only and biphase models (at rest and at the critical needle speed) and the
    mesh volume change at each strain level (PAPER.md Fig. 3 and Table 1).
    """
    from rich.console import Console

    from sim.experiments import indentation_curve

    console = Console(stderr=True)
    strains = np.linspace(0.0, max_strain, steps)
    with console.status("precomputing the test cube and pressing the needle..."):
        curve = indentation_curve(strains)
    if as_json:
        click.echo(json.dumps(curve.as_dict(), indent=2))
        return
    _print_curve(curve)


def _print_curve(curve: Any) -> None:
    from rich.console import Console
    from rich.table import Table

    table = Table(title="Needle pressed into the 10 mm test cube (729 nodes, 3072 elements)")
    for header in (
        "strain",
        "stretch λ",
        "force E1-only (N)",
        "force biphase (N)",
        f"force biphase @ {curve.fast_speed * 1e3:.0f} mm/s (N)",
        "volume change E1-only (%)",
        "volume change biphase (%)",
    ):
        table.add_column(header, justify="right")
    for i, strain in enumerate(curve.strain):
        table.add_row(
            f"{strain:.2f}",
            f"{curve.stretch_ratio[i]:.2f}",
            f"{curve.force_linear[i]:.4f}",
            f"{curve.force_biphase[i]:.4f}",
            f"{curve.force_biphase_fast[i]:.4f}",
            f"{100 * curve.volume_change_linear[i]:+.2f}",
            f"{100 * curve.volume_change_biphase[i]:+.2f}",
        )
    console = Console()
    console.print(table)
    console.print(
        f"precompute (both phases, 915 condensed dofs each): {curve.precompute_seconds:.3f} s "
        "(the paper: 9 min for its smallest model)"
    )


@main.command()
@click.option("--json", "as_json", is_flag=True, help="Print the list as JSON.")
@user_errors
def devices(as_json: bool) -> None:
    """List connected devices and the driver that serves each.

    Looks for 3Dconnexion SpaceMice through hidapi and for known haptic and input
    devices (3D Systems Touch/Phantom, Novint Falcon, Force Dimension, 3Dconnexion)
    on the USB bus through pyusb; reports whether the OpenHaptics driver can be
    used; the scripted and replay devices are always available.
    """
    from sim.devices.discovery import list_devices

    reports = list_devices()
    if as_json:
        click.echo(json.dumps([r.as_dict() for r in reports], indent=2))
        return
    from rich.console import Console
    from rich.table import Table

    table = Table(title="Devices")
    for header in ("device", "driver", "connection", "status"):
        table.add_column(header)
    for r in reports:
        table.add_row(r.name, r.driver, r.connection, r.status)
    Console().print(table)


@main.command()
@click.argument("session_dir", type=click.Path(file_okay=False, path_type=str))
@click.option("--json", "as_json", is_flag=True, help="Print the recovered session's header as JSON.")
@user_errors
def recover(session_dir: str, as_json: bool) -> None:
    """Recover a session a crash left unfinished (SESSION_DIR holds its journal).

    Every complete batch of the journal becomes the session's Parquet files; the
    header is marked recovered with the time up to which data was kept (at most one
    flush interval, 100 ms by default, was lost).
    """
    from recorder import recover as recover_session

    header = recover_session(session_dir)
    if as_json:
        click.echo(json.dumps(header, indent=2, sort_keys=True))
        return
    rows = header["samples"]["rows"]
    until = header.get("recovered_until_s")
    kept = f"up to {until:.3f} s" if until is not None else "no samples"
    click.echo(
        f"recovered {session_dir}: {rows} samples kept ({kept}); at most "
        f"{header.get('lost_at_most_s')} s after that was lost"
    )
