"""A live run (bodyfusion.live) is the batch run on a growing recording: the same states, bit for bit."""

from __future__ import annotations

import json
import socket
import threading

import numpy as np
import pytest

from bodyfusion.base.errors import ConfigError, InputError
from bodyfusion.core.layout import load_layout
from bodyfusion.live.engine import REPLAN_BATCH_S, LiveRun
from bodyfusion.live.sinks import JsonLinesSink
from bodyfusion.live.sources import line_rows, replay, replay_rows
from bodyfusion.runner.batch import run_layout
from tests.paths import CONFIGS

VICON = CONFIGS / "dual_foot_vicon.yaml"


@pytest.fixture(scope="module")
def batch():
    return run_layout(load_layout(VICON))


def _same_tracks(live, batch) -> None:
    for name, expected in batch.trajectories.items():
        got = live.trajectories[name]
        np.testing.assert_array_equal(got.t, expected.t)
        np.testing.assert_array_equal(got.pos_n, expected.pos_n)
        np.testing.assert_array_equal(got.pos_sd, expected.pos_sd)
    assert live.fuser.epochs == batch.fuser.epochs and live.fuser.activations == batch.fuser.activations


def test_a_live_replay_of_the_vicon_walk_is_the_batch_run_bit_for_bit(batch, tmp_path):
    lines = []

    class Collect:
        def write(self, state):
            lines.append(state)

        def close(self):
            pass

    run = LiveRun(load_layout(VICON), [Collect()])
    replay(run, replay_rows(run))
    live = run.close()
    _same_tracks(live, batch)
    assert all(s.revised_inputs == 0 for s in live.systems.values())
    t = np.array([s.t for s in lines])
    assert t.size == run.emitted == 1200 and np.all(np.diff(t) > 0)  # every 0.1 s of the 120 s walk
    # each emitted state is the batch track at its system's own time
    left = batch.trajectories["left_foot"]
    for state in lines[::97]:
        s = state.systems["left_foot"]
        k = int(np.searchsorted(left.t, s.t))
        np.testing.assert_array_equal(s.position_n, left.pos_n[k])
    # states are emitted behind the newest data by the look-ahead, not at the end
    assert len(run.latency_s) > 100


def test_a_replay_as_fast_as_it_runs_passes_every_30_s_and_is_the_batch_run(batch):
    """The spacing of the passes (fusion live --speed max: REPLAN_BATCH_S) changes no state."""
    run = LiveRun(load_layout(VICON), replan_s=REPLAN_BATCH_S)
    replay(run, replay_rows(run))
    _same_tracks(run.close(), batch)
    assert REPLAN_BATCH_S == 30.0 and len(run.latency_s) == 4  # the start, then every 30 s of the 120 s


def _csv_lines(rows):
    """The rows as CSV lines, each stream's columns in reverse order after its header line."""
    out, seen = [], set()
    for _, name, row in rows:
        columns = sorted(row, reverse=True)
        if name not in seen:
            seen.add(name)
            out.append(",".join([f"#{name}", *columns]))
        out.append(",".join([name, *(repr(row[c]) for c in columns)]))
    return [line + "\n" for line in out]


@pytest.mark.parametrize("form", ["json", "csv"])
def test_a_line_stream_over_tcp_gives_the_same_run(batch, form):
    run = LiveRun(load_layout(VICON), [])
    rows = list(replay_rows(run))
    lines = ([json.dumps({"system": name, **row}) + "\n" for _, name, row in rows] if form == "json"
             else _csv_lines(rows))
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]

    def send():
        for _ in range(100):
            try:
                client = socket.create_connection(("127.0.0.1", port))
                break
            except OSError:
                threading.Event().wait(0.05)
        with client, client.makefile("w") as f:
            f.writelines(lines)

    sender = threading.Thread(target=send)
    sender.start()
    replay(run, line_rows(run, f"tcp://127.0.0.1:{port}", timeout_s=30))
    sender.join()
    _same_tracks(run.close(), batch)


@pytest.mark.parametrize(("bad", "said"), [
    (b"\xff\xfe not text\n", "line 3: not UTF-8 text"),
    (b"[1, 2]\n", "line 3: not a JSON object"),
    (b'{"system": "left_foot", "acc_x": NaN}\n', "line 3: left_foot needs finite numbers"),
    (b'{"system": "head"}\n', "line 3: system 'head' is no stream of this layout"),
    (b'{"system": "left_foot", "acc_x": 1' + b"0" * 400 + b'}\n', "line 3: left_foot needs finite numbers"),
    (b"left_foot,1,2,3\n", "line 3: left_foot takes 8 values"),
    (b"left_foot,1,2,3,4,5,6,nan,7\n", "line 3: left_foot needs finite numbers"),
    (b"#left_foot,acc_x,acc_y\n", "line 3: the header of left_foot lacks column"),
    (b"head,1,2\n", "line 3: system 'head' is no stream"),
], ids=["bytes", "array", "nan", "system", "beyond_float", "csv_short", "csv_nan", "csv_header", "csv_system"])
def test_a_bad_line_on_the_stream_is_refused_naming_it(bad, said):
    run = LiveRun(load_layout(VICON), [])
    rows = list(replay_rows(run))[:2]
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]

    def send():
        for _ in range(100):
            try:
                client = socket.create_connection(("127.0.0.1", port))
                break
            except OSError:
                threading.Event().wait(0.05)
        with client:
            lines = [json.dumps({"system": name, **row}).encode() + b"\n" for _, name, row in rows]
            client.sendall(b"".join(lines) + bad)

    sender = threading.Thread(target=send)
    sender.start()
    with pytest.raises(InputError, match=said):
        replay(run, line_rows(run, f"tcp://127.0.0.1:{port}", timeout_s=30))
    sender.join()


def test_a_run_never_ready_starts_at_the_close_on_the_whole_recording(batch, tmp_path):
    path = tmp_path / "states.jsonl"
    run = LiveRun(load_layout(VICON), [JsonLinesSink(open(path, "w"))], warmup_s=1000.0)
    replay(run, replay_rows(run))
    assert run.fusion is None and path.read_text() == ""
    _same_tracks(run.close(), batch)
    assert len(path.read_text().splitlines()) == 1200


def test_no_rows_at_all_is_refused_in_one_line():
    with pytest.raises(ConfigError, match="no rows arrived for left_foot, right_foot"):
        LiveRun(load_layout(VICON)).close()


def test_rows_out_of_time_order_are_dropped_and_counted(batch):
    run = LiveRun(load_layout(VICON))
    rows = list(replay_rows(run))
    for t, name, row in rows[:5000] + rows[4990:5000] + rows[5000:]:  # ten rows again, late
        run.push(name, row)
    _same_tracks(run.close(), batch)
    assert sum(b.dropped for b in run.buffers.values()) == 10


@pytest.mark.parametrize("value", [float("nan"), float("inf"), "abc", None, 10**400])
def test_a_row_holding_no_finite_number_is_refused_naming_the_system_row_and_column(value):
    run = LiveRun(load_layout(VICON))
    rows = list(replay_rows(run))
    for t, name, row in rows[:99]:
        run.push(name, row)
    t, name, row = rows[99]
    with pytest.raises(InputError, match=rf"systems\.{name}\.data: row {sum(n == name for _, n, _ in rows[:100])}: "
                                         r"gyro_x is .*, not a finite number"):
        run.push(name, {**row, "gyro_x": value})


@pytest.mark.parametrize("kind", ["rts", "fb", "fb-rts"])
def test_a_layout_with_a_smoother_other_than_fixed_lag_is_refused_live(kind):
    with pytest.raises(ConfigError, match="smoother.kind.*fixed-lag only"):
        LiveRun(load_layout(VICON, [f"smoother.kind={kind}"]))


def test_a_row_without_the_sections_columns_is_refused():
    run = LiveRun(load_layout(VICON))
    with pytest.raises(ConfigError, match="without column"):
        run.push("left_foot", {"time_index": 0.0})
    with pytest.raises(ConfigError, match="no stream of this layout"):
        run.push("nose", {})


def test_a_start_too_early_waits_for_the_walk_and_gives_the_same_run(batch):
    """A 1 s warm-up: the feet have neither ended their first rest nor walked the 3 m the heading
    alignment takes; the run tries again every 2 s of data and, started, is the batch run."""
    run = LiveRun(load_layout(VICON), warmup_s=1.0)
    replay(run, replay_rows(run))
    assert run.not_started is not None and "yet" in str(run.not_started)
    _same_tracks(run.close(), batch)


@pytest.mark.parametrize(("key", "value"), [("output_interval_s", 1e-9), ("lookahead_s", 1e9), ("warmup_s", 0.0),
                                            ("replan_s", float("nan"))])
def test_a_timing_beyond_sense_is_refused_naming_it(key, value):
    with pytest.raises(ConfigError, match=rf"{key} \(.*\): {value!r} s: give"):
        LiveRun(load_layout(VICON), **{key: value})


def test_a_stream_address_that_cannot_be_listened_on_is_one_error():
    for address in ("tcp://127.0.0.1:99999", "udp://name.invalid:5000"):
        with pytest.raises(InputError, match="cannot listen there"):
            next(line_rows(LiveRun(load_layout(VICON)), address, timeout_s=1))


def test_a_replay_reads_each_file_as_its_section_does(batch, tmp_path):
    """A file with two lines before its header and ';' between cells: the replay reads it with the
    section's skip_rows and delimiter (a chunk at a time), and the run is the batch run."""
    data = CONFIGS.parent / "examples" / "data" / "dual_foot_vicon_hu2025"
    sets = []
    for foot, name in (("left_foot", "imuMeasLeft.csv"), ("right_foot", "imuMeasRight.csv")):
        text = (data / name).read_text().replace(",", ";")
        (tmp_path / name).write_text("recorded by hand\nsecond line of preamble\n" + text)
        sets += [f"systems.{foot}.data.path={tmp_path / name}", f"systems.{foot}.data.skip_rows=2",
                 f"systems.{foot}.data.delimiter=;"]
    run = LiveRun(load_layout(VICON, sets))
    replay(run, replay_rows(run))
    _same_tracks(run.close(), batch)
