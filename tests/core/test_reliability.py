"""No silent wrong answer: every bad layout or input the reliability review found is refused in
one line naming the file and key, or warned about and counted."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from pydantic import ValidationError

from bodyfusion.base.errors import ConfigError, InputError
from bodyfusion.cli import counted_policies
from bodyfusion.core.layout import load_layout
from bodyfusion.core.layout_io import MAX_YAML_DEPTH, MAX_YAML_NODES, read_yaml
from bodyfusion.runner import run_layout
from bodyfusion.io.timestamps import apply_timestamp_policy, timestamp_spikes
from bodyfusion.io.truth import read_truth_csv
from tests.fuzz.recording import write_recording
from tests.paths import CONFIGS

VICON = CONFIGS / "dual_foot_vicon.yaml"


def refused(overrides, path=VICON) -> ConfigError:
    with pytest.raises(ConfigError) as err:
        load_layout(path, overrides)
    assert "\n" not in str(err.value) and str(path.name) in str(err.value)
    return err.value


@pytest.mark.parametrize("override, key", [
    ("constraints.0.distance_m=.inf", "constraints.0.distance_m"),
    ("systems.left_foot.initial.heading_deg=.nan", "systems.left_foot.initial.heading_deg"),
    ("systems.left_foot.initial.position_m=[.inf, 0, 0]", "systems.left_foot.initial.position_m"),
    ("systems.left_foot.filter.zupt_sigma_mps=.nan", "systems.left_foot.filter.zupt_sigma_mps"),
    ("fuser.tolerance_m=.inf", "fuser.tolerance_m"),
])
def test_non_finite_numbers_are_refused_with_their_key(override, key):
    assert refused([override]).key.startswith(key)


def test_a_new_system_is_not_made_by_a_dotted_path():
    err = refused(["systems.left_fot.filter.kind=ekf"])
    assert err.key == "systems.left_fot" and "unknown system" in err.reason


def test_an_infeasible_constraint_set_is_refused(write_yaml):
    path = write_yaml({"systems": {n: {"plugin": "random_walk"} for n in "abc"}, "constraints": [
        {"between": ["a", "b"], "kind": "max", "distance_m": 0.1},
        {"between": ["b", "c"], "kind": "max", "distance_m": 0.1},
        {"between": ["a", "c"], "kind": "min", "distance_m": 5.0}]})
    err = refused([], path)
    assert err.key == "constraints.2.distance_m" and "within 0.2 m" in err.reason
    # the same with a 3-D minimum and horizontal maxima is feasible (the heights are free)
    load_layout(path, ["constraints.2.horizontal=false"])


def test_a_complex_yaml_key_is_a_syntax_error_with_its_line(tmp_path):
    path = tmp_path / "l.yaml"
    path.write_text("name: x\n? [a, b]\n: 1\nsystems: {}\n")
    with pytest.raises(ConfigError, match=r"l\.yaml:2: YAML syntax: a mapping key must be a plain value"):
        read_yaml(path)


def test_an_alias_bomb_is_refused_before_it_is_built(tmp_path):
    lines = ['a: &a ["lol","lol","lol","lol","lol","lol","lol","lol","lol"]']
    lines += [f"{chr(97 + i)}: &{chr(97 + i)} [" + ",".join(["*" + chr(96 + i)] * 9) + "]" for i in range(1, 9)]
    path = tmp_path / "bomb.yaml"
    path.write_text("\n".join(lines) + "\nsystems: {}\n")
    with pytest.raises(ConfigError, match=f"more than {MAX_YAML_NODES} YAML nodes"):
        read_yaml(path)


def test_a_yaml_that_is_not_utf8_is_refused_with_its_line_and_byte(tmp_path):
    path = tmp_path / "latin1.yaml"
    path.write_bytes("name: x\nsystems: {}\n# Gauß\n".encode("latin-1"))
    with pytest.raises(ConfigError, match=r"latin1\.yaml:3: not UTF-8 text \(byte 0xdf at offset 25\)"):
        read_yaml(path)


@pytest.mark.parametrize("depth", [MAX_YAML_DEPTH + 1, 900, 50_000])
def test_a_yaml_nested_beyond_any_layout_is_refused_in_one_line(tmp_path, depth):
    path = tmp_path / "deep.yaml"
    path.write_text("a: " + "[" * depth + "]" * depth + "\n")
    with pytest.raises(ConfigError, match=f"nested deeper than {MAX_YAML_DEPTH} levels"):
        read_yaml(path)


@pytest.mark.parametrize("make", ["fifo", "device", "folder"])
def test_a_special_file_is_refused_unopened_as_layout_data_or_truth(tmp_path, make, write_yaml):
    """A FIFO would block the reader for ever and /dev/zero feed it without end: the layout, a
    system's data and the truth are each refused naming the file, before anything opens them."""
    import os

    special = {"fifo": tmp_path / "pipe", "device": Path("/dev/zero"), "folder": tmp_path}[make]
    if make == "fifo":
        os.mkfifo(special)
    with pytest.raises(ConfigError, match="not a regular file|is a directory"):
        read_yaml(special)
    walker = {"plugin": "foot_ins", "data": {"path": str(special), "rate_hz": 100,
                                             "acc_columns": ["ax", "ay", "az"], "gyro_columns": ["gx", "gy", "gz"]}}
    loaded = load_layout(write_yaml({"systems": {"foot": walker}}))
    with pytest.raises(InputError, match="not a regular file|is a directory"):
        run_layout(loaded)


@pytest.mark.parametrize("name", ["left/foot", "../up", "a\x00b", "..", ".hidden", "x" * 65, "with space"])
def test_a_system_or_layout_name_that_is_no_file_name_is_refused(write_yaml, name):
    """Names become files and folders of the outputs (tum/<system>.txt, out/<layout>): one that
    would reach outside them, or that no file system takes, is refused with its key."""
    err = refused([], write_yaml({"systems": {name: {"plugin": "random_walk"}}}))
    assert err.key == "systems" and "not a system name" in err.reason
    err = refused([], write_yaml({"name": name, "systems": {"walker": {"plugin": "random_walk"}}}))
    assert err.key == "name"


def test_an_oversized_yaml_is_refused_unread(tmp_path):
    path = tmp_path / "big.yaml"
    path.write_text("x: [" + "1," * 3_000_000 + "1]\n")
    with pytest.raises(ConfigError, match="larger than a layout can be"):
        read_yaml(path)


def test_constraints_are_enforced_by_default(write_yaml):
    path = write_yaml({"systems": {n: {"plugin": "random_walk"} for n in "ab"},
                       "constraints": [{"between": ["a", "b"], "distance_m": 1.0}]})
    assert load_layout(path).layout.fuser.method == "projection"


def test_a_corrupt_timestamp_drops_one_sample_not_the_rest():
    t = np.arange(300) * 0.01
    t[100] = 1e30
    assert timestamp_spikes(t).tolist() == [100]
    kept, report, _ = apply_timestamp_policy(t, "drop", "imu.csv")
    assert kept.size == 299 and report.dropped_samples == 1 and len(report.warnings) == 1
    long_gap = np.concatenate([np.arange(100) * 0.01, 100 + np.arange(100) * 0.01])
    assert timestamp_spikes(long_gap).size == 0  # a gap is not a spike


def test_truth_rows_with_missing_cells_are_skipped_and_warned(tmp_path, caplog):
    path = tmp_path / "truth.csv"
    path.write_text("t,x,y,z\n0,0,0,0\n1,1,nan,0\n2,2,2,0\n")
    track = read_truth_csv(path, position_columns={"foot": ["x", "y", "z"]}, time_column="t")["foot"]
    assert track.t.tolist() == [0.0, 2.0]
    assert any("1 truth row(s) of foot skipped" in r.message and "line 3" in r.message for r in caplog.records)


def test_the_console_summary_names_every_counted_policy():
    doc = {"input": {"dropped_samples": 3, "reordered_samples": 0, "warnings": ["w"]},
           "systems": {"foot": {"diagnostics": {"zupt_gated": 2, "zupt_updates": 100,
                                                "input_checks": {"gaps": 1, "warnings": 1}}}},
           "constraints": {"not_converged": 4, "solver_fallbacks": 0, "epochs": 10}}
    lines = counted_policies(doc)
    assert "input: dropped_samples 3" in lines
    assert "foot: zupt_gated 2, input_checks.warnings 1" in lines
    assert "constraints: not_converged 4" in lines
    assert any("1 warning(s)" in line for line in lines)


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    """Both feet, a phone with GNSS and foot-to-foot UWB ranges over a 12 m walk."""
    return write_recording(tmp_path_factory.mktemp("recording"))["csv"]


def input_warnings(layout, overrides=()) -> list[str]:
    return run_layout(load_layout(layout, list(overrides))).input_report.warnings


@pytest.mark.slow
def test_gnss_on_another_clock_is_warned_unused(recording, tmp_path):
    gnss = np.loadtxt(recording.parent / "hand_phone_gnss.csv", delimiter=",", skiprows=1)
    gnss[:, 0] += 86_400.0
    shifted = tmp_path / "gnss.csv"
    np.savetxt(shifted, gnss, delimiter=",", header="t,lat_deg,lon_deg,height_m,accuracy_m,speed_mps,course_deg",
               comments="")
    warned = input_warnings(recording, [f"systems.hand_phone.gnss.path={shifted}", "fuser.method=none"])
    assert any("none of the 13 GNSS fixes" in w and "GNSS unused" in w for w in warned), warned


@pytest.mark.slow
def test_a_range_file_with_no_usable_range_is_warned(recording, tmp_path):
    ranges = tmp_path / "ranges.csv"
    ranges.write_text("t,id,range_m,nlos\n" + "".join(f"{0.1 * k:.1f},right_foot,-1,0\n" for k in range(50)))
    warned = input_warnings(recording, [f"systems.feet_tags.ranges.path={ranges}"])
    assert any("feet_tags: no usable range" in w and "50 negative" in w for w in warned), warned


@pytest.mark.slow
def test_constraints_left_unenforced_are_warned_at_run(recording, caplog):
    run_layout(load_layout(recording, ["fuser.method=none"]))
    assert any("the 2 constraint(s) of the layout are not enforced" in r.message for r in caplog.records)


@pytest.mark.parametrize(("key", "value"), [("filter.members", 100000), ("detector.window", 5000)])
def test_size_fields_of_the_foot_filter_are_capped(key, value, tmp_path):
    """An ensemble or detector window too large to run is refused at validation, by its key."""
    from bodyfusion.plugins.foot_ins.config import FootInsConfig

    section = {"plugin": "foot_ins", "data": {"path": "imu.csv"}}
    head, field = key.split(".")
    section[head] = {field: value}
    with pytest.raises(ValidationError, match=rf"{field}\n  Input should be less than or equal to"):
        FootInsConfig.model_validate(section)


def _left_foot_layout(write_yaml, tmp_path, imu=None, truth=None, **truth_keys) -> Path:
    """The Vicon walk's left foot with its truth, its files replaced by ``imu`` / ``truth``
    (DataFrames written beside the layout) where given."""
    import pandas as pd
    import yaml

    layout = yaml.safe_load(VICON.read_text())
    data = VICON.parent / layout["systems"]["left_foot"]["data"]["path"]
    truth_path = VICON.parent / layout["truth"]["path"]
    foot = layout["systems"]["left_foot"]
    foot["data"]["path"] = str(data)
    if imu is not None:
        imu(pd.read_csv(data)).to_csv(tmp_path / "imu.csv", index=False)
        foot["data"]["path"] = str(tmp_path / "imu.csv")
    layout["truth"]["path"] = str(truth_path)
    if truth is not None:
        truth(pd.read_csv(truth_path)).to_csv(tmp_path / "truth.csv", index=False)
        layout["truth"]["path"] = str(tmp_path / "truth.csv")
    layout["truth"].update(truth_keys)
    layout["truth"]["systems"] = {"left_foot": layout["truth"]["systems"]["left_foot"]}
    layout["systems"] = {"left_foot": foot}
    layout.pop("constraints")
    return write_yaml(layout)


def test_an_accelerometer_that_reads_no_gravity_is_refused_naming_its_file(write_yaml, tmp_path):
    def silent(df):
        df[["acc_x", "acc_y", "acc_z"]] = 0.0
        return df

    with pytest.raises(InputError, match=r"imu\.csv: the accelerometer reads 0 m/s\^2 .* no gravity"):
        run_layout(load_layout(_left_foot_layout(write_yaml, tmp_path, imu=silent)))


def test_a_truth_with_too_few_epochs_in_the_run_is_refused_before_fusing(write_yaml, tmp_path):
    layout = _left_foot_layout(write_yaml, tmp_path, truth=lambda df: df.iloc[:2])
    with pytest.raises(ConfigError) as err:
        run_layout(load_layout(layout))
    assert err.value.key == "truth" and "2 truth epoch(s) within its run" in err.value.reason


def test_a_truth_position_beyond_any_local_frame_is_refused_naming_its_line(write_yaml, tmp_path):
    def corrupt(df):
        df.loc[100, [c for c in df.columns if c.startswith("pos_")][0]] = 1e308
        return df

    with pytest.raises(InputError, match=r"truth\.csv: line 102: left_foot's truth position .* beyond 1e\+07 m"):
        run_layout(load_layout(_left_foot_layout(write_yaml, tmp_path, truth=corrupt)))


def test_a_truth_cut_short_is_scored_on_its_part_with_a_warning(write_yaml, tmp_path, caplog):
    layout = _left_foot_layout(write_yaml, tmp_path, truth=lambda df: df.iloc[: len(df) // 2])
    with caplog.at_level("WARNING", logger="bodyfusion"):
        result = run_layout(load_layout(layout))
    assert "left_foot" in result.scores
    warned = [r.getMessage() for r in caplog.records if "scored on that part only" in r.getMessage()]
    assert len(warned) == 1 and "left_foot" in warned[0] and "50 % of its run" in warned[0], warned


def test_truth_drop_outs_written_as_zeros_are_warned_of_as_jumps(write_yaml, tmp_path, caplog):
    def drop_outs(df):
        df.loc[300:302, [c for c in df.columns if c.startswith("pos_")]] = 0.0
        return df

    clean = _left_foot_layout(write_yaml, tmp_path)
    with caplog.at_level("WARNING", logger="bodyfusion"):
        run_layout(load_layout(clean))
    assert not [r for r in caplog.records if "jump(s) faster than" in r.getMessage()]
    with caplog.at_level("WARNING", logger="bodyfusion"):
        run_layout(load_layout(_left_foot_layout(write_yaml, tmp_path, truth=drop_outs)))
    jumps = [r.getMessage() for r in caplog.records if "jump(s) faster than" in r.getMessage()]
    assert len(jumps) == 1 and "left_foot: 2 jump(s)" in jumps[0], jumps  # into the drop-out and out of it


def test_a_system_the_truth_has_no_track_for_is_named_unscored(tmp_path, caplog):
    layouts = write_recording(tmp_path)
    truth = tmp_path / "truth.csv"
    truth.write_text("".join(line for line in truth.read_text().splitlines(keepends=True)
                             if not line.startswith("hand_phone,")))
    with caplog.at_level("WARNING", logger="bodyfusion"):
        result = run_layout(load_layout(layouts["csv"]))
    assert set(result.scores) == {"left_foot", "right_foot"}
    assert [r.getMessage() for r in caplog.records if "truth: no track" in r.getMessage()] == [
        "truth: no track for hand_phone in the truth section's file: not scored"]


def test_a_truth_in_millimetres_is_named_as_such_and_its_unit_fixes_it(write_yaml, tmp_path):
    def millimetres(df):
        df[[c for c in df.columns if c.startswith("pos_")]] *= 1000.0
        return df

    result = run_layout(load_layout(_left_foot_layout(write_yaml, tmp_path, truth=millimetres)))
    large = [f for f in result.findings if f.kind == "large_error"]
    assert len(large) == 1 and "truth in mm read as metres" in large[0].cause and "truth.unit: mm" in large[0].advice
    fixed = run_layout(load_layout(_left_foot_layout(write_yaml, tmp_path, truth=millimetres, unit="mm")))
    assert fixed.scores["left_foot"].metrics["horizontal_error_m"]["rmse"] < 0.3


def test_a_foot_imu_below_the_rate_a_stride_needs_is_a_finding(write_yaml, tmp_path):
    result = run_layout(load_layout(_left_foot_layout(write_yaml, tmp_path, imu=lambda df: df.iloc[::6]),
                                    ["systems.left_foot.initial.stationary_s=2"]))
    low = [f for f in result.findings if f.kind == "low_rate"]
    assert len(low) == 1 and "10 Hz" in low[0].message
