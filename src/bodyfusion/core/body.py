"""The wearer's proportions, and the distance limits between body parts they give.

Anthropometric shares of the standing height h (Drillis & Contini 1966: leg 0.53 h, arm 0.44 h),
with a margin over what a walk reaches (:mod:`bodyfusion.core.limits` applies them):

* foot–foot: a step of up to :data:`STEP_SHARE` h ahead (a long walking step; the feet of the
  walks with truth here part by at most 0.52 and 0.72 m) beside the stance width,
  √((0.6 h)² + (0.11 h)²) ≈ 1.07 m at 1.75 m. Once the gait's stride s is known the limit
  follows it: √((0.8 s)² + (0.11 h)²), never below :data:`FOOT_FLOOR_SHARE` h (a wide stance,
  turning on the spot). The feet of every walk with truth here (real and simulated: walks,
  stairs, a run) part at their fuser epochs by at most 0.67 s (a walk that turns all the time),
  0.54–0.61 s (straight walks, stairs) and 0.30 s (the run);
* foot–hand: half such a step (the foot from the hip) and the arm's reach with a margin,
  0.3 h + 0.55 h ≈ 1.49 m at 1.75 m (the 1.5 m of the PDR/GNSS paper), or 0.4 s + 0.55 h.

Horizontal distances, metres.
"""

from __future__ import annotations

import numpy as np

STANCE_WIDTH_SHARE = 0.11
"""Lateral distance of the feet standing, as a share of the height (0.19 m at 1.75 m)."""
STEP_SHARE = 0.6
"""The longest walking step, foot to foot, as a share of the height (with margin)."""
ARM_SHARE = 0.44
"""Shoulder to fingertip, as a share of the height."""
HAND_MARGIN_SHARE = 0.11
"""What a hand-held phone adds beyond the reach of a foot half a step away and the arm."""
STRIDE_SHARE = 0.8
"""A foot–foot limit that follows the gait: this share of a stride (the step is half of one;
the margin covers uneven steps, turns and the flight of a run) beside the stance width."""
FOOT_FLOOR_SHARE = 0.35
"""The least foot–foot limit, as a share of the height (a wide stance: 0.61 m at 1.75 m)."""
MAX_STRIDE_SHARE = 1.6
"""Longest stride a body limit follows, as a share of the height (a sprint's)."""


def body_limit(part_a: str | None, part_b: str | None, height_m: float,
               stride_m: float | None = None) -> float | None:
    """The body's maximum horizontal distance (m) between a ``part_a`` and a ``part_b`` of a
    wearer ``height_m`` tall (module docstring), widened to the gait's when a ``stride_m`` (m)
    is known; None for parts it does not know."""
    h = height_m
    width = STANCE_WIDTH_SHARE * h
    step = STEP_SHARE * h if stride_m is None else STRIDE_SHARE * min(stride_m, MAX_STRIDE_SHARE * h)
    parts = sorted((part_a or "", part_b or ""))
    if parts == ["foot", "foot"]:
        return float(max(np.hypot(step, width), FOOT_FLOOR_SHARE * h))
    if parts == ["foot", "hand"]:
        return float(step / 2 + (ARM_SHARE + HAND_MARGIN_SHARE) * h)
    return None
