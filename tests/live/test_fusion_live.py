"""``fusion live``: a replay to JSON lines and MCAP that read back, paced or as fast as it runs,
and Ctrl-C leaving complete files."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from mcap.reader import make_reader

from tests.paths import CONFIGS

VICON = CONFIGS / "dual_foot_vicon.yaml"


def _fusion(*args: str, **kw) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "bodyfusion.cli", *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, **kw)


def _read_mcap(path) -> dict[str, list[dict]]:
    out: dict[str, list[dict]] = {}
    with open(path, "rb") as f:
        for schema, channel, message in make_reader(f).iter_messages():
            out.setdefault(channel.topic, []).append(json.loads(message.data))
            assert schema.name in ("foxglove.PoseInFrame", "bodyfusion.EpochState")
    return out


@pytest.mark.parametrize("speed", ["max", "40"])
def test_fusion_live_replays_the_vicon_walk_to_json_lines_and_mcap_that_read_back(tmp_path, speed):
    jsonl, mcap = tmp_path / "states.jsonl", tmp_path / "states.mcap"
    proc = _fusion("live", str(VICON), "--speed", speed, "--sink", str(jsonl), "--sink", str(mcap),
                   "--out", str(tmp_path / "run"))
    out, err = proc.communicate(timeout=300)
    assert proc.returncode == 0, err
    states = [json.loads(line) for line in jsonl.read_text().splitlines()]
    t = np.array([s["t"] for s in states])
    assert len(states) == 1200 and np.all(np.diff(t) > 0) and t[-1] == pytest.approx(120.0)
    assert set(states[0]["systems"]) == {"left_foot", "right_foot"}
    assert sum(s["health"]["constraint_epochs"] for s in states) > 100
    topics = _read_mcap(mcap)
    assert set(topics) == {"/bodyfusion/epoch", "/bodyfusion/left_foot/pose", "/bodyfusion/right_foot/pose"}
    poses = topics["/bodyfusion/left_foot/pose"]
    assert len(poses) == len(states) and poses[-1]["frame_id"] == "enu"
    assert poses[-1]["pose"]["position"]["x"] == states[-1]["systems"]["left_foot"]["east_m"]
    assert topics["/bodyfusion/epoch"][7] == states[7]
    assert (tmp_path / "run" / "metrics.json").is_file()  # and the finished run's outputs, as fusion run's


def test_ctrl_c_stops_a_live_run_with_130_and_leaves_complete_files(tmp_path):
    jsonl, mcap, csv = tmp_path / "s.jsonl", tmp_path / "s.mcap", tmp_path / "s.csv"
    proc = _fusion("live", str(VICON), "--speed", "4", "--sink", str(jsonl), "--sink", str(mcap), "--sink", str(csv))
    deadline = time.time() + 120
    while time.time() < deadline and (not jsonl.exists() or jsonl.stat().st_size < 2000):
        time.sleep(0.2)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    states = [json.loads(line) for line in jsonl.read_text().splitlines()]  # every line whole
    assert 0 < len(states) < 1200
    assert len(_read_mcap(mcap)["/bodyfusion/epoch"]) == len(states)  # the MCAP closed: its summary readable
    rows = csv.read_text().splitlines()
    assert rows[0].startswith("t,system,") and len(rows) == 1 + 2 * len(states)


def test_an_unknown_sink_is_refused_in_one_line(tmp_path):
    proc = _fusion("live", str(VICON), "--sink", str(tmp_path / "x.txt"))
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 2 and err.strip().splitlines() == [err.strip()] and "--sink" in err


def test_a_sink_file_that_exists_is_refused_unless_overwrite(tmp_path):
    mine = tmp_path / "states.jsonl"
    mine.write_text("my own\n")
    proc = _fusion("live", str(VICON), "--speed", "max", "--sink", str(mine))
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 2 and "--sink" in err and "exists" in err and mine.read_text() == "my own\n"
    proc = _fusion("live", str(VICON), "--speed", "max", "--sink", str(mine), "--overwrite")
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 0, err
    assert json.loads(mine.read_text().splitlines()[0])["systems"]


def test_fusion_live_keep_bounds_the_history_and_says_what_its_result_covers(tmp_path):
    jsonl = tmp_path / "states.jsonl"
    proc = _fusion("live", str(VICON), "--speed", "max", "--keep", "20", "--sink", str(jsonl),
                   "--out", str(tmp_path / "run"))
    _, err = proc.communicate(timeout=300)
    assert proc.returncode == 0, err
    assert len(jsonl.read_text().splitlines()) == 1200  # the sink has the whole track
    findings = json.loads((tmp_path / "run" / "metrics.json").read_text())["health"]["findings"]
    assert {f["system"] for f in findings if f["kind"] == "live_window"} == {"left_foot", "right_foot"}
    proc = _fusion("live", str(VICON), "--keep", "1")
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 2 and err.strip().splitlines() == [err.strip()] and "--keep" in err
