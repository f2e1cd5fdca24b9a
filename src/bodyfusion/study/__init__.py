"""Studies: layouts × parameter overrides × GNSS outage windows × seeds, on a process pool or Dask.

:func:`run_study` runs a study file into an output folder (CONTRACT.md): ``results.parquet``
(one row per run), ``summary.csv``, PNG plots of the outage errors against the outage
duration and ``study.json``. The modules, in the order a study goes through them:

- :mod:`~bodyfusion.study.spec`: the study file and its model;
- :mod:`~bodyfusion.study.validation`: every layout and override checked before any run;
- :mod:`~bodyfusion.study.grid`: the runs of the grid, their keys (SHA-256 of the resolved config and seed)
  and the tasks that carry them (runs that simulate the same data together);
- :mod:`~bodyfusion.study.worker`: a task's runs → their rows, in a worker process (one simulation per data key);
- :mod:`~bodyfusion.study.executors`: the local process pool and Dask;
- :mod:`~bodyfusion.study.results`: resumable part files, results.parquet, the summary table;
- :mod:`~bodyfusion.study.plots`: the study's plots;
- :mod:`~bodyfusion.study.runner`: :func:`run_study`, all of the above in turn.
"""

from bodyfusion.study.executors import Executor
from bodyfusion.study.grid import RunSpec, expand_grid, plan_tasks
from bodyfusion.study.results import HEAD_COLUMNS, ResultStore, is_timing_column, summarise
from bodyfusion.study.runner import StudyReport, run_study
from bodyfusion.study.spec import StudySpec
from bodyfusion.study.validation import load_study
from bodyfusion.study.worker import execute_run, execute_runs

__all__ = [
    "Executor",
    "HEAD_COLUMNS",
    "ResultStore",
    "RunSpec",
    "StudyReport",
    "StudySpec",
    "execute_run",
    "execute_runs",
    "expand_grid",
    "is_timing_column",
    "load_study",
    "plan_tasks",
    "run_study",
    "summarise",
]
