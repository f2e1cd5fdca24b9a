"""UWB tag (plugin ``uwb``): range reader, conformance, the fuser's gated range updates
(anchors on one host, body-to-body with cross-covariances), the simulator, end to end."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from bodyfusion.base.errors import ConfigError, InputError
from bodyfusion.core.fuser import Fuser
from bodyfusion.core.layout import load_layout
from bodyfusion.runner import build_systems, layout_context, run, run_layout
from bodyfusion.base.seeding import system_seed
from bodyfusion.plugins.uwb import UwbTag
from bodyfusion.plugins.uwb.ranges import read_ranges
from bodyfusion.plugins.uwb.simulation import NlosConfig, nlos_states
from bodyfusion.plugins.uwb.system import ACCEPTED, REJECTED
from bodyfusion.sim import simulate
from bodyfusion.testing import check_system, default_context, with_value
from tests.paths import ROOT

ANCHORS = {"A1": [-10.0, -10.0, 2.0], "A2": [-10.0, 10.0, 2.0], "A3": [20.0, 10.0, 2.0], "A4": [20.0, -10.0, 2.0]}


def write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


# --------------------------------------------------------------------------- reader


def test_reader_drops_failed_negative_and_backward_rows_and_counts_them(tmp_path):
    f = write(tmp_path / "r.csv", "t,id,range_m,extra\n0,A1,5.0,x\n0,A2,,x\n0.1,A1,nan,x\n0.1,A2,-0.2,x\n"
                                  "0.05,A1,3.0,x\n\n0.2,A2,4.5,x\n")
    log = read_ranges(f, ["A1", "A2"])
    np.testing.assert_array_equal(log.t, [0.0, 0.2])
    np.testing.assert_array_equal(log.end, [0, 1])
    assert log.dropped == {"failed": 2, "negative": 1, "out_of_order": 1}
    assert log.report.dropped_samples == 4 and "r.csv" in log.report.notes[0]


@pytest.mark.parametrize("text, line, words", [
    ("t,who,range_m\n0,A1,1\n", 1, "missing column 'id'"),
    ("t,id,range_m\n0,A1,1\n0.1,A1,abc\n", 3, "non-numeric value 'abc'"),
    ("t,id,range_m\n0,A1,1\n0.1,B7,2\n", 3, "id 'B7' is neither an anchor nor a peer"),
    ("t,id,range_m\n0,A1,inf\n", 2, "infinite value"),
    ("t,id,range_m\nnan,A1,1\n", 2, "non-finite time"),
    ("t,id,range_m\n0,A1\n", 2, "row has 2 fields"),
])
def test_reader_errors_name_file_and_line(tmp_path, text, line, words):
    f = write(tmp_path / "bad.csv", text)
    with pytest.raises(InputError) as info:
        read_ranges(f, ["A1"])
    assert info.value.line == line and words in str(info.value)
    assert str(info.value).startswith(f"{f}:{line}: ") and "\n" not in str(info.value)


# --------------------------------------------------------------------------- conformance


def test_uwb_tag_conforms(tmp_path):
    write(tmp_path / "r.csv", "t,id,range_m\n0,A1,5\n0,right_foot,0.4\n0.1,A2,6\n0.1,right_foot,0.5\n")
    cfg = {"host": "left_foot", "anchors": {"A1": [0, 0, 2], "A2": [9, 0, 2]}, "peers": {"right_foot": [0, 0, 0.05]},
           "lever_arm_m": [0.0, 0.0, 0.05], "ranges": {"path": "r.csv"}}
    report = check_system(UwbTag, cfg, name="tag", context=default_context(tmp_path), stochastic=False, bad_configs=[
        (with_value(cfg, "sigma_m", 0.0), "sigma_m"),
        (with_value(cfg, "gate_probability", 1.0), "gate_probability"),
        (with_value(cfg, "peers.left_foot", [0, 0, 0]), "peers.left_foot"),
        (with_value(cfg, "peers.A1", [0, 0, 0]), "peers.A1"),
        ({"host": "left_foot", "ranges": {"path": "r.csv"}}, "anchors"),
    ])
    assert report.failed == [] and report.skipped == []


def test_missing_range_file_is_a_config_error_at_layout_level(tmp_path):
    layout = walkers_layout(tmp_path, {"tag": {"plugin": "uwb", "host": "w1", "anchors": ANCHORS,
                                               "ranges": {"path": "nowhere.csv"}}})
    with pytest.raises(InputError, match="nowhere.csv: file not found"):
        run_layout(load_layout(layout))


# --------------------------------------------------------------------------- layouts on random-walk hosts


def walkers_layout(tmp_path: Path, extra: dict, **top) -> Path:
    walker = {"plugin": "random_walk", "velocity_mps": [1.0, 0.0, 0.0], "rate_hz": 20, "duration_s": 30,
              "increment_variance_m2": 4e-4, "initial_variance_m2": 0.01}
    raw = {"systems": {"w1": dict(walker), "w2": {**walker, "start_m": [0.0, 0.6, 0.0]}, **extra},
           "output": {"plots": False}, **top}
    path = tmp_path / "layout.yaml"
    path.write_text(yaml.safe_dump(raw))
    return path


def anchor_ranges(tmp_path: Path, seed: int = 0, outlier_every: int = 0, outlier_m: float = 3.0) -> Path:
    """Ranges of walker w1 (its truth, seed 0) to the four anchors at 10 Hz, σ 0.1 m; every
    ``outlier_every``-th range gets a positive NLOS bias."""
    rng = np.random.default_rng(seed)
    t = np.arange(0, 30.0001, 0.1)
    truth = np.column_stack([t, np.zeros_like(t), np.zeros_like(t)])
    rows = ["t,id,range_m,nlos"]
    k = 0
    for ti, p in zip(t, truth):
        for name, a in ANCHORS.items():
            bias = outlier_m if outlier_every and k % outlier_every == outlier_every - 1 else 0.0
            rows.append(f"{ti:.10g},{name},{np.linalg.norm(p - a) + bias + rng.normal(0, 0.1):.4f},{int(bias > 0)}")
            k += 1
    return write(tmp_path / "ranges.csv", "\n".join(rows) + "\n")


def test_gate_rejects_injected_nlos_and_ranges_bound_a_drifting_host(tmp_path):
    anchor_ranges(tmp_path, outlier_every=7)
    tag = {"plugin": "uwb", "host": "w1", "anchors": ANCHORS, "sigma_m": 0.1,
           "ranges": {"path": "ranges.csv", "nlos_column": "nlos"}}
    res = run_layout(load_layout(walkers_layout(tmp_path, {"tag": tag})))
    free = run_layout(load_layout(walkers_layout(tmp_path, {})))
    gate = res.aiding["tag"].diagnostics()["gate_vs_truth"]
    assert gate["nlos_accepted"] == 0 and gate["nlos_rejected"] > 150
    assert gate["los_rejected"] <= 5
    err = lambda r: np.hypot(*(r.trajectories["w1"].pos_n - r.systems["w1"].truth_pos_n)[:, :2].T)  # noqa: E731
    assert err(res)[-100:].max() < 0.25 < err(free)[-100:].max()
    assert res.aiding["tag"].diagnostics()["anchor_ranges"]["mean_nis_accepted"] == pytest.approx(1.0, abs=0.3)


def test_a_tag_must_ride_on_a_navigation_system(tmp_path):
    anchor_ranges(tmp_path)
    tag = {"plugin": "uwb", "host": "w3", "anchors": ANCHORS, "ranges": {"path": "ranges.csv"}}
    with pytest.raises(ConfigError) as info:
        load_layout(walkers_layout(tmp_path, {"tag": tag}))
    assert info.value.key == "systems.tag.host" and "not a navigation system" in info.value.reason
    ok = {**tag, "host": "w1"}
    cons = [{"between": ["w1", "tag"], "distance_m": 1.0}]
    with pytest.raises(ConfigError) as info:
        load_layout(walkers_layout(tmp_path, {"tag": ok}, constraints=cons))
    assert info.value.key == "constraints.0.between" and "aiding source" in info.value.reason


def joint_filter(fuser: Fuser, q: float, p0_var: float):
    """The optimal joint EKF over both walkers' stacked positions, by brute force: every
    sample P += q I per walker, every range a scalar update on the 6-state stack."""
    w1, w2 = fuser.systems["w1"], fuser.systems["w2"]
    tag = fuser.aiding["tag"]
    x = np.concatenate([w1.truth_pos_n[0], w2.truth_pos_n[0]])
    P = p0_var * np.eye(6)
    lever = np.array(tag.config.lever_arm_m)
    peer_lever = np.array(tag.config.peers["w2"])
    k = 0
    times, log = tag.measurement_times(), tag.log
    for i in range(1, len(w1.t)):
        x += np.concatenate([w1.increments[i - 1], w2.increments[i - 1]])
        P += q * np.eye(6)
        t_next = w1.t[i + 1] if i + 1 < len(w1.t) else np.inf
        while k < len(times) and times[k] < t_next:  # the fuser's state is at the sample at or before
            end = tag.ids[log.end[k]]
            d = x[:3] + lever - (np.asarray(ANCHORS[end]) if end in ANCHORS else x[3:] + peer_lever)
            r = np.linalg.norm(d)
            H = np.concatenate([d / r, np.zeros(3) if end in ANCHORS else -d / r])
            s = H @ P @ H + tag.config.sigma_m ** 2
            if (log.range_m[k] - r) ** 2 / s <= tag.gate_nis:
                K = P @ H / s
                x += K * (log.range_m[k] - r)
                IKH = np.eye(6) - np.outer(K, H)
                P = IKH @ P @ IKH.T + tag.config.sigma_m ** 2 * np.outer(K, K)
            k += 1
    return x, P


def test_body_to_body_ranges_keep_the_joint_covariance_of_the_optimal_filter(tmp_path):
    """With cross-covariances tracked, anchor ranges on one walker and walker-to-walker
    ranges give exactly the joint EKF on the stacked state: both positions and the full
    6×6 covariance, cross blocks included (C_12 ← (I − K H) C_12 after an anchor range)."""
    rng = np.random.default_rng(4)
    rows = ["t,id,range_m"]
    for ti in np.arange(0.07, 30.0, 0.5):  # between samples (20 Hz): the state is at the sample before
        rows.append(f"{ti:.10g},A1,{np.linalg.norm(np.array([ti, 0, 0]) - ANCHORS['A1']) + rng.normal(0, 0.1):.4f}")
        rows.append(f"{ti:.10g},w2,{0.6 + rng.normal(0, 0.1):.4f}")
    write(tmp_path / "ranges.csv", "\n".join(rows) + "\n")
    tag = {"plugin": "uwb", "host": "w1", "anchors": {"A1": ANCHORS["A1"]}, "peers": {"w2": [0.0, 0.0, 0.0]},
           "ranges": {"path": "ranges.csv"}}
    loaded = load_layout(walkers_layout(tmp_path, {"tag": tag}, fuser={"cross_covariance": True}))
    built = build_systems(loaded, layout_context(loaded))
    aiding = {"tag": built.pop("tag")}
    fuser = Fuser(built, loaded.layout.fuser, [], aiding)
    fuser.run()
    x, P = joint_filter(fuser, 4e-4, 0.01)
    np.testing.assert_allclose(np.concatenate([built["w1"].x, built["w2"].x]), x, atol=1e-9)
    P_fused = fuser.joint.covariance()
    np.testing.assert_allclose(P_fused, P, atol=1e-10)
    assert np.abs(P_fused[:3, 3:]).max() > 1e-3  # the ranges correlated the two walkers
    assert (aiding["tag"].fate == ACCEPTED).sum() > 100


def test_without_tracking_a_body_to_body_update_drops_the_correlation(tmp_path):
    write(tmp_path / "ranges.csv", "t,id,range_m\n1.0,w2,0.9\n")
    tag = {"plugin": "uwb", "host": "w1", "peers": {"w2": [0.0, 0.0, 0.0]}, "ranges": {"path": "ranges.csv"}}
    loaded = load_layout(walkers_layout(tmp_path, {"tag": tag}))
    built = build_systems(loaded, layout_context(loaded))
    aiding = {"tag": built.pop("tag")}
    fuser = Fuser(built, loaded.layout.fuser, [], aiding)
    fuser.run()
    assert aiding["tag"].fate[0] == ACCEPTED
    np.testing.assert_array_equal(fuser.joint.cross, 0.0)
    # the update moved the walkers apart along North (the range said 0.9 m, they were 0.6 m apart)
    assert built["w2"].x[1] - built["w1"].x[1] > 0.6 + 0.05


# --------------------------------------------------------------------------- simulator


def test_nlos_chain_spends_the_configured_fraction_in_bursts():
    cfg = NlosConfig(fraction=0.1, mean_duration_s=1.5, bias_min_m=0.3, bias_max_m=2.0)
    rng = np.random.Generator(np.random.PCG64(system_seed(0, "test#uwb")))
    flags, bias = nlos_states(200_000, 0.1, cfg, rng)
    assert flags.mean() == pytest.approx(0.1, abs=0.01)
    starts = np.flatnonzero(np.diff(flags.astype(int)) == 1)
    assert flags.sum() / starts.size * 0.1 == pytest.approx(1.5, rel=0.1)
    assert bias[flags].min() >= 0.3 and bias[flags].max() <= 2.0 and np.all(bias[~flags] == 0)


SHORT = ["path.laps=1", "path.length_m=12", "path.width_m=8"]


def test_simulation_is_deterministic_and_runs_end_to_end(tmp_path):
    scenario = ROOT / "configs" / "foot_uwb_sim.yaml"
    a = simulate(scenario, tmp_path / "a", seed=3, overrides=SHORT)
    b = simulate(scenario, tmp_path / "b", seed=3, overrides=SHORT)
    c = simulate(scenario, tmp_path / "c", seed=4, overrides=SHORT)
    ranges = [r.out_dir / "left_tag_ranges.csv" for r in (a, b, c)]
    assert ranges[0].read_bytes() == ranges[1].read_bytes() != ranges[2].read_bytes()
    assert "left_tag" not in (a.out_dir / "truth.csv").read_text()
    result, out = run(a.config_path, [], tmp_path / "run")
    doc = json.loads((out / "metrics.json").read_text())
    assert doc["systems"]["left_foot"]["horizontal_error_m"]["rmse"] < 0.3
    tag = doc["aiding"]["left_tag"]
    assert tag["host"] == "left_foot" and tag["anchor_ranges"]["accepted"] > 0.8 * tag["samples"]
    assert sum(tag["gate_vs_truth"].values()) == tag["samples"]
    assert doc["input"]["dropped_samples"] == tag["dropped"]["failed"] > 0
    assert (result.aiding["left_tag"].fate == REJECTED).sum() == tag["anchor_ranges"]["rejected_by_gate"]
    smoothed = run_layout(load_layout(a.config_path, ["smoother.kind=rts"]))
    assert smoothed.scores["left_foot"].metrics["horizontal_error_m"]["rmse"] < 0.3
    assert smoothed.systems["left_foot"].diagnostics()["smoothing"]["warnings"] == 0


def test_simulated_tag_needs_a_simulated_host(tmp_path):
    with pytest.raises(ConfigError) as info:
        simulate(ROOT / "configs" / "foot_uwb_sim.yaml", tmp_path, overrides=[*SHORT, "systems.left_tag.host=nobody"])
    assert info.value.key == "systems.left_tag.host"
    with pytest.raises(ConfigError) as info:
        simulate(ROOT / "configs" / "foot_uwb_sim.yaml", tmp_path, overrides=[*SHORT, "systems.left_tag.rate_hz=7"])
    assert info.value.key == "systems.left_tag.rate_hz"
