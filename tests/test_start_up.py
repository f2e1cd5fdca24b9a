"""What ``fusion run`` imports: the main command starts without the libraries only some runs
need (scipy.stats and scipy.signal take over a second to import, pandas 0.3 s, osqp 50 ms), and the
trajectory files are written without pandas (``pa.array`` would import it); what it compiles: one
signature per kernel, and nothing ahead once its kernels are loaded."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest

NOT_AT_START = ("scipy.stats", "scipy.signal", "scipy.ndimage", "pandas", "matplotlib", "plotly", "osqp")


def _modules_after(code: str) -> set[str]:
    """The heavy modules a fresh interpreter has imported after running ``code``."""
    probe = f"{code}\nimport sys\nprint(' '.join(m for m in {NOT_AT_START!r} if m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True)
    return set(out.stdout.split())


def test_the_run_imports_no_library_it_does_not_use():
    loaded = _modules_after(
        "import bodyfusion.cli, bodyfusion.runner.batch, bodyfusion.outputs.write, bodyfusion.api\n"
        "from bodyfusion.core.registry import get_registry\n"
        "get_registry()  # every installed plugin imported\n"
        "from bodyfusion.evaluation.consistency import chi2_band\n"
        "from bodyfusion.nav.measurements import chi2_gate\n"
        "chi2_band(2), chi2_gate(0.99, 3)")
    assert not loaded


def test_trajectory_files_are_written_without_pandas(tmp_path):
    loaded = _modules_after(
        "import numpy as np\n"
        "from pathlib import Path\n"
        "from bodyfusion.base.types import NavigationFrame, Trajectory\n"
        "from bodyfusion.outputs.trajectories import write_trajectories_parquet, write_tum\n"
        "t = np.arange(5.0)\n"
        "tr = {'a': Trajectory(t, np.ones((5, 3)), np.ones((5, 3)), np.zeros(5)),\n"
        "      'b': Trajectory(t, np.ones((5, 3)), np.ones((5, 3)))}\n"
        f"out = Path({str(tmp_path)!r})\n"
        "write_trajectories_parquet(out / 'x.parquet', tr, config_sha256='0', frame=NavigationFrame())\n"
        "write_tum(out / 'tum', tr, {}, 1)")
    assert not loaded
    assert (tmp_path / "x.parquet").is_file()


def test_tables_are_read_without_pandas(tmp_path):
    """Arrow's CSV reader path (:func:`bodyfusion.io.arrow_tables.read_clean_table`), labels and an
    allowed empty cell included: ``to_numpy`` would import pandas."""
    (tmp_path / "truth.csv").write_text("system,t,x\nleft,0,1.5\nright,1,\n")
    loaded = _modules_after(
        "from bodyfusion.io.tables import read_labelled_table\n"
        f"arrays, _, (codes, names) = read_labelled_table({str(tmp_path / 'truth.csv')!r}, ['t', 'x'], 'system',"
        " allow_missing=('x',))\n"
        "assert names == ['left', 'right'] and list(codes) == [0, 1]")
    assert not loaded


@pytest.mark.parametrize("probability, dof", [(0.025, 2), (0.975, 2), (0.99, 3), (0.025, 40), (0.975, 40)])
def test_chi2_quantiles_are_those_of_scipy_stats(probability, dof):
    from scipy.stats import chi2

    from bodyfusion.nav.measurements import chi2_gate

    assert chi2_gate(probability, dof) == float(chi2.ppf(probability, dof))


def test_arrow_arrays_are_those_pa_array_makes():
    import numpy as np
    import pyarrow as pa

    from bodyfusion.outputs.trajectories import arrow_numbers, arrow_strings

    values = np.array([0.5, -1.25, 3.0, 1e300, 7.0])
    mask = np.array([False, True, False, False, True])
    assert arrow_numbers(values).equals(pa.array(values, pa.float64()))
    assert arrow_numbers(values, mask=mask).equals(pa.array(values, pa.float64(), mask=mask))
    assert arrow_numbers(values, mask=mask).null_count == 2
    assert arrow_numbers(values[::2]).equals(pa.array(values[::2], pa.float64()))
    codes = np.array([0, 1, 1, 0], dtype=np.int32)
    assert arrow_numbers(codes).equals(pa.array(codes))
    names = ["left_foot", "hand", "füße"]
    assert arrow_strings(names).equals(pa.array(names, pa.string()))


SIGNATURE_PROBE = """
import json, sys
import numba
from bodyfusion.core.compile_ahead import compile_fuser_kernels
from bodyfusion.core.layout import load_layout
from bodyfusion.runner import build_systems, layout_context, run_layout
from bodyfusion.plugins.foot_ins.estimators import compile_step
from bodyfusion.plugins.foot_ins.system import FootIns
from bodyfusion.sim import simulate
layouts = [(VICON, ["smoother.kind=fb-rts"]), (VICON, ["smoother.kind=rts", "fuser.method=qp"]),
           (VICON, ["systems.left_foot.filter.kind=enekf", "systems.right_foot.filter.kind=ckf"]),
           (VICON, ["fuser.inequality=projection", "fuser.correct=positions"])]
for scenario in SCENARIOS:
    layouts.append((simulate(scenario, OUT / scenario.stem, seed=0).config_path, []))
for config, sets in layouts:
    loaded = load_layout(config, sets)
    compile_fuser_kernels(loaded.layout)  # what a first run compiles ahead: the signatures the run calls
    for system in build_systems(loaded, layout_context(loaded)).values():
        if isinstance(system, FootIns):
            compile_step(system.filter, system.run_data, system.phi)
    run_layout(loaded)
multi = {}
for name, module in list(sys.modules.items()):
    if name.startswith("bodyfusion"):
        for obj in vars(module).values():
            if isinstance(obj, numba.core.registry.CPUDispatcher) and len(obj.overloads) > 1:
                multi[f"{obj.py_func.__module__}.{obj.py_func.__qualname__}"] = [str(s) for s in obj.signatures]
print(json.dumps(multi))
"""


def test_every_kernel_compiles_one_signature_whatever_the_layout(tmp_path):
    """A kernel called with an integer or boolean constant, or with arrays of another layout, is
    compiled again for those types (a literal 3 is a type of its own): seconds of a cold start
    each. Foot INS filters of three kinds, FB-RTS and the whole-run RTS, the QP, a phone with
    GNSS and UWB ranges, run in one process, each layout's fuser kernels and foot steps first
    compiled as a first run compiles them ahead (:mod:`bodyfusion.core.compile_ahead`,
    :func:`~bodyfusion.plugins.foot_ins.estimators.compile_step`): every compiled kernel holds
    one signature."""
    from tests.paths import ROOT

    configs = ROOT / "configs"
    probe = (f"from pathlib import Path\nVICON = Path({str(configs / 'dual_foot_vicon.yaml')!r})\n"
             f"OUT = Path({str(tmp_path)!r})\n"
             f"SCENARIOS = [Path({str(configs / 'dual_foot_hand_gnss.yaml')!r}), "
             f"Path({str(configs / 'sim_dual_foot_uwb.yaml')!r})]\n" + SIGNATURE_PROBE)
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True)
    assert json.loads(out.stdout.strip().splitlines()[-1]) == {}


def test_nothing_is_compiled_ahead_once_the_fusers_kernels_are_loaded():
    from bodyfusion.core.compile_ahead import compile_fuser_ahead
    from bodyfusion.core.constraints.kernels import _all_finite
    from bodyfusion.core.layout import load_layout
    from tests.paths import ROOT

    _all_finite(np.zeros(3), np.eye(3))  # this process has the kernel: a run here compiles nothing more of it
    assert compile_fuser_ahead(load_layout(ROOT / "configs" / "dual_foot_vicon.yaml").layout) is None


def test_a_first_run_says_it_compiles_once_and_the_second_says_nothing(tmp_path):
    """On an empty numba cache ``fusion -v run`` says, once, that it compiles the kernels and for
    about how long (on a terminal too, without -v); the next run loads them and says nothing."""
    from bodyfusion.core.compile_ahead import FIRST_RUN_NOTICE
    from tests.paths import ROOT

    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "numba")}
    runs = [subprocess.run([sys.executable, "-m", "bodyfusion.cli", "-v", "run", str(ROOT / "configs" / "dual_foot_vicon.yaml"),
                            "--out", str(tmp_path / f"out{k}")], capture_output=True, text=True, env=env, check=True)
            for k in range(2)]
    assert runs[0].stderr.count(FIRST_RUN_NOTICE) == 1
    assert FIRST_RUN_NOTICE not in runs[1].stderr
