"""Where a study's runs execute: a local process pool or a Dask distributed cluster.

Runs travel in tasks (:func:`bodyfusion.study.grid.plan_tasks`: a few runs each, those that
share a simulation together), each executed by :func:`bodyfusion.study.worker.execute_runs`
in a worker that stays up for the whole study (its imports and compiled kernels are loaded
once). ``local``: a process pool of spawned workers. ``dask``: a Dask distributed ``LocalCluster``
(one process per worker, one thread each) or an existing cluster's scheduler, whose
workers must have this package installed. Workers run single-threaded BLAS in both, so a
run gives the same bits wherever it runs; only the timing columns
(:func:`bodyfusion.study.results.is_timing_column`) differ. Each worker loads the compiled
kernels from Numba's on-disk cache, which writes each entry to a temporary file and
renames it, so workers compiling at once do not corrupt it. Each finished row is handed
to ``on_row`` as its task returns. Workers never outlive the study: the pool's end with their
parent (:func:`exit_with_parent`); Dask's nannies and workers end when their scheduler's
process does (Dask's own parent watch).
"""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import enum
import logging
import multiprocessing
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterator
from concurrent.futures import ProcessPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool
from typing import Any

from bodyfusion.base.errors import FusionError
from bodyfusion.base.extras import import_optional
from bodyfusion.study.grid import RunSpec
from bodyfusion.study.worker import error_text, execute_runs

log = logging.getLogger(__name__)


class Executor(str, enum.Enum):
    """Where runs execute: a local process pool or a Dask distributed cluster."""

    local = "local"
    dask = "dask"


_SINGLE_THREAD_ENV = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
"""Worker processes run single-threaded BLAS, as Dask's nanny starts its workers, so both
executors compute the same bits."""


@contextlib.contextmanager
def _worker_environment() -> Iterator[None]:
    saved = {k: os.environ.get(k) for k in _SINGLE_THREAD_ENV}
    os.environ.update(_SINGLE_THREAD_ENV)
    try:
        yield
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


PARENT_POLL_S = 0.5
"""How often a pool worker checks that the study that started it is still alive, s."""


def exit_with_parent(parent_pid: int) -> None:
    """Pool worker initialiser: the worker ends when the study process that started it dies
    (even by SIGKILL, which runs no clean-up), instead of living on as an orphan. On Linux the
    kernel sends SIGKILL at once (``prctl(PR_SET_PDEATHSIG)``); everywhere a daemon thread also
    checks the parent every :data:`PARENT_POLL_S` seconds."""
    if sys.platform.startswith("linux"):
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
        libc.prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
    if os.getppid() != parent_pid:  # the parent died before the signal was armed
        os._exit(1)

    def watch() -> None:
        while os.getppid() == parent_pid:
            time.sleep(PARENT_POLL_S)
        os._exit(1)

    threading.Thread(target=watch, name="exit-with-parent", daemon=True).start()


@contextlib.contextmanager
def worker_pool(workers: int) -> Iterator[ProcessPoolExecutor]:
    """A pool of ``workers`` spawned processes that run single-threaded BLAS and end with this
    one (:func:`exit_with_parent`); spawned as the first jobs are submitted, inside the block."""
    pool = ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn"),
                               initializer=exit_with_parent, initargs=(os.getpid(),))
    try:
        with _worker_environment():
            yield pool
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


def run_local(tasks: list[list[RunSpec]], workers: int, on_row: Callable[[dict[str, Any]], None]) -> None:
    """Execute ``tasks`` on a :func:`worker_pool` of ``workers``; a dead worker stops the study
    with a FusionError (the rows already handed over are kept; the runs of its task are run
    again on resume)."""
    try:
        with worker_pool(workers) as pool:
            for fut in as_completed([pool.submit(execute_runs, task) for task in tasks]):
                for row in fut.result():
                    on_row(row)
    except BrokenProcessPool:
        message = "a worker process died; the finished runs are saved: run the study again to resume"
        raise FusionError(message) from None


def run_dask(tasks: list[list[RunSpec]], workers: int, scheduler: str | None,
             on_row: Callable[[dict[str, Any]], None]) -> None:
    """Execute ``tasks`` on a LocalCluster of ``workers`` processes, or on the cluster at
    ``scheduler``; the runs of a task whose worker died are run again one per task, and a run
    whose worker died again becomes a failed row."""
    # late: Dask/distributed are heavy (~0.4 s to import), only this executor needs them, an optional extra
    dask = import_optional("dask", "study", "the dask executor", "dask[distributed]")
    distributed = import_optional("distributed", "study", "the dask executor", "dask[distributed]")
    Client, LocalCluster, dask_as_completed = distributed.Client, distributed.LocalCluster, distributed.as_completed

    with contextlib.ExitStack() as stack:
        if scheduler is None:
            # the same worker environment as the local pool: Dask's default also sets
            # MALLOC_TRIM_THRESHOLD_=65536, which makes these runs ~30 % slower
            stack.enter_context(dask.config.set({"distributed.nanny.pre-spawn-environ": _SINGLE_THREAD_ENV}))
            cluster = stack.enter_context(LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                                       dashboard_address=None, silence_logs=logging.ERROR))
            client = stack.enter_context(Client(cluster))
        else:
            try:
                client = stack.enter_context(Client(scheduler, timeout="30s"))
            except (OSError, TimeoutError) as err:
                raise FusionError(f"--scheduler {scheduler}: cannot connect: {err}") from None
        # a task whose worker died is split into runs of their own, so that only a run that
        # kills its worker again is recorded as failed
        futures = client.map(execute_runs, tasks, key=[f"fusion-runs-{task[0].key}-{len(task)}" for task in tasks])
        by_key = {f.key: task for f, task in zip(futures, tasks)}
        pending = dask_as_completed(futures)
        for fut in pending:
            task = by_key.pop(fut.key)
            if fut.status == "finished":
                for row in fut.result():
                    on_row(row)
            elif len(task) > 1:
                log.warning("a worker died running a task of %d runs (%s): running them one per task", len(task),
                            error_text(fut.exception()))
                for spec in task:
                    single = client.submit(execute_runs, [spec], key=f"fusion-run-{spec.key}")
                    by_key[single.key] = [spec]
                    pending.add(single)
            else:  # the worker itself died running it (e.g. out of memory)
                row = task[0].head()
                row.update(status="failed", error=error_text(fut.exception()))
                on_row(row)
            fut.release()
