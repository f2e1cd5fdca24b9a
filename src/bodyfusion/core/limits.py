"""Distance limits that come from the body, follow the gait, and defend themselves.

Body limits. A constraint whose ``distance_m`` is ``body`` (the default of a ``max`` limit)
takes its limit from where the two systems are worn (their plugins' ``body_part``) and the
wearer's height (the layout's ``body.height_m``): :func:`bodyfusion.core.body.body_limit`.

Strides differ (a shuffle, a stair, a run), so a body limit follows the gait: each foot's stride
(its travel between its own consecutive stance starts, as the fuser sees them; the median of its
last :data:`STRIDES_KEPT`, and the smaller of two feet's, so that a foot whose estimate runs away
cannot widen the limit that should hold it) sets it (:func:`bodyfusion.core.body.body_limit`).

Fights. A limit the estimates keep breaking while both are confident is not holding a drift:
it is wrong for this walk, or the systems disagree about something it cannot fix (their frames
differ). Pulling then drags both tracks away. At every epoch the broken limit's excess is
measured in the separation's own σ (e = (d̂ − d_max) / σ_d, σ_d² = uᵀ Σ_sep u along the
separation); when over the last :data:`FIGHT_EPOCHS` epochs of a constraint e ≥
:data:`FIGHT_SIGMAS` at least :data:`FIGHT_SHARE` of the time, the constraint fights the
systems: the limit is relaxed to :data:`RELAX_FACTOR` times the separation the estimates hold
(``fuser.relax_fights``), and it becomes a finding.

Fixes followed. A system that takes its position afresh from its own absolute sensor (a
phone's GNSS that jumped and stayed) by more than a limit it is held to cannot be there alone:
the fuser moves the systems held to it with it (:meth:`LimitGuard.follow` keeps the record), and
it becomes a finding.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from bodyfusion.base.errors import ConfigError
from bodyfusion.base.findings import Finding
from bodyfusion.core.body import body_limit
from bodyfusion.core.layout import BodyConfig, ConstraintConfig

STRIDES_KEPT = 5
"""A foot's last strides whose median its limit follows."""
FIGHT_EPOCHS = 6
"""Epochs of a constraint over which a fight is judged (about two strides of two feet)."""
FIGHT_SIGMAS = 3.0
"""Excess over the limit, in σ of the separation, that counts towards a fight."""
FIGHT_SHARE = 0.8
"""Share of the judged epochs beyond :data:`FIGHT_SIGMAS` that makes a fight."""
RELAX_FACTOR = 2.0
"""A fighting limit is relaxed to this multiple of the separation the estimates hold: systems
that disagree tend to part further (frames that differ part with every step)."""


def resolve_constraints(constraints: list[ConstraintConfig], parts: dict[str, str | None],
                        body: BodyConfig) -> tuple[list[ConstraintConfig], list[bool]]:
    """The constraints with every ``body`` limit replaced by the body's static one, and which
    of them follow the gait; a ConfigError (naming the key) for a pair the body gives no limit."""
    out, follows = [], []
    for k, c in enumerate(constraints):
        if c.distance_m != "body":
            out.append(c)
            follows.append(False)
            continue
        a, b = c.between
        limit = body_limit(parts.get(a), parts.get(b), body.height_m)
        if limit is None:
            raise ConfigError(f"constraints.{k}.distance_m",
                              f"the body gives no limit between {a} ({parts.get(a) or 'unknown part'}) and {b} "
                              f"({parts.get(b) or 'unknown part'}): give distance_m in metres")
        out.append(c.model_copy(update={"distance_m": limit}))
        follows.append("foot" in (parts.get(a), parts.get(b)))
    return out, follows


@dataclass
class LimitGuard:
    """Each constraint's limit at each epoch (:meth:`limits`): its configured one, or the body's
    following the feet's strides; relaxed where it fights the systems (:meth:`watch`).

    ``constraints``: the resolved constraints (numeric limits); ``follows``: which follow the
    gait; ``parts``: body part of each stacked system (the fuser's order); ``feet_sync``: each
    stacked foot's own sync times (s) known so far (more by :meth:`add_sync_times`, as a live run
    decides them); ``body``; ``relax``: relax fighting limits (else only report them)."""

    constraints: list[ConstraintConfig]
    follows: list[bool]
    order: list[str]
    parts: list[str | None]
    feet_sync: dict[int, np.ndarray]
    body: BodyConfig
    relax: bool = True
    relaxation: np.ndarray = field(init=False)
    """(K,) metres added to each limit by relaxing it."""
    fights: list[tuple[int, float, float, float, float]] = field(default_factory=list)
    """Every relaxation: (constraint, t_start s, t s, limit before m, limit after m)."""
    followed: list[tuple[float, str, tuple[str, ...], np.ndarray]] = field(default_factory=list)
    """Every position reset the body followed: (t s, system, the systems moved with it, move (3,) m)."""
    _strides: dict[int, list[float]] = field(default_factory=dict)
    _last: dict[int, np.ndarray] = field(default_factory=dict)
    _next_sync: dict[int, int] = field(default_factory=dict)
    _history: list[list[tuple[float, bool]]] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.relaxation = np.zeros(len(self.constraints))
        self._history = [[] for _ in self.constraints]
        self._next_sync = {i: 0 for i in self.feet_sync}

    def add_sync_times(self, i: int, times: np.ndarray) -> None:
        """Sync times (s) of stacked system i decided after those known (ignored unless i is a foot)."""
        if i in self.feet_sync and times.size:
            self.feet_sync[i] = np.concatenate([self.feet_sync[i], times]) if self.feet_sync[i].size else times

    def forget_passed(self) -> None:
        """Drop the feet's sync times the limits have passed (a live run that keeps a bounded history)."""
        for i, k in self._next_sync.items():
            self.feet_sync[i] = self.feet_sync[i][k:]
            self._next_sync[i] = 0

    def stride_m(self) -> float | None:
        """The gait's stride (m): the smaller of the feet's medians of their last strides."""
        medians = [float(np.median(s)) for s in self._strides.values() if s]
        return min(medians) if medians else None

    def limits(self, t: float, p_hat: np.ndarray) -> np.ndarray:
        """(K,) limits (m) at epoch t, stacked positions ``p_hat`` (3n,): a foot whose own sync
        time t is adds its travel since its last one to its strides first."""
        for i, times in self.feet_sync.items():
            k = self._next_sync[i]
            while k < times.size and times[k] < t:
                k += 1
            if k < times.size and times[k] == t:
                here = p_hat[3 * i:3 * i + 2].copy()
                if i in self._last:
                    strides = self._strides.setdefault(i, [])
                    strides.append(float(np.hypot(*(here - self._last[i]))))
                    del strides[:-STRIDES_KEPT]
                self._last[i] = here
                k += 1
            self._next_sync[i] = k
        stride = self.stride_m()
        out = np.empty(len(self.constraints))
        for k, c in enumerate(self.constraints):
            d = float(c.distance_m)
            if self.follows[k] and stride is not None:
                a, b = (self.parts[self.order.index(n)] for n in c.between)
                d = body_limit(a, b, self.body.height_m, stride)
            out[k] = d + self.relaxation[k]
        return out

    def watch(self, t: float, p_hat: np.ndarray, sigma: np.ndarray, limits: np.ndarray) -> None:
        """Judge each ``max`` constraint's epoch (the estimates ``p_hat`` (3n,) and their covariance
        ``sigma`` (3n, 3n) against ``limits`` (K,)); relax a fighting one (module docstring)."""
        for k, c in enumerate(self.constraints):
            if c.kind != "max":
                continue
            i, j = self.order.index(c.between[0]), self.order.index(c.between[1])
            dims = 2 if c.horizontal else 3
            r = p_hat[3 * i:3 * i + dims] - p_hat[3 * j:3 * j + dims]
            d = float(np.linalg.norm(r))
            if d == 0.0:
                continue
            u = r / d
            block = (sigma[3 * i:3 * i + dims, 3 * i:3 * i + dims] + sigma[3 * j:3 * j + dims, 3 * j:3 * j + dims]
                     - sigma[3 * i:3 * i + dims, 3 * j:3 * j + dims] - sigma[3 * j:3 * j + dims, 3 * i:3 * i + dims])
            excess = (d - limits[k]) / float(np.sqrt(max(u @ block @ u, 1e-12)))
            history = self._history[k]
            history.append((t, excess >= FIGHT_SIGMAS))
            del history[:-FIGHT_EPOCHS]
            if len(history) == FIGHT_EPOCHS and sum(f for _, f in history) >= FIGHT_SHARE * FIGHT_EPOCHS:
                relaxed = RELAX_FACTOR * d if self.relax else float(limits[k])
                self.fights.append((k, history[0][0], t, float(limits[k]), relaxed))
                self.relaxation[k] += relaxed - limits[k]
                history.clear()

    def beyond_limits(self, name: str, move: np.ndarray) -> bool:
        """Whether a move (3,) m of system ``name`` is longer, horizontally, than the smallest
        limit it is held to (its constraints' current ``max`` limits; False when it has none)."""
        held = [float(c.distance_m) + self.relaxation[k] for k, c in enumerate(self.constraints)
                if c.kind == "max" and name in c.between]
        return bool(held) and float(np.hypot(move[0], move[1])) > min(held)

    def follow(self, t: float, name: str, followers: list[str], move: np.ndarray) -> None:
        """Record that ``followers`` moved by ``move`` (3,) m with system ``name``'s reset at ``t`` (s)."""
        self.followed.append((float(t), name, tuple(followers), np.asarray(move, dtype=float).copy()))

    def findings(self) -> list[Finding]:
        """A finding per constraint that fought the systems, and one per system whose position
        resets the body followed."""
        out = self._followed_findings()
        for k, c in enumerate(self.constraints):
            fights = [f for f in self.fights if f[0] == k]
            if not fights:
                continue
            a, b = c.between
            first, last = fights[0], fights[-1]
            action = (f"relaxed it {len(fights)} time(s), from {first[3]:.2f} to {last[4]:.2f} m, instead of pulling "
                      "both tracks" if self.relax else "kept pulling both tracks (fuser.relax_fights is off)")
            out.append(Finding(
                "constraint_fight", "warning", None, float(first[1]), float(last[2]),
                f"the {a}–{b} limit fought the systems: for {FIGHT_SHARE:.0%} of {FIGHT_EPOCHS} epochs in a row "
                f"both estimates held them more than {FIGHT_SIGMAS:g} σ beyond its {first[3]:.2f} m; the fuser "
                f"{action}.",
                f"the limit is too tight for this walk (a longer stride, a run), or {a} and {b} are not in one "
                "frame (a heading set by hand, a mounting the alignment missed).",
                f"set constraints.{k}.distance_m to body (the default: it follows the gait) or a larger value; "
                "leave heading_deg at auto so that both share one frame."))
        return out

    def _followed_findings(self) -> list[Finding]:
        out = []
        for name in dict.fromkeys(f[1] for f in self.followed):
            moves = [f for f in self.followed if f[1] == name]
            sizes = [float(np.hypot(*f[3][:2])) for f in moves]
            followers = ", ".join(dict.fromkeys(n for f in moves for n in f[2])) or "no other system"
            out.append(Finding(
                "reset_followed", "warning", name, moves[0][0], moves[-1][0],
                f"{name} took its position afresh from its absolute sensor {len(moves)} time(s), by up to "
                f"{max(sizes):.1f} m, beyond the body's limits; {followers} moved with it, so that the constraints "
                "follow the fixes instead of dragging it back.",
                "the absolute sensor jumped and stayed there (a receiver reset, a changed datum or antenna offset, "
                "spoofing), or the dead reckoning strayed further than a constraint could hold.",
                f"look at {name}'s fixes at those times; if the jump is the receiver's error, mask it with an outage "
                "(outages: [{system, start_s, duration_s}])."))
        return out

    def summary(self) -> dict:
        """metrics.json figures: the gait's stride, each constraint's relaxation, and the
        position resets the body followed."""
        stride = self.stride_m()
        return {"stride_m": stride, "follows_gait": [bool(f) for f in self.follows],
                "fights": len(self.fights), "relaxation_m": [float(x) for x in self.relaxation],
                "resets_followed": len(self.followed)}
