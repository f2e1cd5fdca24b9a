"""The study file: its strict model (layouts, parameter grid, GNSS outages, seeds).

A study file (YAML, strict; paths relative to the study file)::

    name: gnss_outage_study
    layouts:                                  # study name → a scenario or a recorded layout
      foot_hand: {scenario: foot_hand_gnss_outage.yaml}
      recorded:  {layout: my_walk.yaml, set: [truth.alignment=none]}
    parameters:                               # optional grid: any --set path → its values
      layout.fuser.method: [projection, none]
    outages:                                  # optional: one GNSS outage per run
      system: hand_phone                      # the system that loses GNSS
      start_s: 30                             # s on the system's clock (a layout may set outage_start_s)
      durations_s: [0, 10, 20, 30, 40, 60, 120]
    seeds: 20                                 # seeds 0..19, or a list of seeds
    figures: {formats: [png, pdf], dpi: 300}  # optional: the plot files (default PNG, 120 dpi)
    runs_per_task: 8                          # optional: runs a worker takes at once (default: up to 8)
    run_outputs: false                        # optional: true writes each run's files (runs/<run key>/)

``parameters`` and ``set`` paths apply to the file the layout names: a scenario's paths
(``layout.fuser.method``, ``systems.hand_phone.gnss.white_sigma_m``) or a layout's
(``fuser.method``). The study's outage replaces the outage system's own: a scenario's
``systems.<system>.gnss.outages``, a recorded layout's ``outages`` entries for that
system; duration 0 means no outage (and the errors "at the end of the outage" are taken
at ``start_s``, with GNSS on, so the 0-s row is the baseline).

A study writes its rows (``results.parquet``), its summary and plots, and no file per run:
``run_outputs: true`` also writes each run's folder ``runs/<run key>/`` in the output folder
(a scenario's simulated sensor files, ``truth.csv`` and ``config.yaml``, then what ``fusion
run`` writes: trajectories, ``metrics.json``, plots as the layout's ``output`` section says),
at the cost of writing them. ``runs_per_task`` (default: up to 8, fewer when there are not two
tasks per worker) sets how many runs a worker takes at once; runs that differ only in the
scenario's ``layout`` section and the outage share one simulation when they are in one task
(:mod:`bodyfusion.study.grid`). Neither changes a row or a run key.

The model checks the file's own keys and values; :mod:`bodyfusion.study.validation`
checks the layouts and overrides it names.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pydantic import Field, field_validator, model_validator

from bodyfusion.base.sections import DataPath, FiguresConfig, StrictModel


class StudyLayout(StrictModel):
    """One layout of the study: exactly one of ``scenario`` (simulated per run) or ``layout``
    (recorded data); ``set``: fixed overrides (KEY=VALUE); ``outage_start_s``: this layout's
    outage start, s (default the study's ``outages.start_s``)."""

    scenario: DataPath | None = None
    layout: DataPath | None = None
    set: list[str] = Field(default_factory=list)
    outage_start_s: float | None = Field(default=None, ge=0)

    @model_validator(mode="after")
    def _one_source(self) -> "StudyLayout":
        if (self.scenario is None) == (self.layout is None):
            raise ValueError("give exactly one of scenario or layout")
        return self

    @property
    def source(self) -> str:
        """``scenario`` or ``layout``: the key that names the file."""
        return "scenario" if self.scenario is not None else "layout"

    @property
    def file(self) -> Path:
        return self.scenario if self.scenario is not None else self.layout  # type: ignore[return-value]


class StudyOutages(StrictModel):
    """GNSS outage windows: the ``system`` loses GNSS at ``start_s`` (s) for each of ``durations_s`` (s; 0: none)."""

    system: str
    start_s: float = Field(ge=0)
    durations_s: list[float] = Field(min_length=1)

    @field_validator("durations_s")
    @classmethod
    def _durations(cls, v: list[float]) -> list[float]:
        if any(not math.isfinite(d) or d < 0 for d in v):
            raise ValueError("durations must be finite and >= 0 s")
        if len(set(v)) != len(v):
            raise ValueError("durations repeat")
        return v


MAX_SEEDS = 100_000
"""Most seeds of a study (a count, or a list's length): 100,000 runs per grid point."""
MAX_SEED = 2**32 - 1
"""Largest seed (numpy's seed range of one 32-bit word)."""


class StudySpec(StrictModel):
    """The study file (module docstring)."""

    name: str | None = None
    layouts: dict[str, StudyLayout] = Field(min_length=1)
    parameters: dict[str, list[Any]] = Field(default_factory=dict)
    outages: StudyOutages | None = None
    seeds: int | list[int]
    figures: FiguresConfig = Field(default_factory=FiguresConfig)
    runs_per_task: int | None = Field(default=None, ge=1, le=1_000_000)
    run_outputs: bool = False

    @field_validator("parameters")
    @classmethod
    def _parameters(cls, v: dict[str, list[Any]]) -> dict[str, list[Any]]:
        for path, values in v.items():
            if not values:
                raise ValueError(f"{path}: give at least one value")
        return v

    @field_validator("seeds")
    @classmethod
    def _seeds(cls, v: int | list[int]) -> int | list[int]:
        """A count of seeds (1 … :data:`MAX_SEEDS`) or distinct seeds (0 … :data:`MAX_SEED`), checked
        before any list of them is made."""
        count = v if isinstance(v, int) else len(v)
        if not 1 <= count <= MAX_SEEDS:
            raise ValueError(f"{count} seeds: give 1 to {MAX_SEEDS}")
        if isinstance(v, list):
            if any(not 0 <= s <= MAX_SEED for s in v):
                raise ValueError(f"a seed is 0 … {MAX_SEED}")
            if len(set(v)) != len(v):
                raise ValueError("seeds repeat")
        return v

    @property
    def seed_list(self) -> list[int]:
        return list(range(self.seeds)) if isinstance(self.seeds, int) else list(self.seeds)

    def outage_windows(self, entry: StudyLayout) -> list[tuple[str, float, float]]:
        """(system, start s, duration s) of each outage duration for one layout; empty without outages."""
        if self.outages is None:
            return []
        start = float(entry.outage_start_s if entry.outage_start_s is not None else self.outages.start_s)
        return [(self.outages.system, start, float(d)) for d in self.outages.durations_s]


@dataclass(frozen=True)
class LoadedStudy:
    """A validated study: its file, model and name."""

    path: Path
    spec: StudySpec

    @property
    def name(self) -> str:
        return self.spec.name or self.path.stem
