"""The out-of-tree example plugin (examples/plugin_barometer) in-process: its own tests,
and a layout that uses it, with the plugin registered the way an installed one is.

The installed round trip (a fresh venv, ``pip install``, ``fusion plugins``,
``fusion validate``/``run``) is in ``.ci/run``.
"""

from __future__ import annotations

import importlib.util
import sys

import numpy as np
import pytest

from tests.paths import ROOT

EXAMPLE = ROOT / "examples" / "plugin_barometer"
if str(EXAMPLE) not in sys.path:
    sys.path.insert(0, str(EXAMPLE))

import bodyfusion_barometer  # noqa: E402

from bodyfusion.core import registry as plugins  # noqa: E402
from bodyfusion import runner
from bodyfusion.base.errors import ConfigError  # noqa: E402
from bodyfusion.core.layout import load_layout  # noqa: E402


def _own_tests():
    spec = importlib.util.spec_from_file_location("barometer_own_tests", EXAMPLE / "tests" / "test_barometer.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


OWN = _own_tests()


@pytest.mark.parametrize("name", ["test_conforms_to_the_sensor_system_contract", "test_height_and_pressure_are_inverse",
                                  "test_tracks_one_storey_up_and_down"])
def test_the_example_plugins_own_tests(name):
    getattr(OWN, name)()


@pytest.fixture()
def registry_with_barometer(monkeypatch):
    """The installed plugins plus the example, registered through the same hook."""
    pm = plugins.make_plugin_manager()
    pm.register(bodyfusion_barometer)
    registry = plugins.Registry(pm)
    monkeypatch.setattr(plugins, "get_registry", lambda: registry)
    return registry


def test_pyproject_declares_the_entry_point():
    import tomllib

    project = tomllib.loads((EXAMPLE / "pyproject.toml").read_text())["project"]
    assert project["entry-points"]["bodyfusion.plugins"] == {"barometer": "bodyfusion_barometer"}
    assert any(dep.startswith("bodyfusion") for dep in project["dependencies"])


def test_layout_needs_the_plugin():
    if "barometer" in plugins.get_registry().names:
        pytest.skip("bodyfusion-barometer is installed here")
    with pytest.raises(ConfigError, match="unknown plugin 'barometer'"):
        load_layout(EXAMPLE / "layout.yaml")


def test_layout_validates_and_runs_with_the_plugin(registry_with_barometer):
    assert "barometer" in registry_with_barometer.names
    loaded = load_layout(EXAMPLE / "layout.yaml")
    result = runner.run_layout(loaded)
    traj = result.trajectories["phone_baro"]
    truth = np.loadtxt(EXAMPLE / "data" / "stairs_pressure.csv", delimiter=",", skiprows=1)[:, 2]
    assert np.sqrt(np.mean((traj.pos_n[:, 2] - truth) ** 2)) < 0.25
    with pytest.raises(ConfigError, match=r"systems\.phone_baro\.filter\.pressure_sigma_pa"):
        load_layout(EXAMPLE / "layout.yaml", ["systems.phone_baro.filter.pressure_sigma_pa=0"])


def test_the_barometer_joins_a_constrained_layout(registry_with_barometer, tmp_path):
    """No core change: a random-walk walker and the barometer held within 1 m (3-D). The
    constraint moves the barometer's unobserved East/North onto the walker and leaves
    the walker's own position (small variance) nearly untouched."""
    layout = tmp_path / "layout.yaml"
    data = EXAMPLE / "data" / "stairs_pressure.csv"
    layout.write_text(f"""
systems:
  walker: {{plugin: random_walk, velocity_mps: [1.0, 0.0, 0.0], duration_s: 60.0, rate_hz: 25.0,
           increment_variance_m2: 0.0001}}
  phone_baro: {{plugin: barometer, data: {{path: {data}}}}}
constraints:
  - {{between: [walker, phone_baro], kind: max, distance_m: 1.0, horizontal: false}}
fuser: {{method: projection, epochs: interval, interval_s: 1.0}}
""")
    result = runner.run_layout(load_layout(layout))
    assert result.fuser.activations > 0
    assert result.fuser.max_violation_before_m > 1.0
    assert result.fuser.max_violation_after_m < 1e-6
    walker = result.trajectories["walker"].pos_n[-1]
    baro = result.trajectories["phone_baro"].pos_n[-1]
    assert abs(baro[0] - walker[0]) < 3.0  # pulled ~60 m East along with the walker
