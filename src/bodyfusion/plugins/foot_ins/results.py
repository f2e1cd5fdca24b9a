"""The foot INS's results in the names every plugin shares (:meth:`bodyfusion.core.system.SensorSystem.states`):
its nominal states, the covariance it stores, its stance phases and its updates' NIS."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from bodyfusion.core.system import CovarianceHistory
from bodyfusion.nav import detectors
from bodyfusion.plugins.foot_ins.kernels import pack_covariance
from bodyfusion.plugins.foot_ins.records import ATTITUDE_COVARIANCE, RECORDED_COVARIANCE, VELOCITY_VARIANCE

STORED = ("after each sample: the position variances east, north, up and the east-north covariance (m^2), "
          "the velocity variances (m^2/s^2) and the attitude error's covariance (rad^2); where smoothed, the "
          "position block alone")
"""What :func:`foot_covariance` holds: the filter's (or the smoother's) recorded covariance entries."""
COVARIANCE_STATES = ("east_m", "north_m", "up_m", "v_east_mps", "v_north_mps", "v_up_mps", "attitude_east_rad",
                     "attitude_north_rad", "attitude_up_rad")
"""The error states whose recorded covariance entries :func:`foot_covariance` gives: δp (ENU, m),
δv (ENU, m/s), δθ (navigation frame, rad)."""


def attitude_columns(q_nb: np.ndarray) -> dict[str, np.ndarray]:
    """``qw``..``qz`` of quaternions q_nb (N, 4) (body to ENU, scalar first) and their
    ``heading_deg`` (azimuth of the body x axis, clockwise from North, in [0, 360)), ``pitch_deg``
    and ``roll_deg`` (ZYX in ENU, the inverse of :func:`bodyfusion.nav.attitude.quat_from_azimuth_pitch_roll`)."""
    yaw, pitch, roll = Rotation.from_quat(q_nb, scalar_first=True).as_euler("ZYX").T
    return {"qw": q_nb[:, 0], "qx": q_nb[:, 1], "qy": q_nb[:, 2], "qz": q_nb[:, 3],
            "heading_deg": np.mod(90.0 - np.degrees(yaw), 360.0), "pitch_deg": np.degrees(pitch),
            "roll_deg": np.degrees(roll)}


def foot_states(t: np.ndarray, x: np.ndarray) -> dict[str, np.ndarray]:
    """Columns of nominal states x (N, 16) at times t (N,) s: position (ENU, m), velocity (m/s),
    attitude, accelerometer (m/s^2) and gyroscope (rad/s) biases on the body axes."""
    out = {"t": t, "east_m": x[:, 0], "north_m": x[:, 1], "up_m": x[:, 2],
           "v_east_mps": x[:, 3], "v_north_mps": x[:, 4], "v_up_mps": x[:, 5], **attitude_columns(x[:, 6:10])}
    for k, axis in enumerate("xyz"):
        out[f"acc_bias_{axis}_mps2"] = x[:, 10 + k]
    for k, axis in enumerate("xyz"):
        out[f"gyro_bias_{axis}_radps"] = x[:, 13 + k]
    return out


def foot_covariance(t: np.ndarray, recorded: np.ndarray) -> CovarianceHistory:
    """The recorded covariance entries (N, 13: :data:`~bodyfusion.plugins.foot_ins.records.RECORDED_COVARIANCE`;
    N, 4 where smoothed: the position block) as (N, 9, 9) over :data:`COVARIANCE_STATES`: the
    position variances and east–north covariance, the velocity variances, the attitude block;
    every other entry (position–velocity, the velocity covariances...) NaN: not stored."""

    def block(epochs: slice) -> np.ndarray:
        rec = recorded[epochs]
        matrix = np.full((len(rec), 9, 9), np.nan)
        k = np.arange(3)
        matrix[:, k, k] = rec[:, :3]
        matrix[:, 0, 1] = matrix[:, 1, 0] = rec[:, 3]
        if rec.shape[1] >= RECORDED_COVARIANCE:
            matrix[:, 3 + k, 3 + k] = rec[:, VELOCITY_VARIANCE]
            att = rec[:, ATTITUDE_COVARIANCE]  # EE, NN, UU, EN, EU, NU
            matrix[:, 6 + k, 6 + k] = att[:, :3]
            for (a, b), column in zip(((0, 1), (0, 2), (1, 2)), (3, 4, 5)):
                matrix[:, 6 + a, 6 + b] = matrix[:, 6 + b, 6 + a] = att[:, column]
        return matrix

    return CovarianceHistory(t, COVARIANCE_STATES, block, STORED)


def zupt_columns(t: np.ndarray, hist_nis: np.ndarray, gate: float) -> dict[str, np.ndarray]:
    """The stance updates among the samples' recorded NIS (``hist_nis``, negative where none):
    ``t`` (s), ``nis``, ``dof`` 3, ``accepted`` (within the chi-square ``gate``; 0: no gate)."""
    i = np.flatnonzero(hist_nis >= 0.0)
    nis = hist_nis[i]
    return {"t": t[i], "nis": nis, "dof": np.full(i.size, 3), "accepted": (gate <= 0.0) | (nis <= gate)}


def stance_phases(t: np.ndarray, stance: np.ndarray) -> dict[str, np.ndarray]:
    """The detector's stance phases: ``event`` ``stance``, ``t`` its first and ``t_end`` its last
    sample's time (s)."""
    starts, ends = detectors.stance_events(stance)
    return {"event": np.full(starts.size, "stance"), "t": t[starts], "t_end": t[ends - 1]}


class Rows:
    """Rows of one ``shape`` and ``dtype`` appended one at a time into blocks of ``block`` rows,
    each allocated when the last fills: no Python object per row, at most one block unused and
    no copy as it grows (:meth:`array` makes the one copy)."""

    def __init__(self, shape: tuple[int, ...] = (), dtype: type | np.dtype = np.float64, block: int = 1024) -> None:
        self._shape, self._dtype, self._block = shape, dtype, block
        self._blocks: list[np.ndarray] = []
        self._n = 0

    def _slot(self) -> int:
        """Index in the last block of a row appended uninitialised."""
        k = self._n % self._block
        if k == 0:
            self._blocks.append(np.empty((self._block, *self._shape), dtype=self._dtype))
        self._n += 1
        return k

    def append(self, row: object) -> None:
        k = self._slot()
        self._blocks[-1][k] = row

    def next_row(self) -> np.ndarray:
        """The next row, appended uninitialised, as a view to write (rows of a shape only)."""
        k = self._slot()
        return self._blocks[-1][k]

    def __len__(self) -> int:
        return self._n

    def array(self, first: int = 0) -> np.ndarray:
        """The rows so far from row ``first`` on, (n − first, *shape) (a copy of those alone)."""
        out = np.empty((max(self._n - first, 0), *self._shape), dtype=self._dtype)
        for k in range(first // self._block, len(self._blocks)):
            lo = k * self._block
            a, b = max(first, lo), min(lo + self._block, self._n)
            out[a - first:b - first] = self._blocks[k][a - lo:b - lo]
        return out


_UPPER = np.triu_indices(15)
_LOWER = np.tril_indices(15, -1)


class CovarianceLog:
    """The (15, 15) covariances a foot INS leaves at samples by corrections outside its compiled
    loop (fuser, position fix, gap policy), for the smoothers, kept compactly: a symmetric one
    (every one that went through the closed-loop reset, which symmetrises) as its upper
    triangle, 120 numbers instead of 225; any other's strict lower triangle beside it. The
    same numbers come back (:meth:`covariances`). ``block``: rows allocated at a time (:class:`Rows`)."""

    def __init__(self, block: int = 1024) -> None:
        self.idx = Rows((), np.int64, block)
        self.upper = Rows((_UPPER[0].size,), np.float64, block)
        self.lower_at = Rows((), np.int64, block)
        self.lower = Rows((_LOWER[0].size,), np.float64, block)

    def add(self, i: int, P: np.ndarray) -> None:
        """The covariance ``P`` (15, 15) left at sample ``i``."""
        if not pack_covariance(P, self.row(i)):  # NaN ≠ NaN: kept whole, as array_equal would
            self.keep_lower(P)

    def row(self, i: int) -> np.ndarray:
        """The row (:data:`~bodyfusion.plugins.foot_ins.kernels.PACKED_SIZE`,) to write the upper
        triangle (by rows) of the covariance left at sample ``i`` into; when that covariance is not
        exactly symmetric, :meth:`keep_lower` it next."""
        self.idx.append(i)
        return self.upper.next_row()

    def keep_lower(self, P: np.ndarray) -> None:
        """The strict lower triangle of the covariance ``P`` (15, 15) whose upper triangle was
        written last (:meth:`row`)."""
        self.lower_at.append(len(self.idx) - 1)
        self.lower.append(P[_LOWER])

    def __len__(self) -> int:
        return len(self.idx)

    def forgotten(self, d: int) -> CovarianceLog:
        """The log of the covariances left at samples ``d`` and later, each index less ``d`` (a live
        run forgetting its first ``d`` samples)."""
        out = CovarianceLog(self.idx._block)
        for i, P in zip(*self.covariances()):
            if i >= d:
                out.add(int(i) - d, P)
        return out

    def covariances(self, since: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """(n,) sample indices and (n, 15, 15) covariances, in the order they were added (their
        samples' order), of the samples ``since`` and later."""
        idx = self.idx.array()
        k0 = int(np.searchsorted(idx, since))
        P = np.empty((idx.size - k0, 15, 15))
        P[:, _UPPER[0], _UPPER[1]] = self.upper.array(k0)
        P[:, _LOWER[0], _LOWER[1]] = P[:, _LOWER[1], _LOWER[0]]
        lower_at = self.lower_at.array()
        m0 = int(np.searchsorted(lower_at, k0))  # in the order added
        P[lower_at[m0:][:, None] - k0, _LOWER[0], _LOWER[1]] = self.lower.array(m0)
        return idx[k0:], P
