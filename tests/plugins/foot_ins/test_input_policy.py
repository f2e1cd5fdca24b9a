"""The foot INS's input policies (bodyfusion.plugins.foot_ins.input_policy): a gyroscope that clips
in every swing is rebuilt and navigated, its repair's uncertainty added on the level axes only."""

from __future__ import annotations

import numpy as np
import pytest

from bodyfusion.core.layout import load_layout
from bodyfusion.runner import run_layout
from bodyfusion.nav.saturation import ClippedRun, Clipping
from bodyfusion.plugins.foot_ins.input_policy import covariance_increments
from bodyfusion.base.types import ImuStream
from bodyfusion.sim import simulate
from tests.paths import ROOT

RUN = ["gait.roll.heel_s=0.07", "gait.roll.toe_s=0.07", "path.laps=1"]


def _running(tmp_path, name: str, gyro_range: str) -> tuple:
    imu = "{preset: icm20948" + (f", gyro_range_radps: {gyro_range}" if gyro_range else "") + "}"
    cfg = simulate(ROOT / "configs" / "sim_running.yaml", tmp_path / name, seed=1, overrides=[
        *RUN, f"systems={{left_foot: {{kind: foot_imu, foot: left, imu: {imu}}}}}"]).config_path
    result = run_layout(load_layout(cfg, ["systems.left_foot.detector.kind=adaptive"]))
    return result, result.scores["left_foot"].metrics["horizontal_error_m"]["rmse"]


@pytest.mark.slow
def test_a_gyroscope_clipped_in_every_swing_is_rebuilt_and_navigated(tmp_path):
    """A run whose swing turns at up to ~12.7 rad/s against a ±8.7 rad/s (500 °/s) gyroscope: every
    stride loses ~0.2 rad of pitch. Rebuilt and its uncertainty added, the track stays within a
    few times the unclipped one's error."""
    clipped, rmse_clipped = _running(tmp_path, "clipped", "8.73")
    _, rmse_full = _running(tmp_path, "full", "")
    notes = " ".join(clipped.input_report.notes)
    assert "clipped gyroscope runs rebuilt" in notes
    assert clipped.systems["left_foot"].clipping["gyro"].rail[1, 0] == pytest.approx(8.73)
    assert rmse_clipped < max(0.5, 4 * rmse_full), (rmse_clipped, rmse_full)


def test_a_repaired_gyroscope_run_adds_level_uncertainty_only():
    """Heading is not observable by the stance updates: an uncertainty added to it would only take
    up their corrections, so a rebuilt pitch rate widens the level axes (east, north) alone."""
    n = 100
    stream = ImuStream(np.arange(n) / 100.0, np.tile([0.0, 0.0, 9.8], (n, 1)), np.zeros((n, 3)))
    clipping = Clipping(runs=[ClippedRun(1, 40, 45, 0.1, np.zeros(5))])
    index, dP = covariance_increments(stream, 9.8, {"gyro": clipping})
    assert index.tolist() == [45]
    np.testing.assert_allclose(np.diag(dP[0])[6:9], [0.05**2, 0.05**2, 0.0])
    assert np.count_nonzero(dP[0]) == 2
