"""`vascsim benchmark jigsaws DIR`: the public JIGSAWS skill benchmark on vascsim's metrics."""

from __future__ import annotations

from pathlib import Path

import click

from sessions.catalog import CatalogError
from sessions.cli.base import print_frame, print_json, progress_bar, user_errors


@click.group()
def benchmark() -> None:
    """Public skill benchmarks run on vascsim's interpretable metrics."""


def _meta_file(folder: Path) -> Path:
    found = sorted(folder.glob("meta_file_*.txt"))
    if len(found) != 1:
        raise CatalogError(
            f"{folder}: expected one meta_file_<Task>.txt beside kinematics/ (found {len(found)}); "
            "name it with --meta"
        )
    return found[0]


@benchmark.command("jigsaws")
@click.argument("task_dir", type=click.Path(path_type=Path))
@click.option("--meta", "meta", type=click.Path(path_type=Path), default=None, help="The task's meta file.")
@click.option(
    "--setup",
    type=click.Path(path_type=Path),
    default=None,
    help="Folder holding Experimental_setup (default: beside or inside TASK_DIR); without it the folds "
    "are built from the trial names.",
)
@click.option(
    "--draws", type=click.IntRange(0, 100_000), default=2000, show_default=True, help="Bootstrap draws."
)
@click.option("--json", "as_json", is_flag=True, help="Print as JSON.")
@user_errors
def jigsaws_benchmark(
    task_dir: Path, meta: Path | None, setup: Path | None, draws: int, as_json: bool
) -> None:
    """Run LOSO (5 folds) and LOUO (8 folds) on one JIGSAWS task folder (kinematics/AllGestures and its
    meta file): novice/intermediate/expert and novice-vs-expert classification and GRS regression on
    vascsim's metrics, each fold standardised and fitted on its training trials only."""
    from metrics.datasets import jigsaws
    from metrics.datasets.jigsaws_benchmark import run_benchmark

    if not task_dir.is_dir():
        raise CatalogError(f"no JIGSAWS task folder {str(task_dir)!r}")
    meta = meta or _meta_file(task_dir)
    trials = jigsaws.load(task_dir, meta)
    if setup is None:
        for candidate in (task_dir.parent, task_dir):
            if (candidate / "Experimental_setup").is_dir():
                setup = candidate
                break
    from metrics import compute_session_metrics

    with progress_bar(transient=as_json) as progress:
        task = progress.add_task("metrics of the trials", total=len(trials), last="")
        table = compute_session_metrics(trials, progress=lambda n: progress.update(task, advance=n))
    result = run_benchmark(trials, setup, draws=draws, table=table)
    if as_json:
        print_json(
            {
                "task": result.task,
                "trials": result.trials,
                "surgeons": result.surgeons,
                "metrics": result.metrics,
                "protocols": {
                    name: {
                        "folds": r.folds,
                        "folds_from": r.source,
                        "accuracy_3": r.accuracy_3,
                        "accuracy_3_ci": list(r.accuracy_3_ci),
                        "macro_f1_3": r.macro_f1_3,
                        "macro_f1_3_ci": list(r.macro_f1_3_ci),
                        "confusion_3": r.confusion_3.to_dict(),
                        "accuracy_2": r.accuracy_2,
                        "accuracy_2_ci": list(r.accuracy_2_ci),
                        "macro_f1_2": r.macro_f1_2,
                        "grs_rho": r.grs_rho,
                        "grs_rho_ci": list(r.grs_rho_ci),
                        "weights": r.weights.to_dict(),
                    }
                    for name, r in result.protocols.items()
                },
                "published": result.published().to_dict(orient="records"),
                "notes": result.notes,
            }
        )
        return
    print_frame(
        result.table(),
        f"JIGSAWS {result.task}: {result.trials} trials, {result.surgeons} surgeons, "
        f"{len(result.metrics)} metrics",
        caption="95 % intervals: bootstrap resampling surgeons.",
    )
    for name, r in result.protocols.items():
        print_frame(r.confusion_3.reset_index(names=""), f"{name}, 3-class confusion (trials)")
        weights = r.weights.head(5).reset_index()
        weights.columns = ["metric", "mean |coefficient|"]
        print_frame(weights, f"{name}: the metrics carrying the most weight (standardised)")
    print_frame(result.published(), "Published figures (the authors' own; for orientation)")
    for note in result.notes:
        click.echo(click.wrap_text(note, width=78, initial_indent="- ", subsequent_indent="  "))
