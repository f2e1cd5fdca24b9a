"""A loaded layout edited in code: every field set is validated, the whole is checked again at
run time, the config hash follows the models, and overrides come as a dict or as strings."""

from __future__ import annotations

import pytest
from pydantic import ValidationError

from bodyfusion.base.errors import ConfigError
from bodyfusion.core.layout import FuserConfig, load_layout
from bodyfusion.runner import run_layout
from tests.paths import CONFIGS

VICON_CFG = CONFIGS / "dual_foot_vicon.yaml"


def test_a_field_set_on_a_loaded_layout_is_validated():
    loaded = load_layout(VICON_CFG)
    with pytest.raises(ValidationError, match="method"):
        loaded.fuser.method = "bogus"
    with pytest.raises(ValidationError, match="kind"):
        loaded.systems["left_foot"].filter.kind = "bogus"
    with pytest.raises(ValidationError):
        loaded.fuser = "projection"
    loaded.fuser = FuserConfig(method="qp")
    assert loaded.layout.fuser.method == "qp"


def test_the_config_hash_follows_the_edited_models():
    loaded = load_layout(VICON_CFG)
    before = loaded.sha256
    loaded.fuser.method = "qp"
    assert loaded.sha256 != before
    assert loaded.sha256 == load_layout(VICON_CFG, ["fuser.method=qp"]).sha256
    loaded.fuser.method = "projection"
    assert loaded.sha256 == before


def test_overrides_as_a_dict_are_the_dotted_strings():
    as_dict = load_layout(VICON_CFG, {"fuser.method": "qp", "systems.left_foot.filter.kind": "ckf",
                                      "constraints.0.distance_m": 0.7})
    as_strings = load_layout(VICON_CFG, ["fuser.method=qp", "systems.left_foot.filter.kind=ckf",
                                         "constraints.0.distance_m=0.7"])
    assert as_dict.to_dict() == as_strings.to_dict()
    assert as_dict.layout.constraints[0].distance_m == 0.7
    with pytest.raises(ConfigError, match="empty part"):
        load_layout(VICON_CFG, {"fuser..method": "qp"})


def test_the_checked_layout_holds_the_same_models():
    loaded = load_layout(VICON_CFG)
    assert loaded.checked().to_dict() == loaded.to_dict()


def test_a_run_refuses_an_edit_that_breaks_a_cross_field_check():
    """Each field is valid on its own; together (a colour factor for the plain EKF) they are not,
    and the run says so with the dotted key before reading any data."""
    loaded = load_layout(VICON_CFG)
    loaded.systems["left_foot"].filter.colour_factor = 0.5
    with pytest.raises(ConfigError, match=r"systems\.left_foot\.filter\.colour_factor"):
        run_layout(loaded)
