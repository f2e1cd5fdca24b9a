"""Conformance checks for sensor-system plugins.

One call runs every check on a plugin class and raises :class:`ConformanceError` (an
``AssertionError``) naming each failing check::

    from bodyfusion.testing import check_system

    def test_my_plugin_conforms():
        check_system(MySystem, {"data": {"path": "tests/data/log.csv"}},
                     bad_configs=[({"data": {"path": "x.csv"}, "noise_pa": -1}, "noise_pa")])

The checks, by name (see ``docs/plugin_guide.md`` for the contract they enforce):

``interface``
    a concrete :class:`~bodyfusion.core.system.SensorSystem` subclass with a lower-case
    ``plugin_name``, a strict pydantic ``Config`` (unknown keys refused) that accepts the
    section's ``plugin`` key, and a 3-wide ``position_indices`` slice.
``documented``
    every parameter of ``Config`` (nested models included) is documented; the rule is in
    :func:`undocumented_fields`.
``bad_config``
    each given bad config, and an unknown key, is refused with a
    :class:`~bodyfusion.core.errors.ConfigError` naming the given dotted key
    (``systems.<name>.<key>``), either by ``Config`` or when the system is built.
``build``
    the config validates and the system builds.
``advance``
    time bookkeeping: starts at ``t_start``; ``sample_times`` strictly increasing from
    ``t_start`` to ``t_end``; ``advance(t)`` processes exactly the samples with time ≤ t,
    never goes back, stops at ``t_end``; ``sync_times`` inside the span;
    ``initial_travel_azimuth`` leaves a fresh system at its start.
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
    only for systems whose ``track_transition`` does not raise: the accumulated Φ is
    (n, n) and finite, a second call without advancing returns I, and
    P_now − Φ P_then Φᵀ is positive semi-definite (the process and measurement noise
    added between syncs).
``jacobians``
    analytic Jacobians match central differences: every :class:`JacobianCase` from the
    system's optional ``jacobian_cases()`` method, and, for systems whose
    ``error_model`` is ``"strapdown15"``, the core 15-state model
    (:func:`strapdown15_jacobian_cases`) at the system's own IMU samples.
"""

from __future__ import annotations

import ast
import copy
import inspect
import json
import math
import re
import textwrap
import typing
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from pydantic import BaseModel

from bodyfusion.core.layout import validate_section
from bodyfusion.core.errors import ConfigError, FusionError
from bodyfusion.core.system import AidingSource, LayoutContext, ScalarMeasurement, SensorSystem
from bodyfusion.core.types import ImuStream, InputReport, Trajectory

__all__ = [
    "AIDING_CHECKS", "CHECKS", "CheckResult", "ConformanceError", "ConformanceReport", "JacobianCase", "STRAPDOWN15",
    "check_jacobian", "check_system", "default_context", "numerical_jacobian", "strapdown15_jacobian_cases",
    "undocumented_fields", "with_value",
]

CHECKS = ("interface", "documented", "bad_config", "build", "advance", "position_indices", "covariance",
          "chunking", "seed", "correction", "trajectory", "cross_covariance", "jacobians")
"""Names of the checks, in the order they run."""

AIDING_CHECKS = ("interface", "documented", "bad_config", "build", "measurements", "seed", "jacobians", "gating")
"""Names of the checks of an :class:`~bodyfusion.core.system.AidingSource` (a UWB tag...), in order:
``interface``, ``documented``, ``bad_config`` and ``build`` as for a system;
``measurements``: times finite and non-decreasing, each measurement relates one or two of
the systems the config names and gives a finite z, h(p̂), ∂h/∂p (m, 3) and r > 0;
``samples``, ``input_report``, JSON-serialisable ``diagnostics()`` before and after the
fuser's verdicts; ``seed``: two builds give the same bits (and, with ``stochastic``,
another seed differs or not); ``jacobians``: the ``jacobian_cases()`` against central
differences; ``gating``: through the fuser's update (:func:`bodyfusion.core.fuser.scalar_update`)
with position variances of 0.01 m², a measurement equal to its prediction is accepted and
one 10 innovation sigmas beyond the gate is rejected."""

STRAPDOWN15 = "strapdown15"
"""``error_model`` value of systems built on :mod:`bodyfusion.nav.strapdown` + :mod:`bodyfusion.nav.error_state`."""

SYMMETRY_RTOL = 1e-12
PSD_RTOL = 1e-9
UNIT_SUFFIXES = ("m", "m2", "s", "hz", "mps", "mps2", "deg", "rad", "radps", "pa", "hpa", "k", "pct")
_NAME_RE = re.compile(r"^[a-z][a-z0-9_]*$")


# --------------------------------------------------------------------------- results


@dataclass
class CheckResult:
    """Outcome of one check: ``status`` is ``passed``, ``failed`` or ``skipped``."""

    name: str
    status: str
    detail: str = ""


@dataclass
class ConformanceReport:
    """Every check's result for one plugin class."""

    plugin: str
    results: list[CheckResult] = field(default_factory=list)

    def _names(self, status: str) -> list[str]:
        return [r.name for r in self.results if r.status == status]

    @property
    def passed(self) -> list[str]:
        return self._names("passed")

    @property
    def failed(self) -> list[str]:
        return self._names("failed")

    @property
    def skipped(self) -> list[str]:
        return self._names("skipped")

    def result(self, name: str) -> CheckResult:
        return next(r for r in self.results if r.name == name)

    def __str__(self) -> str:
        head = (f"conformance of plugin {self.plugin!r}: {len(self.passed)} passed, {len(self.failed)} failed, "
                f"{len(self.skipped)} skipped")
        lines = [head]
        for r in self.results:
            if r.status != "passed":
                lines.append(f"  [{r.name}] {r.status}: {r.detail}")
        return "\n".join(lines)


class ConformanceError(AssertionError):
    """Raised by :func:`check_system` when a check fails; ``report`` has every result."""

    def __init__(self, report: ConformanceReport) -> None:
        super().__init__(str(report))
        self.report = report


class _Skip(Exception):
    """A check that does not apply to this system."""


def _fail(check: str, detail: str) -> None:
    raise AssertionError(detail)


# --------------------------------------------------------------------------- helpers


def default_context(base_dir: str | Path = ".", seed: int = 0) -> LayoutContext:
    """A layout context for tests: g = 9.80665 m/s², latitude 45°, paths relative to ``base_dir``."""
    return LayoutContext(gravity_mps2=9.80665, latitude_deg=45.0, base_dir=Path(base_dir).resolve(), seed=seed)


def with_value(config: Mapping[str, Any], key: str, value: Any) -> dict[str, Any]:
    """A deep copy of ``config`` with the dotted ``key`` set to ``value`` (to make bad configs)."""
    out = copy.deepcopy(dict(config))
    node: Any = out
    parts = key.split(".")
    for part in parts[:-1]:
        if isinstance(node, list):
            node = node[int(part)]
        else:
            node = node.setdefault(part, {})
    if isinstance(node, list):
        node[int(parts[-1])] = value
    else:
        node[parts[-1]] = value
    return out


def _bits(a: Any) -> bytes:
    return np.ascontiguousarray(np.asarray(a, dtype=np.float64)).tobytes()


def _same_bits(a: Any, b: Any) -> bool:
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    return a.shape == b.shape and _bits(a) == _bits(b)


def _max_diff(a: Any, b: Any) -> str:
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    if a.shape != b.shape:
        return f"shapes {a.shape} and {b.shape}"
    with np.errstate(invalid="ignore"):
        d = np.abs(a - b)
    return f"max |difference| {np.nanmax(d) if d.size else 0.0:.3g}"


@dataclass
class _Snapshot:
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
            if not _same_bits(a, b):
                return f"{attr} differs ({_max_diff(a, b)})"
        return None


def _check_covariance(P: Any, where: str, n: int | None = None) -> np.ndarray:
    P = np.asarray(P, dtype=np.float64)
    if P.ndim != 2 or P.shape[0] != P.shape[1]:
        _fail("covariance", f"{where}: covariance() has shape {P.shape}, not (n, n)")
    if n is not None and P.shape[0] != n:
        _fail("covariance", f"{where}: covariance() changed size from {n} to {P.shape[0]}")
    if not np.all(np.isfinite(P)):
        _fail("covariance", f"{where}: covariance() holds non-finite values")
    scale = max(float(np.max(np.abs(np.diag(P)))), np.finfo(float).tiny)
    asym = float(np.max(np.abs(P - P.T)))
    if asym > SYMMETRY_RTOL * scale:
        _fail("covariance", f"{where}: covariance is not symmetric: max |P − Pᵀ| = {asym:.3g} "
                            f"(largest variance {scale:.3g})")
    low = float(np.linalg.eigvalsh(0.5 * (P + P.T)).min())
    if low < -PSD_RTOL * scale:
        _fail("covariance", f"{where}: covariance is not positive semi-definite: smallest eigenvalue {low:.3g} "
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


# --------------------------------------------------------------------------- documentation rule


def _own_doc(cls: type) -> str:
    return cls.__dict__.get("__doc__") or ""


def _config_classes(model: type[BaseModel]) -> list[type]:
    """The model and its bases that are layout sections (not pydantic/core plumbing)."""
    from bodyfusion.core.layout import StrictModel

    return [c for c in model.__mro__ if isinstance(c, type) and issubclass(c, BaseModel)
            and c not in (BaseModel, StrictModel)]


def _attribute_docstrings(model: type[BaseModel]) -> dict[str, str]:
    """Field name → the string literal right below its annotation in the class body."""
    out: dict[str, str] = {}
    for cls in reversed(_config_classes(model)):
        try:
            tree = ast.parse(textwrap.dedent(inspect.getsource(cls)))
        except (OSError, TypeError, SyntaxError):
            continue
        body = tree.body[0].body if tree.body and isinstance(tree.body[0], ast.ClassDef) else []
        for stmt, nxt in zip(body, body[1:]):
            if (isinstance(stmt, ast.AnnAssign) and isinstance(stmt.target, ast.Name)
                    and isinstance(nxt, ast.Expr) and isinstance(nxt.value, ast.Constant)
                    and isinstance(nxt.value.value, str) and nxt.value.value.strip()):
                out[stmt.target.id] = nxt.value.value
    return out


def _stem(name: str) -> str:
    parts = name.split("_")
    if len(parts) > 1 and parts[-1] in UNIT_SUFFIXES:
        parts = parts[:-1]
    return " ".join(parts)


def _mentions(doc: str, name: str) -> bool:
    text = doc.lower().replace("`", " ")
    if re.search(rf"(?<![a-z0-9_]){re.escape(name.lower())}(?![a-z0-9_])", text):
        return True
    stem = r"[\s_]+".join(re.escape(w) for w in _stem(name).lower().split())
    return bool(re.search(rf"(?<![a-z0-9_]){stem}(?![a-z0-9])", text))


def _nested_models(annotation: Any) -> list[type[BaseModel]]:
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return [annotation]
    out: list[type[BaseModel]] = []
    for arg in typing.get_args(annotation):
        out.extend(_nested_models(arg))
    return out


def undocumented_fields(model: type[BaseModel]) -> list[str]:
    """Dotted paths of the fields of ``model`` (nested models included) that are not documented.

    A field counts as documented when any of these holds:

    1. it has a description: ``Field(description=...)``, or an attribute docstring (a
       string literal on the line after the field, which pydantic also reads with
       ``use_attribute_docstrings=True``);
    2. the docstring of its model class (or of a base) names it: the field name itself,
       or its name without a trailing unit suffix (``_m``, ``_s``, ``_hz``, ``_mps``,
       ``_deg``, ``_pa``...) with underscores read as spaces, as whole words,
       case-insensitive (``duration_s`` is documented by "… duration (s) …");
    3. it holds a nested model (optionally, or in a list/dict) whose class has its own
       docstring; that model's fields are then checked in turn under ``field.``;
    4. it is the top-level ``plugin`` key, which the core documents.
    """
    missing: list[str] = []
    seen: set[type] = set()

    def walk(m: type[BaseModel], prefix: str) -> None:
        if m in seen:
            return
        seen.add(m)
        doc = " ".join(_own_doc(c) for c in _config_classes(m))
        attr_docs = _attribute_docstrings(m)
        for fname, finfo in m.model_fields.items():
            nested = _nested_models(finfo.annotation)
            ok = (bool((finfo.description or "").strip()) or fname in attr_docs or _mentions(doc, fname)
                  or (bool(nested) and all(_own_doc(n).strip() for n in nested))
                  or (prefix == "" and fname == "plugin"))
            if not ok:
                missing.append(prefix + fname)
            for n in nested:
                walk(n, f"{prefix}{fname}.")

    walk(model, "")
    return missing


# --------------------------------------------------------------------------- Jacobians


@dataclass
class JacobianCase:
    """An analytic Jacobian to compare with central differences.

    ``func`` maps a nominal state to an output (a propagated state, a predicted
    measurement...), ``x`` is the linearisation point, ``jacobian`` the analytic (m, n)
    matrix of the output's error with respect to the input's error. ``retract(x, dx)``
    applies an error dx (n,) to a nominal state (default ``x + dx``); ``difference(a, b)``
    is the error of output a relative to b, true minus estimated (default ``a − b``).
    The check passes when max |J_num − J| ≤ ``atol`` + ``rtol`` · max |J|.
    """

    name: str
    func: Callable[[np.ndarray], np.ndarray]
    x: np.ndarray
    jacobian: np.ndarray
    step: float = 1e-6
    atol: float = 1e-7
    rtol: float = 1e-6
    retract: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None
    difference: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None


def numerical_jacobian(case: JacobianCase) -> np.ndarray:
    """Central-difference Jacobian of ``case.func`` at ``case.x`` in the error coordinates."""
    J = np.atleast_2d(np.asarray(case.jacobian, dtype=float))
    n = J.shape[1]
    retract = case.retract or (lambda x, dx: np.asarray(x, dtype=float) + dx)
    diff = case.difference or (lambda a, b: np.atleast_1d(np.asarray(a, dtype=float) - np.asarray(b, dtype=float)))
    x = np.asarray(case.x, dtype=float)
    y0 = case.func(x.copy())
    out = np.empty((np.atleast_1d(diff(y0, y0)).size, n))
    for i in range(n):
        e = np.zeros(n)
        e[i] = case.step
        yp = case.func(retract(x.copy(), e))
        ym = case.func(retract(x.copy(), -e))
        out[:, i] = (np.atleast_1d(diff(yp, y0)) - np.atleast_1d(diff(ym, y0))) / (2 * case.step)
    return out


def check_jacobian(case: JacobianCase) -> None:
    """Raise ``AssertionError`` naming the case and the worst entry if J differs from J_num."""
    J = np.atleast_2d(np.asarray(case.jacobian, dtype=float))
    J_num = numerical_jacobian(case)
    if J_num.shape != J.shape:
        raise AssertionError(f"{case.name}: analytic Jacobian has shape {J.shape}, numerical {J_num.shape}")
    err = np.abs(J_num - J)
    tol = case.atol + case.rtol * float(np.max(np.abs(J)))
    worst = np.unravel_index(int(np.argmax(err)), err.shape)
    if err[worst] > tol:
        raise AssertionError(f"{case.name}: analytic Jacobian differs from central differences at {tuple(map(int, worst))}: "
                             f"analytic {J[worst]:.6g}, numerical {J_num[worst]:.6g} (|diff| {err[worst]:.3g} > tol {tol:.3g})")



def random_nominal_state(rng: np.random.Generator) -> np.ndarray:
    """A random strapdown nominal state (16,): position (σ 5 m), velocity (σ 1 m/s), a uniformly
    random attitude quaternion (scalar first), accelerometer (σ 0.05 m/s^2) and gyro (σ 0.01 rad/s) biases."""
    from scipy.spatial.transform import Rotation

    from bodyfusion.nav.strapdown import NOMINAL_SIZE

    x = np.zeros(NOMINAL_SIZE)
    x[0:3] = rng.normal(0, 5, 3)
    x[3:6] = rng.normal(0, 1, 3)
    x[6:10] = Rotation.random(random_state=int(rng.integers(1 << 30))).as_quat(scalar_first=True)
    x[10:13] = rng.normal(0, 0.05, 3)
    x[13:16] = rng.normal(0, 0.01, 3)
    return x

def strapdown15_jacobian_cases(acc_b: np.ndarray, gyro_b: np.ndarray, dt: float, gravity: float,
                               seed: int = 0) -> list[JacobianCase]:
    """The core 15-state error model as :class:`JacobianCase` s, one per IMU sample.

    ``acc_b``, ``gyro_b``: (K, 3) samples (m/s², rad/s). At a random nominal state (fixed
    ``seed``), F is what :func:`bodyfusion.nav.error_state.accumulate_propagation` builds from one
    :func:`bodyfusion.nav.strapdown.mechanise` step; the numerical Jacobian perturbs the nominal
    state with :func:`bodyfusion.nav.error_state.inject` and measures the error after the step as
    true minus estimated (δθ = rotvec(q_true ⊗ q_est⁻¹)). F is first order in dt: what it
    leaves out is O(dt²), so the tolerance is 5 % of max |F − I| (a wrong sign or a missing
    block is O(dt) and fails).
    """
    from bodyfusion.nav.error_state import ERROR_SIZE, accumulate_propagation, error_between, inject
    from bodyfusion.nav.strapdown import mechanise

    rng = np.random.default_rng(seed)
    no_earth = np.zeros(3)

    def step(x: np.ndarray, acc: np.ndarray, gyro: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        x = np.ascontiguousarray(x, dtype=np.float64).copy()
        f_n = np.empty(3)
        C = mechanise(x, acc, gyro, float(dt), float(gravity), no_earth, f_n, np.zeros(6))
        return x, C, f_n

    def retract(x: np.ndarray, dx: np.ndarray) -> np.ndarray:
        out = np.ascontiguousarray(x, dtype=np.float64).copy()
        inject(out, np.ascontiguousarray(dx, dtype=np.float64))
        return out

    difference = error_between

    cases = []
    for k, (acc, gyro) in enumerate(zip(np.asarray(acc_b, dtype=float), np.asarray(gyro_b, dtype=float))):
        acc = np.ascontiguousarray(acc)
        gyro = np.ascontiguousarray(gyro)
        x = random_nominal_state(rng)
        _, C, f_n = step(x, acc, gyro)
        F = np.eye(ERROR_SIZE)
        accumulate_propagation(F, np.ascontiguousarray(C), f_n, float(dt), np.empty((ERROR_SIZE, ERROR_SIZE)))
        first_order = float(np.max(np.abs(F - np.eye(ERROR_SIZE))))
        cases.append(JacobianCase(
            name=f"strapdown15 transition F at sample {k} (|f| {np.linalg.norm(acc):.2f} m/s², "
                 f"|ω| {np.linalg.norm(gyro):.2f} rad/s, dt {dt:.4g} s)",
            func=lambda x, a=acc, g=gyro: step(x, a, g)[0], x=x, jacobian=F, step=1e-6,
            atol=0.05 * first_order, rtol=0.0, retract=retract, difference=difference))
    return cases


def _check_strapdown15(system: SensorSystem) -> str:
    """F from the core error model against finite differences of the mechanisation, at the
    system's own IMU samples, and propagate_covariance(P) = F P Fᵀ + Q_d."""
    from bodyfusion.nav.error_state import ERROR_SIZE, accumulate_propagation, propagate_covariance

    stream = getattr(system, "stream", None)
    if isinstance(stream, ImuStream) and len(stream) > 2:
        dt = float(np.median(np.diff(stream.t)))
        dev = np.abs(np.linalg.norm(stream.acc_b, axis=1) - system.context.gravity_mps2)
        rate = np.linalg.norm(stream.gyro_b, axis=1)
        picks = sorted({int(np.argmin(rate + dev)), int(np.argmax(rate)), int(np.argmax(dev)), len(stream) // 2})
        acc, gyro, source = stream.acc_b[picks], stream.gyro_b[picks], f"samples {picks} of the system's stream"
    else:
        acc = np.array([[0.3, -0.4, 9.9], [4.0, -7.0, 15.0], [-2.0, 1.0, 3.0]])
        gyro = np.array([[0.02, -0.01, 0.03], [1.5, -3.0, 0.8], [-0.2, 0.1, -2.5]])
        dt, source = 0.01, "canned IMU samples (the system has no ImuStream ``stream``)"
    cases = strapdown15_jacobian_cases(acc, gyro, dt, system.context.gravity_mps2)
    for case in cases:
        check_jacobian(case)
    # the covariance propagation uses the same F
    rng = np.random.default_rng(1)
    A = rng.normal(0, 1, (ERROR_SIZE, ERROR_SIZE))
    P = A @ A.T / ERROR_SIZE + 0.1 * np.eye(ERROR_SIZE)
    case = cases[-1]
    from bodyfusion.nav.strapdown import mechanise

    x = np.ascontiguousarray(case.x).copy()
    f_n = np.empty(3)
    C = np.ascontiguousarray(mechanise(x, np.ascontiguousarray(acc[-1]), np.ascontiguousarray(gyro[-1]), dt,
                                       system.context.gravity_mps2, np.zeros(3), f_n, np.zeros(6)))
    F = np.eye(ERROR_SIZE)
    accumulate_propagation(F, C, f_n, dt, np.empty((ERROR_SIZE, ERROR_SIZE)))
    q = np.linspace(1e-6, 1e-3, ERROR_SIZE)
    got = P.copy()
    propagate_covariance(got, C, f_n, dt, q, np.empty((2, ERROR_SIZE, ERROR_SIZE)))
    want = F @ P @ F.T + np.diag(q * dt)
    if np.max(np.abs(got - want)) > 1e-12 * np.max(np.abs(want)):
        raise AssertionError(f"strapdown15: propagate_covariance differs from F P Fᵀ + Q_d ({_max_diff(got, want)})")
    return f"{len(cases)} strapdown15 cases at {source}"


# --------------------------------------------------------------------------- the checker


class _Checker:
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
            _fail("interface", f"{cls!r} is not a subclass of bodyfusion.core.system.{base.__name__}")
        if inspect.isabstract(cls):
            _fail("interface", f"{cls.__name__} leaves abstract methods unimplemented: "
                               f"{', '.join(sorted(cls.__abstractmethods__))}")
        name = getattr(cls, "plugin_name", None)
        if not isinstance(name, str) or not _NAME_RE.match(name):
            _fail("interface", f"plugin_name must be a lower-case identifier (letters, digits, _), got {name!r}")
        model = getattr(cls, "Config", None)
        if not (isinstance(model, type) and issubclass(model, BaseModel)):
            _fail("interface", f"Config must be a pydantic model class, got {model!r}")
        if model.model_config.get("extra") != "forbid":
            _fail("interface", "Config must refuse unknown keys (derive from bodyfusion.core.layout.StrictModel)")
        if "plugin" not in model.model_fields:
            _fail("interface", f"Config has no 'plugin' field: the layout section carries 'plugin: {name}'")
        return name

    def check_interface(self) -> str:
        cls = self.cls
        name = self._check_plugin_class()
        pi = getattr(cls, "position_indices", None)
        if not isinstance(pi, slice) or pi.step not in (None, 1) or pi.start is None or pi.stop - pi.start != 3:
            _fail("interface", f"position_indices must be a slice of 3 consecutive states, got {pi!r}")
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
            _fail("documented", "; ".join(problems))
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
            for n in _nested_models(finfo.annotation):
                out |= _Checker._all_fields(n, f"{prefix}{fname}.", seen)
        return out

    def check_bad_config(self) -> str:
        cases = [(self.section() | {"not_a_parameter": 1}, "not_a_parameter"), *self.bad_configs]
        for config, key in cases:
            want = f"systems.{self.name}.{key}"
            try:
                self.build(config=config)
            except ConfigError as err:
                if err.key != want:
                    _fail("bad_config", f"config with a bad {key!r} was refused under key {err.key!r}, "
                                        f"expected {want!r} ({err.reason})")
                continue
            except Exception as err:  # noqa: BLE001 - any other exception is the failure
                _fail("bad_config", f"config with a bad {key!r} raised {type(err).__name__}: {err} "
                                    f"instead of ConfigError naming {want!r}")
            _fail("bad_config", f"config with a bad {key!r} was accepted (expected ConfigError naming {want!r})")
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
            _fail("advance", f"sample_times() must be (N,) with N ≥ 2, got shape {st.shape}")
        if not np.all(np.diff(st) > 0):
            _fail("advance", "sample_times() is not strictly increasing")
        if not (st[0] == s.t_start and st[-1] == s.t_end):
            _fail("advance", f"sample_times() spans [{st[0]}, {st[-1]}], t_start/t_end are [{s.t_start}, {s.t_end}]")
        if s.t_now != s.t_start:
            _fail("advance", f"a new system is at t_now={s.t_now}, not t_start={s.t_start}")
        if len(s.trajectory().t) != 1:
            _fail("advance", "a new system's trajectory must hold exactly its initial state")
        sync = np.asarray(s.sync_times(), dtype=float)
        if sync.ndim != 1 or (sync.size and (sync.min() < s.t_start or sync.max() > s.t_end)):
            _fail("advance", "sync_times() must be (K,) times inside [t_start, t_end]")
        if not isinstance(s.samples, (int, np.integer)) or s.samples < 1:
            _fail("advance", f"samples must be a positive int, got {s.samples!r}")
        if not isinstance(s.input_report, InputReport):
            _fail("advance", "input_report must be a bodyfusion.core.types.InputReport")
        az = s.initial_travel_azimuth(1.0)
        if az is not None and not math.isfinite(az):
            _fail("advance", f"initial_travel_azimuth returned {az!r}")
        if s.t_now != s.t_start or len(s.trajectory().t) != 1:
            _fail("advance", "initial_travel_azimuth did not leave the system at its start")
        s.advance(s.t_start)
        if s.t_now != s.t_start:
            _fail("advance", "advance(t_start) moved the system")
        k = st.size // 2
        t_mid = 0.5 * (st[k] + st[k + 1]) if k + 1 < st.size else st[k]
        s.advance(t_mid)
        if s.t_now != st[k]:
            _fail("advance", f"advance({t_mid}) left t_now={s.t_now}; the last sample at or before it is {st[k]}")
        s.advance(st[1])
        if s.t_now != st[k]:
            _fail("advance", "advance to an earlier time moved the system (it must be a no-op)")
        s.advance(s.t_end + 10.0)
        if s.t_now != s.t_end:
            _fail("advance", f"advance past the end left t_now={s.t_now}, not t_end={s.t_end}")
        diag = s.diagnostics()
        if not isinstance(diag, dict):
            _fail("advance", "diagnostics() must return a dict")
        try:
            json.dumps(diag, default=float)
        except (TypeError, ValueError) as err:
            _fail("advance", f"diagnostics() is not JSON-serialisable: {err}")
        return f"{st.size} samples, {sync.size} sync times"

    def check_position_indices(self) -> str:
        pi = self.cls.position_indices
        idx = np.arange(self.n)[pi]
        if idx.size != 3:
            _fail("position_indices", f"position_indices {pi} select {idx.size} of {self.n} states, not 3")
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
            _fail("covariance", "covariance() returns the system's own array: the caller can change the state "
                                "(return a copy)")
        p = s.position_n()
        if np.shape(p) != (3,):
            _fail("covariance", f"position_n() has shape {np.shape(p)}, not (3,)")
        p[...] = np.nan
        if not np.all(np.isfinite(s.position_n())):
            _fail("covariance", "position_n() returns the system's own array (return a copy)")
        return f"symmetric PSD at the start and after {len(times)} chunks"

    def check_chunking(self) -> str:
        a = self.build()
        times = _chunk_times(a, self.chunks)
        for t in times:
            a.advance(t)
        b = self.run_to_end(self.build())
        diff = _Snapshot.of(a).first_difference(_Snapshot.of(b))
        if diff:
            _fail("chunking", f"advancing in {len(times)} chunks differs from one pass: {diff}")
        return f"{len(times)} chunks = one pass, bit for bit"

    def check_seed(self) -> str:
        seed = self.context.seed
        a = _Snapshot.of(self.run_to_end(self.build(seed)))
        b = _Snapshot.of(self.run_to_end(self.build(seed)))
        diff = a.first_difference(b)
        if diff:
            _fail("seed", f"two builds with seed {seed} differ: {diff}")
        if self.stochastic is None:
            return "same seed, same bits (other seeds not checked: pass stochastic=True/False)"
        c = _Snapshot.of(self.run_to_end(self.build(seed + 1)))
        other = a.first_difference(c)
        if self.stochastic and other is None:
            _fail("seed", f"seeds {seed} and {seed + 1} give the same bits, but the system is declared stochastic "
                          "(draw from bodyfusion.core.seeding.system_seed(context.seed, name))")
        if not self.stochastic and other is not None:
            _fail("seed", f"seeds {seed} and {seed + 1} differ ({other}), but the system is declared deterministic")
        return "same seed, same bits; " + ("another seed differs" if self.stochastic else "seed-independent")

    def check_correction(self) -> str:
        s = self.build()
        st = np.asarray(s.sample_times(), dtype=float)
        t_mid = float(st[st.size // 2])
        s.advance(t_mid)
        pos0, P0 = np.array(s.position_n(), dtype=float), np.array(s.covariance(), dtype=float)
        n = P0.shape[0]
        s.apply_correction(np.zeros(n), P0.copy())
        if not _same_bits(s.position_n(), pos0):
            _fail("correction", f"a zero correction moved position_n() ({_max_diff(s.position_n(), pos0)})")
        if not _same_bits(s.covariance(), P0):
            _fail("correction", f"a zero correction with the same P changed covariance() ({_max_diff(s.covariance(), P0)})")
        # the rest of the run is unchanged (to round-off: a quaternion may be renormalised)
        ref = self.build()
        ref.advance(t_mid)
        self.run_to_end(ref)
        self.run_to_end(s)
        a, b = _Snapshot.of(s), _Snapshot.of(ref)
        for attr in ("position", "covariance", "pos_n"):
            x, y = getattr(a, attr), getattr(b, attr)
            if x.shape != y.shape or not np.allclose(x, y, rtol=1e-9, atol=1e-9 * max(1.0, float(np.max(np.abs(y))))):
                _fail("correction", f"after a zero correction the rest of the run differs: {attr} ({_max_diff(x, y)})")
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
            _fail("correction", f"a position correction {d.tolist()} (m, ENU) moved position_n() by {moved.tolist()}")
        if not np.allclose(s.covariance(), P_new, rtol=1e-12, atol=0):
            _fail("correction", f"covariance() after apply_correction is not the P given ({_max_diff(s.covariance(), P_new)})")
        tr = s.trajectory()
        if not _same_bits(np.asarray(tr.pos_n)[-1], s.position_n()):
            _fail("correction", "the trajectory's last row does not show the correction (update the history too)")
        return "zero correction is a no-op; position correction moves position_n() by dx"

    def check_trajectory(self) -> str:
        s = self.run_to_end(self.build())
        tr = s.trajectory()
        if not isinstance(tr, Trajectory):
            _fail("trajectory", "trajectory() must return a bodyfusion.core.types.Trajectory")
        t, p, sd = (np.asarray(a, dtype=float) for a in (tr.t, tr.pos_n, tr.pos_sd))
        N = t.shape[0] if t.ndim == 1 else -1
        if t.ndim != 1 or p.shape != (N, 3) or sd.shape != (N, 3):
            _fail("trajectory", f"shapes t {t.shape}, pos_n {p.shape}, pos_sd {sd.shape}; want (N,), (N, 3), (N, 3)")
        if not np.all(np.diff(t) > 0):
            _fail("trajectory", "trajectory time is not strictly increasing")
        if t[0] != s.t_start or t[-1] != s.t_end or s.t_now != s.t_end:
            _fail("trajectory", f"trajectory spans [{t[0]}, {t[-1]}], the system [{s.t_start}, {s.t_end}]")
        if not (np.all(np.isfinite(p)) and np.all(np.isfinite(sd)) and np.all(sd >= 0)):
            _fail("trajectory", "positions and sigmas must be finite, sigmas ≥ 0")
        if not _same_bits(p[-1], s.position_n()):
            _fail("trajectory", f"the last trajectory row is not position_n() ({_max_diff(p[-1], s.position_n())})")
        var = np.diag(np.asarray(s.covariance()))[self.cls.position_indices]
        if not np.allclose(sd[-1], np.sqrt(np.maximum(var, 0.0)), rtol=1e-9, atol=0):
            _fail("trajectory", f"the last pos_sd {sd[-1].tolist()} is not the square root of the covariance's "
                                f"position variances {var.tolist()}")
        return f"{N} rows"

    def check_cross_covariance(self) -> str:
        s = self.build()
        try:
            s.track_transition()
        except FusionError as err:
            raise _Skip(f"the system does not track cross-covariances ({err})") from None
        n = self.n
        P_then = np.asarray(s.covariance(), dtype=float)
        times = _chunk_times(s, self.chunks)
        for k, t in enumerate(times):
            s.advance(t)
            phi = np.asarray(s.transition_since_sync(), dtype=float)
            if phi.shape != (n, n) or not np.all(np.isfinite(phi)):
                _fail("cross_covariance", f"transition_since_sync() gave shape {phi.shape} or non-finite values")
            P_now = np.asarray(s.covariance(), dtype=float)
            D = P_now - phi @ P_then @ phi.T
            scale = max(float(np.max(np.abs(np.diag(P_now)))), float(np.max(np.abs(np.diag(P_then)))))
            low = float(np.linalg.eigvalsh(0.5 * (D + D.T)).min())
            if low < -1e-7 * scale:
                _fail("cross_covariance", f"after chunk {k + 1} (t={s.t_now:.6g} s) P_now − Φ P_then Φᵀ has eigenvalue "
                                          f"{low:.3g} (largest variance {scale:.3g}): Φ is not the transition "
                                          "the covariance went through")
            again = np.asarray(s.transition_since_sync(), dtype=float)
            if not np.array_equal(again, np.eye(n)):
                _fail("cross_covariance", "a second transition_since_sync() without advancing is not I "
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
                _fail("jacobians", "jacobian_cases() returned no cases")
            for case in cases:
                check_jacobian(case)
            notes.append(f"{len(cases)} cases from jacobian_cases()")
        if self.error_model == STRAPDOWN15:
            notes.append(_check_strapdown15(s))
        elif self.error_model is not None:
            _fail("jacobians", f"unknown error_model {self.error_model!r} (known: {STRAPDOWN15!r})")
        if not notes:
            raise _Skip("no analytic Jacobians declared (no jacobian_cases(), no error_model)")
        return "; ".join(notes)


class _AidingChecker(_Checker):
    """The checks of an aiding source (:data:`AIDING_CHECKS`); the shared ones from :class:`_Checker`."""

    base = AidingSource

    def check_interface(self) -> str:
        return f"{self.cls.__name__} as {self._check_plugin_class()!r} (aiding source)"

    def check_build(self) -> str:
        s = self.build()
        refs = self.cls.system_references(s.config)
        return f"{s.samples} measurements of {sorted({r for _, r in refs})}"

    @staticmethod
    def _positions(count: int) -> list[np.ndarray]:
        return [np.array([1.5, -2.0, 0.25]) * (i + 1) for i in range(count)]

    def _measurements(self, s: AidingSource) -> list[ScalarMeasurement]:
        return [s.measure(k, self._positions(len(s.measured_systems(k)))) for k in range(len(s.measurement_times()))]

    def check_measurements(self) -> str:
        s = self.build()
        t = np.asarray(s.measurement_times(), dtype=float)
        if t.ndim != 1 or t.size == 0 or not np.all(np.isfinite(t)) or np.any(np.diff(t) < 0):
            _fail("measurements", "measurement_times() must be (K,) finite, non-decreasing, K ≥ 1")
        if not isinstance(s.samples, (int, np.integer)) or s.samples != t.size:
            _fail("measurements", f"samples ({s.samples!r}) is not the number of measurements ({t.size})")
        if not isinstance(s.input_report, InputReport):
            _fail("measurements", "input_report must be a bodyfusion.core.types.InputReport")
        named = {r for _, r in self.cls.system_references(s.config)}
        for k in range(t.size):
            systems = s.measured_systems(k)
            if not (1 <= len(systems) <= 2 and set(systems) <= named):
                _fail("measurements", f"measurement {k} relates {systems!r}; want one or two of {sorted(named)}")
        for k, m in enumerate(self._measurements(s)):
            H = np.asarray(m.H_p, dtype=float)
            if H.shape != (len(s.measured_systems(k)), 3) or not np.all(np.isfinite(H)):
                _fail("measurements", f"measurement {k}: H_p has shape {H.shape} or non-finite values")
            if not (math.isfinite(m.z) and math.isfinite(m.predicted) and m.r_var > 0):
                _fail("measurements", f"measurement {k}: z {m.z!r}, h {m.predicted!r}, r {m.r_var!r}")
        if not s.gate_nis > 0:
            _fail("measurements", f"gate_nis must be positive, got {s.gate_nis!r}")
        for k in range(t.size):
            s.record(k, 1.0 if k % 2 else 1e6, bool(k % 2))
        for diag in (self.build().diagnostics(), s.diagnostics()):
            try:
                json.dumps(diag, default=float)
            except (TypeError, ValueError) as err:
                _fail("measurements", f"diagnostics() is not JSON-serialisable: {err}")
        return f"{t.size} measurements"

    def check_seed(self) -> str:
        def bits(seed: int) -> tuple:
            s = self.build(seed)
            ms = self._measurements(s)
            return (_bits(s.measurement_times()), _bits([m.z for m in ms]), _bits([m.r_var for m in ms]))

        seed = self.context.seed
        if bits(seed) != bits(seed):
            _fail("seed", f"two builds with seed {seed} give different measurements")
        if self.stochastic is None:
            return "same seed, same bits"
        differs = bits(seed) != bits(seed + 1)
        if differs != self.stochastic:
            _fail("seed", f"seeds {seed} and {seed + 1} give {'different' if differs else 'the same'} measurements, "
                          f"but the source is declared {'stochastic' if self.stochastic else 'deterministic'}")
        return "same seed, same bits; " + ("another seed differs" if self.stochastic else "seed-independent")

    def check_gating(self) -> str:
        from bodyfusion.core.fuser import scalar_update

        s = self.build()
        kinds = {}
        for k in range(len(s.measurement_times())):
            kinds.setdefault(len(s.measured_systems(k)), k)
        for count, k in sorted(kinds.items()):
            m = s.measure(k, self._positions(count))
            H = np.asarray(m.H_p, dtype=float).ravel()
            P = 0.01 * np.eye(H.size)
            sd = math.sqrt(float(H @ P @ H) + m.r_var)
            nis, dx, P_new = scalar_update(P, H, 0.0, m.r_var, s.gate_nis)
            if dx is None or np.linalg.eigvalsh(P_new).min() < -1e-12:
                _fail("gating", f"measurement {k} equal to its prediction was rejected (NIS {nis:.3g})")
            nis, dx, _ = scalar_update(P, H, 10.0 * sd * (1.0 + math.sqrt(s.gate_nis)), m.r_var, s.gate_nis)
            if dx is not None:
                _fail("gating", f"measurement {k} far beyond the gate was accepted (NIS {nis:.3g}, gate "
                                f"{s.gate_nis:.3g})")
        return f"gate NIS {s.gate_nis:.3g}: {len(kinds)} measurement kinds accepted at 0, rejected far out"


def check_system(system_cls: type, config: Mapping[str, Any], *, name: str = "system",
                 context: LayoutContext | None = None, chunks: int = 5,
                 bad_configs: Sequence[tuple[Mapping[str, Any], str]] = (), stochastic: bool | None = None,
                 error_model: str | None = None, allow_undocumented: Iterable[str] = (),
                 checks: Iterable[str] | None = None, raise_on_failure: bool = True) -> ConformanceReport:
    """Run every conformance check (:data:`CHECKS`) on a sensor-system plugin class, or
    those of :data:`AIDING_CHECKS` on an aiding-source class.

    Parameters
    ----------
    system_cls: the :class:`~bodyfusion.core.system.SensorSystem` subclass.
    config: a valid layout section for it, as a dict (``plugin`` may be left out);
        relative paths resolve against ``context.base_dir``.
    name: the system's name in the layout (error keys read ``systems.<name>.<key>``).
    context: layout facts; default :func:`default_context` (g 9.80665, seed 0, base dir ".").
    chunks: uniform chunk ends for the covariance and chunking checks (sync times are added).
    bad_configs: ``(config, dotted_key)`` pairs that must be refused with a ConfigError
        naming ``systems.<name>.<dotted_key>`` (see :func:`with_value`).
    stochastic: True if the system draws random numbers (another seed must differ), False
        if it must not depend on the seed, None to check only same seed → same bits.
    error_model: override of the class's ``error_model`` attribute (``"strapdown15"``).
    allow_undocumented: dotted parameter paths known to be undocumented (a ratchet: an
        entry that is documented, or no field, fails the check).
    checks: run only these checks (and those they need); default all.
    raise_on_failure: raise :class:`ConformanceError` if any check fails (default).

    Returns the :class:`ConformanceReport`. Each check records ``passed``, ``failed`` (with
    the reason) or ``skipped`` (does not apply, or a check it needs failed).
    """
    ctx = context if context is not None else default_context()
    plugin = getattr(system_cls, "plugin_name", getattr(system_cls, "__name__", repr(system_cls)))
    aiding = isinstance(system_cls, type) and issubclass(system_cls, AidingSource)
    names = AIDING_CHECKS if aiding else CHECKS
    chk = (_AidingChecker if aiding else _Checker)(system_cls, config, name, ctx, chunks, bad_configs, stochastic,
                                                    error_model, allow_undocumented)
    wanted = set(names if checks is None else checks)
    unknown = wanted - set(names)
    if unknown:
        raise ValueError(f"unknown checks {sorted(unknown)}; known: {', '.join(names)}")
    report = ConformanceReport(str(plugin))
    needs = {"interface": (), "documented": ("interface",), "bad_config": ("interface",), "build": ("interface",)}
    for check in names:
        if check not in wanted and not (check in ("interface", "build") and wanted - {"interface", "documented"}):
            continue
        blockers = [r.name for r in report.results
                    if r.status == "failed" and r.name in needs.get(check, ("interface", "build"))]
        if blockers:
            report.results.append(CheckResult(check, "skipped", f"not run: {', '.join(blockers)} failed"))
            continue
        try:
            detail = getattr(chk, f"check_{check}")()
            report.results.append(CheckResult(check, "passed", detail or ""))
        except _Skip as skip:
            report.results.append(CheckResult(check, "skipped", str(skip)))
        except AssertionError as err:
            report.results.append(CheckResult(check, "failed", str(err)))
        except Exception as err:  # noqa: BLE001 - a crash inside a check is that check's failure
            report.results.append(CheckResult(check, "failed", f"raised {type(err).__name__}: {err}"))
    if raise_on_failure and report.failed:
        raise ConformanceError(report)
    return report
