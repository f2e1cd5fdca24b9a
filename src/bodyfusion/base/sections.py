"""Building blocks of every layout section (the core's, each plugin's, the simulator's): strict
models, file paths relative to the layout, and errors that name their dotted key."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

from pydantic import AfterValidator, BaseModel, ConfigDict, ValidationInfo


def _resolve_path(value: Path, info: ValidationInfo) -> Path:
    base = (info.context or {}).get("base_dir")
    value = Path(value).expanduser()
    if base is not None and not value.is_absolute():
        value = Path(base) / value
    return value


DataPath = Annotated[Path, AfterValidator(_resolve_path)]
"""A file path; relative paths resolve against the folder of the layout file."""


class StrictModel(BaseModel):
    """Base of every layout section: unknown keys are errors, and so are NaN and infinite numbers;
    a field set on a built model is validated like the file's (``layout.fuser.method = "bogus"``
    raises :class:`pydantic.ValidationError`)."""

    model_config = ConfigDict(extra="forbid", validate_default=True, allow_inf_nan=False, validate_assignment=True)


class KeyedError(ValueError):
    """A cross-field error raised in a validator that knows the dotted key (relative to
    the section being validated) it is about."""

    def __init__(self, key: str, reason: str) -> None:
        super().__init__(reason)
        self.key = key
