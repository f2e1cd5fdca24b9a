"""The project's foot INS against a peer on one stream: gaitmap's RtsKalman (forward + RTS).

One simulated 100 Hz foot IMU stream (:func:`bodyfusion.sim.simulate`: a left foot with an
ICM-20948-class IMU walking ``--laps`` times round a 40 m × 22.5 m rectangle, about 99 s per
lap) goes, in this one process, through

* the project's foot INS at its defaults (15-state error-state EKF with gated ZUPTs): the
  forward filter (``restart`` + ``advance`` over the whole stream), forward + RTS
  (``smoother.kind=rts``, the whole-run fixed-interval smoother) and forward + FB-RTS, each
  run as a layout with that smoother runs it (``FootIns.plan_smoothing`` first: with RTS the
  filter records what the smoother's sweep needs as it runs); forward + FB (the two passes and
  their fusion without the RTS sweeps) is the floor under FB-RTS's cost: FB-RTS is FB plus two
  RTS sweeps;
* gaitmap's ``RtsKalman().estimate`` at its defaults (9-state error-state filter, its own ZUPT
  detector, forward pass and RTS), when gaitmap is installed (``pip install -e ".[bench]"``;
  gaitmap 2.6 pins numpy < 2.1 and pandas < 2.4, so give it its own virtual environment),
  fed the same samples: specific force in m/s² and angular rate in deg/s in the sensor frame
  (z up at rest, as gaitmap's gravity vector), as the DataFrame of ``acc_x`` … ``gyr_z`` it
  takes. Its numba core alone (``rts_kalman_update_series``, without the detector and the
  DataFrames) is timed too.

The project's stance detection and initial alignment run once when the system is built and
are not timed. Every job runs once untimed (JIT compilation, caches), then ``--repeats``
rounds run every job once each, in turn, so that a change of the shared machine's load in
the meantime falls on all of them alike; a job's figure is its median CPU time of this
process (``time.process_time``: the machine is shared, and all the jobs are single-threaded),
each call timed as ``timeit`` times one: Python's garbage collector run before it and off
during it (a collection the objects of one job call for would otherwise fall in another's). Printed: samples/s of each job, the
distance each estimate walked against the truth's (a check that both did the work), and as
the last line the ratio of the project's forward + RTS to gaitmap's RtsKalman,
``rts_vs_gaitmap=<ratio> fbrts_vs_gaitmap=<ratio> fb_vs_gaitmap=<ratio>`` (the project's forward +
RTS, forward + FB-RTS and forward + FB to gaitmap's RtsKalman; ``n/a`` when gaitmap is not
installed).

With ``--cold`` the first call is timed too, each side in a fresh process on an empty numba
cache (``NUMBA_CACHE_DIR`` a new folder), so that it compiles everything it runs: the project
builds the system from the simulated files (reading, stance detection, alignment) and runs
forward + RTS; gaitmap runs ``RtsKalman().estimate`` on the same samples (the DataFrame built
before). Printed: each side's CPU and wall seconds of that first call, and their ratio
gaitmap / project.

Run: python benchmarks/peers.py [--laps 4] [--repeats 7] [--seed 0] [--cold]
"""

from __future__ import annotations

import argparse
import gc
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import yaml

from bodyfusion.core.layout import SmootherConfig, load_layout
from bodyfusion.runner import build_systems, layout_context
from bodyfusion.plugins.foot_ins.smoothing import smooth_system
from bodyfusion.plugins.foot_ins.system import FootIns
from bodyfusion.sim import simulate

RATE_HZ = 100


def scenario(laps: int) -> dict:
    """One foot round the rectangle ``laps`` times, 100 Hz, ICM-20948-class errors."""
    return {
        "name": "peers",
        "rate_hz": RATE_HZ,
        "path": {"kind": "rectangle", "length_m": 40, "width_m": 22.5, "laps": laps, "clockwise": True,
                 "turn_radius_m": 1.0},
        "gait": {"start_still_s": 3, "end_still_s": 2},
        "systems": {"foot": {"kind": "foot_imu", "foot": "left", "imu": {"preset": "icm20948"}}},
        "layout": {"output": {"plots": False}},
    }


def cpu_seconds(jobs: dict[str, Callable[[], object]], repeats: int) -> dict[str, float]:
    """Median CPU seconds of each job over ``repeats`` rounds that call every job once, in
    turn (the garbage collector run before each call and off during it), after one untimed
    call of each."""
    for job in jobs.values():
        job()
    times: dict[str, list[float]] = {name: [] for name in jobs}
    for _ in range(repeats):
        for name, job in jobs.items():
            gc.collect()
            gc.disable()
            t0 = time.process_time()
            job()
            times[name].append(time.process_time() - t0)
            gc.enable()
    return {name: statistics.median(t) for name, t in times.items()}


def walked_m(pos: np.ndarray) -> float:
    """Horizontal distance along a track (m): independent of its frame and heading."""
    return float(np.sum(np.hypot(*np.diff(pos[:, 0:2], axis=0).T)))


def project_jobs(foot: FootIns) -> dict[str, Callable[[], np.ndarray]]:
    """The project's jobs on ``foot``; each returns the positions it estimated (n, 3)."""

    def run(cfg: SmootherConfig) -> np.ndarray:
        foot.plan_smoothing(cfg)  # as a run of a layout with this smoother
        foot.restart()
        foot.advance(foot.t_end)
        return foot.hist_x[:, 0:3]

    def forward() -> np.ndarray:
        return run(SmootherConfig(kind="none"))

    def smoothed(kind: str) -> Callable[[], np.ndarray]:
        def job() -> np.ndarray:
            cfg = SmootherConfig(kind=kind)
            run(cfg)
            smooth_system(foot, cfg)
            return foot.trajectory().pos_n

        return job

    return {"forward": forward, "forward+rts": smoothed("rts"), "forward+fb": smoothed("fb"),
            "forward+fb-rts": smoothed("fb-rts")}


def gaitmap_jobs(foot: FootIns) -> dict[str, Callable[[], np.ndarray]]:
    """gaitmap's RtsKalman at its defaults on the same samples, and its numba core alone;
    empty when gaitmap is not installed."""
    try:
        import pandas as pd
        from gaitmap.trajectory_reconstruction import RtsKalman
        from gaitmap.trajectory_reconstruction.trajectory_methods._kalman_numba_funcs import (
            SimpleZuptParameter, rts_kalman_update_series)
    except ImportError:
        return {}
    acc, gyro_dps = foot.stream.acc_b, np.rad2deg(foot.stream.gyro_b)
    frame = pd.DataFrame(np.column_stack([acc, gyro_dps]),
                         columns=["acc_x", "acc_y", "acc_z", "gyr_x", "gyr_y", "gyr_z"])

    def estimate() -> np.ndarray:
        return RtsKalman().estimate(frame, sampling_rate_hz=float(RATE_HZ)).position_.to_numpy()

    kalman = RtsKalman().estimate(frame, sampling_rate_hz=float(RATE_HZ))
    zupts = kalman.zupt_detector.clone().detect(frame, sampling_rate_hz=float(RATE_HZ)).per_sample_zupts_
    forward_pass = kalman._forward_pass  # the estimate's own arguments, built as estimate() builds them
    process_noise = np.zeros((9, 9))
    process_noise[3:6, 3:6] = kalman.velocity_error_variance * np.eye(3)
    process_noise[6:, 6:] = kalman.orientation_error_variance * np.eye(3)
    meas_noise = np.zeros((4, 4))
    meas_noise[0:3, 0:3] = np.eye(3) * kalman.zupt_variance
    meas_noise[3, 3] = kalman.level_walking_variance
    gyro_rad = np.deg2rad(gyro_dps)
    params = SimpleZuptParameter(level_walking=kalman.level_walking)

    def core() -> np.ndarray:
        states, _ = rts_kalman_update_series(acc, gyro_rad, None, np.array([0, 0, 0, 1.0]), float(RATE_HZ),
                                             meas_noise, process_noise, zupts, parameters=params,
                                             forward_pass_func=forward_pass,
                                             forward_pass_dependencies=kalman._prepare_forward_pass_dependencies())
        return states[0]

    return {"gaitmap RtsKalman.estimate": estimate, "gaitmap core (no detector, no DataFrames)": core}


def cold_child(side: str, config: Path, samples: Path) -> None:
    """In this fresh process (empty numba cache): the first call of one side, printed as JSON
    (CPU and wall seconds of the call)."""
    if side == "gaitmap":
        import pandas as pd
        from gaitmap.trajectory_reconstruction import RtsKalman
        data = np.load(samples)
        frame = pd.DataFrame(np.column_stack([data["acc"], data["gyro_dps"]]),
                             columns=["acc_x", "acc_y", "acc_z", "gyr_x", "gyr_y", "gyr_z"])
        c0, w0 = time.process_time(), time.perf_counter()
        RtsKalman().estimate(frame, sampling_rate_hz=float(RATE_HZ))
    else:
        loaded = load_layout(config)
        c0, w0 = time.process_time(), time.perf_counter()
        cfg = SmootherConfig(kind="rts")
        foot = build_systems(loaded, layout_context(loaded))["foot"]
        foot.plan_smoothing(cfg)
        foot.restart()
        foot.advance(foot.t_end)
        smooth_system(foot, cfg)
    print(json.dumps({"cpu_s": time.process_time() - c0, "wall_s": time.perf_counter() - w0}))


def cold_first_calls(config: Path, foot: FootIns, folder: Path) -> None:
    """Each side's first call in a fresh process on an empty numba cache (:func:`cold_child`)."""
    samples = folder / "samples.npz"
    np.savez(samples, acc=foot.stream.acc_b, gyro_dps=np.rad2deg(foot.stream.gyro_b))
    result = {}
    for side in ("project", "gaitmap"):
        with tempfile.TemporaryDirectory() as cache:
            proc = subprocess.run([sys.executable, __file__, "--cold-child", side, str(config), str(samples)],
                                  env=dict(os.environ, NUMBA_CACHE_DIR=cache), capture_output=True, text=True,
                                  check=False)
        if proc.returncode != 0:
            print(f"cold {side}: failed ({proc.stderr.strip().splitlines()[-1] if proc.stderr.strip() else ''})")
            continue
        result[side] = json.loads(proc.stdout.strip().splitlines()[-1])
        r = result[side]
        what = "build + forward + RTS" if side == "project" else "RtsKalman().estimate"
        print(f"cold {side} ({what}, fresh process, empty numba cache): first call {r['cpu_s']:.2f} CPU-s "
              f"({r['wall_s']:.2f} s wall)")
    if len(result) == 2:
        print(f"cold first call gaitmap / project: {result['gaitmap']['cpu_s'] / result['project']['cpu_s']:.2f}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--laps", type=int, default=4, help="laps of the 125 m rectangle (about 99 s each)")
    ap.add_argument("--repeats", type=int, default=7, help="timed calls per job (median)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--cold", action="store_true", help="also time each side's first call in a fresh process")
    ap.add_argument("--cold-child", nargs=3, metavar=("SIDE", "CONFIG", "SAMPLES"), help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.cold_child:
        cold_child(args.cold_child[0], Path(args.cold_child[1]), Path(args.cold_child[2]))
        return
    with tempfile.TemporaryDirectory() as tmp:
        scn = Path(tmp) / "peers.yaml"
        scn.write_text(yaml.safe_dump(scenario(args.laps)))
        sim = simulate(scn, Path(tmp) / "sim", seed=args.seed)
        loaded = load_layout(sim.config_path)
        foot = build_systems(loaded, layout_context(loaded))["foot"]
        if args.cold:
            cold_first_calls(sim.config_path, foot, Path(tmp))
    n = foot.samples
    jobs = {**project_jobs(foot), **gaitmap_jobs(foot)}
    print(f"stream: {n} samples at {RATE_HZ} Hz ({n / RATE_HZ / 60:.1f} min), stance fraction "
          f"{foot.stance.mean():.2f}; CPU time, median of {args.repeats} warm calls")
    print(f"truth walked {sim.distance_m:.1f} m")
    rate = {}
    for name, seconds in cpu_seconds(jobs, args.repeats).items():
        rate[name] = n / seconds
        print(f"{name}: {rate[name]:,.0f} samples/s ({seconds * 1e3:.1f} ms), walked {walked_m(jobs[name]()):.1f} m")
    if "gaitmap RtsKalman.estimate" not in rate:
        print('gaitmap not installed (pip install -e ".[bench]" in its own environment): peer skipped')
        print("rts_vs_gaitmap=n/a fbrts_vs_gaitmap=n/a fb_vs_gaitmap=n/a")
        return
    core = rate["forward+rts"] / rate["gaitmap core (no detector, no DataFrames)"]
    print(f"project forward+rts / gaitmap core: {core:.2f}")
    peer = rate["gaitmap RtsKalman.estimate"]
    print(f"rts_vs_gaitmap={rate['forward+rts'] / peer:.2f} fbrts_vs_gaitmap={rate['forward+fb-rts'] / peer:.2f} "
          f"fb_vs_gaitmap={rate['forward+fb'] / peer:.2f}")


if __name__ == "__main__":
    main()
