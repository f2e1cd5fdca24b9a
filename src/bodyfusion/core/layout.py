"""Layouts: the YAML file that says which systems are worn, their data, and how they are fused.

Validation is strict (unknown keys are refused) and two-staged: the core checks the
layout's shape here; each system's own section is then checked by its plugin's
``Config`` model (see :mod:`bodyfusion.core.registry`). Every error names the file and the
dotted path of the offending key. Relative paths resolve against the config file's folder.
"""

from __future__ import annotations

import hashlib
import json
import re
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator

from bodyfusion.base.errors import ConfigError
from bodyfusion.base.sections import DataPath, FiguresConfig, GeodeticPoint, KeyedError, StrictModel, TableSection
from bodyfusion.core import registry as plugin_registry
from bodyfusion.core.body import body_limit
from bodyfusion.core.data_tables import bind_tables, require_data
from bodyfusion.core.layout_io import apply_overrides, plain, read_yaml, validate_section
from bodyfusion.nav.frames import NAMED_FRAMES, AxisMap, AxisSigns


class PositionFrame(StrictModel):
    """The frame of positions read from a file (truth, position fixes)."""

    frame: Literal["enu", "ned"] | AxisMap = "enu"
    """The file's position frame: ``enu``, ``ned`` or a signed axis map such as ``[x, -y, -z]``."""
    axis_signs: AxisSigns | None = None
    """Older spelling of a sign-only ``frame`` (``[1, -1, -1]`` is ``[x, -y, -z]``)."""

    @property
    def axes(self) -> tuple[str, str, str]:
        """The file's frame as an axis map into east, north, up."""
        if self.axis_signs is not None:
            return tuple(("-" if s < 0 else "") + a for s, a in zip(self.axis_signs, "xyz"))  # type: ignore[return-value]
        return NAMED_FRAMES[self.frame] if isinstance(self.frame, str) else self.frame

    @model_validator(mode="after")
    def _one_frame(self) -> "PositionFrame":
        if self.axis_signs is not None and self.frame != "enu":
            raise KeyedError("axis_signs", "give frame or axis_signs, not both")
        return self


class SystemSection(BaseModel):
    """A system's section as the core sees it: its plugin name; the rest is the plugin's."""

    model_config = ConfigDict(extra="allow")
    plugin: str


class ConstraintConfig(StrictModel):
    """A distance limit between two systems' positions (m), horizontal by default."""

    between: tuple[str, str]
    kind: Literal["max", "min", "fixed"] = "max"
    distance_m: float | Literal["body"] = "body"
    """The limit, m; ``body`` (the default, ``max`` only): where the two are worn and the wearer's
    height say, widened to the gait's stride (:mod:`bodyfusion.core.limits`)."""
    horizontal: bool = True
    lever_arms_m: dict[str, tuple[float, float, float]] = Field(default_factory=dict)
    """Per system, the offset (ENU, m) from its navigated point to the constrained point."""

    @model_validator(mode="after")
    def _body_limits_are_maxima(self) -> "ConstraintConfig":
        if self.distance_m == "body" and self.kind != "max":
            raise KeyedError("distance_m", f"a {self.kind} limit needs a distance in metres (body: max limits only)")
        if self.distance_m != "body" and not self.distance_m > 0:
            raise KeyedError("distance_m", f"must be > 0 m, got {self.distance_m}")
        return self


class BodyConfig(StrictModel):
    """The wearer, whose proportions give the default distance limits (:mod:`bodyfusion.core.limits`)."""

    height_m: float = Field(default=1.75, ge=1.0, le=2.3)
    """Standing height, m."""


class OutageConfig(StrictModel):
    """A window (s, on the system's clock) in which a system's GNSS is masked."""

    system: str
    start_s: float
    duration_s: float = Field(gt=0)


class FuserConfig(StrictModel):
    """How constraints are enforced.

    method: ``projection`` (linearised, active set; [KFSC2015] eqs. 55–60; the default),
    ``qp`` (OSQP, re-linearised), ``socp`` (cvxpy), or ``none`` (systems run independently:
    the constraints are not enforced).
    epochs: when constraints are enforced — at the constrained systems' ``events``
    (stance starts, steps), every ``interval_s`` seconds, or at every ``sample`` of
    any constrained system. tolerance_m / max_iterations bound the nonlinear solve.
    cross_covariance: keep the cross-covariances a constraint creates between systems
    (the papers drop them). correct: spread the correction to ``all`` error states through
    their covariance with position (the papers), or correct ``positions`` only and keep the
    other states as Schmidt consider states (robust when those correlations are poorly known).
    inequality: what a ``max``/``min`` limit does to the estimate — ``truncation`` (the
    default) takes the mean and covariance of the estimate's density cut at the bound
    ([Simon2010]: a violation of a fraction of σ moves the estimate by less and keeps most of
    its spread), wherever the density crosses the bound, also where the mean keeps the limit
    (within :data:`~bodyfusion.core.constraints.truncation.TAIL_BETA` σ of it); ``projection`` acts only on a
    broken limit, puts the estimate on the bound and shrinks its covariance as for an equality
    ([KFSC2015] eqs. 58–60: no spread left across the bound). ``fixed`` limits are equalities
    either way.
    """

    method: Literal["none", "projection", "qp", "socp"] = "projection"
    """How the layout's constraints are enforced; ``none`` turns them off (said on the console)."""
    epochs: Literal["events", "interval", "sample"] = "events"
    interval_s: float = Field(default=0.5, ge=1e-3)
    tolerance_m: float = Field(default=1e-6, gt=0)
    max_iterations: int = Field(default=20, ge=1, le=1000)
    cross_covariance: bool = False
    correct: Literal["all", "positions"] = "all"
    inequality: Literal["projection", "truncation"] = "truncation"
    relax_fights: bool = True
    """Relax a limit the estimates keep breaking while both are confident (it fights them,
    :mod:`bodyfusion.core.limits`) instead of pulling both tracks; it is reported either way."""


class SmootherConfig(StrictModel):
    """Smoothing of the systems that support it (the foot INS), after the fuser
    (:mod:`bodyfusion.plugins.foot_ins.smoothing`, [Shen2025] §3).

    ``kind``: ``none``; ``rts`` (fixed-interval Rauch–Tung–Striebel over the forward filter's
    error states); ``fixed-lag`` (each segment RTS-smoothed with the data up to the first
    segment boundary at least ``lag_s`` after its end: what a live run can emit with that
    delay, :func:`bodyfusion.plugins.foot_ins.smoothing.lag_windows`); ``fb`` (forward–backward: the filter and a backward navigation started
    without information, fused by covariance, position recomputed from the fused velocity);
    ``fb-rts`` (both passes RTS-smoothed before the fusion). Segments run between stance
    midpoints (stance runs shorter than ``min_stance_s`` are ignored; segments longer than
    ``max_segment_s`` are split).

    ``span``: ``whole`` (the default of ``rts``: one RTS sweep over the whole run) or
    ``segment`` (each segment on its own, the paper's segmented RTS; ``fb`` and ``fb-rts``
    always run per segment). Distance constraints act in the forward pass through the fuser
    (``fuser.method``); the smoothers keep the fuser's corrections as the filter made them
    (each foot is smoothed on its own and cannot re-derive a correction made from the other
    foot's estimate), and ``constrain_smoothed`` applies the constraints again on the smoothed
    tracks, so that they hold there too: by default (unset) wherever the fuser enforces them
    (``fuser.method`` not ``none``); ``true`` also after independent filters; ``false`` never.

    ``joint`` (default true): where the fuser tracks cross-covariances (``fuser.cross_covariance``),
    the whole-run RTS smooths the systems it corrected together as one stacked state
    (:mod:`bodyfusion.core.joint_smoothing`): each correction derived from several systems is
    information for all of their smoothed tracks, not a known input of each; the constraints then
    need not be applied again (``constrain_smoothed`` unset means false there). Without tracked
    cross-covariances, or where a member cannot take part, each system is smoothed on its own.
    """

    kind: Literal["none", "rts", "fixed-lag", "fb", "fb-rts"] = "none"
    span: Literal["whole", "segment"] | None = None
    lag_s: float = Field(default=2.0, gt=0, le=3600.0)
    """The fixed-lag smoother's least delay (s): the future data each estimate is smoothed with."""
    min_stance_s: float = Field(default=0.04, ge=0)
    max_segment_s: float = Field(default=10.0, gt=0)
    constrain_smoothed: bool | None = None
    joint: bool = True

    @model_validator(mode="after")
    def _span_of_kind(self) -> "SmootherConfig":
        if self.kind in ("fb", "fb-rts", "fixed-lag") and self.span == "whole":
            raise KeyedError("span", f"{self.kind} runs per segment; whole applies to rts only")
        return self

    @property
    def rts_sweep(self) -> bool:
        """An RTS sweep over the filter's record (``rts``, ``fixed-lag``)."""
        return self.kind in ("rts", "fixed-lag")

    def smooths_jointly(self, fuser: FuserConfig) -> bool:
        """The whole-run RTS of the fuser's tracked joint state (``joint`` and
        ``fuser.cross_covariance``)."""
        return self.joint and self.kind == "rts" and not self.segmented and fuser.cross_covariance

    @property
    def segmented(self) -> bool:
        """Every segment smoothed on its own (``fb``, ``fb-rts``, ``rts`` with ``span: segment``)."""
        return self.kind != "rts" or self.span == "segment"


class HeadingAlignmentConfig(StrictModel):
    """Puts systems worn together in one navigation frame (:mod:`bodyfusion.core.heading`).

    Systems whose ``initial.heading_deg`` is ``auto`` (a foot INS's default) are rotated about
    their start so that their first ``distance_m`` of travel points the same way as the
    reference system's (``reference``, else one with a geographic heading, else the first with
    a numeric one, else the first that travels). With ``continuous`` the fuser then measures
    every other system's heading against the reference's over each ``window_m`` of travel and
    corrects both (their paths' lateral difference σ ``lateral_sd_m`` per stretch).
    """

    reference: str | None = None
    distance_m: float = Field(default=3.0, gt=0)
    continuous: bool = True
    """Keep estimating the relative headings through the run (off: aligned once at the start)."""
    window_m: float = Field(default=10.0, gt=0, le=1e4)
    """Travel (m) of each stretch whose displacements measure a relative heading."""
    lateral_sd_m: float = Field(default=0.1, gt=0, le=100)
    """One-sigma lateral difference (m) of two dead-reckoned paths over a stretch (stance width,
    gait phase)."""


LENGTH_UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001, "ft": 0.3048, "in": 0.0254}
"""Metres per unit of a truth file's positions (``truth.unit``)."""


class TruthConfig(PositionFrame, TableSection):
    """Reference positions (ENU, m) for scoring; ``loop`` when the walk ends where it began.
    From the file ``path`` or a table given in memory (:func:`bodyfusion.run`'s ``truth``).

    ``wide``: one row per epoch, ``systems`` maps each system to its three columns.
    ``long``: the ``system,t,east_m,north_m,up_m`` shape that ``fusion simulate`` writes.
    ``phone_log``: the surveyed points (POSI lines) of a GetSensorData log, sparse truth
    for ``score_systems``, converted to ENU about the layout's geodetic origin.
    ``frame`` declares the file's position axes: ``enu``, ``ned`` or a signed axis map
    (:data:`AxisMap`) into east, north, up. A system given two columns is horizontal truth
    (its axes are the map's first two entries' sources; vertical errors are not scored).
    ``unit``: the wide file's position unit (:data:`LENGTH_UNITS`).
    """

    path: DataPath | None = None
    """The file; unset: no truth, or the truth given in memory."""
    unit: Literal["m", "cm", "mm", "ft", "in"] = "m"
    format: Literal["wide", "long", "phone_log"] = "wide"
    systems: dict[str, tuple[str, str, str] | tuple[str, str]] = Field(default_factory=dict)
    """wide format: each system's position columns, x, y[, z] of the file's frame."""
    score_systems: list[str] = Field(default_factory=list)
    """phone_log format: the systems scored at the log's surveyed points (POSI lines)."""
    time_column: str | None = None
    time_scale: float = Field(default=1.0, gt=0, le=1e6)
    rate_hz: float | None = Field(default=None, gt=0)
    skip_rows: int = Field(default=0, ge=0, le=10_000_000)
    delimiter: str = ","
    sparse: bool = False
    loop: bool = False
    alignment: Literal["first_3m", "none"] = "first_3m"
    alignment_distance_m: float = Field(default=3.0, gt=0)

    def needs_data(self) -> bool:
        """A truth section says how a truth table is read; without one the run has no truth."""
        return False

    def required_columns(self) -> list[str]:
        """``wide``: the time column and every system's position columns; ``long``: the columns
        ``fusion simulate`` writes; ``phone_log``: none (a log, not a table)."""
        if self.format == "long":
            return ["system", "t", "east_m", "north_m", "up_m"]
        if self.format == "phone_log":
            return []
        return [*super().required_columns(), *(c for columns in self.systems.values() for c in columns)]

    @model_validator(mode="after")
    def _time_source(self) -> "TruthConfig":
        if self.path is None or self.format == "long":
            return self
        if self.format == "phone_log":
            if not self.score_systems:
                raise ValueError("score_systems: name the systems to score at the surveyed points")
            return self
        if (self.time_column is None) == (self.rate_hz is None):
            raise ValueError("give exactly one of time_column or rate_hz")
        if not self.systems:
            raise ValueError("systems: name the position columns of at least one system")
        return self


class OutputConfig(StrictModel):
    """What a run writes: ``dir`` (default ``./out/<layout name>``), the ``plots`` (on or off)
    in the ``figures`` formats and resolution, every ``decimate``-th trajectory sample."""

    dir: DataPath | None = None
    plots: bool = True
    figures: FiguresConfig = Field(default_factory=FiguresConfig)
    decimate: int = Field(default=1, ge=1, le=1_000_000)


def _check_feasible(constraints: list[ConstraintConfig]) -> None:
    """Refuse a constraint set no positions can satisfy: a minimum separation (``min`` or
    ``fixed``) larger than the longest the maximum separations allow between the two systems
    through any chain of others (triangle inequality; a horizontal limit bounds only
    horizontal distances, a 3-D one both). Constraints with lever arms are left out (their
    arms loosen the bound)."""
    plain = [(k, c) for k, c in enumerate(constraints) if not c.lever_arms_m and c.distance_m != "body"]
    names = sorted({n for _, c in plain for n in c.between})
    index = {n: i for i, n in enumerate(names)}
    for horizontal in (True, False):
        far = [[0.0 if i == j else float("inf") for j in range(len(names))] for i in range(len(names))]
        for _, c in plain:  # a 3-D limit bounds the horizontal distance too, not the reverse
            if c.kind in ("max", "fixed") and (horizontal or not c.horizontal):
                i, j = index[c.between[0]], index[c.between[1]]
                far[i][j] = far[j][i] = min(far[i][j], c.distance_m)
        for m in range(len(names)):  # Floyd–Warshall: the loosest chain of maxima
            for i in range(len(names)):
                for j in range(len(names)):
                    far[i][j] = min(far[i][j], far[i][m] + far[m][j])
        for k, c in plain:
            if c.kind in ("min", "fixed") and c.horizontal == horizontal:
                bound = far[index[c.between[0]]][index[c.between[1]]]
                if c.distance_m > bound + 1e-9:
                    raise KeyedError(f"constraints.{k}.distance_m", f"{c.distance_m:g} m apart cannot hold: the "
                                                                    f"maximum separations keep {c.between[0]} and "
                                                                    f"{c.between[1]} within {bound:g} m")


FILE_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]{0,63}")
FILE_NAME_RULE = "letters, digits, '_', '-' and '.', starting with a letter or digit, at most 64, no '..'"
"""What a system's or a layout's name may hold: it names files and folders of the outputs."""


def is_file_name(name: str) -> bool:
    """Whether ``name`` is safe as a file or folder name on every system (:data:`FILE_NAME_RULE`)."""
    return FILE_NAME.fullmatch(name) is not None and ".." not in name


class Layout(StrictModel):
    """A whole body layout. ``systems`` maps a name to its plugin section."""

    name: str | None = None
    gravity_mps2: float | None = Field(default=None, gt=9.7, lt=9.9)
    latitude_deg: float = Field(default=45.0, ge=-90, le=90)
    height_m: float = 0.0
    geodetic_origin: GeodeticPoint | None = None
    """Latitude (deg), longitude (deg), height (m) of the ENU frame's origin, for GNSS,
    surveyed points and geo-referenced output; unset: the first GNSS fix."""
    systems: dict[str, SystemSection]
    outages: list[OutageConfig] = Field(default_factory=list)
    heading_alignment: HeadingAlignmentConfig = Field(default_factory=HeadingAlignmentConfig)
    body: BodyConfig = Field(default_factory=BodyConfig)
    constraints: list[ConstraintConfig] = Field(default_factory=list)
    fuser: FuserConfig = Field(default_factory=FuserConfig)
    smoother: SmootherConfig = Field(default_factory=SmootherConfig)
    truth: TruthConfig | None = None
    output: OutputConfig = Field(default_factory=OutputConfig)

    @model_validator(mode="after")
    def _cross_references(self) -> "Layout":
        if not self.systems:
            raise ValueError("systems: at least one system is needed")
        for name in self.systems:
            if not is_file_name(name):
                raise KeyedError("systems", f"{name!r} is not a system name: {FILE_NAME_RULE} (it names files in the "
                                            "output folder)")
        if self.name is not None and not is_file_name(self.name):
            raise KeyedError("name", f"{self.name!r} is not a layout name: {FILE_NAME_RULE} (it names the output folder)")
        names = set(self.systems)
        ref = self.heading_alignment.reference
        if ref is not None and ref not in names:
            raise KeyedError("heading_alignment.reference", f"unknown system {ref!r} (have {sorted(names)})")
        for k, c in enumerate(self.constraints):
            for side in c.between:
                if side not in names:
                    raise KeyedError(f"constraints.{k}.between", f"unknown system {side!r} (have {sorted(names)})")
            if c.between[0] == c.between[1]:
                raise KeyedError(f"constraints.{k}.between", "a constraint needs two different systems")
            for side in c.lever_arms_m:
                if side not in c.between:
                    raise KeyedError(f"constraints.{k}.lever_arms_m.{side}", "not one of the constrained systems")
        bounds: dict[frozenset[str], dict[str, float]] = {}
        for k, c in enumerate(self.constraints):
            if c.distance_m == "body":
                continue
            pair = bounds.setdefault(frozenset(c.between), {})
            pair[c.kind] = c.distance_m
            if "min" in pair and "max" in pair and pair["min"] > pair["max"]:
                raise KeyedError(f"constraints.{k}.distance_m", "minimum separation exceeds the maximum for this pair")
        _check_feasible(self.constraints)
        for k, outage in enumerate(self.outages):
            if outage.system not in names:
                raise KeyedError(f"outages.{k}.system", f"unknown system {outage.system!r} (have {sorted(names)})")
        if self.truth is not None:
            for k, sys_name in enumerate(self.truth.score_systems):
                if sys_name not in names:
                    raise KeyedError(f"truth.score_systems.{k}", f"unknown system (have {sorted(names)})")
            for sys_name in self.truth.systems:
                if sys_name not in names:
                    raise KeyedError(f"truth.systems.{sys_name}", f"unknown system (have {sorted(names)})")
        return self


class LoadedLayout:
    """A validated layout with each system's section validated by its plugin.

    Attributes: ``path`` (its file; None for a layout built in code), ``base_dir`` (the folder
    relative paths resolve against), ``layout`` (:class:`Layout`), ``system_configs`` (name →
    plugin config model), ``raw`` (the dict it was validated from, after overrides), ``tables``
    (dotted key of a table section → the in-memory table given for it). Every model validates a
    field set on it (``loaded.fuser.method = "bogus"`` raises :class:`pydantic.ValidationError`);
    a :class:`Layout` field read or set on the loaded layout is the :attr:`layout`'s, and
    :attr:`systems` are the plugin models. :meth:`checked` validates the whole again (the
    cross-field and plugin checks) and :attr:`sha256` hashes the models as they are now.
    """

    def __init__(self, path: Path | None, layout: Layout, system_configs: dict[str, BaseModel], raw: dict[str, Any],
                 base_dir: Path | None = None, tables: dict[str, Any] | None = None) -> None:
        self.path = path
        self.base_dir = base_dir if base_dir is not None else (path.resolve().parent if path else Path.cwd())
        self.layout = layout
        self.system_configs = system_configs
        self.raw = raw
        self.tables = dict(tables or {})

    def __getattr__(self, name: str) -> Any:
        layout = self.__dict__.get("layout")
        if layout is not None and name in Layout.model_fields:
            return getattr(layout, name)
        raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")

    def __setattr__(self, name: str, value: Any) -> None:
        if name in Layout.model_fields and name != "systems" and "layout" in self.__dict__:
            setattr(self.layout, name, value)
        else:
            super().__setattr__(name, value)

    @property
    def name(self) -> str:
        return self.layout.name or (self.path.stem if self.path is not None else "layout")

    @property
    def systems(self) -> dict[str, BaseModel]:
        """Name → the system's plugin config model (:attr:`system_configs`)."""
        return self.system_configs

    def to_dict(self) -> dict[str, Any]:
        """The layout as its models hold it now, as a plain dict (every field, defaults included;
        paths under :attr:`base_dir` relative to it)."""
        out = plain(self.layout, self.base_dir)
        out["systems"] = {name: plain(cfg, self.base_dir) for name, cfg in self.system_configs.items()}
        return out

    @property
    def sha256(self) -> str:
        """SHA-256 (hex) of :meth:`to_dict`, computed when asked: an edited model is never stale.
        In-memory tables are named by their sections, not hashed."""
        return hashlib.sha256(json.dumps(self.to_dict(), sort_keys=True, default=str).encode()).hexdigest()

    def checked(self) -> LoadedLayout:
        """The layout validated again as a whole from its models (after fields were set on them):
        every cross-field and plugin check; the tables are kept."""
        return validate_layout(self.to_dict(), self.path, self.base_dir, tables=self.tables)


def load_layout(path: str | Path, overrides: Sequence[str] | Mapping[str, Any] | None = None,
                registry: Any = None) -> LoadedLayout:
    """Read, override, and validate a layout file (both stages); every table section it has
    names its file."""
    path = Path(path)
    try:
        raw = apply_overrides(read_yaml(path), overrides or [])
    except ConfigError as err:
        if err.path is not None:
            raise
        raise ConfigError(err.key, err.reason, path) from None
    loaded = validate_layout(raw, path, path.resolve().parent, registry)
    require_data(loaded.layout, loaded.system_configs, path)
    return loaded


def validate_layout(raw: dict[str, Any], path: Path | None, base_dir: Path, registry: Any = None,
                    tables: dict[str, Any] | None = None) -> LoadedLayout:
    """Validate a raw layout dict (both stages); relative paths resolve against ``base_dir``;
    ``path``: the file it came from, named in errors (None: built in code); ``tables``: dotted key
    of a table section → the in-memory table bound to it. Every section is validated before an
    error is raised: the error is the first found, its ``others`` the rest (``fusion validate``
    lists them all)."""
    errors: list[ConfigError] = []
    try:
        layout = validate_section(Layout, raw, key="", path=path, base_dir=base_dir)
    except ConfigError as err:
        layout, errors = None, err.every()
    registry = registry or plugin_registry.get_registry()
    system_configs: dict[str, BaseModel] = {}
    sections = raw.get("systems") if isinstance(raw, dict) else None
    for name, section in (sections.items() if isinstance(sections, dict) else ()):
        try:
            if not isinstance(section, dict) or "plugin" not in section:
                continue  # the layout's own check said what is wrong with it
            system_cls = registry.system_class(section["plugin"], key=f"systems.{name}.plugin", path=path)
            system_configs[name] = validate_section(system_cls.Config, section, key=f"systems.{name}", path=path,
                                                    base_dir=base_dir)
            check_layout = getattr(system_cls, "check_layout", None)  # optional: refuse unsupported layout settings
            if check_layout is not None and layout is not None:
                try:
                    check_layout(name, system_configs[name], layout)
                except KeyedError as err:
                    raise ConfigError(err.key, str(err), path) from None
        except ConfigError as err:
            seen = {str(x) for x in errors}  # a system's error the layout's own check found too
            errors += [e for e in err.every() if str(e) not in seen]
    if errors:
        raise ConfigError.of(errors)
    _check_aiding_references(layout, system_configs, registry, path)
    bind_tables(layout, system_configs, tables or {}, path)
    return LoadedLayout(path, layout, system_configs, raw, base_dir, tables)


def _check_aiding_references(layout: Layout, system_configs: dict[str, BaseModel], registry: Any, path: Path) -> None:
    """Aiding sources (:class:`bodyfusion.core.system.AidingSource`) name navigation systems, and
    constraints and the heading reference name navigation systems, not aiding sources."""
    classes = {name: registry.system_class(cfg.plugin) for name, cfg in system_configs.items()}
    aiding = {name for name, cls in classes.items() if not cls.navigates}
    navigators = sorted(set(system_configs) - aiding)
    if not navigators:
        raise ConfigError("systems", "no navigation system: aiding sources need a host", path)
    for name in sorted(aiding):
        for key, ref in classes[name].system_references(system_configs[name]):
            if ref not in navigators:
                raise ConfigError(f"systems.{name}.{key}", f"{ref!r} is not a navigation system of this layout "
                                                           f"(have {navigators})", path)
    for k, c in enumerate(layout.constraints):
        for side in c.between:
            if side in aiding:
                raise ConfigError(f"constraints.{k}.between", f"{side!r} is an aiding source, not a navigation system",
                                  path)
    if layout.heading_alignment.reference in aiding:
        raise ConfigError("heading_alignment.reference", "an aiding source has no heading", path)
    for k, c in enumerate(layout.constraints):
        parts = [classes[side].body_part for side in c.between]
        if c.distance_m == "body" and body_limit(*parts, layout.body.height_m) is None:
            raise ConfigError(f"constraints.{k}.distance_m", f"the body gives no limit between {c.between[0]} "
                              f"({parts[0] or 'unknown part'}) and {c.between[1]} ({parts[1] or 'unknown part'}): "
                              "give distance_m in metres", path)
