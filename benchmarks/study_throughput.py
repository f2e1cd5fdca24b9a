"""Study throughput: runs/s of the local process pool and of a Dask LocalCluster, 1 and 2 workers.

The study: the dual-foot + hand layout (``configs/dual_foot_hand_gnss.yaml``, a 165 s walk,
simulated afresh per seed) with GNSS outages of 0, 30, 60 and 120 s × ``--seeds`` seeds
(16 runs by default). ``--runs N`` runs the shipped GNSS-outage study instead
(``configs/gnss_outage_study.yaml``: foot + hand on a 300 s walk and dual foot + hand, outages
of 0–120 s) with as many seeds as N runs need (``--runs 1000``: 72 seeds, 1,008 runs). Each
configuration starts from an empty output folder, so its wall time includes starting the
workers (and, for Dask, the cluster); the mean wall and CPU time a worker spends per run
(simulation + run) are printed beside it — on a machine shared with other jobs, wall time
above CPU time is time the workers waited for a core. The runs of one seed share their
simulation when they share a task (``--runs-per-task``, default the study's: up to 8).

Usage: python benchmarks/study_throughput.py [--seeds 4] [--runs N] [--workers 1 2] [--executors local dask]
       [--runs-per-task K]
"""

from __future__ import annotations

import argparse
import math
import tempfile
from pathlib import Path

import pyarrow.parquet as pq
import yaml

from bodyfusion.study import run_study

CONFIGS = Path(__file__).resolve().parents[1] / "configs"


def study_text(seeds: int, runs: int | None) -> str:
    """The benchmark's study file: the default 16-run study, or the shipped study with enough seeds for ``runs``."""
    if runs is None:
        return (f"layouts:\n  dual_foot_hand: {{scenario: {CONFIGS / 'dual_foot_hand_gnss.yaml'}}}\n"
                "outages: {system: hand_phone, start_s: 30, durations_s: [0, 30, 60, 120]}\n"
                f"seeds: {seeds}\n")
    shipped = yaml.safe_load((CONFIGS / "gnss_outage_study.yaml").read_text())
    per_seed = len(shipped["layouts"]) * len(shipped["outages"]["durations_s"])
    shipped["layouts"] = {name: {"scenario": str(CONFIGS / entry["scenario"])}
                          for name, entry in shipped["layouts"].items()}
    shipped["seeds"] = math.ceil(runs / per_seed)
    return yaml.safe_dump(shipped, sort_keys=False)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=4)
    parser.add_argument("--runs", type=int, default=None, help="the shipped study with seeds for this many runs")
    parser.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--executors", nargs="+", default=["local", "dask"], choices=["local", "dask"])
    parser.add_argument("--runs-per-task", type=int, default=None)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        study = Path(tmp) / "study.yaml"
        study.write_text(study_text(args.seeds, args.runs))
        print(f"{'executor':<9}{'workers':>8}{'runs':>6}{'wall s':>9}{'runs/s':>9}{'s/run':>8}{'cpu s/run':>11}")
        for executor in args.executors:
            for workers in args.workers:
                out = Path(tmp) / f"{executor}-{workers}"
                report = run_study(study, out, executor, workers=workers, runs_per_task=args.runs_per_task)
                times = pq.read_table(out / "results.parquet", columns=["runtime.run_s", "runtime.cpu_s"])
                run_s, cpu_s = (times.column(k).to_pylist() for k in ("runtime.run_s", "runtime.cpu_s"))
                print(f"{executor:<9}{workers:>8}{report.done:>6}{report.wall_s:>9.1f}{report.runs_per_s:>9.3f}"
                      f"{sum(run_s) / len(run_s):>8.2f}{sum(cpu_s) / len(cpu_s):>11.2f}", flush=True)


if __name__ == "__main__":
    main()
