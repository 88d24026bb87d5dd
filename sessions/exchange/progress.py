"""Each participant's progress and status in one table: what a training office keeps in a
spreadsheet (MScore users get it as Excel). One function for the CLI and the dashboard.

Columns name their unit and direction ("entry_to_target, latest (mm, lower is better)"); values are
in the units a surgeon reads (metrics.units); a trainee's status is said in words.
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from metrics.session.registry import REGISTRY
from metrics.study.analysis import StudyAnalysis
from metrics.units import display_unit, in_display_units
from sessions.catalog import Catalog, CatalogError
from sessions.catalog.lookups import participant_activity
from sessions.scoring.analysis import analyse_catalog_study


def _header(metric: str, what: str) -> str:
    spec = REGISTRY[metric]
    unit = display_unit(spec.unit)
    return f"{metric}, {what} ({unit + ', ' if unit else ''}{spec.better} is better)"


def _status(trainee: pd.Series | None, group: str, skilled: str) -> str:
    if group == skilled:
        return "sets the benchmark"
    if trainee is None:
        return "no scored practice yet"
    if bool(trainee["proficient"]):
        text = f"proficient at trial {int(trainee['trials_to_proficiency'])}"
    else:
        text = f"not yet proficient after {int(trainee['practice_sessions'])} practice sessions"
    kept = trainee.get("retention_passed")
    if kept is not None and not pd.isna(kept):
        text += "; retention " + ("held" if bool(kept) else "worse than the benchmark")
    return text


def progress_table(catalog: Catalog, study: str, analysis: StudyAnalysis | None = None) -> pd.DataFrame:
    """One row per participant of ``study``: group, sessions, first and last session dates, passes,
    status, and for each benchmarked metric the latest value beside the benchmark. ``analysis``:
    the study's declared analysis when the caller has it already."""
    if analysis is None:
        analysis, _ = analyse_catalog_study(catalog, study)
    with catalog.session() as orm:
        found = catalog.study(orm, study)
        rows = participant_activity(orm, found.id)
    if not rows:
        raise CatalogError(f"study {study!r} has no participants")
    table, passed = analysis.sessions, analysis.proficiency["passed"]
    trainees = analysis.trainees.set_index("participant_id") if not analysis.trainees.empty else None
    benchmarks = analysis.benchmarks.set_index("metric")
    skilled = analysis.settings.skilled_group
    out = []
    for code, group, count, first, last in rows:
        mine = table[table["participant_id"] == code]
        record = {
            "participant": code,
            "group": group,
            "sessions": int(count),
            "first session (UTC)": first.strftime("%Y-%m-%d %H:%M") if first else "",
            "latest session (UTC)": last.strftime("%Y-%m-%d %H:%M") if last else "",
            f"scored sessions of {analysis.settings.task or 'the task'}": len(mine),
            "sessions passed": int(passed.loc[mine.index].sum()) if len(mine) else 0,
            "latest passed": ("yes" if bool(passed.loc[mine.index[-1]]) else "no") if len(mine) else "",
            "status": _status(
                trainees.loc[code] if trainees is not None and code in trainees.index else None,
                group,
                skilled,
            ),
        }
        for metric in benchmarks.index:
            unit = REGISTRY[metric].unit
            latest = float(mine[metric].iloc[-1]) if len(mine) else None
            record[_header(metric, "latest")] = in_display_units(latest, unit)
            record[_header(metric, "benchmark")] = in_display_units(
                float(benchmarks.at[metric, "benchmark"]), unit
            )
        out.append(record)
    return pd.DataFrame(out)


def write_progress(table: pd.DataFrame, path: Path, study: str) -> Path:
    """``path`` by its suffix: .csv (UTF-8) or .xlsx (one sheet named after the study, header frozen)."""
    suffix = path.suffix.lower()
    if suffix == ".csv":
        table.to_csv(path, index=False, float_format="%.4g")
    elif suffix == ".xlsx":
        with pd.ExcelWriter(path, engine="openpyxl") as writer:
            sheet = study[:31] or "progress"
            table.round(4).to_excel(writer, sheet_name=sheet, index=False, freeze_panes=(1, 1))
            for column in writer.sheets[sheet].columns:
                width = max(len(str(cell.value or "")) for cell in column)
                writer.sheets[sheet].column_dimensions[column[0].column_letter].width = min(
                    max(width, 8) + 2, 48
                )
    else:
        raise CatalogError(f"progress file {path}: use .csv or .xlsx")
    return path
