"""Analytic Jacobians against central differences, and the check of the core 15-state INS error model.

A plugin states its analytic Jacobians as :class:`JacobianCase` s (from its optional
``jacobian_cases()``); :func:`check_jacobian` compares each with :func:`numerical_jacobian`.
A system whose ``error_model`` is :data:`STRAPDOWN15` (built on :mod:`bodyfusion.nav.strapdown`
and :mod:`bodyfusion.nav.error_state`) is checked by :func:`check_strapdown15`: the transition
F of :func:`strapdown15_jacobian_cases` at random nominal states (:func:`random_nominal_state`)
and the system's own IMU samples (canned samples if it has none), and the covariance
propagation with that F.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from bodyfusion.core.system import JacobianCase, SensorSystem
from bodyfusion.base.types import ImuStream
from bodyfusion.nav.error_state import (
    ERROR_SIZE,
    accumulate_propagation,
    error_between,
    inject,
    propagate_covariance,
)
from bodyfusion.nav.strapdown import NOMINAL_SIZE, mechanise
from bodyfusion.testing.compare import max_diff

STRAPDOWN15 = "strapdown15"
"""``error_model`` value of systems built on :mod:`bodyfusion.nav.strapdown` + :mod:`bodyfusion.nav.error_state`."""

# IMU samples (m/s², rad/s, s) for a strapdown15 system without an ImuStream ``stream``:
# near rest, a hard manoeuvre, low specific force in a fast turn
_CANNED_ACC_B = np.array([[0.3, -0.4, 9.9], [4.0, -7.0, 15.0], [-2.0, 1.0, 3.0]])
_CANNED_GYRO_B = np.array([[0.02, -0.01, 0.03], [1.5, -3.0, 0.8], [-0.2, 0.1, -2.5]])
_CANNED_DT_S = 0.01


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
    x = np.zeros(NOMINAL_SIZE)
    x[0:3] = rng.normal(0, 5, 3)
    x[3:6] = rng.normal(0, 1, 3)
    x[6:10] = Rotation.random(random_state=int(rng.integers(1 << 30))).as_quat(scalar_first=True)
    x[10:13] = rng.normal(0, 0.05, 3)
    x[13:16] = rng.normal(0, 0.01, 3)
    return x


def _mechanise_step(x: np.ndarray, acc: np.ndarray, gyro: np.ndarray, dt: float,
                    gravity: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One :func:`bodyfusion.nav.strapdown.mechanise` step from a copy of ``x`` (no Earth
    rotation): the state after it, C_nb at its start and the mean navigation-frame specific force."""
    x = np.ascontiguousarray(x, dtype=np.float64).copy()
    f_n, C = np.empty(3), np.empty((3, 3))
    mechanise(x, np.ascontiguousarray(acc), np.ascontiguousarray(gyro), float(dt), float(gravity), np.zeros(3),
              f_n, np.zeros(6), C)
    return x, np.ascontiguousarray(C), f_n


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
    rng = np.random.default_rng(seed)

    def retract(x: np.ndarray, dx: np.ndarray) -> np.ndarray:
        out = np.ascontiguousarray(x, dtype=np.float64).copy()
        inject(out, np.ascontiguousarray(dx, dtype=np.float64))
        return out

    cases = []
    for k, (acc, gyro) in enumerate(zip(np.asarray(acc_b, dtype=float), np.asarray(gyro_b, dtype=float))):
        acc = np.ascontiguousarray(acc)
        gyro = np.ascontiguousarray(gyro)
        x = random_nominal_state(rng)
        _, C, f_n = _mechanise_step(x, acc, gyro, dt, gravity)
        F = np.eye(ERROR_SIZE)
        accumulate_propagation(F, C, f_n, float(dt))
        first_order = float(np.max(np.abs(F - np.eye(ERROR_SIZE))))
        cases.append(JacobianCase(
            name=f"strapdown15 transition F at sample {k} (|f| {np.linalg.norm(acc):.2f} m/s², "
                 f"|ω| {np.linalg.norm(gyro):.2f} rad/s, dt {dt:.4g} s)",
            func=lambda x, a=acc, g=gyro: _mechanise_step(x, a, g, dt, gravity)[0], x=x, jacobian=F, step=1e-6,
            atol=0.05 * first_order, rtol=0.0, retract=retract, difference=error_between))
    return cases


def _strapdown15_samples(system: SensorSystem) -> tuple[np.ndarray, np.ndarray, float, str]:
    """(acc (K, 3), gyro (K, 3), dt, where they come from): four samples of the system's own
    ImuStream (the quietest, the fastest turn, the largest specific-force deviation from g,
    the middle one), or the canned samples."""
    stream = getattr(system, "stream", None)
    if isinstance(stream, ImuStream) and len(stream) > 2:
        dt = float(np.median(np.diff(stream.t)))
        dev = np.abs(np.linalg.norm(stream.acc_b, axis=1) - system.context.gravity_mps2)
        rate = np.linalg.norm(stream.gyro_b, axis=1)
        picks = sorted({int(np.argmin(rate + dev)), int(np.argmax(rate)), int(np.argmax(dev)), len(stream) // 2})
        return stream.acc_b[picks], stream.gyro_b[picks], dt, f"samples {picks} of the system's stream"
    return _CANNED_ACC_B, _CANNED_GYRO_B, _CANNED_DT_S, "canned IMU samples (the system has no ImuStream ``stream``)"


def check_strapdown15(system: SensorSystem) -> str:
    """F from the core error model against finite differences of the mechanisation, at the
    system's own IMU samples, and propagate_covariance(P) = F P Fᵀ + Q_d."""
    acc, gyro, dt, source = _strapdown15_samples(system)
    gravity = system.context.gravity_mps2
    cases = strapdown15_jacobian_cases(acc, gyro, dt, gravity)
    for case in cases:
        check_jacobian(case)
    # the covariance propagation uses the same F
    rng = np.random.default_rng(1)
    A = rng.normal(0, 1, (ERROR_SIZE, ERROR_SIZE))
    P = A @ A.T / ERROR_SIZE + 0.1 * np.eye(ERROR_SIZE)
    case = cases[-1]
    _, C, f_n = _mechanise_step(case.x, acc[-1], gyro[-1], dt, gravity)
    F = case.jacobian
    q = np.linspace(1e-6, 1e-3, ERROR_SIZE)
    got = P.copy()
    propagate_covariance(got, C, f_n, dt, q)
    want = F @ P @ F.T + np.diag(q * dt)
    if np.max(np.abs(got - want)) > 1e-12 * np.max(np.abs(want)):
        raise AssertionError(f"strapdown15: propagate_covariance differs from F P Fᵀ + Q_d ({max_diff(got, want)})")
    return f"{len(cases)} strapdown15 cases at {source}"
