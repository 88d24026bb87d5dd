"""`vascsim sessions list|show|delete`: recorded sessions."""

from __future__ import annotations

import shlex
from datetime import UTC
from pathlib import Path

import click
import pandas as pd

from metrics.units import shown
from sessions.cli.base import (
    open_store,
    print_frame,
    print_json,
    user_errors,
)
from sessions.status import SCORABLE, SESSION_STATUSES


@click.group()
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
    from sessions.scoring.analysis import metric_versions

    store, _ = open_store()
    catalog = store.catalog
    found = store.sessions(study, task, status)
    versions = metric_versions(catalog, [r.id for r in found])
    columns = ("session", "study", "participant", "task", "trial", "phase", "device", "status")
    rows = [
        dict(
            zip(
                columns,
                (r.uid, r.study, r.participant, r.task, r.trial, r.phase, r.device, r.status),
                strict=True,
            ),
            started=r.started_at.replace(tzinfo=UTC).isoformat(),  # the catalog keeps UTC
            metrics=versions[r.id],
        )
        for r in found
    ]
    if as_json:
        print_json(rows)
        return
    frame = pd.DataFrame(rows, columns=[*columns, "started", "metrics"])
    frame = frame.rename(columns={"participant": "who"})
    days = {f"{r.started_at:%Y-%m-%d}" for r in found}
    one_day = len(days) == 1  # then the day is said once and each row keeps its time
    frame["started"] = [
        f"{r.started_at:%H:%M}" if one_day else f"{r.started_at:%Y-%m-%d %H:%M}" for r in found
    ]
    frame = frame.rename(columns={"started": "time (UTC)" if one_day else "started (UTC)"})
    # a column with one value in every row is said once, in the caption, so the rest fit 80 columns
    same = [
        c for c in ("study", "phase", "device", "status", "metrics") if len(frame) and frame[c].nunique() == 1
    ]
    said = [f"{c} {frame[c].iloc[0]}" for c in same] + ([f"on {days.pop()} (UTC)"] if one_day else [])
    caption = _lines(["all sessions:", *[f"{item};" for item in said[:-1]], *said[-1:]]) if said else None
    print_frame(frame.drop(columns=same), "Sessions", caption)
    stale = [r for r in rows if r["metrics"].startswith("stale")]
    if stale:
        studies = sorted({r["study"] for r in stale})
        click.echo(
            f"{len(stale)} session(s) scored with an older metric registry; rescore: "
            + "; ".join(f"vascsim score --study {shlex.quote(name)}" for name in studies)
        )


@sessions.command("show")
@click.argument("uid")
@click.option("--json", "as_json", is_flag=True, help="Print as JSON.")
@user_errors
def sessions_show(uid: str, as_json: bool) -> None:
    """Show one session: who, what, when, files with checksums, metrics."""

    store, _ = open_store()
    catalog = store.catalog
    facts = store.session_facts(uid)
    row = facts.session
    data = {
        "session": row.uid,
        "study": row.study,
        "participant": row.participant,
        "synthetic": facts.synthetic,
        "task": row.task,
        "device": row.device,
        "clock": facts.clock,
        "trial": row.trial,
        "phase": row.phase,
        "status": row.status,
        "started": row.started_at.isoformat(),
        "ended": row.ended_at.isoformat() if row.ended_at else None,
        "directory": facts.directory,
        "error": facts.error,
        "files": [{"name": f.name, "sha256": f.sha256, "bytes": f.bytes} for f in facts.files],
    }
    from metrics.reading.feedback import metric_groups, session_feedback
    from sessions.scoring.review import review_session, session_against_experts, session_stitches

    rows = session_against_experts(catalog, uid)
    data["metrics"] = {r["metric"]: r["value"] for r in rows}
    data["versus_experts"] = {r["metric"]: r["versus_experts"] for r in rows}
    data["stitches"] = session_stitches(catalog, uid)
    if row.status in SCORABLE:  # judged as the station judges it: the marks it misses lead
        review = review_session(catalog, uid, rows)  # the rows just read, not read again
        data.update(verdict=review.verdict, standard=review.standard)
        data.update(work_on=review.work_on, strengths=review.strengths)
    else:
        data.update(session_feedback(rows))
    if as_json:
        print_json(data)
        return
    for key, value in data.items():
        if key == "files":
            for f in value:
                click.echo(f"  file {f['name']:18s} {f['bytes']:>10d} B")
                click.echo(f"    sha256 {f['sha256']}")  # whole, on a line of its own within 80 columns
        elif key == "metrics":
            click.echo("metrics      (against the experts' quartiles on this task, by direction)")
            for group in metric_groups(rows):
                click.echo(f"  {group['title'].lower()}")
                for r in group["metrics"]:
                    versus = r["versus_experts"] or ""
                    click.echo(f"    {r['metric']:26s} {shown(r['value'], r['unit']):>14s}  {versus}")
        elif key == "versus_experts":
            continue
        elif key == "work_on":
            click.echo("work on      (the pass marks missed, then safety, quality, efficiency)")
            for item in value or [{"kind": "", "line": "nothing worse than the experts' middle half"}]:
                text = f"{item['kind']}: {item['line']}" if item["kind"] else item["line"]
                click.echo(click.wrap_text(text, 78, initial_indent="  ", subsequent_indent="    "))
        elif key == "strengths":
            click.echo("strengths    (better than the experts' middle half, or level with them)")
            for item in value or [{"line": "none yet"}]:
                click.echo(click.wrap_text(item["line"], 78, initial_indent="  ", subsequent_indent="    "))
        elif key == "stitches":
            _show_stitches(value)
        elif key == "standard":
            click.echo(click.wrap_text(f"{key:12s} {value}", 80, subsequent_indent=" " * 13))
        else:
            click.echo(f"{key:12s} {value}")


def _lines(items: list[str], width: int = 80) -> str:
    """``items`` joined by spaces into lines of at most ``width`` characters, never breaking one."""
    lines = [""]
    for item in items:
        joined = f"{lines[-1]} {item}".strip()
        if len(joined) <= width or not lines[-1]:
            lines[-1] = joined
        else:
            lines.append(item)
    return "\n".join(lines)


def final_task_line(final, report) -> str:
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
    click.echo("  stitch  off its track (mm)  swept (mm^2)  wound-edge stress (kPa)")

    def scaled(value, factor: float, digits: int) -> str:
        return "-" if value is None else f"{factor * value:.{digits}f}"

    for s in stitches:
        click.echo(
            f"  {s['stitch']:>6d}  {scaled(s.get('track_offset'), 1e3, 2):>18s}  "
            f"{scaled(s.get('swept_area'), 1e6, 1):>12s}  {scaled(s.get('wound_edge_stress'), 1e-3, 0):>23s}"
        )


@sessions.command("delete")
@click.argument("uid")
@click.option("--yes", is_flag=True, help="Do not ask for confirmation.")
@user_errors
def sessions_delete(uid: str, yes: bool) -> None:
    """Delete a session's catalog rows and its stream files."""
    import shutil

    store, _ = open_store()
    store.session_facts(uid)  # an unknown session is refused before asking
    if not yes:
        click.confirm(f"delete session {uid} and its files?", abort=True)
    directory = store.delete_session(uid)
    if directory and is_session_dir(directory):
        shutil.rmtree(directory, ignore_errors=True)
    click.echo(f"session {uid} deleted")


def is_session_dir(directory: str) -> bool:

    from recorder.layout import is_session_directory

    return is_session_directory(Path(directory))
