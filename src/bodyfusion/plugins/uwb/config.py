"""Layout section of a UWB tag (``plugin: uwb``)."""

from __future__ import annotations

from typing import ClassVar, Literal

from pydantic import Field, model_validator

from bodyfusion.base.sections import DataPath, KeyedError, Point3_m, StrictModel, TableSection

class RangeFileConfig(TableSection):
    """Ranges recorded as CSV with a header line (or a table with those columns given in memory),
    one ranging per row: the time (s, on the host's clock), the id of the other end (an anchor
    name or a peer system name) and the measured range (m). Other columns are ignored. Failed rangings (an empty or NaN range)
    and negative ranges are dropped and counted; rows whose time goes backwards are dropped
    and counted."""

    path: DataPath | None = Field(default=None, description="CSV file of ranges; relative to the layout file "
                                                            "(unset: the table given in memory).")
    time_column: str = Field(default="t", description="Column of ranging times, s.")
    id_column: str = Field(default="id", description="Column naming the other end: an anchor or a peer system.")
    range_column: str = Field(default="range_m", description="Column of measured ranges, m.")
    nlos_column: str | None = Field(
        default=None, description="Evaluation only (simulations): column of 0/1 truth NLOS flags; the filter never "
                                  "reads it, metrics.json reports how the gate treated LOS and NLOS ranges.")
    delimiter: str = Field(default=",", description="Field separator.")

    rows_share_times: ClassVar[bool] = True

    def text_columns(self) -> list[str]:
        return [self.id_column]

    def gap_columns(self) -> list[str]:
        return [self.range_column]


class UwbConfig(StrictModel):
    """A UWB tag worn on a navigation system (``host``), ranging to fixed ``anchors`` and to
    tags worn on other systems (``peers``). Each range is a scalar measurement the fuser
    applies to the host's error state (anchors) or to the host's and the peer's together
    (peers), gated by a chi-square test on its innovation (NLOS outliers). Positions and
    lever arms are ENU, metres."""

    plugin: Literal["uwb"] = "uwb"
    host: str = Field(description="Name of the navigation system that carries the tag.")
    lever_arm_m: Point3_m = Field(
        default=(0.0, 0.0, 0.0),
        description="Offset of the tag's antenna from the host's navigated point, ENU m (a constant offset in the "
                    "navigation frame, e.g. [0, 0, 0.1] for a tag 10 cm above a foot IMU).")
    anchors: dict[str, Point3_m] = Field(default_factory=dict,
                                        description="Fixed anchors: id → surveyed position (east, north, up), m.")
    peers: dict[str, Point3_m] = Field(
        default_factory=dict,
        description="Tags on other navigation systems this tag ranges to: system name → that tag's lever arm, ENU m.")
    ranges: RangeFileConfig
    sigma_m: float = Field(default=0.1, gt=0, description="One-sigma range noise in line of sight, m.")
    gate_probability: float = Field(
        default=0.999, gt=0, lt=1,
        description="Probability that a consistent range passes the chi-square innovation gate (1 dof).")

    @model_validator(mode="after")
    def _ends(self) -> "UwbConfig":
        if not self.anchors and not self.peers:
            raise KeyedError("anchors", "give anchors, peers, or both: the tag ranges to nothing")
        if self.host in self.peers:
            raise KeyedError(f"peers.{self.host}", "the host cannot be its own peer")
        for name in self.peers:
            if name in self.anchors:
                raise KeyedError(f"peers.{name}", "also an anchor id: range ids must name one end")
        return self
