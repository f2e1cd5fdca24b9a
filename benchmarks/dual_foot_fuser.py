"""Throughput of a constrained dual-foot run: both foot INS plus the fuser's epochs.

Runs ``configs/dual_foot_vicon.yaml`` (2 × 7201 samples at 60 Hz, inter-foot limit
0.6 m, constraints at stance starts) in-process, once per method to warm the compiled kernels,
then ``--repeats`` rounds of every method in turn (so that a change of the shared machine's
speed falls on all of them alike), and prints per fuser method the median navigation time (heading
alignment + fuser loop) and samples/s per stream, and for the constrained methods what the
fuser's event loop costs: their navigation time less that of ``none`` (the filters alone, with
the same heading alignment), also as a multiple of it. The shared machine's speed swings by tens
of per cent between those runs, so the loop is also timed inside one run, in CPU time: each
constraint epoch (``Fuser._constraint_epoch``) less the systems' advances within it
(``JointState.advance``), per epoch, the least and the median over the repeats (``--epochs``
other than ``events`` skip it). Last line:

    projection_samples_per_s=<per stream> qp_samples_per_s=<...> socp_samples_per_s=<...>

Usage: python benchmarks/dual_foot_fuser.py [--repeats 9] [--epochs events|interval|sample]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from bodyfusion.core import fuser
from bodyfusion.core.layout import load_layout
from bodyfusion.runner import run_layout

CONFIG = Path(__file__).resolve().parents[1] / "configs" / "dual_foot_vicon.yaml"


METHODS = ("none", "projection", "qp", "socp")


def epoch_overhead_us(loaded, repeats: int) -> tuple[float, float]:
    """CPU µs per constraint epoch spent outside the systems' advances: (least, median) over
    ``repeats`` runs of ``loaded``. Times the fuser's own methods by wrapping them for the
    duration (instrumentation of ~0.2 µs per epoch included)."""
    spent = {"epochs": 0, "advances": 0}
    epoch, advance = fuser.Fuser._constraint_epoch, fuser.JointState.advance

    def timed(method, key):
        def call(self, t):
            t0 = time.process_time_ns()
            method(self, t)
            spent[key] += time.process_time_ns() - t0
        return call

    per_epoch = []
    fuser.Fuser._constraint_epoch, fuser.JointState.advance = timed(epoch, "epochs"), timed(advance, "advances")
    try:
        for _ in range(repeats):
            spent["epochs"] = spent["advances"] = 0
            result = run_layout(loaded)
            per_epoch.append((spent["epochs"] - spent["advances"]) / result.fuser.epochs / 1e3)
    finally:
        fuser.Fuser._constraint_epoch, fuser.JointState.advance = epoch, advance
    return min(per_epoch), float(np.median(per_epoch))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=9)
    parser.add_argument("--epochs", default="events", choices=["events", "interval", "sample"])
    args = parser.parse_args()
    loaded = {m: load_layout(CONFIG, [f"fuser.method={m}", f"fuser.epochs={args.epochs}"]) for m in METHODS}
    results = {m: run_layout(layout) for m, layout in loaded.items()}  # warm-up: kernels, solvers
    times: dict[str, list[float]] = {m: [] for m in METHODS}
    navs: dict[str, list[float]] = {m: [] for m in METHODS}
    for _ in range(args.repeats):  # the methods in turn: a change of the machine's speed falls on all alike
        for m in METHODS:
            t0 = time.perf_counter()
            results[m] = run_layout(loaded[m])
            times[m].append(time.perf_counter() - t0)
            navs[m].append(results[m].timings_s["navigation_s"])
    filters = float(np.median(navs["none"]))
    summary = []
    for m in METHODS:
        nav, wall, result = float(np.median(navs[m])), float(np.median(times[m])), results[m]
        per_stream = max(s.samples for s in result.systems.values()) / nav
        loop = "" if m == "none" else (f", event loop {(nav - filters) * 1e3:.1f} ms = "
                                       f"{(nav - filters) / filters:.2f}x the filters")
        print(f"{m:<11} epochs={result.fuser.epochs:5d} activations={result.fuser.activations:4d} "
              f"navigation {nav * 1e3:7.1f} ms, run {wall * 1e3:7.1f} ms, {per_stream:,.0f} samples/s per stream{loop}")
        if m != "none":
            summary.append(f"{m}_samples_per_s={per_stream:.0f}")
    if args.epochs == "events":
        least, median = epoch_overhead_us(loaded["projection"], args.repeats)
        print(f"projection: the event loop outside the advances {least:.1f} us CPU per epoch at the least, "
              f"{median:.1f} us median")
    print(" ".join(summary))


if __name__ == "__main__":
    main()
