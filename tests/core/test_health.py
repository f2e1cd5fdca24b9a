"""The health block: covariance checks while the fuser runs, each plugin's NIS, the NEES
against truth in metrics.json and nees.png (docs/contract.md)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from bodyfusion.base.types import InputReport, Trajectory
from bodyfusion.core.fuser import Fuser
from bodyfusion.core.health import CovarianceMonitor, stride_times
from bodyfusion.core.layout import FuserConfig, load_layout
from bodyfusion.runner import build_systems, layout_context, run, run_layout
from bodyfusion.core.system import SensorSystem
from bodyfusion.plugins.random_walk.system import RandomWalkConfig
from bodyfusion.plugins.uwb import UwbTag
from bodyfusion.sim import simulate
from bodyfusion.testing import default_context
from tests.paths import CONFIGS

VICON = CONFIGS / "dual_foot_vicon.yaml"
VICON_FIXES = CONFIGS / "dual_foot_vicon_position_fixes.yaml"


class BadCovariance(SensorSystem):
    """A fake system, 10 s at 100 Hz, sync events every 0.5 s, whose covariance stops being
    positive semi-definite (a correlation of 2) from ``bad_from_s``."""

    plugin_name = "bad_covariance"
    Config = RandomWalkConfig

    def __init__(self, bad_from_s: float) -> None:
        super().__init__("bad", RandomWalkConfig(), default_context(Path(".")))
        self.t = np.round(np.arange(1001) * 0.01, 6)
        self.bad_from_s = bad_from_s
        self._i = 0
        self.corrections = 0

    @property
    def samples(self) -> int:
        return len(self.t)

    @property
    def input_report(self) -> InputReport:
        return InputReport()

    @property
    def t_now(self) -> float:
        return float(self.t[self._i])

    def advance(self, t: float) -> None:
        self._i = max(self._i, int(np.searchsorted(self.t, t, side="right")) - 1)

    def position_n(self) -> np.ndarray:
        return np.zeros(3)

    def covariance(self) -> np.ndarray:
        P = np.eye(3)
        if self.t_now >= self.bad_from_s:
            P[0, 1] = P[1, 0] = 2.0
        return P

    def apply_correction(self, dx: np.ndarray, P: np.ndarray) -> None:
        self.corrections += 1

    def sync_times(self) -> np.ndarray:
        return self.t[50::50]

    def sample_times(self) -> np.ndarray:
        return self.t

    def trajectory(self) -> Trajectory:
        n = self._i + 1
        return Trajectory(self.t[:n], np.zeros((n, 3)), np.ones((n, 3)))


def test_stride_times_keep_one_sync_time_a_second():
    np.testing.assert_array_equal(stride_times(np.array([0.5, 0.2, 0.9, 1.3, 1.4, 2.6, 2.6]), 1.0), [0.2, 1.3, 2.6])


def test_a_covariance_that_stops_being_psd_is_caught_where_it_starts():
    system = BadCovariance(bad_from_s=6.2)
    monitor = CovarianceMonitor(system)
    Fuser({"bad": monitor}, FuserConfig(method="none")).run()
    monitor.flush()
    cov = system.health()["covariance"]
    # one check a second at the sync events (0.5, 1.5, ..., 9.5 s) and one at the end (10 s)
    assert cov["checks"] == 11
    assert cov["violations"] == 5 and cov["first_violation_t_s"] == pytest.approx(6.5)
    assert cov["min_eigenvalue"] == pytest.approx(-1.0) and cov["end"]["min_eigenvalue"] == pytest.approx(-1.0)


def test_without_checks_the_current_covariance_is_the_default_health():
    cov = BadCovariance(bad_from_s=0.0).health()["covariance"]
    assert cov["checks"] == 1 and cov["violations"] == 1


def test_the_monitor_changes_no_bit_of_the_run():
    loaded = load_layout(VICON, ["fuser.method=none"])
    runs = []
    for monitored in (False, True):
        systems = build_systems(loaded, layout_context(loaded))
        seen = {name: CovarianceMonitor(s) for name, s in systems.items()} if monitored else systems
        Fuser(seen, loaded.layout.fuser).run()
        runs.append({name: (s.trajectory(), s.covariance()) for name, s in systems.items()})
    for name, (traj, P) in runs[0].items():
        np.testing.assert_array_equal(runs[1][name][0].pos_n, traj.pos_n)
        np.testing.assert_array_equal(runs[1][name][1], P)


def test_foot_ins_health_on_the_vicon_walk_with_position_fixes():
    result = run_layout(load_layout(VICON_FIXES))
    health = result.health()
    for name, h in health.items():
        assert h["covariance"]["checks"] >= result.fuser.epochs and h["covariance"]["violations"] == 0
        assert h["trajectory_covariance"]["checks"] == len(result.trajectories[name].t)
        assert h["quaternion_norm_max_deviation"] < 1e-12
        nis = h["nis"]
        assert {k: nis[k]["expected"] for k in nis} == {"zupt": 3.0, "zaru": 3.0, "position_fix": 3.0}
        assert nis["zupt"]["count"] == result.systems[name].diagnostics()["zupt_updates"]
        assert nis["zupt"]["mean"] == pytest.approx(result.systems[name].diagnostics()["zupt_mean_nis"])
        assert nis["zaru"]["mean"] is None
        fixes = result.systems[name].diagnostics()
        assert nis["position_fix"]["count"] == fixes["position_fixes_accepted"] + fixes["position_fixes_rejected"]
        assert nis["position_fix"]["beyond_gate"] == fixes["position_fixes_rejected"]
        assert h["nees"]["alignment"] == "none" and h["nees"]["epochs"] > 1000


def random_walk_layout(tmp_path: Path, alignment: str) -> Path:
    """Two random walkers east at 1 m/s for 30 s, their exact truth in a long-format CSV."""
    t = np.arange(3001) / 100.0
    rows = [f"{name},{ti:.2f},{ti:.2f},0,0" for name in ("walker_1", "walker_2") for ti in t]
    (tmp_path / "truth.csv").write_text("system,t,east_m,north_m,up_m\n" + "\n".join(rows) + "\n")
    walker = ("{plugin: random_walk, velocity_mps: [1.0, 0.0, 0.0], rate_hz: 100, duration_s: 30, "
              "increment_variance_m2: 0.0004, initial_variance_m2: 0.01}")
    path = tmp_path / "walkers.yaml"
    path.write_text(f"name: walkers\nsystems:\n  walker_1: {walker}\n  walker_2: {walker}\n"
                    "constraints:\n  - {between: [walker_1, walker_2], kind: max, distance_m: 0.5}\n"
                    "fuser: {method: projection, epochs: interval, interval_s: 0.5}\n"
                    f"truth: {{path: truth.csv, format: long, alignment: {alignment}}}\n")
    return path


def test_metrics_json_carries_the_health_block_and_nees_png_is_written(tmp_path):
    result, out = run(random_walk_layout(tmp_path, "none"), out_dir=tmp_path / "out", seed=3)
    doc = json.loads((out / "metrics.json").read_text())
    assert (out / "nees.png").is_file()
    for name, block in doc["systems"].items():
        h = block["health"]
        assert set(h) >= {"covariance", "covariance_history", "trajectory_covariance", "nees"}
        assert h["covariance"]["checks"] >= result.fuser.epochs and h["covariance"]["violations"] == 0
        assert h["covariance_history"]["checks"] == 3001 and h["covariance_history"]["violations"] == 0
        nees = h["nees"]
        assert nees["expected"] == 2.0 and nees["band"] == pytest.approx([0.0506, 7.378], abs=1e-3)
        assert nees["epochs"] == 3001 and 0.0 <= nees["in_band_fraction"] <= 1.0
        assert nees["frame_fitted"] is False and len(nees["profile"]["t_s"]) == 10
        assert nees["mean"] == pytest.approx(np.nanmean(result.nees[name].nees))


def test_with_a_fitted_frame_the_nees_says_so(tmp_path):
    result = run_layout(load_layout(random_walk_layout(tmp_path, "first_3m")))
    nees = result.health()["walker_1"]["nees"]
    assert nees["alignment"] == "first_3m" and nees["frame_fitted"] is True


def test_hand_and_foot_nis_on_a_simulated_walk(tmp_path):
    """The foot + hand scenario on a short rectangle (about 80 s, GNSS on): every aiding type
    reports its NIS beside its measurement dimension, the hand its east–north covariance."""
    sim = simulate(CONFIGS / "foot_hand_gnss_outage.yaml", tmp_path, seed=1,
                   overrides=["path.length_m=30", "path.width_m=20", "path.laps=1", "systems.hand_phone.gnss.outages=[]"])
    result = run_layout(load_layout(sim.config_path))
    health = result.health()
    hand = health["hand_phone"]["nis"]
    assert {k: v["expected"] for k, v in hand.items()} == {"gnss_position": 3.0, "gnss_course": 1.0,
                                                          "gnss_track": 1.0}
    gnss = result.systems["hand_phone"].gnss_counts
    assert hand["gnss_position"]["count"] == gnss["accepted"] + gnss["rejected"]
    assert hand["gnss_course"]["count"] == gnss["heading_accepted"] + gnss["heading_rejected"]
    assert hand["gnss_track"]["count"] == gnss["track_heading_accepted"] + gnss["track_heading_rejected"] > 0
    assert all(0.0 < v["mean"] < 30.0 for v in hand.values())
    assert np.any(result.trajectories["hand_phone"].pos_cov_en != 0.0)
    for name, h in health.items():
        assert h["covariance"]["violations"] == 0 and h["trajectory_covariance"]["violations"] == 0
        assert np.isfinite(h["nees"]["mean"])


def test_uwb_tag_reports_the_nis_of_the_ranges_the_fuser_applied(tmp_path):
    (tmp_path / "r.csv").write_text("t,id,range_m\n0.1,A1,5\n0.2,A2,5\n0.3,foot_b,1\n0.4,A1,5\n0.5,foot_b,1\n")
    config = UwbTag.Config(host="foot_a", anchors={"A1": (0, 0, 0), "A2": (1, 0, 0)}, peers={"foot_b": (0, 0, 0)},
                           ranges={"path": tmp_path / "r.csv"})
    tag = UwbTag("tag", config, default_context(tmp_path))
    for k, (value, accepted) in enumerate([(0.5, True), (1.5, True), (2.0, True), (40.0, False)]):
        tag.record(k, value, accepted)
    tag.record(4, None, False)  # outside the measured systems' data: not applied
    assert tag.health() == {"nis": {
        "anchor_ranges": {"dof": 1, "expected": 1.0, "count": 3, "mean": 14.0, "beyond_gate": 1},
        "peer_ranges": {"dof": 1, "expected": 1.0, "count": 1, "mean": 2.0, "beyond_gate": 0}}}


def test_every_correction_own_or_relative_is_checked():
    system = BadCovariance(bad_from_s=100.0)
    monitor = CovarianceMonitor(system)
    monitor.apply_correction(np.zeros(3), np.eye(3))
    monitor.apply_relative_correction(np.zeros(3), np.eye(3))
    monitor.flush()
    assert system.corrections == 2 and system.health()["covariance"]["checks"] == 2


def test_propagation_is_checked_at_the_stride_times_and_the_end_only():
    """Between corrections a system is checked at its stride times (sync times a second apart)
    and at its end, not at every epoch it is advanced to."""
    system = BadCovariance(bad_from_s=100.0)
    monitor = CovarianceMonitor(system)
    for t in (0.2, 0.3, 0.5, 0.7, 1.2, 1.5, 2.1):  # stride times 0.5, 1.5, 2.5, ...
        monitor.advance(t)
    checked = monitor._t[:monitor._n].tolist()
    monitor.advance(system.t_end)
    assert checked == [0.5, 1.5]
    assert monitor._n == 2 + 8 + 1 and monitor._t[monitor._n - 1] == system.t_end  # 2.5 ... 9.5, and the end
