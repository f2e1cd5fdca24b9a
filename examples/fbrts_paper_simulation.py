"""The FB-RTS paper's simulation (Shen et al. 2025, §4.2, Table 2): ZUPT, RTS, FB and FB-RTS.

Simulates ``configs/fbrts_paper_sim.yaml`` (783.36 m square walk, ICM-20948 errors plus a
10 mg accelerometer bias, 125 Hz) for a few seeds, runs the forward filter once per seed
and each smoother on its record, and prints the horizontal mean, RMSE and maximum
position error (truth at every IMU sample, no alignment) beside the paper's Table 2,
plus the smoothers' per-segment latency.

Run: python examples/fbrts_paper_simulation.py [--seeds 3] [--out out/fbrts_paper_sim]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from bodyfusion.core.layout import SmootherConfig, load_layout
from bodyfusion.core.run import run_layout
from bodyfusion.sim import simulate
from bodyfusion.plugins.foot_ins.smoothing import smooth_record

ROOT = Path(__file__).resolve().parents[1]
PAPER = {"ZUPT": (1.07, 1.32, 2.94), "RTS": (0.596, 0.723, 1.64), "FB": (0.426, 0.520, 1.23),
         "FB-RTS": (0.362, 0.460, 1.19)}
KINDS = {"ZUPT": "none", "RTS": "rts", "FB": "fb", "FB-RTS": "fb-rts"}


def run_seed(seed: int, out: Path) -> dict[str, tuple[float, float, float]]:
    sim = simulate(ROOT / "configs" / "fbrts_paper_sim.yaml", out / f"seed{seed}", seed=seed)
    result = run_layout(load_layout(sim.config_path, ["smoother.kind=none"]))
    system = result.systems["foot"]
    truth = result.truths["foot"]
    rec = system.smoothing_record()
    pos_true = np.column_stack([np.interp(rec["t"], truth.t, truth.pos_n[:, k]) for k in range(2)])
    rows, latency = {}, None
    for label, kind in KINDS.items():
        if kind == "none":
            x = rec["hist_x"]
        else:
            res = smooth_record(rec, SmootherConfig(kind=kind))
            x = res.x if res.x is not None else rec["hist_x"]
            if kind == "fb-rts":
                latency = res.diagnostics.get("latency_ms")
        err = np.hypot(*(x[:, 0:2] - pos_true).T)
        rows[label] = (float(err.mean()), float(np.sqrt(np.mean(err**2))), float(err.max()))
    rows["_latency"] = latency
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--out", type=Path, default=Path("out/fbrts_paper_sim"))
    args = ap.parse_args()
    per_seed = []
    for seed in range(args.seeds):
        rows = run_seed(seed, args.out)
        per_seed.append(rows)
        print(f"seed {seed}: " + ", ".join(f"{k} {rows[k][1]:.3f}" for k in KINDS) + " m RMSE"
              + (f"; FB-RTS latency {rows['_latency']['mean_ms']:.1f} ms/segment" if rows["_latency"] else ""))
    print(f"\nHorizontal error over {args.seeds} seed(s) (mean of the per-seed figures), m; paper Table 2 in brackets")
    print(f"{'algorithm':<8} {'mean':>15} {'RMSE':>15} {'max':>15}")
    for label in KINDS:
        m = np.mean([r[label] for r in per_seed], axis=0)
        p = PAPER[label]
        print(f"{label:<8} " + " ".join(f"{m[k]:7.3f} ({p[k]:5.3f})" for k in range(3)))
    lat = [r["_latency"]["mean_ms"] for r in per_seed if r["_latency"]]
    if lat:
        print(f"\nFB-RTS per-segment latency: mean {np.mean(lat):.1f} ms (paper: 13.7 ms)")


if __name__ == "__main__":
    main()
