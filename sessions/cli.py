"""The ``vascsim`` command line: one entry point, a subcommand per task.

User errors (any :class:`sim.errors.VascsimError`) print one line on stderr and
exit with status 1; ``--help`` on every command explains its options.
"""

from __future__ import annotations

import json
import sys
from collections.abc import Callable
from functools import wraps
from pathlib import Path
from typing import Any

import click
import numpy as np
import pandas as pd

from sessions.status import SCORABLE, SESSION_STATUSES
from sim.errors import VascsimError

LISTED_BY = {
    "study": "vascsim studies list",
    "session": "vascsim sessions list",
    "participant": "vascsim participants list --study STUDY",
    "task": "vascsim tasks list",
    "user": "vascsim users list",
}
"""Where the CLI lists each kind of thing the catalog can fail to find (the library's messages say
only what is missing)."""


def user_errors(command: Callable[..., Any]) -> Callable[..., Any]:
    """Turn vascsim errors into a one-line message and exit status 1 (no traceback)."""

    @wraps(command)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            return command(*args, **kwargs)
        except VascsimError as error:
            from sessions.catalog import NotFound

            hint = LISTED_BY.get(getattr(error, "kind", None)) if isinstance(error, NotFound) else None
            click.echo(f"vascsim: error: {error}" + (f" (list them with `{hint}`)" if hint else ""), err=True)
            sys.exit(1)

    return wrapper


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="vascsim")
def main() -> None:
    """vascsim: a haptic vascular-suturing simulator and assessment platform.

    Run `vascsim demo` for a tour on built-in data; `vascsim COMMAND --help`
    explains each command. Data lives in VASCSIM_HOME (default
    ~/.local/share/vascsim); VASCSIM_DATABASE_URL selects a PostgreSQL catalog.
    """
    from sessions.config import prepare_rendering

    prepare_rendering()


@main.command()
@click.option(
    "--tissue",
    "preset",
    default="porcine-artery",
    show_default=True,
    type=click.Choice(["porcine-artery", "calcified", "paper"]),
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
@click.option("--json", "as_json", is_flag=True, help="Print the results as JSON instead of a table.")
@user_errors
def indentation(preset: str, max_strain: float, max_depth: float, steps: int, as_json: bool) -> None:
    """Press a scripted needle straight into the tissue and print force against depth.

    With a calibrated preset (default porcine-artery): the wall-stitch patch (0.3 mm cells in the
    stitch region) pressed at its entry point at 4 mm/s through the runtime's force kernel; prints
    the normal force in mN, the biphase phase, the local von Mises stress in kPa and the depth at
    which the needle pierces. With --tissue paper: the paper's 10 mm cube (E1 = 20 kPa, E2 =
    40 kPa), E1-only and biphase forces and the mesh volume change per strain level.
    """
    from rich.console import Console

    console = Console(stderr=True)
    if preset == "paper":
        from sim.experiments import indentation_curve

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
    from sim.experiments import kernel_indentation_curve
    from sim.fem import BiphaseTissue
    from sim.tissue_presets import tissue_preset

    spec, chosen = task_spec("wall-stitch"), tissue_preset(preset)
    with console.status(f"precomputing the wall-stitch patch ({preset}) and pressing the needle..."):
        base = tissue_for("wall-stitch", cache_dir())
        tissue = base
        if chosen.biphase != base.parameters:
            tissue = BiphaseTissue.build(
                base.mesh, base.soft.fixed_dofs // 3, chosen.biphase, contact_nodes=base.soft.contact_nodes
            )
        depths = np.linspace(0.0, max_depth * 1e-3, steps)
        curve = kernel_indentation_curve(
            tissue, chosen.forces, spec.entry, spec.normal, depths, needle_speed=0.004
        )
    if as_json:
        click.echo(json.dumps({"tissue": preset, **curve.as_dict()}, indent=2))
        return
    _print_kernel_curve(preset, curve)


def _print_kernel_curve(preset: str, curve: Any) -> None:
    from rich.console import Console
    from rich.table import Table

    table = Table(title=f"Needle pressed into the {preset} wall-stitch patch at 4 mm/s")
    for header in ("depth (mm)", "force (mN)", "phase", "local stress (kPa)"):
        table.add_column(header, justify="right")
    for depth, force, share, stress in zip(
        curve.depth, curve.force, curve.soft_share, curve.local_stress, strict=True
    ):
        phase = "soft" if share >= 1.0 else f"stiff {100 * (1 - share):.0f}%"
        table.add_row(f"{depth * 1e3:.2f}", f"{max(force, 0.0) * 1e3:.0f}", phase, f"{stress / 1e3:.0f}")
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
@click.argument("session")
@click.option("--score/--no-score", default=True, show_default=True, help="Score the session once recovered.")
@click.option("--json", "as_json", is_flag=True, help="Print the recovered session's header as JSON.")
@user_errors
def recover(session: str, score: bool, as_json: bool) -> None:
    """Recover a session a crash left unfinished: SESSION is its id or its directory.

    Every batch of the journal that verifies against its checksum becomes the
    session's Parquet files (reading stops at the first damaged or torn batch, and
    what was cut is reported); if the recording process died but the machine did
    not, the samples it recorded after its last flush are taken from its memory
    (tmpfs) too. The header records the measured loss. A catalogued session becomes
    `recovered`, with its files' checksums, and is scored. Find candidates with
    `vascsim sessions list --status running`.
    """
    from sessions.runner import recover_session, score_session

    catalog, home = _catalog()
    uid, header = recover_session(catalog, session)
    if uid is not None and score and header["samples"]["rows"]:
        score_session(catalog, uid, home)
    if as_json:
        click.echo(json.dumps(dict(header, catalog_session=uid), indent=2, sort_keys=True))
        return
    rows = header["samples"]["rows"]
    until = header.get("recovered_until_s")
    kept = f"up to {until:.3f} s" if until is not None else "no samples"
    click.echo(f"recovered {uid or session}: {rows} samples kept ({kept}); {header['loss_note']}")
    for stream in ("samples", "events"):
        cut = header[stream].get("cut")
        if cut:
            click.echo(
                f"  {stream}: {cut['bytes']} damaged or incomplete bytes cut after batch "
                f"{cut['after_batches']} ({cut['reason']})"
            )


# -- catalog-backed commands ------------------------------------------------------------
def _catalog():
    from sessions.catalog import Catalog
    from sessions.config import data_home, database_url

    home = data_home()
    catalog = Catalog(database_url(home))
    click.get_current_context().call_on_close(catalog.close)  # no pooled connection outlives the command
    return catalog, home


def _progress(transient: bool = False):
    """A progress bar on stderr; a transient one vanishes when done and stays silent off a terminal."""
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    console = _stderr_console()
    return Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        TextColumn("{task.fields[last]}"),
        transient=transient,
        disable=transient and not console.is_terminal,
        console=console,
    )


def _stderr_console():
    from rich.console import Console

    return Console(stderr=True)


def _print_frame(frame, title: str, caption: str | None = None) -> None:
    from rich import box
    from rich.console import Console
    from rich.table import Table

    table = Table(title=title, caption=caption, box=box.SIMPLE_HEAD, padding=(0, 1), collapse_padding=True)
    for k, column in enumerate(frame.columns):
        # names are never cut and no value ends in an ellipsis: a short value keeps its width, a long
        # one wraps at its spaces ("0.83" over "(0.61-0.95)")
        widest = max([len(_cell(v)) for v in frame[column]] or [0])
        short = max([len(part) for v in frame[column] for part in _cell(v).split()] or [0])
        table.add_column(str(column), no_wrap=k == 0, overflow="fold", min_width=min(widest, max(short, 4)))
    for row in frame.itertuples(index=False):
        table.add_row(*[_cell(v) for v in row])
    Console().print(table)


def _cell(value) -> str:
    if value is None or value is pd.NA:
        return ""
    if isinstance(value, float):
        return "" if value != value else f"{value:.4g}"
    if isinstance(value, bool | np.bool_):
        return "yes" if value else "no"
    return str(value)


def _json(data) -> None:
    click.echo(json.dumps(data, indent=2, default=_json_default))


def _json_default(value):
    if isinstance(value, np.generic):
        return value.item()
    return str(value)


@main.command()
@click.option(
    "--small",
    is_flag=True,
    help="A reduced study (2 experts x 2, 3 trainees x 3 + retention) for a quick look.",
)
@click.option("--json", "as_json", is_flag=True, help="Print the summary as JSON.")
@user_errors
def demo(small: bool, as_json: bool) -> None:
    """Run a small synthetic study end to end and print what it found.

    With no hardware and no configuration, a two-task course on a porcine artery
    with an arteriotomy: 4 synthetic experts x 3 sessions and 6 synthetic trainees
    x 5 practice sessions + 1 retention session of the interrupted stitch, then
    every participant closes the arteriotomy once (a row of three stitches). Each
    session is a scripted pass through the real simulator (simulated time, two at
    once), recorded, catalogued and scored. Then it prints which metrics
    discriminate on the practice task (primary set declared in advance), effect
    sizes, each trainee's proficiency status, the final task's largest
    differences, and the paths of the reports (HTML, Markdown, CSV, figures).
    Re-running replaces the previous demo study; participants are labelled
    synthetic everywhere.
    """
    from metrics.report import compact_caption, compact_summary, composite_summary, summary_table
    from sessions.demo import DEMO_STUDY, DemoSize, run_demo

    catalog, home = _catalog()
    size = DemoSize(2, 2, 3, 3, True) if small else DemoSize()
    with _progress() as progress:
        task = progress.add_task("synthetic sessions", total=size.sessions, last="")
        result = run_demo(
            catalog, home, size, advance=lambda text: progress.update(task, advance=1, last=text)
        )
    analysis = result.analysis
    validity = analysis.validity
    groups = analysis.settings.groups
    summary = compact_summary(analysis)
    trainees = analysis.trainees[["participant_id", "passes", "proficient", "trials_to_proficiency"]].copy()
    if "retention_passed" in analysis.trainees:
        trainees["retention_passed"] = analysis.trainees["retention_passed"]
    if as_json:
        _json(
            {
                "sessions": result.sessions,
                "seconds": result.seconds,
                "report": str(result.report),
                "metrics": summary_table(analysis).to_dict(orient="records"),
                "trainees": trainees.to_dict(orient="records"),
                "notes": validity.notes + analysis.notes,
                "composite_auc": None if validity.composite is None else validity.composite.auc,
                "composite": composite_summary(validity.composite),
                "synthetic": True,
            }
        )
        return
    _print_frame(
        summary,
        f"Construct validity, {groups[0]} vs {groups[1]}, participant level (SYNTHETIC participants)",
        compact_caption(analysis),
    )
    _print_frame(trainees, "Trainees: proficiency (benchmarks from the experts)")
    for note in validity.notes + analysis.notes:
        click.echo(f"note: {note}")
    click.echo(f"composite score: {composite_summary(validity.composite)}")
    if result.final is not None:
        click.echo(_final_task_line(result.final, result.final_report))
    click.echo(f"{result.sessions} sessions in {result.seconds:.0f} s; full report: {result.report}")
    first_trainee = analysis.sessions.loc[analysis.sessions["label"] == "trainee", "session_id"]
    if len(first_trainee):
        click.echo(
            f"replay a trainee against the experts: vascsim replay {first_trainee.iloc[0]} "
            "--vs-group experts --mode side-by-side"
        )
    with catalog.session() as orm:
        study_id = catalog.study(orm, DEMO_STUDY).id
    click.echo(
        "open the results in the dashboard: vascsim users add NAME --role admin; vascsim serve; "
        f"then http://127.0.0.1:8000/studies/{study_id}"
    )


@main.group()
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
        _json(rows)
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
        _json(asdict(spec))
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


@main.group()
def studies() -> None:
    """Studies and courses in the catalog."""


@studies.command("list")
@click.option("--json", "as_json", is_flag=True, help="Print as JSON.")
@user_errors
def studies_list(as_json: bool) -> None:
    """List studies with their participant and session counts."""
    import pandas as pd

    catalog, _ = _catalog()
    with catalog.session() as orm:
        from sqlalchemy import select

        from sessions.models import Study

        rows = [
            {
                "study": s.name,
                "participants": len(s.participants),
                "sessions": sum(len(p.sessions) for p in s.participants),
                "synthetic": any(p.synthetic for p in s.participants),
                "description": s.description,
            }
            for s in orm.scalars(select(Study).order_by(Study.name))
        ]
    if as_json:
        _json(rows)
        return
    _print_frame(
        pd.DataFrame(rows, columns=["study", "participants", "sessions", "synthetic", "description"]),
        "Studies",
    )


@studies.command("add")
@click.argument("name")
@click.option("--description", default="", help="Free text shown in listings and reports.")
@user_errors
def studies_add(name: str, description: str) -> None:
    """Create a study (or course) called NAME."""
    from sessions.catalog import CatalogError

    catalog, _ = _catalog()
    with catalog.session() as orm:
        from sqlalchemy import select

        from sessions.models import Study

        if orm.scalar(select(Study).where(Study.name == name)) is not None:
            raise CatalogError(f"study {name!r} already exists")
        catalog.study(orm, name, create=True, description=description)
    click.echo(f"study {name} created")


@studies.command("analysis")
@click.argument("study")
@click.option("--groups", default=None, help="The two groups compared, skilled first (a,b).")
@click.option("--level", type=click.Choice(["participant", "trial"]), default=None, help="Analysis level.")
@click.option("--metrics", "metric_names", default=None, help="Comma-separated primary metrics.")
@click.option("--rule", default=None, help="Benchmark rule: mean, median or percentile:Q.")
@click.option(
    "--consecutive", type=int, default=None, help="Consecutive passes that make a trainee proficient."
)
@click.option("--rating", default=None, help="Continuous rating for concurrent validity, e.g. grs_total.")
@click.option(
    "--retention-baseline",
    type=int,
    default=None,
    help="Retention: compare the delayed session with the mean of this many last practice sessions.",
)
@click.option("--by", "author", default=None, help="Who declares this version (default: the login name).")
@click.option("--note", default="", help="Why this version.")
@click.option("--json", "as_json", is_flag=True, help="Print as JSON.")
@user_errors
def studies_analysis(
    study, groups, level, metric_names, rule, consecutive, rating, retention_baseline, author, note, as_json
) -> None:
    """Show a study's declared analysis and its versions, or declare a new version.

    With no option it prints what every report, the dashboard and exports use. Any option
    declares a new version from the current one with that choice changed (recorded with who,
    when and --note); earlier versions are kept.
    """
    import dataclasses
    import getpass

    from sessions.analysis import analysis_history, declare_analysis, declared_settings, settings_to_json

    catalog, _ = _catalog()
    changes = _analysis_options(groups, level, metric_names, rule, consecutive)
    if rating is not None:
        changes["rating_col"] = rating
    if retention_baseline is not None:
        changes["retention_baseline"] = retention_baseline
    if changes:
        current, _, _ = declared_settings(catalog, study)
        version = declare_analysis(
            catalog, study, dataclasses.replace(current, **changes), author or getpass.getuser(), note
        )
        click.echo(f"study {study!r}: analysis version {version} declared")
    settings, version, who = declared_settings(catalog, study)
    history = analysis_history(catalog, study)
    if as_json:
        _json(
            {"study": study, "version": version, "settings": settings_to_json(settings), "history": history}
        )
        return
    click.echo(
        f"study {study!r}: "
        + (f"declared analysis version {version} (by {who})" if version else "no analysis declared; defaults")
    )
    for name, value in settings_to_json(settings).items():
        if value is None:
            value = (
                "the discriminating metrics" if name == "benchmark_metrics" else "every metric with values"
            )
        elif isinstance(value, list):
            value = ", ".join(value)
        click.echo(f"  {name:20s} {value}")
    for entry in history:
        click.echo(f"  v{entry['version']} {entry['created_at']} {entry['author']}: {entry['note']}")


@main.group()
def participants() -> None:
    """Pseudonymous participants of a study."""


@participants.command("add")
@click.argument("code")
@click.option("--study", required=True, help="Study the participant joins.")
@click.option("--level", default="", help="Self-reported level, e.g. expert, trainee, novice.")
@click.option("--group", "group_label", default="", help="Group label analysed (default: the level).")
@click.option("--years", type=click.FloatRange(0, 80), default=None, help="Years of surgical experience.")
@click.option(
    "--handedness", type=click.Choice(["right", "left", "ambidextrous"]), default="right", show_default=True
)
@user_errors
def participants_add(code: str, study: str, level: str, group_label: str, years, handedness: str) -> None:
    """Add participant CODE (a pseudonym; never a name) to a study."""
    catalog, _ = _catalog()
    with catalog.session() as orm:
        found = catalog.study(orm, study)
        catalog.add_participant(orm, found, code, level, group_label, years, handedness)
    click.echo(f"participant {code} added to {study}")


@participants.command("list")
@click.option("--study", required=True, help="Study to list.")
@click.option("--json", "as_json", is_flag=True, help="Print as JSON.")
@user_errors
def participants_list(study: str, as_json: bool) -> None:
    """List a study's participants."""
    import pandas as pd

    catalog, _ = _catalog()
    with catalog.session() as orm:
        found = catalog.study(orm, study)
        rows = [
            {
                "code": p.code,
                "level": p.level,
                "group": p.group_label,
                "years": p.years_experience,
                "handedness": p.handedness,
                "synthetic": p.synthetic,
                "sessions": len(p.sessions),
            }
            for p in sorted(found.participants, key=lambda p: p.code)
        ]
    if as_json:
        _json(rows)
        return
    _print_frame(pd.DataFrame(rows), f"Participants of {study}")


@main.command()
@click.option("--study", required=True, help="Study the session belongs to.")
@click.option("--participant", required=True, help="Participant code.")
@click.option("--task", default="wall-stitch", show_default=True, help="Task / scenario.")
@click.option(
    "--device",
    default="scripted",
    show_default=True,
    help="scripted, spacemouse, openhaptics, or replay:SESSION to play a recorded session back.",
)
@click.option(
    "--skill",
    type=click.FloatRange(0, 1),
    default=0.9,
    show_default=True,
    help="Scripted device: skill of the pass (0-1).",
)
@click.option("--phase", type=click.Choice(["practice", "retention"]), default="practice", show_default=True)
@click.option(
    "--duration", type=click.FloatRange(0.1, 7200), default=None, help="Seconds (needed for live devices)."
)
@click.option(
    "--realtime", is_flag=True, help="Real-time clock (a person at the device); default simulated time."
)
@click.option("--json", "as_json", is_flag=True, help="Print the session's metrics as JSON.")
@user_errors
def run(study, participant, task, device, skill, phase, duration, realtime, as_json) -> None:
    """Run one session: device + simulator + recorder + catalog entry, then scoring.

    The catalog row is written as 'running' first and becomes 'complete' only when
    the streams are closed and checksummed; Ctrl-C or an error keeps the data and
    marks the session 'failed'; after a crash, `vascsim recover` restores it.
    """
    from sessions.runner import SessionPlan, run_session
    from sessions.synthetic import pass_parameters

    catalog, home = _catalog()
    clock = "realtime" if realtime or device in ("spacemouse", "openhaptics") else "simulated"
    if duration is None and device in ("spacemouse", "openhaptics"):
        raise click.UsageError(f"--duration is needed with device {device!r} (it runs until stopped)")
    plan = SessionPlan(study, participant, task, None, phase, device, clock)  # next trial, allocated
    parameters = (lambda trial: pass_parameters(skill, seed=trial)) if device == "scripted" else None
    with _stderr_console().status(f"running {participant} on {device}..."):
        uid = run_session(catalog, home, plan, parameters, duration)
    with catalog.session() as orm:
        trial = catalog.recorded_session(orm, uid).trial
    values = _session_metrics(catalog, uid)
    if as_json:
        _json({"session": uid, "trial": trial, "metrics": values})
        return
    click.echo(f"session {uid} ({participant}, trial {trial}) complete and scored")
    for name, value in values.items():
        click.echo(f"  {name:28s} {_cell(value)}")


def _session_metrics(catalog, uid: str) -> dict:

    from metrics import REGISTRY_VERSION

    with catalog.session() as orm:
        row = catalog.recorded_session(orm, uid)
        return {
            m.metric: m.value
            for m in sorted(row.metrics, key=lambda m: m.id)
            if m.registry_version == REGISTRY_VERSION
        }


@main.group()
def sessions() -> None:
    """Recorded sessions: list, show, delete."""


@sessions.command("list")
@click.option("--study", default=None, help="Only this study.")
@click.option("--task", default=None, help="Only sessions of this task.")
@click.option("--status", type=click.Choice(SESSION_STATUSES), default=None)
@click.option("--json", "as_json", is_flag=True, help="Print as JSON.")
@user_errors
def sessions_list(study, task, status, as_json) -> None:
    """List sessions (newest last), with the task each ran (trials count per task)."""
    import pandas as pd
    from sqlalchemy import select

    from sessions.analysis import metric_versions
    from sessions.models import Participant, Session, Study, Task

    catalog, _ = _catalog()
    with catalog.session() as orm:
        query = (
            select(
                Session.uid,
                Study.name,
                Participant.code,
                Task.name,
                Session.trial,
                Session.phase,
                Session.device,
                Session.status,
            )
            .join(Participant, Session.participant_id == Participant.id)
            .join(Study, Participant.study_id == Study.id)
            .join(Task, Session.task_id == Task.id)
            .order_by(Session.id)
        )
        if study:
            catalog.study(orm, study)
            query = query.where(Study.name == study)
        if task:
            query = query.where(Task.name == task)
        if status:
            query = query.where(Session.status == status)
        found = orm.execute(query.add_columns(Session.id)).all()
    versions = metric_versions(catalog, [r[-1] for r in found])
    columns = ("session", "study", "participant", "task", "trial", "phase", "device", "status")
    rows = [dict(zip(columns, r[:-1], strict=True), metrics=versions[r[-1]]) for r in found]
    if as_json:
        _json(rows)
        return
    frame = pd.DataFrame(rows, columns=[*columns, "metrics"])
    # a column with one value in every row is said once, in the caption, so the rest fit 80 columns
    same = [c for c in ("study", "device", "metrics") if len(frame) and frame[c].nunique() == 1]
    caption = "; ".join(f"{c} {frame[c].iloc[0]}" for c in same) if same else None
    _print_frame(frame.drop(columns=same), "Sessions", f"all sessions: {caption}" if caption else None)
    stale = [r for r in rows if r["metrics"].startswith("stale")]
    if stale:
        studies = sorted({r["study"] for r in stale})
        click.echo(
            f"{len(stale)} session(s) scored with an older metric registry; rescore: "
            + "; ".join(f"vascsim score --study {name}" for name in studies)
        )


@sessions.command("show")
@click.argument("uid")
@click.option("--json", "as_json", is_flag=True, help="Print as JSON.")
@user_errors
def sessions_show(uid: str, as_json: bool) -> None:
    """Show one session: who, what, when, files with checksums, metrics."""

    catalog, _ = _catalog()
    with catalog.session() as orm:
        row = catalog.recorded_session(orm, uid)
        data = {
            "session": row.uid,
            "study": row.participant.study.name,
            "participant": row.participant.code,
            "synthetic": row.participant.synthetic,
            "task": row.task.name,
            "device": row.device,
            "clock": row.clock,
            "trial": row.trial,
            "phase": row.phase,
            "status": row.status,
            "started": row.started_at.isoformat(),
            "ended": row.ended_at.isoformat() if row.ended_at else None,
            "directory": row.directory,
            "error": row.error,
            "files": [{"name": f.name, "sha256": f.sha256, "bytes": f.bytes} for f in row.files],
        }
    from sessions.review import session_against_experts, session_stitches

    rows = session_against_experts(catalog, uid)
    data["metrics"] = {r["metric"]: r["value"] for r in rows}
    data["versus_experts"] = {r["metric"]: r["versus_experts"] for r in rows}
    data["stitches"] = session_stitches(catalog, uid)
    if as_json:
        _json(data)
        return
    for key, value in data.items():
        if key == "files":
            for f in value:
                click.echo(f"  file {f['name']:18s} {f['bytes']:>10d} B  sha256 {f['sha256']}")
        elif key == "metrics":
            click.echo(
                "metrics      (against the experts' quartiles of this task, by each metric's direction)"
            )
            for r in rows:
                versus = r["versus_experts"] or ""
                click.echo(f"  {r['metric']:28s} {_cell(r['value']):>12s} {r['unit']:8s} {versus}")
        elif key == "versus_experts":
            continue
        elif key == "stitches":
            _show_stitches(value)
        else:
            click.echo(f"{key:12s} {value}")


def _final_task_line(final, report) -> str:
    """One line on the demo's final task: its three largest expert-trainee differences and its report."""
    table = final.validity.table.dropna(subset=["auc"])
    top = table.assign(effect=(table["auc"] - 0.5).abs()).nlargest(3, "effect")
    named = ", ".join(
        f"{row.metric} (AUC {row.auc:.2f}: {'experts' if row.auc > 0.5 else 'trainees'} better)"
        for row in top.itertuples()
    )
    return (
        f"final task {final.settings.task} (each participant once, after practice): largest expert-trainee "
        f"differences {named}; report: {report}"
    )


def _show_stitches(stitches: list[dict]) -> None:
    """Where each bite went, in mm (fits 80 columns)."""
    if not stitches:
        click.echo("stitches     none scored against placement targets (older sessions: `vascsim score`)")
        return
    click.echo("stitches     where each bite went, in mm (from the wound edge; from the marks)")
    click.echo("  stitch  entry bite  exit bite  entry to mark  exit to mark  through intima")

    def mm(value) -> str:
        return "-" if value is None else f"{1e3 * value:.2f}"

    for s in stitches:
        through = {None: "no exit", 1.0: "yes", 0.0: "no (cut edge)"}.get(s.get("full_thickness"), "?")
        click.echo(
            f"  {s['stitch']:>6d}  {mm(s.get('entry_bite')):>10s}  {mm(s.get('exit_bite')):>9s}  "
            f"{mm(s.get('entry_to_target')):>13s}  {mm(s.get('exit_to_target')):>12s}  {through}"
        )
    if all(s.get("track_offset") is None for s in stitches):
        return
    click.echo("passage      how the needle went through the wall (lower is better)")
    click.echo("  stitch  off its track (mm)  swept (mm^2)  wound-edge stress (MPa)")

    def scaled(value, factor: float, digits: int) -> str:
        return "-" if value is None else f"{factor * value:.{digits}f}"

    for s in stitches:
        click.echo(
            f"  {s['stitch']:>6d}  {scaled(s.get('track_offset'), 1e3, 2):>18s}  "
            f"{scaled(s.get('swept_area'), 1e6, 1):>12s}  {scaled(s.get('wound_edge_stress'), 1e-6, 2):>23s}"
        )


@sessions.command("delete")
@click.argument("uid")
@click.option("--yes", is_flag=True, help="Do not ask for confirmation.")
@user_errors
def sessions_delete(uid: str, yes: bool) -> None:
    """Delete a session's catalog rows and its stream files."""
    import shutil

    catalog, _ = _catalog()
    with catalog.session() as orm:
        row = catalog.recorded_session(orm, uid)
        if not yes:
            click.confirm(f"delete session {uid} and its files?", abort=True)
        directory = row.directory
        orm.delete(row)
    if directory and _is_session_dir(directory):
        shutil.rmtree(directory, ignore_errors=True)
    click.echo(f"session {uid} deleted")


def _is_session_dir(directory: str) -> bool:
    from pathlib import Path

    from recorder.layout import is_session_directory

    return is_session_directory(Path(directory))


@main.command()
@click.argument("uids", nargs=-1)
@click.option("--study", default=None, help="Score every complete session of this study.")
@click.option("--json", "as_json", is_flag=True, help="Print the metrics as JSON.")
@user_errors
def score(uids, study, as_json) -> None:
    """(Re)compute every metric of the given sessions, or of a whole study."""
    from sqlalchemy import select

    from sessions.catalog import CatalogError
    from sessions.models import Participant, Session, Study
    from sessions.runner import score_session

    catalog, home = _catalog()
    targets = list(uids)
    if study:
        with catalog.session() as orm:
            catalog.study(orm, study)
            targets += list(
                orm.scalars(
                    select(Session.uid)
                    .join(Participant, Session.participant_id == Participant.id)
                    .join(Study, Participant.study_id == Study.id)
                    .where(
                        Study.name == study,
                        Session.status.in_(SCORABLE),
                        Session.device != "jigsaws",
                    )
                )
            )
    if not targets:
        raise CatalogError("nothing to score: give session ids or --study")
    results = {}
    with _progress() as progress:
        task = progress.add_task("scoring", total=len(targets), last="")
        for uid in targets:
            results[uid] = score_session(catalog, uid, home)
            progress.update(task, advance=1, last=uid)
    if as_json:
        _json(results)
    else:
        click.echo(f"scored {len(results)} session(s)")


@main.command()
@click.option("--study", required=True, help="Study to report on.")
@click.option(
    "--out",
    type=click.Path(file_okay=False),
    default=None,
    help="Folder (default VASCSIM_HOME/reports/STUDY).",
)
@click.option("--groups", default=None, help="Override: the two groups compared, skilled first (a,b).")
@click.option(
    "--level", type=click.Choice(["participant", "trial"]), default=None, help="Override: analysis level."
)
@click.option("--metrics", "metric_names", default=None, help="Override: comma-separated primary metrics.")
@click.option("--rule", default=None, help="Override: benchmark rule, mean, median or percentile:Q.")
@click.option(
    "--rating", default=None, help="Override: a continuous rating for concurrent validity, e.g. grs_total."
)
@click.option("--task", default=None, help="Override: the task whose sessions are analysed.")
@click.option("--json", "as_json", is_flag=True, help="Print the validity table as JSON.")
@user_errors
def report(study, out, groups, level, metric_names, rule, rating, task, as_json) -> None:
    """Write a study report (HTML, Markdown, CSV tables, PNG/SVG figures).

    The analysis is the one the study declared (`vascsim studies analysis STUDY` shows it), the
    same the dashboard and the demo use. Options override it for this report only; the report
    says which.
    """
    from pathlib import Path

    from metrics.report import write_report
    from sessions.analysis import analyse_catalog_study

    catalog, home = _catalog()
    overrides = _analysis_options(groups, level, metric_names, rule)
    if rating is not None:
        overrides["rating_col"] = rating
    if task is not None:
        overrides["task"] = task
    with _stderr_console().status("analysing and writing the report..."):
        analysis, source = analyse_catalog_study(catalog, study, overrides)
        page = write_report(analysis, Path(out) if out else home / "reports" / study, title=f"Study {study}")
    if as_json:
        _json(
            {
                "report": str(page),
                "analysis_version": source.version,
                "overridden": {k: {"declared": a, "used": b} for k, (a, b) in source.overridden.items()},
                "validity": analysis.validity.table.to_dict(orient="records"),
                "benchmarks": analysis.benchmarks.to_dict(orient="records"),
                "proficiency": analysis.proficiency.to_dict(orient="records"),
                "concurrent": None
                if analysis.concurrent is None
                else analysis.concurrent.table.to_dict(orient="records"),
            }
        )
        return
    for note in analysis.notes[:2]:
        click.echo(note)
    click.echo(f"report: {page}")


def _analysis_options(groups, level, metric_names, rule, consecutive=None) -> dict:
    from sessions.catalog import CatalogError

    options: dict = {"level": level, "benchmark_rule": rule, "consecutive_passes": consecutive}
    if groups is not None:
        names = tuple(part.strip() for part in groups.split(","))
        if len(names) != 2:
            raise CatalogError(f"--groups needs two comma-separated groups, skilled first; got {groups!r}")
        options["groups"], options["skilled_group"] = names, names[0]
    if metric_names is not None:
        options["metrics"] = tuple(part.strip() for part in metric_names.split(",") if part.strip())
    return {k: v for k, v in options.items() if v is not None}


def _video_size(_ctx, _param, value: str) -> tuple[int, int]:
    try:
        width, height = (int(part) for part in value.lower().split("x"))
    except ValueError:
        raise click.BadParameter(f"{value!r} is not WIDTHxHEIGHT, e.g. 1280x720") from None
    return width, height


@main.command()
@click.argument("session")
@click.option("--vs", "versus", default=None, help="An expert session to compare with (ghosted or beside).")
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
    "--size", default="1280x720", show_default=True, callback=_video_size, help="WIDTHxHEIGHT, even."
)
@click.option(
    "--stills", type=click.Path(file_okay=False), default=None,
    help="Also write insertion.png, stress_insertion.exr (Pa) and signals.png/.svg to this folder.",
)  # fmt: skip
@click.option("--json", "as_json", is_flag=True, help="Print the result as JSON.")
@user_errors
def replay(session, versus, versus_group, mode, out, fps, size, stills, as_json) -> None:
    """Render a session's replay video, optionally against an expert.

    The 3-D scene (deformed wall with its stress colour map, needle, reaction-force
    arrow, insertion point) with a heads-up panel of phase, force, tip speed and
    entry angle; against an expert, the sessions are aligned phase by phase (DTW on
    the needle-tip path) and the expert is ghosted into the scene or shown beside it.
    """
    from metrics.replay.export import ReplaySettings, export_replay
    from metrics.replay.video import check_video_path
    from sessions.replaying import replay_inputs

    catalog, home = _catalog()
    settings = ReplaySettings(fps=fps, size=size, mode=mode)
    target = (
        Path(out) if out else home / "replays" / f"{session}{'-vs' if versus or versus_group else ''}.mp4"
    )
    check_video_path(target)
    recorded, tissue, experts = replay_inputs(catalog, home, session, versus, versus_group)
    with _progress() as progress:
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
        _json(summary)
    else:
        click.echo(f"replay: {result.path} ({result.frames} frames, {result.frames_per_second:.0f} frames/s)")
        for path in result.stills:
            click.echo(f"  {path}")


@main.command("export")
@click.option("--study", required=True, help="Study to export.")
@click.option(
    "-o",
    "--out",
    type=click.Path(dir_okay=False),
    default=None,
    help="Archive to write (default: STUDY.vascsim.zip in the current directory).",
)
@click.option(
    "--sign",
    "sign_key",
    type=click.Path(dir_okay=False),
    default=None,
    help="Sign the bundle with this site's Ed25519 private key (make one with `vascsim keys new`).",
)
@click.option("--json", "as_json", is_flag=True, help="Print the summary as JSON.")
@user_errors
def export_bundle(study: str, out: str | None, sign_key: str | None, as_json: bool) -> None:
    """Write a study as one self-contained archive (catalog rows + stream files + checksums).

    The archive moves a study between machines or catalogs (SQLite <-> PostgreSQL);
    `vascsim import-bundle` reads it back. Every file is checked against its
    recorded SHA-256 on the way out. A checksum proves only that nothing was damaged
    by accident; --sign adds an Ed25519 signature, so a site holding your public key
    can verify that the study comes from you unchanged (`import-bundle --trust`).
    """
    from sessions.bundle import export_study

    catalog, _ = _catalog()
    target = out or f"{study}.vascsim.zip"
    summary = _per_file("exporting", lambda advance: export_study(catalog, study, target, advance, sign_key))
    signed = f", signed by key {summary['signed_by']}" if summary["signed_by"] else ""
    _summary(
        summary,
        as_json,
        f"exported study {study}: {summary['sessions']} session(s), {summary['files']} file(s) "
        f"-> {summary['bundle']}{signed}",
    )


@main.group()
def keys() -> None:
    """Signing keys for study bundles (Ed25519)."""


@keys.command("new")
@click.argument("path", type=click.Path(dir_okay=False))
@user_errors
def keys_new(path: str) -> None:
    """Make a site key pair: PATH (private, readable by you only) and PATH.pub (hand this out).

    Sign exports with `vascsim export --sign PATH`; a receiving site verifies them with
    `vascsim import-bundle --trust PATH.pub`.
    """
    from sessions.signing import new_key_pair, trusted_fingerprint

    private, public = new_key_pair(path)
    key = trusted_fingerprint(public)
    click.echo(f"private key {private} (keep it safe), public key {public}: key {key}")


def _per_file(description: str, work):
    """Run ``work(advance)`` under a transient progress bar advanced once per file."""
    with _progress(transient=True) as progress:
        task = progress.add_task(description, total=None, last="")
        return work(lambda name: progress.update(task, advance=1, last=name))


def _summary(summary: dict, as_json: bool, text: str) -> None:
    if as_json:
        _json(summary)
    else:
        click.echo(text)


@main.command("import-bundle")
@click.argument("bundle", type=click.Path(dir_okay=False))
@click.option(
    "--trust",
    type=click.Path(dir_okay=False),
    default=None,
    help="Accept the bundle only if it is signed by this public key (PATH.pub of `vascsim keys new`).",
)
@click.option(
    "--keep-imported-metrics",
    is_flag=True,
    help="Store the bundle's metric values as they are (marked imported, unverified) instead of "
    "recomputing them from the streams.",
)
@click.option("--json", "as_json", is_flag=True, help="Print the summary as JSON.")
@user_errors
def import_bundle_command(bundle: str, trust: str | None, keep_imported_metrics: bool, as_json: bool) -> None:
    """Add a study exported by `vascsim export` to this catalog.

    The bundle is checked completely first: its declared schema, every file's size
    and checksum, the signature when --trust is given. Metric values are recomputed
    from the imported streams (values the bundle states differently are counted and
    replaced). A bad bundle, a study name already in use, or a session id already
    catalogued is refused and nothing is changed. Participants arrive without any
    account link: link trainee accounts here with `vascsim users`.
    """
    from sessions.bundle import import_bundle

    catalog, home = _catalog()
    summary = _per_file(
        "verifying",
        lambda advance: import_bundle(catalog, home, bundle, advance, trust, not keep_imported_metrics),
    )
    if keep_imported_metrics:
        metrics = "metrics imported as stated, unverified"
    else:
        differing = summary["metric_values_differing"]
        metrics = f"metrics recomputed from the streams ({differing} stated value(s) differed, replaced)"
    signed = f"; signed by trusted key {summary['signed_by']}" if summary["signed_by"] else ""
    _summary(
        summary,
        as_json,
        f"imported study {summary['study']}: {summary['participants']} participant(s), "
        f"{summary['sessions']} session(s); {metrics}{signed}",
    )


def _pair(text: str, what: str, kind=int, count: int = 2) -> tuple:
    try:
        parts = tuple(kind(part) for part in text.replace("x", ",").split(","))
    except ValueError:
        parts = ()
    if len(parts) != count:
        raise click.BadParameter(f"{what} {text!r} needs {count} numbers separated by ',' or 'x'")
    return parts


@main.command()
@click.argument("images", nargs=-1, required=True, type=click.Path(exists=True, dir_okay=False))
@click.option(
    "-o", "--out", required=True, type=click.Path(dir_okay=False), help="Calibration JSON to write."
)
@click.option("--squares", default="7x5", show_default=True, help="ChArUco board squares, COLUMNSxROWS.")
@click.option("--square-mm", default=30.0, show_default=True, type=click.FloatRange(min=1.0))
@click.option("--marker-mm", default=22.0, show_default=True, type=click.FloatRange(min=1.0))
@click.option("--dictionary", default="DICT_4X4_50", show_default=True, help="ArUco dictionary of the board.")
@user_errors
def calibrate(images, out, squares, square_mm, marker_mm, dictionary) -> None:
    """Calibrate a bench camera from photos of a ChArUco board (10-20 views, varied tilt).

    Writes the intrinsic matrix, distortion and the reprojection error (pixels) as
    JSON, for `vascsim import-video --camera`.
    """
    import cv2

    from metrics.bench.camera import BoardSpec, calibrate_charuco
    from metrics.streams import MetricsError

    frames = []
    for path in images:
        image = cv2.imread(path, cv2.IMREAD_GRAYSCALE)
        if image is None:
            raise MetricsError(f"{path} is not an image OpenCV can read")
        frames.append(image)
    board = BoardSpec(_pair(squares, "--squares"), square_mm / 1e3, marker_mm / 1e3, dictionary)
    camera = calibrate_charuco(frames, board)
    camera.save(out)
    click.echo(
        f"calibration: {out} (reprojection error {camera.rms:.3f} px, focal {camera.matrix[0, 0]:.1f} px)"
    )


@main.command("import-video")
@click.argument("video", type=click.Path(exists=True, dir_okay=False))
@click.option("--camera", "camera_file", required=True, type=click.Path(exists=True, dir_okay=False),
              help="Calibration JSON from `vascsim calibrate`.")  # fmt: skip
@click.option("--study", required=True, help="Study to add the session to.")
@click.option("--participant", required=True, help="Participant code (enrolled in the study).")
@click.option("--marker-id", default=7, show_default=True, type=click.IntRange(0, 999))
@click.option(
    "--marker-mm", default=30.0, show_default=True, type=click.FloatRange(min=1.0), help="Marker side."
)
@click.option(
    "--tip-offset-mm", default="0,-60,-10", show_default=True,
    help="Instrument tip in the marker frame (x right, y up, z out of the marker), mm.",
)  # fmt: skip
@click.option("--json", "as_json", is_flag=True, help="Print the session's metrics as JSON.")
@user_errors
def import_video(
    video, camera_file, study, participant, marker_id, marker_mm, tip_offset_mm, as_json
) -> None:
    """Add a bench-model session from video: ArUco tracking of the needle holder.

    The marker's pose (sub-pixel corners, solvePnP) gives the instrument tip in
    every frame; the smoothed path becomes a session of the study with the same
    motion metrics as simulator sessions (no force or tissue metrics).
    """
    from metrics.bench.tracking import ToolMarker
    from sessions.importing import import_bench_video

    offset = tuple(v / 1e3 for v in _pair(tip_offset_mm, "--tip-offset-mm", float, 3))
    marker = ToolMarker(marker_id, marker_mm / 1e3, offset)
    catalog, home = _catalog()
    with _progress(transient=True) as progress:
        task = progress.add_task("tracking", total=None, last="")
        uid, values = import_bench_video(
            catalog, home, video, camera_file, study, participant, marker,
            lambda done: progress.update(task, completed=done, last=f"frame {done}"),
        )  # fmt: skip
    if as_json:
        _json({"session": uid, "metrics": values})
    else:
        click.echo(f"imported bench session {uid} for {participant} in study {study}")


@main.command("import")
@click.argument("kinematics_dir", type=click.Path(exists=True, file_okay=False))
@click.argument("meta_file", type=click.Path(exists=True, dir_okay=False))
@click.option("--study", required=True, help="Study to import into (created if missing).")
@user_errors
def import_jigsaws(kinematics_dir: str, meta_file: str, study: str) -> None:
    """Import a JIGSAWS task (kinematics folder + meta file) as a scored study.

    Surgeons become participants (labels novice/intermediate/expert from the
    self-reported level; GRS totals stored as ratings); trials become sessions
    whose files are the kinematics files, with checksums.
    """
    from sessions.importing import import_jigsaws as run_import

    catalog, _ = _catalog()
    count = run_import(catalog, kinematics_dir, meta_file, study)
    click.echo(f"imported {count} JIGSAWS trial(s) into study {study}")


from sessions import cli_accounts as _cli_accounts  # noqa: E402,F401  (registers `vascsim users`)
