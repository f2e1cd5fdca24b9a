"""The whole-run RTS of a run whose record does not fit (bodyfusion.plugins.foot_ins.smoothing):
the filter keeps covariance checkpoints as it runs and the sweep replays each block between
two once; the smoothed run is the one the filter's own whole-run record gives, bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

from bodyfusion.core.layout import SmootherConfig, load_layout
from bodyfusion.runner import run_layout
from bodyfusion.plugins.foot_ins import smoothing, smoothing_record
from bodyfusion.plugins.foot_ins.smoothing import MAX_BLOCK_SAMPLES, smooth_record
from bodyfusion.plugins.foot_ins.smoothing_record import CHECKPOINT_SAMPLES, BlockBuffers, RunRecord
from tests.paths import ROOT

VICON_CFG = ROOT / "configs" / "dual_foot_vicon.yaml"
RTS = SmootherConfig(kind="rts")
FEET = ("left_foot", "right_foot")


def _smoothed(result, foot: str) -> tuple[np.ndarray, np.ndarray]:
    system = result.systems[foot]
    return system.smoothed_x, system.smoothed_pos_cov


@pytest.fixture(scope="module")
def vicon_runs():
    """The constrained Vicon walk smoothed by the whole-run RTS: from the filter's own record
    (it fits), and with the record limit at 1 kB, so that the filter keeps checkpoints. A limit
    of 0.45 m by projection (it acts only where broken, at some checkpoints and not others) and
    no heading tie (its corrections at most stance epochs would leave no checkpoint free of one)."""
    settings = ["smoother.kind=rts", "heading_alignment.continuous=false", "fuser.inequality=projection",
                "constraints.0.distance_m=0.45"]
    whole = run_layout(load_layout(VICON_CFG, settings))
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(smoothing_record, "STORE_BYTES", 1024)
        checkpointed = run_layout(load_layout(VICON_CFG, settings))
    return whole, checkpointed


def test_checkpointed_run_smooths_as_the_filters_whole_record(vicon_runs):
    whole, checkpointed = vicon_runs
    for foot in FEET:
        assert whole.systems[foot].smoothing_record()["forward_record"].active, foot
        record = checkpointed.systems[foot].smoothing_record()["forward_record"]
        assert not record.active and record.checkpointing and record.kept > 10, foot
        x, var = _smoothed(checkpointed, foot)
        x_ref, var_ref = _smoothed(whole, foot)
        assert np.array_equal(x, x_ref) and np.array_equal(var, var_ref), foot
        d = checkpointed.systems[foot].diagnostics()["smoothing"]
        assert d["covariance_rebuild_rel_error"] == 0.0 and d["state_rebuild_max_abs_error"] == 0.0, foot


def test_checkpoints_are_spaced_and_hold_the_filters_covariance(vicon_runs):
    """At least CHECKPOINT_SAMPLES apart, and each the covariance the replayed filter has
    there (after the corrections made there)."""
    _, checkpointed = vicon_runs
    for foot in FEET:
        rec = checkpointed.systems[foot].smoothing_record()
        r = RunRecord(rec)
        starts, P = rec["forward_record"].checkpoints(r)
        assert starts[0] == 0 and np.all(np.diff(starts) >= CHECKPOINT_SAMPLES), foot
        assert np.isin(starts[1:], r.ov_idx).any() and not np.isin(starts[1:], r.ov_idx).all(), foot
        buf = BlockBuffers(1)
        for k in range(1, starts.size):
            replayed = r.forward(int(starts[k - 1]), int(starts[k]), P[k - 1], False, buf)
            assert np.array_equal(replayed, P[k]), (foot, k)


def test_each_block_is_replayed_once(vicon_runs, monkeypatch):
    """With the filter's checkpoints no replay runs before the sweep's own (one per block);
    without them the stretches longer than MAX_BLOCK_SAMPLES are cut by one replay, and the
    result is the same."""
    _, checkpointed = vicon_runs
    calls = []
    forward = RunRecord.forward
    monkeypatch.setattr(RunRecord, "forward",
                        lambda self, a, b, *args: calls.append((a, b)) or forward(self, a, b, *args))
    for foot in FEET:
        rec = checkpointed.systems[foot].smoothing_record()
        calls.clear()
        own = smooth_record(rec, RTS)
        assert calls == [], foot
        bare = smooth_record({**rec, "forward_record": None}, RTS)
        n = rec["hist_x"].shape[0]
        assert n > MAX_BLOCK_SAMPLES and len(calls) == (n - 2) // CHECKPOINT_SAMPLES, foot
        assert calls[0][0] == 0 and all(b == a + CHECKPOINT_SAMPLES for a, b in calls), foot
        assert np.array_equal(own.x, bare.x) and np.array_equal(own.pos_var, bare.pos_var), foot


def test_the_ckf_keeps_checkpoints_and_smooths_as_its_replay():
    """The ckf records no whole run (its stance updates are the recorded covariances): it keeps
    checkpoints, and the blocks they start smooth as the replay of the whole run does."""
    result = run_layout(load_layout(VICON_CFG, ["smoother.kind=rts", "systems.left_foot.filter.kind=ckf"]))
    rec = result.systems["left_foot"].smoothing_record()
    assert rec["forward_record"].checkpointing and rec["forward_record"].kept > 10
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(smoothing, "MAX_BLOCK_SAMPLES", rec["hist_x"].shape[0])  # one block, no checkpoint
        whole = smooth_record({**rec, "forward_record": None}, RTS)
    own = smooth_record(rec, RTS)
    assert np.array_equal(own.x, whole.x) and np.array_equal(own.pos_var, whole.pos_var)
    assert own.diagnostics["covariance_rebuild_rel_error"] == 0.0
