"""Throughput of the ensemble foot INS (``filter.kind: enekf`` / ``cenekf``) on one core.

Runs one foot of the vendored dual-foot Vicon walk (60 Hz, 7201 samples, 44 % stance)
through the normal layout path and prints, per ensemble size M, the filter steps per
second (one step = every member mechanised with its noise draw, plus the ensemble
analysis at stance samples), warm: best of three full passes after the kernels are
compiled. The last line is ``steps_per_s=<enekf, M = 100>``.

Usage: python benchmarks/enekf_throughput.py [--members 20 50 100] [--kind enekf cenekf]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from bodyfusion.core.layout import load_layout
from bodyfusion.runner import build_systems, layout_context

ROOT = Path(__file__).resolve().parents[1]
CONFIG = ROOT / "configs" / "dual_foot_vicon.yaml"


def steps_per_s(kind: str, members: int, repeats: int = 3) -> float:
    """Best-of-``repeats`` filter steps per second of the left foot with ``members`` members."""
    overrides = [f"systems.left_foot.filter.kind={kind}", f"systems.left_foot.filter.members={members}",
                 "fuser.method=none"]
    if kind == "cenekf":
        overrides.append("systems.left_foot.filter.colour_factor=0.9")
    loaded = load_layout(CONFIG, overrides)
    system = build_systems(loaded, layout_context(loaded))["left_foot"]
    system.advance(system.t_start + 2.0)  # compile
    best = 0.0
    for _ in range(repeats):
        system.restart()
        t0 = time.perf_counter()
        system.advance(system.t_end)
        wall = time.perf_counter() - t0
        best = max(best, (system.samples - 1) / wall)
    return best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--members", type=int, nargs="+", default=[20, 50, 100])
    parser.add_argument("--kind", nargs="+", default=["enekf", "cenekf"], choices=["enekf", "cenekf"])
    args = parser.parse_args()
    result = {}
    for kind in args.kind:
        for m in args.members:
            result[kind, m] = steps_per_s(kind, m)
            print(f"{kind:7s} M={m:4d}: {result[kind, m]:10.0f} steps/s  "
                  f"({result[kind, m] * m:12.0f} member-steps/s)")
    if ("enekf", 100) in result:
        print(f"steps_per_s={result['enekf', 100]:.0f}")


if __name__ == "__main__":
    main()
