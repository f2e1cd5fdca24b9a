"""Verdicts on a run's consistency, said as findings: is each system's horizontal NEES against
truth, and each aiding type's NIS, where a consistent filter's would be, and if not, why.

A consistent filter's NEES (NIS) has the χ² distribution of its dimension: mean = dof, and 95 %
of its epochs inside the two-sided band of one epoch (:func:`~bodyfusion.evaluation.consistency.chi2_band`).
One run's epochs are strongly correlated (the epochs of one stance, a drift that lasts), so a
band for their mean from their count would be far too narrow; the verdict takes the mean within
a factor :data:`CONSISTENT_FACTOR` of the dof (and, for the NEES, at least
:data:`MIN_IN_BAND` of the epochs inside the one-epoch band) as consistent. Beyond it the finding
says how far, and a cause from where in the run it happens: large from the start and falling
(the initial state is off by more than its σ), growing (a drift the covariance does not follow),
large throughout (noise models too small), or too small (too large: the σ is pessimistic). Where
the truth's frame was fitted to the estimate (``first_3m``), the NEES is approximate: its start
measures the fit, so no initial mismatch is read from it, and its findings are ``info``
(shown with ``-v``, kept in metrics.json); against a truth in the run's own frame they are
warnings.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from bodyfusion.base.findings import Finding
from bodyfusion.evaluation.consistency import NeesTrack

CONSISTENT_FACTOR = 3.0
"""A mean NEES or NIS within [dof / this, dof × this] is consistent for one run."""
MIN_IN_BAND = 0.5
"""Least share of a run's epochs whose NEES lies inside the one-epoch 95 % band."""
EARLY_SHARE = 0.2
"""The first this share of a run's epochs is its start (initial-state mismatch)."""
TREND_FACTOR = 3.0
"""A start (end) whose mean NEES is this many times the end's (start's) marks a falling (growing) NEES."""

NIS_CAUSES = {
    "zupt": ("the foot is not at rest where stance is declared (a rolling stance, a detector that calls stance too "
             "early), or filter.zupt_sigma_mps is smaller than this foot's rest", "raise filter.zupt_sigma_mps, or "
             "check the detector's stance share in diagnostics"),
    "position_fix": ("the fixes are noisier than their σ", "raise position_fixes.sigma_m"),
    "gnss_position": ("the GNSS fixes are noisier than their reported accuracy (multipath, a wrong accuracy_to_sigma)",
                      "raise filter.accuracy_to_sigma or filter.default_sigma_m"),
}
"""Likely cause and advice of an aiding type's NIS beyond its band (others: a generic one)."""


def _span(t: np.ndarray) -> tuple[float, float]:
    return float(t[0]), float(t[-1])


def nees_findings(tracks: Mapping[str, NeesTrack]) -> list[Finding]:
    """A finding per scored system whose horizontal NEES is beyond a consistent filter's (module
    docstring), with a cause from its course over the run."""
    out = []
    for name, track in tracks.items():
        ok = np.isfinite(track.nees)
        t, v = track.t[ok], track.nees[ok]
        if v.size < 10:
            continue
        lo, hi = track.band()
        mean, dof = float(v.mean()), track.dof
        inside = float(np.mean((v >= lo) & (v <= hi)))
        if dof / CONSISTENT_FACTOR <= mean <= dof * CONSISTENT_FACTOR and inside >= MIN_IN_BAND:
            continue
        k = max(1, int(EARLY_SHARE * v.size))
        early, late = float(v[:k].mean()), float(v[v.size // 2:].mean())
        fitted = f" (truth frame fitted: {track.alignment})" if track.alignment != "none" else ""
        severity = "warning" if track.alignment == "none" else "info"
        what = (f"the horizontal NEES against truth averages {mean:.3g} (a consistent filter: {dof}, within "
                f"{dof / CONSISTENT_FACTOR:.2g}–{dof * CONSISTENT_FACTOR:.2g}); {100 * inside:.0f} % of the epochs lie "
                f"in the one-epoch 95 % band [{lo:.3g}, {hi:.3g}]{fitted}.")
        if mean < dof / CONSISTENT_FACTOR:
            out.append(Finding("nees_pessimistic", "info", name, *_span(t), what,
                               "the filter's σ is larger than its errors: noise densities or initial σ set too large.",
                               "lower the noise densities (filter.*_noise_density) toward the sensor's datasheet."))
        elif early > TREND_FACTOR * late and early > dof * CONSISTENT_FACTOR and track.alignment == "none":
            out.append(Finding("initial_state_mismatch", "warning", name, *_span(t[:k]), what,
                               f"the initial state is off by more than its σ: the NEES starts at {early:.3g} and falls "
                               f"to {late:.3g} (a start position or heading given wrongly, two systems started at one "
                               "point).", "give initial.position_m / heading_deg as worn, or raise "
                               "initial.position_sd_m / heading_sd_deg."))
        elif late > TREND_FACTOR * early:
            out.append(Finding("nees_drift", severity, name, *_span(t), what,
                               f"an error that grows faster than the covariance: the NEES rises from {early:.3g} to "
                               f"{late:.3g} (heading drift from a gyro bias about Up, which stance updates cannot "
                               "observe, or a scale error).", "raise filter.gyro_bias_random_walk, or aid the heading "
                               "(a second foot, a magnetometer, position fixes)."))
        else:
            out.append(Finding("nees_overconfident", severity, name, *_span(t), what,
                               "the filter is overconfident throughout: its noise models are smaller than the "
                               "sensor's errors.", "raise filter.zupt_sigma_mps and the noise densities."))
    return out


def nis_findings(nis: Mapping[str, Mapping[str, dict]], spans: Mapping[str, tuple[float, float]]) -> list[Finding]:
    """A finding per system and aiding type (``nis[system][kind]``: metrics.json's ``health.nis``
    entries, ``mean`` and ``dof``) whose mean NIS is beyond a consistent filter's; ``spans``:
    each system's time span (s)."""
    out = []
    for name, kinds in nis.items():
        for kind, tally in kinds.items():
            mean, dof, count = tally.get("mean"), tally.get("dof"), tally.get("count", 0)
            if mean is None or not dof or count < 10:
                continue
            if dof / CONSISTENT_FACTOR <= mean <= dof * CONSISTENT_FACTOR:
                continue
            what = (f"the {kind.replace('_', ' ')} updates' NIS averages {mean:.3g} over {count} updates (a consistent "
                    f"filter: {dof}, within {dof / CONSISTENT_FACTOR:.2g}–{dof * CONSISTENT_FACTOR:.2g}); "
                    f"{tally.get('beyond_gate', 0)} beyond the gate.")
            if mean < dof / CONSISTENT_FACTOR:
                out.append(Finding("nis_pessimistic", "info", name, *spans[name], what,
                                   "the measurement's σ is larger than its errors.",
                                   f"lower the {kind.replace('_', ' ')} σ."))
                continue
            cause, advice = NIS_CAUSES.get(kind, ("the measurement is noisier than its σ, or the filter's state "
                                                  "disagrees with it (a drift)", "raise its σ, or look at the "
                                                  "system's other findings"))
            out.append(Finding("nis_high", "warning", name, *spans[name], what, cause + ".", advice + "."))
    return out
