"""The phone's GNSS as its filter takes it: position fixes, their course, the heading the track's shape
gives, and the consistency checks that keep the dead reckoning from straying from the fixes.

A mixin of :class:`~bodyfusion.plugins.hand_pdr.system.HandPdr` (the filter, its bank and its
model are the system's; the module docstring there states the measurement models):

* every usable fix is a gated position update with its correlated error β (its outliers
  refused by the chi-square gate; after ``reset_after_rejections`` refusals in a row the
  position is forgotten and taken from the fix);
* consistency: a filter that keeps the fixes only by holding a correlated error |β̂| beyond
  :data:`BIAS_LIMIT` of their σ (a bias the fixes do not have: the dead reckoning strayed —
  missed steps, a heading gone wrong) is re-anchored: β̂ ← 0, the position forgotten and the
  heading widened to :data:`REANCHOR_HEADING_SD_DEG`, so that the fixes set them again;
* heading from the course (Doppler) when the phone walks fast enough, held steadily, with an
  accurate fix; and from the track's shape (:mod:`bodyfusion.plugins.hand_pdr.track_heading`),
  which needs no speed and is not the fixes' jitter.
"""

from __future__ import annotations

import math

import numpy as np

from bodyfusion.core.heading import wrap_angle
from bodyfusion.plugins.hand_pdr.model import BE, BN, E, N, PSI, U

DIFFUSE_SD_M = 1e3
"""One-sigma (m) of a position not known yet: far above any fix error, well inside float64."""
BIAS_LIMIT = 3.03
"""Largest correlated GNSS error β̂ (in the fixes' σ, the 99 % chi-square bound of 2 degrees of
freedom) the filter may hold: beyond it the dead reckoning, not the fixes, has gone astray."""
REANCHOR_HEADING_SD_DEG = 30.0
"""Heading σ (degrees) after a re-anchoring: the fixes that follow set it again."""


class GnssAiding:
    """The GNSS updates of the hand PDR (module docstring)."""

    def _reanchor(self) -> None:
        """The PDR disagrees with the fixes beyond what their correlated error allows
        (|β̂| > :data:`BIAS_LIMIT`): β̂ ← 0 with its prior variance, the position forgotten
        (:meth:`_forget_position`) and the heading σ widened to :data:`REANCHOR_HEADING_SD_DEG`,
        so that the fixes set them again."""
        (h,) = self._bank.hypotheses
        h.x[5:7] = 0.0
        for i in (BE, BN):
            h.P[i, :] = h.P[:, i] = 0.0
            h.P[i, i] = 1.0
        h.P[PSI, PSI] = max(h.P[PSI, PSI], np.deg2rad(REANCHOR_HEADING_SD_DEG) ** 2)
        self._track.clear()
        self._forget_position()

    def _forget_position(self) -> None:
        """δp ← fresh with σ :data:`DIFFUSE_SD_M` (rows of δp in the transition zeroed)."""
        F = np.eye(self.n_err)
        F[[E, N, U]] = 0.0
        Q = np.diag([DIFFUSE_SD_M**2 if i in (E, N, U) else 0.0 for i in range(self.n_err)])
        self._bank.transition(F, Q)

    def _gnss(self, j: int) -> None:
        counts, fx = self.gnss_counts, self._fixes
        skipped = fx.skipped(j, self._start_fix)
        if skipped is not None:
            counts[skipped] += 1
            return
        f = self.config.filter
        walking, steady = bool(fx.walking[j]), bool(fx.steady[j])
        self._model.gnss_position(fx.sd[j])
        H, R = self._model.H_pos, self._model.R_pos
        H_nominal = H[:, self._nominal]

        def residual(x: np.ndarray) -> np.ndarray:  # z − (p̂ + σ_k √ρ β̂): linear in the nominal state
            return fx.pos[j] - H_nominal @ x

        ok = self._update(H, residual, R, self._gate_pos, walking and steady, "gnss_position")
        self._rejected_in_row = 0 if ok else self._rejected_in_row + 1
        if not ok and 0 < f.reset_after_rejections <= self._rejected_in_row:
            before = self.position_n().copy()
            self._forget_position()
            ok = self._update(H, residual, R, math.inf, False, None)  # a reset takes the fix, however far
            counts["position_resets"] += 1
            self._rejected_in_row = 0
            self._position_resets.append((self._tc, self.position_n() - before))
        elif ok and len(self._bank) == 1 and (bias := np.hypot(*self._bank.moments(copy=False)[0][5:7])) > BIAS_LIMIT:
            before = self.position_n().copy()
            self._reanchor()  # the filter explains the fixes by a bias no fix has: the PDR strayed
            ok = self._update(H, residual, R, self._gate_pos, False, None)
            counts["reanchored"] += 1
            self.reanchor_times.append(self._tc)
            self.reanchors.append((self._tc, float(np.hypot(*(self.position_n() - before)[:2])), float(bias),
                                   float(fx.sd[j])))
        counts["accepted" if ok else "rejected"] += 1
        if len(self._bank) > 1:
            self.heading_counts["unweighted_standing" if not walking else
                                "unweighted_handling" if not steady else "weighted"] += 1
        self._track_heading(j, ok, walking, steady)
        if not (ok and np.isfinite(fx.course[j]) and fx.speed[j] >= f.min_speed_for_heading_mps):
            return
        if not walking:
            counts["heading_skipped_standing"] += 1
        elif not steady:
            counts["heading_skipped_handling"] += 1
        elif fx.accuracy[j] > f.max_accuracy_for_heading_m:
            counts["heading_skipped_accuracy"] += 1
        else:
            okh = self._update(self._model.H_psi, lambda x: np.array([wrap_angle(fx.course[j] - x[3])]), self._model.R_psi,
                               self._gate_psi, True, "gnss_course")
            counts["heading_accepted" if okh else "heading_rejected"] += 1

    def _track_heading(self, j: int, accepted: bool, walking: bool, steady: bool) -> None:
        """Fix j into the GNSS track's stretch (:mod:`bodyfusion.plugins.hand_pdr.track_heading`),
        and a heading update when the stretch is complete; handling the phone or an open heading
        bank starts the stretch anew."""
        if not steady or len(self._bank) > 1:
            self._track.clear()
            return
        if not (accepted and walking):
            return
        self._track.add(self._fixes.pos[j, :2], float(self._fixes.sd[j]))
        got = self._track.measure()
        if got is None:
            return
        z, r_var = got
        ok = self._update(self._model.H_psi, lambda x: np.array([z]), np.array([[r_var]]), self._gate_psi, True,
                          "gnss_track")
        self.gnss_counts["track_heading_accepted" if ok else "track_heading_rejected"] += 1
