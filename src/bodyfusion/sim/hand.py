"""A phone held in the hand of the walking pedestrian (``kind: hand_phone``).

Body. The body point moves along the body path (:mod:`bodyfusion.sim.paths`) by arc length
``s(t)``, kept midway between the feet: at the k-th heel strike it is (k − ½) step
lengths along, halfway between the footprints, so its linear progress at ``v_c`` = step
length / ``T`` (the gait's speed, ``T`` one step) starts half a step before the first
heel strike and ends half a step before the last; a smooth speed-up and slow-down of
one gait cycle ``2T`` are centred on those instants (speed ``v_c · r(τ)``,
``r = 10τ³ − 15τ⁴ + 6τ⁵``). Its heading is the path azimuth at ``s(t)``
(rate κ(s)·ṡ, κ the path curvature, positive turning right). The body *frame* (the
hand's offset and the phone's yaw) turns with that azimuth smoothed over
``heading_smoothing_m`` of arc length, so its turn rate is continuous at the joints of
lines and arcs (a rate jump would make the offset phone's velocity jump).

Step rhythm. With ``T`` = one step (half a gait cycle) and ``t_h0`` the first heel
strike, the phase is ``φ = 2π (t − t_h0) / T``; the heel strikes are the swing ends of
both feet (each within half a sample of φ ≡ 0). The body bounces vertically,
``−bounce_m · e(t) · cos φ`` (lowest, i.e. the vertical acceleration at its peak
``bounce_m (2π/T)²``, at each heel strike: one clear peak of ‖f‖ − g per step), and
sways laterally towards the stance foot, ``±lateral_sway_m · e(t) · sin(φ/2)``. The
envelope ``e`` rises smoothly (C²) from 0 at ``t_h0 − T/2`` to 1 at ``t_h0`` and falls
from 1 at the last heel strike to 0 half a step later (over a longer ramp the bounce's
half-grown crest a step before the first heel strike would read as an extra step).

Hand. The phone sits ``offset_m`` = (forward, left, up) from the body point in the
body's heading frame, plus hand sway: on each of forward, left, up (``position_sd_m``)
and roll, pitch (``attitude_sd_deg``), yaw (``yaw_sd_deg``), a sum of ``components``
sinusoids with seeded random frequencies in [``min_hz``, ``max_hz``] and phases (RMS
the given σ), times the envelope ``e`` — smooth, analytic, still while the pedestrian
stands still. Attitude ``q_nb = q_z(π/2 − az − mount_yaw − yaw_w) ⊗ q_y(pitch_w) ⊗
q_x(roll_w)``: screen up (body z up), x along the walking direction turned clockwise
by ``mount_yaw_deg``, y to the left.

Its IMU comes from :func:`bodyfusion.sim.imu.ideal_imu` (same increment convention as the
feet) and :func:`bodyfusion.sim.imu.corrupt` (default preset ``phone``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from pydantic import Field

from bodyfusion.base.sections import StrictModel
from bodyfusion.base.seeding import system_seed
from bodyfusion.sim.gait import GaitPlan
from bodyfusion.sim.imu import MotionState, blockwise, quat_about_axis, quat_multiply
from bodyfusion.sim.paths import Arc, BodyPath, direction, left_normal

__all__ = ["HandMotion", "HandSwayConfig", "hand_motion", "heel_strikes"]

Deriv = tuple[np.ndarray, np.ndarray, np.ndarray]
"""A function of time with its first and second derivatives."""


class HandSwayConfig(StrictModel):
    """Smooth random wobble of the hand (see the module docstring)."""

    position_sd_m: float = Field(default=0.01, ge=0)
    attitude_sd_deg: float = Field(default=2.0, ge=0)
    yaw_sd_deg: float = Field(default=2.0, ge=0)
    min_hz: float = Field(default=0.2, gt=0)
    max_hz: float = Field(default=1.2, gt=0)
    components: int = Field(default=4, ge=1, le=32)


# --------------------------------------------------------------------------- smooth helpers


def _smoothstep(t: np.ndarray, a: float, b: float) -> Deriv:
    """C² ramp 0 → 1 on [a, b] (10τ³ − 15τ⁴ + 6τ⁵) and its time derivatives."""
    d = b - a
    tau = np.clip((t - a) / d, 0.0, 1.0)
    inside = (t > a) & (t < b)
    v = tau**3 * (10 - 15 * tau + 6 * tau**2)
    d1 = np.where(inside, 30 * tau**2 * (1 - tau) ** 2 / d, 0.0)
    d2 = np.where(inside, 60 * tau * (1 - tau) * (1 - 2 * tau) / d**2, 0.0)
    return v, d1, d2


def _product(f: Deriv, g: Deriv) -> Deriv:
    return f[0] * g[0], f[1] * g[0] + f[0] * g[1], f[2] * g[0] + 2 * f[1] * g[1] + f[0] * g[2]


def _add(*fs: Deriv) -> Deriv:
    return tuple(sum(f[k] for f in fs) for k in range(3))  # type: ignore[return-value]


def _scale(f: Deriv, c: float) -> Deriv:
    return f[0] * c, f[1] * c, f[2] * c


def _const(t: np.ndarray, c: float) -> Deriv:
    return np.full(t.shape, float(c)), np.zeros(t.shape), np.zeros(t.shape)


def _sinusoid(t: np.ndarray, amp: float, omega: float, phase: float) -> Deriv:
    s, c = np.sin(omega * t + phase), np.cos(omega * t + phase)
    return amp * s, amp * omega * c, -amp * omega**2 * s


@dataclass(frozen=True)
class _Wobble:
    """Sum of sinusoids: amplitudes (K,), angular frequencies (K,), phases (K,)."""

    amp: np.ndarray
    omega: np.ndarray
    phase: np.ndarray

    @classmethod
    def draw(cls, rng: np.random.Generator, sd: float, cfg: HandSwayConfig) -> "_Wobble":
        k = cfg.components
        lo, hi = sorted((cfg.min_hz, cfg.max_hz))
        freq = rng.uniform(lo, hi, k)
        phase = rng.uniform(0.0, 2 * math.pi, k)
        return cls(np.full(k, sd * math.sqrt(2.0 / k)), 2 * math.pi * freq, phase)

    def __call__(self, t: np.ndarray) -> Deriv:
        return _add(*(_sinusoid(t, a, w, p) for a, w, p in zip(self.amp, self.omega, self.phase)))


# --------------------------------------------------------------------------- body progression


def _curvature(path: BodyPath, s: np.ndarray) -> np.ndarray:
    """Signed curvature dψ/ds (1/m, positive turning right) at arc lengths ``s``."""
    idx = np.clip(np.searchsorted(path.s_start, s, side="right") - 1, 0, len(path.segments) - 1)
    per_segment = np.array([math.copysign(1.0 / seg.radius, seg.turn) if isinstance(seg, Arc) else 0.0
                            for seg in path.segments])
    return per_segment[idx]


@dataclass(frozen=True)
class _SmoothHeading:
    """The path azimuth smoothed over ``width`` metres of arc length.

    The path azimuth is piecewise linear in s (lines, arcs): ψ(s) = ψ₀ + Σ c_j max(s − s_j, 0)
    with c_j the curvature change at segment boundary s_j. Convolving with the biweight
    kernel K(u) = (15/16)(1 − x²)²/h, x = u/h, h = width/2, turns each kink into a C² ramp
    whose second derivative is c_j K: the heading rate of the body frame is continuous (a
    point offset from the body moves without velocity jumps) and its derivative bounded.

    Each point's kinks that lie h or more behind it count as the unsmoothed azimuth there
    (``psi``, ``rate``: the azimuth and curvature after each kink), those h or more ahead of it
    not at all; only the few within reach are smoothed, so a walk of K kinks costs O(N + K),
    not O(N K), and every point's value is its own (the same however the points are batched).
    """

    az0: float
    knots: np.ndarray
    jumps: np.ndarray
    half: float
    psi: np.ndarray
    rate: np.ndarray

    @classmethod
    def of(cls, path: BodyPath, width: float) -> "_SmoothHeading":
        kappa = _curvature(path, path.s_start + 1e-12)
        jumps = np.diff(np.concatenate([[0.0], kappa]))
        keep = jumps != 0
        knots, jumps = path.s_start[keep], jumps[keep]
        rate = np.cumsum(jumps)
        psi = path.start[1] + np.concatenate([[0.0], np.cumsum(rate[:-1] * np.diff(knots))])
        return cls(path.start[1], knots, jumps, 0.5 * width, psi, rate)

    def __call__(self, s: np.ndarray) -> Deriv:
        """ψ_h(s), dψ_h/ds, d²ψ_h/ds²."""
        h, knots = self.half, self.knots
        if knots.size == 0:
            return np.full(s.shape, self.az0), np.zeros(s.shape), np.zeros(s.shape)
        behind = np.searchsorted(knots, s - h, side="right")  # kinks 0 .. behind−1 lie h or more behind
        ahead = np.searchsorted(knots, s + h, side="left")    # kinks from ahead on lie h or more ahead
        last = np.maximum(behind - 1, 0)
        v = np.where(behind > 0, self.psi[last] + self.rate[last] * (s - knots[last]), self.az0)
        d1 = np.where(behind > 0, self.rate[last], 0.0)
        d2 = np.zeros(s.shape)
        for r in range(int(np.max(ahead - behind, initial=0))):
            j = np.minimum(behind + r, knots.size - 1)
            sj, c = knots[j], np.where(behind + r < ahead, self.jumps[j], 0.0)
            x = np.clip((s - sj) / h, -1.0, 1.0)
            v += c * h * (15 / 16 * (x**2 / 2 - x**4 / 6 + x**6 / 30) + x / 2 + 5 / 32)
            d1 += c * (15 / 16 * (x - 2 * x**3 / 3 + x**5 / 5) + 0.5)
            d2 += c * 15 / 16 * (1 - x**2) ** 2 / h
        return v, d1, d2


@dataclass(frozen=True)
class _Progress:
    """Arc length s(t) along the path: still, speed-up over ``ramp`` s, constant, slow-down."""

    t0: float
    t1: float
    ramp: float
    length: float

    @property
    def speed(self) -> float:
        return self.length / (self.t1 - self.t0 - self.ramp)

    def __call__(self, t: np.ndarray) -> Deriv:
        v, r = self.speed, self.ramp

        def integral(x: np.ndarray) -> np.ndarray:  # ∫₀^x of the speed-up ramp, x in s since start
            tau = np.clip(x / r, 0.0, 1.0)
            return r * tau**4 * (2.5 - 3 * tau + tau**2) + np.maximum(x - r, 0.0)

        up = _smoothstep(t, self.t0, self.t0 + r)
        down = _smoothstep(t, self.t1 - r, self.t1)
        s = v * (integral(t - self.t0) - integral(t - (self.t1 - r)))
        sd = v * (up[0] - down[0])
        sdd = v * (up[1] - down[1])
        return np.clip(s, 0.0, self.length), sd, sdd


def heel_strikes(plan: GaitPlan) -> np.ndarray:
    """Sample indices of every heel strike (swing end) of either foot, sorted."""
    return np.sort(np.concatenate([m.k_end for m in plan.feet.values()]))


# --------------------------------------------------------------------------- the phone


@dataclass
class HandMotion:
    """The phone's analytic motion (see the module docstring); ``evaluate(t)`` for the IMU."""

    path: BodyPath
    progress: _Progress
    heading: _SmoothHeading
    step_s: float
    t_first: float
    t_last: float
    offset_m: tuple[float, float, float]
    bounce_m: float
    lateral_sway_m: float
    lateral_sign: float
    mount_yaw_rad: float
    wobble: dict[str, _Wobble]

    def envelope(self, t: np.ndarray) -> Deriv:
        T = 0.5 * self.step_s  # half a step: a slower ramp would show as an extra ‖f‖ peak a step early
        up = _smoothstep(t, self.t_first - T, self.t_first)
        down = _smoothstep(t, self.t_last, self.t_last + T)
        return _add(up, _scale(down, -1.0))

    def evaluate(self, t: np.ndarray) -> MotionState:
        """The motion at times ``t`` (s), computed a block of instants at a time (:func:`~bodyfusion.sim.imu.blockwise`)."""
        return blockwise(self._evaluate, t)

    def _evaluate(self, t: np.ndarray) -> MotionState:
        env = self.envelope(t)
        s, sd, sdd = self.progress(t)
        xy, az_path = self.path.at(s)
        kappa = _curvature(self.path, s)
        az, dh, ddh = self.heading(s)  # the body frame's (smoothed) heading
        w, wd = dh * sd, ddh * sd**2 + dh * sdd  # its rate and the rate's derivative
        f, lv = direction(az), left_normal(az)
        fp, lp = direction(az_path), left_normal(az_path)

        omega_step = 2 * math.pi / self.step_s
        bounce = _product(env, _sinusoid(t, -self.bounce_m, omega_step, -omega_step * self.t_first + math.pi / 2))
        sway = _product(env, _sinusoid(t, self.lateral_sign * self.lateral_sway_m, 0.5 * omega_step,
                                       -0.5 * omega_step * self.t_first))
        wob = {k: _product(env, fn(t)) for k, fn in self.wobble.items()}
        a = _add(_const(t, self.offset_m[0]), wob["forward"])
        b = _add(_const(t, self.offset_m[1]), sway, wob["left"])
        z = _add(_const(t, self.offset_m[2]), bounce, wob["up"])

        # Horizontal: P(s) + a f + b l, with f, l the body frame's forward and left
        # (df/dt = −ω l, dl/dt = ω f); the path point moves along the path's own tangent fp.
        fa = a[1] + w * b[0]
        la = b[1] - w * a[0]
        facc = a[2] + wd * b[0] + 2 * w * b[1] - w**2 * a[0]
        lacc = b[2] - wd * a[0] - 2 * w * a[1] - w**2 * b[0]
        path_acc = sdd[:, None] * fp - (kappa * sd**2)[:, None] * lp
        pos = np.column_stack([xy + a[0][:, None] * f + b[0][:, None] * lv, z[0]])
        vel = np.column_stack([sd[:, None] * fp + fa[:, None] * f + la[:, None] * lv, z[1]])
        acc = np.column_stack([path_acc + facc[:, None] * f + lacc[:, None] * lv, z[2]])

        # Attitude: yaw (ENU, counter-clockwise from East), pitch about y, roll about x.
        yaw = 0.5 * math.pi - az - self.mount_yaw_rad - wob["yaw"][0]
        yaw_rate = -w - wob["yaw"][1]
        pitch, pitch_rate = wob["pitch"][0], wob["pitch"][1]
        roll, roll_rate = wob["roll"][0], wob["roll"][1]
        q = quat_multiply(quat_multiply(quat_about_axis(yaw, 3), quat_about_axis(pitch, 2)), quat_about_axis(roll, 1))
        cy, sy, cp, sp = np.cos(yaw), np.sin(yaw), np.cos(pitch), np.sin(pitch)
        omega = np.column_stack([
            -pitch_rate * sy + roll_rate * cy * cp,
            pitch_rate * cy + roll_rate * sy * cp,
            yaw_rate - roll_rate * sp,
        ])
        return MotionState(pos=pos, vel=vel, acc=acc, q_nb=q, omega_n=omega)


def hand_motion(plan: GaitPlan, cycle_samples: int, *, seed: int, name: str, offset_m: tuple[float, float, float],
                bounce_m: float, lateral_sway_m: float, mount_yaw_deg: float, sway: HandSwayConfig,
                heading_smoothing_m: float = 1.0) -> HandMotion:
    """The phone of system ``name`` carried through ``plan``; ``cycle_samples``: one gait
    cycle in samples (as :func:`bodyfusion.sim.gait.plan_gait` rounded it). The hand sway is
    drawn from its own stream, ``system_seed(seed, name + "#sway")``."""
    rate = plan.rate_hz
    hs = heel_strikes(plan)
    t_first, t_last = hs[0] / rate, hs[-1] / rate
    t1 = max(int(m.k_end[-1]) for m in plan.feet.values()) / rate
    cycle = cycle_samples / rate
    step = 0.5 * cycle
    # Centred between the feet: at the k-th heel strike (k = 1, 2, ...) the body is at
    # (k − ½)·step length, i.e. linear progress reaches 0 half a step before the first heel
    # strike and the end half a step before the last; speed-up and slow-down of one gait
    # cycle centred on those instants (peak surge ≈ 1.9 v/cycle ≈ 2 m/s² at a normal gait).
    ramp = min(cycle, 0.45 * (t1 - t_first))
    t0 = max(t_first - 0.5 * step - 0.5 * ramp, 0.0)
    t_end = t_last - 0.5 * step + 0.5 * ramp
    progress = _Progress(t0, t_end, ramp, plan.path.length)
    lead = "left" if plan.feet["left"].k_start[0] <= plan.feet["right"].k_start[0] else "right"
    # After the lead foot's heel strike the body moves over it (mid-stance a quarter cycle later).
    lateral_sign = 1.0 if lead == "left" else -1.0
    rng = np.random.Generator(np.random.PCG64(system_seed(seed, f"{name}#sway")))
    sds = {"forward": sway.position_sd_m, "left": sway.position_sd_m, "up": sway.position_sd_m,
           "roll": math.radians(sway.attitude_sd_deg), "pitch": math.radians(sway.attitude_sd_deg),
           "yaw": math.radians(sway.yaw_sd_deg)}
    wobble = {k: _Wobble.draw(rng, sd, sway) for k, sd in sds.items()}
    heading = _SmoothHeading.of(plan.path, heading_smoothing_m)
    return HandMotion(plan.path, progress, heading, 0.5 * cycle, t_first, t_last, tuple(float(v) for v in offset_m),
                      bounce_m, lateral_sway_m, lateral_sign, math.radians(mount_yaw_deg), wobble)
