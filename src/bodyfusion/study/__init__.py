"""Studies: layouts × parameter overrides × GNSS outage windows × seeds, on a process pool or Dask.

:func:`run_study` runs a study file into an output folder (CONTRACT.md): ``results.parquet``
(one row per run), ``summary.csv``, PNG plots of the outage errors against the outage
duration and ``study.json``. The modules, in the order a study goes through them:

- :mod:`~bodyfusion.study.spec`: the study file and its model;
- :mod:`~bodyfusion.study.validation`: every layout and override checked before any run;
- :mod:`~bodyfusion.study.grid`: the runs of the grid and their keys (SHA-256 of the resolved config and seed);
- :mod:`~bodyfusion.study.worker`: one run → one row, in a worker process;
- :mod:`~bodyfusion.study.executors`: the local process pool and Dask;
- :mod:`~bodyfusion.study.results`: resumable part files, results.parquet, the summary table;
- :mod:`~bodyfusion.study.plots`: the study's plots;
- :mod:`~bodyfusion.study.runner`: :func:`run_study`, all of the above in turn.
"""

from bodyfusion.study.executors import Executor
from bodyfusion.study.grid import RunSpec, expand_grid
from bodyfusion.study.results import HEAD_COLUMNS, ResultStore, is_timing_column, summarise
from bodyfusion.study.runner import StudyReport, run_study
from bodyfusion.study.spec import StudySpec
from bodyfusion.study.validation import load_study
from bodyfusion.study.worker import execute_run

__all__ = [
    "Executor",
    "HEAD_COLUMNS",
    "ResultStore",
    "RunSpec",
    "StudyReport",
    "StudySpec",
    "execute_run",
    "expand_grid",
    "is_timing_column",
    "load_study",
    "run_study",
    "summarise",
]
