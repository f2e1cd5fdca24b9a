"""Tests for bodyfusion.core.layout: strict two-stage layout validation, overrides, path resolution.

Every refusal is a :class:`bodyfusion.base.errors.ConfigError` whose text names the file and the
dotted path of the offending key (docs/contract.md).
"""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
import yaml

from bodyfusion.base.errors import ConfigError, FusionError
from bodyfusion.core.layout import Layout, load_layout
from bodyfusion.core.layout_io import apply_overrides, parse_override, read_yaml
from tests.paths import CONFIGS, ROOT

VICON_CFG = CONFIGS / "dual_foot_vicon.yaml"
XIO_CFG = CONFIGS / "xio_long_walk.yaml"
VICON_DATA = ROOT / "examples" / "data" / "dual_foot_vicon_hu2025"

MINIMAL = """\
systems:
  foot:
    plugin: foot_ins
    data:
      path: imu.csv
      rate_hz: 100
      acc_columns: [ax, ay, az]
      gyro_columns: [gx, gy, gz]
"""


def refused(path: Path, overrides: list[str] | None = None) -> ConfigError:
    with pytest.raises(ConfigError) as ei:
        load_layout(path, overrides)
    return ei.value


def write(tmp_path: Path, text: str, name: str = "layout.yaml") -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


# --------------------------------------------------------------------------- shipped configs


@pytest.mark.parametrize("cfg", [VICON_CFG, XIO_CFG], ids=lambda p: p.name)
def test_shipped_configs_validate(cfg):
    loaded = load_layout(cfg)
    assert loaded.system_configs
    assert set(loaded.system_configs) == set(loaded.layout.systems)
    for sc in loaded.system_configs.values():
        assert sc.data.path.is_absolute()
        assert sc.data.path.is_file(), sc.data.path
    assert len(loaded.sha256) == 64


def test_vicon_config_reads_as_written():
    loaded = load_layout(VICON_CFG)
    left, right = loaded.system_configs["left_foot"], loaded.system_configs["right_foot"]
    assert left.detector.kind == right.detector.kind == "labels"
    assert left.initial.heading_deg == right.initial.heading_deg == "auto"  # one frame by default
    assert right.data.path.name == "imuMeasRight.csv"
    assert right.data.acc_columns == ("acc_x", "acc_y", "acc_z")  # from the YAML merge key
    assert loaded.layout.heading_alignment.reference is None
    assert loaded.layout.constraints[0].distance_m == "body"
    assert loaded.layout.truth.alignment == "first_3m"
    assert loaded.name == "dual_foot_vicon"


# --------------------------------------------------------------------------- unknown keys


@pytest.mark.parametrize("key", [
    "colour",
    "systems.left_foot.colour",
    "systems.left_foot.filter.acc_noise_densty",
    "systems.left_foot.data.colour",
    "systems.left_foot.detector.colour",
    "systems.right_foot.initial.colour",
    "truth.colour",
    "fuser.colour",
    "heading_alignment.colour",
    "output.colour",
])
def test_unknown_key_anywhere_is_refused_with_file_and_dotted_path(key):
    err = refused(VICON_CFG, [f"{key}=1"])
    assert err.key == key
    assert key in str(err)
    assert "dual_foot_vicon.yaml" in str(err)
    assert "unknown key" in str(err)


def test_unknown_key_written_in_the_file_names_the_file(tmp_path):
    text = MINIMAL + "    filter:\n      acc_noise_densty: 0.01\n"
    p = write(tmp_path, text, "typo.yaml")
    err = refused(p)
    assert "systems.foot.filter.acc_noise_densty" in str(err)
    assert "typo.yaml" in str(err)
    assert "\n" not in str(err)


def test_unknown_key_in_a_constraint_item():
    err = refused(VICON_CFG, ["constraints=[{between: [left_foot, right_foot], distance_m: 1.0, colour: 2}]"])
    assert err.key == "constraints.0.colour"
    assert "constraints.0.colour" in str(err) and "dual_foot_vicon.yaml" in str(err)


# --------------------------------------------------------------------------- constraints


@pytest.mark.parametrize("constraints,key", [
    ("[{between: [left_foot, nose], distance_m: 1.0}]", "constraints.0.between"),
    ("[{between: [left_foot, right_foot], distance_m: 1.0}, {between: [nose, left_foot], distance_m: 1.0}]",
     "constraints.1.between"),
    ("[{between: [left_foot, right_foot], distance_m: -1.0}]", "constraints.0.distance_m"),
    ("[{between: [left_foot, right_foot], distance_m: 0}]", "constraints.0.distance_m"),
    ("[{between: [left_foot, left_foot], distance_m: 1.0}]", "constraints.0.between"),
    ("[{between: [left_foot, right_foot], kind: max, distance_m: 1.0},"
     " {between: [right_foot, left_foot], kind: min, distance_m: 2.0}]", "constraints.1.distance_m"),
    ("[{between: [left_foot, right_foot], kind: min, distance_m: 2.0},"
     " {between: [left_foot, right_foot], kind: max, distance_m: 1.0}]", "constraints.1.distance_m"),
    ("[{between: [left_foot, right_foot], kind: most, distance_m: 1.0}]", "constraints.0.kind"),
    ("[{between: [left_foot, right_foot], distance_m: 1.0, lever_arms_m: {nose: [0, 0, 0]}}]",
     "constraints.0.lever_arms_m.nose"),
], ids=["unknown-system", "unknown-system-second", "negative-distance", "zero-distance", "same-system-twice",
        "min-above-max", "min-above-max-reversed", "unknown-kind", "lever-arm-unknown-system"])
def test_bad_constraint_is_refused_with_its_key_path(constraints, key):
    err = refused(VICON_CFG, [f"constraints={constraints}"])
    assert err.key == key
    assert key in str(err)
    assert "dual_foot_vicon.yaml" in str(err)


def test_consistent_constraints_are_accepted():
    loaded = load_layout(VICON_CFG, [
        "constraints=[{between: [left_foot, right_foot], kind: max, distance_m: 1.2},"
        " {between: [right_foot, left_foot], kind: min, distance_m: 0.1}]"])
    assert [c.kind for c in loaded.layout.constraints] == ["max", "min"]
    assert loaded.layout.constraints[1].between == ("right_foot", "left_foot")


def test_heading_alignment_reference_must_name_a_system():
    err = refused(VICON_CFG, ["heading_alignment.reference=nose"])
    assert err.key == "heading_alignment.reference"
    assert "nose" in str(err)


def test_same_system_name_twice_in_systems_is_refused(tmp_path):
    text = MINIMAL + (
        "  foot:\n"
        "    plugin: foot_ins\n"
        "    data: {path: other.csv, rate_hz: 100, acc_columns: [ax, ay, az], gyro_columns: [gx, gy, gz]}\n")
    p = write(tmp_path, text, "twice.yaml")
    err = refused(p)
    assert "key 'foot' appears twice" in str(err)
    assert "twice.yaml:9" in str(err)


# --------------------------------------------------------------------------- plugins


def test_unknown_plugin_is_refused_with_installed_names():
    err = refused(VICON_CFG, ["systems.left_foot.plugin=sonar_insole"])
    assert err.key == "systems.left_foot.plugin"
    assert "sonar_insole" in str(err) and "foot_ins" in str(err) and "hand_pdr" in str(err)
    assert "dual_foot_vicon.yaml" in str(err)


def test_missing_plugin_key_is_refused():
    err = refused(VICON_CFG, ["systems.left_foot.plugin=null"])
    assert err.key.startswith("systems.left_foot.plugin")


# --------------------------------------------------------------------------- paths


def test_relative_data_paths_resolve_against_the_config_folder(tmp_path, monkeypatch):
    folder = tmp_path / "walk"
    (folder / "data").mkdir(parents=True)
    shutil.copy(VICON_DATA / "imuMeasLeft.csv", folder / "imuMeasLeft.csv")
    shutil.copy(VICON_DATA / "imuMeasRight.csv", folder / "data" / "right.csv")
    shutil.copy(VICON_DATA / "positionGt.csv", folder / "truth.csv")
    text = VICON_CFG.read_text()
    text = text.replace("../examples/data/dual_foot_vicon_hu2025/imuMeasLeft.csv", "imuMeasLeft.csv")
    text = text.replace("../examples/data/dual_foot_vicon_hu2025/imuMeasRight.csv", "data/right.csv")
    text = text.replace("../examples/data/dual_foot_vicon_hu2025/positionGt.csv", "truth.csv")
    cfg = folder / "layout.yaml"
    cfg.write_text(text)
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    loaded = load_layout(Path("..") / "walk" / "layout.yaml")
    assert loaded.system_configs["left_foot"].data.path.resolve() == (folder / "imuMeasLeft.csv").resolve()
    assert loaded.system_configs["right_foot"].data.path.resolve() == (folder / "data" / "right.csv").resolve()
    assert loaded.layout.truth.path.resolve() == (folder / "truth.csv").resolve()
    # and the systems really read their data from there
    from bodyfusion.runner import build_systems, layout_context

    systems = build_systems(loaded, layout_context(loaded))
    assert systems["left_foot"].samples == systems["right_foot"].samples > 1000


def test_absolute_data_paths_are_kept(tmp_path):
    imu = VICON_DATA / "imuMeasLeft.csv"
    p = write(tmp_path, MINIMAL.replace("path: imu.csv", f"path: {imu}"))
    assert load_layout(p).system_configs["foot"].data.path == imu


# --------------------------------------------------------------------------- overrides


def test_override_sets_nested_keys_and_creates_missing_mappings():
    raw = {"a": {"b": 1}, "c": [1, 2]}
    out = apply_overrides(raw, ["a.b=2", "x.y.z=hello"])
    assert out == {"a": {"b": 2}, "c": [1, 2], "x": {"y": {"z": "hello"}}}
    assert raw == {"a": {"b": 1}, "c": [1, 2]}  # the input is not touched


def test_override_list_index():
    raw = {"constraints": [{"distance_m": 1.0}, {"distance_m": 2.0}], "cols": ["a", "b", "c"]}
    out = apply_overrides(raw, ["constraints.1.distance_m=3.5", "cols.0=q"])
    assert out["constraints"] == [{"distance_m": 1.0}, {"distance_m": 3.5}]
    assert out["cols"] == ["q", "b", "c"]


@pytest.mark.parametrize("text,value", [
    ("3", 3), ("0.25", 0.25), ("-2", -2), ("[1, 2.5]", [1, 2.5]), ("true", True), ("false", False),
    ("null", None), ("qp", "qp"), ("'3'", "3"), ("{a: 1}", {"a": 1}), ("a=b", "a=b"),
])
def test_override_values_are_yaml_typed(text, value):
    key, parsed = parse_override(f"k.v={text}")
    assert key == "k.v"
    assert parsed == value
    assert type(parsed) is type(value)


def test_overrides_reach_the_validated_layout():
    loaded = load_layout(VICON_CFG, [
        "systems.left_foot.filter.acc_noise_density=1e-3",
        "systems.left_foot.filter.zaru_sigma_radps=0.01",
        "systems.left_foot.filter.earth_rate=true",
        "systems.left_foot.initial.position_m=[1, 2, 3]",
        "heading_alignment.distance_m=5",
        "output.plots=false",
    ])
    f = loaded.system_configs["left_foot"].filter
    assert f.acc_noise_density == pytest.approx(1e-3)
    assert f.zaru_sigma_radps == 0.01
    assert f.earth_rate is True
    assert loaded.system_configs["left_foot"].initial.position_m == (1.0, 2.0, 3.0)
    assert loaded.layout.heading_alignment.distance_m == 5.0
    assert loaded.layout.output.plots is False
    # the right foot is untouched and the hash follows the overrides
    assert loaded.system_configs["right_foot"].filter.earth_rate is False
    assert loaded.sha256 != load_layout(VICON_CFG).sha256


@pytest.mark.parametrize("item,key", [
    ("nokey", "nokey"),
    ("a..b=1", "a..b"),
    (".a=1", ".a"),
    ("a.=1", "a."),
    ("=1", ""),
    ("constraints.3.distance_m=1", "constraints.3"),
    ("constraints.-1.distance_m=1", "constraints.-1"),
    ("constraints.x=1", "constraints.x"),
    ("name.sub=1", "name.sub"),
])
def test_bad_override_forms_are_refused(item, key):
    raw = {"name": "walk", "constraints": [{"distance_m": 1.0}]}
    with pytest.raises(ConfigError) as ei:
        apply_overrides(raw, [item])
    assert ei.value.key == key
    assert "\n" not in str(ei.value)


def test_bad_override_through_load_layout():
    err = refused(VICON_CFG, ["constraints.5.distance_m=1"])
    assert err.key == "constraints.5"


def test_override_of_an_aliased_value_changes_only_the_named_key():
    loaded = load_layout(VICON_CFG, ["systems.left_foot.data.acc_columns.0=acc_q"])
    assert loaded.system_configs["left_foot"].data.acc_columns == ("acc_q", "acc_y", "acc_z")
    assert loaded.system_configs["right_foot"].data.acc_columns == ("acc_x", "acc_y", "acc_z")


def test_override_of_a_plain_alias_changes_only_the_named_system(tmp_path):
    text = (
        "systems:\n"
        "  a:\n"
        "    plugin: foot_ins\n"
        "    data: &imu {path: a.csv, rate_hz: 100, acc_columns: [ax, ay, az], gyro_columns: [gx, gy, gz]}\n"
        "  b:\n"
        "    plugin: foot_ins\n"
        "    data: *imu\n")
    p = write(tmp_path, text)
    loaded = load_layout(p, ["systems.b.data.path=b.csv"])
    assert loaded.system_configs["a"].data.path.name == "a.csv"
    assert loaded.system_configs["b"].data.path.name == "b.csv"


# --------------------------------------------------------------------------- YAML and file errors


def test_yaml_syntax_error_names_file_and_line(tmp_path):
    text = MINIMAL.replace("rate_hz: 100", "rate_hz: [100")  # line 6 opens a flow sequence never closed
    text += "  other: {plugin: foot_ins\n"
    p = write(tmp_path, text, "broken.yaml")
    with pytest.raises(ConfigError) as ei:
        read_yaml(p)
    msg = str(ei.value)
    assert "broken.yaml:" in msg
    line = int(msg.split("broken.yaml:")[1].split(":")[0])
    assert 6 <= line <= len(text.splitlines()) + 1
    assert "YAML" in msg
    assert "\n" not in msg


def test_yaml_syntax_error_line_is_the_offending_line(tmp_path):
    p = write(tmp_path, "name: walk\nsystems:\n  foot: {plugin: foot_ins\n  other: 1\nfuser: {}\n", "bad.yaml")
    msg = str(refused(p))
    assert f"{p}:4:" in msg


def test_missing_config_file_is_a_config_error(tmp_path):
    err = refused(tmp_path / "nope.yaml")
    assert "nope.yaml" in str(err) and "not found" in str(err)


@pytest.mark.parametrize("text", ["- a\n- b\n", "just a string\n", ""])
def test_config_must_be_a_mapping(tmp_path, text):
    err = refused(write(tmp_path, text, "notmap.yaml"))
    assert "notmap.yaml" in str(err)
    assert isinstance(err, FusionError)


def test_layout_without_systems_is_refused(tmp_path):
    err = refused(write(tmp_path, "systems: {}\n", "empty.yaml"))
    assert "systems" in str(err) and "empty.yaml" in str(err)


# --------------------------------------------------------------------------- truth and heading


def test_wide_truth_without_time_source_is_refused():
    err = refused(VICON_CFG, ["truth.time_column=null"])
    assert err.key == "truth"
    assert "time_column" in str(err) and "rate_hz" in str(err)
    assert "dual_foot_vicon.yaml" in str(err)


def test_wide_truth_with_two_time_sources_is_refused():
    err = refused(VICON_CFG, ["truth.rate_hz=60"])
    assert err.key == "truth"


def test_long_truth_needs_no_time_source():
    loaded = load_layout(VICON_CFG, ["truth.format=long", "truth.time_column=null", "truth.systems={}"])
    assert loaded.layout.truth.format == "long"


def test_truth_columns_for_unknown_system_are_refused():
    err = refused(VICON_CFG, ["truth.systems.nose=[a, b, c]"])
    assert err.key == "truth.systems.nose"


def test_heading_auto_is_accepted():
    loaded = load_layout(VICON_CFG, ["systems.left_foot.initial.heading_deg=auto"])
    assert loaded.system_configs["left_foot"].initial.heading_deg == "auto"
    loaded = load_layout(VICON_CFG, ["systems.right_foot.initial.heading_deg=-37.5"])
    assert loaded.system_configs["right_foot"].initial.heading_deg == -37.5


def test_heading_north_is_refused():
    err = refused(VICON_CFG, ["systems.right_foot.initial.heading_deg=north"])
    assert "systems.right_foot.initial.heading_deg" in str(err)
    assert "dual_foot_vicon.yaml" in str(err)


def test_heading_north_error_names_exactly_the_config_key():
    err = refused(VICON_CFG, ["systems.right_foot.initial.heading_deg=north"])
    assert err.key == "systems.right_foot.initial.heading_deg"


@pytest.mark.parametrize("override,key", [
    ("gravity_mps2=12", "gravity_mps2"),
    ("latitude_deg=95", "latitude_deg"),
    ("fuser.method=bogus", "fuser.method"),
    ("systems.left_foot.filter.acc_noise_density=-1", "systems.left_foot.filter.acc_noise_density"),
    ("systems.left_foot.detector.kind=psychic", "systems.left_foot.detector.kind"),
    ("systems.left_foot.data.acc_unit=furlong", "systems.left_foot.data.acc_unit"),
    ("systems.left_foot.data.axes=[x, x, z]", "systems.left_foot.data.axes"),
    ("systems.left_foot.data.max_step_samples=1", "systems.left_foot.data.max_step_samples"),
    ("truth.frame=[y, x, w]", "truth.frame"),
    ("output.decimate=0", "output.decimate"),
    ("systems.left_foot.plugin={x: 1}", "systems.left_foot.plugin"),
    ("systems.left_foot.plugin=[foot_ins]", "systems.left_foot.plugin"),
])
def test_out_of_range_values_are_refused_with_their_key(override, key):
    err = refused(VICON_CFG, [override])
    assert err.key == key
    assert f"dual_foot_vicon.yaml: {key}:" in str(err)


def test_layout_model_is_strict():
    assert Layout.model_config["extra"] == "forbid"
    raw = yaml.safe_load(XIO_CFG.read_text())
    Layout.model_validate(raw, context={"base_dir": XIO_CFG.parent})
