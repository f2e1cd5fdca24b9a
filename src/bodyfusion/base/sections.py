"""Building blocks of every layout section (the core's, each plugin's, the simulator's): strict
models, file paths relative to the layout, and errors that name their dotted key."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import (
    AfterValidator,
    BaseModel,
    ConfigDict,
    Field,
    PrivateAttr,
    ValidationInfo,
    field_validator,
)


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


class TableSection(StrictModel):
    """A section whose data is one table: the file ``path`` (relative to the layout) or a table
    given to the run in memory (:func:`bodyfusion.run`'s ``data``): a pandas DataFrame, a mapping
    of column name to array, or a numpy structured array, read with the section's column names
    and the same checks as the file (:func:`bodyfusion.io.tables.read_source`). :attr:`table` is
    the in-memory table bound to the section, :attr:`label` its dotted key in the layout."""

    path: DataPath | None = None
    """The file; unset when the table is given in memory."""
    _table: Any = PrivateAttr(default=None)
    _label: str = PrivateAttr(default="")

    def bind(self, table: Any, label: str) -> None:
        """Take ``table`` as this section's data, ``label`` (its dotted key) naming it in errors."""
        self._table, self._label = table, label

    @property
    def table(self) -> Any:
        """The in-memory table bound to the section (None: its data is the file at :attr:`path`)."""
        return self._table

    @property
    def label(self) -> str:
        """The section's dotted key in the layout, once a table is bound."""
        return self._label

    def needs_data(self) -> bool:
        """The section reads a table (a file or one in memory) to be used; False where it may
        stand without one (a section that says how other data are read)."""
        return True


class KeyedError(ValueError):
    """A cross-field error raised in a validator that knows the dotted key (relative to
    the section being validated) it is about."""

    def __init__(self, key: str, reason: str) -> None:
        super().__init__(reason)
        self.key = key


class FiguresConfig(StrictModel):
    """The plot files: each plot is written once per format of ``formats`` (``png``, ``pdf``,
    ``svg``: ``trajectory.png``, ``trajectory.pdf``...); ``dpi``, dots per inch, sets the
    resolution of PNG files and of the raster parts of PDF and SVG files."""

    formats: list[Literal["png", "pdf", "svg"]] = Field(default_factory=lambda: ["png"], min_length=1)
    dpi: int = Field(default=120, ge=50, le=1200)

    @field_validator("formats")
    @classmethod
    def _once_each(cls, v: list[str]) -> list[str]:
        if len(set(v)) != len(v):
            raise ValueError("a format is named twice")
        return v
