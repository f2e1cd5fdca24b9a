"""A bounded live run (``--keep``) imports what it uses: Arrow (~30 MB resident, a twelfth of a
bounded hour's memory) only when it writes a Parquet sink or the run's files. (A run holding
everything reads its truth whole, through Arrow's reader.)"""

from __future__ import annotations

import json
import subprocess
import sys

from tests.paths import CONFIGS

PROBE = """
import json, sys
from bodyfusion.core.layout import load_layout
from bodyfusion.live.engine import LiveRun
from bodyfusion.live.sinks import open_sink
from bodyfusion.live.sources import replay, replay_rows

sinks = [open_sink(sys.argv[2])] if len(sys.argv) > 2 else []
run = LiveRun(load_layout(sys.argv[1]), sinks, replan_s=0.5, keep_s=10.0)
rows = list(replay_rows(run))
replay(run, iter([r for r in rows if r[0] <= rows[0][0] + 40.0]), None)
run.close()
print(json.dumps({"states": run.output.emitted, "arrow": "pyarrow" in sys.modules}))
"""


def _live_run(*sink: str) -> dict:
    proc = subprocess.run([sys.executable, "-c", PROBE, str(CONFIGS / "dual_foot_vicon.yaml"), *sink],
                          capture_output=True, text=True, check=True)
    return json.loads(proc.stdout.strip().splitlines()[-1])


def test_a_live_run_without_files_never_imports_arrow():
    probe = _live_run()
    assert probe["states"] > 100 and not probe["arrow"]


def test_a_parquet_sink_imports_arrow(tmp_path):
    probe = _live_run(str(tmp_path / "states.parquet"))
    assert probe["states"] > 100 and probe["arrow"]
