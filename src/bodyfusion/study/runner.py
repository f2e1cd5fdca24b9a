"""Running a study end to end: :func:`run_study`.

Validate the study file, expand its grid, skip the runs already saved in the output
folder, put the others into tasks (:func:`bodyfusion.study.grid.plan_tasks`) and execute them
(:mod:`bodyfusion.study.executors`) with a progress bar when asked,
save the finished rows in batches, then compact them into ``results.parquet`` (and
its per-system view ``results_by_system.parquet``) and write ``summary.csv``, the plots and
``study.json`` (counts and throughput).
"""

from __future__ import annotations

import dataclasses
import json
import logging
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

from bodyfusion.base.errors import ConfigError
from bodyfusion.base.progress import ProgressCallback
from bodyfusion.study.executors import Executor, run_dask, run_local
from bodyfusion.study.grid import expand_grid, plan_tasks
from bodyfusion.study.plots import write_plots
from bodyfusion.study.results import SUMMARY_FILE, ResultStore, summarise, write_summary
from bodyfusion.study.validation import load_study

log = logging.getLogger(__name__)


@dataclass
class StudyReport:
    """What a study did: counts, wall time (s), throughput of the runs executed (runs/s), the
    tasks they went in, files."""

    out_dir: Path
    total: int
    done: int = 0
    failed: int = 0
    skipped: int = 0
    wall_s: float = 0.0
    executor: str = "local"
    workers: int = 1
    tasks: int = 0
    files: list[Path] = field(default_factory=list)

    @property
    def runs_per_s(self) -> float:
        executed = self.done + self.failed
        return executed / self.wall_s if self.wall_s > 0 else 0.0


def _progress(shown: bool) -> Progress:
    """The study's bar on stderr (runs finished of all, done, failed, skipped, ETA); a no-op unless
    ``shown``."""
    console = Console(stderr=True)
    return Progress(TextColumn("[bold]{task.description}"), BarColumn(), MofNCompleteColumn(),
                    TextColumn("{task.fields[done]} done · {task.fields[failed]} failed · {task.fields[skipped]} "
                               "skipped"), TimeElapsedColumn(), TextColumn("ETA"), TimeRemainingColumn(),
                    console=console, disable=not shown, transient=False)


def run_study(study_path: str | Path, out_dir: str | Path, executor: Executor | str = Executor.local,
              workers: int | None = None, scheduler: str | None = None, batch_rows: int = 16,
              flush_s: float = 5.0, progress: bool | ProgressCallback = False,
              runs_per_task: int | None = None) -> StudyReport:
    """Validate the study, run every run not yet saved in ``out_dir``, compact, summarise, plot.

    ``workers``: processes (local pool or LocalCluster; default all cores); ``scheduler``: a
    Dask scheduler address (``tcp://host:port``; only with ``executor='dask'``). Finished rows
    are saved every ``batch_rows`` rows or ``flush_s`` seconds, whichever comes first.
    ``progress``: ``True`` shows a bar on stderr, a callable is told (runs finished, runs in all)
    as each run finishes (local pool or Dask alike; a task's runs arrive together).
    ``runs_per_task``: runs a worker takes at once (default: the study file's, else up to
    :data:`~bodyfusion.study.grid.DEFAULT_RUNS_PER_TASK`, fewer for two tasks per worker).
    """
    executor = Executor(executor)
    workers = workers if workers is not None else os.cpu_count() or 1
    if workers < 1:
        raise ConfigError("--workers", f"must be >= 1, got {workers}")
    if scheduler is not None and executor is not Executor.dask:
        raise ConfigError("--scheduler", "only with --executor dask")
    if runs_per_task is not None and runs_per_task < 1:
        raise ConfigError("runs_per_task", f"must be >= 1, got {runs_per_task}")
    study = load_study(study_path)
    grid = expand_grid(study)
    order = {s.key: i for i, s in enumerate(grid)}
    store = ResultStore(Path(out_dir))
    saved = store.keys()
    todo = [s for s in grid if s.key not in saved]
    if study.spec.run_outputs:
        runs_dir = Path(out_dir).resolve() / "runs"
        todo = [dataclasses.replace(s, run_dir=str(runs_dir / s.key)) for s in todo]
    tasks = plan_tasks(todo, runs_per_task or study.spec.runs_per_task, workers)
    report = StudyReport(Path(out_dir), len(grid), skipped=len(grid) - len(todo), executor=executor.value,
                         workers=workers, tasks=len(tasks))
    pending: list[dict[str, Any]] = []
    last_flush = time.monotonic()
    log.info("%s: %d runs, %d saved already, %d to run in %d tasks (%s, %d workers)", study.name, len(grid),
             report.skipped, len(todo), len(tasks), executor.value, workers)
    told = progress if callable(progress) else None
    t0 = time.perf_counter()
    with _progress(progress is True) as bar:
        task = bar.add_task(study.name, total=len(grid), completed=report.skipped, done=0, failed=0,
                                 skipped=report.skipped)

        def on_row(row: dict[str, Any]) -> None:
            nonlocal last_flush
            pending.append(row)
            if row["status"] == "ok":
                report.done += 1
            else:
                report.failed += 1
            bar.update(task, advance=1, done=report.done, failed=report.failed)
            if told is not None:
                told(report.skipped + report.done + report.failed, report.total)
            if len(pending) >= batch_rows or time.monotonic() - last_flush >= flush_s:
                store.append(pending)
                pending.clear()
                last_flush = time.monotonic()

        try:
            if tasks and executor is Executor.local:
                run_local(tasks, min(workers, len(tasks)), on_row)
            elif tasks:
                run_dask(tasks, workers, scheduler, on_row)
        finally:
            store.append(pending)  # also when interrupted: nothing finished is lost
    report.wall_s = time.perf_counter() - t0
    table = store.compact(order)
    in_grid = [r for r in table.to_pylist() if r["run_key"] in order]
    params = [f"param.{p}" for p in study.spec.parameters]
    out = Path(out_dir)
    write_summary(out / SUMMARY_FILE, summarise(in_grid, params))
    report.files = [store.results_path, store.by_system_path, out / SUMMARY_FILE,
                    *write_plots(out, in_grid, params, study.spec.figures)]
    (out / "study.json").write_text(json.dumps({
        "study": str(study_path), "name": study.name, "runs": report.total, "done": report.done,
        "failed": report.failed, "skipped": report.skipped, "executor": report.executor, "workers": workers,
        "tasks": report.tasks, "wall_s": report.wall_s, "runs_per_s": report.runs_per_s}, indent=2) + "\n")
    return report
