"""The conformance checks of a sensor-system plugin (:class:`SystemChecker`), one method per check.

A check passes by returning a one-line detail, fails by raising ``AssertionError``
(:func:`fail`) and does not apply by raising :class:`Skip`;
:func:`bodyfusion.testing.conformance.check_system` runs them in the order of :data:`CHECKS`.
The checks, by name (see ``docs/plugin_guide.md`` for the contract they enforce):

``interface``
    a concrete :class:`~bodyfusion.core.system.SensorSystem` subclass with a lower-case
    ``plugin_name``, a strict pydantic ``Config`` (unknown keys refused) that accepts the
    section's ``plugin`` key, and a 3-wide ``position_indices`` slice.
``documented``
    every parameter of ``Config`` (nested models included) is documented; the rule is in
    :func:`bodyfusion.testing.documentation.undocumented_fields`.
``bad_config``
    each given bad config, and an unknown key, is refused with a
    :class:`~bodyfusion.base.errors.ConfigError` naming the given dotted key
    (``systems.<name>.<key>``), either by ``Config`` or when the system is built.
``build``
    the config validates and the system builds.
``advance``
    time bookkeeping: starts at ``t_start``; ``sample_times`` strictly increasing from
    ``t_start`` to ``t_end``; ``advance(t)`` processes exactly the samples with time ≤ t,
    never goes back, stops at ``t_end``; ``sync_times`` inside the span; for a system with
    :class:`~bodyfusion.core.capabilities.HeadingAlignment`, ``initial_travel_azimuth`` leaves a
    fresh system at its start.
``position_indices``
    select 3 valid states of the covariance.
``covariance``
    ``covariance()`` is square, finite, symmetric (to 1e-12 of its scale) and positive
    semi-definite (eigenvalues ≥ −1e-9 × the largest variance) at the start and after
    every chunk; ``covariance()`` and ``position_n()`` return copies.
``chunking``
    advancing in several chunks (uniform times and sync times) gives the same bits
    (trajectory, position, covariance) as one pass to the end.
``seed``
    two builds with the same ``context.seed`` give the same bits; with
    ``stochastic=True`` another seed must give different bits, with ``stochastic=False``
    the same bits.
``correction``
    a zero correction leaves position and covariance bit-for-bit unchanged (and the rest
    of the run unchanged to 1e-9); a position correction moves ``position_n()`` by that
    amount; the covariance becomes the given one; the trajectory's last row follows.
``trajectory``
    after a full run: shapes (N,), (N, 3), (N, 3); time strictly increasing from
    ``t_start`` to ``t_end``; finite positions; ``pos_sd ≥ 0``; last row equals
    ``position_n()`` and the square root of the covariance's position diagonal.
``cross_covariance``
    only for systems with :class:`~bodyfusion.core.capabilities.TransitionTracking` whose
    ``track_transition`` does not raise: the accumulated Φ is
    (n, n) and finite, a second call without advancing returns I, and
    P_now − Φ P_then Φᵀ is positive semi-definite (the process and measurement noise
    added between syncs).
``jacobians``
    analytic Jacobians match central differences: every :class:`~bodyfusion.testing.jacobians.JacobianCase` from the
    system's optional ``jacobian_cases()`` method, and, for systems whose
    ``error_model`` is ``"strapdown15"``, the core 15-state model
    (:func:`~bodyfusion.testing.jacobians.strapdown15_jacobian_cases`) at the system's own IMU samples.
"""

from __future__ import annotations

import copy
import inspect
import json
import math
import re
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from pydantic import BaseModel

from bodyfusion.base.errors import ConfigError, FusionError
from bodyfusion.core.capabilities import HeadingAlignment, TransitionTracking, offers
from bodyfusion.core.layout_io import validate_section
from bodyfusion.core.system import LayoutContext, SensorSystem
from bodyfusion.base.types import InputReport, Trajectory
from bodyfusion.testing.compare import max_diff, same_bits
from bodyfusion.testing.documentation import nested_models, undocumented_fields
from bodyfusion.testing.jacobians import STRAPDOWN15, check_jacobian, check_strapdown15

CHECKS = ("interface", "documented", "bad_config", "build", "advance", "position_indices", "covariance",
          "chunking", "seed", "correction", "trajectory", "cross_covariance", "jacobians")
"""Names of the checks, in the order they run."""

SYMMETRY_RTOL = 1e-12
"""Largest |P − Pᵀ| of a covariance, relative to its largest variance."""
PSD_RTOL = 1e-9
"""Most negative eigenvalue of a covariance, relative to its largest variance."""
_NAME_RE = re.compile(r"^[a-z][a-z0-9_]*$")


class Skip(Exception):
    """A check that does not apply to this system."""


def fail(check: str, detail: str) -> None:
    """Fail the ``check`` running now with ``detail``."""
    raise AssertionError(detail)


@dataclass
class _Snapshot:
    """What a system shows at one moment, to compare two runs bit for bit."""

    t_now: float
    position: np.ndarray
    covariance: np.ndarray
    t: np.ndarray
    pos_n: np.ndarray
    pos_sd: np.ndarray

    @classmethod
    def of(cls, s: SensorSystem) -> "_Snapshot":
        tr = s.trajectory()
        return cls(float(s.t_now), np.array(s.position_n(), dtype=float), np.array(s.covariance(), dtype=float),
                   np.array(tr.t, dtype=float), np.array(tr.pos_n, dtype=float), np.array(tr.pos_sd, dtype=float))

    def first_difference(self, other: "_Snapshot") -> str | None:
        for attr in ("t_now", "position", "covariance", "t", "pos_n", "pos_sd"):
            a, b = getattr(self, attr), getattr(other, attr)
            if not same_bits(a, b):
                return f"{attr} differs ({max_diff(a, b)})"
        return None


def _check_covariance(P: Any, where: str, n: int | None = None) -> np.ndarray:
    P = np.asarray(P, dtype=np.float64)
    if P.ndim != 2 or P.shape[0] != P.shape[1]:
        fail("covariance", f"{where}: covariance() has shape {P.shape}, not (n, n)")
    if n is not None and P.shape[0] != n:
        fail("covariance", f"{where}: covariance() changed size from {n} to {P.shape[0]}")
    if not np.all(np.isfinite(P)):
        fail("covariance", f"{where}: covariance() holds non-finite values")
    scale = max(float(np.max(np.abs(np.diag(P)))), np.finfo(float).tiny)
    asym = float(np.max(np.abs(P - P.T)))
    if asym > SYMMETRY_RTOL * scale:
        fail("covariance", f"{where}: covariance is not symmetric: max |P − Pᵀ| = {asym:.3g} "
                           f"(largest variance {scale:.3g})")
    low = float(np.linalg.eigvalsh(0.5 * (P + P.T)).min())
    if low < -PSD_RTOL * scale:
        fail("covariance", f"{where}: covariance is not positive semi-definite: smallest eigenvalue {low:.3g} "
                           f"(largest variance {scale:.3g})")
    return P


def _chunk_times(s: SensorSystem, chunks: int) -> list[float]:
    """Chunk ends: ``chunks`` uniform times (between samples, as the fuser's ``interval``
    epochs fall) and a few sync times (at samples), ending at t_end."""
    t0, t1 = s.t_start, s.t_end
    times = set(np.linspace(t0, t1, max(chunks, 1) + 1)[1:-1].tolist())
    sync = np.asarray(s.sync_times(), dtype=float)
    sync = sync[(sync > t0) & (sync < t1)]
    if sync.size:
        times.update(sync[np.linspace(0, sync.size - 1, min(3, sync.size)).astype(int)].tolist())
    return sorted(times) + [t1]


class SystemChecker:
    """The checks of a sensor-system class (``check_<name>`` per name in :data:`CHECKS`), each on
    fresh systems built from the config; ``check_build`` records the error-state size ``n``."""

    def __init__(self, system_cls: type, config: Mapping[str, Any], name: str, context: LayoutContext,
                 chunks: int, bad_configs: Sequence[tuple[Mapping[str, Any], str]], stochastic: bool | None,
                 error_model: str | None, allow_undocumented: Iterable[str]) -> None:
        self.cls = system_cls
        self.config = config
        self.name = name
        self.context = context
        self.chunks = chunks
        self.bad_configs = list(bad_configs)
        self.stochastic = stochastic
        self.error_model = error_model if error_model is not None else getattr(system_cls, "error_model", None)
        self.allow_undocumented = set(allow_undocumented)
        self.n: int | None = None

    # building ---------------------------------------------------------------------
    def section(self, config: Mapping[str, Any] | None = None) -> dict[str, Any]:
        section = copy.deepcopy(dict(self.config if config is None else config))
        section.setdefault("plugin", getattr(self.cls, "plugin_name", None))
        return section

    def build(self, seed: int | None = None, config: Mapping[str, Any] | None = None) -> SensorSystem:
        ctx = self.context if seed is None else replace(self.context, seed=seed)
        cfg = validate_section(self.cls.Config, self.section(config), key=f"systems.{self.name}", path=None,
                               base_dir=ctx.base_dir)
        return self.cls(self.name, cfg, ctx)

    def run_to_end(self, s: SensorSystem) -> SensorSystem:
        s.advance(s.t_end)
        return s

    # checks -------------------------------------------------------------------------
    base: type = SensorSystem
    """The interface class the plugin class must implement."""

    def _check_plugin_class(self) -> str:
        """The class implements :attr:`base`, names itself, and has a strict Config with
        a ``plugin`` field; returns the plugin name."""
        cls, base = self.cls, self.base
        if not (isinstance(cls, type) and issubclass(cls, base)):
            fail("interface", f"{cls!r} is not a subclass of bodyfusion.core.system.{base.__name__}")
        if inspect.isabstract(cls):
            fail("interface", f"{cls.__name__} leaves abstract methods unimplemented: "
                              f"{', '.join(sorted(cls.__abstractmethods__))}")
        name = getattr(cls, "plugin_name", None)
        if not isinstance(name, str) or not _NAME_RE.match(name):
            fail("interface", f"plugin_name must be a lower-case identifier (letters, digits, _), got {name!r}")
        model = getattr(cls, "Config", None)
        if not (isinstance(model, type) and issubclass(model, BaseModel)):
            fail("interface", f"Config must be a pydantic model class, got {model!r}")
        if model.model_config.get("extra") != "forbid":
            fail("interface", "Config must refuse unknown keys (derive from bodyfusion.core.layout.StrictModel)")
        if "plugin" not in model.model_fields:
            fail("interface", f"Config has no 'plugin' field: the layout section carries 'plugin: {name}'")
        return name

    def check_interface(self) -> str:
        cls = self.cls
        name = self._check_plugin_class()
        pi = getattr(cls, "position_indices", None)
        if not isinstance(pi, slice) or pi.step not in (None, 1) or pi.start is None or pi.stop - pi.start != 3:
            fail("interface", f"position_indices must be a slice of 3 consecutive states, got {pi!r}")
        return f"{cls.__name__} as {name!r}"

    def check_documented(self) -> str:
        missing = undocumented_fields(self.cls.Config)
        unexpected = [m for m in missing if m not in self.allow_undocumented]
        fields = self._all_fields(self.cls.Config)
        stale = sorted(a for a in self.allow_undocumented if a not in missing)
        problems = []
        if unexpected:
            problems.append(f"undocumented parameters: {', '.join(unexpected)} (give each a Field(description=...), "
                            "an attribute docstring, or name it in the model's docstring)")
        if stale:
            why = ["documented now" if a in fields else "no such field" for a in stale]
            problems.append("stale allow_undocumented entries: "
                            + ", ".join(f"{a} ({w})" for a, w in zip(stale, why)))
        if problems:
            fail("documented", "; ".join(problems))
        allowed = len(missing)
        return f"{len(fields)} parameters" + (f", {allowed} allowed undocumented" if allowed else "")

    @staticmethod
    def _all_fields(model: type[BaseModel], prefix: str = "", seen: set | None = None) -> set[str]:
        seen = set() if seen is None else seen
        out: set[str] = set()
        if model in seen:
            return out
        seen.add(model)
        for fname, finfo in model.model_fields.items():
            out.add(prefix + fname)
            for n in nested_models(finfo.annotation):
                out |= SystemChecker._all_fields(n, f"{prefix}{fname}.", seen)
        return out

    def check_bad_config(self) -> str:
        cases = [(self.section() | {"not_a_parameter": 1}, "not_a_parameter"), *self.bad_configs]
        for config, key in cases:
            want = f"systems.{self.name}.{key}"
            try:
                self.build(config=config)
            except ConfigError as err:
                if err.key != want:
                    fail("bad_config", f"config with a bad {key!r} was refused under key {err.key!r}, "
                                       f"expected {want!r} ({err.reason})")
                continue
            except Exception as err:  # noqa: BLE001 - any other exception is the failure
                fail("bad_config", f"config with a bad {key!r} raised {type(err).__name__}: {err} "
                                   f"instead of ConfigError naming {want!r}")
            fail("bad_config", f"config with a bad {key!r} was accepted (expected ConfigError naming {want!r})")
        return f"{len(cases)} bad configs refused (1 unknown key)"

    def check_build(self) -> str:
        s = self.build()
        P = np.asarray(s.covariance())
        self.n = P.shape[0] if P.ndim == 2 else None
        return f"error state of {self.n} states"

    def check_advance(self) -> str:
        s = self.build()
        st = np.asarray(s.sample_times(), dtype=float)
        if st.ndim != 1 or st.size < 2:
            fail("advance", f"sample_times() must be (N,) with N ≥ 2, got shape {st.shape}")
        if not np.all(np.diff(st) > 0):
            fail("advance", "sample_times() is not strictly increasing")
        if not (st[0] == s.t_start and st[-1] == s.t_end):
            fail("advance", f"sample_times() spans [{st[0]}, {st[-1]}], t_start/t_end are [{s.t_start}, {s.t_end}]")
        if s.t_now != s.t_start:
            fail("advance", f"a new system is at t_now={s.t_now}, not t_start={s.t_start}")
        if len(s.trajectory().t) != 1:
            fail("advance", "a new system's trajectory must hold exactly its initial state")
        sync = np.asarray(s.sync_times(), dtype=float)
        if sync.ndim != 1 or (sync.size and (sync.min() < s.t_start or sync.max() > s.t_end)):
            fail("advance", "sync_times() must be (K,) times inside [t_start, t_end]")
        if not isinstance(s.samples, (int, np.integer)) or s.samples < 1:
            fail("advance", f"samples must be a positive int, got {s.samples!r}")
        if not isinstance(s.input_report, InputReport):
            fail("advance", "input_report must be a bodyfusion.base.types.InputReport")
        if offers(s, HeadingAlignment):
            az = s.initial_travel_azimuth(1.0)
            if az is not None and not math.isfinite(az):
                fail("advance", f"initial_travel_azimuth returned {az!r}")
            if s.t_now != s.t_start or len(s.trajectory().t) != 1:
                fail("advance", "initial_travel_azimuth did not leave the system at its start")
        s.advance(s.t_start)
        if s.t_now != s.t_start:
            fail("advance", "advance(t_start) moved the system")
        k = st.size // 2
        t_mid = 0.5 * (st[k] + st[k + 1]) if k + 1 < st.size else st[k]
        s.advance(t_mid)
        if s.t_now != st[k]:
            fail("advance", f"advance({t_mid}) left t_now={s.t_now}; the last sample at or before it is {st[k]}")
        s.advance(st[1])
        if s.t_now != st[k]:
            fail("advance", "advance to an earlier time moved the system (it must be a no-op)")
        s.advance(s.t_end + 10.0)
        if s.t_now != s.t_end:
            fail("advance", f"advance past the end left t_now={s.t_now}, not t_end={s.t_end}")
        diag = s.diagnostics()
        if not isinstance(diag, dict):
            fail("advance", "diagnostics() must return a dict")
        try:
            json.dumps(diag, default=float)
        except (TypeError, ValueError) as err:
            fail("advance", f"diagnostics() is not JSON-serialisable: {err}")
        return f"{st.size} samples, {sync.size} sync times"

    def check_position_indices(self) -> str:
        pi = self.cls.position_indices
        idx = np.arange(self.n)[pi]
        if idx.size != 3:
            fail("position_indices", f"position_indices {pi} select {idx.size} of {self.n} states, not 3")
        return f"states {idx.tolist()} of {self.n}"

    def check_covariance(self) -> str:
        s = self.build()
        _check_covariance(s.covariance(), "at the start", self.n)
        times = _chunk_times(s, self.chunks)
        for k, t in enumerate(times):
            s.advance(t)
            _check_covariance(s.covariance(), f"after chunk {k + 1} (t={s.t_now:.6g} s)", self.n)
        P = s.covariance()
        P[...] = np.nan
        if not np.all(np.isfinite(s.covariance())):
            fail("covariance", "covariance() returns the system's own array: the caller can change the state "
                               "(return a copy)")
        p = s.position_n()
        if np.shape(p) != (3,):
            fail("covariance", f"position_n() has shape {np.shape(p)}, not (3,)")
        p[...] = np.nan
        if not np.all(np.isfinite(s.position_n())):
            fail("covariance", "position_n() returns the system's own array (return a copy)")
        return f"symmetric PSD at the start and after {len(times)} chunks"

    def check_chunking(self) -> str:
        a = self.build()
        times = _chunk_times(a, self.chunks)
        for t in times:
            a.advance(t)
        b = self.run_to_end(self.build())
        diff = _Snapshot.of(a).first_difference(_Snapshot.of(b))
        if diff:
            fail("chunking", f"advancing in {len(times)} chunks differs from one pass: {diff}")
        return f"{len(times)} chunks = one pass, bit for bit"

    def check_seed(self) -> str:
        seed = self.context.seed
        a = _Snapshot.of(self.run_to_end(self.build(seed)))
        b = _Snapshot.of(self.run_to_end(self.build(seed)))
        diff = a.first_difference(b)
        if diff:
            fail("seed", f"two builds with seed {seed} differ: {diff}")
        if self.stochastic is None:
            return "same seed, same bits (other seeds not checked: pass stochastic=True/False)"
        c = _Snapshot.of(self.run_to_end(self.build(seed + 1)))
        other = a.first_difference(c)
        if self.stochastic and other is None:
            fail("seed", f"seeds {seed} and {seed + 1} give the same bits, but the system is declared stochastic "
                         "(draw from bodyfusion.base.seeding.system_seed(context.seed, name))")
        if not self.stochastic and other is not None:
            fail("seed", f"seeds {seed} and {seed + 1} differ ({other}), but the system is declared deterministic")
        return "same seed, same bits; " + ("another seed differs" if self.stochastic else "seed-independent")

    def check_correction(self) -> str:
        s = self.build()
        st = np.asarray(s.sample_times(), dtype=float)
        t_mid = float(st[st.size // 2])
        s.advance(t_mid)
        pos0, P0 = np.array(s.position_n(), dtype=float), np.array(s.covariance(), dtype=float)
        n = P0.shape[0]
        s.apply_correction(np.zeros(n), P0.copy())
        if not same_bits(s.position_n(), pos0):
            fail("correction", f"a zero correction moved position_n() ({max_diff(s.position_n(), pos0)})")
        if not same_bits(s.covariance(), P0):
            fail("correction", f"a zero correction with the same P changed covariance() ({max_diff(s.covariance(), P0)})")
        # the rest of the run is unchanged (to round-off: a quaternion may be renormalised)
        ref = self.build()
        ref.advance(t_mid)
        self.run_to_end(ref)
        self.run_to_end(s)
        a, b = _Snapshot.of(s), _Snapshot.of(ref)
        for attr in ("position", "covariance", "pos_n"):
            x, y = getattr(a, attr), getattr(b, attr)
            if x.shape != y.shape or not np.allclose(x, y, rtol=1e-9, atol=1e-9 * max(1.0, float(np.max(np.abs(y))))):
                fail("correction", f"after a zero correction the rest of the run differs: {attr} ({max_diff(x, y)})")
        # a position correction
        s = self.build()
        s.advance(t_mid)
        pos0, P0 = np.array(s.position_n(), dtype=float), np.array(s.covariance(), dtype=float)
        d = np.array([0.25, -0.5, 0.125])
        dx = np.zeros(n)
        dx[self.cls.position_indices] = d
        P_new = 0.5 * P0
        s.apply_correction(dx, P_new.copy())
        moved = np.asarray(s.position_n()) - pos0
        if not np.allclose(moved, d, rtol=0, atol=1e-9 * max(1.0, float(np.max(np.abs(pos0))))):
            fail("correction", f"a position correction {d.tolist()} (m, ENU) moved position_n() by {moved.tolist()}")
        if not np.allclose(s.covariance(), P_new, rtol=1e-12, atol=0):
            fail("correction", f"covariance() after apply_correction is not the P given ({max_diff(s.covariance(), P_new)})")
        tr = s.trajectory()
        if not same_bits(np.asarray(tr.pos_n)[-1], s.position_n()):
            fail("correction", "the trajectory's last row does not show the correction (update the history too)")
        return "zero correction is a no-op; position correction moves position_n() by dx"

    def check_trajectory(self) -> str:
        s = self.run_to_end(self.build())
        tr = s.trajectory()
        if not isinstance(tr, Trajectory):
            fail("trajectory", "trajectory() must return a bodyfusion.base.types.Trajectory")
        t, p, sd = (np.asarray(a, dtype=float) for a in (tr.t, tr.pos_n, tr.pos_sd))
        N = t.shape[0] if t.ndim == 1 else -1
        if t.ndim != 1 or p.shape != (N, 3) or sd.shape != (N, 3):
            fail("trajectory", f"shapes t {t.shape}, pos_n {p.shape}, pos_sd {sd.shape}; want (N,), (N, 3), (N, 3)")
        if not np.all(np.diff(t) > 0):
            fail("trajectory", "trajectory time is not strictly increasing")
        if t[0] != s.t_start or t[-1] != s.t_end or s.t_now != s.t_end:
            fail("trajectory", f"trajectory spans [{t[0]}, {t[-1]}], the system [{s.t_start}, {s.t_end}]")
        if not (np.all(np.isfinite(p)) and np.all(np.isfinite(sd)) and np.all(sd >= 0)):
            fail("trajectory", "positions and sigmas must be finite, sigmas ≥ 0")
        if not same_bits(p[-1], s.position_n()):
            fail("trajectory", f"the last trajectory row is not position_n() ({max_diff(p[-1], s.position_n())})")
        var = np.diag(np.asarray(s.covariance()))[self.cls.position_indices]
        if not np.allclose(sd[-1], np.sqrt(np.maximum(var, 0.0)), rtol=1e-9, atol=0):
            fail("trajectory", f"the last pos_sd {sd[-1].tolist()} is not the square root of the covariance's "
                               f"position variances {var.tolist()}")
        return f"{N} rows"

    def check_cross_covariance(self) -> str:
        s = self.build()
        if not offers(s, TransitionTracking):
            raise Skip("the system does not track cross-covariances (no TransitionTracking)")
        try:
            s.track_transition()
        except FusionError as err:
            raise Skip(f"the system does not track cross-covariances ({err})") from None
        n = self.n
        P_then = np.asarray(s.covariance(), dtype=float)
        times = _chunk_times(s, self.chunks)
        for k, t in enumerate(times):
            s.advance(t)
            phi = np.asarray(s.transition_since_sync(), dtype=float)
            if phi.shape != (n, n) or not np.all(np.isfinite(phi)):
                fail("cross_covariance", f"transition_since_sync() gave shape {phi.shape} or non-finite values")
            P_now = np.asarray(s.covariance(), dtype=float)
            D = P_now - phi @ P_then @ phi.T
            scale = max(float(np.max(np.abs(np.diag(P_now)))), float(np.max(np.abs(np.diag(P_then)))))
            low = float(np.linalg.eigvalsh(0.5 * (D + D.T)).min())
            if low < -1e-7 * scale:
                fail("cross_covariance", f"after chunk {k + 1} (t={s.t_now:.6g} s) P_now − Φ P_then Φᵀ has eigenvalue "
                                         f"{low:.3g} (largest variance {scale:.3g}): Φ is not the transition "
                                         "the covariance went through")
            again = np.asarray(s.transition_since_sync(), dtype=float)
            if not np.array_equal(again, np.eye(n)):
                fail("cross_covariance", "a second transition_since_sync() without advancing is not I "
                                         "(restart the accumulation at each call)")
            P_then = P_now
        return f"Φ consistent with the covariance over {len(times)} chunks"

    def check_jacobians(self) -> str:
        s = self.build()
        notes = []
        own = getattr(s, "jacobian_cases", None)
        if callable(own):
            cases = list(own())
            if not cases:
                fail("jacobians", "jacobian_cases() returned no cases")
            for case in cases:
                check_jacobian(case)
            notes.append(f"{len(cases)} cases from jacobian_cases()")
        if self.error_model == STRAPDOWN15:
            notes.append(check_strapdown15(s))
        elif self.error_model is not None:
            fail("jacobians", f"unknown error_model {self.error_model!r} (known: {STRAPDOWN15!r})")
        if not notes:
            raise Skip("no analytic Jacobians declared (no jacobian_cases(), no error_model)")
        return "; ".join(notes)
