"""Filter consistency after distance constraints: drop the cross-covariances, or track them?

The papers drop the cross-covariances a constraint creates between two systems. This
script measures what that costs on the PDR/GNSS paper's Monte-Carlo model
(``configs/paper_constraint_monte_carlo.yaml``: two random-walk dead-reckoning systems
within 1.5 m, truth known exactly), with the horizontal-position NEES — a consistent
filter averages 2 — and the RMSE, over many seeds:

* independent systems (no constraint),
* constrained, cross-covariances dropped (``fuser.cross_covariance: false``, the papers),
* constrained, cross-covariances tracked (``fuser.cross_covariance: true``).

Usage: python examples/cross_covariance_nees.py [--runs 30] [--duration 100]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

from bodyfusion.core.layout import load_layout
from bodyfusion.runner import run_layout

CONFIG = Path(__file__).resolve().parents[1] / "configs" / "paper_constraint_monte_carlo.yaml"
CASES = {
    "independent": ["fuser.method=none"],
    "constrained, cross-cov dropped": ["fuser.method=projection", "fuser.cross_covariance=false"],
    "constrained, cross-cov tracked": ["fuser.method=projection", "fuser.cross_covariance=true"],
}


def consistency(overrides: list[str], runs: int, duration: float) -> tuple[float, float]:
    """Mean horizontal NEES over the second half of every run, and the final horizontal RMSE (m)."""
    nees, sq = [], []
    for seed in range(runs):
        ov = [*overrides, f"systems.system_1.duration_s={duration}", f"systems.system_2.duration_s={duration}"]
        result = run_layout(load_layout(CONFIG, ov), seed=seed)
        for system in result.systems.values():
            n = system.horizontal_nees()
            nees.append(n[len(n) // 2:])
            sq.append(np.sum((system.hist_pos[-1] - system.truth_pos_n[-1])[:2] ** 2))
    return float(np.nanmean(np.concatenate(nees))), float(np.sqrt(np.mean(sq)))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=30)
    parser.add_argument("--duration", type=float, default=100.0)
    args = parser.parse_args()
    table = Table(title=f"Two random-walk systems within 1.5 m: {args.runs} runs × {args.duration:.0f} s")
    for col in ("case", "mean NEES (2 = consistent)", "final RMSE (m)"):
        table.add_column(col, justify="right")
    for name, overrides in CASES.items():
        nees, rmse = consistency(overrides, args.runs, args.duration)
        table.add_row(name, f"{nees:.2f}", f"{rmse:.2f}")
    Console().print(table)


if __name__ == "__main__":
    main()
