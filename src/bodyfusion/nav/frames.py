"""Frames of the files a user brings: signed axis maps and named position frames.

An IMU writes its axes its own way (z down at rest, x and y swapped); a truth file may be ENU,
NED, or a motion-capture room's own axes. Both are declared in the layout as a signed axis map
(:data:`AxisMap`): entry k names the file axis that becomes axis k of the project's frame
(body x, y, z for an IMU; east, north, up for positions).
"""

from __future__ import annotations

from typing import Annotated

import numpy as np
from pydantic import AfterValidator


def _right_handed(signs: tuple[int, int, int]) -> tuple[int, int, int]:
    if any(v not in (-1, 1) for v in signs):
        raise ValueError("each axis sign must be 1 or -1")
    if signs[0] * signs[1] * signs[2] != 1:
        raise ValueError("these signs mirror the frame (their product must be +1 for a right-handed ENU)")
    return signs


AxisSigns = Annotated[tuple[int, int, int], AfterValidator(_right_handed)]
"""Signs (+1/−1) turning a file's x, y, z position axes into east, north, up; e.g.
``[1, -1, -1]`` for a right-handed frame whose z points down (a rotation of 180° about x).
Kept for older layouts: :data:`AxisMap` (``frame:``) says the same and more."""

_AXIS_INDEX = {"x": 0, "y": 1, "z": 2}


def _signed_axis_map(axes: tuple[str, str, str]) -> tuple[str, str, str]:
    seen = []
    for entry in axes:
        name = entry.strip().lstrip("+-")
        if name not in _AXIS_INDEX or entry.strip().count("-") > 1:
            raise ValueError(f"each entry must be one of x, y, z, -x, -y, -z; got {entry!r}")
        seen.append(name)
    if sorted(seen) != ["x", "y", "z"]:
        raise ValueError(f"each of x, y, z must appear once, got {list(axes)}")
    return tuple(a.strip().lstrip("+") for a in axes)  # type: ignore[return-value]


AxisMap = Annotated[tuple[str, str, str], AfterValidator(_signed_axis_map)]
"""A signed axis map: entry k names the file axis (``x``, ``-y``, ...) that becomes axis k of
the project's frame. ``[x, -y, -z]``: a frame with z down turned 180° about x; ``[y, x, -z]``:
north-east-down to east-north-up. Any signed permutation (a map that mirrors is allowed: the
file's frame may be left-handed)."""

def _sensor_axis_map(axes: tuple[str, str, str]) -> tuple[str, str, str]:
    axes = _signed_axis_map(axes)
    if axis_map_determinant(axes) < 0:
        raise ValueError(f"{list(axes)} mirrors the sensor's frame (a left-handed map): a sensor's axes are "
                         "right-handed, so a body frame reached from them by a rotation negates an even number "
                         "of axes when it keeps their order ([x, -y, -z]: z down, 180° about x) or swaps two and "
                         "negates one ([y, x, -z])")
    return axes


def axis_map_determinant(axes: tuple[str, str, str]) -> int:
    """+1 for a signed axis map that rotates (right-handed to right-handed), −1 for one that
    mirrors: the sign of the permutation times the product of the signs."""
    order = [_AXIS_INDEX[a.lstrip("-")] for a in axes]
    inversions = sum(order[i] > order[j] for i in range(3) for j in range(i + 1, 3))
    negated = sum(a.startswith("-") for a in axes)
    return -1 if (inversions + negated) % 2 else 1


SensorAxisMap = Annotated[tuple[str, str, str], AfterValidator(_sensor_axis_map)]
"""A signed axis map (:data:`AxisMap`) that rotates: a sensor's frame (an IMU's, a
magnetometer's) is right-handed, so a map that mirrors it (``[x, y, -z]``) is refused: it would
navigate a mirror image of the walk."""

NAMED_FRAMES: dict[str, tuple[str, str, str]] = {"enu": ("x", "y", "z"), "ned": ("y", "x", "-z")}
"""Position frames by name, as axis maps into east, north, up."""


def apply_axis_map(axes: tuple[str, str, str], v_file: np.ndarray) -> np.ndarray:
    """Vectors (N, 3) in the file's axes → (N, 3) in the project's frame by a signed axis map
    (:data:`AxisMap`); a column that is NaN in the file (absent height) stays NaN only where
    it is used."""
    v_file = np.asarray(v_file, dtype=float)
    out = np.empty_like(v_file)
    for k, entry in enumerate(axes):
        out[:, k] = v_file[:, _AXIS_INDEX[entry.lstrip("-")]] * (-1.0 if entry.startswith("-") else 1.0)
    return out
