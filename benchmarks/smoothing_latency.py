"""Per-segment latency of the FB-RTS smoother on the FB-RTS paper's simulation.

Simulates ``configs/fbrts_paper_sim.yaml`` (one seed) in a temporary directory with
:func:`bodyfusion.sim.simulate`, runs the forward filter once (``smoother.kind=none``), then
:func:`bodyfusion.plugins.foot_ins.smoothing.smooth_record` with ``kind=fb-rts`` on its record and prints the
per-segment compute time (the filter's replay, the backward pass, both RTS sweeps, the
fusion and the position of one segment: the latency after the segment's last sample). The
first segment is left out of the statistics: it includes numba's compilation (or cache load)
of the kernels.

Run: python benchmarks/smoothing_latency.py [--seed 0]
Last line: ``fbrts_segment_ms=<median> segments=<n>`` (n: the segments counted).
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np

from bodyfusion.core.layout import SmootherConfig, load_layout
from bodyfusion.runner import run_layout
from bodyfusion.sim import simulate
from bodyfusion.plugins.foot_ins.smoothing import smooth_record

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        sim = simulate(ROOT / "configs" / "fbrts_paper_sim.yaml", Path(tmp) / "sim", seed=args.seed)
        result = run_layout(load_layout(sim.config_path, ["smoother.kind=none"]))
        rec = result.systems["foot"].smoothing_record()
    res = smooth_record(rec, SmootherConfig(kind="fb-rts"))
    ms = res.segment_latency_ms
    if res.x is None or ms is None or ms.size < 2:
        raise SystemExit(f"fb-rts did not run: {res.diagnostics.get('warning_messages')}")
    first, rest = ms[0], ms[1:]
    print(f"fb-rts on the paper simulation (seed {args.seed}): {ms.size} segments, "
          f"{rec['t'].size} samples at {rec['rate_hz']:.0f} Hz")
    print(f"first segment (includes numba compilation / cache load, excluded): {first:.1f} ms")
    print(f"per-segment latency over the other {rest.size}: median {np.median(rest):.2f} ms, "
          f"p95 {np.percentile(rest, 95):.2f} ms, max {rest.max():.2f} ms")
    print(f"fbrts_segment_ms={np.median(rest):.3f} segments={rest.size}")


if __name__ == "__main__":
    main()
