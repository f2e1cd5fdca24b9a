"""The smoothed stream of a live run (``smoother.kind: fixed-lag``): each system's live smoother
hands on the samples the data now smooth for good
(:meth:`~bodyfusion.core.capabilities.Smoothing.live_smoother`); :class:`SmoothedEpochs` merges
them into output epochs on the filtered stream's grid (multiples of ``output_interval_s``), each
written to the sinks once every smoothing system's smoothed samples reach it
(:meth:`~bodyfusion.core.epoch_state.EpochOutput.emit_smoothed`). A system's state at an epoch is
its last smoothed sample at or before it, as in the filtered stream. Systems that cannot smooth
live (the hand-held phone) are not in the smoothed stream; their filtered states are in the other.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from bodyfusion.core.epoch_state import EpochOutput, SmoothedSamples, SystemState


class SmoothedEpochs:
    """``smoothers`` (system → its live smoother) merged into smoothed epochs written to
    ``output`` with ``lag_s`` (module docstring). ``held``: the samples not emitted yet, per system."""

    def __init__(self, smoothers: Mapping[str, object], output: EpochOutput, lag_s: float) -> None:
        self.smoothers, self.output, self.lag_s = dict(smoothers), output, lag_s
        self.held: dict[str, SmoothedSamples | None] = dict.fromkeys(self.smoothers)
        self._next_k: int | None = None
        """The next epoch's multiple of the output interval."""

    def advance(self, final: bool = False) -> int:
        """Take what each smoother now gives (``final``: the recordings are complete) and emit every
        epoch all of them reach. Returns the epochs emitted."""
        for name, smoother in self.smoothers.items():
            new = smoother.advance(final)
            if new is not None and new.t.size:
                old = self.held[name]
                self.held[name] = new if old is None else SmoothedSamples(
                    *(np.concatenate([a, b]) for a, b in zip((old.t, old.position_n, old.position_sd_m),
                                                             (new.t, new.position_n, new.position_sd_m))))
        if not self.smoothers or any(h is None for h in self.held.values()):
            return 0
        dt = self.output.interval_s
        if self._next_k is None:  # as the filtered stream: epochs after every system's first sample
            self._next_k = math.floor(max(h.t[0] for h in self.held.values()) / dt)
            while round(self._next_k * dt, 9) <= max(h.t[0] for h in self.held.values()):
                self._next_k += 1
        reach = min(h.t[-1] for h in self.held.values())  # final: the filtered stream's last epoch too
        emitted = 0
        while (t := round(self._next_k * dt, 9)) <= reach:
            states = {}
            for name, h in self.held.items():
                i = int(np.searchsorted(h.t, t, side="right")) - 1
                states[name] = SystemState(float(h.t[i]), h.position_n[i], h.position_sd_m[i])
            self.output.emit_smoothed(t, states, self.lag_s)
            emitted += 1
            self._next_k += 1
        if emitted:
            t = round(self._next_k * dt, 9)
            for name, h in self.held.items():  # keep the last sample at or before the next epoch, and later ones
                i = max(int(np.searchsorted(h.t, t, side="right")) - 1, 0)
                self.held[name] = SmoothedSamples(h.t[i:], h.position_n[i:], h.position_sd_m[i:])
        return emitted

    def diagnostics(self) -> dict:
        """Per system its smoother's diagnostics, and the smoothed epochs emitted."""
        return {"epochs": self.output.smoothed_emitted,
                "systems": {name: s.diagnostics() for name, s in self.smoothers.items()}}
