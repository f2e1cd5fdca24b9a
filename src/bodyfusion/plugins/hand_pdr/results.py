"""The hand PDR's results: its records as a track, states in the names every plugin shares
(:meth:`bodyfusion.core.system.SensorSystem.states`), covariances, steps, innovations, counts."""

from __future__ import annotations

import numpy as np

from bodyfusion.base.types import InputReport, Trajectory
from bodyfusion.core.heading import wrap_angle
from bodyfusion.core.system import CovarianceHistory
from bodyfusion.nav.filter_health import innovation_columns
from bodyfusion.plugins.hand_pdr.model import E, N

ERROR_STATES = ("east_m", "north_m", "up_m", "heading_rad", "step_length_m", "gyro_bias_radps", "gnss_bias_east",
                "gnss_bias_north", "step_scale", "holding_offset_rad")
"""Names of the error states δE, δN, δU (m), δψ (rad), δS (m), δb (rad/s), δβE, δβN (units of a
fix's correlated σ), δc and δo (rad), in :meth:`~bodyfusion.plugins.hand_pdr.system.HandPdr.covariance_history`."""
STORED = ("the whole error-state covariance at each step, GNSS and magnetometer update and correction (a "
          "mixture's moments while the heading bank is open)")
"""What the hand PDR's covariance history holds."""


def hand_states(h: np.ndarray) -> dict[str, np.ndarray]:
    """Columns of the records h (K, 1 + n): time (s), position (ENU, m), ``heading_deg`` (walking
    azimuth, clockwise from North), ``gyro_bias_radps``, ``gnss_bias_east`` and ``gnss_bias_north``
    (units of a fix's correlated σ), ``step_scale`` and, with the magnetometer (n = 9),
    ``holding_offset_deg`` (in [−180, 180))."""
    out = {"t": h[:, 0], "east_m": h[:, 1], "north_m": h[:, 2], "up_m": h[:, 3],
           "heading_deg": np.mod(np.degrees(h[:, 4]), 360.0), "gyro_bias_radps": h[:, 5],
           "gnss_bias_east": h[:, 6], "gnss_bias_north": h[:, 7], "step_scale": h[:, 8]}
    if h.shape[1] > 9:
        out["holding_offset_deg"] = np.degrees(np.mod(h[:, 9] + np.pi, 2.0 * np.pi) - np.pi)
    return out


class PdrResults:
    """What :class:`~bodyfusion.plugins.hand_pdr.system.HandPdr` gives once run: its records (one
    at each step, GNSS and magnetometer update and correction) as a track, states and covariances,
    its steps, innovations and counts."""

    def _history(self) -> tuple[np.ndarray, np.ndarray]:
        """The records (t, nominal state) (K, 1 + n) and covariances (K, n_err, n_err); of several
        records at one time (an update right after a step), the last."""
        h = self._hist_x.view()
        last = np.concatenate([h[1:, 0] > h[:-1, 0], [True]])
        return h[last], self._hist_P.view()[last]

    def trajectory(self) -> Trajectory:
        h, P = self._history()
        var = np.diagonal(P, axis1=1, axis2=2)[:, :3]
        return Trajectory(h[:, 0], h[:, 1:4], np.sqrt(np.maximum(var, 0.0)), P[:, E, N])

    def states(self) -> dict[str, np.ndarray]:
        """At every record (each step, GNSS or magnetometer update, the fuser's corrections; the
        mixture's mean while the heading bank is open): :func:`~bodyfusion.plugins.hand_pdr.results.hand_states`."""
        return hand_states(self._history()[0])

    def covariance_history(self) -> CovarianceHistory:
        """The whole error-state covariance (:data:`ERROR_STATES`) at every record."""
        h, P = self._history()
        return CovarianceHistory(h[:, 0], ERROR_STATES[:self.n_err], P.copy(), STORED)

    def events(self) -> dict[str, np.ndarray]:
        """The detected steps: their time (s) and modelled length (m, before the step scale)."""
        t = self.t[self.step_index]
        return {"event": np.full(t.size, "step"), "t": t, "t_end": t, "length_m": self.step_length_m}

    def innovations(self) -> dict[str, np.ndarray]:
        """GNSS position (3 dof), GNSS course and magnetometer (1 dof) updates, recorded while the
        heading bank is one filter (see :meth:`health`)."""
        return innovation_columns({kind: rec.columns() for kind, rec in self.nis_records.items()})

    @property
    def samples(self) -> int:
        return len(self.t)

    @property
    def input_report(self) -> InputReport:
        return self._report

    def diagnostics(self) -> dict:
        """Counts for metrics.json. ``start_fix_s``: the fix the position started from.
        ``gnss``: fixes accepted, rejected by the gate, masked by an outage, held (a repeat of
        the previous position), too fast, before the start fix; position resets after
        rejections in a row; course updates accepted, rejected, skipped while standing, while
        the phone was handled, for the fix's accuracy. ``heading``: ``given`` or ``gnss_track``
        with the bank's size, the hypotheses alive at the end, the times it resolved
        (``resolutions_s``; ``resolved_s`` the last, None if open at the end), how often
        handling the phone re-opened it, and the fixes that weighed the hypotheses or did
        not (the phone standing or handled). ``magnetometer``: its counts and offset (deg)."""
        x = self.x
        heading: dict = {"initial": "given" if self.config.initial.heading_deg != "gnss_track" else "gnss_track"}
        if heading["initial"] == "gnss_track":
            heading.update(hypotheses=self.config.initial.heading_hypotheses, alive=len(self._bank),
                           resolved_s=self.heading_resolved_s, resolutions_s=list(self.heading_resolutions),
                           **self.heading_counts)
        return {"steps": len(self.step_index),
                "mean_step_length_m": float(x[7] * self.step_length_m.mean()) if len(self.step_length_m) else None,
                "step_scale": float(x[7]),
                "start_fix_s": self.start_fix_s,
                "gnss": dict(self.gnss_counts),
                "heading": heading,
                **({"magnetometer": {**self.mag_counts, "offset_deg": float(np.rad2deg(wrap_angle(x[8])))}}
                   if self._mag is not None else {})}

    def health(self) -> dict:
        """As :meth:`SensorSystem.health`, plus ``nis``: ``gnss_position`` (3 dof: east, north, up),
        ``gnss_course`` (1 dof) and, with the magnetometer, ``magnetometer`` (1 dof), each counted
        before the gate while the heading bank is one filter (an open bank's moments are a
        mixture's, not a Gaussian's); the update that follows a position reset is not counted."""
        return {**super().health(), "nis": {kind: rec.tally().to_dict() for kind, rec in self.nis_records.items()}}
