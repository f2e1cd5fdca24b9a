"""Building blocks of every layout section (the core's, each plugin's, the simulator's): strict
models whose numbers stay within physical sense, file paths relative to the layout, and errors
that name their dotted key."""

from __future__ import annotations

from pathlib import Path
from typing import ClassVar, Annotated, Any, Literal

from pydantic import (
    AfterValidator,
    BaseModel,
    ConfigDict,
    Field,
    PrivateAttr,
    ValidationInfo,
    field_validator,
    model_validator,
)


def _resolve_path(value: Path, info: ValidationInfo) -> Path:
    base = (info.context or {}).get("base_dir")
    value = Path(value).expanduser()
    if base is not None and not value.is_absolute():
        value = Path(base) / value
    return value


DataPath = Annotated[Path, AfterValidator(_resolve_path)]
"""A file path; relative paths resolve against the folder of the layout file."""

Coordinate_m = Annotated[float, Field(ge=-2e7, le=2e7)]
"""A coordinate in a local frame, m: within half the Earth's circumference."""
Point3_m = tuple[Coordinate_m, Coordinate_m, Coordinate_m]
"""A point (east, north, up or x, y, z), m."""
GeodeticPoint = tuple[Annotated[float, Field(ge=-90.0, le=90.0)], Annotated[float, Field(ge=-180.0, le=360.0)],
                      Annotated[float, Field(ge=-1e4, le=1e5)]]
"""Latitude (deg, ±90), longitude (deg) and ellipsoidal height (m, −10 km to 100 km)."""


UNIT_BOUNDS: tuple[tuple[str, float, str], ...] = (
    ("_hz", 1e5, "Hz, above any body-worn sensor's rate"),
    ("_s", 6.048e5, "s, a week"),
    ("_m", 2e7, "m, half the Earth's circumference"),
    ("_m2", 4e14, "m², the square of that"),
    ("_mps", 1e3, "m/s"),
    ("_mps2", 1e4, "m/s², about 1,000 g"),
    ("_radps", 1e3, "rad/s"),
    ("_deg", 720.0, "°, two turns"),
    ("_uT", 1e4, "µT, 200 times the Earth's field"),
    ("_ppm", 1e6, "ppm"),
    ("_mrad", 1e4, "mrad"),
    ("noise_density", 1e3, "per √Hz"),
    ("random_walk", 1e3, "per √Hz"),
    ("_decades", 20.0, "decades"),
)
"""The largest magnitude a number may have, by the unit its name ends with (the project names
quantities with their unit): beyond it a value is no measurement of a person walking, and it
would only exhaust the memory or the floating point range of a run."""


def unit_bound(name: str) -> tuple[float, str] | None:
    """(largest magnitude, what it is) of the field ``name`` by its unit suffix
    (:data:`UNIT_BOUNDS`), or None when its name carries no unit."""
    for suffix, bound, what in UNIT_BOUNDS:
        if name.endswith(suffix):
            return bound, what
    return None


def _numbers(value: Any) -> list[float]:
    """The numbers in a field's value: a number, or the numbers of a tuple, list or dict of them."""
    if isinstance(value, bool):
        return []
    if isinstance(value, (int, float)):
        return [float(value)]
    if isinstance(value, (tuple, list)):
        return [x for v in value for x in _numbers(v)]
    if isinstance(value, dict):
        return [x for v in value.values() for x in _numbers(v)]
    return []


class StrictModel(BaseModel):
    """Base of every layout section: unknown keys are errors, and so are NaN and infinite numbers
    and numbers beyond physical sense for their unit (:data:`UNIT_BOUNDS`; a field whose name has
    no unit declares its own bounds); a field set on a built model is validated like the file's
    (``layout.fuser.method = "bogus"`` raises :class:`pydantic.ValidationError`)."""

    model_config = ConfigDict(extra="forbid", validate_default=True, allow_inf_nan=False, validate_assignment=True)

    @model_validator(mode="after")
    def _within_physical_sense(self) -> Any:
        for name in type(self).model_fields:
            bound = unit_bound(name)
            if bound is None:
                continue
            for x in _numbers(getattr(self, name)):
                if abs(x) > bound[0]:
                    raise KeyedError(name, f"{x:g} is beyond {bound[0]:g} {bound[1]}: not a plausible value")
        return self


class TableSection(StrictModel):
    """A section whose data is one table: the file ``path`` (relative to the layout) or a table
    given to the run in memory (:func:`bodyfusion.run`'s ``data``): a pandas DataFrame, a mapping
    of column name to array, or a numpy structured array, read with the section's column names
    and the same checks as the file (:func:`bodyfusion.io.tables.read_source`). :attr:`table` is
    the in-memory table bound to the section, :attr:`label` its dotted key in the layout."""

    path: DataPath | None = None
    """The file; unset when the table is given in memory."""
    topic: str | None = None
    """A topic of a ROS 1 or 2 bag or an MCAP file at ``path``: the table is its messages, the
    columns their field paths (:mod:`bodyfusion.io.ros`)."""
    group: str | None = None
    """A group (its one-dimensional datasets are the columns) or a compound dataset (its fields
    are) of an HDF5 file at ``path`` (:mod:`bodyfusion.io.hdf5`)."""
    _table: Any = PrivateAttr(default=None)
    _label: str = PrivateAttr(default="")

    def bind(self, table: Any, label: str) -> None:
        """Take ``table`` as this section's data, ``label`` (its dotted key) naming it in errors."""
        self._table, self._label = table, label

    @property
    def table(self) -> Any:
        """The in-memory table bound to the section (None: its data is the file at :attr:`path`)."""
        return self._table

    def rows_from(self, first: int) -> TableSection:
        """A copy of the section bound to its in-memory table's rows from ``first`` on (a column →
        array table: what a live pass reads again)."""
        section = self.model_copy()
        section.bind({c: v[first:] for c, v in self._table.items()}, self._label)
        return section

    @property
    def label(self) -> str:
        """The section's dotted key in the layout, once a table is bound."""
        return self._label

    def needs_data(self) -> bool:
        """The section reads a table (a file or one in memory) to be used; False where it may
        stand without one (a section that says how other data are read)."""
        return True

    def text_columns(self) -> list[str]:
        """Of :meth:`required_columns`, those holding names (an anchor's id), not numbers: a live
        run's row buffer keeps them as text. Default: none."""
        return []

    def gap_columns(self) -> list[str]:
        """Of :meth:`required_columns`, those whose cell may be empty or NaN (a failed ranging): the
        reader drops and counts such rows by its policy, so a live row may carry them. Default: none."""
        return []

    rows_share_times: ClassVar[bool] = False
    """Several rows may carry one time (ranges to several anchors): a live row buffer then drops
    only rows earlier than the newest, not those at its time."""

    def required_columns(self) -> list[str]:
        """The columns its file must have: every ``*_column`` and ``*_columns`` field set (a
        section of another shape says its own); what ``fusion validate`` checks the header for."""
        out: list[str] = []
        for name in type(self).model_fields:
            value = getattr(self, name)
            if name.endswith("_column") and isinstance(value, str):
                out.append(value)
            elif name.endswith("_columns") and isinstance(value, (list, tuple)):
                out.extend(v for v in value if isinstance(v, str))
        return out


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
