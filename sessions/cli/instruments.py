"""`vascsim instruments`: real instruments tracked by a camera, and where their tips are."""

from __future__ import annotations

import click

from sessions.cli.base import open_catalog, print_json, user_errors


@click.group()
def instruments() -> None:
    """Instruments tracked by a camera: register their tips, list them."""


@instruments.command("register")
@click.argument("name", type=click.Choice(["needle-holder", "forceps"]))
@click.option(
    "--source", default="camera:0", show_default=True,
    help="camera:INDEX, a stream URL, or a video file of the pivoting instrument.",
)  # fmt: skip
@click.option(
    "--seconds", default=15.0, show_default=True, type=click.FloatRange(min=3.0),
    help="How long to watch a live camera.",
)  # fmt: skip
@user_errors
def register(name, source, seconds) -> None:
    """Find an instrument's tip by pivoting it (pivot calibration).

    Rest the instrument's tip in a small dimple (a pencil mark on card will do) in
    view of the calibrated camera and, keeping the tip there, tilt the instrument in
    every direction for the given time. The tip's position in the marker cube's
    frame is fitted by least squares; the residual (mm) says how well the tip stayed
    put, and a residual over 1 mm, or less than 20 deg of tilt, is refused.
    """
    from sessions.running.camera import register_instrument

    _, home = open_catalog()
    click.echo(f"pivot the {name} about its tip for {seconds:g} s ...", err=True)
    result, path = register_instrument(source, home, name, seconds)
    tip = ", ".join(f"{v * 1e3:.1f}" for v in result.tip_offset)
    click.echo(
        f"{name}: tip at ({tip}) mm in the cube's frame, residual {result.residual * 1e3:.2f} mm "
        f"(lower is better; at most 1 mm), {result.poses} poses over {result.spread_deg:.0f} deg of tilt; "
        f"saved in {path}"
    )


@instruments.command("list")
@click.option("--json", "as_json", is_flag=True, help="Print as JSON.")
@user_errors
def list_instruments(as_json) -> None:
    """The instruments, their markers and tips (registered, or nominal until registered)."""
    from sessions.running.camera import registered_tips
    from sim.tracking.markers import INSTRUMENTS

    _, home = open_catalog()
    tips = registered_tips(home)
    rows = []
    for key, body in INSTRUMENTS.items():
        entry = tips.get(key)
        offset = entry["tip_offset_mm"] if entry else [round(v * 1e3, 1) for v in body.tip_offset_m]
        rows.append(
            {
                "instrument": key,
                "markers": list(body.ids),
                "tip_offset_mm": offset,
                "residual_mm": entry["residual_mm"] if entry else None,
                "registered_at": entry["registered_at"] if entry else None,
            }
        )
    if as_json:
        print_json(rows)
        return
    for row in rows:
        where = ", ".join(f"{v:g}" for v in row["tip_offset_mm"])
        how = (
            f"registered {row['registered_at']}, residual {row['residual_mm']:.2f} mm"
            if row["registered_at"]
            else "nominal (not registered)"
        )
        click.echo(
            f"{row['instrument']}: markers {row['markers'][0]}-{row['markers'][-1]}, tip ({where}) mm, {how}"
        )
