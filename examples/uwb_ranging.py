"""UWB ranging on foot-mounted INS, over several simulation seeds.

1. Anchors (``configs/foot_uwb_sim.yaml``): one foot INS with a tag ranging to four
   anchors (LOS σ 0.1 m, 10 % NLOS bursts, 2 % failed rangings). Per seed: the foot's
   horizontal RMSE with and without the tag, and how the innovation gate treated the
   ranges against the simulator's truth NLOS flags (NLOS rejected / NLOS accepted /
   LOS rejected / LOS accepted).
2. Foot to foot (``configs/sim_dual_foot_uwb.yaml``): both feet, tags ranging to each
   other (σ 0.05 m). Horizontal RMSE of both feet with the feet independent, the 0.9 m
   inequality alone, the ranges alone (cross-covariances tracked, and dropped), and
   ranges + inequality; the error of the left − right vector; the mean NEES.

Usage: python examples/uwb_ranging.py [--seeds 5] [--out out/uwb_ranging]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import yaml
from rich.console import Console
from rich.table import Table

from bodyfusion.core.layout import load_layout
from bodyfusion.runner import run_layout
from bodyfusion.sim import simulate

CONFIGS = Path(__file__).resolve().parents[1] / "configs"
DUAL_CASES = {
    "feet independent": (False, ["fuser.method=none"]),
    "inequality 0.9 m alone": (False, []),
    "ranges alone": (True, ["fuser.method=none"]),
    "ranges alone, cross-covariances dropped": (True, ["fuser.method=none", "fuser.cross_covariance=false"]),
    "ranges + inequality": (True, []),
}
"""case → (keep the tag, overrides of the simulated layout)."""


def variant(config: Path, keep_tag: bool, tag: str) -> Path:
    """The simulated layout, or a copy of it without the tag."""
    if keep_tag:
        return config
    raw = yaml.safe_load(config.read_text())
    del raw["systems"][tag]
    out = config.with_name("config_without_tag.yaml")
    out.write_text(yaml.safe_dump(raw, sort_keys=False))
    return out


def rmse(result, name: str) -> float:
    return float(result.scores[name].metrics["horizontal_error_m"]["rmse"])


def nees(result, name: str) -> float:
    """Mean over the truth epochs of e_E²/σ_E² + e_N²/σ_N² (the filter's per-axis σ; a
    consistent filter averages about 2, an overconfident one far more)."""
    score, traj = result.scores[name], result.trajectories[name]
    sd = np.column_stack([np.interp(score.t, traj.t, traj.pos_sd[:, k]) for k in range(2)])
    err = (score.pos_est_aligned - score.pos_truth)[:, :2]
    return float(np.mean(np.sum((err / sd) ** 2, axis=1)))


def relative_rmse(result, a: str, b: str) -> float:
    """Horizontal RMSE (m) of the estimated a − b vector against the true one (same truth epochs)."""
    sa, sb = result.scores[a], result.scores[b]
    err = (sa.pos_est_aligned - sb.pos_est_aligned) - (sa.pos_truth - sb.pos_truth)
    return float(np.sqrt(np.mean(np.sum(err[:, :2] ** 2, axis=1))))


def anchors(seeds: int, out: Path, console: Console) -> None:
    table = Table(title="foot INS + UWB tag to 4 anchors (foot_uwb_sim), horizontal RMSE (m)")
    for col in ("seed", "INS alone", "INS + UWB", "NLOS rejected", "NLOS accepted", "LOS rejected", "LOS accepted"):
        table.add_column(col, justify="right")
    totals = np.zeros(4, dtype=int)
    with_tag = []
    for seed in range(seeds):
        config = simulate(CONFIGS / "foot_uwb_sim.yaml", out / f"foot_uwb_{seed}", seed=seed,
                          overwrite=True).config_path
        alone = run_layout(load_layout(variant(config, False, "left_tag")), seed=seed)
        fused = run_layout(load_layout(config), seed=seed)
        gate = fused.aiding["left_tag"].diagnostics()["gate_vs_truth"]
        counts = [gate[k] for k in ("nlos_rejected", "nlos_accepted", "los_rejected", "los_accepted")]
        totals += counts
        with_tag.append(rmse(fused, "left_foot"))
        table.add_row(str(seed), f"{rmse(alone, 'left_foot'):.3f}", f"{with_tag[-1]:.3f}", *map(str, counts))
    table.add_row("all", "", f"max {max(with_tag):.3f}", *map(str, totals))
    console.print(table)


def feet(seeds: int, out: Path, console: Console) -> None:
    table = Table(title="both feet, foot-to-foot UWB σ 0.05 m (sim_dual_foot_uwb), horizontal RMSE (m), mean over "
                        f"{seeds} seeds [min–max]")
    for col in ("case", "left foot", "right foot", "left − right vector", "NEES (both feet)",
                "ranges accepted / rejected"):
        table.add_column(col, justify="right")
    results: dict[str, list] = {case: [] for case in DUAL_CASES}
    for seed in range(seeds):
        config = simulate(CONFIGS / "sim_dual_foot_uwb.yaml", out / f"dual_foot_uwb_{seed}", seed=seed,
                          overwrite=True).config_path
        for case, (keep, overrides) in DUAL_CASES.items():
            res = run_layout(load_layout(variant(config, keep, "feet_tags"), overrides), seed=seed)
            diag = res.aiding["feet_tags"].diagnostics()["peer_ranges"] if keep else None
            results[case].append((rmse(res, "left_foot"), rmse(res, "right_foot"),
                                  relative_rmse(res, "left_foot", "right_foot"),
                                  0.5 * (nees(res, "left_foot") + nees(res, "right_foot")), diag))
    for case, rows in results.items():
        cells = []
        for col in range(3):
            v = np.array([r[col] for r in rows])
            cells.append(f"{v.mean():.3f} [{v.min():.3f}–{v.max():.3f}]")
        cells.append(f"{np.mean([r[3] for r in rows]):.3g}")
        gate = "" if rows[0][4] is None else (f"{sum(r[4]['accepted'] for r in rows)} / "
                                               f"{sum(r[4]['rejected_by_gate'] for r in rows)}")
        table.add_row(case, *cells, gate)
    console.print(table)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--out", type=Path, default=Path("out/uwb_ranging"))
    args = parser.parse_args()
    console = Console()
    anchors(args.seeds, args.out, console)
    feet(args.seeds, args.out, console)


if __name__ == "__main__":
    main()
