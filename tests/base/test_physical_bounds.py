"""Every number a layout, a scenario or a study holds is bounded by physical sense in the schema:
by the unit its name ends with (base.sections.UNIT_BOUNDS), or by the bounds its field declares;
a value beyond is refused in one line naming its key, before anything runs."""

from __future__ import annotations

import importlib
import pkgutil
import typing

import pytest
from annotated_types import Ge, Gt, Le, Lt
from hypothesis import given, settings
from hypothesis import strategies as st
from pydantic import BaseModel

import bodyfusion
from bodyfusion.base.errors import ConfigError
from bodyfusion.base.sections import StrictModel, unit_bound
from bodyfusion.core.layout import load_layout
from bodyfusion.study import load_study
from tests.paths import CONFIGS

VALIDATED_ELSEWHERE = {
    "axis_signs": "each ±1, a right-handed map (core.layout._right_handed)",
    "axis_b": "a unit vector (hand_pdr.config.MagnetometerConfig._unit_axis)",
    "seeds": "a count 1 … 100,000 or distinct seeds 0 … 2³² − 1 (study.spec.StudySpec._seeds)",
}
"""Numeric fields bounded by a validator of their own instead of their type's bounds."""


def _every_model() -> list[type[StrictModel]]:
    for module in pkgutil.walk_packages(bodyfusion.__path__, "bodyfusion."):
        if not module.name.endswith("__main__"):
            importlib.import_module(module.name)
    out, stack = [], [StrictModel]
    while stack:
        for sub in stack.pop().__subclasses__():
            out.append(sub)
            stack.append(sub)
    ours = {m for m in out if m.__module__.startswith("bodyfusion.")}
    return sorted(ours, key=lambda c: (c.__module__, c.__qualname__))


def _numeric(annotation: typing.Any) -> bool:
    if annotation in (int, float):
        return True
    return any(_numeric(a) for a in typing.get_args(annotation) if a is not type(None))


def _bounded(annotation: typing.Any, metadata: list) -> bool:
    """Whether every number the annotation admits has a lower and an upper bound: in the field's
    metadata, or in the metadata of each numeric element type (tuples, lists, dict values)."""
    if any(isinstance(m, (Gt, Ge)) for m in metadata) and any(isinstance(m, (Lt, Le)) for m in metadata):
        return True
    if typing.get_origin(annotation) is typing.Annotated:
        inner, *extra = typing.get_args(annotation)
        flat = [m for e in extra for m in getattr(e, "metadata", [e])]
        return _bounded(inner, metadata + flat)
    if annotation in (int, float):
        return False
    args = [a for a in typing.get_args(annotation) if a is not type(None) and a is not Ellipsis]
    numeric = [a for a in args if _numeric(a)]
    return bool(numeric) and all(_bounded(a, []) for a in numeric)


def test_every_number_of_every_section_is_bounded_by_its_unit_or_its_field():
    unbounded = []
    for model in _every_model():
        for name, field in model.model_fields.items():
            if not _numeric(field.annotation) or any(isinstance(a, type) and issubclass(a, BaseModel)
                                                     for a in typing.get_args(field.annotation)):
                continue
            if unit_bound(name) is None and name not in VALIDATED_ELSEWHERE \
                    and not _bounded(field.annotation, list(field.metadata)):
                unbounded.append(f"{model.__module__}.{model.__qualname__}.{name}")
    assert not unbounded, unbounded


def _unit_keys(model: BaseModel, prefix: str = "") -> list[str]:
    """Dotted keys of the scalar numeric fields of a loaded layout whose name carries a unit."""
    keys = []
    for name, field in type(model).model_fields.items():
        value = getattr(model, name)
        key = f"{prefix}{name}"
        if isinstance(value, BaseModel):
            keys += _unit_keys(value, key + ".")
        elif isinstance(value, dict):
            keys += [k for n, v in value.items() if isinstance(v, BaseModel) for k in _unit_keys(v, f"{key}.{n}.")]
        elif isinstance(value, (int, float)) and not isinstance(value, bool) and unit_bound(name) is not None:
            keys.append(key)
    return keys


VICON = CONFIGS / "dual_foot_vicon.yaml"
_LOADED = load_layout(VICON)
UNIT_KEYS = _unit_keys(_LOADED.layout) + [key for name, cfg in _LOADED.system_configs.items()
                                          for key in _unit_keys(cfg, f"systems.{name}.")]


@settings(max_examples=60, deadline=None)
@given(key=st.sampled_from(UNIT_KEYS), magnitude=st.floats(1e8, 1e300), sign=st.sampled_from([1.0, -1.0]))
def test_an_absurd_number_anywhere_in_a_layout_is_refused_naming_its_key(key, magnitude, sign):
    with pytest.raises(ConfigError) as err:
        load_layout(VICON, [f"{key}={sign * magnitude!r}"])
    assert err.value.key == key and "\n" not in str(err.value)


@pytest.mark.parametrize("override, key, reason", [
    ("fuser.interval_s=1e-5", "fuser.interval_s", "greater than or equal to 0.001"),
    ("systems.left_foot.data.time_scale=1e300", "systems.left_foot.data.time_scale", "less than or equal to"),
    ("geodetic_origin=[91, 0, 0]", "geodetic_origin.0", "less than or equal to 90"),
    ("output.decimate=10000000000", "output.decimate", "less than or equal to 1000000"),
])
def test_numbers_with_their_own_bounds_are_refused_naming_their_key(override, key, reason):
    with pytest.raises(ConfigError) as err:
        load_layout(VICON, [override])
    assert err.value.key == key and reason in err.value.reason


@pytest.mark.parametrize("seeds, reason", [("1000000000", "1000000000 seeds: give 1 to 100000"),
                                           ("[0, 4294967296]", "a seed is 0 … 4294967295"),
                                           ("[3, 3]", "seeds repeat")])
def test_a_study_with_absurd_seeds_is_refused_before_any_is_drawn(tmp_path, seeds, reason):
    (tmp_path / "walk.yaml").write_text((CONFIGS / "sim_perfect_walk.yaml").read_text())
    study = tmp_path / "study.yaml"
    study.write_text(f"layouts:\n  walk: {{scenario: walk.yaml}}\nseeds: {seeds}\n")
    with pytest.raises(ConfigError) as err:
        load_study(study)
    assert err.value.key.startswith("seeds") and reason in str(err.value)
