"""Throughput of a constrained dual-foot run: both foot INS plus the fuser's epochs.

Runs ``configs/dual_foot_vicon.yaml`` (2 × 7201 samples at 60 Hz, inter-foot limit
0.6 m, constraints at stance starts) in-process, once to warm the compiled kernels, then
``--repeats`` times, and prints per fuser method the median navigation time (heading
alignment + fuser loop) and samples/s per stream, and for the constrained methods what the
fuser's event loop costs: their navigation time less that of ``none`` (the filters alone, with
the same heading alignment), also as a multiple of it. Last line:

    projection_samples_per_s=<per stream> qp_samples_per_s=<...> socp_samples_per_s=<...>

Usage: python benchmarks/dual_foot_fuser.py [--repeats 9] [--epochs events|interval|sample]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from bodyfusion.core.layout import load_layout
from bodyfusion.core.run import run_layout

CONFIG = Path(__file__).resolve().parents[1] / "configs" / "dual_foot_vicon.yaml"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=9)
    parser.add_argument("--epochs", default="events", choices=["events", "interval", "sample"])
    args = parser.parse_args()
    summary = []
    for method in ("none", "projection", "qp", "socp"):
        loaded = load_layout(CONFIG, [f"fuser.method={method}", f"fuser.epochs={args.epochs}"])
        run_layout(loaded)  # warm-up: kernels compiled or loaded from the cache, solver set up
        times, navs = [], []
        for _ in range(args.repeats):
            t0 = time.perf_counter()
            result = run_layout(loaded)
            times.append(time.perf_counter() - t0)
            navs.append(result.timings_s["navigation_s"])
        nav = float(np.median(navs))
        wall = float(np.median(times))
        per_stream = max(s.samples for s in result.systems.values()) / nav
        loop = "" if method == "none" else (f", event loop {(nav - filters) * 1e3:.1f} ms = "
                                            f"{(nav - filters) / filters:.2f}x the filters")
        print(f"{method:<11} epochs={result.fuser.epochs:5d} activations={result.fuser.activations:4d} "
              f"navigation {nav * 1e3:7.1f} ms, run {wall * 1e3:7.1f} ms, {per_stream:,.0f} samples/s per stream{loop}")
        if method == "none":
            filters = nav
        else:
            summary.append(f"{method}_samples_per_s={per_stream:.0f}")
    print(" ".join(summary))


if __name__ == "__main__":
    main()
