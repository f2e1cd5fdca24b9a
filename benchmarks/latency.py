"""Latency and speed of a live run (:mod:`bodyfusion.live`): a layout's recordings replayed.

``--layout vicon`` (default): the vendored dual-foot Vicon walk (both feet, 60 Hz, 120 s, the
body's maximum-separation constraint with projection, heading ties). ``--layout hand``: the
simulated walk of ``configs/dual_foot_hand_gnss.yaml`` (both feet and a hand-held phone with GNSS,
100 Hz, 166 s, three maximum-separation constraints with the cross-covariances), simulated into a
temporary folder first. Each is replayed through :class:`~bodyfusion.live.engine.LiveRun` with
its defaults (look-ahead 2 s, a pass every 0.5 s of data, a state every 0.1 s):

* at ×max (rows pushed as fast as the run takes them, a pass every 30 s of data as ``fusion live
  --speed max`` makes them): the replay speed as a ratio to real time, start and close included,
  and the speed it sustains once started (the data after the start's over the wall time after
  the start's pass, which builds the run; every pass is done before the next is due, by
  construction);
* at ×``--speed`` (default 1, real time; ``--seconds`` of the walk, default all of it): the
  latency of every pass, from the arrival of the row that made it due to its last state emitted
  (p50, p99, max), and whether any pass took longer than the data it covers (a backlog).

``--set KEY=VALUE`` overrides the layout (``--set smoother.kind=fixed-lag``: the live fixed-lag
smoother's stream beside the filtered one; its smoothed states are counted too).

Last line: ``p99_ms=… max_ms=… max_speedup=… sustained_speedup=…`` (p99 and max at the paced speed).

Run: python benchmarks/latency.py [--layout vicon|hand] [--speed 1] [--seconds 120] [--set KEY=VALUE]...
"""

from __future__ import annotations

import argparse
import itertools
import tempfile
import time
from pathlib import Path

import numpy as np

from bodyfusion.core.layout import load_layout
from bodyfusion.live.engine import REPLAN_BATCH_S, REPLAN_S, LiveRun
from bodyfusion.live.sources import replay, replay_rows
from bodyfusion.sim.scenario import simulate

CONFIGS = Path(__file__).resolve().parents[1] / "configs"


def layout(name: str, folder: Path) -> Path:
    """The layout file of ``--layout name``: the vendored Vicon walk, or the dual-foot + hand walk
    simulated into ``folder``."""
    if name == "vicon":
        return CONFIGS / "dual_foot_vicon.yaml"
    simulate(CONFIGS / "dual_foot_hand_gnss.yaml", folder)
    return folder / "config.yaml"


def live_replay(config: Path, speed: float | None, seconds: float | None,
                overrides: list[str] = ()) -> tuple[LiveRun, float, float, float]:
    """Replay ``seconds`` of the walk (None: all) at ``speed`` (None: ×max); the run, the data's
    span (s), the wall time (s) of the replay and the run's close, and the speed (× real time)
    sustained after the start: the data from the start's to the last row over the wall time from
    the end of the start's pass (building the run: levelling, heading alignment) to the last row's."""
    run = LiveRun(load_layout(config, list(overrides)), replan_s=REPLAN_S if speed is not None else REPLAN_BATCH_S)
    rows = list(replay_rows(run))
    if seconds is not None:
        rows = list(itertools.takewhile(lambda r: r[0] <= rows[0][0] + seconds, rows))
    wall0 = time.perf_counter()
    replay(run, iter(rows), speed)
    replayed = time.perf_counter()
    run.close()
    t_start, wall_start = run.started
    return run, rows[-1][0] - rows[0][0], time.perf_counter() - wall0, (rows[-1][0] - t_start) / (replayed - wall_start)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--speed", type=float, default=1.0, help="the paced replay's speed (× real time)")
    parser.add_argument("--seconds", type=float, default=None, help="seconds of the walk to pace (default all)")
    parser.add_argument("--layout", choices=("vicon", "hand"), default="vicon",
                        help="vicon: the dual-foot Vicon walk; hand: the simulated dual-foot + hand-held phone walk")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override the layout")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as folder:
        return measure(layout(args.layout, Path(folder)), args.speed, args.seconds, args.set)


def measure(config: Path, speed: float, seconds: float | None, overrides: list[str] = ()) -> int:
    """Both replays of ``config`` (module docstring); prints the figures."""
    run, span, wall, sustained = live_replay(config, None, None, overrides)
    max_speedup = span / wall
    fast = np.array(run.latency_s) * 1e3
    print(f"x max: {span:.0f} s of data in {wall:.2f} s: {max_speedup:.1f}x real time, {sustained:.1f}x after the "
          f"start's pass, {run.emitted} states ({run.output.smoothed_emitted} smoothed), {len(fast)} passes; pass p50 "
          f"{np.percentile(fast, 50):.1f} ms, max {fast.max():.1f} ms (the start)")
    run, span, wall, _ = live_replay(config, speed, seconds, overrides)
    lat = np.array(run.latency_s) * 1e3
    budget_ms = REPLAN_S / speed * 1e3
    backlog = int(np.count_nonzero(lat > budget_ms))
    p50, p99, worst = np.percentile(lat, 50), np.percentile(lat, 99), lat.max()
    print(f"x {speed:g}: {span:.0f} s of data in {wall:.1f} s, {run.emitted} states, {len(lat)} passes; "
          f"latency p50 {p50:.1f} ms, p99 {p99:.1f} ms, max {worst:.1f} ms; passes longer than the "
          f"{budget_ms:.0f} ms of data they cover: {backlog}")
    print(f"p99_ms={p99:.2f} max_ms={worst:.2f} max_speedup={max_speedup:.1f} sustained_speedup={sustained:.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
