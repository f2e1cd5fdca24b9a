"""The conformance checks of an aiding-source plugin (a UWB tag...): :class:`AidingChecker`.

An aiding source shares the ``interface``, ``documented``, ``bad_config`` and ``build``
checks with a sensor system (:class:`~bodyfusion.testing.systems.SystemChecker`) and has
its own ``measurements``, ``seed``, ``jacobians`` and ``gating`` (:data:`AIDING_CHECKS`).
"""

from __future__ import annotations

import json
import math

import numpy as np

from bodyfusion.nav.kalman import gated_update
from bodyfusion.core.system import AidingSource, ScalarMeasurement
from bodyfusion.base.types import InputReport
from bodyfusion.testing.compare import as_bytes
from bodyfusion.testing.systems import SystemChecker, fail

AIDING_CHECKS = ("interface", "documented", "bad_config", "build", "measurements", "seed", "jacobians", "gating")
"""Names of the checks of an :class:`~bodyfusion.core.system.AidingSource` (a UWB tag...), in order:
``interface``, ``documented``, ``bad_config`` and ``build`` as for a system;
``measurements``: times finite and non-decreasing, each measurement relates one or two of
the systems the config names and gives a finite z, h(p̂), ∂h/∂p (m, 3) and r > 0;
``samples``, ``input_report``, JSON-serialisable ``diagnostics()`` before and after the
fuser's verdicts; ``seed``: two builds give the same bits (and, with ``stochastic``,
another seed differs or not); ``jacobians``: the ``jacobian_cases()`` against central
differences; ``gating``: through the fuser's update (:func:`bodyfusion.nav.kalman.gated_update`)
with position variances of 0.01 m², a measurement equal to its prediction is accepted and
one 10 innovation sigmas beyond the gate is rejected."""


class AidingChecker(SystemChecker):
    """The checks of an aiding source (:data:`AIDING_CHECKS`); the shared ones from :class:`SystemChecker`."""

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
            fail("measurements", "measurement_times() must be (K,) finite, non-decreasing, K ≥ 1")
        if not isinstance(s.samples, (int, np.integer)) or s.samples != t.size:
            fail("measurements", f"samples ({s.samples!r}) is not the number of measurements ({t.size})")
        if not isinstance(s.input_report, InputReport):
            fail("measurements", "input_report must be a bodyfusion.base.types.InputReport")
        named = {r for _, r in self.cls.system_references(s.config)}
        for k in range(t.size):
            systems = s.measured_systems(k)
            if not (1 <= len(systems) <= 2 and set(systems) <= named):
                fail("measurements", f"measurement {k} relates {systems!r}; want one or two of {sorted(named)}")
        for k, m in enumerate(self._measurements(s)):
            H = np.asarray(m.H_p, dtype=float)
            if H.shape != (len(s.measured_systems(k)), 3) or not np.all(np.isfinite(H)):
                fail("measurements", f"measurement {k}: H_p has shape {H.shape} or non-finite values")
            if not (math.isfinite(m.z) and math.isfinite(m.predicted) and m.r_var > 0):
                fail("measurements", f"measurement {k}: z {m.z!r}, h {m.predicted!r}, r {m.r_var!r}")
        if not s.gate_nis > 0:
            fail("measurements", f"gate_nis must be positive, got {s.gate_nis!r}")
        for k in range(t.size):
            s.record(k, 1.0 if k % 2 else 1e6, bool(k % 2))
        for diag in (self.build().diagnostics(), s.diagnostics()):
            try:
                json.dumps(diag, default=float)
            except (TypeError, ValueError) as err:
                fail("measurements", f"diagnostics() is not JSON-serialisable: {err}")
        return f"{t.size} measurements"

    def check_seed(self) -> str:
        def bits(seed: int) -> tuple:
            s = self.build(seed)
            ms = self._measurements(s)
            return (as_bytes(s.measurement_times()), as_bytes([m.z for m in ms]), as_bytes([m.r_var for m in ms]))

        seed = self.context.seed
        if bits(seed) != bits(seed):
            fail("seed", f"two builds with seed {seed} give different measurements")
        if self.stochastic is None:
            return "same seed, same bits"
        differs = bits(seed) != bits(seed + 1)
        if differs != self.stochastic:
            fail("seed", f"seeds {seed} and {seed + 1} give {'different' if differs else 'the same'} measurements, "
                         f"but the source is declared {'stochastic' if self.stochastic else 'deterministic'}")
        return "same seed, same bits; " + ("another seed differs" if self.stochastic else "seed-independent")

    def check_gating(self) -> str:
        s = self.build()
        kinds = {}
        for k in range(len(s.measurement_times())):
            kinds.setdefault(len(s.measured_systems(k)), k)
        for count, k in sorted(kinds.items()):
            m = s.measure(k, self._positions(count))
            H = np.asarray(m.H_p, dtype=float).ravel()
            P = 0.01 * np.eye(H.size)
            sd = math.sqrt(float(H @ P @ H) + m.r_var)
            nis, accepted, _, P_new = gated_update(P, H, m.r_var, 0.0, s.gate_nis)
            if not accepted or np.linalg.eigvalsh(P_new).min() < -1e-12:
                fail("gating", f"measurement {k} equal to its prediction was rejected (NIS {nis:.3g})")
            nis, accepted, _, _ = gated_update(P, H, m.r_var, 10.0 * sd * (1.0 + math.sqrt(s.gate_nis)), s.gate_nis)
            if accepted:
                fail("gating", f"measurement {k} far beyond the gate was accepted (NIS {nis:.3g}, gate "
                               f"{s.gate_nis:.3g})")
        return f"gate NIS {s.gate_nis:.3g}: {len(kinds)} measurement kinds accepted at 0, rejected far out"
