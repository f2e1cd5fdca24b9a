"""Simulated IMUs: the ideal sensor from a trajectory, and the sensor error model.

Ideal IMU
    Specific force ``f_b = C_bn (a_n − g_n)`` with ``g_n = [0, 0, −g]`` and angular rate
    ``ω_b = C_bn ω_n`` (``ω_n``: the body's angular velocity in the navigation frame; no
    Earth rotation, the matching mechanisation runs with the Earth rate off). Sample k is
    the MEAN over ``(t_{k−1}, t_k]`` — the increment convention of
    :mod:`bodyfusion.nav.strapdown` — integrated with Gauss–Legendre quadrature on each interval
    (8 nodes: exact for polynomials up to degree 15); sample 0 is the instantaneous value.

Consistency with the mechanisation: free inertial integration of the ideal IMU with
:func:`bodyfusion.nav.strapdown.integrate` (default gait) leaves a truncation error that falls as
dt²: at 100 Hz ≈ 18 mm after the first stride, mostly vertical (the velocity update has
no sculling or second-order rotation terms; the attitude update no coning term, which
shows after turns); at 1000 Hz ≈ 0.2 mm per stride and 3.5 cm after 20 s. A
mechanisation with those terms reaches ≈ 0.25 mm per stride at 100 Hz
(``tests/test_sim.py``).

Error model (per triad, accelerometer and gyroscope alike)::

    y_k = (I + S + M) x_k + b_const + b_gm(t_k) + b_rw(t_k) + b_w (1 − e^(−t_k/τ_w)) + n_k

``S``: scale factors (ppm); ``M``: axis misalignment (off-diagonal, mrad);
``b_const``: turn-on bias (given vector plus a draw of σ ``*_bias_sd_*``);
``b_gm``: first-order Gauss–Markov bias instability (stationary σ, correlation time τ);
``b_rw``: bias random walk (density, starts at 0); ``b_w``: the warm-up drift, the bias's
move while the part heats after power-on (a draw of σ ``*_bias_warmup_*`` per axis, reached with
time constant τ_w ``*_bias_warmup_tau_s``: the temperature transient a datasheet's bias
temperature coefficient and a filter's bias model leave out); ``n_k``: white noise of
per-sample σ = density·√rate. A sensor with a ``range`` then clips every axis of ``y_k`` to
±range (saturation: a swing turning faster than the gyroscope measures). Units: accelerometer m/s^2 (density m/s^2/√Hz, random
walk m/s^3/√Hz), gyroscope rad/s (density rad/s/√Hz, random walk rad/s^2/√Hz).

Random numbers: every system has its own :class:`numpy.random.SeedSequence` built
from ``(seed, stable_hash(system name))``; each error term of each sensor draws from its
own child of it (:func:`error_generators`). The same seed gives the same bits, adding a
system leaves the others' noise alone, and switching one error term on or off leaves
the other terms' draws alone.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Literal, Protocol

import numpy as np
from pydantic import Field
from scipy.signal import lfilter

from bodyfusion.base.seeding import system_seed

from bodyfusion.base.sections import StrictModel
from bodyfusion.nav.earth import STANDARD_GRAVITY

__all__ = [
    "ERROR_TERMS",
    "ImuErrorConfig",
    "ImuErrorModel",
    "MotionState",
    "PRESETS",
    "SensorErrors",
    "blockwise",
    "corrupt",
    "dcm_from_quat",
    "error_generators",
    "ideal_imu",
    "quat_multiply",
]

_DEG = math.pi / 180.0


# --------------------------------------------------------------------------- kinematics


@dataclass
class MotionState:
    """A rigid body's motion at N instants, ENU navigation frame.

    pos, vel, acc: (N, 3) m, m/s, m/s^2. q_nb: (N, 4) scalar-first body→nav.
    omega_n: (N, 3) angular velocity of the body, navigation-frame components, rad/s.
    """

    pos: np.ndarray
    vel: np.ndarray
    acc: np.ndarray
    q_nb: np.ndarray
    omega_n: np.ndarray


class Motion(Protocol):
    """Anything the ideal IMU can sample: analytic in time, vectorised."""

    def evaluate(self, t: np.ndarray) -> MotionState: ...


EVALUATE_BLOCK = 1 << 16
"""Instants a motion model evaluates at once (:func:`blockwise`): its temporaries are a few
dozen arrays of this length, whatever the length of the walk."""


def blockwise(evaluate: Callable[[np.ndarray], MotionState], t: np.ndarray) -> MotionState:
    """``evaluate(t)`` of a motion that computes every instant on its own (the same numbers),
    :data:`EVALUATE_BLOCK` instants at a time into arrays sized once."""
    t = np.atleast_1d(np.asarray(t, dtype=float))
    if t.size <= EVALUATE_BLOCK:
        return evaluate(t)
    n = t.size
    out = MotionState(pos=np.empty((n, 3)), vel=np.empty((n, 3)), acc=np.empty((n, 3)), q_nb=np.empty((n, 4)),
                      omega_n=np.empty((n, 3)))
    for lo in range(0, n, EVALUATE_BLOCK):
        part = evaluate(t[lo:lo + EVALUATE_BLOCK])
        for name in ("pos", "vel", "acc", "q_nb", "omega_n"):
            getattr(out, name)[lo:lo + EVALUATE_BLOCK] = getattr(part, name)
    return out


def quat_multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton products of scalar-first quaternions, broadcast over leading axes."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    aw, ax, ay, az = np.moveaxis(a, -1, 0)
    bw, bx, by, bz = np.moveaxis(b, -1, 0)
    return np.stack([
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    ], axis=-1)


def quat_about_axis(angle: np.ndarray, axis: int) -> np.ndarray:
    """Quaternions (..., 4), scalar first, of rotations by ``angle`` (rad) about body axis
    ``axis`` (1: x, 2: y, 3: z: the quaternion component it sets)."""
    h = 0.5 * np.asarray(angle, dtype=float)
    q = np.zeros(h.shape + (4,))
    q[..., 0] = np.cos(h)
    q[..., axis] = np.sin(h)
    return q


def dcm_from_quat(q: np.ndarray) -> np.ndarray:
    """C_nb (..., 3, 3) of unit scalar-first quaternions q_nb (..., 4)."""
    w, x, y, z = np.moveaxis(np.asarray(q, dtype=float), -1, 0)
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], axis=-1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], axis=-1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], axis=-1),
    ], axis=-2)


def _body_readings(state: MotionState, g: float) -> tuple[np.ndarray, np.ndarray]:
    C = dcm_from_quat(state.q_nb)
    f_n = state.acc.copy()
    f_n[:, 2] += g
    f_b = np.einsum("nji,nj->ni", C, f_n)
    w_b = np.einsum("nji,nj->ni", C, state.omega_n)
    return f_b, w_b


def ideal_imu(motion: Motion, t: np.ndarray, g: float, *, nodes: int = 8,
              chunk: int = 2048) -> tuple[np.ndarray, np.ndarray]:
    """Error-free specific force (N, 3) m/s^2 and angular rate (N, 3) rad/s at times ``t``.

    Sample k ≥ 1 is the mean over (t[k−1], t[k]] by ``nodes``-point Gauss–Legendre
    quadrature; sample 0 is the instantaneous value at t[0]. The motion is evaluated
    ``chunk`` samples at a time (every value is computed point by point, so the chunk
    changes no bit): 2048 samples keep its temporaries in the core's cache (a foot ~20 %
    faster than with 20,000, a tenth of the memory).
    """
    t = np.asarray(t, dtype=float)
    n = t.size
    acc = np.empty((n, 3))
    gyro = np.empty((n, 3))
    acc[:1], gyro[:1] = _body_readings(motion.evaluate(t[:1]), g)
    x, w = np.polynomial.legendre.leggauss(nodes)
    frac = 0.5 * (x + 1.0)
    weight = 0.5 * w
    for lo in range(1, n, chunk):
        hi = min(lo + chunk, n)
        t0 = t[lo - 1:hi - 1]
        dt = t[lo:hi] - t0
        tn = (t0[:, None] + dt[:, None] * frac[None, :]).ravel()
        f_b, w_b = _body_readings(motion.evaluate(tn), g)
        acc[lo:hi] = np.einsum("q,kqi->ki", weight, f_b.reshape(hi - lo, nodes, 3))
        gyro[lo:hi] = np.einsum("q,kqi->ki", weight, w_b.reshape(hi - lo, nodes, 3))
    return acc, gyro


# --------------------------------------------------------------------------- error model


Vec3 = tuple[float, float, float]
Vec6 = tuple[float, float, float, float, float, float]


@dataclass(frozen=True)
class SensorErrors:
    """Fully resolved errors of one triad (units in the module docstring)."""

    noise_density: float = 0.0
    bias_instability: float = 0.0
    bias_tau_s: float = 100.0
    bias_random_walk: float = 0.0
    bias: Vec3 = (0.0, 0.0, 0.0)
    bias_sd: float = 0.0
    scale_ppm: Vec3 = (0.0, 0.0, 0.0)
    misalignment_mrad: Vec6 = (0.0,) * 6
    warmup_sd: float = 0.0
    """σ per axis of the bias's warm-up drift b_w (module docstring)."""
    warmup_tau_s: float = 300.0
    """Time constant τ_w of the warm-up drift (s)."""
    range: float = math.inf
    """Largest reading per axis (m/s^2 or rad/s); beyond it the sensor reads ±range."""

    @property
    def bias_drift_density(self) -> float:
        """Random-walk density a filter can use to model this bias drift: the Gauss–Markov
        driving noise σ·√(2/τ) and the random walk, added in quadrature."""
        gm = self.bias_instability * math.sqrt(2.0 / self.bias_tau_s) if self.bias_instability else 0.0
        return math.hypot(gm, self.bias_random_walk)

    @property
    def gauss_markov_tau_s(self) -> float | None:
        """τ (s) when the bias is exactly one zero-mean first-order Gauss–Markov process (no
        turn-on bias, no random walk): a filter can then model it as such; else None."""
        pure = (self.bias_instability > 0 and self.bias_random_walk == 0 and self.bias_sd == 0
                and not any(self.bias))
        return self.bias_tau_s if pure else None

    def initial_bias_sd(self, averaged_s: float = 0.0) -> float:
        """One-sigma bias (per axis) a filter starts with: the turn-on bias (the fixed
        vector's RMS and the drawn σ) and the Gauss–Markov σ, added in quadrature. When the
        bias is estimated by averaging a still window of T = ``averaged_s`` seconds starting
        at the first sample, what is left is that average's white-noise error N/√T and the
        Gauss–Markov bias's move from the first sample to the window's mean,
        var(b_0 − b̄) = σ² (1 − 2 m + 2 (τ/T)(1 − m)), m = (τ/T)(1 − e^(−T/τ))."""
        gm = self.bias_instability
        if averaged_s > 0:
            m = self.bias_tau_s / averaged_s * -math.expm1(-averaged_s / self.bias_tau_s)
            moved = gm * math.sqrt(max(1.0 - 2.0 * m + 2.0 * self.bias_tau_s / averaged_s * (1.0 - m), 0.0))
            return math.hypot(self.noise_density / math.sqrt(averaged_s), moved)
        fixed = math.sqrt(sum(b * b for b in self.bias) / 3.0)
        return math.sqrt(fixed**2 + self.bias_sd**2 + gm**2)


@dataclass(frozen=True)
class ImuErrorModel:
    """Errors of both triads of one IMU."""

    acc: SensorErrors
    gyro: SensorErrors


_UG = 1e-6 * STANDARD_GRAVITY
PRESETS: dict[str, dict[str, float]] = {
    "perfect": {},
    # [Shen2025] (FB-RTS), Table 1, ICM-20948 nodes at 125 Hz: gyroscope white noise
    # 0.5 °/√h and bias instability 13 °/h; accelerometer 168 µg/√Hz and 162 µg. Bias
    # instability is simulated as a Gauss–Markov process of that σ with τ = 100 s.
    "icm20948": {
        "gyro_noise_density": 0.5 * _DEG / 60.0,          # °/√h → rad/s/√Hz
        "gyro_bias_instability_radps": 13.0 * _DEG / 3600.0,  # °/h → rad/s
        "gyro_bias_tau_s": 100.0,
        "acc_noise_density": 168.0 * _UG,                 # µg/√Hz → m/s^2/√Hz
        "acc_bias_instability_mps2": 162.0 * _UG,          # µg → m/s^2
        "acc_bias_tau_s": 100.0,
    },
    # A smartphone-grade MEMS IMU (BMI160 / LSM6DS-class datasheet values, after the OS's
    # own gyro calibration): gyroscope white noise 0.007 °/s/√Hz, bias instability 10 °/h
    # (Gauss–Markov, τ = 100 s) and a turn-on bias of σ 0.05 °/s; accelerometer
    # 180 µg/√Hz, bias instability 100 µg (τ = 100 s) and a turn-on bias of σ 5 mg.
    "phone": {
        "gyro_noise_density": 0.007 * _DEG,               # °/s/√Hz → rad/s/√Hz
        "gyro_bias_instability_radps": 10.0 * _DEG / 3600.0,
        "gyro_bias_tau_s": 100.0,
        "gyro_bias_sd_radps": 0.05 * _DEG,
        "acc_noise_density": 180.0 * _UG,
        "acc_bias_instability_mps2": 100.0 * _UG,
        "acc_bias_tau_s": 100.0,
        "acc_bias_sd_mps2": 5000.0 * _UG,
    },
    # A consumer-grade MEMS IMU, the dual-foot papers' class of sensor (MPU-6050 /
    # MPU-9250-class low-cost parts, not factory-calibrated over temperature): an order of
    # magnitude worse than the ICM-20948 in bias instability. Gyroscope: angle random walk
    # 1 °/√h (0.017 °/s/√Hz), bias instability 100 °/h (Gauss–Markov, τ = 100 s), turn-on
    # bias σ 1 °/s; accelerometer: 400 µg/√Hz (the MPU-6050 datasheet's noise density), bias
    # instability 2 mg (τ = 100 s), turn-on bias σ 20 mg (the datasheet's ±50 mg initial
    # tolerance as ≈ 2.5 σ).
    "consumer": {
        "gyro_noise_density": 1.0 * _DEG / 60.0,           # °/√h → rad/s/√Hz
        "gyro_bias_instability_radps": 100.0 * _DEG / 3600.0,  # °/h → rad/s
        "gyro_bias_tau_s": 100.0,
        "gyro_bias_sd_radps": 1.0 * _DEG,                 # °/s → rad/s
        "acc_noise_density": 400.0 * _UG,                 # µg/√Hz → m/s^2/√Hz
        "acc_bias_instability_mps2": 2000.0 * _UG,         # µg → m/s^2
        "acc_bias_tau_s": 100.0,
        "acc_bias_sd_mps2": 20000.0 * _UG,
    },
}
"""Named error sets; any field of :class:`ImuErrorConfig` given beside ``preset`` overrides it."""


class ImuErrorConfig(StrictModel):
    """A scenario's ``imu`` section: a preset plus overrides of any of its fields.

    A turn-on bias is the given vector plus a draw of the given σ (either may be absent).
    Misalignment: six small angles (mrad) for the off-diagonal entries xy, xz, yx, yz, zx, zy.
    """

    preset: Literal["perfect", "icm20948", "phone", "consumer"] = "perfect"
    acc_noise_density: float | None = Field(default=None, ge=0)
    gyro_noise_density: float | None = Field(default=None, ge=0)
    acc_bias_instability_mps2: float | None = Field(default=None, ge=0)
    gyro_bias_instability_radps: float | None = Field(default=None, ge=0)
    acc_bias_tau_s: float | None = Field(default=None, gt=0)
    gyro_bias_tau_s: float | None = Field(default=None, gt=0)
    acc_bias_random_walk: float | None = Field(default=None, ge=0)
    gyro_bias_random_walk: float | None = Field(default=None, ge=0)
    acc_bias_mps2: Vec3 | None = None
    gyro_bias_radps: Vec3 | None = None
    acc_bias_sd_mps2: float | None = Field(default=None, ge=0)
    gyro_bias_sd_radps: float | None = Field(default=None, ge=0)
    acc_scale_ppm: Vec3 | float | None = None
    gyro_scale_ppm: Vec3 | float | None = None
    acc_misalignment_mrad: Vec6 | None = None
    gyro_misalignment_mrad: Vec6 | None = None
    acc_bias_warmup_mps2: float | None = Field(default=None, ge=0)
    """σ per axis of the accelerometer bias's warm-up drift (m/s^2; unset: none)."""
    gyro_bias_warmup_radps: float | None = Field(default=None, ge=0)
    """σ per axis of the gyroscope bias's warm-up drift (rad/s; unset: none)."""
    acc_bias_warmup_tau_s: float | None = Field(default=None, gt=0)
    gyro_bias_warmup_tau_s: float | None = Field(default=None, gt=0)
    acc_range_mps2: float | None = Field(default=None, gt=0)
    """Accelerometer full scale per axis, m/s^2 (unset: unlimited); beyond it the reading clips."""
    gyro_range_radps: float | None = Field(default=None, gt=0)
    """Gyroscope full scale per axis, rad/s (unset: unlimited); beyond it the reading clips."""

    def resolve(self) -> ImuErrorModel:
        """The preset's values with this section's explicit fields on top."""
        values: dict[str, object] = dict(PRESETS[self.preset])
        for name in self.model_fields_set - {"preset"}:
            if getattr(self, name) is not None:
                values[name] = getattr(self, name)

        def triad(prefix: str, unit: str) -> SensorErrors:
            def get(field: str, default: object) -> object:
                return values.get(f"{prefix}_{field}", default)

            scale = get("scale_ppm", 0.0)
            scale3 = (float(scale),) * 3 if isinstance(scale, (int, float)) else tuple(float(v) for v in scale)
            return SensorErrors(
                noise_density=float(get("noise_density", 0.0)),
                bias_instability=float(get(f"bias_instability_{unit}", 0.0)),
                bias_tau_s=float(get("bias_tau_s", 100.0)),
                bias_random_walk=float(get("bias_random_walk", 0.0)),
                bias=tuple(float(v) for v in get(f"bias_{unit}", (0.0, 0.0, 0.0))),
                bias_sd=float(get(f"bias_sd_{unit}", 0.0)),
                scale_ppm=scale3,
                misalignment_mrad=tuple(float(v) for v in get("misalignment_mrad", (0.0,) * 6)),
                warmup_sd=float(get(f"bias_warmup_{unit}", 0.0)),
                warmup_tau_s=float(get("bias_warmup_tau_s", 300.0)),
                range=float(get(f"range_{unit}", math.inf)),
            )

        return ImuErrorModel(acc=triad("acc", "mps2"), gyro=triad("gyro", "radps"))


ERROR_TERMS = ("bias", "gauss_markov", "random_walk", "white", "warmup")
"""One random stream per (sensor, term), spawned in this fixed order (append new terms at
the end so the existing streams keep their bits)."""


def error_generators(seed: int, system: str) -> dict[str, np.random.Generator]:
    """Independent generators ``"acc.white"``, ``"gyro.bias"``, ... of one system.

    All come from ``SeedSequence([seed, stable_hash(system)])``: spawned once per sensor
    (acc, gyro), then once per term of :data:`ERROR_TERMS`.
    """
    out: dict[str, np.random.Generator] = {}
    sensors = system_seed(seed, system).spawn(2)
    for sensor, ss in zip(("acc", "gyro"), sensors):
        for term, child in zip(ERROR_TERMS, ss.spawn(len(ERROR_TERMS))):
            out[f"{sensor}.{term}"] = np.random.Generator(np.random.PCG64(child))
    return out


def gauss_markov(n: int, dt: float, sigma: float, tau: float, rng: np.random.Generator) -> np.ndarray:
    """(n, 3) first-order Gauss–Markov samples, stationary from the first sample."""
    z = rng.standard_normal((n, 3))
    if sigma == 0.0 or n == 0:
        return np.zeros((n, 3))
    phi = math.exp(-dt / tau)
    c = sigma * math.sqrt(-math.expm1(-2.0 * dt / tau))
    z[0] *= sigma / c  # so that b_0 = σ z_0 (stationary start)
    return lfilter([c], [1.0, -phi], z, axis=0)


def corrupt(ideal: np.ndarray, rate_hz: float, errors: SensorErrors,
            rngs: dict[str, np.random.Generator], sensor: Literal["acc", "gyro"]) -> np.ndarray:
    """Apply ``errors`` to ideal (N, 3) readings sampled at ``rate_hz``; see the module docstring."""
    ideal = np.asarray(ideal, dtype=float)
    n = ideal.shape[0]
    dt = 1.0 / rate_hz
    r = {term: rngs[f"{sensor}.{term}"] for term in ERROR_TERMS}

    m = np.eye(3)
    m[np.diag_indices(3)] += 1e-6 * np.asarray(errors.scale_ppm)
    off = [(0, 1), (0, 2), (1, 0), (1, 2), (2, 0), (2, 1)]
    for (i, j), v in zip(off, errors.misalignment_mrad):
        m[i, j] += 1e-3 * v
    out = ideal @ m.T if not np.array_equal(m, np.eye(3)) else ideal.copy()

    bias = np.asarray(errors.bias, dtype=float) + errors.bias_sd * r["bias"].standard_normal(3)
    out += bias
    # each random term drawn and added NOISE_BLOCK samples at a time: the same numbers as whole
    if errors.bias_instability > 0:
        sigma, tau = errors.bias_instability, errors.bias_tau_s
        phi = math.exp(-dt / tau)
        c = sigma * math.sqrt(-math.expm1(-2.0 * dt / tau))
        state = np.zeros((1, 3))
        for lo, z in _normal_blocks(r["gauss_markov"], n):
            if lo == 0:
                z[0] *= sigma / c  # so that b_0 = σ z_0 (stationary start), as gauss_markov
            y, state = lfilter([c], [1.0, -phi], z, axis=0, zi=state)
            out[lo:lo + len(z)] += y
    if errors.bias_random_walk > 0:
        last = np.zeros(3)
        for lo, z in _normal_blocks(r["random_walk"], n):
            steps = errors.bias_random_walk * math.sqrt(dt) * z
            if lo == 0:
                steps[0] = 0.0
            steps[0] += last
            np.cumsum(steps, axis=0, out=steps)
            out[lo:lo + len(z)] += steps
            last = steps[-1]
    if errors.noise_density > 0:
        for lo, z in _normal_blocks(r["white"], n):
            out[lo:lo + len(z)] += errors.noise_density * math.sqrt(rate_hz) * z
    if errors.warmup_sd > 0:
        settled = errors.warmup_sd * r["warmup"].standard_normal(3)
        out += np.outer(-np.expm1(-np.arange(n) * dt / errors.warmup_tau_s), settled)
    if math.isfinite(errors.range):
        np.clip(out, -errors.range, errors.range, out=out)
    return out


NOISE_BLOCK = 1 << 16
"""Samples of each random error term drawn at a time (:func:`corrupt`)."""


def _normal_blocks(rng: np.random.Generator, n: int) -> Iterator[tuple[int, np.ndarray]]:
    """``rng.standard_normal((n, 3))`` as (first row, rows) blocks of :data:`NOISE_BLOCK`
    rows: the same numbers (a generator's draws follow each other however they are asked for)."""
    for lo in range(0, n, NOISE_BLOCK):
        yield lo, rng.standard_normal((min(NOISE_BLOCK, n - lo), 3))


def measured_imu(motion: Motion, t: np.ndarray, rate_hz: float, gravity_mps2: float, imu: ImuErrorConfig,
                 seed: int, name: str) -> tuple[np.ndarray, np.ndarray]:
    """What the IMU of system ``name`` riding ``motion`` reports at times ``t`` (s): the
    ideal specific force (m/s^2) and angular rate (rad/s) corrupted by its error model
    from its own random streams (:func:`error_generators`)."""
    acc, gyro = ideal_imu(motion, t, gravity_mps2)
    errors = imu.resolve()
    rngs = error_generators(seed, name)
    acc = corrupt(acc, rate_hz, errors.acc, rngs, "acc")  # the measured replaces the ideal
    gyro = corrupt(gyro, rate_hz, errors.gyro, rngs, "gyro")
    return acc, gyro
