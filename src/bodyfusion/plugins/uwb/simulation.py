"""A simulated UWB tag (scenario ``kind: uwb_tag``): two-way ranges from a tag on one
simulated system to fixed anchors and to tags on other simulated systems.

Geometry: the tag's antenna is at the host's true position plus ``lever_arm_m`` (ENU, m,
constant in the navigation frame); a peer's antenna likewise on its system. Rangings
happen at ``rate_hz`` on the scenario's sample grid (every rate/``rate_hz``-th IMU sample,
so their times are IMU sample times), all links at each ranging epoch.

Errors, per link (anchor or peer), each from its own random stream:

* line of sight: white Gaussian noise, σ ``sigma_m``;
* non-line of sight: a two-state Markov chain at the ranging rate spends on average
  ``nlos.fraction`` of the time in NLOS, in bursts of mean length ``nlos.mean_duration_s``
  (P(NLOS→LOS) = Δt / mean duration per ranging, P(LOS→NLOS) chosen for the fraction;
  the chain starts in its stationary distribution). In a burst every range is longer by
  a positive bias drawn once per burst, uniform in [``nlos.bias_min_m``, ``nlos.bias_max_m``],
  plus white noise of σ ``nlos.sigma_m`` (the excess path round the body or a wall);
* dropouts: each ranging fails with ``dropout_probability`` and is written with an
  empty range (the reader counts and drops it).

Written: ``<name>_ranges.csv`` with ``t,id,range_m,nlos`` (``nlos``: the truth flag, for
evaluation; the generated layout names it ``ranges.nlos_column``), and a
``plugin: uwb`` layout section built with :class:`~bodyfusion.plugins.uwb.config.UwbConfig`.
A tag has no truth track of its own.

Random numbers: ``system_seed(seed, name + "#uwb")`` spawned into one stream per link,
in the order anchors then peers.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Literal

import numpy as np
from pydantic import Field, model_validator

from bodyfusion.base.errors import ConfigError
from bodyfusion.base.sections import KeyedError, Point3_m, StrictModel
from bodyfusion.base.seeding import system_seed
from bodyfusion.plugins.uwb.config import RangeFileConfig, UwbConfig
from bodyfusion.sim.context import SimContext, SystemKind, SystemOutput, layout_section
from bodyfusion.sim.files import SimFile, printed


__all__ = ["NlosConfig", "RANGE_COLUMNS", "SIMULATION_KINDS", "UwbTagSystem", "link_ranges", "nlos_states",
           "ranges_file", "simulate_uwb_tag"]

RANGE_COLUMNS = ("t", "id", "range_m", "nlos")
class NlosConfig(StrictModel):
    """NLOS bursts of one link (see the module docstring): ``fraction`` of the time in NLOS,
    bursts of mean length ``mean_duration_s``, bias per burst uniform in
    [``bias_min_m``, ``bias_max_m``], white noise ``sigma_m`` in a burst."""

    fraction: float = Field(default=0.0, ge=0, lt=1)
    mean_duration_s: float = Field(default=1.5, gt=0)
    bias_min_m: float = Field(default=0.3, ge=0)
    bias_max_m: float = Field(default=2.0, ge=0)
    sigma_m: float = Field(default=0.3, ge=0)

    @model_validator(mode="after")
    def _bias_range(self) -> "NlosConfig":
        if self.bias_max_m < self.bias_min_m:
            raise KeyedError("bias_max_m", "must be at least bias_min_m")
        return self


class UwbTagSystem(StrictModel):
    """A UWB tag on the simulated system ``host`` (``kind: uwb_tag``), ranging to ``anchors``
    (id → position, ENU m) and to ``peers`` (simulated system → its tag's lever arm, ENU m)
    at ``rate_hz``; ``lever_arm_m``: the tag's offset from the host's point (ENU m);
    ``sigma_m``: line-of-sight noise (m); ``nlos``: :class:`NlosConfig`;
    ``dropout_probability``: chance that a ranging fails."""

    kind: Literal["uwb_tag"]
    host: str
    lever_arm_m: Point3_m = (0.0, 0.0, 0.0)
    anchors: dict[str, Point3_m] = Field(default_factory=dict)
    peers: dict[str, Point3_m] = Field(default_factory=dict)
    rate_hz: float = Field(default=10.0, gt=0)
    sigma_m: float = Field(default=0.1, gt=0)
    nlos: NlosConfig = Field(default_factory=NlosConfig)
    dropout_probability: float = Field(default=0.0, ge=0, lt=1)

    @model_validator(mode="after")
    def _ends(self) -> "UwbTagSystem":
        if not self.anchors and not self.peers:
            raise KeyedError("anchors", "give anchors, peers, or both: the tag ranges to nothing")
        for name in self.peers:
            if name in self.anchors or name == self.host:
                raise KeyedError(f"peers.{name}", "a peer must be another system, not an anchor id or the host")
        return self


def nlos_states(n: int, dt: float, cfg: NlosConfig, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """NLOS flags (n,) of a two-state Markov chain at step ``dt`` (s) and the bias (n,) (m,
    0 in LOS, one uniform draw per burst)."""
    flags = np.zeros(n, dtype=bool)
    bias = np.zeros(n)
    if cfg.fraction == 0.0 or n == 0:
        return flags, bias
    p_out = min(1.0, dt / cfg.mean_duration_s)
    p_in = min(1.0, cfg.fraction * p_out / (1.0 - cfg.fraction))
    nlos = bool(rng.random() < cfg.fraction)
    i = 0
    while i < n:
        length = int(rng.geometric(p_out if nlos else p_in))
        if nlos:
            flags[i:i + length] = True
            bias[i:i + length] = rng.uniform(cfg.bias_min_m, cfg.bias_max_m)
        i += length
        nlos = not nlos
    return flags, bias


def link_ranges(true_range_m: np.ndarray, dt: float, cfg: UwbTagSystem,
                rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Measured ranges (NaN: dropout) and NLOS flags of one link from its true ranges (m)."""
    n = true_range_m.size
    flags, bias = nlos_states(n, dt, cfg.nlos, rng)
    noise = rng.standard_normal(n) * np.where(flags, cfg.nlos.sigma_m, cfg.sigma_m)
    measured = np.abs(true_range_m + bias + noise)
    measured[rng.random(n) < cfg.dropout_probability] = np.nan
    return measured, flags


def write_ranges_csv(path: Path, t: np.ndarray, ids: list[str], range_m: np.ndarray, nlos: np.ndarray) -> None:
    """``t,id,range_m,nlos``: rows epoch by epoch, links in ``ids`` order; range_m (K, L),
    nlos (K, L); a NaN range is written as an empty cell."""
    with path.open("w") as fh:
        fh.write(",".join(RANGE_COLUMNS) + "\n")
        for k, tk in enumerate(t):
            for j, end in enumerate(ids):
                r = range_m[k, j]
                fh.write(f"{tk:.10g},{end},{'' if math.isnan(r) else f'{r:.4f}'},{int(nlos[k, j])}\n")


def ranges_file(section: str, name: str, t: np.ndarray, ids: list[str], range_m: np.ndarray,
                nlos: np.ndarray) -> SimFile:
    """The ranges file :func:`write_ranges_csv` writes, as a :class:`~bodyfusion.sim.files.SimFile`
    read by the layout section ``section``: its rows (epoch by epoch, links in ``ids`` order) at
    the printed precision, a failed ranging NaN."""
    columns = {"t": printed(np.repeat(t, len(ids)), "%.10g"),
               "id": np.tile(np.asarray(ids, dtype=object), len(t)),
               "range_m": printed(range_m.ravel(), "%.4f"), "nlos": nlos.ravel()}
    return SimFile(section, name, columns, lambda path: write_ranges_csv(path, t, ids, range_m, nlos))


def simulate_uwb_tag(name: str, cfg: UwbTagSystem, ctx: SimContext) -> SystemOutput:
    """Ranges of tag ``name`` from the true tracks of its host and peers (already simulated)."""

    key = f"systems.{name}"
    for ref_key, ref in (("host", cfg.host), *((f"peers.{p}", p) for p in cfg.peers)):
        out = ctx.outputs.get(ref)
        if out is None or out.truth_t.size == 0:
            raise ConfigError(f"{key}.{ref_key}", f"{ref!r} is not a simulated navigation system")
    rate = ctx.rate_hz
    step = rate / cfg.rate_hz
    if abs(step - round(step)) > 1e-9:
        raise ConfigError(f"{key}.rate_hz", f"must divide the scenario's rate_hz {rate:g} (rangings at IMU samples)")
    idx = np.arange(0, ctx.t.size, int(round(step)))
    t = ctx.t[idx]

    def antenna(system: str, lever: Point3_m) -> np.ndarray:
        out = ctx.outputs[system]
        pos = np.column_stack([np.interp(t, out.truth_t, out.truth_pos[:, c]) for c in range(3)])
        return pos + np.asarray(lever, dtype=float)

    tag = antenna(cfg.host, cfg.lever_arm_m)
    others = [np.broadcast_to(np.asarray(a, dtype=float), tag.shape) for a in cfg.anchors.values()]
    others += [antenna(p, lever) for p, lever in cfg.peers.items()]
    ids = [*cfg.anchors, *cfg.peers]
    rngs = [np.random.Generator(np.random.PCG64(s)) for s in system_seed(ctx.seed, f"{name}#uwb").spawn(len(ids))]
    ranges = np.empty((t.size, len(ids)))
    nlos = np.empty((t.size, len(ids)), dtype=bool)
    for j, (other, rng) in enumerate(zip(others, rngs)):
        ranges[:, j], nlos[:, j] = link_ranges(np.linalg.norm(tag - other, axis=1), 1.0 / cfg.rate_hz, cfg, rng)
    file = ranges_file("ranges", f"{name}_ranges.csv", t, ids, ranges, nlos)
    section = UwbConfig(plugin="uwb", host=cfg.host, lever_arm_m=cfg.lever_arm_m, anchors=cfg.anchors,
                        peers=cfg.peers, ranges=RangeFileConfig(path=Path(file.name), nlos_column="nlos"),
                        sigma_m=cfg.sigma_m)
    return SystemOutput(np.empty(0), np.empty((0, 3)), layout_section(section), int(ranges.size), [file])


SIMULATION_KINDS = [SystemKind("uwb_tag", UwbTagSystem, simulate_uwb_tag, "uwb", aids=True)]
"""What this plugin simulates (returned by its ``fusion_simulation_kinds`` hook)."""
