"""Scoring: alignment, error statistics, interpolation, sparse truth, loop closure."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bodyfusion.base.errors import FusionError
from bodyfusion.base.types import Trajectory, TruthTrack
from bodyfusion.evaluation.metrics import (
    ErrorSketch,
    PERCENTILES,
    PlanarTransform,
    error_cdf,
    error_stats,
    fit_first_distance_alignment,
    interpolate_truth,
    loop_closure_m,
    path_length_m,
    score_systems,
)

STAT_KEYS = {"rmse", "mean", "max", "p50", "p75", "p90", "p95", "p99"}


def _traj(t: np.ndarray, pos: np.ndarray) -> Trajectory:
    return Trajectory(np.asarray(t, float), np.asarray(pos, float), np.full((len(t), 3), 0.1))


def _curvy_walk(t: np.ndarray, offset=(0.0, 0.0, 0.0)) -> np.ndarray:
    """A non-straight walk (so rotation is observable), ENU m, ~1.2 m/s."""
    e = 1.2 * t + 0.3 * np.sin(0.7 * t)
    n = 0.5 * np.sin(0.4 * t) + 0.05 * t**2
    u = 0.02 * np.sin(3.0 * t)
    return np.column_stack([e, n, u]) + np.asarray(offset, float)


def _two_feet(t: np.ndarray):
    """Truth for two feet 0.3 m apart, and estimates = truth mapped by a known inverse transform."""
    left = _curvy_walk(t, (0.0, 0.15, 0.0))
    right = _curvy_walk(t, (0.0, -0.15, 0.0))
    truths = {"left": TruthTrack(t, left), "right": TruthTrack(t, right)}
    return truths


def _inverse_map(pos: np.ndarray, theta: float, trans: np.ndarray, dz: float) -> np.ndarray:
    """Estimate such that R(theta) @ est + trans == truth, est_up + dz == truth_up."""
    c, s = math.cos(theta), math.sin(theta)
    rot = np.array([[c, -s], [s, c]])
    out = np.empty_like(pos)
    out[:, :2] = (pos[:, :2] - trans) @ rot  # R^T (p - t) row-wise
    out[:, 2] = pos[:, 2] - dz
    return out


# --------------------------------------------------------------------------- alignment


def test_alignment_recovers_known_rotation_translation_for_two_systems():
    t = np.linspace(0.0, 20.0, 401)
    truths = _two_feet(t)
    theta, trans, dz = 0.7, np.array([12.0, -5.0]), 0.4
    est = {k: _traj(t, _inverse_map(v.pos_n, theta, trans, dz)) for k, v in truths.items()}

    tf = fit_first_distance_alignment(est, truths, distance_m=3.0)

    assert tf.rotation_rad == pytest.approx(theta, abs=1e-9)
    np.testing.assert_allclose(tf.translation_m, trans, atol=1e-9)
    assert tf.vertical_offset_m == pytest.approx(dz, abs=1e-9)
    for k in truths:
        np.testing.assert_allclose(tf.apply(est[k].pos_n), truths[k].pos_n, atol=1e-9)


@pytest.mark.parametrize("theta", [-math.pi + 1e-6, -2.5, -1.0, -1e-4, 0.0, 0.3, 1.5, 3.0, math.pi - 1e-6])
@pytest.mark.parametrize(("tx", "ty"), [(0.0, 0.0), (-80.0, 45.5)])
def test_alignment_recovers_any_rotation(theta, tx, ty):
    t = np.linspace(0.0, 10.0, 101)
    truths = _two_feet(t)
    trans = np.array([tx, ty])
    est = {k: _traj(t, _inverse_map(v.pos_n, theta, trans, 0.0)) for k, v in truths.items()}
    tf = fit_first_distance_alignment(est, truths)
    d = (tf.rotation_rad - theta + math.pi) % (2 * math.pi) - math.pi
    assert abs(d) < 1e-9
    np.testing.assert_allclose(tf.translation_m, trans, atol=1e-8)


def test_alignment_uses_one_transform_and_keeps_relative_offset_between_systems():
    t = np.linspace(0.0, 20.0, 401)
    truths = _two_feet(t)
    # Estimates equal truth except the right foot is shifted 0.5 m east: one shared transform
    # cannot remove that relative offset (it would with a per-system fit).
    est = {
        "left": _traj(t, truths["left"].pos_n),
        "right": _traj(t, truths["right"].pos_n + [0.5, 0.0, 0.0]),
    }
    tf, scores = score_systems(est, truths, alignment="first_3m")
    # Relative geometry of the aligned estimates is unchanged: the same rigid R maps both.
    rel = scores["right"].pos_est_aligned - scores["left"].pos_est_aligned
    rel_raw = est["right"].pos_n - est["left"].pos_n
    np.testing.assert_allclose(rel[:, :2], rel_raw[:, :2] @ tf.matrix.T, atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(rel[:, :2], axis=1), np.hypot(0.5, 0.3), atol=1e-9)
    # The 0.5 m offset is split between the feet, not removed: error sum stays 0.5 m.
    h_l = scores["left"].horizontal_error_m
    h_r = scores["right"].horizontal_error_m
    assert h_r.max() > 0.2 and h_l.max() > 0.2
    # A per-system fit would make each error ~0; the shared one cannot.
    tf_left_only = fit_first_distance_alignment({"left": est["left"]}, {"left": truths["left"]})
    np.testing.assert_allclose(tf_left_only.translation_m, 0.0, atol=1e-9)
    assert not np.allclose(tf.translation_m, 0.0, atol=1e-3)


def test_alignment_uses_only_first_distance_of_truth_travel():
    t = np.linspace(0.0, 20.0, 401)
    truth = TruthTrack(t, _curvy_walk(t))
    pos = truth.pos_n.copy()
    # Corrupt the estimate only after the truth has travelled well past 3 m.
    cum = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(pos[:, :2], axis=0).T))])
    late = cum > 4.0
    pos[late, :2] += np.column_stack([np.linspace(0, 30, late.sum()), np.linspace(0, -20, late.sum())])
    tf = fit_first_distance_alignment({"a": _traj(t, pos)}, {"a": truth}, distance_m=3.0)
    assert tf.rotation_rad == pytest.approx(0.0, abs=1e-12)
    np.testing.assert_allclose(tf.translation_m, 0.0, atol=1e-12)


def test_alignment_without_time_overlap_raises_one_line_fusion_error():
    est = {"a": _traj(np.array([0.0, 1.0]), np.zeros((2, 3)))}
    truths = {"a": TruthTrack(np.array([5.0, 6.0]), np.zeros((2, 3)))}
    with pytest.raises(FusionError) as exc:
        fit_first_distance_alignment(est, truths)
    assert "\n" not in str(exc.value) and "overlap" in str(exc.value)


def test_alignment_single_pair_is_translation_only():
    est = {"a": _traj(np.array([0.0, 10.0]), np.array([[1.0, 2.0, 0.0], [50.0, 2.0, 0.0]]))}
    truths = {"a": TruthTrack(np.array([0.0]), np.array([[4.0, 6.0, 1.0]]), sparse=True)}
    tf = fit_first_distance_alignment(est, truths)
    assert tf.rotation_rad == 0.0
    np.testing.assert_allclose(tf.translation_m, [3.0, 4.0])
    assert tf.vertical_offset_m == pytest.approx(1.0)


def test_transform_identity_and_apply():
    p = np.array([[1.0, 0.0, 2.0], [0.0, 2.0, -1.0]])
    np.testing.assert_array_equal(PlanarTransform.identity().apply(p), p)
    tf = PlanarTransform(math.pi / 2, np.array([1.0, 1.0]), 0.5)
    np.testing.assert_allclose(tf.apply(p), [[1.0, 2.0, 2.5], [-1.0, 1.0, -0.5]], atol=1e-12)


# --------------------------------------------------------------------------- statistics


def test_error_stats_hand_computed_and_nan_ignored():
    err = np.array([1.0, -2.0, 3.0, 4.0, np.nan])  # absolute values 1, 2, 3, 4
    s = error_stats(err)
    assert set(s) == STAT_KEYS
    assert all(type(v) is float for v in s.values())
    assert s["rmse"] == pytest.approx(math.sqrt(30.0 / 4.0))
    assert s["mean"] == pytest.approx(2.5)
    assert s["max"] == pytest.approx(4.0)
    # linear percentiles on [1, 2, 3, 4]: value at rank q/100 * 3
    for q in PERCENTILES:
        assert s[f"p{q}"] == pytest.approx(1.0 + 3.0 * q / 100.0)


def test_error_stats_all_nan_gives_nan():
    s = error_stats(np.array([np.nan, np.nan]))
    assert all(math.isnan(v) for v in s.values())


def test_error_cdf_sorted_and_ends_at_one():
    e, p = error_cdf(np.array([3.0, np.nan, 1.0, 2.0, -0.5]))
    np.testing.assert_array_equal(e, [0.5, 1.0, 2.0, 3.0])
    np.testing.assert_allclose(p, [0.25, 0.5, 0.75, 1.0])


# --------------------------------------------------------------------------- scoring


def test_score_none_alignment_known_offset_gives_exact_error():
    t = np.linspace(0.0, 10.0, 101)
    truth_pos = _curvy_walk(t)
    est = {"a": _traj(t, truth_pos + [3.0, 4.0, -2.0])}
    tf, scores = score_systems(est, {"a": TruthTrack(t, truth_pos)}, alignment="none")
    assert tf.rotation_rad == 0.0
    sc = scores["a"]
    np.testing.assert_allclose(sc.horizontal_error_m, 5.0, atol=1e-12)
    np.testing.assert_allclose(sc.vertical_error_m, 2.0, atol=1e-12)
    m = sc.metrics
    assert m["horizontal_error_m"]["rmse"] == pytest.approx(5.0)
    assert m["horizontal_error_m"]["p99"] == pytest.approx(5.0)
    assert m["vertical_error_m"]["max"] == pytest.approx(2.0)
    assert m["distance_m"] == pytest.approx(path_length_m(truth_pos))
    assert m["final_error_pct_distance"] == pytest.approx(100.0 * 5.0 / m["distance_m"])
    assert "loop_closure_m" not in m


def test_score_interpolates_estimate_to_truth_epochs_and_skips_truth_outside_span():
    # Estimate: straight line east at 1 m/s, sampled every 1 s from t=2 to t=8.
    t_est = np.arange(2.0, 8.0 + 1e-9, 1.0)
    est_pos = np.column_stack([t_est, np.zeros_like(t_est), np.zeros_like(t_est)])
    # Truth at 0.25 s steps from 0 to 10, displaced 1 m north.
    t_tr = np.arange(0.0, 10.0 + 1e-9, 0.25)
    tr_pos = np.column_stack([t_tr, np.ones_like(t_tr), np.zeros_like(t_tr)])
    _, scores = score_systems({"a": _traj(t_est, est_pos)}, {"a": TruthTrack(t_tr, tr_pos)}, alignment="none")
    sc = scores["a"]
    np.testing.assert_array_equal(sc.t, t_tr[(t_tr >= 2.0) & (t_tr <= 8.0)])
    assert sc.t[0] == 2.0 and sc.t[-1] == 8.0
    # Interpolated estimate east equals the truth time (off-sample epochs included).
    np.testing.assert_allclose(sc.pos_est_aligned[:, 0], sc.t, atol=1e-12)
    np.testing.assert_allclose(sc.horizontal_error_m, 1.0, atol=1e-12)
    assert sc.metrics["distance_m"] == pytest.approx(6.0)
    assert sc.metrics["scored_epochs"] == len(sc.t)


def test_score_holds_views_of_the_truth_not_copies():
    # The truth's epochs inside the estimate's span are consecutive: the score's truth times and
    # positions are read-only views of the truth's arrays (an hour's truth is not copied per system).
    t_tr = np.arange(0.0, 10.0 + 1e-9, 0.25)
    truth = TruthTrack(t_tr, _curvy_walk(t_tr))
    t_est = np.arange(2.0, 8.0 + 1e-9, 0.5)
    _, scores = score_systems({"a": _traj(t_est, _curvy_walk(t_est))}, {"a": truth}, alignment="none")
    sc = scores["a"]
    inside = (t_tr >= 2.0) & (t_tr <= 8.0)
    np.testing.assert_array_equal(sc.t, t_tr[inside])
    np.testing.assert_array_equal(sc.pos_truth, truth.pos_n[inside])
    assert np.shares_memory(sc.t, truth.t) and np.shares_memory(sc.pos_truth, truth.pos_n)
    assert not sc.t.flags.writeable and not sc.pos_truth.flags.writeable
    assert truth.t.flags.writeable and truth.pos_n.flags.writeable


def test_score_of_truth_epochs_not_consecutive_in_span_copies_them():
    # Times not increasing (as a TruthTrack built in code may have them): the epochs inside are
    # picked one by one, as before.
    t_tr = np.array([0.0, 3.0, 9.0, 4.0, 5.0])
    pos = np.column_stack([t_tr, np.ones_like(t_tr), np.zeros_like(t_tr)])
    t_est = np.arange(2.0, 6.0 + 1e-9, 1.0)
    est = np.column_stack([t_est, np.zeros_like(t_est), np.zeros_like(t_est)])
    _, scores = score_systems({"a": _traj(t_est, est)}, {"a": TruthTrack(t_tr, pos)}, alignment="none")
    sc = scores["a"]
    np.testing.assert_array_equal(sc.t, [3.0, 4.0, 5.0])
    np.testing.assert_array_equal(sc.pos_truth, pos[[1, 3, 4]])
    np.testing.assert_allclose(sc.horizontal_error_m, 1.0, atol=1e-12)


def test_interpolate_truth_linear_and_nan_outside():
    truth = TruthTrack(np.array([0.0, 2.0]), np.array([[0.0, 0.0, 0.0], [2.0, 4.0, 6.0]]))
    p = interpolate_truth(truth, np.array([-1.0, 0.5, 2.0, 3.0]))
    assert np.all(np.isnan(p[0])) and np.all(np.isnan(p[3]))
    np.testing.assert_allclose(p[1], [0.5, 1.0, 1.5])
    np.testing.assert_allclose(p[2], [2.0, 4.0, 6.0])


def test_sparse_truth_gives_same_block():
    t = np.linspace(0.0, 10.0, 1001)
    truth_pos = _curvy_walk(t)
    est = {"a": _traj(t, truth_pos + [0.6, -0.8, 0.0])}
    idx = np.array([0, 200, 450, 700, 1000])
    sparse = TruthTrack(t[idx], truth_pos[idx], sparse=True)
    dense = TruthTrack(t, truth_pos)
    _, s_sparse = score_systems(est, {"a": sparse}, alignment="none", loop=True)
    _, s_dense = score_systems(est, {"a": dense}, alignment="none", loop=True)
    ms, md = s_sparse["a"].metrics, s_dense["a"].metrics
    assert set(ms) == set(md)
    assert set(ms["horizontal_error_m"]) == STAT_KEYS
    np.testing.assert_array_equal(s_sparse["a"].t, t[idx])
    np.testing.assert_allclose(s_sparse["a"].horizontal_error_m, 1.0, atol=1e-12)
    assert ms["horizontal_error_m"]["rmse"] == pytest.approx(md["horizontal_error_m"]["rmse"])
    # Sparse truth: distance from the estimate's own path, equal here to the dense truth's.
    assert ms["distance_source"] == "estimate" and md["distance_source"] == "truth"
    assert ms["distance_m"] == pytest.approx(md["distance_m"], rel=1e-9)
    assert ms["loop_closure_m"] == pytest.approx(md["loop_closure_m"])


def test_sparse_truth_alignment_with_first_3m():
    t = np.linspace(0.0, 10.0, 501)
    truth_pos = _curvy_walk(t)
    theta, trans = -0.3, np.array([2.0, 1.0])
    est = {"a": _traj(t, _inverse_map(truth_pos, theta, trans, 0.0))}
    idx = np.array([0, 100, 200, 350, 500])  # first gap already > 3 m of travel
    tf, scores = score_systems(est, {"a": TruthTrack(t[idx], truth_pos[idx], sparse=True)})
    assert tf.rotation_rad == pytest.approx(theta, abs=1e-9)
    np.testing.assert_allclose(scores["a"].horizontal_error_m, 0.0, atol=1e-9)


def test_score_systems_without_truth_are_absent_and_loop_included():
    t = np.linspace(0.0, 10.0, 101)
    pos = _curvy_walk(t)
    est = {"a": _traj(t, pos), "b": _traj(t, pos + 1.0)}
    _, scores = score_systems(est, {"a": TruthTrack(t, pos)}, alignment="first_3m", loop=True)
    assert set(scores) == {"a"}
    assert scores["a"].metrics["loop_closure_m"] == pytest.approx(loop_closure_m(est["a"]))


def test_score_systems_rejects_unknown_alignment():
    t = np.linspace(0.0, 1.0, 3)
    with pytest.raises(FusionError, match="alignment"):
        score_systems({"a": _traj(t, np.zeros((3, 3)))}, {"a": TruthTrack(t, np.zeros((3, 3)))}, alignment="best")


# --------------------------------------------------------------------------- geometry


def test_loop_closure_and_path_length_on_simple_shapes():
    # Unit square walked once, back to start: length 4, closure 0.
    square = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 5], [0, 1, 0], [0, 0, 0]], float)
    assert path_length_m(square) == pytest.approx(4.0)  # vertical ignored
    assert loop_closure_m(_traj(np.arange(5.0), square)) == pytest.approx(0.0)
    # 3-4-5: walk east 3 then north 4; closure 5, length 7.
    l_shape = np.array([[0, 0, 0], [3, 0, 0], [3, 4, 9]], float)
    assert path_length_m(l_shape) == pytest.approx(7.0)
    assert loop_closure_m(_traj(np.arange(3.0), l_shape)) == pytest.approx(5.0)
    # Circle of radius 2, many samples: length -> 4*pi.
    a = np.linspace(0, 2 * np.pi, 2001)
    circle = np.column_stack([2 * np.cos(a), 2 * np.sin(a), np.zeros_like(a)])
    assert path_length_m(circle) == pytest.approx(4 * np.pi, rel=1e-5)
    assert path_length_m(np.zeros((1, 3))) == 0.0


@settings(max_examples=60, deadline=None)
@given(errors=st.lists(st.one_of(st.floats(0.0, 50.0), st.floats(1e-12, 1e-6), st.just(float("nan"))), min_size=1,
                       max_size=400),
       cuts=st.lists(st.integers(0, 400), max_size=6))
def test_an_error_sketch_taken_in_blocks_gives_error_stats_within_its_accuracy(errors, cuts):
    """RMSE, mean and largest as error_stats gives them; each percentile within 0.1 % of its value
    (or 1e-9 m, the sketch's smallest), whatever blocks the errors come in."""
    e = np.asarray(errors)
    sketch = ErrorSketch()
    for block in np.split(e, sorted(c for c in cuts if c < e.size)):
        sketch.add(-block)  # absolute values are taken
    exact, got = error_stats(e), sketch.stats()
    if not np.isfinite(e).any():
        assert sketch.count == 0 and all(math.isnan(v) for v in got.values())
        return
    assert sketch.count == int(np.isfinite(e).sum())
    for key in ("rmse", "mean", "max"):
        assert got[key] == pytest.approx(exact[key], rel=1e-12, abs=1e-300)
    for key, value in exact.items():
        assert abs(got[key] - value) <= 1e-3 * value + 1e-9, key
