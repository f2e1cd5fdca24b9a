"""Health findings: what went wrong in a run, said so that a person can act on it.

A finding is one sentence of ``message`` (what, where: the system and time span, how bad,
with the band it should be in), a likely ``cause`` and ``advice`` (what to try). Systems,
the fuser and the evaluation each report theirs; a run shows them all on stderr (one line
each, :meth:`Finding.line`) and keeps them in metrics.json ``health.findings`` (run level)
and ``systems.<name>.health.findings`` (the system's own), in the fields the contract names:
``severity, system, t_start, t_end, message, cause, advice`` (and ``kind``, a stable key for
tools: ``missed_stances``, ``zupt_lockout``, ``constraint_fight``, ...).

Severities: ``warning`` (the result is likely wrong there), ``info`` (worth knowing, the
result is not in doubt).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Literal

Severity = Literal["info", "warning"]


@dataclass(frozen=True)
class Finding:
    """One health finding (module docstring). Times in seconds on the layout's clock; None
    for the whole run."""

    kind: str
    severity: Severity
    system: str | None
    t_start: float | None
    t_end: float | None
    message: str
    cause: str
    advice: str

    def to_dict(self) -> dict:
        """Plain JSON (metrics.json)."""
        return asdict(self)

    def line(self) -> str:
        """The finding on one line: where, what, cause, advice."""
        where = self.system or "run"
        if self.t_start is not None and self.t_end is not None:
            where += f", t = {self.t_start:.1f}–{self.t_end:.1f} s"
        return f"{where}: {self.message} Likely cause: {self.cause} Try: {self.advice}"


def spans(times: list[float] | tuple[float, ...]) -> str:
    """"a–b s, c–d s" of consecutive (start, end) pairs, at most three and "…" after."""
    pairs = [f"{a:.1f}–{b:.1f} s" for a, b in zip(times[::2], times[1::2])]
    return ", ".join(pairs[:3]) + (f" and {len(pairs) - 3} more" if len(pairs) > 3 else "")
