"""Long-run soak: a simulated dual-foot + hand-phone walk of many hours, simulated and run as a
user would (``fusion simulate`` then ``fusion run``), each in its own process.

The walk: three times round the 40 m × 22.5 m rectangle of ``configs/sim_dual_foot_uwb.yaml``
per ~5 min, repeated to ``--hours``; both feet ICM-20948-class IMUs at 100 Hz, a phone (PDR)
with 1 Hz GNSS that drops out for 2 min in every 10; the three maximum-separation constraints
of ``configs/dual_foot_hand_gnss.yaml``. Prints per phase the wall time and the peak resident
memory of the process (``wait4`` rusage), and from metrics.json the health block (covariances
symmetric positive semi-definite, quaternions unit) and each system's horizontal error.

Usage: python benchmarks/soak.py [--hours H] [--keep DIR]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import yaml

LAP_M = 2 * (40.0 + 22.5)
WALK_MPS = 1.4 * 108 / 120  # stride m × strides per s


def scenario(hours: float) -> dict:
    laps = max(1, math.ceil(hours * 3600 * WALK_MPS / LAP_M))
    outages = [{"start_s": 600.0 * k + 300.0, "duration_s": 120.0}
               for k in range(int(hours * 3600 // 600))]
    return {
        "name": f"soak_{hours:g}h",
        "rate_hz": 100,
        "gravity_mps2": 9.80665,
        "geodetic_origin": [49.4613, 11.1109, 390.0],
        "path": {"kind": "rectangle", "length_m": 40, "width_m": 22.5, "laps": laps, "clockwise": True,
                 "turn_radius_m": 1.0},
        "gait": {"stride_m": 1.4, "cadence_steps_per_min": 108, "stance_fraction": 0.6, "start_still_s": 3,
                 "end_still_s": 2},
        "systems": {
            "left_foot": {"kind": "foot_imu", "foot": "left", "imu": {"preset": "icm20948"}},
            "right_foot": {"kind": "foot_imu", "foot": "right", "imu": {"preset": "icm20948"}},
            "hand_phone": {"kind": "hand_phone", "imu": {"preset": "phone"}, "offset_m": [0.3, -0.2, 1.1],
                           "gnss": {"rate_hz": 1, "white_sigma_m": 1.5, "gm_sigma_m": 3.0, "gm_tau_s": 60,
                                    "outages": outages}},
        },
        "layout": {
            "systems": {"hand_phone": {"filter": {"step_scale_sd": 0.1}}},
            "constraints": [{"between": ["left_foot", "right_foot"], "kind": "max", "distance_m": 0.9},
                            {"between": ["left_foot", "hand_phone"], "kind": "max", "distance_m": 1.5},
                            {"between": ["right_foot", "hand_phone"], "kind": "max", "distance_m": 1.5}],
            "fuser": {"method": "projection", "epochs": "events", "correct": "positions",
                      "cross_covariance": True},
            "output": {"plots": False},
        },
    }


def measured(command: list[str]) -> tuple[float, float]:
    """Run ``command``; (wall s, peak RSS MB) of its process. Its output goes to our stderr."""
    start = time.perf_counter()
    proc = subprocess.Popen(command, stdout=sys.stderr)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - start
    if os.waitstatus_to_exitcode(status) != 0:
        sys.exit(f"{' '.join(command)} failed with exit code {os.waitstatus_to_exitcode(status)}")
    return wall, usage.ru_maxrss / 1024.0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--hours", type=float, default=24.0, help="walk duration, hours")
    parser.add_argument("--keep", type=Path, help="folder for the files (default: a temporary one, removed)")
    args = parser.parse_args()
    folder = args.keep or Path(tempfile.mkdtemp(prefix="soak_"))
    folder.mkdir(parents=True, exist_ok=True)
    try:
        scn = folder / "scenario.yaml"
        scn.write_text(yaml.safe_dump(scenario(args.hours), sort_keys=False))
        fusion = [sys.executable, "-m", "bodyfusion"]
        sim_s, sim_mb = measured([*fusion, "simulate", str(scn), "--out", str(folder / "data")])
        size_mb = sum(p.stat().st_size for p in (folder / "data").iterdir()) / 2**20
        run_s, run_mb = measured([*fusion, "run", str(folder / "data" / "config.yaml"), "--out", str(folder / "out")])
        doc = json.loads((folder / "out" / "metrics.json").read_text())
        samples = doc["runtime"]["samples"]
        print(f"soak {args.hours:g} h: {samples} samples, input files {size_mb:.0f} MB")
        print(f"simulate: wall {sim_s:.1f} s, peak RSS {sim_mb:.0f} MB")
        print(f"run:      wall {run_s:.1f} s, peak RSS {run_mb:.0f} MB "
              f"(navigation {doc['runtime']['navigation_s']:.1f} s, {doc['runtime']['samples_per_s']:,.0f} samples/s)")
        for name, block in doc["systems"].items():
            h, health = block.get("horizontal_error_m", {}), block.get("health", {})
            cov, nees = health.get("covariance", {}), health.get("nees", {})
            print(f"{name}: h-RMSE {h.get('rmse', float('nan')):.2f} m, h-max {h.get('max', float('nan')):.2f} m; "
                  f"covariance checks {cov.get('checks', 0)}, PSD violations {cov.get('violations', 0)}, "
                  f"min eigenvalue {cov.get('min_eigenvalue', float('nan')):.3g}; "
                  f"|q| - 1 max {health.get('quaternion_norm_max_deviation', float('nan')):.1e}; "
                  f"NEES mean {nees.get('mean', float('nan')):.2f} (in 95 % band {nees.get('in_band_fraction', 0):.0%})")
    finally:
        if args.keep is None:
            shutil.rmtree(folder, ignore_errors=True)


if __name__ == "__main__":
    main()
