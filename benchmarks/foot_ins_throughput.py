"""Throughput of the foot-mounted INS (strapdown + 15-state EKF + ZUPT) on one core.

Builds a 1-hour, 100 Hz synthetic foot IMU stream (stance/swing cycles with noise),
runs the foot plugin over it through the normal layout path, and prints

    samples_per_s=<warm> cold_s=<cold start incl. JIT>

as its last line. ``cold_s`` is measured in a fresh interpreter with an empty numba
cache (import, compile, and the whole run); a second fresh interpreter then shows the
cold start once the kernels are in numba's on-disk cache (every run after the first);
``warm`` is the best of three full passes after the kernels are compiled.

Usage: python benchmarks/foot_ins_throughput.py [--hours 1.0] [--rate 100]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml


def synthetic_stream(path: Path, hours: float, rate_hz: float, seed: int = 0) -> int:
    """Write a gait-like IMU CSV: 0.6 s stance (gravity + noise), 0.5 s swing bursts."""
    rng = np.random.default_rng(seed)
    n = int(hours * 3600 * rate_hz)
    t = np.arange(n) / rate_hz
    phase = np.mod(t, 1.1)
    swing = phase > 0.6
    s = np.where(swing, np.sin(np.pi * (phase - 0.6) / 0.5), 0.0)
    acc = np.zeros((n, 3))
    acc[:, 0] = 8.0 * s * np.cos(np.pi * (phase - 0.6) / 0.5)
    acc[:, 2] = 9.80665 + 3.0 * s
    gyro = np.zeros((n, 3))
    gyro[:, 1] = 4.0 * s * np.sin(2 * np.pi * (phase - 0.6) / 0.5)
    acc += rng.normal(0, 0.02, acc.shape)
    gyro += rng.normal(0, 0.002, gyro.shape)
    data = np.column_stack([t, acc, gyro, (~swing).astype(float)])
    np.savetxt(path, data, delimiter=",", fmt="%.6f", header="t,ax,ay,az,gx,gy,gz,stance", comments="")
    return n


def write_layout(folder: Path, csv: Path) -> Path:
    layout = {
        "name": "throughput",
        "gravity_mps2": 9.80665,
        "systems": {"foot": {
            "plugin": "foot_ins",
            "data": {"path": str(csv), "time_column": "t", "acc_columns": ["ax", "ay", "az"],
                     "gyro_columns": ["gx", "gy", "gz"], "stance_column": "stance"},
            "detector": {"kind": "labels"},
        }},
        "output": {"plots": False},
    }
    path = folder / "layout.yaml"
    path.write_text(yaml.safe_dump(layout))
    return path


def run_once(layout: Path) -> tuple[float, int]:
    """Seconds for one full pass of the foot system over its stream, and the sample count."""
    from bodyfusion.core.layout import load_layout
    from bodyfusion.runner import build_systems, layout_context

    loaded = load_layout(layout)
    system = build_systems(loaded, layout_context(loaded))["foot"]
    best = np.inf
    for _ in range(3):
        system.restart()
        t0 = time.perf_counter()
        system.advance(system.t_end)
        best = min(best, time.perf_counter() - t0)
    return best, system.samples


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--hours", type=float, default=1.0)
    parser.add_argument("--rate", type=float, default=100.0)
    parser.add_argument("--layout", type=Path, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.layout is not None:  # child process: one cold run
        t0 = time.perf_counter()
        from bodyfusion.core.layout import load_layout
        from bodyfusion.runner import build_systems, layout_context

        loaded = load_layout(args.layout)
        t1 = time.perf_counter()
        system = build_systems(loaded, layout_context(loaded))["foot"]
        t2 = time.perf_counter()
        system.advance(system.t_end)
        t3 = time.perf_counter()
        print(f"import+config {t1 - t0:.2f} s, read CSV {t2 - t1:.2f} s, compile+run {t3 - t2:.2f} s")
        print(t3 - t0)
        return
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        csv = folder / "foot.csv"
        synthetic_stream(csv, args.hours, args.rate)
        layout = write_layout(folder, csv)
        env = dict(os.environ, NUMBA_CACHE_DIR=str(folder / "numba_cache"))
        cold = []
        for _ in range(2):  # first: empty numba cache (compiles); second: kernels loaded from the cache
            child = subprocess.run([sys.executable, __file__, "--layout", str(layout)], env=env,
                                   capture_output=True, text=True, check=True)
            split, inner = child.stdout.strip().splitlines()[-2:]
            cold.append((float(inner), split))
        warm_s, samples = run_once(layout)
        print(f"stream: {samples} samples ({args.hours} h at {args.rate} Hz)")
        print(f"warm pass: {warm_s:.3f} s")
        print(f"cold process, empty JIT cache: {cold[0][0]:.2f} s ({cold[0][1]})")
        print(f"cold process, JIT cache filled: {cold[1][0]:.2f} s ({cold[1][1]})")
        print(f"samples_per_s={samples / warm_s:.0f} cold_s={cold[0][0]:.2f}")


if __name__ == "__main__":
    main()
