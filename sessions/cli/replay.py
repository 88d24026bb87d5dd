"""`vascsim replay`: a session's replay video and stills."""

from __future__ import annotations

from pathlib import Path

import click

from sessions.cli.base import (
    open_catalog,
    parse_size,
    print_json,
    progress_bar,
    user_errors,
)


@click.command()
@click.argument("session")
@click.option(
    "--vs",
    "versus",
    default=None,
    help="A session to compare with (ghosted or beside): its id, or a participant code of this "
    "session's study for that participant's latest session on the same task.",
)
@click.option(
    "--vs-group",
    "versus_group",
    default=None,
    help="Compare with every session of this group in the session's study (e.g. experts): the most "
    "typical one is shown, all of them set the expert bands.",
)
@click.option("--mode", type=click.Choice(["ghost", "side-by-side"]), default="ghost", show_default=True)
@click.option(
    "-o", "--out", type=click.Path(dir_okay=False), default=None,
    help="Video file: .mp4 (H.264, plays in every browser) or .webm (VP9). Default: "
    "VASCSIM_HOME/replays/SESSION.mp4.",
)  # fmt: skip
@click.option("--fps", type=click.IntRange(1, 120), default=30, show_default=True, help="Frames per second.")
@click.option(
    "--size", default="1280x720", show_default=True, callback=parse_size, help="WIDTHxHEIGHT, even."
)
@click.option(
    "--stills", type=click.Path(file_okay=False), default=None,
    help="Also write insertion.png, stress_insertion.exr (Pa) and signals.png/.svg to this folder.",
)  # fmt: skip
@click.option(
    "--blind", is_flag=True,
    help="The render for blinded rating: the session alone, the wall in one colour, bites in grey, no "
    "names, expert, force arrow or readouts. Default file: VASCSIM_HOME/replays/blind/SESSION.mp4, "
    "which the dashboard's blinded rating page plays.",
)  # fmt: skip
@click.option("--json", "as_json", is_flag=True, help="Print the result as JSON.")
@user_errors
def replay(session, versus, versus_group, mode, out, fps, size, stills, blind, as_json) -> None:
    """Render a session's replay video, optionally against an expert.

    The 3-D scene (deformed wall with its stress colour map, needle, reaction-force
    arrow, insertion point) with a heads-up panel of phase, force, tip speed and
    entry angle; against an expert, the sessions are aligned phase by phase (DTW on
    the needle-tip path) and the expert is ghosted into the scene or shown beside it.
    """
    from metrics.replay.export import ReplaySettings, export_replay
    from metrics.replay.video import check_video_path
    from sessions.catalog import CatalogError
    from sessions.replaying import blind_replay_path, replay_inputs

    if versus and versus_group:
        raise CatalogError("give either --vs SESSION or --vs-group GROUP, not both")
    if blind and (versus or versus_group or mode != "ghost" or stills):
        raise CatalogError(
            "--blind shows the session alone: drop --vs, --vs-group, --mode side-by-side and --stills"
        )
    catalog, home = open_catalog()
    settings = ReplaySettings(fps=fps, size=size, mode=mode, blind=blind)
    if out:
        target = Path(out)
    elif blind:
        target = blind_replay_path(home, session)
    else:
        target = home / "replays" / f"{session}{'-vs' if versus or versus_group else ''}.mp4"
    check_video_path(target)
    recorded, tissue, experts = replay_inputs(catalog, home, session, versus, versus_group)
    with progress_bar() as progress:
        task = progress.add_task("rendering", total=None, last="")

        def advance(done: int, total: int) -> None:
            progress.update(task, completed=done, total=total, last=f"{done / settings.fps:.1f} s")

        result = export_replay(recorded, tissue, target, experts, settings, advance, stills)
    summary = {
        "video": str(result.path),
        "frames": result.frames,
        "seconds": round(result.seconds, 2),
        "frames_per_second": round(result.frames_per_second, 1),
        "experts": len(experts),
        "stills": [str(p) for p in result.stills],
    }
    if as_json:
        print_json(summary)
    else:
        click.echo(
            f"replay: {result.path} ({result.frames} frames at {fps:g} frames/s of video; "
            f"rendered at {result.frames_per_second:.0f} frames/s)"
        )
        for path in result.stills:
            click.echo(f"  {path}")
