"""UWB tag: two-way ranges to fixed anchors and to tags on other body-worn systems.

Measurement model (positions ENU, m). The tag's antenna is at p_h + l_h, the host's
navigated position plus a constant lever arm in the navigation frame.

* Anchor a at a_n:  r = ‖p_h + l_h − a_n‖ + v,  ∂r/∂p_h = uᵀ,  u = (p_h + l_h − a_n) / r.
* Peer tag on system j (lever arm l_j):  r = ‖(p_h + l_h) − (p_j + l_j)‖ + v,
  ∂r/∂p_h = uᵀ, ∂r/∂p_j = −uᵀ, u the unit vector from the peer's antenna to the host's.

v ~ N(0, σ²) in line of sight. Non-line-of-sight ranges are longer than the geometric
distance (the signal goes round or through the body): the fuser's chi-square gate on
the innovation rejects those whose excess is large against √(H P Hᵀ + σ²).
The tag has no state: the fuser applies each range to the measured systems' error
states (:mod:`bodyfusion.core.fuser`).
"""

from __future__ import annotations

import numpy as np

from bodyfusion.base.types import InputReport
from bodyfusion.core.system import (
    AidingSource,
    JacobianCase,
    LayoutContext,
    ScalarMeasurement,
)
from bodyfusion.nav.filter_health import NisTally
from bodyfusion.io.tables import source_name
from bodyfusion.nav.measurements import chi2_gate
from bodyfusion.plugins.uwb.config import UwbConfig
from bodyfusion.plugins.uwb.streaming import ACCEPTED, LATE, NOT_APPLIED, REJECTED, UNUSED, RangeTally, StreamingUwbTag



def range_and_jacobian(a_n: np.ndarray, b_n: np.ndarray) -> tuple[float, np.ndarray]:
    """‖a_n − b_n‖ (m) and its gradient with respect to a_n (the unit vector from b to a;
    the gradient with respect to b_n is its negative)."""
    d = a_n - b_n
    r = float(np.sqrt(d @ d))
    return r, d / max(r, 1e-9)


class UwbTag(StreamingUwbTag, AidingSource):
    """A UWB tag on the system ``host`` (see :class:`bodyfusion.plugins.uwb.config.UwbConfig`).

    Ranges come from the layout's CSV (:func:`bodyfusion.plugins.uwb.ranges.read_ranges`);
    ``fate`` (K,) records what the fuser did with each (:data:`ACCEPTED`, :data:`REJECTED`
    by the gate, :data:`NOT_APPLIED`: outside the measured systems' data, :data:`LATE`: arrived
    after the fuser passed its time in a live run) and ``nis`` (K,) its normalised innovation
    squared. It runs live (:mod:`bodyfusion.plugins.uwb.streaming`).
    """

    plugin_name = "uwb"
    Config = UwbConfig
    data_section = "ranges"

    def __init__(self, name: str, config: UwbConfig, context: LayoutContext) -> None:
        super().__init__(name, config, context)
        self.ids = [*config.anchors, *config.peers]
        self.n_anchors = len(config.anchors)
        rc = config.ranges
        self.log = self.read_log()
        if len(self.log) == 0 and not context.growing:  # a live run's ranges may not have begun
            self.log.report.warn(f"{name}: no usable range in {source_name(rc)} "
                                 f"(dropped: {', '.join(f'{v} {k}' for k, v in self.log.dropped.items() if v) or 'none'})")
        self._anchor_n = np.array(list(config.anchors.values()), dtype=float).reshape(-1, 3)
        self._peer_lever_n = np.array(list(config.peers.values()), dtype=float).reshape(-1, 3)
        self._lever_n = np.asarray(config.lever_arm_m, dtype=float)
        self._systems = [(config.host,) if k < self.n_anchors else (config.host, self.ids[k])
                         for k in range(len(self.ids))]
        self._gate = chi2_gate(config.gate_probability, 1)
        self.fate = np.full(len(self.log), UNUSED, dtype=np.int8)
        self.nis = np.full(len(self.log), np.nan)

    @classmethod
    def system_references(cls, config: UwbConfig) -> list[tuple[str, str]]:
        return [("host", config.host), *((f"peers.{name}", name) for name in config.peers)]

    # --- measurements ----------------------------------------------------------------
    def measurement_times(self) -> np.ndarray:
        return self.log.t

    def measured_systems(self, k: int) -> tuple[str, ...]:
        return self._systems[self.log.end[k]]

    def measure(self, k: int, positions_n: list[np.ndarray]) -> ScalarMeasurement:
        end = int(self.log.end[k])
        antenna_n = positions_n[0] + self._lever_n
        if end < self.n_anchors:
            r, u = range_and_jacobian(antenna_n, self._anchor_n[end])
            H_p = u[None, :]
        else:
            r, u = range_and_jacobian(antenna_n, positions_n[1] + self._peer_lever_n[end - self.n_anchors])
            H_p = np.vstack([u, -u])
        return ScalarMeasurement(float(self.log.range_m[k]), r, H_p, self.config.sigma_m ** 2)

    @property
    def gate_nis(self) -> float:
        return self._gate

    def record(self, k: int, nis: float | None, accepted: bool) -> None:
        self.fate[k] = NOT_APPLIED if nis is None else (ACCEPTED if accepted else REJECTED)
        self.nis[k] = np.nan if nis is None else nis

    def jacobian_cases(self) -> list:
        """The range Jacobians (anchor and peer) at a few geometries, for the conformance check."""
        rng = np.random.default_rng(0)
        lever = self._lever_n
        cases = []
        for k in range(3):
            p, q = rng.normal(0, 10, 3), rng.normal(0, 10, 3)
            a = self._anchor_n[k % len(self._anchor_n)] if len(self._anchor_n) else rng.normal(0, 10, 3)
            _, u = range_and_jacobian(p + lever, a)
            cases.append(JacobianCase(f"anchor range at {np.round(p, 2).tolist()}",
                                      lambda x, a=a: np.array([np.linalg.norm(x + lever - a)]), p, u[None, :]))
            peer_lever = rng.normal(0, 0.2, 3)
            _, u = range_and_jacobian(p + lever, q + peer_lever)
            cases.append(JacobianCase(
                f"peer range at {np.round(p, 2).tolist()} / {np.round(q, 2).tolist()}",
                lambda x, pl=peer_lever: np.array([np.linalg.norm(x[:3] + lever - x[3:] - pl)]),
                np.concatenate([p, q]), np.concatenate([u, -u])[None, :]))
        return cases

    # --- results -----------------------------------------------------------------------
    @property
    def samples(self) -> int:
        return int(self.tally().fates.sum())

    @property
    def input_report(self) -> InputReport:
        return self.log.report

    @staticmethod
    def _counts(tally: RangeTally, ends: np.ndarray) -> dict:
        """Ranges, accepted, rejected by the gate, not applied, late and the mean NIS of the
        accepted, over the ends (indices) ``ends``."""
        fates = tally.fates[ends].sum(axis=0)
        accepted = int(fates[ACCEPTED])
        return {"ranges": int(fates.sum()), "accepted": accepted, "rejected_by_gate": int(fates[REJECTED]),
                "not_applied": int(fates[NOT_APPLIED]), "late": int(fates[LATE]),
                "mean_nis_accepted": float(tally.nis_accepted[ends].sum()) / accepted if accepted else None}

    def diagnostics(self) -> dict:
        """Per end (anchor or peer) and for anchors and peers together: ranges, accepted,
        rejected by the gate, not applied (outside the measured systems' data), late (a live run's
        ranges that arrived after the fuser passed their time), mean NIS of the accepted; the
        reader's drops; with a truth NLOS column, the gate's confusion counts. Of the whole run,
        the ranges a bounded live run forgot included (:meth:`tally`)."""
        tally = self.tally()
        ends = np.arange(len(self.ids))
        out: dict = {"plugin": self.plugin_name, "host": self.config.host,
                     "gate_nis": self._gate, "sigma_m": self.config.sigma_m, "dropped": dict(tally.dropped)}
        if self.n_anchors:
            out["anchor_ranges"] = self._counts(tally, ends[:self.n_anchors])
        if len(self.ids) > self.n_anchors:
            out["peer_ranges"] = self._counts(tally, ends[self.n_anchors:])
        out["per_end"] = {name: self._counts(tally, ends[k:k + 1]) for k, name in enumerate(self.ids)}
        if self.log.nlos is not None:
            (los_accepted, los_rejected), (nlos_accepted, nlos_rejected) = tally.nlos.tolist()
            out["gate_vs_truth"] = {"nlos_rejected": nlos_rejected, "nlos_accepted": nlos_accepted,
                                    "los_rejected": los_rejected, "los_accepted": los_accepted}
        return out

    def innovations(self) -> dict[str, np.ndarray]:
        """Every range the fuser applied (accepted or refused by the gate): ``aiding``
        ``anchor_range`` or ``peer_range``, ``end`` (the anchor or peer system), 1 dof."""
        applied = np.flatnonzero((self.fate == ACCEPTED) | (self.fate == REJECTED))
        end = self.log.end[applied]
        return {"t": self.log.t[applied], "aiding": np.where(end < self.n_anchors, "anchor_range", "peer_range"),
                "nis": self.nis[applied], "dof": np.ones(applied.size, dtype=np.int64),
                "accepted": self.fate[applied] == ACCEPTED, "end": np.asarray(self.ids, dtype=object)[end]}

    def health(self) -> dict:
        """``nis`` of the ranges the fuser applied (1 dof, before the gate; beyond the gate:
        rejected), ``anchor_ranges`` and ``peer_ranges`` apart where the tag has them; of the
        whole run (:meth:`tally`)."""
        tally = self.tally()
        ends = np.arange(len(self.ids))
        groups = {"anchor_ranges": ends[:self.n_anchors], "peer_ranges": ends[self.n_anchors:]}
        tallies = {}
        for kind, group in groups.items():
            fates = tally.fates[group].sum(axis=0)
            if fates.sum():
                tallies[kind] = NisTally(1, int(fates[ACCEPTED] + fates[REJECTED]),
                                         float(tally.nis_applied[group].sum()), int(fates[REJECTED]))
        return {"nis": {kind: tally.to_dict() for kind, tally in tallies.items()}}
