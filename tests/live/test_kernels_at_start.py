"""A live run loads every compiled kernel it calls at its start: no later pass waits the ~10 ms a
load from numba's cache takes (which was a pass's worst latency)."""

from __future__ import annotations

import json
import subprocess
import sys

from tests.paths import CONFIGS

PROBE = """
import json, sys
from numba.core.registry import CPUDispatcher
from bodyfusion.core.layout import load_layout
from bodyfusion.live.engine import LiveRun
from bodyfusion.live.sources import replay, replay_rows

def signatures():
    out = {}
    for module in list(sys.modules.values()):
        if getattr(module, "__name__", "").startswith("bodyfusion"):
            for value in vars(module).values():
                if isinstance(value, CPUDispatcher):
                    out[f"{value.py_func.__module__}.{value.py_func.__name__}"] = len(value.signatures)
    return out

run = LiveRun(load_layout(sys.argv[1], sys.argv[2:]), replan_s=0.5)
rows = list(replay_rows(run))
rows = [r for r in rows if r[0] <= rows[0][0] + 60.0]  # a minute: the heading ties and health checks come in it
started = None
for row in rows:
    replay(run, iter([row]), None)
    if started is None and run.fusion is not None:
        started = signatures()
after = signatures()
print(json.dumps({"passes": len(run.latency_s),
                  "loaded": sorted(k for k, n in after.items() if n > started.get(k, 0))}))
"""


def _kernels_loaded_after_the_start(*overrides: str) -> dict:
    proc = subprocess.run([sys.executable, "-c", PROBE, str(CONFIGS / "dual_foot_vicon.yaml"), *overrides],
                          capture_output=True, text=True, check=True)
    return json.loads(proc.stdout.strip().splitlines()[-1])


def test_no_pass_after_the_start_loads_a_kernel():
    """The Vicon walk's first minute live, in a fresh process (nothing loaded before): the fuser's
    kernels (the heading ties' gated update, the covariance checks) load in the start's pass."""
    probe = _kernels_loaded_after_the_start()
    assert probe["passes"] > 50 and probe["loaded"] == []
