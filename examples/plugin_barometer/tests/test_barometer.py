"""The barometer plugin's own tests: the core's conformance checker, the atmosphere
model, accuracy on the sample walk, and discovery once pip-installed."""

from __future__ import annotations

from importlib import metadata
from pathlib import Path

import numpy as np
import pytest

from bodyfusion.core.layout_io import validate_section
from bodyfusion.testing import check_system, default_context, with_value
from bodyfusion_barometer import Barometer, atmosphere

HERE = Path(__file__).resolve().parents[1]
CONFIG = {"data": {"path": "data/stairs_pressure.csv"}, "filter": {"pressure_sigma_pa": 2.5, "bias_random_walk": 0.05}}
CONTEXT = default_context(HERE)


def test_conforms_to_the_sensor_system_contract():
    check_system(Barometer, CONFIG, name="baro", context=CONTEXT, stochastic=False, bad_configs=[
        (with_value(CONFIG, "filter.pressure_sigma_pa", -1.0), "filter.pressure_sigma_pa"),
        (with_value(CONFIG, "data.pressure_unit", "psi"), "data.pressure_unit"),
        (with_value(CONFIG, "initial.reference_pressure_pa", 5.0), "initial.reference_pressure_pa"),
        (with_value(CONFIG, "data.pressure_column", "no_such_column"), "data.pressure_column"),  # refused at build
        (with_value(CONFIG, "data.path", "missing.csv"), "data.path"),
    ])


def test_height_and_pressure_are_inverse():
    h = np.array([-50.0, 0.0, 3.0, 1000.0])
    p = atmosphere.pressure_at(h, 98000.0, 290.0)
    np.testing.assert_allclose(atmosphere.height_at(p, 98000.0, 290.0), h, atol=1e-9)
    assert atmosphere.pressure_at(0.0, atmosphere.SEA_LEVEL_PA) == atmosphere.SEA_LEVEL_PA
    assert -13.0 < atmosphere.dpressure_dheight(0.0, atmosphere.SEA_LEVEL_PA) < -11.0  # about 12 Pa per metre


def test_tracks_one_storey_up_and_down():
    cfg = validate_section(Barometer.Config, {"plugin": "barometer", **CONFIG}, key="systems.baro", path=None,
                           base_dir=HERE)
    s = Barometer("baro", cfg, CONTEXT)
    s.advance(s.t_end)
    truth = np.loadtxt(HERE / "data" / "stairs_pressure.csv", delimiter=",", skiprows=1)[:, 2]
    up = s.trajectory().pos_n[:, 2]
    assert np.sqrt(np.mean((up - truth) ** 2)) < 0.25
    assert s.trajectory().pos_sd[-1, 0] > 100.0  # East/North: unobserved, large sigma


def test_is_discovered_once_installed():
    try:
        metadata.distribution("bodyfusion-barometer")
    except metadata.PackageNotFoundError:
        pytest.skip("bodyfusion-barometer is not pip-installed")
    from bodyfusion.core.registry import get_registry

    assert get_registry().system_class("barometer") is Barometer
