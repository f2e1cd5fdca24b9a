"""Magnetic heading of a hand-held phone: tilt-compensated azimuth and the Earth-field check.

Frames: the phone (body) frame b as its sensors report it; the ENU navigation frame n.
Azimuths in radians, clockwise from North; magnetic field in µT.

Levelling. ``u_b`` is the unit Up vector in the phone frame (the low-passed specific force,
:func:`bodyfusion.plugins.hand_pdr.pdr.up_in_body`). The field's horizontal part
``h_b = m_b − (m_b·u_b) u_b`` points to magnetic North: ``n_b = h_b / ‖h_b‖`` and
``e_b = n_b × u_b`` (North × Up = East) are, with ``u_b``, the rows of C_nb in the magnetic
ENU frame. The azimuth of a phone axis ``a_b`` is then ``atan2(a_b·e_b, a_b·n_b)`` from
magnetic North; adding the declination (East positive) refers it to true North.

Dip: ``asin(−m_b·u_b / ‖m_b‖)``, positive when the field points below the horizontal.

Quasi-static check (site-independent). In a field that is fixed in the world the device
azimuth ψ_d and the gyro's azimuth ψ_g (:func:`bodyfusion.plugins.hand_pdr.pdr.azimuth_increments`)
turn together, so ψ_d − ψ_g is constant up to the gyro's slow drift. Where steel bends the
field as the phone moves past it, or where the levelling fails (a phone swinging in the
hand, carried in a pocket), ψ_d turns on its own: a sample is kept only if the standard
deviation of unwrap(ψ_d − ψ_g) over the preceding ``window_s`` (every raw sample, so the
magnetometer's own noise counts too) is at most ``tolerance_deg``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bodyfusion.io.imu import ImuCsvConfig
from bodyfusion.base.errors import InputError
from bodyfusion.io.tables import read_source
from bodyfusion.io.timestamps import apply_timestamp_policy
from bodyfusion.plugins.hand_pdr.config import FieldCheckConfig, MagnetometerConfig, QuasiStaticConfig

MAG_UNITS: dict[str, float] = {"uT": 1.0, "nT": 1e-3, "G": 100.0}
"""Magnetometer unit → µT."""


def device_azimuth(m_b: np.ndarray, up_b: np.ndarray, axis_b: np.ndarray) -> np.ndarray:
    """(N,) azimuth (rad, clockwise from magnetic North) of the phone axis ``axis_b`` (3,),
    from the field ``m_b`` (N, 3) and the Up direction ``up_b`` (N, 3, unit), both in the
    phone frame: the tilt-compensated compass heading of that axis."""
    h_b = m_b - np.einsum("ij,ij->i", m_b, up_b)[:, None] * up_b
    n_b = h_b / np.linalg.norm(h_b, axis=1, keepdims=True)
    e_b = np.cross(n_b, up_b)
    return np.arctan2(e_b @ axis_b, n_b @ axis_b)


def field_magnitude_dip(m_b: np.ndarray, up_b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(N,) field magnitude ‖m_b‖ (units of ``m_b``) and dip (rad, positive below the horizontal)."""
    norm = np.linalg.norm(m_b, axis=1)
    return norm, np.arcsin(np.clip(-np.einsum("ij,ij->i", m_b, up_b) / norm, -1.0, 1.0))


def earth_like(m_uT: np.ndarray, up_b: np.ndarray, check: FieldCheckConfig | None) -> np.ndarray:
    """(N,) True where the sample (µT, phone frame) passes the field check (all, without one)."""
    if check is None:
        return np.ones(len(m_uT), dtype=bool)
    norm, dip = field_magnitude_dip(m_uT, up_b)
    ok = np.abs(norm - check.expected_uT) <= check.tolerance_uT
    if check.inclination_deg is not None:
        ok &= np.abs(np.rad2deg(dip) - check.inclination_deg) <= check.inclination_tolerance_deg
    return ok


def quasi_static(t_m: np.ndarray, psi_d: np.ndarray, psi_g: np.ndarray, keep: np.ndarray,
                 check: QuasiStaticConfig | None) -> np.ndarray:
    """(K,) True for the samples ``keep`` (indices into ``t_m``, s) where ψ_d − ψ_g (rad, both
    at ``t_m``) has a standard deviation of at most ``check.tolerance_deg`` over the
    ``check.window_s`` before them (a window the data does not cover fails); all True
    without a check."""
    if check is None:
        return np.ones(len(keep), dtype=bool)
    finite = np.isfinite(psi_d)
    diff = np.full(len(t_m), np.nan)
    diff[finite] = np.unwrap(psi_d[finite] - psi_g[finite])
    start = np.searchsorted(t_m, t_m[keep] - check.window_s)
    ok = np.zeros(len(keep), dtype=bool)
    for k, (i0, i1) in enumerate(zip(start, keep)):
        span = diff[i0:i1 + 1]
        ok[k] = (t_m[i1] - t_m[0] >= check.window_s and np.all(np.isfinite(span))
                 and np.std(span) <= np.deg2rad(check.tolerance_deg))
    return ok


def decimate(t: np.ndarray, rate_hz: float) -> np.ndarray:
    """Indices of the first sample in each 1/``rate_hz`` interval from ``t[0]`` (s)."""
    _, first = np.unique(np.floor((t - t[0]) * rate_hz), return_index=True)
    return first


@dataclass
class MagneticHeading:
    """Decimated magnetometer updates: times t (s), device azimuths ψ_d (rad, clockwise
    from true North, declination applied), whether each passed the field check (a sample
    without a horizontal field component never does) and the quasi-static check."""

    t: np.ndarray
    psi_d: np.ndarray
    earth_like: np.ndarray
    quasi_static: np.ndarray

    @classmethod
    def of(cls, t_m: np.ndarray, m_uT: np.ndarray, t_imu: np.ndarray, up_b: np.ndarray, azimuth: np.ndarray,
           cfg: MagnetometerConfig) -> "MagneticHeading":
        """From samples ``m_uT`` (N, 3, µT, phone frame) at ``t_m`` (s), the Up direction ``up_b``
        and the gyro's azimuth ``azimuth`` (rad) at the IMU's times ``t_imu``; samples outside the
        IMU's span are dropped."""
        inside = (t_m >= t_imu[0]) & (t_m <= t_imu[-1])
        t_m, m_uT = t_m[inside], m_uT[inside]
        if t_m.size == 0:
            return cls(np.empty(0), np.empty(0), np.empty(0, dtype=bool), np.empty(0, dtype=bool))
        u = np.column_stack([np.interp(t_m, t_imu, up_b[:, i]) for i in range(3)])
        u /= np.linalg.norm(u, axis=1, keepdims=True)
        axis = np.asarray(cfg.axis_b, dtype=float)
        with np.errstate(invalid="ignore"):  # a field along Up has no azimuth: NaN, refused below
            psi = device_azimuth(m_uT, u, axis / np.linalg.norm(axis)) + np.deg2rad(cfg.declination_deg)
        keep = decimate(t_m, cfg.rate_hz)
        still = quasi_static(t_m, psi, np.interp(t_m, t_imu, azimuth), keep, cfg.quasi_static)
        return cls(t_m[keep], psi[keep], earth_like(m_uT[keep], u[keep], cfg.field_check) & np.isfinite(psi[keep]),
                   still)


def read_magnetometer_csv(d: ImuCsvConfig, columns: tuple[str, str, str], unit: str) -> tuple[np.ndarray, np.ndarray]:
    """Times (s) and field (N, 3, µT) from the magnetometer ``columns`` of the IMU CSV ``d`` (or of
    its in-memory table); rows with empty cells are skipped, the IMU's timestamp policy applies."""
    names = list(columns) + ([d.time_column] if d.time_column is not None and d.time_column not in columns else [])
    arrays, lines, where = read_source(d, names, skip_rows=d.skip_rows, delimiter=d.delimiter, allow_missing=columns)
    n = len(arrays[names[0]])
    t = arrays[d.time_column] * d.time_scale if d.time_column is not None else np.arange(n) / d.rate_hz
    m = np.column_stack([arrays[c] for c in columns]) * MAG_UNITS[unit]
    present = np.all(np.isfinite(m), axis=1)
    t, m = t[present], m[present]
    kept, _, t_kept = apply_timestamp_policy(t, d.timestamp_policy, where, lines=None if lines is None else lines[present])
    if kept.size < 2:
        raise InputError(where, f"fewer than 2 magnetometer samples in columns {', '.join(columns)}")
    return t_kept, m[kept]
