"""The tutorial notebook (docs/tutorial_vicon.ipynb) runs: every code cell in order, in one
namespace, in this process, as a kernel would (no Jupyter needed), with its files in a temporary
folder; then a few of its results are checked."""

from __future__ import annotations

import ast
import json

import matplotlib
import pytest

from tests.paths import ROOT

NOTEBOOK = ROOT / "docs" / "tutorial_vicon.ipynb"


def code_cells() -> list[str]:
    cells = json.loads(NOTEBOOK.read_text(encoding="utf-8"))["cells"]
    return ["".join(cell["source"]) for cell in cells if cell["cell_type"] == "code"]


def run_cell(source: str, namespace: dict, name: str) -> object:
    """Exec one cell; like a kernel, evaluate a final expression and return its value."""
    tree = ast.parse(source, name)
    last = tree.body.pop() if tree.body and isinstance(tree.body[-1], ast.Expr) else None
    exec(compile(tree, name, "exec"), namespace)  # noqa: S102 - the repository's own notebook
    if last is None:
        return None
    return eval(compile(ast.Expression(last.value), name, "eval"), namespace)  # noqa: S307


def test_the_notebook_is_stored_without_outputs():
    cells = json.loads(NOTEBOOK.read_text(encoding="utf-8"))["cells"]
    assert [c for c in cells if c["cell_type"] == "code" and (c["outputs"] or c["execution_count"])] == []


@pytest.mark.slow
def test_the_tutorial_notebook_runs_and_compares_the_methods(tmp_path, monkeypatch):
    matplotlib.use("Agg")
    monkeypatch.setenv("BODYFUSION_TUTORIAL_OUT", str(tmp_path))
    monkeypatch.chdir(NOTEBOOK.parent)  # where Jupyter starts the notebook
    namespace: dict = {"__name__": "__main__"}
    shown = [run_cell(source, namespace, f"{NOTEBOOK.name}, code cell {i}")
             for i, source in enumerate(code_cells(), 1)]
    assert shown[-1].index.tolist() == ["left_foot", "right_foot"]  # the last cell's summary table

    assert set(namespace["rmse"]) == {"left_foot", "right_foot"}
    assert all(0.02 < value < 0.3 for value in namespace["rmse"].values())  # m: ~0.11 and ~0.08

    comparison = namespace["comparison"]
    assert len(comparison) == 8 and set(comparison.system) == {"left_foot", "right_foot"}
    mean_rmse = comparison.groupby("method").rmse_m.mean()
    for method in ("forward", "RTS"):  # the constraint helps both feet, filtered or smoothed
        assert mean_rmse[f"{method}, constrained"] < mean_rmse[f"{method}, independent"]
    assert mean_rmse.between(0.02, 0.4).all()

    events = namespace["events"]
    assert 0.0 < (events.active | events.tail_truncated).mean() <= 1.0
    assert (events.limit_m > 0.6).all() and (events.limit_m <= 1.1).all()  # the body's, following the strides
    active = events[events.active]
    assert (active.distance_after_m <= active.limit_m + 1e-6).all()

    frame = namespace["frame"]
    assert {"system", "t", "east_m", "north_m", "up_m", "sd_east_m", "sd_north_m", "v_east_mps",
            "heading_deg"} <= set(frame.columns)
    assert frame.groupby("system").t.max().between(100.0, 130.0).all()  # the 120 s walk

    assert len(namespace["fig"].axes) >= 2
    for name in ("methods.pdf", "methods.png", "error_cdf.png", "rts_constrained_frame.parquet",
                 "trajectories.parquet", "tum/left_foot.txt", "tum/right_foot_truth.txt"):
        assert (tmp_path / name).stat().st_size > 0, name
    assert set(namespace["back"]) == {"left_foot", "right_foot"}
