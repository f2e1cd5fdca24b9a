"""Study throughput: runs/s of the local process pool and of a Dask LocalCluster, 1 and 2 workers.

The study: the dual-foot + hand layout (``configs/dual_foot_hand_gnss.yaml``, a 165 s walk,
simulated afresh per run) with GNSS outages of 0, 30, 60 and 120 s × ``--seeds`` seeds
(16 runs by default). Each configuration starts from an empty output folder, so its wall
time includes starting the workers (and, for Dask, the cluster); the mean wall and CPU
time a worker spends per run (simulation + run) are printed beside it — on a machine
shared with other jobs, wall time above CPU time is time the workers waited for a core.

Usage: python benchmarks/study_throughput.py [--seeds 4] [--workers 1 2] [--executors local dask]
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import pyarrow.parquet as pq

from bodyfusion.study import run_study

CONFIGS = Path(__file__).resolve().parents[1] / "configs"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=4)
    parser.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--executors", nargs="+", default=["local", "dask"], choices=["local", "dask"])
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        study = Path(tmp) / "study.yaml"
        study.write_text(f"layouts:\n  dual_foot_hand: {{scenario: {CONFIGS / 'dual_foot_hand_gnss.yaml'}}}\n"
                         "outages: {system: hand_phone, start_s: 30, durations_s: [0, 30, 60, 120]}\n"
                         f"seeds: {args.seeds}\n")
        print(f"{'executor':<9}{'workers':>8}{'runs':>6}{'wall s':>9}{'runs/s':>9}{'s/run':>8}{'cpu s/run':>11}")
        for executor in args.executors:
            for workers in args.workers:
                out = Path(tmp) / f"{executor}-{workers}"
                report = run_study(study, out, executor, workers=workers)
                times = pq.read_table(out / "results.parquet", columns=["runtime.run_s", "runtime.cpu_s"])
                run_s, cpu_s = (times.column(k).to_pylist() for k in ("runtime.run_s", "runtime.cpu_s"))
                print(f"{executor:<9}{workers:>8}{report.done:>6}{report.wall_s:>9.1f}{report.runs_per_s:>9.3f}"
                      f"{sum(run_s) / len(run_s):>8.2f}{sum(cpu_s) / len(cpu_s):>11.2f}")


if __name__ == "__main__":
    main()
