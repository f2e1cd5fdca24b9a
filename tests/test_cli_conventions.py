"""The command line's conventions: ``--version``, ``-v``/``-q`` wired to the package's loggers,
progress bars only when asked, and the one-line error naming the extra an optional part needs."""

from __future__ import annotations

import contextlib
import io
import itertools
import logging
import subprocess
import sys
from importlib.metadata import version
from pathlib import Path

import pytest

import bodyfusion
from bodyfusion.cli import main
from tests.paths import CONFIGS, EXAMPLE_DATA
from tests.test_cli import assert_one_line_user_error, fusion, layout_text

VICON_LEFT = EXAMPLE_DATA / "dual_foot_vicon_hu2025" / "imuMeasLeft.csv"


def fusion_here(*args: str | Path) -> subprocess.CompletedProcess:
    """``fusion ARGS`` in this process (stdout and stderr are not terminals), the package's
    logger left as the CLI found it."""
    out, err = io.StringIO(), io.StringIO()
    argv, log = sys.argv, logging.getLogger("bodyfusion")
    handlers, propagate, level = list(log.handlers), log.propagate, log.level
    code = 0
    try:
        sys.argv = ["fusion", *map(str, args)]
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            main()
    except SystemExit as exit_:
        code = exit_.code if isinstance(exit_.code, int) else 1
    finally:
        sys.argv = argv
        log.handlers[:], log.propagate, log.level = handlers, propagate, level
    return subprocess.CompletedProcess(list(args), code, out.getvalue(), err.getvalue())


@pytest.fixture(scope="module")
def one_foot(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One foot of the Vicon walk, no plots: a run of a second or two."""
    cfg = tmp_path_factory.mktemp("one_foot") / "layout.yaml"
    cfg.write_text(layout_text(VICON_LEFT))
    return cfg


def test_version_prints_the_package_version():
    proc = fusion("--version")
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout == f"bodyfusion {bodyfusion.__version__}\n"
    assert bodyfusion.__version__ == version("bodyfusion")


def test_default_shows_warnings_and_the_summary_but_no_stages_and_no_bar(one_foot, tmp_path):
    proc = fusion_here("run", one_foot, "--out", tmp_path / "out")
    assert proc.returncode == 0, proc.stderr
    assert "samples, navigation" in proc.stdout
    assert "info:" not in proc.stderr and "fusing" not in proc.stderr


def test_verbose_logs_each_stage_and_the_bar_and_very_verbose_debug(one_foot, tmp_path):
    proc = fusion_here("-v", "run", one_foot, "--out", tmp_path / "out")
    assert proc.returncode == 0, proc.stderr
    for stage in ("info: loading", "info: reading the data of foot (foot_ins)", "info: foot: 7201 samples at 60 Hz",
                  "info: fusing 1 system(s)", "info: writing the outputs to"):
        assert stage in proc.stderr, (stage, proc.stderr)
    assert "debug:" not in proc.stderr
    bar = [line for line in proc.stderr.splitlines() if line.startswith("fusing")]
    assert len(bar) == 1 and "120/120 s of data" in bar[0], proc.stderr  # a pipe gets the finished bar once
    proc = fusion_here("-vv", "run", one_foot, "--out", tmp_path / "out", "--overwrite")
    assert proc.returncode == 0 and "debug: fused in" in proc.stderr, proc.stderr


def test_quiet_shows_errors_only(one_foot, tmp_path):
    proc = fusion_here("-q", "run", one_foot, "--out", tmp_path / "out")
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout == "" and proc.stderr == ""
    assert (tmp_path / "out" / "metrics.json").is_file()
    assert_one_line_user_error(fusion_here("-q", "run", tmp_path / "absent.yaml"), "error:", "absent.yaml")


def test_quiet_hides_warnings_the_default_shows(tmp_path):
    truth = tmp_path / "truth.csv"
    truth.write_text("t,x,y,z\n5000,0,0,0\n5100,1,0,0\n")
    cfg = tmp_path / "clocks.yaml"
    cfg.write_text(layout_text(VICON_LEFT) + f"truth: {{path: {truth}, time_column: t, systems: {{foot: [x, y, z]}}}}\n")
    assert "warning: systems.foot.data" in fusion_here("validate", cfg).stderr
    proc = fusion_here("-q", "validate", cfg)
    assert proc.returncode == 0 and proc.stdout == "" and proc.stderr == "", proc


def test_quiet_and_verbose_together_are_refused():
    proc = fusion_here("-q", "-v", "plugins")
    assert proc.returncode == 2 and "-q and -v exclude each other" in proc.stderr


def test_library_logs_its_stages_on_module_loggers_and_draws_no_bar(one_foot, caplog, capsys):
    with caplog.at_level(logging.INFO, logger="bodyfusion"):
        bodyfusion.run(one_foot)
    stages = {(r.name, r.getMessage().split(" ")[0]) for r in caplog.records}
    assert {("bodyfusion.runner.batch", "reading"), ("bodyfusion.runner.batch", "fusing")} <= stages, stages
    assert ("bodyfusion.plugins.foot_ins.system", "foot:") in stages
    assert capsys.readouterr().err == ""


def test_run_progress_callback_is_told_the_seconds_fused(one_foot):
    told: list[tuple[float, float]] = []
    bodyfusion.run(one_foot, progress=lambda done, total: told.append((done, total)))
    assert told and told[-1][0] == told[-1][1] == pytest.approx(120.0, abs=0.1)
    assert all(a[0] <= b[0] for a, b in itertools.pairwise(told))


def test_simulate_progress_callback_counts_the_systems():
    told: list[tuple[float, float]] = []
    bodyfusion.simulate(CONFIGS / "sim_perfect_walk.yaml", progress=lambda done, total: told.append((done, total)))
    assert told[0][0] == 0 and told[-1][0] == told[-1][1] > 0


def test_socp_without_cvxpy_names_the_extra(monkeypatch, tmp_path):
    monkeypatch.setitem(sys.modules, "cvxpy", None)  # as if not installed
    proc = fusion_here("run", CONFIGS / "dual_foot_vicon.yaml", "--set", "fuser.method=socp", "--set",
                       "output.plots=false", "--out", tmp_path / "out")
    assert proc.returncode == 2
    assert_one_line_user_error(
        proc, 'error: fuser.method=socp needs the optional dependency cvxpy: pip install "bodyfusion[socp]"')


def test_dask_executor_without_distributed_names_the_extra(monkeypatch, tmp_path):
    from bodyfusion.base.errors import MissingExtraError
    from bodyfusion.study.executors import run_dask

    monkeypatch.setitem(sys.modules, "distributed", None)
    with pytest.raises(MissingExtraError, match=r'the dask executor needs the optional dependency dask\[distributed\]: '
                                                r'pip install "bodyfusion\[study\]"'):
        run_dask([], 1, None, lambda row: None)
